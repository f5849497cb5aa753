//! `catmodel sil --stdio`: lockstep software-in-the-loop over stdin/stdout, so that any
//! simulator (ours, Gazebo, CARLA, a script) can close the loop around the very same node
//! (README, "Software in the loop").
//!
//! Input, one item per line: a candump line (a frame the node reads), or `TICK SECONDS.UUUUUU`.
//! On `TICK T` the node runs its tick at time T with every frame given since the previous tick
//! (in the order given; frames stamped after T are the node's to reject, as on the bus), writes
//! that tick's frames as candump lines stamped T, then the line `END SECONDS.UUUUUU` (T in the
//! candump timestamp format), and flushes. End of input: success. A malformed line, or a TICK
//! not later than the previous one: an error naming the line number, and nothing more is read.
//! Blank lines are skipped (as in `replay`).
use std::io::{BufRead, Write};

use catmodel::can::{candump, CanFrame, TimedFrame};

use crate::closed_loop::driver::Driver;
use crate::replay::{candump_line, candump_reason};

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

/// `SECONDS.UUUUUU` as the candump timestamp writes it (seconds zero-padded to 10 digits).
fn timestamp(t_us: u64) -> String {
    format!("{:010}.{:06}", t_us / 1_000_000, t_us % 1_000_000)
}

/// Runs a session: reads `input` to its end, ticking `driver`, writing to `output`. Returns the
/// number of ticks run.
pub fn run(
    driver: &mut dyn Driver,
    input: impl BufRead,
    mut output: impl Write,
) -> Result<u64, SilError> {
    let mut pending: Vec<TimedFrame> = Vec::new();
    let mut last_tick: Option<u64> = None;
    let mut ticks = 0;
    let mut tx: Vec<CanFrame> = Vec::new();
    for (i, line) in input.lines().enumerate() {
        let line_no = i + 1;
        let line = line.map_err(SilError::Io)?;
        let text = line.trim_end();
        if text.trim().is_empty() {
            continue;
        }
        let malformed = |reason: String| SilError::Malformed {
            line: line_no,
            reason,
        };
        if let Some(rest) = text.strip_prefix("TICK") {
            let t_us = rest
                .strip_prefix(' ')
                .ok_or(())
                .and_then(|t| candump::parse_timestamp(t).map_err(|_| ()))
                .map_err(|()| {
                    malformed(format!(
                        "expected `TICK SECONDS.UUUUUU` (six decimals), got {text:?}"
                    ))
                })?;
            if let Some(prev) = last_tick.filter(|p| t_us <= *p) {
                return Err(malformed(format!(
                    "TICK {} is not later than the previous TICK {}",
                    timestamp(t_us),
                    timestamp(prev)
                )));
            }
            tx.clear();
            driver.tick(t_us, &pending, &mut tx);
            pending.clear();
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
            Ok(frame) => pending.push(frame),
            Err(e) => {
                return Err(malformed(format!(
                    "neither a candump line nor `TICK SECONDS.UUUUUU` ({}): {text:?}",
                    candump_reason(e)
                )))
            }
        }
    }
    output.flush().map_err(SilError::Io)?;
    Ok(ticks)
}
