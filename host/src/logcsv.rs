//! The log CSV schema (DESIGN.md, "Log CSV") and the ground-truth CSV of the simulator: typed rows,
//! strict readers and writers.
//!
//! Reading: a header row is required; columns may come in any order; extra columns are ignored;
//! an empty cell means the sensor did not report at that time. Every problem is an error that
//! names the file, the line, the column (character position and name) and the reason; nothing
//! is skipped silently and nothing panics. Writing produces Rust's shortest round-trip form of
//! each number, so `read(write(rows)) == rows` bit for bit.
use std::fmt;
use std::io::Write;
use std::path::{Path, PathBuf};

/// One row of a driving log. Each sensor reports on its own clock, so most cells are empty.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LogRow {
    /// Time, s (strictly increasing down the file).
    pub t: f64,
    /// Measured speed, m/s.
    pub vel: Option<f64>,
    /// Commanded speed, m/s.
    pub input_vel: Option<f64>,
    /// Accelerator pedal, % 0..100.
    pub accel: Option<f64>,
    /// Measured steering, % -100..100, positive = right.
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
/// Columns of the truth CSV.
pub const TRUTH_COLUMNS: [&str; 6] = ["t", "x", "y", "heading", "yaw_rate", "speed"];

/// Why a file was rejected.
#[derive(Debug)]
pub enum LogErrorKind {
    /// The file could not be read or written.
    Io(std::io::Error),
    /// The bytes are not UTF-8.
    NotUtf8,
    /// The file has no header row.
    MissingHeader,
    /// A header cell is empty.
    EmptyColumnName,
    /// The header names a column twice.
    DuplicateColumn(String),
    /// A column the schema requires is absent.
    MissingColumn(&'static str),
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
    /// The value is outside its unit's range.
    OutOfRange {
        /// The value.
        value: f64,
        /// Smallest allowed.
        min: f64,
        /// Largest allowed.
        max: f64,
    },
    /// `t` is not greater than the previous row's.
    TimeNotIncreasing {
        /// This row's time, s.
        t: f64,
        /// The previous row's time, s.
        previous: f64,
    },
    /// Only one of `lat` and `lon` is present.
    HalfFix,
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
            LogErrorKind::NotUtf8 => write!(f, "not UTF-8 text"),
            LogErrorKind::MissingHeader => write!(f, "missing header row"),
            LogErrorKind::EmptyColumnName => write!(f, "empty column name in the header"),
            LogErrorKind::DuplicateColumn(c) => {
                write!(f, "column `{c}` appears twice in the header")
            }
            LogErrorKind::MissingColumn(c) => write!(f, "missing required column `{c}`"),
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
            LogErrorKind::OutOfRange { value, min, max } => {
                write!(f, "value {value} outside {min}..{max}")
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

/// Reads a driving log. All eight schema columns are required (a sensor that never reported is
/// an empty column).
pub fn read_log(path: &Path) -> Result<Vec<LogRow>, LogError> {
    let text = read_text(path)?;
    parse_log(&text, path)
}

/// Parses log text; `path` only names the source in errors.
pub fn parse_log(text: &str, path: &Path) -> Result<Vec<LogRow>, LogError> {
    let table = Table::new(text, path, &LOG_COLUMNS)?;
    let ranges: [(f64, f64); 8] = [
        (f64::NEG_INFINITY, f64::INFINITY),
        (f64::NEG_INFINITY, f64::INFINITY),
        (f64::NEG_INFINITY, f64::INFINITY),
        (0.0, 100.0),
        (-100.0, 100.0),
        (0.0, 100.0),
        (-90.0, 90.0),
        (-180.0, 180.0),
    ];
    let mut rows = Vec::new();
    let mut previous: Option<f64> = None;
    for line in table.lines() {
        let line = line?;
        let mut values = [None; 8];
        for (i, v) in values.iter_mut().enumerate() {
            *v = line.value(i, ranges[i])?;
        }
        let t = match values[0] {
            Some(t) => t,
            None => return Err(line.error(0, LogErrorKind::MissingValue)),
        };
        check_time(&line, t, &mut previous)?;
        if values[6].is_some() != values[7].is_some() {
            let missing = if values[6].is_some() { 7 } else { 6 };
            return Err(line.error(missing, LogErrorKind::HalfFix));
        }
        rows.push(LogRow {
            t,
            vel: values[1],
            input_vel: values[2],
            accel: values[3],
            steer: values[4],
            brake: values[5],
            lat: values[6],
            lon: values[7],
        });
    }
    Ok(rows)
}

/// Reads a truth CSV (every cell required).
pub fn read_truth(path: &Path) -> Result<Vec<TruthRow>, LogError> {
    let text = read_text(path)?;
    parse_truth(&text, path)
}

/// Parses truth text; `path` only names the source in errors.
pub fn parse_truth(text: &str, path: &Path) -> Result<Vec<TruthRow>, LogError> {
    let table = Table::new(text, path, &TRUTH_COLUMNS)?;
    let mut rows = Vec::new();
    let mut previous: Option<f64> = None;
    let any = (f64::NEG_INFINITY, f64::INFINITY);
    for line in table.lines() {
        let line = line?;
        let mut v = [0.0; 6];
        for (i, out) in v.iter_mut().enumerate() {
            *out = match line.value(i, any)? {
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
    let mut buf = Vec::new();
    write_log_to(&mut buf, rows).map_err(|(line, column, kind)| LogError {
        path: path.to_path_buf(),
        line,
        char_column: 0,
        column: column.map(str::to_string),
        kind,
    })?;
    std::fs::write(path, buf).map_err(|e| file_error(path, LogErrorKind::Io(e)))
}

/// Writes a driving log to any writer. Errors carry (line, column, reason).
pub fn write_log_to<W: Write>(
    w: &mut W,
    rows: &[LogRow],
) -> Result<(), (usize, Option<&'static str>, LogErrorKind)> {
    let io = |e| (0, None, LogErrorKind::Io(e));
    writeln!(w, "{}", LOG_COLUMNS.join(",")).map_err(io)?;
    let mut previous: Option<f64> = None;
    let mut line_text = String::new();
    for (i, r) in rows.iter().enumerate() {
        let line = i + 2;
        let cells = [
            Some(r.t),
            r.vel,
            r.input_vel,
            r.accel,
            r.steer,
            r.brake,
            r.lat,
            r.lon,
        ];
        check_write(line, &cells, &LOG_COLUMNS, &mut previous)?;
        format_cells(&mut line_text, &cells);
        w.write_all(line_text.as_bytes()).map_err(io)?;
    }
    Ok(())
}

/// Writes a truth CSV.
pub fn write_truth(path: &Path, rows: &[TruthRow]) -> Result<(), LogError> {
    let mut buf = Vec::new();
    write_truth_to(&mut buf, rows).map_err(|(line, column, kind)| LogError {
        path: path.to_path_buf(),
        line,
        char_column: 0,
        column: column.map(str::to_string),
        kind,
    })?;
    std::fs::write(path, buf).map_err(|e| file_error(path, LogErrorKind::Io(e)))
}

/// Writes a truth CSV to any writer. Errors carry (line, column, reason).
pub fn write_truth_to<W: Write>(
    w: &mut W,
    rows: &[TruthRow],
) -> Result<(), (usize, Option<&'static str>, LogErrorKind)> {
    let io = |e| (0, None, LogErrorKind::Io(e));
    writeln!(w, "{}", TRUTH_COLUMNS.join(",")).map_err(io)?;
    let mut previous: Option<f64> = None;
    let mut line_text = String::new();
    for (i, r) in rows.iter().enumerate() {
        let cells = [
            Some(r.t),
            Some(r.x),
            Some(r.y),
            Some(r.heading),
            Some(r.yaw_rate),
            Some(r.speed),
        ];
        check_write(i + 2, &cells, &TRUTH_COLUMNS, &mut previous)?;
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
) -> Result<(), (usize, Option<&'static str>, LogErrorKind)> {
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

fn read_text(path: &Path) -> Result<String, LogError> {
    let bytes = std::fs::read(path).map_err(|e| file_error(path, LogErrorKind::Io(e)))?;
    match String::from_utf8(bytes) {
        Ok(s) => Ok(s),
        Err(e) => {
            let good = e
                .as_bytes()
                .get(..e.utf8_error().valid_up_to())
                .unwrap_or(&[]);
            let line = 1 + good.iter().filter(|&&b| b == b'\n').count();
            Err(LogError {
                path: path.to_path_buf(),
                line,
                char_column: 0,
                column: None,
                kind: LogErrorKind::NotUtf8,
            })
        }
    }
}

fn check_time(line: &Line<'_>, t: f64, previous: &mut Option<f64>) -> Result<(), LogError> {
    if let Some(p) = *previous {
        if t <= p {
            return Err(line.error(0, LogErrorKind::TimeNotIncreasing { t, previous: p }));
        }
    }
    *previous = Some(t);
    Ok(())
}

/// A cell: its text (trimmed, outer quotes removed) and 1-based character position.
struct Cell<'a> {
    text: &'a str,
    char_column: usize,
}

fn split_cells(line: &str) -> Vec<Cell<'_>> {
    let mut cells = Vec::new();
    let mut start_byte = 0;
    let mut start_char = 1;
    for (char_index, (byte, ch)) in line
        .char_indices()
        .chain(std::iter::once((line.len(), ',')))
        .enumerate()
    {
        if ch == ',' {
            let raw = line.get(start_byte..byte).unwrap_or("");
            let trimmed = raw.trim();
            let text = trimmed
                .strip_prefix('"')
                .and_then(|s| s.strip_suffix('"'))
                .unwrap_or(trimmed)
                .trim();
            cells.push(Cell {
                text,
                char_column: start_char,
            });
            start_byte = byte + 1;
            start_char = char_index + 2;
        }
    }
    cells
}

/// A parsed header and the data lines after it.
struct Table<'a> {
    path: &'a Path,
    header_len: usize,
    /// For each wanted column, its index among the header cells.
    index: Vec<usize>,
    names: &'static [&'static str],
    /// (1-based line number, text) of every line after the header.
    data: Vec<(usize, &'a str)>,
}

impl<'a> Table<'a> {
    fn new(
        text: &'a str,
        path: &'a Path,
        wanted: &'static [&'static str],
    ) -> Result<Self, LogError> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let mut lines = text
            .lines()
            .enumerate()
            .map(|(i, l)| (i + 1, l.strip_suffix('\r').unwrap_or(l)));
        let err = |line, char_column, column: Option<String>, kind| LogError {
            path: path.to_path_buf(),
            line,
            char_column,
            column,
            kind,
        };
        let (_, header) = match lines.next() {
            Some((n, h)) if !h.trim().is_empty() => (n, h),
            _ => return Err(err(1, 0, None, LogErrorKind::MissingHeader)),
        };
        let cells = split_cells(header);
        for (i, c) in cells.iter().enumerate() {
            if c.text.is_empty() {
                return Err(err(1, c.char_column, None, LogErrorKind::EmptyColumnName));
            }
            if cells.iter().take(i).any(|p| p.text == c.text) {
                return Err(err(
                    1,
                    c.char_column,
                    Some(c.text.to_string()),
                    LogErrorKind::DuplicateColumn(c.text.to_string()),
                ));
            }
        }
        if cells.iter().all(|c| c.text.parse::<f64>().is_ok()) {
            return Err(err(1, 1, None, LogErrorKind::MissingHeader));
        }
        let mut index = Vec::with_capacity(wanted.len());
        for name in wanted {
            match cells.iter().position(|c| c.text == *name) {
                Some(i) => index.push(i),
                None => {
                    return Err(err(
                        1,
                        0,
                        Some((*name).to_string()),
                        LogErrorKind::MissingColumn(name),
                    ))
                }
            }
        }
        let mut data: Vec<(usize, &str)> = lines.collect();
        // Trailing blank lines are the end of the file, not missing rows.
        while data.last().is_some_and(|(_, l)| l.trim().is_empty()) {
            data.pop();
        }
        Ok(Table {
            path,
            header_len: cells.len(),
            index,
            names: wanted,
            data,
        })
    }

    fn lines(&self) -> impl Iterator<Item = Result<Line<'_>, LogError>> + '_ {
        self.data.iter().map(move |&(number, text)| {
            let fail = |kind| LogError {
                path: self.path.to_path_buf(),
                line: number,
                char_column: 0,
                column: None,
                kind,
            };
            if text.trim().is_empty() {
                return Err(fail(LogErrorKind::BlankLine));
            }
            let cells = split_cells(text);
            if cells.len() != self.header_len {
                return Err(fail(LogErrorKind::FieldCount {
                    expected: self.header_len,
                    found: cells.len(),
                }));
            }
            Ok(Line {
                table: self,
                number,
                cells,
            })
        })
    }
}

/// One data line, split into cells.
struct Line<'a> {
    table: &'a Table<'a>,
    number: usize,
    cells: Vec<Cell<'a>>,
}

impl Line<'_> {
    /// Error at wanted column `i`.
    fn error(&self, i: usize, kind: LogErrorKind) -> LogError {
        let cell = self.table.index.get(i).and_then(|&h| self.cells.get(h));
        LogError {
            path: self.table.path.to_path_buf(),
            line: self.number,
            char_column: cell.map_or(0, |c| c.char_column),
            column: self.table.names.get(i).map(|s| s.to_string()),
            kind,
        }
    }

    /// Value of wanted column `i`: `None` for an empty cell.
    fn value(&self, i: usize, (min, max): (f64, f64)) -> Result<Option<f64>, LogError> {
        let text = match self.table.index.get(i).and_then(|&h| self.cells.get(h)) {
            Some(c) => c.text,
            None => "",
        };
        if text.is_empty() {
            return Ok(None);
        }
        let v: f64 = text
            .parse()
            .map_err(|_| self.error(i, LogErrorKind::NotANumber(text.to_string())))?;
        if !v.is_finite() {
            return Err(self.error(i, LogErrorKind::NonFinite(text.to_string())));
        }
        if v < min || v > max {
            return Err(self.error(i, LogErrorKind::OutOfRange { value: v, min, max }));
        }
        Ok(Some(v))
    }
}
