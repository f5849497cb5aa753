//! The QEMU run's use of candump text, through the core's `catmodel::can::candump`: the same
//! parser and formatter as host replay, so that `target/qemu/tx.log` and `catmodel replay
//! --tx-out` can be byte-identical.
use core::fmt::Write;

use catmodel::can::candump::{format_line, parse_line, CandumpError};
use catmodel::can::TimedFrame;

/// Longest line the QEMU run writes: `(` 10 digits `.` 6 digits `) can0 ` 8 `#` 16 `\n` = 50.
pub const LINE_CAP: usize = 64;

/// Why a line is not a frame for the node.
#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub enum LineError {
    /// Not a candump frame line.
    Syntax(CandumpError),
    /// A remote, CAN FD or error frame, which the node does not use (skipped and counted).
    Unsupported,
}

/// Parses one candump line (without its line break).
pub fn parse(line: &str) -> Result<TimedFrame, LineError> {
    parse_line(line).map_err(|error| {
        if error.is_unsupported_frame() {
            LineError::Unsupported
        } else {
            LineError::Syntax(error)
        }
    })
}

/// Formats `frame` as a candump line on interface `iface`, with a trailing `\n`.
pub fn format(frame: &TimedFrame, iface: &str, out: &mut heapless::String<LINE_CAP>) {
    out.clear();
    // Note: the longest line fits LINE_CAP, so neither write can fail; a failure would only
    // truncate the line (and show up in the byte-for-byte comparison with host replay).
    let _ = format_line(frame, iface, out);
    let _ = out.write_char('\n');
}
