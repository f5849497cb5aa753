//! `catmodel replay`: the very same [`Node`] as the firmware, stepped every 20 ms of log time
//! over a candump file, with the tick schedule of docs/architecture.md (so that its frames are
//! byte-identical to the QEMU run's `target/qemu/tx.log`).
use std::fmt::Write as _;
use std::io::{BufRead, BufReader, Write};
use std::path::Path;

use anyhow::{bail, Context, Result};
use catmodel::can::candump;
use catmodel::can::codec::{ModelMode, Prediction, StateMotion, StatePosition};
use catmodel::can::{CanFrame, TimedFrame};
use catmodel::node::{first_tick_us, Counters, Node, NodeConfig, PlatformStats, Tick, TxFrames};
use catmodel::SAMPLE_PERIOD_US;

/// Interface name written into candump output.
pub const IFACE: &str = "can0";

/// Reads a candump log. Errors name the file, the line and the reason; time going backwards
/// is an error with the line.
pub fn read_candump(path: &Path) -> Result<Vec<TimedFrame>> {
    let file = std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let mut frames = Vec::new();
    let mut last_t = None;
    for (i, line) in BufReader::new(file).lines().enumerate() {
        let lineno = i + 1;
        let line = line.with_context(|| format!("{}:{lineno}: reading", path.display()))?;
        if line.trim().is_empty() {
            continue;
        }
        let frame = candump::parse_line(&line).map_err(|e| {
            anyhow::anyhow!(
                "{}:{lineno}: malformed candump line ({}): {line:?}",
                path.display(),
                candump_reason(e)
            )
        })?;
        // Far beyond any clock (year 292 000); keeps the tick arithmetic from overflowing.
        if frame.t_us > u64::MAX / 2 {
            bail!(
                "{}:{lineno}: timestamp {} us out of range",
                path.display(),
                frame.t_us
            );
        }
        if let Some(prev) = last_t {
            if frame.t_us < prev {
                bail!(
                    "{}:{lineno}: time goes backwards ({} us after {} us)",
                    path.display(),
                    frame.t_us,
                    prev
                );
            }
        }
        last_t = Some(frame.t_us);
        frames.push(frame);
    }
    Ok(frames)
}

/// What is wrong with a rejected candump line, in words.
pub fn candump_reason(e: candump::CandumpError) -> &'static str {
    use candump::CandumpError as E;
    match e {
        E::Empty => "empty line",
        E::MissingTimestamp => "expected `(SECONDS.UUUUUU)` at the start",
        E::BadTimestamp => "timestamp is not `(SECONDS.UUUUUU)` with six decimals",
        E::MissingInterface => "no interface name after the timestamp",
        E::BadInterface => "interface name empty, too long or not printable",
        E::MissingSeparator => "no `#` between identifier and data",
        E::BadId => "identifier is not 3 or 8 hex digits",
        E::IdOutOfRange => "identifier above 0x7FF (3 digits) or 0x1FFFFFFF (8 digits)",
        E::RemoteFrame => "remote frame (`#R`), not supported",
        E::FdFrame => "CAN FD frame (`##`), not supported",
        E::BadHex => "data is not hex",
        E::OddHex => "odd number of data hex digits",
        E::TooLong => "more than 8 data bytes",
        E::TrailingGarbage => "unexpected text after the data",
    }
}

/// One candump line (`(secs.micros) can0 ID#DATA`).
pub fn candump_line(t_us: u64, frame: &CanFrame) -> String {
    let mut s = String::new();
    // Note: writing to a String cannot fail.
    let _ = candump::format_line(
        &TimedFrame {
            t_us,
            frame: *frame,
        },
        IFACE,
        &mut s,
    );
    s
}

/// What a replay produced.
pub struct ReplayOutput {
    /// Predictions CSV rows: `t,step,horizon_s,x,y,heading,speed,mode`.
    pub predictions_csv: String,
    /// The node's frames, candump, stamped with the tick time.
    pub tx_log: String,
    /// Ticks run.
    pub ticks: u64,
    /// The node's rejection counters at the end.
    pub counters: Counters,
    /// Origin used, 1e-7 deg.
    pub origin_e7: Option<(i32, i32)>,
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

/// Runs the node over `frames` (sorted by time).
pub fn replay(frames: &[TimedFrame], config: NodeConfig) -> ReplayOutput {
    replay_with_progress(frames, config, |_| {})
}

/// [`replay`], calling `progress(ticks_done)` every 500 ticks.
pub fn replay_with_progress(
    frames: &[TimedFrame],
    config: NodeConfig,
    mut progress: impl FnMut(u64),
) -> ReplayOutput {
    let mut node = Node::new(config);
    let mut csv = String::from("t,step,horizon_s,x,y,heading,speed,mode\n");
    let mut tx_log = String::new();
    let Some(first) = frames.first() else {
        return ReplayOutput {
            predictions_csv: csv,
            tx_log,
            ticks: 0,
            counters: *node.counters(),
            origin_e7: None,
        };
    };
    let last_us = frames.last().map_or(first.t_us, |f| f.t_us);
    let mut now = first_tick_us(first.t_us);
    let mut next = 0usize;
    let mut step = 0u64;
    let mut tx = TxFrames::new();
    // The last tick is the one at or after the last frame (the QEMU run stops there too).
    let last_tick_us = first_tick_us(last_us);
    while now <= last_tick_us {
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
            tx_log.push_str(&candump_line(now, f));
            tx_log.push('\n');
        }
        append_prediction_rows(&mut csv, now, step, &tx);
        step += 1;
        if step.is_multiple_of(500) {
            progress(step);
        }
        now += SAMPLE_PERIOD_US;
    }
    ReplayOutput {
        predictions_csv: csv,
        tx_log,
        ticks: step,
        counters: *node.counters(),
        origin_e7: node.origin_e7(),
    }
}

/// Decodes one tick's frames (what the planner receives, with its 1 cm / 1 mrad resolution)
/// into CSV rows: horizon 0 from STATE_POSITION + STATE_MOTION, then each prediction point.
fn append_prediction_rows(csv: &mut String, now_us: u64, step: u64, tx: &TxFrames) {
    let mut pos = None;
    let mut motion = None;
    let mut preds = Vec::new();
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
    let (Some(x), Some(y), Some(h), Some(v)) = (p.east_m, p.north_m, m.heading_rad, m.speed_mps)
    else {
        return;
    };
    let mode = match m.mode {
        ModelMode::Kinematic => "kinematic",
        ModelMode::Dynamic => "dynamic",
    };
    let t = now_us as f64 * 1e-6;
    let _ = writeln!(csv, "{t:.6},{step},0.00,{x:.2},{y:.2},{h:.3},{v:.2},{mode}");
    for q in preds {
        let (Some(dx), Some(dy), Some(dh), Some(speed)) =
            (q.dx_m, q.dy_m, q.dheading_rad, q.speed_mps)
        else {
            continue;
        };
        let horizon_s = q.point.horizon_us() as f64 * 1e-6;
        let heading = catmodel::math::wrap_pi(h + dh);
        let _ = writeln!(
            csv,
            "{t:.6},{step},{horizon_s:.2},{:.2},{:.2},{heading:.3},{speed:.2},{mode}",
            x + dx,
            y + dy
        );
    }
}

/// Writes `text` to `path`, creating parent directories.
pub fn write_file(path: &Path, text: &str) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let mut f =
        std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
    f.write_all(text.as_bytes())
        .with_context(|| format!("writing {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

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
        let config = NodeConfig::paper().unwrap();
        let mut calls = Vec::new();
        let out = replay_with_progress(&frames, config, |n| calls.push(n));
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
}
