//! The QEMU run's single use of candump text, kept behind two functions until the core's
//! `catmodel::can::candump::{parse_line, format_line}` lands; then these become one-line calls.
//!
//! Format (SocketCAN log): `(1700000000.123456) can0 123#DEADBEEF`, standard IDs as 3 hex
//! digits, extended IDs as 8, payload as upper-case hex pairs, 0 to 8 bytes.
use core::fmt::Write;

use crate::can::{CanFrame, CanId, TimedFrame};

/// Longest line the QEMU run writes: `(` 10+ digits `.` 6 digits `) can0 ` 8 `#` 16.
pub const LINE_CAP: usize = 64;

/// Why a line is not a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LineError {
    /// Not `(seconds.micros) iface ID#DATA`.
    Syntax,
    /// A remote or CAN FD frame, which the node does not use.
    Unsupported,
}

fn parse_hex(text: &str) -> Option<u32> {
    if text.is_empty() || text.len() > 8 {
        return None;
    }
    u32::from_str_radix(text, 16).ok()
}

fn parse_decimal(text: &str) -> Option<u64> {
    if text.is_empty() || !text.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    text.parse().ok()
}

/// Parses one candump line (without its line break).
pub fn parse(line: &str) -> Result<TimedFrame, LineError> {
    let mut fields = line.split_ascii_whitespace();
    let stamp = fields.next().ok_or(LineError::Syntax)?;
    let _iface = fields.next().ok_or(LineError::Syntax)?;
    let body = fields.next().ok_or(LineError::Syntax)?;
    if fields.next().is_some() {
        return Err(LineError::Syntax);
    }
    let stamp = stamp
        .strip_prefix('(')
        .and_then(|s| s.strip_suffix(')'))
        .ok_or(LineError::Syntax)?;
    let (secs, micros) = stamp.split_once('.').ok_or(LineError::Syntax)?;
    if micros.len() != 6 {
        return Err(LineError::Syntax);
    }
    let t_us = parse_decimal(secs)
        .and_then(|s| s.checked_mul(1_000_000))
        .and_then(|s| s.checked_add(parse_decimal(micros)?))
        .ok_or(LineError::Syntax)?;

    let (id_text, data_text) = body.split_once('#').ok_or(LineError::Syntax)?;
    if data_text.starts_with('#') || data_text.starts_with('R') || data_text.starts_with('r') {
        return Err(LineError::Unsupported);
    }
    let raw_id = parse_hex(id_text).ok_or(LineError::Syntax)?;
    let id = match id_text.len() {
        3 => CanId::Standard(u16::try_from(raw_id).map_err(|_| LineError::Syntax)?),
        8 => CanId::Extended(raw_id),
        _ => return Err(LineError::Syntax),
    };
    if data_text.len() % 2 != 0 || data_text.len() > 16 {
        return Err(LineError::Syntax);
    }
    let mut data = [0u8; 8];
    for (byte, pair) in data.iter_mut().zip(data_text.as_bytes().chunks(2)) {
        let pair = core::str::from_utf8(pair).map_err(|_| LineError::Syntax)?;
        *byte = u8::from_str_radix(pair, 16).map_err(|_| LineError::Syntax)?;
    }
    let len = data_text.len() / 2;
    let frame =
        CanFrame::new(id, data.get(..len).ok_or(LineError::Syntax)?).ok_or(LineError::Syntax)?;
    Ok(TimedFrame { t_us, frame })
}

/// Formats `frame` as a candump line on interface `iface`, with a trailing `\n`.
pub fn format(frame: &TimedFrame, iface: &str, out: &mut heapless::String<LINE_CAP>) {
    out.clear();
    // Note: the longest line (LINE_CAP) fits, so the writes cannot fail; a failure would only
    // truncate the line.
    let _ = write!(
        out,
        "({}.{:06}) {} ",
        frame.t_us / 1_000_000,
        frame.t_us % 1_000_000,
        iface
    );
    let _ = match frame.frame.id {
        CanId::Standard(id) => write!(out, "{id:03X}#"),
        CanId::Extended(id) => write!(out, "{id:08X}#"),
    };
    for byte in frame.frame.payload() {
        let _ = write!(out, "{byte:02X}");
    }
    let _ = out.push('\n');
}
