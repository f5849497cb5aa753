//! `catmodel replay`: the very same [`Node`] as the firmware, stepped every 20 ms of log time
//! over a candump file, with the tick schedule of docs/architecture.md (so that its frames are
//! byte-identical to the QEMU run's `target/qemu/tx.log`). Its frames go through the firmware's
//! receive path, as `sil`'s do ([`crate::sil::RxQueue`]): the acceptance filter
//! ([`catmodel::can::spec::is_node_input`]), the 64-frame receive queue, which drops a frame
//! given to it full and counts it (NODE_STATUS `rx_queue_drops`), and at most
//! [`MAX_RX_FRAMES_PER_TICK`] frames a tick, the rest left queued. (It used to hold every frame
//! back, never dropping one: a bus with other receivers' fixes, which the filter admits, grew a
//! backlog without end, every input went stale, and the log ran longer than it lasted, where
//! the firmware drops and keeps up: a black-box probe's drive replayed with no position at
//! any tick, where `sil` scored 1.36 m.)
//!
//! The text around the node is written for speed (the issue's "replay >= 100x faster than
//! NumPy/SciPy"): the log is read at once and parsed line by line in place, the CSV and the
//! candump TX text are written into one growing buffer by hand-written formatters that give
//! exactly the text of `format!`'s `{:.N}` (round half to even on the exact binary value; tested
//! against `format!` below), and the TX text is built only when asked for.
use std::io::{Read, Write};
use std::path::Path;

use anyhow::{bail, Context, Result};
use catmodel::can::candump;
use catmodel::can::codec::{
    Direction, GnssPosition, ModelMode, Prediction, SpeedReport, StateMotion, StatePosition,
};
use catmodel::can::freshness::{FreshnessConfig, Input};
use catmodel::can::spec::{node_input_index, NODE_INPUTS};
use catmodel::can::{CanFrame, CanId, TimedFrame};
use catmodel::node::steering::SteeringCheck;
use catmodel::node::{
    first_tick_us, Counters, NodeConfig, PlatformStats, Tick, TxFrames, MAX_RX_FRAMES_PER_TICK,
};
use catmodel::SAMPLE_PERIOD_US;

use crate::planner_refusals::PlannerRefusals;

/// Interface name written into candump output.
pub const IFACE: &str = "can0";

/// A candump log as read: its frames, and the lines of frames the node has no use for
/// (remote, CAN FD, error frames: [`candump::CandumpError::is_unsupported_frame`]), skipped
/// and counted as the firmware's receive path does.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CandumpLog {
    /// The frames, in file order.
    pub frames: Vec<TimedFrame>,
    /// Remote, CAN FD and error frames skipped.
    pub unsupported: u64,
    /// What the reader noticed without refusing the log.
    pub report: LogReport,
}

/// What reading a candump log noticed without refusing it: the user must see it
/// ([`LogReport::notes`], [`LogReport::warnings`]).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct LogReport {
    /// The interfaces of the log's frame lines, in order of first appearance, with their
    /// number of lines.
    pub interfaces: Vec<(String, u64)>,
    /// The interface kept (`--interface`), if one was asked for.
    pub kept: Option<String>,
    /// Frame lines of the other interfaces, skipped because of `--interface`.
    pub other_interfaces: u64,
    /// `candump -d` lines (`DROPCOUNT: dropped N CAN frames ...`): how many, the first's line
    /// number, and the frames they say the recording lost.
    pub drop_lines: u64,
    pub first_drop_line: Option<usize>,
    pub dropped_frames: u64,
    /// The last line, cut short without a line end (the recorder lost power): its number;
    /// the line was left out.
    pub truncated_last_line: Option<usize>,
    /// How the frames' timestamps were taken ([`TimestampStats`]): batched by the recorder?
    pub timestamps: TimestampStats,
    /// Frames written with can-utils' raw DLC suffix (`123#1122334455667788_9`: a classic
    /// frame of 8 data bytes whose DLC field said 9..15), read as the 8 bytes they carry; the
    /// first one's line.
    pub raw_dlc_frames: u64,
    pub first_raw_dlc_line: Option<usize>,
    /// Frame lines identical to the frame line before them (timestamp, interface, identifier,
    /// length and data), left out: a logger that wrote frames twice. The first one's line.
    pub duplicate_lines: u64,
    pub first_duplicate_line: Option<usize>,
    /// The node's input messages as the log carries them ([`InputCensus`]).
    pub inputs: InputCensus,
    /// Pauses of the log longer than [`PAUSE_NOTE_US`] (no frame at all): how many, and the
    /// longest's line (the frame after it) and its start and end, us.
    pub pauses: u64,
    pub longest_pause: Option<(usize, u64, u64)>,
    /// Frames of one interface stamped before a frame of another written above them, by up to
    /// [`CROSS_INTERFACE_REORDER_US`] (`candump -l can0 can1` reads its sockets in turn): put
    /// in time order. How many, the first one's line, the largest step back, us.
    pub reordered: u64,
    pub first_reordered_line: Option<usize>,
    pub largest_reorder_us: u64,
    /// Frames that repeat a frame of another interface (the same identifier, length and data)
    /// within [`MIRROR_WINDOW_US`] after it: one bus logged on two interfaces (a gateway that
    /// mirrors it). Their count, the interfaces (index of the first's, the copy's) of the
    /// first, and each copy's delay, us.
    pub mirrored: u64,
    pub mirror_pair: Option<(usize, usize)>,
    pub mirror_delays_us: Vec<u64>,
}

/// Frames of two interfaces may come out of time order by this much, us: `candump` of several
/// interfaces reads its sockets in turn, so a frame of `can1` can be written after a later
/// frame of `can0` (a black-box probe's log: 428 us). Within one interface the time must not go
/// back at all; across interfaces up to one node tick (20 ms) is a reader's order and the
/// frames are put in time order; more is another clock.
pub const CROSS_INTERFACE_REORDER_US: u64 = 20_000;

/// A frame that repeats a frame of another interface within this time is its copy, us: a
/// gateway or bridge forwards a frame within a few hundred microseconds (a black-box probe's:
/// 200 us), and no two interfaces carry the same frame, rolling counter and CRC included, by
/// chance within 10 ms.
pub const MIRROR_WINDOW_US: u64 = 10_000;

/// A log with no frame for longer than this has paused, us: every input of the node is
/// silent (a recorder pause, a gateway reset, a stalled bridge), which the node ticks through
/// with its inputs timing out (docs/faults.md); `replay` names it.
pub const PAUSE_NOTE_US: u64 = 1_000_000;

/// How the log carries each of the node's input messages ([`NODE_INPUTS`], by index):
/// frames the node can read, and CAN FD frames of the message's identifier (skipped: the node
/// reads classic CAN only).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct InputCensus {
    /// Classic frames of the message's identifier.
    pub classic: [u64; 10],
    /// CAN FD frames of it (`ID##...`).
    pub fd: [u64; 10],
    /// Frames with a 29-bit identifier whose value is the message's 11-bit one (`00000100#...`
    /// for 0x100): a recorder or converter that wrote every identifier with 8 digits. The
    /// node does not take them (an 11-bit and a 29-bit identifier are different frames on
    /// the bus).
    pub as_extended: [u64; 10],
}

impl InputCensus {
    /// The warnings: messages that came as CAN FD frames (with none as classic CAN, the node
    /// never had the message).
    pub fn warnings(&self, path: &Path) -> Vec<String> {
        let mut out = Vec::new();
        for (i, spec) in NODE_INPUTS.iter().enumerate() {
            let (fd, classic) = (self.fd[i], self.classic[i]);
            let name = spec.name;
            let id = id_text(spec.id);
            if let (CanId::Standard(raw), n @ 1..) = (spec.id, self.as_extended[i]) {
                out.push(format!(
                    "{}: {n} frames with the 29-bit identifier 0x{raw:08X} carry the number of \
                     {name} ({id}, an 11-bit identifier in catmodel.dbc){}: the node does not \
                     take a 29-bit frame for an 11-bit one; if the recorder or a converter wrote \
                     every identifier with 8 hex digits, write the 11-bit ones with 3 \
                     (`{raw:03X}#...`)",
                    path.display(),
                    if classic == 0 {
                        format!(
                            ", and no {name} came with the 11-bit one, so the node ran without it"
                        )
                    } else {
                        format!(" (beside {classic} with the 11-bit one)")
                    }
                ));
            }
            if fd == 0 {
                continue;
            }
            out.push(if classic == 0 {
                format!(
                    "{}: no {name} ({id}) arrived as classic CAN: its {fd} frames came as CAN FD \
                     frames (`##` in the log format, a two-digit `[LEN]` in the screen format), which the node does not read (it reads classic \
                     CAN only; they were skipped), so it ran without {name}",
                    path.display()
                )
            } else {
                format!(
                    "{}: {fd} {name} frames ({id}) came as CAN FD frames (`##` in the log format, a two-digit `[LEN]` in the screen format), \
                     beside {classic} as classic CAN: the node reads classic CAN only, and the \
                     CAN FD ones were skipped",
                    path.display()
                )
            });
        }
        out
    }
}

/// An identifier as candump writes it, with `0x`: 3 hex digits standard, 8 extended.
pub fn id_text(id: CanId) -> String {
    match id {
        CanId::Standard(raw) => format!("0x{raw:03X}"),
        CanId::Extended(raw) => format!("0x{raw:08X}"),
    }
}

/// The identifier of a CAN FD frame line (`(TS) IFACE ID##F...`, or the screen format's
/// `(TS)  IFACE  ID  [LEN] ...`, `-x`'s direction and flags before the identifier), which the
/// core's parser refuses without it.
fn fd_frame_id(line: &str) -> Option<CanId> {
    let (_, rest) = line.trim_start().strip_prefix('(')?.split_once(')')?;
    let mut tokens = rest.split_ascii_whitespace();
    tokens.next()?;
    let mut token = tokens.next()?;
    let id = match token.split_once("##") {
        Some((id, _)) => id,
        None => {
            if matches!(token, "RX" | "TX") {
                tokens.next()?;
                tokens.next()?;
                token = tokens.next()?;
            }
            token
        }
    };
    let raw = u32::from_str_radix(id, 16).ok()?;
    match id.len() {
        3 if raw <= 0x7FF => Some(CanId::Standard(raw as u16)),
        8 if raw <= 0x1FFF_FFFF => Some(CanId::Extended(raw)),
        _ => None,
    }
}

/// A step between two distinct timestamps this long or longer spans two of the node's 20 ms
/// ticks or more, us.
pub const BATCH_STEP_US: u64 = 2 * SAMPLE_PERIOD_US;

/// Distinct timestamps needed before a log's timestamps are judged: a second of 20 ms batches.
const MIN_INSTANTS_JUDGED: u64 = 50;

/// How a log's timestamps were taken, counted frame by frame ([`TimestampTracker`]). A bus
/// recorder stamps each frame as it arrives: distinct timestamps milliseconds apart, and never
/// one message twice in one microsecond (a CAN frame takes over 100 us on the wire). A recorder
/// that reads its queue in batches and stamps each batch (review finding 03) gives many frames
/// one timestamp, several of one message among them, and steps of 40-60 ms between the
/// timestamps. The node runs on the timestamps as given (the firmware would too), and the
/// batching moved its filtered position 9 m RMS off on the 5-minute drive.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TimestampStats {
    /// Frames counted.
    pub frames: u64,
    /// Distinct timestamps (a frame stamped later than the one before starts one).
    pub instants: u64,
    /// Steps between consecutive distinct timestamps of [`BATCH_STEP_US`] or more.
    pub coarse_steps: u64,
    /// Frames whose identifier already came at the same timestamp.
    pub repeats: u64,
    /// The first and last timestamps, us.
    pub first_us: u64,
    pub last_us: u64,
}

impl TimestampStats {
    /// The timestamps come in batches coarser than the node's tick: enough of them to judge,
    /// most steps between them two ticks or longer, and messages repeating within one
    /// timestamp (at least one such frame every other timestamp): a slow bus alone (a 10 Hz
    /// log) has the long steps but no repeats.
    pub fn batched(&self) -> bool {
        self.instants >= MIN_INSTANTS_JUDGED
            && 2 * self.coarse_steps >= self.instants - 1
            && 2 * self.repeats >= self.instants
    }

    /// The warning for batched timestamps, naming `source`; `None` if they are not.
    pub fn warning(&self, source: &str) -> Option<String> {
        if !self.batched() {
            return None;
        }
        let mean_step_ms =
            (self.last_us - self.first_us) as f64 * 1e-3 / (self.instants - 1).max(1) as f64;
        Some(format!(
            "{source}: the timestamps come in batches coarser than the node's 20 ms tick: {} \
             frames on {} distinct timestamps ({:.1} a timestamp, {:.0} ms apart on average; \
             {:.0} % of the steps {} ms or longer), and {} frames repeat a message already \
             stamped in the same microsecond, which no bus carries: the recorder stamped the \
             frames when it read them in batches, not when they arrived. The node runs on the \
             timestamps as given (the firmware does the same), so it sees each sensor's reports \
             bunched at one instant and none in the ticks between: its GNSS filter takes the \
             fixes late and in jumps and its gate refuses many, and the filtered position can \
             be metres off (9 m RMS on the simulator's 5-minute drive batched to 50 ms, raw \
             GNSS 1.9 m). Record with a timestamp per frame as received (candump -l)",
            self.frames,
            self.instants,
            self.frames as f64 / self.instants as f64,
            mean_step_ms,
            100.0 * self.coarse_steps as f64 / (self.instants - 1).max(1) as f64,
            BATCH_STEP_US / 1000,
            self.repeats,
        ))
    }
}

/// Counts [`TimestampStats`] over frames in log order: the identifiers seen at the current
/// timestamp (a few dozen at most are kept: enough to see a batch's repeats).
#[derive(Debug, Clone, Default)]
pub struct TimestampTracker {
    last_us: Option<u64>,
    ids: Vec<CanId>,
}

/// Identifiers kept per timestamp by [`TimestampTracker`].
const TRACKED_IDS: usize = 32;

impl TimestampTracker {
    /// A frame of identifier `id` stamped `t_us`, counted into `stats`.
    #[inline]
    pub fn observe(&mut self, stats: &mut TimestampStats, t_us: u64, id: CanId) {
        stats.frames += 1;
        match self.last_us {
            Some(last) if last == t_us => {
                if self.ids.contains(&id) {
                    stats.repeats += 1;
                } else if self.ids.len() < TRACKED_IDS {
                    self.ids.push(id);
                }
                return;
            }
            Some(last) => {
                if t_us > last && t_us - last >= BATCH_STEP_US {
                    stats.coarse_steps += 1;
                }
            }
            None => stats.first_us = t_us,
        }
        stats.instants += 1;
        stats.last_us = stats.last_us.max(t_us);
        self.last_us = Some(t_us);
        self.ids.clear();
        self.ids.push(id);
    }
}

impl LogReport {
    /// Notes: what the log holds that the user may not expect (frames of several interfaces).
    pub fn notes(&self, path: &Path) -> Vec<String> {
        self.notes_at(path, AtPause::Ticked)
    }

    /// [`LogReport::notes`], the pause's note saying what the command did at it.
    pub fn notes_at(&self, path: &Path, at: AtPause) -> Vec<String> {
        let mut out = Vec::new();
        if let Some((line, from_us, to_us)) = self.longest_pause {
            let s = |us: u64| us as f64 * 1e-6;
            let done = match at {
                AtPause::Ticked => {
                    "the node ticked through it, its inputs timing out, the position lost \
                     after gnss_lost_s and the heading taken again once its error bound \
                     reached a radian (docs/faults.md)"
                }
                AtPause::Split(what) => what,
            };
            out.push(format!(
                "{}:{line}: the log pauses {} time(s) with no frame for more than {} s, the \
                 longest {:.1} s (from t = {:.3} to {:.3} s): every input was silent (a \
                 recorder pause, a gateway reset?); {done}",
                path.display(),
                self.pauses,
                PAUSE_NOTE_US / 1_000_000,
                s(to_us - from_us),
                s(from_us),
                s(to_us)
            ));
        }
        if let Some(line) = self.first_raw_dlc_line {
            out.push(format!(
                "{}:{line}: {} frame(s) carry can-utils' raw DLC suffix (`#<8 bytes>_9` .. \
                 `_F`: a classic frame of 8 data bytes whose DLC field said 9..15, which ISO \
                 11898-1 reads as 8): read as the 8 bytes they carry",
                path.display(),
                self.raw_dlc_frames
            ));
        }
        if let Some(line) = self.first_reordered_line {
            out.push(format!(
                "{}:{line}: {} frame(s) were written after a later frame of another interface, \
                 up to {:.3} ms (candump reads its sockets in turn; within one interface the \
                 time never goes back): put in time order",
                path.display(),
                self.reordered,
                self.largest_reorder_us as f64 * 1e-3
            ));
        }
        if self.interfaces.len() < 2 {
            return out;
        }
        let list = self
            .interfaces
            .iter()
            .map(|(name, n)| format!("`{name}` ({n} lines)"))
            .collect::<Vec<_>>()
            .join(", ");
        out.push(match &self.kept {
            Some(kept) => format!(
                "{}: frames of {} interfaces, {list}: only `{kept}`'s are read ({} lines of the others skipped)",
                path.display(),
                self.interfaces.len(),
                self.other_interfaces
            ),
            None => format!(
                "{}: frames of {} interfaces, {list}: all are read as one bus; `--interface NAME` keeps one",
                path.display(),
                self.interfaces.len()
            ),
        });
        out
    }

    /// Warnings: the recording lost frames, its last line was cut short, or its timestamps
    /// come in batches ([`TimestampStats::warning`]).
    pub fn warnings(&self, path: &Path) -> Vec<String> {
        let mut out = Vec::new();
        if let Some(w) = self.timestamps.warning(&path.display().to_string()) {
            out.push(w);
        }
        out.extend(self.inputs.warnings(path));
        if self.mirrored > 0 && self.kept.is_none() {
            if let Some((from, to)) = self.mirror_pair {
                let name = |i: usize| self.interfaces.get(i).map_or("?", |(n, _)| n.as_str());
                out.push(format!(
                    "{}: {} frame(s) of `{}` repeat a frame of `{}` within {} ms (a gateway that \
                     forwards some messages?): the node receives those twice",
                    path.display(),
                    self.mirrored,
                    name(to),
                    name(from),
                    MIRROR_WINDOW_US / 1000
                ));
            }
        }
        if let Some(line) = self.first_drop_line {
            out.push(format!(
                "{}:{line}: the recording lost {} frame(s): candump -d reported drops on {} line(s) (`DROPCOUNT: ...`, skipped); the node saw gaps there",
                path.display(),
                self.dropped_frames,
                self.drop_lines
            ));
        }
        if let Some(line) = self.first_duplicate_line {
            let every = if self.duplicate_lines == self.timestamps.frames {
                ", every frame of the log twice"
            } else {
                ""
            };
            out.push(format!(
                "{}:{line}: {} frame line(s) repeat the line before them exactly (the same \
                 timestamp to the microsecond, interface, identifier and data){every}: a logger \
                 that wrote frames twice. No bus carries one frame twice in one microsecond (a \
                 frame takes over 100 us on the wire), and a report the bus did carry twice \
                 comes with another rolling counter, which the node checks: each repeat was left \
                 out, its frame read once",
                path.display(),
                self.duplicate_lines
            ));
        }
        if let Some(line) = self.truncated_last_line {
            out.push(format!(
                "{}:{line}: the last line is cut short and has no line end (the recorder stopped mid-line): left out",
                path.display()
            ));
        }
        out
    }
}

/// What a command does where a log pauses, for the reader's note: the node ticks through it
/// (`replay`), or the command measures the stretches on either side apart, never across it
/// (what it says: `receiver-error`, `identify-steering`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AtPause {
    Ticked,
    Split(&'static str),
}

/// [`read_candump_log_on`] for the CLI: prints the report's notes and warnings on stderr
/// (`catmodel: note: ...`, `catmodel: warning: ...`).
pub fn read_candump_reporting(path: &Path, interface: Option<&str>) -> Result<CandumpLog> {
    read_candump_reporting_at(path, interface, AtPause::Ticked)
}

/// [`read_candump_reporting`] for a command that does `at` where the log pauses.
pub fn read_candump_reporting_at(
    path: &Path,
    interface: Option<&str>,
    at: AtPause,
) -> Result<CandumpLog> {
    let log = read_candump_log_on(path, interface)?;
    print_report_at(path, &log.report, at);
    Ok(log)
}

/// Prints a [`LogReport`]'s notes and warnings on stderr.
pub fn print_report(path: &Path, report: &LogReport) {
    print_report_at(path, report, AtPause::Ticked);
}

/// [`print_report`] for a command that does `at` where the log pauses.
pub fn print_report_at(path: &Path, report: &LogReport, at: AtPause) {
    for note in report.notes_at(path, at) {
        eprintln!("catmodel: note: {note}");
    }
    for warning in report.warnings(path) {
        eprintln!("catmodel: warning: {warning}");
    }
}

/// The longest pause between two frames of one log: a day. Ticks run through a pause (the
/// node sees its inputs time out and recovers, docs/faults.md), 4.3 M of them for a day,
/// about 2 s of replay; a longer jump is a clock step or logs joined, and would tick for hours
/// (a jump of 1.7e9 s: 9 hours at 2.6 M ticks/s), so it is refused with its line.
pub const MAX_LOG_PAUSE_US: u64 = 86_400 * 1_000_000;

/// Reads a candump log ([`read_candump_log`] without the count of skipped frames).
pub fn read_candump(path: &Path) -> Result<Vec<TimedFrame>> {
    read_candump_log(path).map(|log| log.frames)
}

/// Reads a candump log. Errors name the file, the line and the reason; time going backwards
/// is an error with the line.
pub fn read_candump_log(path: &Path) -> Result<CandumpLog> {
    read_candump_log_on(path, None)
}

/// [`read_candump_log`] keeping only the frames of `interface` (all if `None`); an interface
/// with no frame in the log is an error naming the log's interfaces.
pub fn read_candump_log_on(path: &Path, interface: Option<&str>) -> Result<CandumpLog> {
    let bytes = read_bytes(path)?;
    parse_candump_bytes(path, &bytes, interface)
}

/// [`read_candump_log_on`] keeping only the frames `select` takes, read a line at a time: the
/// memory is the frames kept, not the file. Every line is still checked and counted (the
/// report's timestamps, interfaces, drops), so a log refused or warned about by
/// [`read_candump_log_on`] is refused or warned about here alike. For commands that pick a
/// few messages out of a bus (`evaluate`'s inputs): an hour of other ECUs' traffic (5.4 M
/// frames, 257 MB) took 464 MB read whole, against 88 MB for the node's inputs alone.
pub fn read_candump_selected(
    path: &Path,
    interface: Option<&str>,
    select: impl Fn(&CanFrame) -> bool,
) -> Result<CandumpLog> {
    use std::io::BufRead;
    let file = std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let mut input = std::io::BufReader::with_capacity(1 << 16, file);
    let mut reader = LineReader::new(path, interface);
    let mut line = Vec::new();
    let mut lineno = 0;
    loop {
        line.clear();
        let n = input
            .read_until(b'\n', &mut line)
            .with_context(|| format!("{}: reading", path.display()))?;
        if n == 0 {
            break;
        }
        lineno += 1;
        let unterminated = line.last() != Some(&b'\n');
        let text = line.strip_suffix(b"\n").unwrap_or(&line);
        let text = std::str::from_utf8(text)
            .map_err(|e| anyhow::anyhow!("{}:{lineno}: reading: {e}", path.display()))?;
        let kept = reader.log.frames.len();
        reader.push(lineno, text, unterminated)?;
        if reader.log.frames.len() > kept && !select(&reader.log.frames[reader.inserted_at].frame) {
            reader.log.frames.remove(reader.inserted_at);
        }
    }
    reader.finish()
}

/// [`read_candump_selected`] for the CLI, printing the report as [`read_candump_reporting`].
pub fn read_candump_selected_reporting(
    path: &Path,
    interface: Option<&str>,
    select: impl Fn(&CanFrame) -> bool,
) -> Result<CandumpLog> {
    let log = read_candump_selected(path, interface, select)?;
    print_report(path, &log.report);
    Ok(log)
}

/// [`read_candump`] over text already in memory; `path` names the file in errors.
pub fn parse_candump(path: &Path, text: &str) -> Result<Vec<TimedFrame>> {
    parse_candump_log(path, text).map(|log| log.frames)
}

/// [`read_candump_log`] over text already in memory; `path` names the file in errors.
pub fn parse_candump_log(path: &Path, text: &str) -> Result<CandumpLog> {
    parse_candump_bytes(path, text.as_bytes(), None)
}

/// [`read_candump_log_on`] over bytes already in memory; `path` names the file in errors (a
/// line that is not UTF-8 among them).
pub fn parse_candump_bytes(
    path: &Path,
    bytes: &[u8],
    interface: Option<&str>,
) -> Result<CandumpLog> {
    // Lines are ~48 bytes; one allocation for the whole log in the usual case.
    let mut reader = LineReader::new(path, interface);
    reader.log.frames.reserve(bytes.len() / 40 + 1);
    for (lineno, line, unterminated) in byte_lines(bytes) {
        let line = std::str::from_utf8(line)
            .map_err(|e| anyhow::anyhow!("{}:{lineno}: reading: {e}", path.display()))?;
        reader.push(lineno, line, unterminated)?;
    }
    reader.finish()
}

/// The lines of `bytes` with their numbers (from 1), and whether the line is the last one
/// and has no line end; as `str::lines`, a final line end does not start another line.
fn byte_lines(bytes: &[u8]) -> impl Iterator<Item = (usize, &[u8], bool)> {
    let terminated = bytes.ends_with(b"\n");
    let mut lines = bytes.split(|&c| c == b'\n').peekable();
    let mut lineno = 0;
    std::iter::from_fn(move || {
        let line = lines.next()?;
        lineno += 1;
        let last = lines.peek().is_none();
        if last && terminated {
            return None;
        }
        Some((lineno, line, last))
    })
}

/// The lines of `text` as [`byte_lines`].
fn text_lines(text: &str) -> impl Iterator<Item = (usize, &str, bool)> {
    // Note: the pieces split at '\n' of UTF-8 text are UTF-8.
    byte_lines(text.as_bytes()).map(|(n, l, u)| (n, std::str::from_utf8(l).unwrap_or_default(), u))
}

/// Reads a candump log line by line into a [`CandumpLog`].
struct LineReader<'a> {
    path: &'a Path,
    interface: Option<&'a str>,
    last_t: Option<u64>,
    timestamps: TimestampTracker,
    log: CandumpLog,
    /// The interface (index in the report's) of the line [`Self::keep`] last counted.
    iface: usize,
    /// The last frame kept and its interface, to tell a line written twice.
    last: Option<(TimedFrame, usize)>,
    /// The latest timestamp of each interface (by index), us.
    iface_last_t: Vec<Option<u64>>,
    /// The frames kept within [`MIRROR_WINDOW_US`] of the latest, with their interface.
    recent: std::collections::VecDeque<(TimedFrame, usize)>,
    /// Where the last frame kept went in the frames (the end, unless it was put in time
    /// order before frames of another interface).
    inserted_at: usize,
}

impl<'a> LineReader<'a> {
    fn new(path: &'a Path, interface: Option<&'a str>) -> Self {
        let mut log = CandumpLog::default();
        log.report.kept = interface.map(str::to_owned);
        Self {
            path,
            interface,
            last_t: None,
            timestamps: TimestampTracker::default(),
            log,
            iface: 0,
            last: None,
            iface_last_t: Vec::new(),
            recent: std::collections::VecDeque::new(),
            inserted_at: 0,
        }
    }

    /// Counts `frame` (of interface `self.iface`) as a copy when it repeats a recent frame of
    /// another interface ([`MIRROR_WINDOW_US`]), and keeps it among the recent ones.
    fn observe_mirror(&mut self, frame: TimedFrame) {
        while self
            .recent
            .front()
            .is_some_and(|(f, _)| f.t_us + MIRROR_WINDOW_US < frame.t_us)
        {
            self.recent.pop_front();
        }
        let original = self
            .recent
            .iter()
            .find(|(f, i)| *i != self.iface && f.frame == frame.frame && f.t_us <= frame.t_us);
        if let Some(&(f, i)) = original {
            let report = &mut self.log.report;
            report.mirrored += 1;
            report.mirror_pair.get_or_insert((i, self.iface));
            report.mirror_delays_us.push(frame.t_us - f.t_us);
        }
        if self.recent.len() < 256 {
            self.recent.push_back((frame, self.iface));
        }
    }

    /// Parses one line (blank lines are skipped, unsupported frames counted, `candump -d`
    /// lines counted, a malformed last line without a line end left out with a warning) and
    /// appends its frame, checking the time order.
    #[inline]
    fn push(&mut self, lineno: usize, line: &str, unterminated_last: bool) -> Result<()> {
        let path = self.path;
        if candump::is_error_detail(line) {
            // `candump -e`'s explanation of the error frame before, which is skipped.
            return Ok(());
        }
        let (parsed, raw_dlc) = match candump::parse_line_and_dlc(line) {
            Ok((frame, dlc)) => (Ok(frame), dlc.is_some()),
            Err(e) => (Err(e), false),
        };
        let frame = match parsed {
            Ok(frame) => Some(frame),
            Err(_) if line.trim().is_empty() => return Ok(()),
            Err(e) if e.is_unsupported_frame() => None,
            Err(candump::CandumpError::DropCount) => {
                let Some(n) = candump::dropped_frames(line) else {
                    bail!(
                        "{}:{lineno}: malformed candump -d line (expected `DROPCOUNT: dropped N CAN frames on 'IFACE' socket (total drops M)`): {line:?}",
                        path.display()
                    );
                };
                let report = &mut self.log.report;
                report.drop_lines += 1;
                report.dropped_frames += u64::from(n);
                report.first_drop_line.get_or_insert(lineno);
                return Ok(());
            }
            Err(_) if unterminated_last => {
                self.log.report.truncated_last_line = Some(lineno);
                return Ok(());
            }
            Err(candump::CandumpError::MissingTimestamp) if untimed_screen_line(line) => bail!(
                "{}:{lineno}: a candump line without a timestamp (candump's screen format \
                 without `-t`): a replay needs each frame's time: record with `candump -ta` \
                 (screen format, absolute time) or `candump -l` (log file): {line:?}",
                path.display()
            ),
            Err(e) => bail!(
                "{}:{lineno}: malformed candump line ({}): {line:?}",
                path.display(),
                candump_reason(e)
            ),
        };
        if !self.keep(line) {
            return Ok(());
        }
        let Some(frame) = frame else {
            self.log.unsupported += 1;
            if parsed == Err(candump::CandumpError::FdFrame) {
                if let Some(i) = fd_frame_id(line).and_then(node_input_index) {
                    self.log.report.inputs.fd[i] += 1;
                }
            }
            return Ok(());
        };
        if raw_dlc {
            let report = &mut self.log.report;
            report.raw_dlc_frames += 1;
            report.first_raw_dlc_line.get_or_insert(lineno);
        }
        // A line written twice: the same frame in the same microsecond on one interface.
        if self.last == Some((frame, self.iface)) {
            let report = &mut self.log.report;
            report.duplicate_lines += 1;
            report.first_duplicate_line.get_or_insert(lineno);
            return Ok(());
        }
        self.last = Some((frame, self.iface));
        let inputs = &mut self.log.report.inputs;
        if let Some(i) = node_input_index(frame.frame.id) {
            inputs.classic[i] += 1;
        } else if let CanId::Extended(raw @ 0..=0x7FF) = frame.frame.id {
            if let Some(i) = u16::try_from(raw)
                .ok()
                .and_then(|raw| node_input_index(CanId::Standard(raw)))
            {
                inputs.as_extended[i] += 1;
            }
        }
        // Far beyond any clock (year 292 000); keeps the tick arithmetic from overflowing.
        if frame.t_us > u64::MAX / 2 {
            bail!(
                "{}:{lineno}: timestamp {} us out of range",
                path.display(),
                frame.t_us
            );
        }
        let iface_prev = self.iface_last_t.get(self.iface).copied().flatten();
        let behind_other = self.last_t.is_some_and(|prev| {
            frame.t_us < prev
                && prev - frame.t_us <= CROSS_INTERFACE_REORDER_US
                && iface_prev.is_none_or(|p| frame.t_us >= p)
        });
        if self.iface_last_t.len() <= self.iface {
            self.iface_last_t.resize(self.iface + 1, None);
        }
        if behind_other {
            // A frame of this interface written after a later one of another: candump reads
            // its sockets in turn. Put in time order at the end.
            let report = &mut self.log.report;
            report.reordered += 1;
            report.first_reordered_line.get_or_insert(lineno);
            let back = self.last_t.unwrap_or(frame.t_us) - frame.t_us;
            report.largest_reorder_us = report.largest_reorder_us.max(back);
            self.iface_last_t[self.iface] = Some(frame.t_us);
            self.observe_mirror(frame);
            self.timestamps
                .observe(&mut self.log.report.timestamps, frame.t_us, frame.frame.id);
            // In time order, after the frames of its instant: near the end.
            let frames = &mut self.log.frames;
            let at = frames.partition_point(|f| f.t_us <= frame.t_us);
            frames.insert(at, frame);
            self.inserted_at = at;
            return Ok(());
        }
        if let Some(prev) = self.last_t {
            if frame.t_us < prev {
                let other = iface_prev.is_none_or(|p| frame.t_us >= p);
                bail!(
                    "{}:{lineno}: time goes backwards ({} us after {} us){}",
                    path.display(),
                    frame.t_us,
                    prev,
                    if short_timestamp(line) {
                        ": the timestamps look like `candump -td`'s, each the time since the \
                         frame before, which cannot be replayed: record with `-ta` (absolute) \
                         or `-tz` (from the first frame)"
                    } else if dated_timestamp(line) {
                        ": `candump -t A` writes the recorder's local time, which goes back an \
                         hour where daylight saving time ends: record with `-ta` (seconds \
                         since 1970, UTC)"
                    } else if other {
                        ": a frame of another interface than the frame before, more than the \
                         20 ms two interfaces' frames may come out of order (candump reads its \
                         sockets in turn): the interfaces' clocks differ; replay one with \
                         `--interface NAME`"
                    } else {
                        ""
                    }
                );
            }
            let gap_us = frame.t_us - prev;
            if gap_us > PAUSE_NOTE_US {
                let report = &mut self.log.report;
                report.pauses += 1;
                if report
                    .longest_pause
                    .is_none_or(|(_, from, to)| gap_us > to - from)
                {
                    report.longest_pause = Some((lineno, prev, frame.t_us));
                }
            }
            if frame.t_us - prev > MAX_LOG_PAUSE_US {
                bail!(
                    "{}:{lineno}: the clock jumps {:.0} s forward, more than the {} s a log may \
                     pause (a clock step or two logs joined): split the log at this line",
                    path.display(),
                    (frame.t_us - prev) as f64 * 1e-6,
                    MAX_LOG_PAUSE_US / 1_000_000
                );
            }
        }
        self.last_t = Some(frame.t_us);
        self.iface_last_t[self.iface] = Some(frame.t_us);
        self.observe_mirror(frame);
        self.timestamps
            .observe(&mut self.log.report.timestamps, frame.t_us, frame.frame.id);
        self.inserted_at = self.log.frames.len();
        self.log.frames.push(frame);
        Ok(())
    }

    /// Counts the line's interface; whether its frame is kept (`--interface`).
    #[inline]
    fn keep(&mut self, line: &str) -> bool {
        let name = candump::interface_of(line).unwrap_or_default();
        let report = &mut self.log.report;
        match report.interfaces.iter_mut().position(|(n, _)| n == name) {
            Some(i) => {
                report.interfaces[i].1 += 1;
                self.iface = i;
            }
            None => {
                self.iface = report.interfaces.len();
                report.interfaces.push((name.to_owned(), 1));
            }
        }
        let keep = self.interface.is_none_or(|kept| kept == name);
        if !keep {
            report.other_interfaces += 1;
        }
        keep
    }

    /// The log; an error if `--interface` named an interface the log does not have.
    fn finish(self) -> Result<CandumpLog> {
        self.log.report.check_interface(self.path)?;
        self.log.report.check_mirrored(self.path)?;
        Ok(self.log)
    }
}

impl LogReport {
    /// An error if most frames of one interface are copies of another's ([`Self::mirrored`]):
    /// read as one bus, every frame would reach the node twice.
    fn check_mirrored(&self, path: &Path) -> Result<()> {
        let Some((from, to)) = self.mirror_pair else {
            return Ok(());
        };
        let name = |i: usize| self.interfaces.get(i).map_or("?", |(n, _)| n.as_str());
        let lines = |i: usize| self.interfaces.get(i).map_or(0, |(_, n)| *n);
        let mut delays = self.mirror_delays_us.clone();
        let mid = delays.len() / 2;
        let median_us = delays.select_nth_unstable(mid).1.to_owned();
        let fewer = lines(from).min(lines(to));
        let what = format!(
            "{} frames of `{}` repeat a frame of `{}` {:.3} ms later (the median; the same \
             identifier and data, rolling counter and CRC included)",
            self.mirrored,
            name(to),
            name(from),
            median_us as f64 * 1e-3
        );
        if self.kept.is_none() && self.mirrored >= 50 && 2 * self.mirrored >= fewer {
            bail!(
                "{}: {what}: one bus logged on two interfaces (a gateway or bridge that \
                 mirrors it); read as one bus, every frame would reach the node twice (the \
                 copies' rolling counters refused, the GNSS fixes taken for a receiver \
                 twice as fast, or faster): replay one interface with `--interface {}`",
                path.display(),
                name(from)
            );
        }
        Ok(())
    }

    /// An error if the interface kept is not among the log's.
    fn check_interface(&self, path: &Path) -> Result<()> {
        if let Some(kept) = &self.kept {
            if !self.interfaces.iter().any(|(n, _)| n == kept) {
                let found = self
                    .interfaces
                    .iter()
                    .map(|(n, _)| format!("`{n}`"))
                    .collect::<Vec<_>>();
                bail!(
                    "{}: no frame on interface `{kept}` (--interface); the log's interfaces: {}",
                    path.display(),
                    if found.is_empty() {
                        "none (no frame)".to_string()
                    } else {
                        found.join(", ")
                    }
                );
            }
        }
        Ok(())
    }
}

/// Whether `line` is candump's screen format without a timestamp (`candump can0`): an
/// interface, an identifier and `[LEN]` (or `-8`'s `{DLC}`), each in its place.
fn untimed_screen_line(line: &str) -> bool {
    let mut tokens = line.split_ascii_whitespace();
    let (Some(_iface), Some(mut id)) = (tokens.next(), tokens.next()) else {
        return false;
    };
    if matches!(id, "RX" | "TX") {
        tokens.next();
        tokens.next();
        match tokens.next() {
            Some(t) => id = t,
            None => return false,
        }
    }
    let len = tokens.next().unwrap_or_default();
    matches!(id.len(), 3 | 8)
        && id.bytes().all(|c| c.is_ascii_hexdigit())
        && (len.starts_with('[') && len.ends_with(']')
            || len.starts_with('{') && len.ends_with('}'))
}

/// Whether the line's timestamp has fewer than the 10 digits of seconds of candump's absolute
/// time (`%010lu`): `candump -td` and `-tz` write `%03lu`.
fn short_timestamp(line: &str) -> bool {
    line.trim_start()
        .strip_prefix('(')
        .and_then(|rest| rest.split_once('.'))
        .is_some_and(|(secs, _)| secs.len() < 10)
}

/// Whether the line's timestamp is a date (`candump -t A`: `(2024-01-01 12:00:00.123456)`).
fn dated_timestamp(line: &str) -> bool {
    line.trim_start()
        .strip_prefix('(')
        .and_then(|rest| rest.split_once(')'))
        .is_some_and(|(stamp, _)| stamp.contains(' '))
}

/// What is wrong with a rejected candump line, in words.
pub fn candump_reason(e: candump::CandumpError) -> &'static str {
    use candump::CandumpError as E;
    match e {
        E::Empty => "empty line",
        E::MissingTimestamp => "expected `(SECONDS.UUUUUU)` at the start",
        E::BadTimestamp => {
            "timestamp is not `(SECONDS.UUUUUU)` with six or nine decimals, nor a date \
             `(YYYY-MM-DD HH:MM:SS.UUUUUU)` from 1970 on"
        }
        E::MissingInterface => "no interface name after the timestamp",
        E::BadInterface => "interface name empty, too long or not printable",
        E::MissingSeparator => "no `#` between identifier and data",
        E::BadId => "identifier is not 3 or 8 hex digits",
        E::IdOutOfRange => "identifier above 0x7FF (3 digits) or 0x1FFFFFFF (8 digits)",
        E::RemoteFrame => "remote frame (`#R`), not supported",
        E::FdFrame => "CAN FD frame (`##`, or a two-digit `[LEN]`), not supported",
        E::ErrorFrame => "error frame (CAN_ERR_FLAG in the identifier), not a bus frame",
        E::BadHex => "data is not hex",
        E::OddHex => "odd number of data hex digits",
        E::TooLong => "more than 8 data bytes",
        E::TrailingGarbage => "unexpected text after the data",
        E::BadRawDlc => {
            "`_` after the data, but not can-utils' raw DLC suffix (`_` and one hex digit 9..F \
             after 8 data bytes: a classic frame whose DLC field said 9..15)"
        }
        E::LengthMismatch => "fewer data bytes than the `[LEN]` field says",
        E::DropCount => "a `candump -d` drop count, not a frame",
    }
}

/// One candump line (`(secs.micros) can0 ID#DATA`).
pub fn candump_line(t_us: u64, frame: &CanFrame) -> String {
    let mut out = Vec::with_capacity(48);
    text::push_candump_line(&mut out, t_us, frame);
    text::into_string(out)
}

/// What a replay produced.
pub struct ReplayOutput {
    /// Predictions CSV rows: `t,step,horizon_s,x,y,heading,speed,mode`.
    pub predictions_csv: String,
    /// The node's frames, candump, stamped with the tick time; empty unless asked for
    /// ([`ReplayText::with_tx_log`]).
    pub tx_log: String,
    /// Ticks run.
    pub ticks: u64,
    /// The node's rejection counters at the end.
    pub counters: Counters,
    /// Origin used, 1e-7 deg.
    pub origin_e7: Option<(i32, i32)>,
}

/// Which text a replay writes besides the predictions CSV.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReplayText {
    /// Also build the candump TX log (`--tx-out`).
    pub with_tx_log: bool,
}

/// What a replay did, its text aside.
#[derive(Clone, Debug, PartialEq)]
pub struct ReplayStats {
    /// Frames handed to the node.
    pub frames: u64,
    /// Frames the acceptance filter refused (not node inputs), as the firmware's bus does.
    pub filtered: u64,
    /// Remote, CAN FD and error frames skipped ([`CandumpLog::unsupported`]).
    pub unsupported: u64,
    /// Ticks run.
    pub ticks: u64,
    /// Ticks with a valid position (the others' predictions are "not available").
    pub valid_ticks: u64,
    /// The highest speed the node used at any tick, m/s (0 for a car that never moved: no
    /// heading from its course, so no position).
    pub max_speed_mps: f32,
    /// The node's rejection counters at the end.
    pub counters: Counters,
    /// The node's steering check at the end ([`catmodel::node::steering`]).
    pub steering: SteeringCheck,
    /// Ticks at which the node used a steering gain other than the model file's.
    pub steering_mismatch_ticks: u64,
    /// Origin used at the end, 1e-7 deg.
    pub origin_e7: Option<(i32, i32)>,
    /// Times the local frame moved (a LOCAL_ORIGIN, or the car leaving the node's own frame:
    /// STATE_POSITION jumps there).
    pub origin_moves: u32,
    /// GNSS fixes beyond the local frame's validity radius ([`Node::gnss_fixes_beyond_frame`]).
    pub fixes_beyond_frame: u32,
    /// The receiver's rate over the whole log ([`ReceiverRate::measure`]), `None` with fewer
    /// than two fixes.
    pub gnss_rate: Option<crate::ReceiverRate>,
    /// The node's planner refusals (on no status page but as the bit
    /// `planner_refused_recently`) and the first one's reason, as `sil` sums them up.
    pub planner: PlannerRefusals,
    /// Frames dropped because the receive queue was full (as the firmware drops them).
    pub rx_queue_drops: u32,
    /// GNSS positions given to the node from the model file's receiver
    /// (`[inputs] gnss_source_address`).
    pub fixes: u64,
    /// GNSS positions given to the node from other source addresses (refused as unknown ids),
    /// by address.
    pub other_gnss_sources: Vec<(u8, u64)>,
    /// Speed reports above the model file's `max_speed_mps`, which the node clamps to it
    /// without a counter of its own ([`speed_note`]).
    pub speeds_over_max: SpeedsOverMax,
    /// SPEED_REPORT's `direction` over the log ([`direction_note`]).
    pub directions: DirectionReports,
    /// The steering and speed reports' intervals against their timeouts ([`slow_reports_note`]).
    pub report_intervals: [ReportIntervals; 2],
}

/// One 50 Hz report's intervals over a log (pauses of the whole log, [`PAUSE_NOTE_US`] and
/// longer, left out), against the model file's timeout for it.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ReportIntervals {
    /// The message's name.
    pub name: &'static str,
    /// The model file's key for its timeout.
    pub key: &'static str,
    /// Its timeout, us.
    pub timeout_us: u64,
    /// The last report's time stamp, us.
    last_us: Option<u64>,
    /// Every interval, us.
    intervals_us: Vec<u64>,
    /// Intervals this long or longer are the log's pauses, left out, us.
    pause_us: u64,
}

impl ReportIntervals {
    fn new(name: &'static str, key: &'static str, timeout_us: u64) -> Self {
        Self {
            name,
            key,
            timeout_us,
            pause_us: PAUSE_NOTE_US,
            ..Self::default()
        }
    }

    /// The steering's and the speed's reports, against `config`'s timeouts for them.
    pub fn steering_and_speed(config: &NodeConfig) -> [Self; 2] {
        Self::steering_and_speed_of(&config.freshness)
    }

    /// The steering's and the speed's reports, against `freshness`'s timeouts for them.
    pub fn steering_and_speed_of(freshness: &FreshnessConfig) -> [Self; 2] {
        [
            Self::new(
                "STEERING_REPORT",
                "steer_timeout_s",
                freshness.timeout_us(Input::Steer),
            ),
            Self::new(
                "SPEED_REPORT",
                "speed_timeout_s",
                freshness.timeout_us(Input::Speed),
            ),
        ]
    }

    /// The steering's and the speed's reports as a log's sensor columns would give them,
    /// stamped at their samples' times, s: `steer`'s, and `vel`'s or `input_vel`'s, whichever
    /// come further apart (both ride SPEED_REPORT), against `freshness`'s timeouts. Every
    /// interval counts: a log's pauses are refused before `identify` fits it
    /// (`identify::preprocess::MAX_PAUSE_S`), and a sensor logged every second or slower is
    /// what is to be named.
    pub fn of_log_columns(
        freshness: &FreshnessConfig,
        steer_t_s: &[f64],
        speed_t_s: [&[f64]; 2],
    ) -> [Self; 2] {
        let [mut steer, speed] = Self::steering_and_speed_of(freshness);
        let of = |mut r: Self, times: &[f64]| {
            r.pause_us = u64::MAX;
            for t in times {
                // Note: a log's times are finite (the reader refuses others); a time before 0
                // saturates to 0, and only intervals are used.
                r.observe((t * 1e6).round().max(0.0) as u64);
            }
            r
        };
        steer = of(steer, steer_t_s);
        let [vel, cmd] = speed_t_s.map(|t| of(speed.clone(), t));
        let median = |r: &Self| r.median_and_stale_share().map_or(0, |m| m.0);
        let speed = if median(&cmd) > median(&vel) {
            cmd
        } else {
            vel
        };
        [steer, speed]
    }

    /// The pairs of [`Self::steering_and_speed`] of several logs (each [`Self::of_log_columns`])
    /// pooled into one, against `freshness`'s timeouts.
    pub fn pooled<'a>(
        freshness: &FreshnessConfig,
        logs: impl IntoIterator<Item = &'a [Self; 2]>,
    ) -> [Self; 2] {
        let mut pair = Self::steering_and_speed_of(freshness);
        for log in logs {
            for (all, one) in pair.iter_mut().zip(log) {
                all.intervals_us.extend_from_slice(&one.intervals_us);
            }
        }
        pair
    }

    /// `frame`, stamped `t_us`, counted in [`Self::steering_and_speed`]'s pair if it is one of
    /// their reports.
    pub fn observe_frame(pair: &mut [Self; 2], frame: &CanFrame, t_us: u64) {
        if frame.id == catmodel::can::spec::STEERING_REPORT.id {
            pair[0].observe(t_us);
        } else if frame.id == catmodel::can::spec::SPEED_REPORT.id {
            pair[1].observe(t_us);
        }
    }

    /// A report stamped `t_us`.
    fn observe(&mut self, t_us: u64) {
        if let Some(last) = self.last_us {
            let dt = t_us.saturating_sub(last);
            if dt < self.pause_us {
                self.intervals_us.push(dt);
            }
        }
        self.last_us = Some(t_us);
    }

    /// The median interval, us, and the share of the time spent in intervals longer than the
    /// timeout (the node sees the input stale in them); `None` with fewer than 10 intervals.
    pub fn median_and_stale_share(&self) -> Option<(u64, f64)> {
        if self.intervals_us.len() < 10 {
            return None;
        }
        let mut sorted = self.intervals_us.clone();
        sorted.sort_unstable();
        let median = sorted[sorted.len() / 2];
        let total: u64 = sorted.iter().sum();
        let stale: u64 = sorted
            .iter()
            .filter(|&&dt| dt > self.timeout_us)
            .map(|&dt| dt - self.timeout_us)
            .sum();
        Some((median, stale as f64 / total.max(1) as f64))
    }
}

/// What a replay should say about steering or speed reports that come further apart than
/// their timeouts (a sensor logged at 5 Hz by a telemetry logger, not the bus's 50 Hz): the
/// node takes the input for stale between reports, dead-reckons straight on or on the speed
/// model while it is, and its predictions and heading suffer (a black-box probe's 5 Hz log:
/// the current speed 0.74 m/s RMS off, 0.03 at 50 Hz, and a steering check that read the
/// straight-on ticks as a steering 1.7 times the model file's). `None` while the median
/// interval is within the timeout.
pub fn slow_reports_note(stats: &ReplayStats) -> Option<String> {
    let slow = slow_reports(&stats.report_intervals);
    (!slow.is_empty()).then(|| {
        format!(
            "the log's reports come further apart than the node's timeouts: {}. Between \
             reports the node takes the input for stale (NODE_STATUS), steers straight on or \
             runs the speed model, and its predictions and heading are as much off; {SLOW_FIX}",
            slow.join("; ")
        )
    })
}

/// What to do about reports further apart than their timeouts ([`slow_reports_note`],
/// [`slow_log_reports_note`]).
const SLOW_FIX: &str = "a logger that samples the bus slower than its 50 Hz loses what the \
     node needs: record every frame (candump -l)";

/// What `csv2can` should say about the steering and speed reports it wrote from a log whose
/// sensors were recorded further apart than the node's timeouts (`intervals`: the reports
/// written, against the timeouts of the model file `replay` uses by default), worded as
/// [`slow_reports_note`] (a black-box probe's 5 Hz log went through `csv2can` without a word).
/// `None` while the median interval is within the timeout.
pub fn slow_log_reports_note(intervals: &[ReportIntervals]) -> Option<String> {
    let slow = slow_reports(intervals);
    (!slow.is_empty()).then(|| {
        format!(
            "the log's `steer` and `vel` rows come further apart than the node's timeouts (the \
             default model file's): {}. `replay` of this candump takes the input for stale \
             between reports, steers straight on or runs the speed model, and its predictions \
             and heading are as much off; {SLOW_FIX}",
            slow.join("; ")
        )
    })
}

/// Each report of `intervals` whose median interval is longer than its timeout, in words.
pub fn slow_reports(intervals: &[ReportIntervals]) -> Vec<String> {
    intervals
        .iter()
        .filter_map(|r| {
            let (median, share) = r.median_and_stale_share()?;
            (median > r.timeout_us).then(|| {
                // To the microsecond where the millisecond would read as the timeout (a 10 Hz
                // logger's 0.100001 s against 0.100 s).
                let every = match format!("{:.3}", median as f64 * 1e-6) {
                    ms if ms == format!("{:.3}", r.timeout_us as f64 * 1e-6) => {
                        format!("{:.6}", median as f64 * 1e-6)
                    }
                    ms => ms,
                };
                format!(
                    "{} every {every} s (median), longer than its {:.3} s timeout \
                     (`[inputs] {}`): stale {:.0} % of the time",
                    r.name,
                    r.timeout_us as f64 * 1e-6,
                    r.key,
                    100.0 * share
                )
            })
        })
        .collect()
}

/// Measured speeds (SPEED_REPORT frames the node took: CRC and length right) above the model
/// file's `max_speed_mps`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SpeedsOverMax {
    /// The model file's `max_speed_mps`, m/s.
    pub max_speed_mps: f32,
    /// Reports above it.
    pub reports: u64,
    /// The fastest of them, m/s.
    pub fastest_mps: f32,
    /// The first one's time stamp, us.
    pub first_t_us: Option<u64>,
}

impl SpeedsOverMax {
    /// Counts `frame` (stamped `t_us`) if it is a speed report above the limit.
    fn observe(&mut self, frame: &CanFrame, t_us: u64) {
        if frame.id != catmodel::can::spec::SPEED_REPORT.id {
            return;
        }
        let Ok((report, _)) = SpeedReport::decode(frame) else {
            return;
        };
        if let Some(v) = report.speed_mps.filter(|v| *v > self.max_speed_mps) {
            self.reports += 1;
            self.fastest_mps = self.fastest_mps.max(v);
            self.first_t_us.get_or_insert(t_us);
        }
    }
}

/// What a replay should say about speed reports above the model file's `max_speed_mps`: the
/// node clamps its speed to it (as the firmware does, and counts nothing), so its predictions
/// there fall short of the car. `None` without such reports.
pub fn speed_note(stats: &ReplayStats) -> Option<String> {
    let s = &stats.speeds_over_max;
    let first = s.first_t_us?;
    Some(format!(
        "{} speed report(s) (SPEED_REPORT) were above the model file's max_speed_mps \
         ({} m/s), up to {:.2} m/s, the first at t = {:.6} s: the node clamps its speed to \
         {} m/s, so its state and predictions there fall behind the car; check \
         [vehicle] max_speed_mps against the car (and `speed_mps`'s unit on the bus)",
        s.reports,
        s.max_speed_mps,
        s.fastest_mps,
        first as f64 * 1e-6,
        s.max_speed_mps
    ))
}

/// SPEED_REPORT `direction` in the reports the node took (CRC and length right): how many
/// said forward, reverse and invalid (the rest said nothing: a kit without the signal).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DirectionReports {
    /// Reports that said forward.
    pub forward: u64,
    /// Reports that said reverse.
    pub reverse: u64,
    /// Reports that said invalid (taken as not reported, counted as an invalid input).
    pub invalid: u64,
    /// The first reverse report's time stamp, us.
    pub first_reverse_t_us: Option<u64>,
}

impl DirectionReports {
    /// Counts `frame` (stamped `t_us`) if it is a speed report with a direction.
    fn observe(&mut self, frame: &CanFrame, t_us: u64) {
        if frame.id != catmodel::can::spec::SPEED_REPORT.id {
            return;
        }
        let Ok((report, _)) = SpeedReport::decode(frame) else {
            return;
        };
        match report.direction {
            Direction::NotReported => {}
            Direction::Forward => self.forward += 1,
            Direction::Reverse => {
                self.reverse += 1;
                self.first_reverse_t_us.get_or_insert(t_us);
            }
            Direction::Invalid => self.invalid += 1,
        }
    }
}

/// What a replay says about SPEED_REPORT's `direction`, when any report carried one: how many
/// said reverse (the node moved the car backwards there and its controller held it) and how
/// many said invalid. `None` for a log whose reports say no direction (every log before the
/// signal).
pub fn direction_note(stats: &ReplayStats) -> Option<String> {
    let d = &stats.directions;
    if d.forward + d.reverse + d.invalid == 0 {
        return None;
    }
    let mut note = format!(
        "SPEED_REPORT direction: {} report(s) forward, {} reverse",
        d.forward, d.reverse
    );
    if let Some(t) = d.first_reverse_t_us {
        note.push_str(&format!(
            " (the first at t = {:.6} s: the node dead-reckoned and predicted the car \
             backwards there, and a controller with a path held it, `fallback_reason` \
             reversing)",
            t as f64 * 1e-6
        ));
    }
    if d.invalid > 0 {
        note.push_str(&format!(
            ", {} invalid (taken as not reported, counted as invalid inputs)",
            d.invalid
        ));
    }
    Some(note)
}

/// GNSS positions from other source addresses than the model file's (`(address, count)`), as
/// `replay` and `receiver-error` name them: the list (`30161 from 128 (0x80), ...`) and the
/// busiest address. `None` without them.
pub fn other_sources_list(others: &[(u8, u64)]) -> Option<(String, u8)> {
    let (busiest, _) = *others.iter().max_by_key(|(_, n)| *n)?;
    let list = others
        .iter()
        .map(|(sa, n)| format!("{n} from {sa} (0x{sa:02X})"))
        .collect::<Vec<_>>()
        .join(", ");
    Some((list, busiest))
}

/// What a replay should say about GNSS positions of receivers at source addresses other than
/// the model file's: with none of its own, which address to declare (a black-box probe's
/// receiver at 0x1D had its 30 161 fixes counted as unknown ids and the model file's
/// `gnss_rate_hz` blamed); beside its own, that they were refused. `None` without them.
pub fn other_sources_note(stats: &ReplayStats, declared: u8) -> Option<String> {
    let (list, busiest) = other_sources_list(&stats.other_gnss_sources)?;
    Some(if stats.fixes == 0 {
        format!(
            "no GNSS position came from source address {declared} (the model file's [inputs] \
             gnss_source_address), and {list} did: the node refused them as unknown ids; if \
             that is the car's receiver, set gnss_source_address = {busiest}"
        )
    } else {
        format!(
            "GNSS positions from other source addresses than the model file's {declared} were \
             refused as unknown ids ({list}): the node uses one receiver's fixes"
        )
    })
}

/// What a replay should say about the local frame: fixes beyond its validity radius
/// ([`catmodel::geodesy::VALIDITY_RADIUS_M`]) from the origin, and the frame's moves, at
/// which STATE_POSITION jumps. `None` when neither happened.
pub fn frame_note(stats: &ReplayStats) -> Option<String> {
    if stats.fixes_beyond_frame == 0 {
        return None;
    }
    let radius_km = catmodel::geodesy::VALIDITY_RADIUS_M / 1000.0;
    let origin = stats.origin_e7.map_or(String::new(), |(lat, lon)| {
        format!(
            " (now {:.7},{:.7})",
            f64::from(lat) * 1e-7,
            f64::from(lon) * 1e-7
        )
    });
    Some(if stats.origin_moves > 0 {
        format!(
            "{} GNSS fixes lay more than {radius_km} km from the local frame's origin{origin}, among the gate's rejections; \
             the frame moved {} time(s), and STATE_POSITION and the predictions jump where it did (the node moves a frame it chose at its first fix; \
             a LOCAL_ORIGIN from the planner or --origin fixes the frame instead)",
            stats.fixes_beyond_frame, stats.origin_moves
        )
    } else {
        format!(
            "{} GNSS fixes lay more than {radius_km} km from the local frame's origin{origin} and were refused (counted among the gate's rejections): \
             the origin given (--origin, or the planner's LOCAL_ORIGIN) is too far from the drive; give one within {radius_km} km of it",
            stats.fixes_beyond_frame
        )
    })
}

/// Number of ticks [`replay`] runs over `frames` (sorted by time).
pub fn tick_count(frames: &[TimedFrame]) -> u64 {
    match (frames.first(), frames.last()) {
        (Some(first), Some(last)) => {
            (first_tick_us(last.t_us) - first_tick_us(first.t_us)) / SAMPLE_PERIOD_US + 1
        }
        _ => 0,
    }
}

/// Runs the node over `frames` (sorted by time): the predictions CSV and the TX log.
pub fn replay(frames: &[TimedFrame], config: NodeConfig) -> ReplayOutput {
    replay_with_progress(frames, config, ReplayText { with_tx_log: true }, |_| {})
}

/// The CSV header row.
const CSV_HEADER: &str = "t,step,horizon_s,x,y,heading,speed,mode\n";

/// [`replay`] writing the text `text` asks for, calling `progress(ticks_done)` every 500 ticks.
pub fn replay_with_progress(
    frames: &[TimedFrame],
    config: NodeConfig,
    text: ReplayText,
    progress: impl FnMut(u64),
) -> ReplayOutput {
    let ticks = usize::try_from(tick_count(frames)).unwrap_or(0);
    // Up to 11 rows of ~55 bytes per tick; 14 lines of ~40 bytes of TX text.
    let mut csv = Vec::with_capacity(CSV_HEADER.len() + ticks.saturating_mul(640));
    let mut tx_log = Vec::with_capacity(if text.with_tx_log {
        ticks.saturating_mul(600)
    } else {
        0
    });
    let tx_sink = if text.with_tx_log {
        Some(&mut tx_log)
    } else {
        None
    };
    // Note: writing to a Vec cannot fail.
    let stats = replay_into(frames, config, &mut csv, tx_sink, progress).unwrap_or(ReplayStats {
        frames: 0,
        filtered: 0,
        unsupported: 0,
        ticks: 0,
        valid_ticks: 0,
        max_speed_mps: 0.0,
        counters: Counters::default(),
        steering: SteeringCheck::new(),
        steering_mismatch_ticks: 0,
        origin_e7: None,
        origin_moves: 0,
        fixes_beyond_frame: 0,
        gnss_rate: None,
        planner: PlannerRefusals::default(),
        rx_queue_drops: 0,
        fixes: 0,
        other_gnss_sources: Vec::new(),
        speeds_over_max: SpeedsOverMax::default(),
        directions: DirectionReports::default(),
        report_intervals: Default::default(),
    });
    ReplayOutput {
        predictions_csv: text::into_string(csv),
        tx_log: text::into_string(tx_log),
        ticks: stats.ticks,
        counters: stats.counters,
        origin_e7: stats.origin_e7,
    }
}

/// Ticks handed from the node to the text writer at a time.
const BATCH_TICKS: usize = 256;

/// The text is handed to the sinks in pieces of about this many bytes.
const CHUNK_BYTES: usize = 1 << 17;

/// Runs the node over `frames` (sorted by time), writing the predictions CSV to `csv` and,
/// if given, the candump TX log to `tx_log` as it goes (in pieces of ~128 KiB: the text is
/// never whole in memory); calls `progress(ticks_done)` every 500 ticks. Errors are the
/// sinks' (the first one stops the writing; the node runs to the end regardless).
///
/// Two threads: this one steps the node, a second one turns each batch of
/// [`BATCH_TICKS`] ticks' frames into text behind it (the text depends only on the frames, so
/// it is the same as one thread writing it after each tick).
pub fn replay_into<C: Write + Send, T: Write + Send>(
    frames: &[TimedFrame],
    config: NodeConfig,
    csv: C,
    tx_log: Option<T>,
    progress: impl FnMut(u64),
) -> std::io::Result<ReplayStats> {
    let source = SliceSource { frames, next: 0 };
    let (stats, written, _) = run(source, config, csv, tx_log, false, progress);
    written.map(|()| stats)
}

/// [`read_candump`] and [`replay_into`] at once, over the text of a candump file (`path`
/// names it in errors): a third thread parses the text ahead of the node, so the node starts
/// with the first lines. Nothing reaches the sinks unless the whole text parses (the errors
/// are [`read_candump`]'s, word for word); then the text is the same as [`replay_into`]'s.
pub fn replay_text_into<C: Write + Send, T: Write + Send>(
    path: &Path,
    text: &str,
    config: NodeConfig,
    csv: C,
    tx_log: Option<T>,
    progress: impl FnMut(u64),
) -> Result<ReplayStats> {
    replay_text(path, text, None, config, csv, tx_log, false, progress).map(|(stats, _)| stats)
}

/// [`replay_text_into`] keeping the frames of `interface` (all if `None`), with what the
/// reader noticed; with `stream`, the text reaches the sinks as the node runs, before the
/// input is known to be valid (for sinks that are discarded on an error: [`PartialFile`]).
#[allow(clippy::too_many_arguments)]
fn replay_text<C: Write + Send, T: Write + Send>(
    path: &Path,
    text: &str,
    interface: Option<&str>,
    config: NodeConfig,
    csv: C,
    tx_log: Option<T>,
    stream: bool,
    progress: impl FnMut(u64),
) -> Result<(ReplayStats, CandumpLog)> {
    let (to_node, chunks) = std::sync::mpsc::sync_channel::<Result<Vec<TimedFrame>>>(16);
    std::thread::scope(|scope| {
        // Returns the log without its frames: the counts and the report.
        let parser = scope.spawn(move || {
            let mut reader = LineReader::new(path, interface);
            reader.log.frames = Vec::with_capacity(PARSE_CHUNK_FRAMES);
            for (lineno, line, unterminated) in text_lines(text) {
                if let Err(e) = reader.push(lineno, line, unterminated) {
                    // Note: a send fails only if the node stopped listening.
                    let _ = to_node.send(Err(e));
                    return reader.log;
                }
                if reader.log.frames.len() >= PARSE_CHUNK_FRAMES {
                    // The frames within the reorder window of the latest stay: a frame of
                    // another interface may still go before them.
                    let frames = &mut reader.log.frames;
                    let latest = frames.last().map_or(0, |f| f.t_us);
                    let hold =
                        frames.partition_point(|f| f.t_us + CROSS_INTERFACE_REORDER_US < latest);
                    if hold > 0 {
                        let mut full = std::mem::replace(
                            frames,
                            Vec::with_capacity(PARSE_CHUNK_FRAMES + PARSE_CHUNK_FRAMES / 4),
                        );
                        frames.extend(full.drain(hold..));
                        if to_node.send(Ok(full)).is_err() {
                            return reader.log;
                        }
                    }
                }
            }
            let last = std::mem::take(&mut reader.log.frames);
            let checked = reader.log.report.check_interface(path);
            let _ = match checked.and_then(|()| reader.log.report.check_mirrored(path)) {
                Ok(()) => to_node.send(Ok(last)),
                Err(e) => to_node.send(Err(e)),
            };
            reader.log
        });
        let source = StreamSource {
            chunks,
            pending: Vec::with_capacity(2 * PARSE_CHUNK_FRAMES),
            next: 0,
            finished: false,
            error: None,
        };
        let (mut stats, written, parse_error) = run(source, config, csv, tx_log, stream, progress);
        if let Some(e) = parse_error {
            return Err(e);
        }
        let log = match parser.join() {
            Ok(log) => log,
            Err(panic) => std::panic::resume_unwind(panic),
        };
        stats.unsupported = log.unsupported;
        written.context("writing the output")?;
        Ok((stats, log))
    })
}

/// `catmodel replay`: the candump file at `log` through the node (its frames on `interface`
/// only, if given), the predictions CSV to `csv_path` and the TX log to `tx_path` if given
/// (files, with their directories, written as `.partial` files while the node runs and renamed
/// once the whole log has parsed: an error leaves none behind; [`PartialFile`]). A log with no
/// frame to replay is an error naming it. `progress` as in [`replay_into`]; [`estimate_ticks`]
/// gives the total. Returns what the reader noticed too ([`LogReport`]).
pub fn replay_file(
    log: &Path,
    text: &[u8],
    interface: Option<&str>,
    config: NodeConfig,
    csv_path: &Path,
    tx_path: Option<&Path>,
    progress: impl FnMut(u64),
) -> Result<(ReplayStats, LogReport)> {
    let mut csv = PartialFile::new(csv_path);
    let mut tx = tx_path.map(PartialFile::new);
    let (stats, report) = match std::str::from_utf8(text) {
        Ok(text) => {
            let (stats, read) = replay_text(
                log,
                text,
                interface,
                config,
                &mut csv,
                tx.as_mut(),
                true,
                progress,
            )?;
            (stats, read.report)
        }
        Err(_) => {
            // Not UTF-8 somewhere: the byte reader names the line.
            let read = parse_candump_bytes(log, text, interface)?;
            let mut stats = replay_into(&read.frames, config, &mut csv, tx.as_mut(), progress)
                .context("writing the output")?;
            stats.unsupported = read.unsupported;
            (stats, read.report)
        }
    };
    if stats.ticks == 0 {
        // No frame, no tick: a replay of nothing would "succeed" with an empty predictions
        // file. The output files are dropped uncommitted (none is left behind).
        let skipped = match stats.unsupported {
            0 => String::new(),
            n => format!(" ({n} remote/FD/error frames skipped, which the node cannot use)"),
        };
        bail!(
            "{}: no CAN frame to replay{skipped}: a log with no frames is not a drive",
            log.display()
        );
    }
    csv.commit()?;
    if let Some(tx) = tx {
        tx.commit()?;
    }
    Ok((stats, report))
}

/// Reads a whole file. Errors name it.
pub fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    let mut file =
        std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let mut bytes = Vec::new();
    file.read_to_end(&mut bytes)
        .with_context(|| format!("{}: reading", path.display()))?;
    Ok(bytes)
}

/// The number of ticks a replay of candump `text` runs, from its first and last lines (0 if
/// either does not parse): for a progress display.
pub fn estimate_ticks(text: &[u8]) -> u64 {
    let mut lines = text
        .split(|&c| c == b'\n')
        .filter(|l| !l.trim_ascii().is_empty());
    let parse = |l: Option<&[u8]>| {
        l.and_then(|l| std::str::from_utf8(l).ok())
            .and_then(|l| candump::parse_line(l).ok())
    };
    let first = parse(lines.next());
    let last = parse(
        text.split(|&c| c == b'\n')
            .rev()
            .find(|l| !l.trim_ascii().is_empty()),
    );
    match (first, last) {
        (Some(a), Some(b)) if b.t_us >= a.t_us && b.t_us <= u64::MAX / 2 => tick_count(&[a, b]),
        _ => 0,
    }
}

/// An output file written as `PATH.partial` beside `PATH` (created on the first write or
/// flush) and renamed to `PATH` by [`PartialFile::commit`]; dropped without
/// a commit (the input failed), it is removed. So the text streams to disk as the node runs
/// (before, it was held in memory until the whole input had parsed: 3.6 times the input's
/// size) and a failed replay still leaves no output behind. A `PATH` that exists and is not a
/// regular file (`/dev/null`, a pipe) is written in place: renaming over it would replace the
/// device with a file (as root, `--out /dev/null` did).
struct PartialFile<'a> {
    path: &'a Path,
    /// Where the text goes until the commit: `PATH.partial`, or `PATH` itself.
    partial: std::path::PathBuf,
    in_place: bool,
    file: Option<std::fs::File>,
}

impl<'a> PartialFile<'a> {
    fn new(path: &'a Path) -> Self {
        let in_place = std::fs::metadata(path).is_ok_and(|m| !m.file_type().is_file());
        let mut name = path.as_os_str().to_owned();
        if !in_place {
            name.push(".partial");
        }
        Self {
            path,
            partial: name.into(),
            in_place,
            file: None,
        }
    }

    fn file(&mut self) -> std::io::Result<&mut std::fs::File> {
        if self.file.is_none() {
            let created = create_file(&self.partial).map_err(std::io::Error::other)?;
            self.file = Some(created);
        }
        self.file
            .as_mut()
            .ok_or_else(|| std::io::Error::other("file not created"))
    }

    /// The text is complete: `PATH.partial` becomes `PATH` (created empty if nothing was
    /// written).
    fn commit(mut self) -> Result<()> {
        self.file()?.flush()?;
        self.file = None;
        if self.in_place {
            return Ok(());
        }
        std::fs::rename(&self.partial, self.path).with_context(|| {
            format!(
                "renaming {} to {}",
                self.partial.display(),
                self.path.display()
            )
        })
    }
}

impl Drop for PartialFile<'_> {
    fn drop(&mut self) {
        if self.file.take().is_some() && !self.in_place {
            // Note: best effort; a partial file left behind is named as one.
            let _ = std::fs::remove_file(&self.partial);
        }
    }
}

impl Write for PartialFile<'_> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.file()?.write(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.file()?.flush()
    }
}

/// Frames parsed per piece handed to the node.
const PARSE_CHUNK_FRAMES: usize = 2048;

/// Where the node's input frames come from, in time order.
trait FrameSource {
    /// The time of the first frame; `None` if there is none.
    fn first_t_us(&mut self) -> Option<u64>;
    /// The next frame not taken yet if it is due at `now_us` (stamped at or before it).
    fn peek_due(&mut self, now_us: u64) -> Option<TimedFrame>;
    /// Takes the frame [`FrameSource::peek_due`] returned.
    fn take(&mut self);
    /// Whether frames remain.
    fn has_more(&mut self) -> bool;
    /// Whether the input is complete and valid, so that text may leave (checked after each
    /// tick); `None` while not known yet.
    fn input_ok(&self) -> Option<bool>;
    /// The input's error, if it had one.
    fn into_error(self) -> Option<anyhow::Error>;
}

/// Frames in memory.
struct SliceSource<'a> {
    frames: &'a [TimedFrame],
    next: usize,
}

impl FrameSource for SliceSource<'_> {
    fn first_t_us(&mut self) -> Option<u64> {
        self.frames.first().map(|f| f.t_us)
    }
    fn peek_due(&mut self, now_us: u64) -> Option<TimedFrame> {
        self.frames
            .get(self.next)
            .filter(|f| f.t_us <= now_us)
            .copied()
    }
    fn take(&mut self) {
        self.next += 1;
    }
    fn has_more(&mut self) -> bool {
        self.next < self.frames.len()
    }
    fn input_ok(&self) -> Option<bool> {
        Some(true)
    }
    fn into_error(self) -> Option<anyhow::Error> {
        None
    }
}

/// Frames arriving in pieces from the parser thread; an `Err` ends the input.
struct StreamSource {
    chunks: std::sync::mpsc::Receiver<Result<Vec<TimedFrame>>>,
    /// Frames received; `pending[next..]` not taken yet.
    pending: Vec<TimedFrame>,
    next: usize,
    finished: bool,
    error: Option<anyhow::Error>,
}

impl StreamSource {
    /// Waits for the next piece; false at the end of the input (or on its error).
    fn receive(&mut self) -> bool {
        if self.finished {
            return false;
        }
        match self.chunks.recv() {
            Ok(Ok(chunk)) => {
                self.pending.extend_from_slice(&chunk);
                true
            }
            Ok(Err(e)) => {
                self.error = Some(e);
                self.finished = true;
                false
            }
            // The parser sends its last piece, or its error, before it ends.
            Err(_) => {
                self.finished = true;
                false
            }
        }
    }
}

impl FrameSource for StreamSource {
    fn first_t_us(&mut self) -> Option<u64> {
        while self.pending.len() <= self.next {
            if !self.receive() {
                return None;
            }
        }
        self.pending.get(self.next).map(|f| f.t_us)
    }
    fn peek_due(&mut self, now_us: u64) -> Option<TimedFrame> {
        // Frames taken by earlier ticks are dropped now and then.
        if self.next > PARSE_CHUNK_FRAMES {
            self.pending.drain(..self.next);
            self.next = 0;
        }
        while self.pending.len() <= self.next {
            if !self.receive() {
                return None;
            }
        }
        self.pending
            .get(self.next)
            .filter(|f| f.t_us <= now_us)
            .copied()
    }
    fn take(&mut self) {
        self.next += 1;
    }
    fn has_more(&mut self) -> bool {
        while self.pending.len() <= self.next {
            if !self.receive() {
                return false;
            }
        }
        true
    }
    fn input_ok(&self) -> Option<bool> {
        match (self.finished, &self.error) {
            (false, _) => None,
            (true, None) => Some(true),
            (true, Some(_)) => Some(false),
        }
    }
    fn into_error(self) -> Option<anyhow::Error> {
        self.error
    }
}

/// What the node sends the text writer.
enum ToWriter {
    /// Ticks' times and frames.
    Batch(Vec<(u64, TxFrames)>),
    /// The input is complete and valid: text may leave.
    Release,
}

/// The node loop (this thread) and the text writer (a second one) over `source`.
fn run<S: FrameSource, C: Write + Send, T: Write + Send>(
    mut source: S,
    config: NodeConfig,
    csv: C,
    tx_log: Option<T>,
    stream: bool,
    mut progress: impl FnMut(u64),
) -> (ReplayStats, std::io::Result<()>, Option<anyhow::Error>) {
    let gnss_source = config.gnss_source;
    let mut speeds_over_max = SpeedsOverMax {
        max_speed_mps: config.max_speed_mps,
        ..SpeedsOverMax::default()
    };
    let mut report_intervals = ReportIntervals::steering_and_speed(&config);
    let mut directions = DirectionReports::default();
    let mut node = crate::new_node(config);
    // The times of the receiver's position frames, for the rate the whole log shows.
    let mut fix_times_us: Vec<u64> = Vec::new();
    // Positions of receivers at other source addresses, by address (refused as unknown ids).
    let mut other_sources = [0u64; 256];
    let (to_writer, messages) = std::sync::mpsc::sync_channel::<ToWriter>(8);
    let (to_node, spare) = std::sync::mpsc::channel::<Vec<(u64, TxFrames)>>();
    let mut frames = 0u64;
    let mut valid_ticks = 0u64;
    let mut max_speed_mps = 0.0f32;
    let mut steering_mismatch_ticks = 0u64;
    let mut origin_moves = 0u32;
    let mut planner = PlannerRefusals::default();
    let mut rx: Vec<TimedFrame> = Vec::with_capacity(MAX_RX_FRAMES_PER_TICK);
    let mut queue = crate::sil::RxQueue::default();
    let (written, ticks, input_ok) = std::thread::scope(|scope| {
        let writer = scope.spawn(move || {
            let mut out = TextOut::new(csv, tx_log);
            if stream {
                // The sinks are discarded on an input error ([`PartialFile`]): no need to hold.
                out.release();
            }
            for message in messages {
                match message {
                    ToWriter::Batch(mut batch) => {
                        for (now, tx) in &batch {
                            out.tick(*now, tx);
                        }
                        batch.clear();
                        // Note: the node may have finished; a lost spare batch costs nothing.
                        let _ = to_node.send(batch);
                    }
                    ToWriter::Release => out.release(),
                }
            }
            out.finish()
        });
        let mut released = false;
        let release = |source: &S, released: &mut bool| {
            if !*released && source.input_ok() == Some(true) {
                *released = true;
                let _ = to_writer.send(ToWriter::Release);
            }
        };
        let mut step = 0u64;
        let mut last_origin = None;
        if let Some(first_t_us) = source.first_t_us() {
            let mut now = first_tick_us(first_t_us);
            let mut batch = Vec::with_capacity(BATCH_TICKS);
            loop {
                let mut tx = TxFrames::new();
                // What the firmware's app does: the frames due arrive through the acceptance
                // filter into the receive queue (dropped when it is full), and the tick takes
                // at most the node's per-tick cap of them, the rest left queued.
                while let Some(f) = source.peek_due(now) {
                    queue.push(f);
                    source.take();
                }
                queue.take_tick(&mut rx);
                let tick = Tick {
                    now_us: now,
                    platform: PlatformStats {
                        rx_queue_drops: queue.drops(),
                        ..PlatformStats::default()
                    },
                };
                frames += rx.len() as u64;
                for f in &rx {
                    speeds_over_max.observe(&f.frame, f.t_us);
                    directions.observe(&f.frame, f.t_us);
                    ReportIntervals::observe_frame(&mut report_intervals, &f.frame, f.t_us);
                    match GnssPosition::decode(&f.frame, gnss_source) {
                        Ok(_) => fix_times_us.push(f.t_us),
                        Err(catmodel::can::codec::DecodeError::WrongSource { got }) => {
                            other_sources[usize::from(got)] += 1;
                        }
                        Err(_) => {}
                    }
                }
                let before = *node.drive().planner().counters();
                let estimate = node.step(&tick, &rx, &mut tx);
                planner.observe(
                    now,
                    &rx,
                    (&before, node.drive().planner().counters()),
                    node.drive().planner().car(),
                );
                if estimate.pose.is_some() {
                    valid_ticks += 1;
                }
                if estimate.speed_mps.is_finite() {
                    max_speed_mps = max_speed_mps.max(estimate.speed_mps);
                }
                if node.steering().mismatch() {
                    steering_mismatch_ticks += 1;
                }
                let origin = node.origin_e7();
                if origin != last_origin && last_origin.is_some() {
                    origin_moves += 1;
                }
                last_origin = origin;
                batch.push((now, tx));
                step += 1;
                if step.is_multiple_of(500) {
                    progress(step);
                }
                // The last tick is the one at or after the last frame once every frame is
                // taken (the QEMU run stops there too): another one follows while a frame
                // remains, in the log or in the queue.
                let more = source.has_more() || !queue.is_empty();
                if source.input_ok() == Some(false) {
                    break;
                }
                if batch.len() == BATCH_TICKS || !more {
                    release(&source, &mut released);
                    let fresh = spare
                        .try_recv()
                        .unwrap_or_else(|_| Vec::with_capacity(BATCH_TICKS));
                    // Note: the writer only stops when this side hangs up.
                    let _ = to_writer.send(ToWriter::Batch(std::mem::replace(&mut batch, fresh)));
                }
                if !more {
                    break;
                }
                now += SAMPLE_PERIOD_US;
            }
        }
        // No frame at all: the input is over (and valid unless it failed).
        let _ = source.has_more();
        release(&source, &mut released);
        drop(to_writer);
        let written = match writer.join() {
            Ok(result) => result,
            Err(panic) => std::panic::resume_unwind(panic),
        };
        (written, step, source.input_ok())
    });
    let stats = ReplayStats {
        frames,
        filtered: queue.filtered(),
        rx_queue_drops: queue.drops(),
        fixes: fix_times_us.len() as u64,
        other_gnss_sources: other_sources
            .iter()
            .enumerate()
            .filter(|(_, n)| **n > 0)
            .map(|(sa, n)| (sa as u8, *n))
            .collect(),
        unsupported: 0,
        ticks,
        valid_ticks,
        max_speed_mps,
        counters: *node.counters(),
        steering: *node.steering(),
        steering_mismatch_ticks,
        origin_e7: node.origin_e7(),
        origin_moves,
        fixes_beyond_frame: node.gnss_fixes_beyond_frame(),
        gnss_rate: crate::ReceiverRate::measure(&fix_times_us),
        planner,
        speeds_over_max,
        directions,
        report_intervals,
    };
    let error = if input_ok == Some(true) {
        None
    } else {
        source.into_error()
    };
    (stats, written, error)
}

/// The text a replay writes, tick by tick in the node's order, into buffers handed to the
/// sinks whenever they pass [`CHUNK_BYTES`].
struct TextOut<C, T> {
    csv_sink: C,
    tx_sink: Option<T>,
    csv: Vec<u8>,
    tx_log: Vec<u8>,
    step: u64,
    /// Text leaves only once released (the input known to be valid).
    released: bool,
    error: Option<std::io::Error>,
}

impl<C: Write, T: Write> TextOut<C, T> {
    fn new(csv_sink: C, tx_sink: Option<T>) -> Self {
        let mut csv = Vec::with_capacity(CHUNK_BYTES + 4096);
        csv.extend_from_slice(CSV_HEADER.as_bytes());
        let tx_log = Vec::with_capacity(if tx_sink.is_some() {
            CHUNK_BYTES + 4096
        } else {
            0
        });
        Self {
            csv_sink,
            tx_sink,
            csv,
            tx_log,
            step: 0,
            released: false,
            error: None,
        }
    }

    fn release(&mut self) {
        self.released = true;
    }

    fn tick(&mut self, now_us: u64, tx: &TxFrames) {
        if self.tx_sink.is_some() {
            for f in tx {
                text::push_candump_line(&mut self.tx_log, now_us, f);
                self.tx_log.push(b'\n');
            }
        }
        append_prediction_rows(&mut self.csv, now_us, self.step, tx);
        self.step += 1;
        if self.released && (self.csv.len() >= CHUNK_BYTES || self.tx_log.len() >= CHUNK_BYTES) {
            self.flush();
        }
    }

    fn flush(&mut self) {
        if self.error.is_none() {
            let mut result = self.csv_sink.write_all(&self.csv);
            if let (Ok(()), Some(sink)) = (&result, self.tx_sink.as_mut()) {
                result = sink.write_all(&self.tx_log);
            }
            self.error = result.err();
        }
        self.csv.clear();
        self.tx_log.clear();
    }

    fn finish(mut self) -> std::io::Result<()> {
        if !self.released {
            // The input failed: nothing leaves.
            return Ok(());
        }
        self.flush();
        if let Some(e) = self.error.take() {
            return Err(e);
        }
        self.csv_sink.flush()?;
        match self.tx_sink.as_mut() {
            Some(sink) => sink.flush(),
            None => Ok(()),
        }
    }
}

/// Decodes one tick's frames (what the planner receives, with its 1 cm / 1 mrad resolution)
/// into CSV rows: horizon 0 from STATE_POSITION + STATE_MOTION, then each prediction point.
/// The text is `format!`'s: `{t:.6},{step},{horizon_s:.2},{x:.2},{y:.2},{heading:.3},
/// {speed:.2},{mode}` with `t` and `horizon_s` f64, the rest f32.
fn append_prediction_rows(csv: &mut Vec<u8>, now_us: u64, step: u64, tx: &TxFrames) {
    let mut pos = None;
    let mut motion = None;
    let mut preds = [None; catmodel::node::MAX_TX_FRAMES];
    let mut n_preds = 0;
    for f in tx {
        if let Ok((p, _)) = StatePosition::decode(f) {
            pos = Some(p);
        } else if let Ok((m, _)) = StateMotion::decode(f) {
            motion = Some(m);
        } else if let Ok((p, _)) = Prediction::decode(f) {
            if let Some(slot) = preds.get_mut(n_preds) {
                *slot = Some(p);
                n_preds += 1;
            }
        }
    }
    let (Some(p), Some(m)) = (pos, motion) else {
        return;
    };
    let (Some(x), Some(y), Some(h), Some(v)) = (p.east_m, p.north_m, m.heading_rad, m.speed_mps)
    else {
        return;
    };
    let mode: &[u8] = match m.mode {
        ModelMode::Kinematic => b"kinematic\n",
        ModelMode::Dynamic => b"dynamic\n",
    };
    // `t,step,` is the same on every row of the tick: written once, then copied.
    let prefix_start = csv.len();
    text::push_f64_fixed(csv, now_us as f64 * 1e-6, 6);
    csv.push(b',');
    text::push_u64(csv, step);
    csv.push(b',');
    let prefix = prefix_start..csv.len();
    let mut first = true;
    let mut row = |horizon_s: f64, x: f32, y: f32, heading: f32, speed: f32| {
        if !first {
            csv.extend_from_within(prefix.clone());
        }
        first = false;
        text::push_f64_fixed(csv, horizon_s, 2);
        csv.push(b',');
        text::push_f32_fixed(csv, x, 2);
        csv.push(b',');
        text::push_f32_fixed(csv, y, 2);
        csv.push(b',');
        text::push_f32_fixed(csv, heading, 3);
        csv.push(b',');
        text::push_f32_fixed(csv, speed, 2);
        csv.push(b',');
        csv.extend_from_slice(mode);
    };
    row(0.0, x, y, h, v);
    for q in preds.iter().flatten() {
        let (Some(dx), Some(dy), Some(dh), Some(speed)) =
            (q.dx_m, q.dy_m, q.dheading_rad, q.speed_mps)
        else {
            continue;
        };
        let horizon_s = q.point.horizon_us() as f64 * 1e-6;
        let heading = catmodel::math::wrap_pi(h + dh);
        row(horizon_s, x + dx, y + dy, heading, speed);
    }
}

/// Creates `path` for writing (its directory must exist: the CLI refuses a missing one before
/// it starts, [`crate::outputs`]).
pub fn create_file(path: &Path) -> Result<std::fs::File> {
    std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))
}

/// Writes `text` to `path` (its directory must exist, as for [`create_file`]).
pub fn write_file(path: &Path, text: &str) -> Result<()> {
    let mut f =
        std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
    f.write_all(text.as_bytes())
        .with_context(|| format!("writing {}", path.display()))
}

/// Hand-written text formatting for the replay's output, byte-identical to `format!`.
mod text {
    use super::{CanFrame, CanId};

    /// The buffer as a `String` (everything written here is ASCII).
    pub fn into_string(bytes: Vec<u8>) -> String {
        String::from_utf8(bytes).unwrap_or_else(|e| String::from_utf8_lossy(e.as_bytes()).into())
    }

    /// Appends `v` in decimal, at least `min_digits` digits (zero-padded): `{v:0min_digits$}`.
    #[inline]
    pub fn push_u64_padded(out: &mut Vec<u8>, mut v: u64, min_digits: usize) {
        let mut buf = [0u8; 24];
        let mut i = buf.len();
        while i > 0 && (v != 0 || buf.len() - i < min_digits.max(1)) {
            i -= 1;
            if let Some(b) = buf.get_mut(i) {
                *b = b'0' + (v % 10) as u8;
            }
            v /= 10;
        }
        out.extend_from_slice(buf.get(i..).unwrap_or_default());
    }

    /// Appends `v` in decimal: `{v}`.
    #[inline]
    pub fn push_u64(out: &mut Vec<u8>, v: u64) {
        push_u64_padded(out, v, 1);
    }

    const POW10: [u128; 7] = [1, 10, 100, 1_000, 10_000, 100_000, 1_000_000];

    /// Appends `(-1)^neg * m * 2^e` with `decimals` digits after the point, rounded half to
    /// even on the exact value (what `format!("{:.N}")` does); `false` (nothing written) for
    /// magnitudes beyond what this handles (>= 2^40 * 2^53), left to `format!`.
    #[inline]
    fn push_fixed(out: &mut Vec<u8>, neg: bool, m: u64, e: i32, decimals: usize) -> bool {
        let Some(&pow) = POW10.get(decimals) else {
            return false;
        };
        // m < 2^53 and pow <= 10^6 < 2^20: p < 2^73.
        let p = u128::from(m) * pow;
        let q = if e >= 0 {
            if e > 40 {
                return false;
            }
            p << e
        } else if e <= -100 {
            // p * 2^e < 2^-27: rounds to 0.
            0
        } else {
            let s = e.unsigned_abs();
            let q = p >> s;
            let r = p & ((1u128 << s) - 1);
            let half = 1u128 << (s - 1);
            if r > half || (r == half && q & 1 == 1) {
                q + 1
            } else {
                q
            }
        };
        let Ok(q) = u64::try_from(q) else {
            return false;
        };
        if neg {
            out.push(b'-');
        }
        let scale = POW10.get(decimals).map_or(1, |&p| p as u64);
        push_u64(out, q / scale);
        if decimals > 0 {
            out.push(b'.');
            push_u64_padded(out, q % scale, decimals);
        }
        true
    }

    /// Appends `format!("{v:.decimals$}")` for an `f32`.
    #[inline]
    pub fn push_f32_fixed(out: &mut Vec<u8>, v: f32, decimals: usize) {
        let bits = v.to_bits();
        let neg = bits >> 31 != 0;
        let exp = ((bits >> 23) & 0xFF) as i32;
        let frac = u64::from(bits & 0x7F_FFFF);
        let done = match exp {
            0xFF => false,
            0 => push_fixed(out, neg, frac, -149, decimals),
            _ => push_fixed(out, neg, frac | 0x80_0000, exp - 150, decimals),
        };
        if !done {
            use std::io::Write as _;
            let _ = write!(out, "{v:.decimals$}");
        }
    }

    /// Appends `format!("{v:.decimals$}")` for an `f64`.
    #[inline]
    pub fn push_f64_fixed(out: &mut Vec<u8>, v: f64, decimals: usize) {
        let bits = v.to_bits();
        let neg = bits >> 63 != 0;
        let exp = ((bits >> 52) & 0x7FF) as i32;
        let frac = bits & 0xF_FFFF_FFFF_FFFF;
        let done = match exp {
            0x7FF => false,
            0 => push_fixed(out, neg, frac, -1074, decimals),
            _ => push_fixed(out, neg, frac | 0x10_0000_0000_0000, exp - 1075, decimals),
        };
        if !done {
            use std::io::Write as _;
            let _ = write!(out, "{v:.decimals$}");
        }
    }

    const HEX: &[u8; 16] = b"0123456789ABCDEF";

    /// Appends `v`'s low `digits` hex digits, upper case.
    #[inline]
    fn push_hex(out: &mut Vec<u8>, v: u32, digits: u32) {
        for k in (0..digits).rev() {
            let nibble = (v >> (4 * k)) & 0xF;
            out.push(HEX.get(nibble as usize).copied().unwrap_or(b'0'));
        }
    }

    /// Appends one candump line without its line end, exactly as
    /// [`catmodel::can::candump::format_line`] writes it on [`super::IFACE`].
    pub fn push_candump_line(out: &mut Vec<u8>, t_us: u64, frame: &CanFrame) {
        out.push(b'(');
        push_u64_padded(out, t_us / 1_000_000, 10);
        out.push(b'.');
        push_u64_padded(out, t_us % 1_000_000, 6);
        out.extend_from_slice(b") ");
        out.extend_from_slice(super::IFACE.as_bytes());
        out.push(b' ');
        match frame.id {
            // `{:03X}`: at least 3 digits (a valid id has 3; wider ones print in full).
            CanId::Standard(id) => push_hex(out, u32::from(id), if id > 0xFFF { 4 } else { 3 }),
            CanId::Extended(id) => push_hex(out, id, 8),
        }
        out.push(b'#');
        for &byte in frame.payload() {
            push_hex(out, u32::from(byte), 2);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use std::fmt::Write as _;

    fn at(t_us: u64) -> TimedFrame {
        TimedFrame {
            t_us,
            frame: CanFrame::new(catmodel::can::CanId::Standard(0x555), &[]).unwrap(),
        }
    }

    #[test]
    fn tick_count_matches_the_ticks_replay_runs() {
        assert_eq!(tick_count(&[]), 0);
        // Ticks at 20 000 (first frame 1 us rounded up) .. 100 000 (last frame 80 001 us).
        let frames = [at(1), at(50_000), at(80_001)];
        assert_eq!(tick_count(&frames), 5);
        let config = crate::model_file::paper().node_config();
        let mut calls = Vec::new();
        let out = replay_with_progress(&frames, config, ReplayText::default(), |n| calls.push(n));
        assert_eq!(out.ticks, 5);
        assert!(calls.is_empty(), "progress every 500 ticks only");
        // A frame exactly on a tick: that tick is the last.
        assert_eq!(tick_count(&[at(20_000), at(40_000)]), 2);
    }

    #[test]
    fn candump_errors_read_as_words() {
        let e = candump::parse_line("(1.000000) can0 100#ABC").unwrap_err();
        assert_eq!(candump_reason(e), "odd number of data hex digits");
    }

    fn fmt_f32(v: f32, d: usize) -> String {
        let mut out = Vec::new();
        text::push_f32_fixed(&mut out, v, d);
        String::from_utf8(out).unwrap()
    }

    fn fmt_f64(v: f64, d: usize) -> String {
        let mut out = Vec::new();
        text::push_f64_fixed(&mut out, v, d);
        String::from_utf8(out).unwrap()
    }

    /// The fixed-point formatter against `format!` on hand-picked cases: ties (round half to
    /// even on the exact binary value), signs of zero, subnormals, the fallbacks.
    #[test]
    fn fixed_formatting_equals_format_on_edge_cases() {
        let f32s = [
            0.0f32,
            -0.0,
            0.125,
            0.375,
            -0.125,
            0.005,
            0.015,
            0.025,
            -0.001,
            1e-30,
            -1e-30,
            f32::MIN_POSITIVE,
            1e-45,
            0.5,
            1.5,
            2.5,
            9.995,
            99.995,
            0.0005,
            0.0015,
            123456.79,
            16_777_216.0,
            3.0e12,
            1.0e30,
            -3.4e38,
            f32::MAX,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            std::f32::consts::PI,
            -std::f32::consts::PI,
        ];
        for v in f32s {
            for d in [0, 1, 2, 3, 6] {
                assert_eq!(fmt_f32(v, d), format!("{v:.d$}"), "{v:e} .{d}");
            }
        }
        let f64s = [
            0.0f64,
            -0.0,
            0.125,
            0.005,
            0.015,
            2.5e-7,
            1.5e-6,
            0.0000005,
            1e-300,
            5e-324,
            1.0e15,
            1.0e20,
            1.0e300,
            f64::MAX,
            f64::NAN,
            f64::INFINITY,
            299.99999949999997,
            0.2,
            1.4,
            1e-6 * 123_456_789.0,
        ];
        for v in f64s {
            for d in [0, 1, 2, 3, 6] {
                assert_eq!(fmt_f64(v, d), format!("{v:.d$}"), "{v:e} .{d}");
            }
        }
    }

    /// ... and on a million random bit patterns of each width, biased towards the magnitudes
    /// the CSV carries (|v| < 2^20), plus the CSV's own values: sums of 1 cm steps.
    #[test]
    fn fixed_formatting_equals_format_on_random_values() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for i in 0..1_000_000u32 {
            let bits: u32 = rng.gen();
            let v = if i % 2 == 0 {
                f32::from_bits(bits)
            } else {
                // Exponent in [2^-30, 2^20).
                f32::from_bits((bits & 0x807F_FFFF) | ((97 + (bits >> 23) % 50) << 23))
            };
            let d = [2, 3][(i % 2) as usize];
            assert_eq!(fmt_f32(v, d), format!("{v:.d$}"), "{v:e} .{d}");
            let cm = (rng.gen_range(-1_000_000i32..1_000_000) as f32) * 0.01
                + (rng.gen_range(-8_000i32..8_000) as f32) * 0.01;
            assert_eq!(fmt_f32(cm, 2), format!("{cm:.2}"), "{cm:e}");
            let bits: u64 = rng.gen();
            let w = if i % 2 == 0 {
                f64::from_bits(bits)
            } else {
                f64::from_bits((bits & 0x800F_FFFF_FFFF_FFFF) | ((993 + (bits >> 52) % 60) << 52))
            };
            let d = [2, 6][(i % 2) as usize];
            assert_eq!(fmt_f64(w, d), format!("{w:.d$}"), "{w:e} .{d}");
            let t = rng.gen_range(0..10_000_000_000u64) as f64 * 1e-6;
            assert_eq!(fmt_f64(t, 6), format!("{t:.6}"), "{t:e}");
        }
    }

    #[test]
    fn candump_lines_equal_the_core_formatter() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for i in 0..100_000u32 {
            let id = if i % 2 == 0 {
                CanId::Standard(rng.gen_range(0..=0x7FF))
            } else {
                CanId::Extended(rng.gen_range(0..=0x1FFF_FFFF))
            };
            let len = rng.gen_range(0..=8usize);
            let data: Vec<u8> = (0..len).map(|_| rng.gen()).collect();
            let t_us = match i % 3 {
                0 => rng.gen_range(0..100_000_000),
                1 => rng.gen(),
                _ => rng.gen_range(0..u64::MAX / 2),
            };
            let f = TimedFrame {
                t_us,
                frame: CanFrame::new(id, &data).unwrap(),
            };
            let mut expected = String::new();
            candump::format_line(&f, IFACE, &mut expected).unwrap();
            assert_eq!(candump_line(t_us, &f.frame), expected);
        }
    }

    /// The CSV as the straightforward `format!` version wrote it (before the hand-written
    /// formatters), from the same frames.
    fn reference_rows(csv: &mut String, now_us: u64, step: u64, tx: &TxFrames) {
        let (mut pos, mut motion, mut preds) = (None, None, Vec::new());
        for f in tx {
            if let Ok((p, _)) = StatePosition::decode(f) {
                pos = Some(p);
            } else if let Ok((m, _)) = StateMotion::decode(f) {
                motion = Some(m);
            } else if let Ok((p, _)) = Prediction::decode(f) {
                preds.push(p);
            }
        }
        let (Some(p), Some(m)) = (pos, motion) else {
            return;
        };
        let (Some(x), Some(y), Some(h), Some(v)) =
            (p.east_m, p.north_m, m.heading_rad, m.speed_mps)
        else {
            return;
        };
        let mode = match m.mode {
            ModelMode::Kinematic => "kinematic",
            ModelMode::Dynamic => "dynamic",
        };
        let t = now_us as f64 * 1e-6;
        writeln!(csv, "{t:.6},{step},0.00,{x:.2},{y:.2},{h:.3},{v:.2},{mode}").unwrap();
        for q in preds {
            let (Some(dx), Some(dy), Some(dh), Some(speed)) =
                (q.dx_m, q.dy_m, q.dheading_rad, q.speed_mps)
            else {
                continue;
            };
            let horizon_s = q.point.horizon_us() as f64 * 1e-6;
            let heading = catmodel::math::wrap_pi(h + dh);
            writeln!(
                csv,
                "{t:.6},{step},{horizon_s:.2},{:.2},{:.2},{heading:.3},{speed:.2},{mode}",
                x + dx,
                y + dy
            )
            .unwrap();
        }
    }

    /// The whole replay of the bundled drive: CSV and TX log byte-identical to the `format!`
    /// versions over the same node run.
    #[test]
    fn replay_text_equals_the_format_reference_on_the_bundled_drive() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/bundled.can.log");
        let frames = read_candump(&path).unwrap();
        let config = crate::model_file::paper().node_config();
        let out = replay(&frames, config.clone());
        let mut csv = String::from(CSV_HEADER);
        let mut tx_log = String::new();
        let mut node = crate::new_node(config);
        let (mut now, mut next, mut step) = (first_tick_us(frames[0].t_us), 0, 0);
        let mut tx = TxFrames::new();
        while now <= first_tick_us(frames.last().unwrap().t_us) {
            let start = next;
            while next < frames.len() && frames[next].t_us <= now {
                next += 1;
            }
            tx.clear();
            let tick = Tick {
                now_us: now,
                platform: PlatformStats::default(),
            };
            node.step(&tick, &frames[start..next], &mut tx);
            for f in &tx {
                let tf = TimedFrame {
                    t_us: now,
                    frame: *f,
                };
                candump::format_line(&tf, IFACE, &mut tx_log).unwrap();
                tx_log.push('\n');
            }
            reference_rows(&mut csv, now, step, &tx);
            step += 1;
            now += SAMPLE_PERIOD_US;
        }
        assert_eq!(out.ticks, step);
        assert!(csv.lines().count() > 5_000, "a real drive");
        assert!(out.predictions_csv == csv, "predictions CSV differs");
        assert!(out.tx_log == tx_log, "TX log differs");
        let no_tx = replay_with_progress(
            &frames,
            node.config().clone(),
            ReplayText::default(),
            |_| {},
        );
        assert_eq!(no_tx.predictions_csv, csv);
        assert!(no_tx.tx_log.is_empty());
    }

    /// Parsing ahead of the node gives the same text as parsing first; an error anywhere in
    /// the log (here the very last line) gives `read_candump`'s error and no text at all.
    #[test]
    fn streamed_parsing_equals_parsing_first() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/bundled.can.log");
        let text = std::fs::read_to_string(&path).unwrap();
        let frames = read_candump(&path).unwrap();
        let config = crate::model_file::paper().node_config();
        let (mut csv_a, mut tx_a, mut csv_b, mut tx_b) = (vec![], vec![], vec![], vec![]);
        let a = replay_into(&frames, config.clone(), &mut csv_a, Some(&mut tx_a), |_| {}).unwrap();
        let b = replay_text_into(
            &path,
            &text,
            config.clone(),
            &mut csv_b,
            Some(&mut tx_b),
            |_| {},
        )
        .unwrap();
        assert_eq!(a, b);
        assert_eq!(b.frames, frames.len() as u64);
        assert!(csv_a == csv_b && tx_a == tx_b);
        assert!(csv_a.len() > 100_000);

        let bad = format!("{text}(9999999999.000000) can0 100#0G\n");
        let (mut csv, mut tx) = (vec![], vec![]);
        let err = replay_text_into(&path, &bad, config.clone(), &mut csv, Some(&mut tx), |_| {})
            .unwrap_err();
        let lines = text.lines().count() + 1;
        let expected = format!(
            "{}:{lines}: malformed candump line (data is not hex)",
            path.display()
        );
        assert!(err.to_string().starts_with(&expected), "{err}");
        assert!(csv.is_empty() && tx.is_empty());
        // An empty log: the header only.
        let mut csv = vec![];
        let s =
            replay_text_into(&path, "", config, &mut csv, None::<&mut Vec<u8>>, |_| {}).unwrap();
        assert_eq!((s.ticks, csv.as_slice()), (0, CSV_HEADER.as_bytes()));
    }

    /// The in-memory parser and the line-by-line reader agree, blank lines and CRLF included,
    /// and a line that is not UTF-8 is named.
    #[test]
    fn log_reading_paths_agree() {
        let dir = std::env::temp_dir().join(format!("catmodel-replay-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let text = "(0000000001.000000) can0 100#01\r\n\n  \n(0000000001.500000) can0 18FEF100#0102\n(2.000000) vcan1 7FF#";
        let p = dir.join("a.log");
        std::fs::write(&p, text).unwrap();
        let fast = read_candump(&p).unwrap();
        let slow = parse_candump_bytes(&p, text.as_bytes(), None)
            .unwrap()
            .frames;
        assert_eq!(fast, slow);
        assert_eq!(fast.len(), 3);
        assert_eq!(fast[2].t_us, 2_000_000);
        // The selecting reader: every frame kept, the same log and report; one identifier
        // kept, its frames alone, the report still of every line.
        let whole = read_candump_log(&p).unwrap();
        assert_eq!(read_candump_selected(&p, None, |_| true).unwrap(), whole);
        let one = read_candump_selected(&p, None, |f| f.id == CanId::Standard(0x100)).unwrap();
        assert_eq!(one.frames, whole.frames[..1]);
        assert_eq!(one.report, whole.report);
        let mut bad = text.as_bytes().to_vec();
        bad.extend_from_slice(b"\n(3.000000) can0 100#\xff\n");
        std::fs::write(&p, &bad).unwrap();
        let err = format!("{:#}", read_candump(&p).unwrap_err());
        assert!(err.contains("a.log:6: reading"), "{err}");
        let err = format!(
            "{:#}",
            read_candump_selected(&p, None, |_| true).unwrap_err()
        );
        assert!(err.contains("a.log:6: reading"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Remote, CAN FD and error frames (`candump -e`) are skipped and counted by every reader,
    /// as the firmware's receive path skips them, instead of refusing the log; replay reports
    /// them; the node gets the same frames as without them.
    /// Replay sums up the planner's refusals as `sil` does (the same [`PlannerRefusals`]): a
    /// path whose points are 0.05 m apart, 0.04 m once PATH_POINT has rounded them.
    #[test]
    fn planner_refusals_are_summed_up_as_in_sil() {
        let frames: Vec<TimedFrame> = crate::closed_loop::planner::straight_path_frames(6, 0.05)
            .into_iter()
            .map(|frame| TimedFrame {
                t_us: 1_000_000,
                frame,
            })
            .collect();
        let config = crate::node_config(None).unwrap();
        let stats = replay_into(&frames, config, Vec::new(), None::<Vec<u8>>, |_| {}).unwrap();
        assert_eq!(stats.planner.counters.paths_invalid, 1);
        let text = stats.planner.to_string();
        assert!(
            text.contains("1 refused (invalid paths 1")
                && text.contains("path 0 refused: points 1 and 2 are 0.040 m apart"),
            "{text}"
        );
    }

    #[test]
    fn unsupported_frames_are_skipped_and_counted() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/smoke.can.log");
        let text = std::fs::read_to_string(&path).unwrap();
        let mut with = String::new();
        for (i, line) in text.lines().enumerate() {
            with.push_str(line);
            with.push('\n');
            if i % 100 == 7 {
                let stamp = &line[..line.find(')').unwrap() + 1];
                with.push_str(&format!("{stamp} can0 20000080#0000000000000000\n"));
                with.push_str(&format!("{stamp} can0 100#R\n"));
                with.push_str(&format!("{stamp} can0 100##1DEADBEEF\n"));
            }
        }
        let plain = parse_candump_log(&path, &text).unwrap();
        let log = parse_candump_log(&path, &with).unwrap();
        assert_eq!(plain.unsupported, 0);
        assert_eq!(log.frames, plain.frames);
        let inserted = 3 * (0..text.lines().count()).filter(|i| i % 100 == 7).count();
        assert_eq!(log.unsupported, inserted as u64);
        let config = crate::model_file::paper().node_config();
        let (mut csv_a, mut csv_b) = (vec![], vec![]);
        let a = replay_text_into(
            &path,
            &text,
            config.clone(),
            &mut csv_a,
            None::<&mut Vec<u8>>,
            |_| {},
        )
        .unwrap();
        let b = replay_text_into(
            &path,
            &with,
            config,
            &mut csv_b,
            None::<&mut Vec<u8>>,
            |_| {},
        )
        .unwrap();
        assert_eq!((a.unsupported, b.unsupported), (0, inserted as u64));
        assert_eq!(
            ReplayStats {
                unsupported: 0,
                ..b
            },
            a
        );
        assert_eq!(csv_a, csv_b);
    }

    /// Speed reports above the model file's `max_speed_mps` are counted and named (black-box
    /// probe: the 5-minute drive's reports up to 10 m/s against a file's 5 m/s were clamped
    /// without a word); the node's frames are the same as without the count; under the limit,
    /// nothing is said.
    #[test]
    fn speeds_above_the_model_files_limit_are_counted() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/smoke.can.log");
        let text = std::fs::read_to_string(&path).unwrap();
        let run = |max: f32| {
            let mut config = crate::model_file::paper().node_config();
            config.max_speed_mps = max;
            let mut csv = vec![];
            let stats =
                replay_text_into(&path, &text, config, &mut csv, None::<&mut Vec<u8>>, |_| {})
                    .unwrap();
            (stats, csv)
        };
        let (within, _) = run(60.0);
        assert_eq!(within.speeds_over_max.reports, 0);
        assert_eq!(speed_note(&within), None);
        let (over, _) = run(3.0);
        let s = over.speeds_over_max;
        assert!(s.reports > 10, "{s:?}");
        assert!(s.fastest_mps > 3.0 && s.fastest_mps < 20.0, "{s:?}");
        let note = speed_note(&over).unwrap();
        assert!(
            note.starts_with(&format!(
                "{} speed report(s) (SPEED_REPORT) were above the model file's max_speed_mps \
                 (3 m/s), up to {:.2} m/s",
                s.reports, s.fastest_mps
            )) && note.contains("the node clamps its speed to 3 m/s"),
            "{note}"
        );
    }

    /// A forward clock jump beyond a day (a clock step, logs joined) is refused with its line,
    /// instead of ticking through it for hours; a day's pause is replayed.
    /// The tracker's counts: a batch is one timestamp; a message twice in it is a repeat; a
    /// step of two ticks or more between timestamps is coarse.
    #[test]
    fn timestamps_in_batches_are_counted() {
        let id = |n: u16| CanId::Standard(n);
        let mut stats = TimestampStats::default();
        let mut tracker = TimestampTracker::default();
        for (t, n) in [
            (0, 1),
            (0, 2),
            (0, 1),
            (50_000, 1),
            (50_000, 1),
            (60_000, 3),
        ] {
            tracker.observe(&mut stats, t, id(n));
        }
        assert_eq!(
            stats,
            TimestampStats {
                frames: 6,
                instants: 3,
                coarse_steps: 1,
                repeats: 2,
                first_us: 0,
                last_us: 60_000,
            }
        );
        assert!(!stats.batched(), "too few to judge");
        // 100 batches of 50 ms, each with a message twice: batched.
        let (mut stats, mut tracker) = (TimestampStats::default(), TimestampTracker::default());
        for k in 0..100 {
            for n in [1, 2, 1] {
                tracker.observe(&mut stats, k * 50_000, id(n));
            }
        }
        assert!(stats.batched(), "{stats:?}");
        assert!(stats
            .warning("x.log")
            .unwrap()
            .starts_with("x.log: the timestamps come in batches"));
        // The same steps with no message twice at one timestamp: a slow bus, not batches.
        let (mut stats, mut tracker) = (TimestampStats::default(), TimestampTracker::default());
        for k in 0..100 {
            for n in [1, 2] {
                tracker.observe(&mut stats, k * 50_000, id(n));
            }
        }
        assert!(!stats.batched(), "{stats:?}");
        assert_eq!(stats.warning("x.log"), None);
    }

    #[test]
    fn a_clock_jump_beyond_a_day_is_refused_with_its_line() {
        let path = Path::new("jump.log");
        let day = MAX_LOG_PAUSE_US / 1_000_000;
        let ok = format!("(1.000000) can0 100#01\n({}.000000) can0 100#01\n", 1 + day);
        assert_eq!(parse_candump(path, &ok).unwrap().len(), 2);
        let jump = format!(
            "(1.000000) can0 100#01\n(1.020000) can0 100#01\n({}.000000) can0 100#01\n",
            1_700_000_000u64
        );
        let err = format!("{:#}", parse_candump(path, &jump).unwrap_err());
        assert!(
            err.starts_with("jump.log:3: the clock jumps 1699999999 s forward")
                && err.contains("split the log"),
            "{err}"
        );
    }

    /// `replay`'s files stream to `.partial` files renamed at the end; an input error (here
    /// on the last line) leaves neither the files nor their partial forms.
    #[test]
    fn output_files_appear_only_for_a_valid_log() {
        let dir = std::env::temp_dir().join(format!("catmodel-partial-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        // The output directory exists: the CLI refuses a missing one ([`crate::outputs`]).
        std::fs::create_dir_all(dir.join("out")).unwrap();
        let log = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/smoke.can.log");
        let text = std::fs::read(&log).unwrap();
        let config = crate::model_file::paper().node_config();
        let (csv, tx) = (dir.join("out/p.csv"), dir.join("out/tx.log"));
        let mut bad = text.clone();
        bad.extend_from_slice(b"(9999999999.000000) can0 100#0G\n");
        let err =
            replay_file(&log, &bad, None, config.clone(), &csv, Some(&tx), |_| {}).unwrap_err();
        assert!(err.to_string().contains("data is not hex"), "{err}");
        let left: Vec<_> = std::fs::read_dir(dir.join("out"))
            .map(|d| d.map(|e| e.unwrap().file_name()).collect())
            .unwrap_or_default();
        assert!(left.is_empty(), "{left:?}");
        let (stats, _) = replay_file(&log, &text, None, config, &csv, Some(&tx), |_| {}).unwrap();
        let mut names: Vec<_> = std::fs::read_dir(dir.join("out"))
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        names.sort();
        assert_eq!(names, ["p.csv", "tx.log"]);
        let lines = std::fs::read_to_string(&tx).unwrap().lines().count() as u64;
        assert_eq!(lines, 14 * stats.ticks);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// An output that is not a regular file is written in place, never renamed over: as root,
    /// `--out /dev/null` once replaced the device with a regular file.
    #[test]
    #[cfg(unix)]
    fn an_output_device_is_written_in_place() {
        use std::os::unix::fs::FileTypeExt;
        let null = Path::new("/dev/null");
        assert!(std::fs::metadata(null)
            .unwrap()
            .file_type()
            .is_char_device());
        let log = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/smoke.can.log");
        let text = std::fs::read(&log).unwrap();
        let config = crate::model_file::paper().node_config();
        replay_file(&log, &text, None, config, null, Some(null), |_| {}).unwrap();
        assert!(std::fs::metadata(null)
            .unwrap()
            .file_type()
            .is_char_device());
        assert!(!Path::new("/dev/null.partial").exists());
    }
}
