//! `catmodel sil --stdio`: lockstep software-in-the-loop over stdin/stdout, so that any
//! simulator (ours, Gazebo, CARLA, a script) can close the loop around the very same node
//! (README, "Software in the loop").
//!
//! Input, one item per line: a candump line (a frame the node reads), or `TICK SECONDS.UUUUUU`.
//! On `TICK T` the node runs its tick at time T with the frames given since the previous tick,
//! through the firmware's receive path ([`RxQueue`]): the acceptance filter, a queue of
//! [`RX_QUEUE_LEN`] frames (a frame given to a full queue is dropped and counted,
//! NODE_STATUS's `rx_queue_drops`), and at most [`MAX_RX_FRAMES_PER_TICK`] frames a tick, in
//! the order given, the rest left queued for the next tick (frames stamped after T are the
//! node's to reject, as on the bus). It writes that tick's frames as candump lines stamped T,
//! then the line `END SECONDS.UUUUUU` (T in the candump timestamp format), and flushes.
//! Remote, CAN FD and error frames are skipped and counted, as the firmware's receive path
//! skips them; blank lines are skipped (as in `replay`). End of input: success, and a summary
//! of the frames not given to the node, of the node's rejections and of its planner's
//! refusals with the first one's reason, a path it was still receiving, and a last line cut
//! short without a line end that does not parse (left out, as replay leaves out a log's)
//! ([`SilSummary`]). A malformed line (not UTF-8, neither
//! a candump line nor a TICK), or a TICK beyond year 292 000 or off the node's tick schedule
//! (the first on a whole multiple of 20 ms, each next one 20 ms after the previous:
//! [`check_tick_schedule`]): an error naming the line number (quoting at most 80 characters of
//! it, or the TICK expected), and nothing more is read.
use std::collections::VecDeque;
use std::io::{BufRead, Read, Write};

use catmodel::can::spec::is_node_input;
use catmodel::can::{candump, CanFrame, TimedFrame};
use catmodel::node::{
    first_tick_us, Counters, PlatformStats, Tick, MAX_RX_FRAMES_PER_TICK, RX_QUEUE_LEN,
};
use catmodel::SAMPLE_PERIOD_US;

use crate::closed_loop::driver::Driver;
use crate::planner_refusals::PlannerRefusals;
use crate::replay::{candump_line, candump_reason, TimestampStats, TimestampTracker};

/// Why a session stopped early.
#[derive(Debug)]
pub enum SilError {
    /// Line `line` (1-based) is neither a candump line nor a valid TICK.
    Malformed {
        /// Line number.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// Reading stdin or writing stdout failed.
    Io(std::io::Error),
}

impl std::fmt::Display for SilError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SilError::Malformed { line, reason } => write!(f, "stdin:{line}: {reason}"),
            SilError::Io(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for SilError {}

/// The firmware's receive path between the bus and the tick (the app's `receive_loop` and
/// `drain_due`), so that a session gives the node the frames the firmware would: frames that are
/// not node inputs are refused (the acceptance filter, counted in [`RxQueue::filtered`]); a
/// frame given to a full queue of [`RX_QUEUE_LEN`] is dropped and counted
/// ([`PlatformStats::rx_queue_drops`], on the bus); each tick takes at most
/// [`MAX_RX_FRAMES_PER_TICK`] frames, oldest first.
#[derive(Debug, Default)]
pub struct RxQueue {
    frames: VecDeque<TimedFrame>,
    drops: u32,
    filtered: u64,
    unsupported: u64,
}

impl RxQueue {
    /// A frame arrives.
    pub fn push(&mut self, frame: TimedFrame) {
        if !is_node_input(frame.frame.id) {
            self.filtered += 1;
        } else if self.frames.len() < RX_QUEUE_LEN {
            self.frames.push_back(frame);
        } else {
            self.drops = self.drops.saturating_add(1);
        }
    }

    /// The next tick's frames (cleared first): the oldest, at most [`MAX_RX_FRAMES_PER_TICK`].
    pub fn take_tick(&mut self, rx: &mut Vec<TimedFrame>) {
        rx.clear();
        let n = self.frames.len().min(MAX_RX_FRAMES_PER_TICK);
        rx.extend(self.frames.drain(..n));
    }

    /// Frames dropped because the queue was full, since the start.
    pub fn drops(&self) -> u32 {
        self.drops
    }

    /// Frames refused by the acceptance filter, since the start.
    pub fn filtered(&self) -> u64 {
        self.filtered
    }

    /// Frames waiting.
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    /// Whether no frame waits.
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }
}

/// `SECONDS.UUUUUU` as the candump timestamp writes it (seconds zero-padded to 10 digits).
fn timestamp(t_us: u64) -> String {
    format!("{:010}.{:06}", t_us / 1_000_000, t_us % 1_000_000)
}

/// The longest input line taken, bytes: a classic candump line is under 60, a CAN FD one
/// under 200.
pub const MAX_LINE_BYTES: usize = 4096;

/// Runs a session: reads `input` to its end, ticking `driver`, writing to `output`. Returns
/// what it did.
pub fn run(
    driver: &mut dyn Driver,
    mut input: impl BufRead,
    mut output: impl Write,
) -> Result<SilSummary, SilError> {
    let mut queue = RxQueue::default();
    let mut rx: Vec<TimedFrame> = Vec::with_capacity(MAX_RX_FRAMES_PER_TICK);
    let mut last_tick: Option<u64> = None;
    let mut ticks = 0;
    let mut tx: Vec<CanFrame> = Vec::new();
    let mut bytes = Vec::new();
    // As replay: are the frames stamped in batches coarser than the tick?
    let mut timestamps = TimestampStats::default();
    let mut tracker = TimestampTracker::default();
    let mut planner = PlannerRefusals::default();
    let mut cut_line = None;
    for line_no in 1.. {
        bytes.clear();
        let read = (&mut input)
            .take(MAX_LINE_BYTES as u64 + 1)
            .read_until(b'\n', &mut bytes)
            .map_err(SilError::Io)?;
        if read == 0 {
            break;
        }
        // The last line without its line end: the simulator stopped mid-write. Left out
        // and named if it does not parse (as replay leaves out a log's cut last line).
        let cut = bytes.last() != Some(&b'\n');
        let malformed = |reason: String| SilError::Malformed {
            line: line_no,
            reason,
        };
        let cut_or = |e: SilError| if cut { Ok(line_no) } else { Err(e) };
        if bytes.len() > MAX_LINE_BYTES {
            // Refused after the cap, not after the line: a line without an end (a simulator
            // writing binary, a stream cut of its newlines) would otherwise be held in memory
            // whole (200 MB for a 200 MB line, measured).
            return Err(malformed(format!(
                "longer than {MAX_LINE_BYTES} bytes (a candump line or a TICK is under 200)"
            )));
        }
        let text = match std::str::from_utf8(&bytes) {
            Ok(text) => text.trim_end(),
            Err(e) => {
                cut_line = Some(cut_or(malformed(format!(
                    "not UTF-8 (byte {})",
                    e.valid_up_to() + 1
                )))?);
                break;
            }
        };
        if text.trim().is_empty() {
            continue;
        }
        if let Some(rest) = text.strip_prefix("TICK") {
            let stamp = rest.strip_prefix(' ');
            let t_us = match stamp.map(candump::parse_timestamp) {
                Some(Ok(t_us)) => t_us,
                // The syntax is right, the value overflows the microseconds' u64.
                Some(Err(_)) if stamp.is_some_and(is_timestamp_syntax) => {
                    return Err(malformed(format!(
                        "{} out of range (above {} s)",
                        quoted(text),
                        timestamp(MAX_TICK_US)
                    )))
                }
                _ => {
                    cut_line = Some(cut_or(malformed(format!(
                        "expected `TICK SECONDS.UUUUUU` (six decimals), got {}",
                        quoted(text)
                    )))?);
                    break;
                }
            };
            // As replay refuses a frame time beyond it (year 292 000): keeps the node's tick
            // arithmetic from overflowing.
            if t_us > MAX_TICK_US {
                return Err(malformed(format!(
                    "TICK {} out of range (above {} s)",
                    timestamp(t_us),
                    timestamp(MAX_TICK_US)
                )));
            }
            if let Some(prev) = last_tick.filter(|p| t_us <= *p) {
                return Err(malformed(format!(
                    "TICK {} is not later than the previous TICK {}",
                    timestamp(t_us),
                    timestamp(prev)
                )));
            }
            check_tick_schedule(t_us, last_tick).map_err(malformed)?;
            tx.clear();
            queue.take_tick(&mut rx);
            let tick = Tick {
                now_us: t_us,
                platform: PlatformStats {
                    rx_queue_drops: queue.drops(),
                    ..PlatformStats::default()
                },
            };
            let before = driver.planner_counters();
            driver.tick(&tick, &rx, &mut tx);
            planner.observe(
                t_us,
                &rx,
                (&before, &driver.planner_counters()),
                &driver.path_car(),
            );
            for frame in &tx {
                writeln!(output, "{}", candump_line(t_us, frame)).map_err(SilError::Io)?;
            }
            writeln!(output, "END {}", timestamp(t_us)).map_err(SilError::Io)?;
            output.flush().map_err(SilError::Io)?;
            last_tick = Some(t_us);
            ticks += 1;
            continue;
        }
        match candump::parse_line(text) {
            Ok(frame) => {
                tracker.observe(&mut timestamps, frame.t_us, frame.frame.id);
                queue.push(frame)
            }
            // What the firmware's receive path does with them: skipped and counted.
            Err(e) if e.is_unsupported_frame() => queue.unsupported += 1,
            Err(e) => {
                cut_line = Some(cut_or(malformed(format!(
                    "neither a candump line nor `TICK SECONDS.UUUUUU` ({}): {}",
                    candump_reason(e),
                    quoted(text)
                )))?);
                break;
            }
        }
    }
    output.flush().map_err(SilError::Io)?;
    Ok(SilSummary {
        ticks,
        never_ticked: queue.len() as u64,
        filtered: queue.filtered,
        unsupported: queue.unsupported,
        rx_queue_drops: queue.drops,
        counters: driver.counters(),
        timestamps,
        planner,
        cut_line,
        path_unfinished: driver.path_receiving(),
    })
}

/// Whether `text` has the candump timestamp's syntax (1-20 digits, a dot, six digits), so that
/// a TICK [`candump::parse_timestamp`] refuses is out of range, not malformed.
fn is_timestamp_syntax(text: &str) -> bool {
    let digits = |s: &str| s.bytes().all(|b| b.is_ascii_digit());
    text.split_once('.').is_some_and(|(secs, frac)| {
        (1..=20).contains(&secs.len()) && digits(secs) && frac.len() == 6 && digits(frac)
    })
}

/// The node's tick schedule, which a TICK at `t_us` after the TICK at `previous_us` must
/// follow (docs/architecture.md, "Tick schedule", as replay, QEMU and the board tick): the
/// first on a whole multiple of [`SAMPLE_PERIOD_US`] (20 ms), each next one 20 ms after the
/// previous. An error, not a warning: the node steps its filters, dead reckoning and models
/// by 20 ms a tick whatever the TICK says, and its receive cap
/// ([`MAX_RX_FRAMES_PER_TICK`]) and GNSS fixes per tick are sized for 20 ms of bus traffic, so
/// a simulator ticking every 40 ms drove a car the node saw move at half its speed and
/// overflowed the receive queue (the session never drove, and the summary blamed the queue and
/// the GNSS gate: docs/findings.md). The error names the TICK expected.
fn check_tick_schedule(t_us: u64, previous_us: Option<u64>) -> Result<(), String> {
    let expected = match previous_us {
        Some(prev) => prev.saturating_add(SAMPLE_PERIOD_US),
        None => first_tick_us(t_us),
    };
    if t_us == expected {
        return Ok(());
    }
    let period_s = SAMPLE_PERIOD_US as f64 / 1e6;
    Err(match previous_us {
        Some(prev) => format!(
            "TICK {} is {} ms after the previous TICK {}: the node ticks every {period_s} s \
             (its models, filters and receive cap are per 20 ms tick); expected TICK {}",
            timestamp(t_us),
            (t_us - prev) as f64 / 1000.0,
            timestamp(prev),
            timestamp(expected)
        ),
        None => format!(
            "TICK {} is off the node's tick schedule: ticks fall on whole multiples of \
             {period_s} s (docs/architecture.md, \"Tick schedule\"); expected TICK {}",
            timestamp(t_us),
            timestamp(expected)
        ),
    })
}

/// Ticks after this are refused, us: the last tick of the schedule at or below the largest
/// time `replay` accepts for a frame (`u64::MAX / 2`, year 292 000). On the schedule itself,
/// so that no TICK accepted is told to be followed by one that is not, and the limit the
/// error names is the limit applied (a black-box probe's TICK 9223372036854.775800 was told
/// to expect 9223372036854.780000, out of range; 9223372036854.760000 was accepted where the
/// error said "above 9223372036854 s").
const MAX_TICK_US: u64 = u64::MAX / 2 / SAMPLE_PERIOD_US * SAMPLE_PERIOD_US;

/// Longest part of a bad line an error repeats, characters.
const QUOTE_CHARS: usize = 80;

/// `text` quoted for an error message, cut to [`QUOTE_CHARS`] characters (a bad line can be
/// megabytes long).
fn quoted(text: &str) -> String {
    match text.char_indices().nth(QUOTE_CHARS) {
        None => format!("{text:?}"),
        Some((cut, _)) => format!("{:?}... ({} bytes)", &text[..cut], text.len()),
    }
}

/// What a session did, for its closing line on stderr.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SilSummary {
    /// Ticks run.
    pub ticks: u64,
    /// Frames still in the receive queue when the input ended: given after the last TICK, or
    /// held over the per-tick cap, no TICK took them to the node (a black-box probe's were
    /// left out of the summary without a word).
    pub never_ticked: u64,
    /// Frames the acceptance filter refused (not node inputs).
    pub filtered: u64,
    /// Remote, CAN FD and error frames skipped.
    pub unsupported: u64,
    /// Frames dropped because the receive queue was full.
    pub rx_queue_drops: u32,
    /// The node's rejection counters at the end (`time_errors`, frames stamped after the TICK
    /// that delivered them, is on no status page).
    pub counters: Counters,
    /// How the frames were stamped ([`TimestampStats::warning`]: in batches?).
    pub timestamps: TimestampStats,
    /// The node's planner refusals (on no status page but as the bit
    /// `planner_refused_recently`) and the first one's reason.
    pub planner: PlannerRefusals,
    /// The last line, cut short without a line end (the simulator stopped mid-write) and not
    /// a line the session reads: its number; it was left out.
    pub cut_line: Option<usize>,
    /// The path the node was receiving when the input ended ([`Driver::path_receiving`]):
    /// it never loaded.
    pub path_unfinished: Option<(u8, usize, usize, usize)>,
}

impl std::fmt::Display for SilSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let c = &self.counters;
        write!(
            f,
            "{} ticks; frames not given to the node: {} not node inputs (acceptance filter), \
             {} remote/FD/error frames, {} dropped by the full receive queue, {} queued when \
             the input ended (no TICK after them); rejected by the node: crc {}, counter {}, \
             dlc {}, range {}, gnss gate {}, gnss rate {}, unknown id {}, stamped after their \
             TICK {}; {}",
            self.ticks,
            self.filtered,
            self.unsupported,
            self.rx_queue_drops,
            self.never_ticked,
            c.crc_errors,
            c.counter_errors,
            c.dlc_errors,
            c.range_errors,
            c.gnss_gate_rejects,
            c.gnss_rate_mismatch,
            c.unknown_ids,
            c.time_errors,
            self.planner
        )?;
        if let Some((id, points, limits, count)) = self.path_unfinished {
            write!(
                f,
                "; the input ended while the node was receiving path {id}: {points} of its \
                 {count} points and {limits} of its limits were in (a TICK takes at most \
                 {MAX_RX_FRAMES_PER_TICK} frames), so it never loaded"
            )?;
        }
        if let Some(line) = self.cut_line {
            write!(
                f,
                "; the last line (line {line}) had no line end and was not a whole candump \
                 line or TICK: cut short, left out"
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::closed_loop::driver::{Controller, NodeDriver};
    use crate::closed_loop::planner::{path_frames, straight_path_frames, PlannedPoint};
    use crate::replay::candump_line;
    use catmodel::can::{CanFrame, CanId};

    fn steering_frame(t_us: u64) -> TimedFrame {
        TimedFrame {
            t_us,
            frame: CanFrame::new(CanId::Standard(0x100), &[0; 8]).unwrap(),
        }
    }

    #[test]
    fn the_queue_filters_holds_64_and_hands_12_a_tick() {
        let mut q = RxQueue::default();
        // Not a node input (the node's own CONTROL_COMMAND): refused, counted, not queued.
        q.push(TimedFrame {
            t_us: 0,
            frame: CanFrame::new(CanId::Standard(0x320), &[0; 8]).unwrap(),
        });
        for k in 0..100 {
            q.push(steering_frame(k));
        }
        assert_eq!((q.filtered(), q.len(), q.drops()), (1, RX_QUEUE_LEN, 36));
        let mut rx = Vec::new();
        q.take_tick(&mut rx);
        // The oldest first; the rest wait.
        let stamps: Vec<u64> = rx.iter().map(|f| f.t_us).collect();
        assert_eq!(
            stamps,
            (0..MAX_RX_FRAMES_PER_TICK as u64).collect::<Vec<_>>()
        );
        assert_eq!(q.len(), RX_QUEUE_LEN - MAX_RX_FRAMES_PER_TICK);
    }

    /// A line longer than [`MAX_LINE_BYTES`] is refused once the cap is read, not held whole
    /// (a black-box probe's 200 MB line without an end took 201 MB before its error); a line of
    /// the cap's length is read as any other.
    #[test]
    fn a_line_longer_than_the_cap_is_refused_without_reading_it_whole() {
        /// Yields `b'A'` forever: a line with no end.
        struct Endless(usize);
        impl std::io::Read for Endless {
            fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
                buf.fill(b'A');
                self.0 += buf.len();
                Ok(buf.len())
            }
        }
        let config = crate::node_config(None).unwrap();
        let mut driver = NodeDriver::new(config.clone(), Controller::FromModel);
        let mut endless = std::io::BufReader::new(Endless(0));
        let err = run(&mut driver, &mut endless, Vec::new()).unwrap_err();
        assert!(err.to_string().contains("longer than 4096 bytes"), "{err}");
        assert!(
            endless.get_ref().0 <= 2 * MAX_LINE_BYTES + 8192,
            "{}",
            endless.get_ref().0
        );
        // At the cap, with its newline: a malformed line, judged as a line.
        let mut line = "TICK".to_string();
        line.push_str(&" ".repeat(MAX_LINE_BYTES - 5));
        line.push('\n');
        let mut driver = NodeDriver::new(config, Controller::FromModel);
        let err = run(&mut driver, line.as_bytes(), Vec::new()).unwrap_err();
        assert!(err.to_string().contains("expected `TICK"), "{err}");
    }

    /// `frames` stamped at 1 s, then `TICK 1.020000`.
    fn path_then_tick(frames: &[CanFrame]) -> String {
        let mut input: String = frames
            .iter()
            .map(|f| format!("{}\n", candump_line(1_000_000, f)))
            .collect();
        input.push_str("TICK 1.020000\n");
        input
    }

    #[test]
    fn a_path_given_in_one_tick_loads_over_two_as_on_the_firmware() {
        // A 6-point path is 13 frames: the node takes 12 in the first tick and the 13th in
        // the next (before the receive queue, the 13th was counted over the cap and lost, so
        // the path never loaded in SIL while it did in replay).
        let frames = straight_path_frames(6, 5.0);
        assert_eq!(frames.len(), 13);
        let mut input = path_then_tick(&frames);
        let config = crate::node_config(None).unwrap();
        let mut driver = NodeDriver::new(config.clone(), Controller::FromModel);
        let mut out = Vec::new();
        run(&mut driver, input.as_bytes(), &mut out).unwrap();
        assert!(driver.node().drive().planner().path().is_none());
        input.push_str("TICK 1.040000\n");
        let mut driver = NodeDriver::new(config, Controller::FromModel);
        run(&mut driver, input.as_bytes(), &mut out).unwrap();
        assert_eq!(
            driver
                .node()
                .drive()
                .planner()
                .path()
                .map(|p| p.points().len()),
            Some(6)
        );
        assert_eq!(driver.node().counters().rx_over_cap, 0);
    }

    fn session(input: &[u8]) -> (Result<SilSummary, SilError>, String) {
        let config = crate::node_config(None).unwrap();
        let mut driver = NodeDriver::new(config, Controller::FromModel);
        let mut out = Vec::new();
        let result = run(&mut driver, input, &mut out);
        (result, String::from_utf8(out).unwrap())
    }

    fn malformed(input: &[u8]) -> (usize, String) {
        match session(input).0 {
            Err(SilError::Malformed { line, reason }) => (line, reason),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn bad_lines_name_their_line_and_quote_at_most_80_characters() {
        // Not UTF-8: the line, not a bare I/O error.
        let (line, reason) = malformed(b"TICK 0.020000\n(0.030000) can0 100#\xff\n");
        assert_eq!(line, 2);
        assert!(reason.contains("not UTF-8 (byte 21)"), "{reason}");
        // A megabyte of garbage: refused at the line cap, not held whole.
        let mut long = b"TICK 0.020000\n".to_vec();
        long.extend(std::iter::repeat_n(b'x', 1 << 20));
        let (line, reason) = malformed(&long);
        assert_eq!(line, 2);
        assert!(
            reason.len() < 300 && reason.contains("longer than 4096 bytes"),
            "{reason}"
        );
        // Under the cap: quoted in part, with its length.
        let mut long = b"TICK 0.020000\n".to_vec();
        long.extend(std::iter::repeat_n(b'x', 4000));
        long.push(b'\n');
        let (line, reason) = malformed(&long);
        assert_eq!(line, 2);
        assert!(
            reason.len() < 300 && reason.contains("... (4000 bytes)"),
            "{reason}"
        );
        // A tick beyond what replay accepts for a frame.
        let (line, reason) = malformed(b"TICK 0.020000\nTICK 9223372036855.000000\n");
        assert_eq!(line, 2);
        assert!(reason.contains("out of range"), "{reason}");
        // The last tick of the schedule is taken; past it, what the error names is what is
        // refused (the first TICK of the probe's was told to expect one out of range).
        let (result, _) = session(b"TICK 9223372036854.760000\n");
        assert_eq!(result.unwrap().ticks, 1);
        for late in ["9223372036854.775800", "9223372036854.780000"] {
            let (line, reason) = malformed(format!("TICK {late}\n").as_bytes());
            assert_eq!(line, 1);
            assert!(
                reason.contains("out of range (above 9223372036854.760000 s)"),
                "{reason}"
            );
        }
    }

    #[test]
    fn a_tick_too_large_for_microseconds_is_out_of_range_not_malformed() {
        // Six decimals, but 1e20 us overflows a u64: the reason is the range (it said "six
        // decimals" before).
        let (line, reason) = malformed(b"TICK 0.020000\nTICK 99999999999999.000000\n");
        assert_eq!(line, 2);
        assert!(
            reason.contains("out of range (above 9223372036854.760000 s)")
                && !reason.contains("six decimals"),
            "{reason}"
        );
        // A wrong syntax still says what the syntax is.
        let (_, reason) = malformed(b"TICK 0.02\n");
        assert!(reason.contains("six decimals"), "{reason}");
    }

    #[test]
    fn a_tick_off_the_20_ms_schedule_is_refused_with_the_tick_expected() {
        for (input, line, needle) in [
            // A 25 Hz simulator: the node would step 20 ms for every 40.
            (
                &b"TICK 0.020000\nTICK 0.060000\n"[..],
                2,
                "40 ms after the previous TICK 0000000000.020000: the node ticks every 0.02 s \
                 (its models, filters and receive cap are per 20 ms tick); expected TICK \
                 0000000000.040000",
            ),
            (
                b"TICK 0.020000\nTICK 0.027000\n",
                2,
                "expected TICK 0000000000.040000",
            ),
            // The first tick off the grid every platform ticks on.
            (
                b"TICK 0.013000\n",
                1,
                "off the node's tick schedule: ticks fall on whole multiples of 0.02 s \
                 (docs/architecture.md, \"Tick schedule\"); expected TICK 0000000000.020000",
            ),
        ] {
            let (got_line, reason) = malformed(input);
            assert_eq!(got_line, line, "{reason}");
            assert!(reason.contains(needle), "{reason}");
        }
        // On the schedule, at an epoch time too.
        let (result, _) = session(b"TICK 1700000000.020000\nTICK 1700000000.040000\n");
        assert_eq!(result.unwrap().ticks, 2);
    }

    /// A session giving `frames` at 1 s, then ticking 1.02..1.10.
    fn session_of(frames: &[CanFrame]) -> SilSummary {
        let mut input: String = frames
            .iter()
            .map(|f| format!("{}\n", candump_line(1_000_000, f)))
            .collect();
        for k in 1..=5 {
            input.push_str(&format!("TICK 1.{:02}0000\n", 2 * k));
        }
        session(input.as_bytes()).0.unwrap()
    }

    /// Frames given after the last TICK never reach the node: the summary counts them (a
    /// black-box probe's were dropped without a word).
    #[test]
    fn frames_after_the_last_tick_are_counted() {
        let report = catmodel::can::SteeringReport {
            steer_pct: Some(1.0),
        };
        let line = |t_us: u64, counter: u8| candump_line(t_us, &report.encode(counter));
        let input = format!(
            "{}\nTICK 0.020000\n{}\n{}\n",
            line(10_000, 0),
            line(30_000, 1),
            line(35_000, 2)
        );
        let (result, _) = session(input.as_bytes());
        let summary = result.unwrap();
        assert_eq!((summary.ticks, summary.never_ticked), (1, 2));
        assert!(
            summary
                .to_string()
                .contains("2 queued when the input ended (no TICK after them)"),
            "{summary}"
        );
    }

    #[test]
    fn planner_refusals_are_summed_up_with_the_first_reason() {
        // The probe's path: points 0.05 m apart, which PATH_POINT turns into 0.06 and 0.04 m.
        // The node refuses it; the summary said nothing was rejected.
        let summary = session_of(&straight_path_frames(6, 0.05));
        assert_eq!(summary.planner.counters.paths_invalid, 1);
        let text = summary.to_string();
        assert!(
            text.contains(
                "planner: 0 paths loaded, 1 refused (invalid paths 1, abandoned 0, duplicate \
                 indices 0, stray frames 0, stuck counters 0, unpaired origin pages 0); the \
                 first at 1.040000 s: path 0 refused: points 1 and 2 are 0.040 m apart as decoded \
                 (at least 0.05, at most 50; PATH_POINT rounds each coordinate to 0.02 m: space \
                 the points at least 0.08 m apart before encoding them)"
            ),
            "{text}"
        );
        // Spaced as docs/bus.md says: loaded, nothing refused.
        let summary = session_of(&straight_path_frames(6, 0.08));
        assert_eq!(
            (
                summary.planner.counters.paths_activated,
                summary.planner.first
            ),
            (1, None)
        );
        // A frame given twice (its counter repeated): the node refuses the copy; the path
        // still loads.
        let mut frames = straight_path_frames(6, 1.0);
        frames.insert(2, frames[1]);
        let summary = session_of(&frames);
        let text = summary.to_string();
        assert!(
            text.contains("1 paths loaded, 1 refused")
                && text.contains("stuck counters 1")
                && text.contains("repeated its message's rolling counter"),
            "{text}"
        );
    }

    #[test]
    fn a_corridor_the_body_does_not_fit_in_is_refused_with_both_widths() {
        // The probe's corridor of nothing, and one 2.6 cm under the CAT Vehicle's 1.806 m (the
        // model file's width; PATH_LIMITS carries 0.01 m, the node allows that much).
        let path = |side: f64| -> Vec<PlannedPoint> {
            (0..20)
                .map(|i| PlannedPoint {
                    east_m: 0.0,
                    north_m: f64::from(i),
                    speed_mps: 3.0,
                    left_m: side,
                    right_m: side,
                })
                .collect()
        };
        let text = session_of(&path_frames(&path(0.0))).to_string();
        assert!(
            text.contains(
                "1 refused (invalid paths 1, abandoned 0, duplicate indices 0, stray frames 0, \
                 stuck counters 0, unpaired origin pages 0); the first at 1.080000 s: path 0 \
                 refused: the corridor at point 0 is 0.00 m wide (left 0.00 + right 0.00), \
                 narrower than the car's body (1.81 m, the model file's vehicle width)"
            ),
            "{text}"
        );
        let text = session_of(&path_frames(&path(0.89))).to_string();
        assert!(
            text.contains("the corridor at point 0 is 1.78 m wide (left 0.89 + right 0.89)"),
            "{text}"
        );
        // The body's width as the bus carries it (0.90 m a side): loaded.
        let summary = session_of(&path_frames(&path(0.903)));
        assert_eq!(
            (
                summary.planner.counters.paths_activated,
                summary.planner.first
            ),
            (1, None)
        );
    }

    #[test]
    fn unsupported_and_foreign_frames_are_skipped_and_summed_up() {
        // And a steering report stamped after the TICK that delivers it: the node's to
        // reject, counted in the summary (no status page carries `time_errors`).
        let late = crate::replay::candump_line(
            30_000,
            &catmodel::can::SteeringReport {
                steer_pct: Some(1.0),
            }
            .encode(0),
        );
        let input = format!(
            "(0.001000) can0 20000080#0000000000000000\n(0.002000) can0 100#R\n\
             (0.003000) can0 320#0000000000000000\n{late}\nTICK 0.020000\n"
        );
        let (result, out) = session(input.as_bytes());
        let summary = result.unwrap();
        assert_eq!(
            summary,
            SilSummary {
                ticks: 1,
                never_ticked: 0,
                filtered: 1,
                unsupported: 2,
                rx_queue_drops: 0,
                counters: Counters {
                    time_errors: 1,
                    ..summary.counters
                },
                timestamps: summary.timestamps,
                planner: summary.planner.clone(),
                cut_line: None,
                path_unfinished: None,
            }
        );
        assert_eq!(summary.counters.time_errors, 1);
        says(
            &summary,
            "stamped after their TICK 1; planner: 0 paths loaded, 0 refused",
        );
        assert!(out.ends_with("END 0000000000.020000\n"));
    }

    /// Asserts that the summary's line says `text`.
    fn says(summary: &SilSummary, text: &str) {
        assert!(summary.to_string().contains(text), "{summary}");
    }

    #[test]
    fn a_last_line_cut_short_is_left_out_and_named() {
        // A simulator that stopped mid-write: the session's frames were lost to an error on
        // a line the simulator never finished.
        let tails: [&[u8]; 3] = [
            b"TICK 0.0400",
            b"(0.030000) can0 10",
            b"(0.030000) can0 100#0\xC3",
        ];
        for tail in tails {
            let mut input = b"TICK 0.020000\n".to_vec();
            input.extend_from_slice(tail);
            let tail = String::from_utf8_lossy(tail);
            let (result, out) = session(&input);
            let summary = result.unwrap_or_else(|e| panic!("{tail}: {e}"));
            assert_eq!((summary.ticks, summary.cut_line), (1, Some(2)), "{tail}");
            says(&summary, "the last line (line 2) had no line end");
            assert!(out.ends_with("END 0000000000.020000\n"));
        }
        // With its line end it is an error, as any malformed line.
        let (line, _) = malformed(b"TICK 0.020000\nTICK 0.0400\n");
        assert_eq!(line, 2);
        // A whole last line without an end is read.
        let (result, _) = session(b"TICK 0.020000\nTICK 0.040000");
        let summary = result.unwrap();
        assert_eq!((summary.ticks, summary.cut_line), (2, None));
        assert!(!summary.to_string().contains("line end"), "{summary}");
    }

    #[test]
    fn a_path_still_arriving_when_the_input_ends_is_named() {
        // 13 frames for 6 points: one TICK takes 12, the path's last frame waits for a TICK
        // that never comes.
        let mut input = path_then_tick(&straight_path_frames(6, 5.0));
        let summary = session(input.as_bytes()).0.unwrap();
        let (id, points, limits, count) = summary.path_unfinished.unwrap();
        assert_eq!((points.max(limits), count), (6, 6), "{id}");
        assert!(points < 6 || limits < 6);
        says(
            &summary,
            &format!("the input ended while the node was receiving path {id}"),
        );
        // One more TICK: loaded, no word of it.
        input.push_str("TICK 1.040000\n");
        let summary = session(input.as_bytes()).0.unwrap();
        assert_eq!(summary.path_unfinished, None);
        assert!(!summary.to_string().contains("receiving path"), "{summary}");
    }
}
