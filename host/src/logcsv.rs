//! The log CSV schema (docs/logs.md) and the ground-truth CSV of the simulator: typed rows,
//! strict readers and writers.
//!
//! Reading takes logs as recorders write them (docs/logs.md): a header row is required; columns
//! may come in any order; extra columns (unnamed ones too: a trailing comma on every line) are
//! ignored and named in a note, and never read (bytes that are not UTF-8 in them are accepted);
//! quoted cells may hold commas and line breaks (RFC 4180); an empty cell means the sensor did
//! not report at that time; a UTF-8 byte-order mark and CRLF line ends are accepted; a
//! bare CR outside a quoted cell (classic Mac OS line ends) is refused, named as such;
//! rows with equal `t` are one instant (several sensors reported then) and are merged into one
//! row. A value outside its column's physical range ([`LOG_RANGES`]) is an error. Every problem
//! is an error that names the file, the line, the column (character position and name) and the
//! reason; nothing is skipped silently and nothing panics. What reading noticed without refusing
//! the file (extra columns, a sensor reporting two different values at one instant) comes back
//! as [`LogNotes`], for the caller to print.
//!
//! Writing produces Rust's shortest round-trip form of each number, so `read(write(rows)) ==
//! rows` bit for bit.
use std::fmt;
use std::io::Write;
use std::path::{Path, PathBuf};

/// One row of a driving log. Each sensor reports on its own clock, so most cells are empty.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LogRow {
    /// Time, s (as read: strictly increasing down the rows, equal-time lines merged).
    pub t: f64,
    /// Measured speed, m/s.
    pub vel: Option<f64>,
    /// Commanded speed, m/s.
    pub input_vel: Option<f64>,
    /// Accelerator pedal, % 0..100.
    pub accel: Option<f64>,
    /// Measured steering, % -100..100, positive = right (up to [`STEER_PAST_LOCK_PCT`] read as the lock).
    pub steer: Option<f64>,
    /// Brake pedal, % 0..100.
    pub brake: Option<f64>,
    /// GNSS latitude, degrees WGS-84 (present together with `lon`).
    pub lat: Option<f64>,
    /// GNSS longitude, degrees WGS-84 (present together with `lat`).
    pub lon: Option<f64>,
}

impl LogRow {
    /// A row at `t` where no sensor reported.
    pub fn empty(t: f64) -> Self {
        LogRow {
            t,
            ..Default::default()
        }
    }

    /// The cells in the order of [`LOG_COLUMNS`] (`t` always present).
    pub fn cells(&self) -> [Option<f64>; 8] {
        [
            Some(self.t),
            self.vel,
            self.input_vel,
            self.accel,
            self.steer,
            self.brake,
            self.lat,
            self.lon,
        ]
    }

    /// Fills the cells of `other` that are present into `self` (rows logged at the same time).
    pub fn merge(&mut self, other: &LogRow) {
        let pairs = [
            (&mut self.vel, other.vel),
            (&mut self.input_vel, other.input_vel),
            (&mut self.accel, other.accel),
            (&mut self.steer, other.steer),
            (&mut self.brake, other.brake),
            (&mut self.lat, other.lat),
            (&mut self.lon, other.lon),
        ];
        for (mine, theirs) in pairs {
            if theirs.is_some() {
                *mine = theirs;
            }
        }
    }
}

/// One row of the simulator's ground truth (reference point: the rear-axle centre).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TruthRow {
    /// Time, s, on the log's time base.
    pub t: f64,
    /// East of the origin, m.
    pub x: f64,
    /// North of the origin, m.
    pub y: f64,
    /// Heading, clockwise from north, rad, in (-pi, pi].
    pub heading: f64,
    /// Yaw rate, positive clockwise, rad/s.
    pub yaw_rate: f64,
    /// Speed of the reference point, m/s.
    pub speed: f64,
}

/// Columns of the log schema, in the order the writer uses.
pub const LOG_COLUMNS: [&str; 8] = [
    "t",
    "vel",
    "input_vel",
    "accel",
    "steer",
    "brake",
    "lat",
    "lon",
];
/// Columns of the log schema a log may leave out: the pedals (`identify` and `csv2can` use
/// them when present; a missing column reads as a sensor that never reported).
pub const OPTIONAL_LOG_COLUMNS: [&str; 2] = ["accel", "brake"];
/// Columns of the truth CSV.
pub const TRUTH_COLUMNS: [&str; 6] = ["t", "x", "y", "heading", "yaw_rate", "speed"];

/// Why a file was rejected.
#[derive(Debug)]
pub enum LogErrorKind {
    /// The file could not be read or written.
    Io(std::io::Error),
    /// A byte that is not UTF-8 in the header or in a cell that is read.
    NotUtf8,
    /// A quote opens a cell and is never closed (the rest of the file would be one cell).
    UnclosedQuote,
    /// The file has no header row.
    MissingHeader,
    /// A CR not followed by LF outside a quoted cell: the line ends of classic Mac OS, which
    /// make the whole file (or the rest of it) one line.
    BareCarriageReturn {
        /// Bare CRs in the text from this line on (a quoted cell's included).
        count: usize,
    },
    /// The header names a column twice.
    DuplicateColumn(String),
    /// A column the schema requires is absent: the column, and the header found.
    MissingColumn {
        /// The column missing.
        column: &'static str,
        /// The header row as found.
        header: String,
    },
    /// The median interval between the log's instants is far from the schema's 20 ms.
    SampleInterval {
        /// The median interval, in the file's unit of `t`.
        median: f64,
    },
    /// A blank line before the end of the file.
    BlankLine,
    /// A row has a different number of cells than the header.
    FieldCount {
        /// Cells in the header.
        expected: usize,
        /// Cells in this row.
        found: usize,
    },
    /// A cell that must have a value is empty (`t`, every truth column).
    MissingValue,
    /// The cell is not a number.
    NotANumber(String),
    /// The cell is NaN or infinite.
    NonFinite(String),
    /// The value is outside its column's physical range ([`LOG_RANGES`]).
    OutOfRange {
        /// The value.
        value: f64,
        /// The column's range.
        range: &'static ColumnRange,
    },
    /// A GNSS fix at latitude 0, longitude 0: the placeholder many receivers write without a
    /// fix, not a position (it is in the Gulf of Guinea).
    NullIsland,
    /// Every fix of the log lies within pi/2 deg of the equator and pi deg of Greenwich: open
    /// sea in the Gulf of Guinea, and exactly the range of a latitude and longitude in
    /// radians ([`radians_likely`]).
    RadiansLikely {
        /// Fixes in the log.
        fixes: usize,
    },
    /// `t` is smaller than the previous row's (log), or not greater (truth, written files).
    TimeNotIncreasing {
        /// This row's time, s.
        t: f64,
        /// The previous row's time, s.
        previous: f64,
    },
    /// Only one of `lat` and `lon` is present.
    HalfFix,
}

/// The largest median interval between a log's instants, s: the schema's sensors report every
/// 20 ms (a receiver once a second at the slowest), so a median over a second is a `t` in
/// another unit. A `t` in milliseconds put 20 ms samples 20 "s" apart: identify ran for
/// minutes on the 20 ms grid of a log a thousand times too long, compare fitted nonsense.
pub const MAX_MEDIAN_INTERVAL_S: f64 = 1.0;

/// Why a header lacks `column`, when the header shows it: a comment line above it, `;`
/// separators, units in the names, upper case.
fn header_hint(column: &str, header: &str) -> Option<&'static str> {
    if header.trim_start().starts_with(['#', '%']) {
        return Some("the first line is a comment (a logger's banner): the header, `t,vel,...`, must be the file's first line; remove the comment lines above it");
    }
    let cells: Vec<&str> = header.split(',').map(str::trim).collect();
    if cells.len() == 1 && header.contains(';') {
        return Some("the header is separated by `;`: the schema's separator is `,` (a spreadsheet's export with a `;` list separator)");
    }
    if cells.len() == 1 && header.contains('\t') {
        return Some("the header is separated by tabs: the schema's separator is `,`");
    }
    let names = |c: &&str| c.trim_matches('"').trim().to_string();
    if cells.iter().map(names).any(|c| {
        c.strip_prefix(column).is_some_and(|rest| {
            rest.trim_start().starts_with(['[', '(', '_', '/']) || rest.starts_with(' ')
        })
    }) {
        return Some("a column name carries a unit or suffix: name the columns exactly `t`, `vel`, ... (the units are the schema's, docs/logs.md)");
    }
    if cells
        .iter()
        .map(names)
        .any(|c| c.eq_ignore_ascii_case(column))
    {
        return Some("column names are lower case (`vel`, not `VEL`)");
    }
    None
}

/// A rejected file: where and why.
#[derive(Debug)]
pub struct LogError {
    /// The file.
    pub path: PathBuf,
    /// 1-based line (the header is line 1); 0 when the problem is not on a line (I/O).
    pub line: usize,
    /// 1-based character position of the offending cell; 0 when the whole line is at fault.
    pub char_column: usize,
    /// Name of the offending column, when there is one.
    pub column: Option<String>,
    /// The reason.
    pub kind: LogErrorKind,
}

impl fmt::Display for LogErrorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LogErrorKind::Io(e) => write!(f, "{e}"),
            LogErrorKind::NotUtf8 => write!(
                f,
                "not UTF-8 text (the header and the schema's columns must be UTF-8; bytes \
                 of another encoding are accepted only in columns that are ignored)"
            ),
            LogErrorKind::UnclosedQuote => write!(
                f,
                "the quote that opens this cell is never closed (RFC 4180: a quoted cell ends \
                 at the next lone `\"`; `\"\"` is a quote inside it)"
            ),
            LogErrorKind::MissingHeader => write!(f, "missing header row"),
            LogErrorKind::BareCarriageReturn { count } => {
                write!(f, "a line ends here with a bare CR (`\\r` without `\\n`)")?;
                if *count > 1 {
                    write!(f, ", and {} more after it", count - 1)?;
                }
                write!(
                    f,
                    ": the line ends of classic Mac OS, not the schema's LF or CRLF (the lines \
                     after a bare CR would be read as part of this one): convert them, e.g. \
                     `tr '\\r' '\\n' < IN > OUT`"
                )
            }
            LogErrorKind::DuplicateColumn(c) => {
                write!(f, "column `{c}` appears twice in the header")
            }
            LogErrorKind::MissingColumn { column, header } => {
                write!(
                    f,
                    "missing required column `{column}` (the header found: `{header}`)"
                )?;
                match header_hint(column, header) {
                    Some(hint) => write!(f, ": {hint}"),
                    None => Ok(()),
                }
            }
            LogErrorKind::SampleInterval { median } => {
                write!(
                    f,
                    "the median interval between samples is {median:.3} (in the unit of `t`), far \
                     from the 20 ms of the log schema (`t` in seconds, sensors every 20 ms or \
                     faster)"
                )?;
                if (MAX_MEDIAN_INTERVAL_S..=1000.0).contains(median) {
                    write!(f, ": `t` looks like milliseconds; divide it by 1000")
                } else if *median > 1000.0 {
                    write!(f, ": `t` looks like microseconds; divide it by 1e6")
                } else {
                    Ok(())
                }
            }
            LogErrorKind::BlankLine => write!(f, "blank line inside the data"),
            LogErrorKind::FieldCount { expected, found } => {
                write!(
                    f,
                    "expected {expected} cells as in the header, found {found}"
                )
            }
            LogErrorKind::MissingValue => write!(f, "empty cell where a value is required"),
            LogErrorKind::NotANumber(s) => write!(f, "not a number: `{s}`"),
            LogErrorKind::NonFinite(s) => write!(f, "non-finite value: `{s}`"),
            LogErrorKind::OutOfRange { value, range } => write!(
                f,
                "{value} {unit} is outside {min}..{max} {unit} ({why})",
                value = Readable(*value),
                unit = range.unit,
                min = Readable(range.min),
                max = Readable(range.max),
                why = range.why
            )
            .and_then(|()| match range.unit {
                "deg" => write!(f, "{}", angle_format_hint(*value, range)),
                _ => Ok(()),
            }),
            LogErrorKind::NullIsland => write!(
                f,
                "fix at latitude 0, longitude 0: the placeholder receivers write without a fix; leave `lat` and `lon` empty instead"
            ),
            LogErrorKind::RadiansLikely { fixes } => write!(
                f,
                "all {fixes} fixes lie within 1.5708 deg of the equator and 3.1416 deg of \
                 Greenwich, in the open sea of the Gulf of Guinea: `lat` and `lon` look like \
                 radians; the schema's are degrees (multiply both columns by 57.29578)"
            ),
            LogErrorKind::TimeNotIncreasing { t, previous } if t < previous => {
                write!(f, "time goes backwards: {t} after {previous}")
            }
            LogErrorKind::TimeNotIncreasing { t, previous } => {
                write!(f, "time not increasing: {t} after {previous}")
            }
            LogErrorKind::HalfFix => {
                write!(f, "`lat` and `lon` must be both present or both empty")
            }
        }
    }
}

/// What an angle outside a latitude's or longitude's range most likely is: integers of 1e-7
/// deg (u-blox's binary messages, and converters that keep them), or NMEA's `ddmm.mmmm`
/// (degrees times 100 plus minutes). Empty when it is neither.
fn angle_format_hint(value: f64, range: &ColumnRange) -> &'static str {
    let a = value.abs();
    if a >= 1e5 && a / 1e7 <= range.max {
        "; integers of 1e-7 deg (as u-blox writes them) need dividing by 1e7"
    } else if a < 100.0 * range.max && a % 100.0 < 60.0 {
        "; NMEA's ddmm.mmmm (degrees times 100 plus minutes) needs converting to degrees"
    } else {
        ""
    }
}

/// A number as a person reads it: plain (`101`, `-0.5`), or in exponent form when plain
/// would be a long run of digits (`1e30`, `1.5e-9`).
pub struct Readable(pub f64);

impl fmt::Display for Readable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let a = self.0.abs();
        if a != 0.0 && !(1e-4..1e7).contains(&a) {
            write!(f, "{:e}", self.0)
        } else {
            write!(f, "{}", self.0)
        }
    }
}

impl fmt::Display for LogError {
    /// `path:line:column: column `name`: reason`, like a compiler diagnostic.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.path.display())?;
        if self.line > 0 {
            write!(f, ":{}", self.line)?;
            if self.char_column > 0 {
                write!(f, ":{}", self.char_column)?;
            }
        }
        write!(f, ": ")?;
        if let Some(c) = &self.column {
            write!(f, "column `{c}`: ")?;
        }
        write!(f, "{}", self.kind)
    }
}

impl std::error::Error for LogError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match &self.kind {
            LogErrorKind::Io(e) => Some(e),
            _ => None,
        }
    }
}

fn file_error(path: &Path, kind: LogErrorKind) -> LogError {
    LogError {
        path: path.to_path_buf(),
        line: 0,
        char_column: 0,
        column: None,
        kind,
    }
}

/// The physical range of a log column: a value outside it is not a measurement of a car
/// (a unit mistake, a corrupt cell, a sentinel) and the file is refused at that cell.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ColumnRange {
    /// Column name.
    pub column: &'static str,
    /// Unit, as the error message prints it.
    pub unit: &'static str,
    /// Smallest value accepted.
    pub min: f64,
    /// Largest value accepted.
    pub max: f64,
    /// Why the range ends there (printed with the error).
    pub why: &'static str,
}

/// Speed range shared by `vel` and `input_vel`.
const SPEED_WHY: &str = "no car drives this: 80 m/s = 288 km/h is above the 250 km/h most cars are limited to, -10 m/s = 36 km/h in reverse; a speed in km/h or mph?";
/// Pedal range shared by `accel` and `brake`.
const PEDAL_WHY: &str = "a pedal travels 0..100 %";

/// Full lock, `steer`'s 100 %: the most the steering report on the bus carries
/// (`catmodel::can::spec` STEER_PCT, -100..100 %).
pub const STEER_LOCK_PCT: f64 = 100.0;

/// The largest `steer` magnitude read, %: a sensor calibrated a few tenths of a per cent past
/// the lock (a black-box probe's 100.9 % refused the whole log) is a real car's, and read as
/// the lock ([`STEER_LOCK_PCT`], what the node reads on the bus), counted in a note
/// ([`LogNotes::steer_past_lock`]); 5 % past it, the steering zero's tolerance of a whole
/// sensor's noise in `identify` (its outlier check's 5 %), is the most a calibration is off by,
/// and beyond it no car's steering reads.
pub const STEER_PAST_LOCK_PCT: f64 = 105.0;

/// Ranges of the log columns, in the order of [`LOG_COLUMNS`] (docs/logs.md). Deliberately
/// wide: they catch values no car can have, not unusual driving.
pub const LOG_RANGES: [ColumnRange; 8] = [
    ColumnRange {
        column: "t",
        unit: "s",
        min: -1e10,
        max: 1e10,
        why: "1e10 s is 317 years: a time in milliseconds or microseconds?",
    },
    ColumnRange {
        column: "vel",
        unit: "m/s",
        min: -10.0,
        max: 80.0,
        why: SPEED_WHY,
    },
    ColumnRange {
        column: "input_vel",
        unit: "m/s",
        min: -10.0,
        max: 80.0,
        why: SPEED_WHY,
    },
    ColumnRange {
        column: "accel",
        unit: "%",
        min: 0.0,
        max: 100.0,
        why: PEDAL_WHY,
    },
    ColumnRange {
        column: "steer",
        unit: "%",
        min: -STEER_PAST_LOCK_PCT,
        max: STEER_PAST_LOCK_PCT,
        why: "100 % is full lock; up to 105 % is a sensor calibrated a little past it, read as the lock",
    },
    ColumnRange {
        column: "brake",
        unit: "%",
        min: 0.0,
        max: 100.0,
        why: PEDAL_WHY,
    },
    ColumnRange {
        column: "lat",
        unit: "deg",
        min: -90.0,
        max: 90.0,
        why: "WGS-84 latitude",
    },
    ColumnRange {
        column: "lon",
        unit: "deg",
        min: -180.0,
        max: 180.0,
        why: "WGS-84 longitude",
    },
];

/// The largest distance from the truth frame's origin, m: 10 000 km, a quarter of the way
/// round the Earth; a flat east/north frame means nothing further out. A larger value is a
/// corrupt cell or another unit, not a car's position.
pub const MAX_TRUTH_POSITION_M: f64 = 1e7;

/// Ranges of the truth columns, in the order of [`TRUTH_COLUMNS`] (docs/logs.md). As wide as
/// the log's: they catch corrupt cells and unit mistakes (a truth `x = 1e300` made `evaluate`
/// print `inf` and `NaN`), not unusual driving.
pub const TRUTH_RANGES: [ColumnRange; 6] = [
    LOG_RANGES[0],
    ColumnRange {
        column: "x",
        unit: "m",
        min: -MAX_TRUTH_POSITION_M,
        max: MAX_TRUTH_POSITION_M,
        why: "10 000 km from the origin, a quarter of the way round the Earth: a corrupt cell, or not metres?",
    },
    ColumnRange {
        column: "y",
        unit: "m",
        min: -MAX_TRUTH_POSITION_M,
        max: MAX_TRUTH_POSITION_M,
        why: "10 000 km from the origin, a quarter of the way round the Earth: a corrupt cell, or not metres?",
    },
    ColumnRange {
        column: "heading",
        unit: "rad",
        min: -6.3,
        max: 6.3,
        why: "a heading in radians, -pi..pi or 0..2 pi; in degrees?",
    },
    ColumnRange {
        column: "yaw_rate",
        unit: "rad/s",
        min: -10.0,
        max: 10.0,
        why: "573 deg/s; a car spinning out turns at about 3 rad/s: in deg/s?",
    },
    ColumnRange {
        column: "speed",
        unit: "m/s",
        min: -10.0,
        max: 80.0,
        why: SPEED_WHY,
    },
];

/// Index of `t`, `lat` and `lon` in [`LOG_COLUMNS`].
const T: usize = 0;
const STEER: usize = 4;
const LAT: usize = 6;
const LON: usize = 7;

/// A driving log as read: its rows (strictly increasing in time) and what reading noticed.
#[derive(Debug, Clone, PartialEq)]
pub struct Log {
    /// One row per instant.
    pub rows: Vec<LogRow>,
    /// The file line each row starts on (the first of its instant's lines).
    pub lines: Vec<usize>,
    /// Accepted, but worth telling the user.
    pub notes: LogNotes,
}

/// A sensor that reported two different values at one instant.
#[derive(Debug, Clone, PartialEq)]
pub struct Conflict {
    /// The column.
    pub column: &'static str,
    /// The instant, s.
    pub t: f64,
    /// The earlier value and its line.
    pub first: (f64, usize),
    /// The later value (the one kept) and its line.
    pub kept: (f64, usize),
}

/// What reading a log noticed without refusing it.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LogNotes {
    /// The file.
    pub path: PathBuf,
    /// Header cells that are not schema columns, in file order (ignored); `""` for an unnamed
    /// column (an empty header cell: a trailing comma on every line).
    pub extra_columns: Vec<String>,
    /// Lines merged into the row before them because they share its `t`.
    pub merged_lines: usize,
    /// Cells whose sensor already had a different value at that instant (the later line
    /// wins), counted; the first one is kept as an example.
    pub conflicts: usize,
    /// The first conflict.
    pub first_conflict: Option<Conflict>,
    /// The last line, when the file ends without a line end after it (a recorder that lost
    /// power mid-line): its number, and whether it was left out (it did not read as a row).
    pub cut_last_line: Option<CutLine>,
    /// `steer` samples past full lock (within [`STEER_PAST_LOCK_PCT`]), read as the lock.
    pub steer_past_lock: Option<PastLock>,
}

/// `steer` samples past full lock read as the lock ([`LogNotes::steer_past_lock`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PastLock {
    /// How many.
    pub samples: usize,
    /// The one furthest past it, % (as written, signed).
    pub largest_pct: f64,
    /// Its line (1-based).
    pub line: usize,
}

impl PastLock {
    /// `steer = value` of line `line`, read as the lock when past it (counted in `past`).
    fn clamp(past: &mut Option<Self>, value: f64, line: usize) -> f64 {
        if value.abs() <= STEER_LOCK_PCT {
            return value;
        }
        match past {
            Some(p) => {
                p.samples += 1;
                if value.abs() > p.largest_pct.abs() {
                    p.largest_pct = value;
                    p.line = line;
                }
            }
            None => {
                *past = Some(Self {
                    samples: 1,
                    largest_pct: value,
                    line,
                })
            }
        }
        value.clamp(-STEER_LOCK_PCT, STEER_LOCK_PCT)
    }
}

/// The last line of a file that ends without a line end ([`LogNotes::cut_last_line`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CutLine {
    /// Its number (1-based).
    pub line: usize,
    /// Left out: it did not read as a row (too few cells, a number cut short into nothing or
    /// out of range, a `t` cut to before the line above).
    pub left_out: bool,
}

impl LogNotes {
    /// One line per note, `FILE[:LINE]: text`, for stderr. Equal-time lines that merge without
    /// a conflict are normal and get no note.
    pub fn messages(&self) -> Vec<String> {
        let mut out = Vec::new();
        let file = self.path.display();
        if !self.extra_columns.is_empty() {
            let names: Vec<String> = self
                .extra_columns
                .iter()
                .filter(|c| !c.is_empty())
                .map(|c| format!("`{c}`"))
                .collect();
            let unnamed = self.extra_columns.len() - names.len();
            let mut parts = Vec::new();
            match names.len() {
                0 => {}
                1 => parts.push(format!("column {}", names.join(""))),
                _ => parts.push(format!("columns {}", names.join(", "))),
            }
            match unnamed {
                0 => {}
                1 => parts.push(
                    "1 unnamed column (an empty header cell, as a trailing comma on every line \
                     makes)"
                        .to_string(),
                ),
                n => parts.push(format!(
                    "{n} unnamed columns (empty header cells, as trailing commas on every line \
                     make)"
                )),
            }
            let verb = if self.extra_columns.len() == 1 {
                "is"
            } else {
                "are"
            };
            out.push(format!(
                "{file}: {} {verb} not in the log schema: ignored",
                parts.join(" and ")
            ));
        }
        if let Some(p) = &self.steer_past_lock {
            out.push(format!(
                "{file}:{}: column `steer`: {} sample(s) past full lock, the largest {} % on \
                 this line: a steering sensor calibrated a little past its lock (up to \
                 {STEER_PAST_LOCK_PCT} % is taken so); read as the lock, {} % (the steering \
                 report on the bus carries no more, so the node reads the lock there too)",
                p.line,
                p.samples,
                Readable(p.largest_pct),
                Readable(p.largest_pct.signum() * STEER_LOCK_PCT)
            ));
        }
        if let Some(c) = &self.first_conflict {
            out.push(format!(
                "{file}:{}: column `{}`: two values at t = {} s ({} on line {}, {} on line {}): the later one is kept ({} such cell(s) in the file)",
                c.kept.1, c.column, c.t, c.first.0, c.first.1, c.kept.0, c.kept.1, self.conflicts
            ));
        }
        out
    }

    /// One line per warning, `FILE:LINE: text`, for stderr: a last line without a line end,
    /// as the candump reader warns of one.
    pub fn warnings(&self) -> Vec<String> {
        let file = self.path.display();
        self.cut_last_line
            .iter()
            .map(|c| {
                let fate = if c.left_out {
                    "it does not read as a row: left out"
                } else {
                    "its values are kept; a number cut short that reads as another is left to \
                     the check of each sample against its neighbours (identify, compare)"
                };
                format!(
                    "{file}:{}: the last line has no line end: the recorder may have stopped \
                     mid-line (lost power); {fate}",
                    c.line
                )
            })
            .collect()
    }
}

/// The physical line number of the last line of `text` when the file ends without a line end
/// after it (blanks after the last line end are no line).
fn unterminated_last_line(text: &str) -> Option<usize> {
    let end = text.trim_end_matches([' ', '\t']);
    (!end.is_empty() && !end.ends_with('\n')).then(|| end.matches('\n').count() + 1)
}

/// Reads a driving log. The schema's columns are required but for the pedals, `accel` and
/// `brake` (a sensor that never reported is an empty column, or for the pedals no column);
/// a log whose median interval between instants is over [`MAX_MEDIAN_INTERVAL_S`] is refused.
pub fn read_log(path: &Path) -> Result<Log, LogError> {
    let text = read_text(path)?;
    parse_log_text(&text.text, path, text.lossy)
}

/// The instant being assembled from lines that share one `t`.
struct PendingRow {
    row: LogRow,
    /// The instant's first line.
    line: usize,
    /// For each column: (line, character column) of the cell that set it.
    source: [(usize, usize); 8],
}

impl PendingRow {
    fn error(&self, path: &Path, i: usize, kind: LogErrorKind) -> LogError {
        let (line, char_column) = self.source.get(i).copied().unwrap_or((0, 0));
        LogError {
            path: path.to_path_buf(),
            line,
            char_column,
            column: LOG_COLUMNS.get(i).map(|s| s.to_string()),
            kind,
        }
    }

    /// Checks the merged fix: both halves or neither, and not the no-fix placeholder.
    fn finish(self, path: &Path) -> Result<LogRow, LogError> {
        match (self.row.lat, self.row.lon) {
            (Some(_), None) => Err(self.error(path, LAT, LogErrorKind::HalfFix)),
            (None, Some(_)) => Err(self.error(path, LON, LogErrorKind::HalfFix)),
            (Some(lat), Some(lon)) if lat == 0.0 && lon == 0.0 => {
                Err(self.error(path, LAT, LogErrorKind::NullIsland))
            }
            _ => Ok(self.row),
        }
    }
}

/// Parses log text; `path` only names the source in errors.
pub fn parse_log(text: &str, path: &Path) -> Result<Log, LogError> {
    parse_log_text(text, path, false)
}

/// [`parse_log`]; `lossy`: bytes that were not UTF-8 were replaced by U+FFFD in `text`
/// ([`read_text`]).
fn parse_log_text(text: &str, path: &Path, lossy: bool) -> Result<Log, LogError> {
    let table = Table::new(text, path, &LOG_COLUMNS, &OPTIONAL_LOG_COLUMNS, lossy)?;
    let mut notes = LogNotes {
        path: path.to_path_buf(),
        extra_columns: table.extra_columns(),
        ..LogNotes::default()
    };
    let mut rows = Vec::new();
    let mut lines = Vec::new();
    let mut pending: Option<PendingRow> = None;
    // A last line without a line end that does not read is left out with a warning, as the
    // candump reader does: the recorder stopped in the middle of it.
    let cut = unterminated_last_line(text);
    for line in table.lines() {
        let line = match line {
            Ok(line) => line,
            Err(e) => {
                let n = e.line;
                leave_out_cut(&mut notes, cut, e, n)?;
                break;
            }
        };
        let previous = pending.as_ref().map(|p| p.row.t);
        let (mut values, t) = match line_values(&line, previous) {
            Ok(v) => v,
            Err(e) => {
                leave_out_cut(&mut notes, cut, e, line.number)?;
                break;
            }
        };
        if let Some(steer) = values[STEER].as_mut() {
            *steer = PastLock::clamp(&mut notes.steer_past_lock, *steer, line.number);
        }
        if cut == Some(line.number) {
            notes.cut_last_line = Some(CutLine {
                line: line.number,
                left_out: false,
            });
        }
        let instant = match pending.take() {
            Some(p) if p.row.t == t => {
                notes.merged_lines += 1;
                p
            }
            Some(p) => {
                lines.push(p.line);
                rows.push(p.finish(path)?);
                PendingRow {
                    row: LogRow::empty(t),
                    line: line.number,
                    source: [(0, 0); 8],
                }
            }
            None => PendingRow {
                row: LogRow::empty(t),
                line: line.number,
                source: [(0, 0); 8],
            },
        };
        let mut instant = instant;
        let cells = [
            &mut instant.row.vel,
            &mut instant.row.input_vel,
            &mut instant.row.accel,
            &mut instant.row.steer,
            &mut instant.row.brake,
            &mut instant.row.lat,
            &mut instant.row.lon,
        ];
        for (k, cell) in cells.into_iter().enumerate() {
            let i = k + 1;
            let Some(v) = values[i] else { continue };
            if let Some(old) = *cell {
                if old != v {
                    notes.conflicts += 1;
                    if notes.first_conflict.is_none() {
                        notes.first_conflict = Some(Conflict {
                            column: LOG_COLUMNS[i],
                            t,
                            first: (old, instant.source[i].0),
                            kept: (v, line.number),
                        });
                    }
                }
            }
            *cell = Some(v);
            instant.source[i] = line.position(i);
        }
        pending = Some(instant);
    }
    if let Some(p) = pending {
        let line = p.line;
        match p.finish(path) {
            Ok(row) => {
                lines.push(line);
                rows.push(row);
            }
            // Half a fix on the cut line (`lon` lost).
            Err(e) if cut == Some(line) => leave_out_cut(&mut notes, cut, e, line)?,
            Err(e) => return Err(e),
        }
    }
    check_sample_interval(&rows, path)?;
    if let Some(fixes) = radians_likely(&rows) {
        let first = rows.iter().position(|r| r.lat.is_some()).unwrap_or(0);
        return Err(LogError {
            path: path.to_path_buf(),
            line: lines.get(first).copied().unwrap_or(0),
            char_column: 0,
            column: Some("lat".to_string()),
            kind: LogErrorKind::RadiansLikely { fixes },
        });
    }
    Ok(Log { rows, lines, notes })
}

/// Leaves out the line `line` of a log, which did not read (`e`), with a warning in `notes`
/// when it is the last line and has no line end (`cut`, [`unterminated_last_line`]); `e`
/// otherwise.
fn leave_out_cut(
    notes: &mut LogNotes,
    cut: Option<usize>,
    e: LogError,
    line: usize,
) -> Result<(), LogError> {
    match cut {
        Some(c) if c == line || c == e.line => {
            notes.cut_last_line = Some(CutLine {
                line: c,
                left_out: true,
            });
            Ok(())
        }
        _ => Err(e),
    }
}

/// The values of a log line (in [`LOG_COLUMNS`] order, each in its range) and its `t`, which
/// must not be before `previous` (the instant above).
fn line_values(
    line: &Line<'_>,
    previous: Option<f64>,
) -> Result<([Option<f64>; 8], f64), LogError> {
    let mut values = [None; 8];
    for (i, v) in values.iter_mut().enumerate() {
        *v = line.value(i, LOG_RANGES.get(i))?;
    }
    let Some(t) = values[T] else {
        return Err(line.error(T, LogErrorKind::MissingValue));
    };
    if let Some(p) = previous.filter(|p| t < *p) {
        return Err(line.error(T, LogErrorKind::TimeNotIncreasing { t, previous: p }));
    }
    Ok((values, t))
}

/// The number of fixes when every fix of `rows` lies in the box a latitude and longitude in
/// radians fill when read as degrees (|lat| <= pi/2, |lon| <= pi). In degrees that box is the
/// open sea south of Ghana, about 270 km from the nearest land (Annobon, 1.4 deg south, 5.6 deg
/// east; Ghana's coast is at 4.7 deg north): no drive is logged there, so a log whose fixes all
/// lie in it is in radians. The wheel speed's unit check cannot tell (`identify::units`): its
/// chords need metres of track, and a track in radians read as degrees is 57 times too short.
pub fn radians_likely(rows: &[LogRow]) -> Option<usize> {
    use std::f64::consts::{FRAC_PI_2, PI};
    let mut fixes = 0;
    for r in rows {
        if let (Some(lat), Some(lon)) = (r.lat, r.lon) {
            if lat.abs() > FRAC_PI_2 || lon.abs() > PI {
                return None;
            }
            fixes += 1;
        }
    }
    (fixes > 0).then_some(fixes)
}

/// Refuses a log whose median interval between instants is over [`MAX_MEDIAN_INTERVAL_S`].
fn check_sample_interval(rows: &[LogRow], path: &Path) -> Result<(), LogError> {
    let mut intervals: Vec<f64> = rows.windows(2).map(|w| w[1].t - w[0].t).collect();
    if intervals.len() < 2 {
        return Ok(());
    }
    let mid = intervals.len() / 2;
    let median = *intervals.select_nth_unstable_by(mid, f64::total_cmp).1;
    if median > MAX_MEDIAN_INTERVAL_S {
        return Err(LogError {
            path: path.to_path_buf(),
            line: 0,
            char_column: 0,
            column: Some("t".to_string()),
            kind: LogErrorKind::SampleInterval { median },
        });
    }
    Ok(())
}

/// Reads a truth CSV (every cell required, each within its column's range: [`TRUTH_RANGES`]).
pub fn read_truth(path: &Path) -> Result<Vec<TruthRow>, LogError> {
    let text = read_text(path)?;
    parse_truth_text(&text.text, path, text.lossy)
}

/// Parses truth text; `path` only names the source in errors.
pub fn parse_truth(text: &str, path: &Path) -> Result<Vec<TruthRow>, LogError> {
    parse_truth_text(text, path, false)
}

fn parse_truth_text(text: &str, path: &Path, lossy: bool) -> Result<Vec<TruthRow>, LogError> {
    let table = Table::new(text, path, &TRUTH_COLUMNS, &[], lossy)?;
    let mut rows = Vec::new();
    let mut previous: Option<f64> = None;
    for line in table.lines() {
        let line = line?;
        let mut v = [0.0; 6];
        for (i, out) in v.iter_mut().enumerate() {
            *out = match line.value(i, TRUTH_RANGES.get(i))? {
                Some(x) => x,
                None => return Err(line.error(i, LogErrorKind::MissingValue)),
            };
        }
        check_time(&line, v[0], &mut previous)?;
        rows.push(TruthRow {
            t: v[0],
            x: v[1],
            y: v[2],
            heading: v[3],
            yaw_rate: v[4],
            speed: v[5],
        });
    }
    Ok(rows)
}

/// Writes a driving log (header + rows). Rejects non-finite values and non-increasing time, so
/// that what is written can always be read back.
pub fn write_log(path: &Path, rows: &[LogRow]) -> Result<(), LogError> {
    write_file(path, |buf| write_log_to(buf, rows))
}

/// Writes a driving log to any writer. Errors carry (line, column, reason).
pub fn write_log_to<W: Write>(w: &mut W, rows: &[LogRow]) -> Result<(), WriteError> {
    write_table(w, &LOG_COLUMNS, rows.iter().map(LogRow::cells))
}

/// Writes a truth CSV.
pub fn write_truth(path: &Path, rows: &[TruthRow]) -> Result<(), LogError> {
    write_file(path, |buf| write_truth_to(buf, rows))
}

/// Writes a truth CSV to any writer. Errors carry (line, column, reason).
pub fn write_truth_to<W: Write>(w: &mut W, rows: &[TruthRow]) -> Result<(), WriteError> {
    let cells = rows.iter().map(|r| {
        [
            Some(r.t),
            Some(r.x),
            Some(r.y),
            Some(r.heading),
            Some(r.yaw_rate),
            Some(r.speed),
        ]
    });
    write_table(w, &TRUTH_COLUMNS, cells)
}

/// What a writer refused: (line, column, reason).
pub type WriteError = (usize, Option<&'static str>, LogErrorKind);

/// Formats a whole table in memory, then writes the file: nothing is written for a table with a
/// bad cell.
fn write_file(
    path: &Path,
    format: impl FnOnce(&mut Vec<u8>) -> Result<(), WriteError>,
) -> Result<(), LogError> {
    let mut buf = Vec::new();
    format(&mut buf).map_err(|(line, column, kind)| LogError {
        path: path.to_path_buf(),
        line,
        char_column: 0,
        column: column.map(str::to_string),
        kind,
    })?;
    std::fs::write(path, buf).map_err(|e| file_error(path, LogErrorKind::Io(e)))
}

/// The header, then one line per row of cells, each checked (finite, time increasing) first.
fn write_table<W: Write, const N: usize>(
    w: &mut W,
    names: &[&'static str; N],
    rows: impl Iterator<Item = [Option<f64>; N]>,
) -> Result<(), WriteError> {
    let io = |e| (0, None, LogErrorKind::Io(e));
    writeln!(w, "{}", names.join(",")).map_err(io)?;
    let mut previous: Option<f64> = None;
    let mut line_text = String::new();
    for (i, cells) in rows.enumerate() {
        check_write(i + 2, &cells, names, &mut previous)?;
        format_cells(&mut line_text, &cells);
        w.write_all(line_text.as_bytes()).map_err(io)?;
    }
    Ok(())
}

fn check_write(
    line: usize,
    cells: &[Option<f64>],
    names: &[&'static str],
    previous: &mut Option<f64>,
) -> Result<(), WriteError> {
    for (cell, name) in cells.iter().zip(names) {
        if let Some(v) = cell {
            if !v.is_finite() {
                return Err((line, Some(*name), LogErrorKind::NonFinite(v.to_string())));
            }
        }
    }
    if let Some(Some(t)) = cells.first() {
        if let Some(p) = *previous {
            if *t <= p {
                return Err((
                    line,
                    Some("t"),
                    LogErrorKind::TimeNotIncreasing { t: *t, previous: p },
                ));
            }
        }
        *previous = Some(*t);
    }
    Ok(())
}

fn format_cells(out: &mut String, cells: &[Option<f64>]) {
    use std::fmt::Write as _;
    out.clear();
    for (i, cell) in cells.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        if let Some(v) = cell {
            // Note: writing into a String cannot fail.
            let _ = write!(out, "{v}");
        }
    }
    out.push('\n');
}

/// A file's text, and whether bytes that are not UTF-8 were replaced (U+FFFD) to get it.
struct Text {
    text: String,
    lossy: bool,
}

/// Reads a file as text. Bytes that are not UTF-8 (a cp1252 `ß` in a recorder's comment) are
/// replaced by U+FFFD and the text is marked lossy: such a byte is refused where it is read
/// (the header, a schema column: [`LogErrorKind::NotUtf8`] with its line and column) and
/// never looked at in an ignored column. A replacement never swallows a comma, a quote or a
/// line end (they are ASCII), so the cells and lines stay where they were.
fn read_text(path: &Path) -> Result<Text, LogError> {
    let bytes = std::fs::read(path).map_err(|e| file_error(path, LogErrorKind::Io(e)))?;
    Ok(match String::from_utf8(bytes) {
        Ok(text) => Text { text, lossy: false },
        Err(e) => Text {
            text: String::from_utf8_lossy(e.as_bytes()).into_owned(),
            lossy: true,
        },
    })
}

/// Strictly increasing time (the truth CSV: one row per sample, never two at one instant).
fn check_time(line: &Line<'_>, t: f64, previous: &mut Option<f64>) -> Result<(), LogError> {
    if let Some(p) = *previous {
        if t <= p {
            return Err(line.error(0, LogErrorKind::TimeNotIncreasing { t, previous: p }));
        }
    }
    *previous = Some(t);
    Ok(())
}

/// A cell: its text (trimmed, outer quotes removed) and where it starts.
struct Cell<'a> {
    text: &'a str,
    /// 1-based physical line the cell starts on (a quoted cell may hold line breaks, so the
    /// cells of one record can start on different lines).
    line: usize,
    /// 1-based character position on that line.
    char_column: usize,
}

/// One record of the file (a header or a data row): usually one line; more when a quoted cell
/// holds a line break (RFC 4180 allows it; a recorder's free-text comment does it).
struct Record<'a> {
    /// 1-based physical line the record starts on.
    line: usize,
    /// Physical lines it spans.
    lines: usize,
    /// (line, character column) of the first CR outside a quoted cell that no LF follows.
    bare_cr: Option<(usize, usize)>,
    /// Its text without the line end.
    text: &'a str,
    cells: Vec<Cell<'a>>,
}

/// A quote that opens a cell and is never closed: (line, character column) of the quote.
struct UnclosedQuote(usize, usize);

/// Splits the record at the start of `text` (which starts on physical line `line`) into cells
/// at the commas outside quoted cells; returns it and the text after its line end. RFC 4180
/// quoting: a `"` that is the first non-blank character of a cell opens a quoted cell, in which
/// commas and line breaks are text and `""` is a quote; the next lone `"` closes it. A `"`
/// anywhere else is text (`5" screen`), so a stray quote cannot swallow the lines after it. A
/// cell's text is trimmed and loses its outer quotes; escaped quotes are left as they are (no
/// schema column holds text).
fn next_record(text: &str, line: usize) -> Result<(Record<'_>, &str), UnclosedQuote> {
    let bytes = text.as_bytes();
    let mut cells = Vec::new();
    let mut cell_start = 0;
    let (mut cell_line, mut cell_column) = (line, 1);
    let mut current_line = line;
    // Character column of the next byte that starts a character. The delimiters are ASCII,
    // so scanning bytes finds them; a multi-byte character counts once.
    let mut next_column = 1;
    let mut at_cell_start = true;
    let mut open_quote: Option<(usize, usize)> = None;
    let mut bare_cr: Option<(usize, usize)> = None;
    let cell = |start: usize, end: usize, line: usize, char_column: usize| {
        let trimmed = text.get(start..end).unwrap_or("").trim();
        let text = trimmed
            .strip_prefix('"')
            .and_then(|s| s.strip_suffix('"'))
            .unwrap_or(trimmed)
            .trim();
        Cell {
            text,
            line,
            char_column,
        }
    };
    let mut i = 0;
    while let Some(&b) = bytes.get(i) {
        let column = next_column;
        if b & 0xC0 != 0x80 {
            next_column += 1;
        }
        if open_quote.is_some() {
            match b {
                b'"' if bytes.get(i + 1) == Some(&b'"') => {
                    i += 1;
                    next_column += 1;
                }
                b'"' => open_quote = None,
                b'\n' => {
                    current_line += 1;
                    next_column = 1;
                }
                _ => {}
            }
        } else {
            match b {
                b'"' if at_cell_start => {
                    open_quote = Some((current_line, column));
                    at_cell_start = false;
                }
                b',' => {
                    cells.push(cell(cell_start, i, cell_line, cell_column));
                    cell_start = i + 1;
                    (cell_line, cell_column) = (current_line, next_column);
                    at_cell_start = true;
                }
                b'\n' => {
                    cells.push(cell(cell_start, i, cell_line, cell_column));
                    let record = Record {
                        line,
                        lines: current_line - line + 1,
                        bare_cr,
                        text: record_text(text, i),
                        cells,
                    };
                    return Ok((record, text.get(i + 1..).unwrap_or("")));
                }
                // A CR that ends the text is a CRLF file cut before its last LF.
                b'\r' if !matches!(bytes.get(i + 1), Some(&b'\n') | None) => {
                    bare_cr.get_or_insert((current_line, column));
                }
                b' ' | b'\t' | b'\r' => {}
                _ => at_cell_start = false,
            }
        }
        i += 1;
    }
    if let Some((l, c)) = open_quote {
        return Err(UnclosedQuote(l, c));
    }
    cells.push(cell(cell_start, text.len(), cell_line, cell_column));
    let record = Record {
        line,
        lines: current_line - line + 1,
        bare_cr,
        text: record_text(text, text.len()),
        cells,
    };
    Ok((record, ""))
}

/// CRs in `text` that no LF follows.
fn bare_crs(text: &str) -> usize {
    let b = text.as_bytes();
    (0..b.len())
        .filter(|&i| b[i] == b'\r' && b.get(i + 1) != Some(&b'\n'))
        .count()
}

/// `text[..end]` without a CR before the line end.
fn record_text(text: &str, end: usize) -> &str {
    let t = text.get(..end).unwrap_or("");
    t.strip_suffix('\r').unwrap_or(t)
}

/// A parsed header and the data records after it.
struct Table<'a> {
    path: &'a Path,
    header_len: usize,
    /// For each wanted column, its index among the header cells (`None`: an optional column
    /// the header lacks, read as empty).
    index: Vec<Option<usize>>,
    names: &'static [&'static str],
    /// Header cells that are not wanted columns, in file order (`""` for an unnamed one).
    extra: Vec<String>,
    /// The text after the header.
    data: &'a str,
    /// The physical line `data` starts on.
    data_line: usize,
    /// Bytes that were not UTF-8 were replaced by U+FFFD ([`read_text`]): a cell that is read
    /// and holds one is refused.
    lossy: bool,
}

impl<'a> Table<'a> {
    fn new(
        text: &'a str,
        path: &'a Path,
        wanted: &'static [&'static str],
        optional: &[&str],
        lossy: bool,
    ) -> Result<Self, LogError> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let err = |line, char_column, column: Option<String>, kind| LogError {
            path: path.to_path_buf(),
            line,
            char_column,
            column,
            kind,
        };
        let (header, data) = match next_record(text, 1) {
            Ok((h, rest)) if !h.text.trim().is_empty() => (h, rest),
            Ok(_) => return Err(err(1, 0, None, LogErrorKind::MissingHeader)),
            Err(UnclosedQuote(l, c)) => return Err(err(l, c, None, LogErrorKind::UnclosedQuote)),
        };
        if let Some((l, c)) = header.bare_cr {
            let count = bare_crs(text);
            return Err(err(l, c, None, LogErrorKind::BareCarriageReturn { count }));
        }
        let cells = &header.cells;
        for (i, c) in cells.iter().enumerate() {
            if lossy && c.text.contains(char::REPLACEMENT_CHARACTER) {
                return Err(err(c.line, c.char_column, None, LogErrorKind::NotUtf8));
            }
            // Unnamed columns (a trailing comma on every line) are extra columns: ignored,
            // however many there are. A named column twice is ambiguous.
            if !c.text.is_empty() && cells.iter().take(i).any(|p| p.text == c.text) {
                return Err(err(
                    c.line,
                    c.char_column,
                    Some(c.text.to_string()),
                    LogErrorKind::DuplicateColumn(c.text.to_string()),
                ));
            }
        }
        let named = || cells.iter().filter(|c| !c.text.is_empty());
        if named().next().is_some() && named().all(|c| c.text.parse::<f64>().is_ok()) {
            return Err(err(1, 1, None, LogErrorKind::MissingHeader));
        }
        let mut index = Vec::with_capacity(wanted.len());
        for name in wanted {
            match cells.iter().position(|c| c.text == *name) {
                Some(i) => index.push(Some(i)),
                None if optional.contains(name) => index.push(None),
                None => {
                    return Err(err(
                        1,
                        0,
                        Some((*name).to_string()),
                        LogErrorKind::MissingColumn {
                            column: name,
                            header: header.text.to_string(),
                        },
                    ))
                }
            }
        }
        let extra = cells
            .iter()
            .filter(|c| !wanted.contains(&c.text))
            .map(|c| c.text.to_string())
            .collect();
        Ok(Table {
            path,
            header_len: cells.len(),
            index,
            names: wanted,
            extra,
            data,
            data_line: header.line + header.lines,
            lossy,
        })
    }

    /// The header's extra columns (`""` for an unnamed one).
    fn extra_columns(&self) -> Vec<String> {
        self.extra.clone()
    }

    /// The data records, one [`Line`] each; the first error ends them.
    fn lines(&self) -> Lines<'_> {
        Lines {
            table: self,
            rest: self.data,
            line: self.data_line,
        }
    }
}

/// The data records of a [`Table`].
struct Lines<'t> {
    table: &'t Table<'t>,
    rest: &'t str,
    /// The physical line `rest` starts on.
    line: usize,
}

impl<'t> Iterator for Lines<'t> {
    type Item = Result<Line<'t>, LogError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.rest.is_empty() {
            return None;
        }
        let fail = |line, char_column, kind| LogError {
            path: self.table.path.to_path_buf(),
            line,
            char_column,
            column: None,
            kind,
        };
        let (record, rest) = match next_record(self.rest, self.line) {
            Ok(r) => r,
            Err(UnclosedQuote(l, c)) => {
                self.rest = "";
                return Some(Err(fail(l, c, LogErrorKind::UnclosedQuote)));
            }
        };
        if let Some((l, c)) = record.bare_cr {
            let count = bare_crs(self.rest);
            self.rest = "";
            return Some(Err(fail(l, c, LogErrorKind::BareCarriageReturn { count })));
        }
        if record.text.trim().is_empty() {
            // Trailing blank lines are the end of the file, not missing rows.
            if rest.trim().is_empty() {
                self.rest = "";
                return None;
            }
            self.rest = "";
            return Some(Err(fail(record.line, 0, LogErrorKind::BlankLine)));
        }
        self.rest = rest;
        self.line = record.line + record.lines;
        if record.cells.len() != self.table.header_len {
            self.rest = "";
            return Some(Err(fail(
                record.line,
                0,
                LogErrorKind::FieldCount {
                    expected: self.table.header_len,
                    found: record.cells.len(),
                },
            )));
        }
        Some(Ok(Line {
            table: self.table,
            number: record.line,
            cells: record.cells,
        }))
    }
}

/// One data record, split into cells.
struct Line<'a> {
    table: &'a Table<'a>,
    /// The physical line it starts on.
    number: usize,
    cells: Vec<Cell<'a>>,
}

impl Line<'_> {
    /// (physical line, character column) of wanted column `i`'s cell; (the record's first
    /// line, 0) if the column is absent.
    fn position(&self, i: usize) -> (usize, usize) {
        self.table
            .index
            .get(i)
            .copied()
            .flatten()
            .and_then(|h| self.cells.get(h))
            .map_or((self.number, 0), |c| (c.line, c.char_column))
    }

    /// Error at wanted column `i`.
    fn error(&self, i: usize, kind: LogErrorKind) -> LogError {
        let (line, char_column) = self.position(i);
        LogError {
            path: self.table.path.to_path_buf(),
            line,
            char_column,
            column: self.table.names.get(i).map(|s| s.to_string()),
            kind,
        }
    }

    /// Value of wanted column `i`: `None` for an empty cell. Finite always; within `range`
    /// when one is given.
    fn value(
        &self,
        i: usize,
        range: Option<&'static ColumnRange>,
    ) -> Result<Option<f64>, LogError> {
        let cell = self.table.index.get(i).copied().flatten();
        let text = match cell.and_then(|h| self.cells.get(h)) {
            Some(c) => c.text,
            None => "",
        };
        if text.is_empty() {
            return Ok(None);
        }
        if self.table.lossy && text.contains(char::REPLACEMENT_CHARACTER) {
            return Err(self.error(i, LogErrorKind::NotUtf8));
        }
        let v: f64 = text
            .parse()
            .map_err(|_| self.error(i, LogErrorKind::NotANumber(text.to_string())))?;
        if !v.is_finite() {
            return Err(self.error(i, LogErrorKind::NonFinite(text.to_string())));
        }
        if let Some(range) = range {
            if v < range.min || v > range.max {
                return Err(self.error(i, LogErrorKind::OutOfRange { value: v, range }));
            }
        }
        Ok(Some(v))
    }
}

/// Fixes a logger repeated ([`held_fix_repeats`]): a logger that samples every column at its
/// own rate and writes the last value it has (sample and hold) repeats a slower receiver's fix
/// on every row until the next one comes.
#[derive(Debug, Clone, PartialEq)]
pub struct HeldFixes {
    /// The repeats' indices in the fixes given, increasing.
    pub repeats: Vec<usize>,
    /// The fixes given (repeats included).
    pub fixes: usize,
    /// The median interval between the fixes that change, s: the receiver's period.
    pub receiver_period_s: f64,
    /// The median interval between the rows that carry a fix, s: the logger's period.
    pub logger_period_s: f64,
}

impl HeldFixes {
    /// What was found, for a note: "N of M fixes (P %) repeat ..., a logger that holds ...".
    pub fn describe(&self) -> String {
        format!(
            "{} of {} fixes ({:.0} %) repeat the fix before them exactly, and the fixes that \
             change come every {:.1} ms ({:.1} Hz, the median), regularly: a logger that writes \
             every {:.1} ms and repeats (samples and holds) the receiver's last fix; the \
             repeats are no fixes",
            self.repeats.len(),
            self.fixes,
            100.0 * self.repeats.len() as f64 / self.fixes.max(1) as f64,
            1e3 * self.receiver_period_s,
            1.0 / self.receiver_period_s,
            1e3 * self.logger_period_s,
        )
    }
}

/// A repeated fix is a held one only when at least this share of the fixes repeat ...
const HELD_MIN_SHARE: f64 = 1.0 / 3.0;
/// ... the fixes that change come at least this many times further apart than the rows ...
const HELD_MIN_PERIOD_RATIO: f64 = 1.5;
/// ... at least this share of them within a quarter of their median interval (or one logger
/// period) of it ...
const HELD_MIN_REGULAR: f64 = 0.5;
/// ... and they step by at least this many times the resolution `lat`/`lon` are written with,
/// in the median (a track written with few decimals repeats its fixes while the car crosses a
/// cell of that grid: those repeats are the resolution's, and are kept).
const HELD_MIN_STEP_CELLS: f64 = 3.0;

/// The fixes (times `t`, s, increasing; `fixes` lat, lon, degrees) that repeat the one before
/// them exactly because a logger held them, or `None`. Held repeats are told from a receiver
/// whose fixes stand still (a car at rest, a receiver's static hold) and from a track written
/// with too few decimals by their pattern: a third of the fixes or more repeat, the fixes that
/// change come regularly (half of their intervals within a quarter of the median, or within
/// one logger period) and at least 1.5 times further apart than the rows, and they step by three
/// times the decimals' resolution or more. A black-box probe's 10 Hz receiver held at 100 Hz:
/// 90 % repeats, the changes every 100 ms; the simulator's receivers at 1-100 Hz, RTK included,
/// repeat none.
pub fn held_fix_repeats(t: &[f64], fixes: &[(f64, f64)]) -> Option<HeldFixes> {
    let n = fixes.len().min(t.len());
    if n < 20 {
        return None;
    }
    let repeats: Vec<usize> = (1..n).filter(|&i| fixes[i] == fixes[i - 1]).collect();
    if (repeats.len() as f64) < HELD_MIN_SHARE * n as f64 {
        return None;
    }
    let median = |mut v: Vec<f64>| -> Option<f64> {
        if v.is_empty() {
            return None;
        }
        let mid = v.len() / 2;
        Some(*v.select_nth_unstable_by(mid, f64::total_cmp).1)
    };
    let logger_period_s = median(t[..n].windows(2).map(|w| w[1] - w[0]).collect())?;
    let changes: Vec<usize> = (0..n)
        .filter(|&i| i == 0 || fixes[i] != fixes[i - 1])
        .collect();
    let intervals: Vec<f64> = changes.windows(2).map(|w| t[w[1]] - t[w[0]]).collect();
    if intervals.len() < 10 {
        return None;
    }
    let receiver_period_s = median(intervals.clone())?;
    if receiver_period_s.is_nan() || receiver_period_s < HELD_MIN_PERIOD_RATIO * logger_period_s {
        return None;
    }
    let tolerance = (0.25 * receiver_period_s).max(logger_period_s) * (1.0 + 1e-6);
    let regular = intervals
        .iter()
        .filter(|d| (*d - receiver_period_s).abs() <= tolerance)
        .count();
    if (regular as f64) < HELD_MIN_REGULAR * intervals.len() as f64 {
        return None;
    }
    // The decimals the fixes are written with (the coarsest grid, 1 to 1e-9 deg, they all lie
    // on), and the median step between the fixes that change against it, in degrees.
    let on_grid = |v: f64, scale: f64| ((v * scale).round() - v * scale).abs() < 1e-3;
    let cell_deg = (0..=9)
        .map(|d| 10f64.powi(-d))
        .find(|cell| {
            changes
                .iter()
                .all(|&i| on_grid(fixes[i].0, 1.0 / cell) && on_grid(fixes[i].1, 1.0 / cell))
        })
        .unwrap_or(0.0);
    let cos_lat = fixes[0].0.to_radians().cos().abs().max(1e-3);
    let step_deg = median(
        changes
            .windows(2)
            .map(|w| {
                let (a, b) = (fixes[w[0]], fixes[w[1]]);
                ((b.0 - a.0).powi(2) + ((b.1 - a.1) * cos_lat).powi(2)).sqrt()
            })
            .collect(),
    )?;
    if step_deg < HELD_MIN_STEP_CELLS * cell_deg {
        return None;
    }
    Some(HeldFixes {
        repeats,
        fixes: n,
        receiver_period_s,
        logger_period_s,
    })
}
