//! The SocketCAN log format of `candump -l` / `canplayer`, one frame per line:
//! `(1700000000.123456) can0 123#DEADBEEF`.
//!
//! - Timestamp: decimal seconds, a dot, exactly six decimals; converted to integer microseconds
//!   without any float. [`format_line`] pads the seconds to 10 digits as can-utils does
//!   (`%010lu.%06lu`); [`parse_line`] accepts 1 to 20 digits. Also read: nine decimals
//!   (`candump -N`, nanoseconds, in the log and the screen format alike), truncated to the
//!   microsecond as candump truncates them without `-N`, so that one recording reads the same
//!   either way; and the date of `candump -t A` (`2024-01-01 12:00:00.123456`, the recorder's
//!   local time), read as if it were UTC: only differences of time matter to a replay.
//! - Interface: 1 to 15 printable characters (Linux `IFNAMSIZ` - 1), after one or more spaces:
//!   candump right-aligns the names to the longest one it has seen (`%*s`), so a log of `can0`
//!   and `vcan0` writes `(...)  can0 123#00`.
//! - Identifier: exactly 3 hex digits = 11-bit (<= 0x7FF), exactly 8 = 29-bit (<= 0x1FFFFFFF).
//! - Data: 0 to 8 bytes as pairs of hex digits, either case; [`format_line`] writes upper case.
//! - `candump -l -x` appends ` R` (received) or ` T` (sent by this host) after the data:
//!   read and ignored.
//! - can-utils' raw DLC suffix (lib.c's `CC_DLC_DELIM`): `_` and one hex digit 9..F after the
//!   8 data bytes of a classic frame whose DLC field said 9..15 (written when the interface
//!   reports raw DLCs, `CAN_CTRLMODE_CC_LEN8_DLC`), `123#1122334455667788_9`: read as the 8
//!   bytes it carries, as ISO 11898-1 reads such a DLC; [`parse_line_and_dlc`] also returns
//!   the DLC, so that a reader can say the log had them. Any other `_` suffix is refused
//!   ([`CandumpError::BadRawDlc`]).
//! - Leading and trailing whitespace (and CR / LF) are ignored: the screen format starts every
//!   line with a space.
//! - Rejected with a reason: anything else after the data.
//! - `candump -d` writes `DROPCOUNT: dropped N CAN frame(s) on 'IFACE' socket (total drops M)`
//!   lines between the frames when the socket lost frames: [`parse_line`] refuses them with
//!   [`CandumpError::DropCount`], [`dropped_frames`] reads the count, so a reader can skip
//!   them and say how many frames the recording lost.
//! - Also read: candump's screen format with a timestamp (`candump -ta` / `-td` / `-tz`, what
//!   `candump -t a can0 > file` records): `(1700000000.123456)  can0  123   [4]  DE AD BE EF`,
//!   any whitespace between the fields ([`parse_line`] tells the two apart by the `[LEN]`
//!   field); with `-x`, `RX` or `TX` and two flag columns after the name (`can0  RX - -  123`),
//!   read and ignored. [`format_line`] writes the log format only.
//!   In the screen format the length tells classic CAN from CAN FD as can-utils' lib.c writes
//!   it: `[%d]` (one digit) for a classic frame, `[%02d]` (two digits, `[08]`) for a CAN FD
//!   frame of any length; `candump -8` writes a classic frame's raw DLC as `{%X}` (`{8}`, `{9}`
//!   for 8 bytes whose DLC field said 9), read as `[LEN]` with the DLC returned as the log
//!   format's `_9` is; `candump -a` appends the data as ASCII in quotes (`'.36..[..'`) after
//!   the bytes: read and ignored.
//! - Frames the node does not use, well-formed lines that readers skip and count
//!   ([`CandumpError::is_unsupported_frame`]): remote frames (`123#R`), CAN FD frames
//!   (`123##1...`, or `[08]` in the screen format) and error frames (`candump -e`: an 8-digit
//!   identifier with the kernel's `CAN_ERR_FLAG` 0x20000000 set, `20000080#...`). `candump -e`
//!   explains an error frame in the screen format on lines of their own that start with a tab
//!   (`\tbus-error`): [`is_error_detail`] tells them, and readers skip them with their frame.
//!
//! No allocation, no panic: this is what the QEMU replay bus parses on the target.
use core::fmt::Write;
use core::str::SplitAsciiWhitespace;

use super::frame::{CanFrame, CanId, TimedFrame};

/// Why a candump line was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CandumpError {
    /// The line is empty (or only whitespace).
    Empty,
    /// The line does not start with `(`.
    MissingTimestamp,
    /// The timestamp is not `SECONDS.UUUUUU` (digits, one dot, six or nine decimals, closing
    /// `)`) nor a date `YYYY-MM-DD HH:MM:SS.UUUUUU` from 1970 on, or it overflows 64-bit
    /// microseconds.
    BadTimestamp,
    /// No interface after the timestamp (the line ends, or no single space follows `)`).
    MissingInterface,
    /// The interface name is empty, longer than 15 characters or not printable.
    BadInterface,
    /// No `#` between identifier and data.
    MissingSeparator,
    /// The identifier is not 3 or 8 hex digits.
    BadId,
    /// 3 hex digits above 0x7FF, or 8 hex digits above 0x1FFFFFFF.
    IdOutOfRange,
    /// A remote transmission request (`#R`): the node has no use for them.
    RemoteFrame,
    /// A CAN FD frame (`##`): the bus is classic CAN.
    FdFrame,
    /// An error frame (`candump -e`): the identifier carries `CAN_ERR_FLAG` (0x20000000,
    /// linux/can.h) and the error class, not a bus identifier.
    ErrorFrame,
    /// A data character that is not a hex digit.
    BadHex,
    /// An odd number of data hex digits.
    OddHex,
    /// More than 8 data bytes.
    TooLong,
    /// Something other than whitespace after the data.
    TrailingGarbage,
    /// `_` after the data, but not can-utils' raw DLC suffix: one hex digit 9..F after
    /// exactly 8 data bytes.
    BadRawDlc,
    /// Screen format: fewer data bytes than its `[LEN]` says.
    LengthMismatch,
    /// A `candump -d` line, `DROPCOUNT: dropped N CAN frames on 'IFACE' socket (total drops
    /// M)`: not a frame; the recording lost N frames here ([`dropped_frames`]).
    DropCount,
}

impl CandumpError {
    /// A well-formed line of a frame the node has no use for (remote, CAN FD, error frame):
    /// readers skip it and count it, as the firmware's receive path does, instead of refusing
    /// the log.
    pub const fn is_unsupported_frame(self) -> bool {
        matches!(
            self,
            CandumpError::RemoteFrame | CandumpError::FdFrame | CandumpError::ErrorFrame
        )
    }
}

/// The kernel's error-frame flag in a candump identifier (linux/can.h `CAN_ERR_FLAG`).
const CAN_ERR_FLAG: u32 = 0x2000_0000;

/// Longest interface name (Linux IFNAMSIZ 16, minus the terminating NUL).
pub const MAX_IFACE_LEN: usize = 15;

fn hex_value(c: u8) -> Option<u8> {
    match c {
        b'0'..=b'9' => Some(c - b'0'),
        b'a'..=b'f' => Some(c - b'a' + 10),
        b'A'..=b'F' => Some(c - b'A' + 10),
        _ => None,
    }
}

fn parse_hex_u32(text: &str) -> Option<u32> {
    text.bytes().try_fold(0u32, |acc, c| {
        let v = hex_value(c)?;
        acc.checked_mul(16)?.checked_add(u32::from(v))
    })
}

fn parse_decimal(text: &str) -> Option<u64> {
    if text.is_empty() {
        return None;
    }
    text.bytes().try_fold(0u64, |acc, c| {
        if !c.is_ascii_digit() {
            return None;
        }
        acc.checked_mul(10)?.checked_add(u64::from(c - b'0'))
    })
}

/// `SECONDS.UUUUUU` (1-20 digits, a dot, exactly six decimals) to microseconds, without float;
/// the candump timestamp's syntax, also used by the SIL protocol's `TICK` lines.
pub fn parse_timestamp(text: &str) -> Result<u64, CandumpError> {
    let (secs, frac) = text.split_once('.').ok_or(CandumpError::BadTimestamp)?;
    if secs.is_empty() || secs.len() > 20 || frac.len() != 6 {
        return Err(CandumpError::BadTimestamp);
    }
    let secs = parse_decimal(secs).ok_or(CandumpError::BadTimestamp)?;
    let micros = parse_decimal(frac).ok_or(CandumpError::BadTimestamp)?;
    secs.checked_mul(1_000_000)
        .and_then(|us| us.checked_add(micros))
        .ok_or(CandumpError::BadTimestamp)
}

/// Two ASCII digits, at most `max`.
fn two_digits(text: &str, max: u64) -> Option<u64> {
    (text.len() == 2)
        .then(|| parse_decimal(text))
        .flatten()
        .filter(|v| *v <= max)
}

/// Days from 1970-01-01 to `year-month-day` (proleptic Gregorian calendar, the one `strftime`
/// writes); `None` for a date that does not exist or is before 1970.
fn days_since_epoch(year: u64, month: u64, day: u64) -> Option<u64> {
    /// Days of a common year before each month's first day.
    const BEFORE_MONTH: [u64; 12] = [0, 31, 59, 90, 120, 151, 181, 212, 243, 273, 304, 334];
    const MONTH_DAYS: [u64; 12] = [31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31];
    let is_leap = |y: u64| y.is_multiple_of(4) && (!y.is_multiple_of(100) || y.is_multiple_of(400));
    let index = usize::try_from(month.checked_sub(1)?).ok()?;
    let leap_day = u64::from(is_leap(year) && month > 2);
    let month_days = MONTH_DAYS.get(index)? + u64::from(is_leap(year) && month == 2);
    let before_month = BEFORE_MONTH.get(index)?;
    if year < 1970 || day == 0 || day > month_days {
        return None;
    }
    // Leap days in the years 1970 ..= year - 1 (1968 was the last one before).
    let leap_days_to = |y: u64| y / 4 - y / 100 + y / 400;
    let leap_days = leap_days_to(year - 1) - leap_days_to(1969);
    Some((year - 1970) * 365 + leap_days + before_month + leap_day + day - 1)
}

/// A candump timestamp to microseconds: [`parse_timestamp`]'s `SECONDS.UUUUUU`, nine decimals
/// (`candump -N`: truncated to the microsecond, as candump itself writes microseconds), or the
/// date of `candump -t A` (`YYYY-MM-DD HH:MM:SS` and six or nine decimals, local time read as
/// UTC).
fn parse_stamp(text: &str) -> Result<u64, CandumpError> {
    let (seconds, frac) = text.rsplit_once('.').ok_or(CandumpError::BadTimestamp)?;
    let micros = match frac.len() {
        6 => parse_decimal(frac),
        9 => parse_decimal(frac).map(|ns| ns / 1000),
        _ => None,
    }
    .ok_or(CandumpError::BadTimestamp)?;
    let seconds = match seconds.split_once(' ') {
        None if !seconds.is_empty() && seconds.len() <= 20 => parse_decimal(seconds),
        None => None,
        Some((date, clock)) => date_seconds(date, clock),
    }
    .ok_or(CandumpError::BadTimestamp)?;
    seconds
        .checked_mul(1_000_000)
        .and_then(|us| us.checked_add(micros))
        .ok_or(CandumpError::BadTimestamp)
}

/// `YYYY-MM-DD` and `HH:MM:SS` (`strftime("%Y-%m-%d %H:%M:%S")`) to seconds since 1970 (a
/// leap second's `:60` included).
fn date_seconds(date: &str, clock: &str) -> Option<u64> {
    let mut ymd = date.split('-');
    let (year, month, day) = (ymd.next()?, ymd.next()?, ymd.next()?);
    let mut hms = clock.split(':');
    let (hour, minute, second) = (hms.next()?, hms.next()?, hms.next()?);
    if ymd.next().is_some() || hms.next().is_some() || year.len() != 4 {
        return None;
    }
    let days = days_since_epoch(
        parse_decimal(year)?,
        two_digits(month, 12)?,
        two_digits(day, 31)?,
    )?;
    let in_day = two_digits(hour, 23)? * 3600 + two_digits(minute, 59)? * 60;
    Some(days * 86_400 + in_day + two_digits(second, 60)?)
}

fn parse_id(text: &str) -> Result<CanId, CandumpError> {
    let value = parse_hex_u32(text).ok_or(CandumpError::BadId)?;
    let id = match text.len() {
        3 => CanId::Standard(u16::try_from(value).map_err(|_| CandumpError::IdOutOfRange)?),
        8 if value & !(CAN_ERR_FLAG | 0x1FFF_FFFF) == 0 && value & CAN_ERR_FLAG != 0 => {
            return Err(CandumpError::ErrorFrame)
        }
        8 => CanId::Extended(value),
        _ => return Err(CandumpError::BadId),
    };
    if id.is_valid() {
        Ok(id)
    } else {
        Err(CandumpError::IdOutOfRange)
    }
}

fn parse_data(text: &str) -> Result<([u8; 8], u8), CandumpError> {
    if text.starts_with('#') {
        return Err(CandumpError::FdFrame);
    }
    if text.starts_with(['R', 'r']) {
        return Err(CandumpError::RemoteFrame);
    }
    let bytes = text.as_bytes();
    if let Some(bad) = bytes.iter().find(|c| hex_value(**c).is_none()) {
        return Err(if bad.is_ascii_whitespace() {
            CandumpError::TrailingGarbage
        } else {
            CandumpError::BadHex
        });
    }
    if bytes.len() > 16 {
        return Err(CandumpError::TooLong);
    }
    if !bytes.len().is_multiple_of(2) {
        return Err(CandumpError::OddHex);
    }
    let mut data = [0u8; 8];
    for (out, pair) in data.iter_mut().zip(bytes.chunks_exact(2)) {
        let hi = pair.first().copied().and_then(hex_value).unwrap_or(0);
        let lo = pair.get(1).copied().and_then(hex_value).unwrap_or(0);
        *out = (hi << 4) | lo;
    }
    Ok((data, (bytes.len() / 2) as u8))
}

/// The start of a `candump -d` line.
const DROPCOUNT_PREFIX: &str = "DROPCOUNT: dropped ";

/// The number of frames a `candump -d` line says the socket dropped, `N` in `DROPCOUNT:
/// dropped N CAN frame(s) on 'IFACE' socket (total drops M)` (can-utils candump.c); `None`
/// for any other line.
pub fn dropped_frames(line: &str) -> Option<u32> {
    let rest = line.trim().strip_prefix(DROPCOUNT_PREFIX)?;
    let (count, rest) = rest.split_once(' ')?;
    let rest = rest
        .strip_prefix("CAN frames on '")
        .or_else(|| rest.strip_prefix("CAN frame on '"))?;
    let (_iface, rest) = rest.split_once("' socket (total drops ")?;
    let total = rest.strip_suffix(')')?;
    parse_decimal(total).filter(|t| *t <= u64::from(u32::MAX))?;
    parse_decimal(count).and_then(|n| u32::try_from(n).ok())
}

/// Whether `line` is one of the lines `candump -e` writes after an error frame in the screen
/// format to explain it (lib.c's `snprintf_can_error_frame`, with `\n\t` between the items:
/// `\tbus-error`, `\tcontroller-problem{rx-error-warning}`): it starts with a tab and is not a
/// frame. Readers skip it, as they skip its error frame.
pub fn is_error_detail(line: &str) -> bool {
    let rest = line.trim_start_matches(['\r', '\n']);
    rest.starts_with('\t') && {
        let text = rest.trim();
        !text.is_empty() && !text.starts_with('(') && !text.starts_with(DROPCOUNT_PREFIX)
    }
}

/// The interface name of a candump line (log or screen format), or `None` if the line has no
/// `(timestamp)` followed by a name. Does not check the rest of the line: [`parse_line`] does.
pub fn interface_of(line: &str) -> Option<&str> {
    let rest = line.trim_start().strip_prefix('(')?;
    let (_, rest) = rest.split_once(')')?;
    rest.split_ascii_whitespace().next()
}

/// Parses one candump line (leading and trailing whitespace, CR and LF are ignored).
pub fn parse_line(line: &str) -> Result<TimedFrame, CandumpError> {
    parse_line_and_dlc(line).map(|(frame, _)| frame)
}

/// [`parse_line`], and the raw DLC (9..15) of a frame written with can-utils' suffix
/// (`#1122334455667788_9`); `None` for a frame without one.
pub fn parse_line_and_dlc(line: &str) -> Result<(TimedFrame, Option<u8>), CandumpError> {
    let line = line.trim();
    if line.is_empty() {
        return Err(CandumpError::Empty);
    }
    if line.starts_with(DROPCOUNT_PREFIX) {
        return Err(CandumpError::DropCount);
    }
    let rest = line
        .strip_prefix('(')
        .ok_or(CandumpError::MissingTimestamp)?;
    let (stamp, rest) = rest.split_once(')').ok_or(CandumpError::BadTimestamp)?;
    let t_us = parse_stamp(stamp)?;
    if screen_fields(rest).is_some_and(|(_, _, len, _)| len.starts_with(['[', '{'])) {
        return parse_screen(t_us, rest);
    }
    // One space, more when candump right-aligned the name to a longer one (`%*s`).
    let rest = rest
        .strip_prefix(' ')
        .ok_or(CandumpError::MissingInterface)?
        .trim_start_matches(' ');
    let (iface, frame_text) = rest.split_once(' ').ok_or(CandumpError::MissingInterface)?;
    // `candump -l -x`: ` R` (received) or ` T` (transmitted) after the frame.
    let frame_text = frame_text
        .strip_suffix(" R")
        .or_else(|| frame_text.strip_suffix(" T"))
        .unwrap_or(frame_text);
    if iface.is_empty()
        || iface.len() > MAX_IFACE_LEN
        || !iface.bytes().all(|c| c.is_ascii_graphic())
    {
        return Err(CandumpError::BadInterface);
    }
    let (id_text, data_text) = frame_text
        .split_once('#')
        .ok_or(CandumpError::MissingSeparator)?;
    let id = parse_id(id_text)?;
    let (data_text, raw_dlc) = split_raw_dlc(data_text)?;
    let (data, len) = parse_data(data_text)?;
    let frame = TimedFrame {
        t_us,
        frame: CanFrame { id, len, data },
    };
    Ok((frame, raw_dlc))
}

/// The data of a log-format frame and its raw DLC suffix, if it has one (`_` and one hex
/// digit 9..F after exactly 16 hex digits).
fn split_raw_dlc(text: &str) -> Result<(&str, Option<u8>), CandumpError> {
    let Some((data, dlc)) = text.split_once('_') else {
        return Ok((text, None));
    };
    if text.starts_with(['#', 'R', 'r']) {
        // A CAN FD or remote frame: parse_data names it.
        return Ok((text, None));
    }
    match dlc.as_bytes() {
        [digit] if data.len() == 16 => match hex_value(*digit) {
            Some(raw @ 9..=15) => Ok((data, Some(raw))),
            _ => Err(CandumpError::BadRawDlc),
        },
        _ => Err(CandumpError::BadRawDlc),
    }
}

/// The rest of a line in candump's screen format with a timestamp (`candump -ta`, `-td`,
/// `-tz`: what `candump -t a can0 > file` records): `  IFACE  ID   [LEN]  B0 B1 ...`, any
/// whitespace between the fields; `remote request` in place of the data for a remote frame, a
/// two-digit length (`[%02d]`) for a CAN FD frame, `{DLC}` for `candump -8`'s raw DLC of a
/// classic frame (returned when 9..15), `'ASCII'` after the data for `candump -a`.
fn parse_screen(t_us: u64, rest: &str) -> Result<(TimedFrame, Option<u8>), CandumpError> {
    let (iface, id, len_text, mut tokens) =
        screen_fields(rest).ok_or(CandumpError::MissingSeparator)?;
    if iface.len() > MAX_IFACE_LEN || !iface.bytes().all(|c| c.is_ascii_graphic()) {
        return Err(CandumpError::BadInterface);
    }
    let id = parse_id(id)?;
    let (len, raw_dlc) =
        if let Some(dlc) = len_text.strip_prefix('{').and_then(|t| t.strip_suffix('}')) {
            // `candump -8`: a classic frame's DLC field, one hex digit; 9..15 mean 8 bytes.
            let dlc = match dlc.as_bytes() {
                &[digit] => hex_value(digit).ok_or(CandumpError::BadRawDlc)?,
                _ => return Err(CandumpError::BadRawDlc),
            };
            (u64::from(dlc.min(8)), (dlc > 8).then_some(dlc))
        } else {
            let len_text = Some(len_text)
                .and_then(|t| t.strip_prefix('['))
                .and_then(|t| t.strip_suffix(']'))
                .ok_or(CandumpError::MissingSeparator)?;
            let len = parse_decimal(len_text)
                .filter(|n| *n <= 64)
                .ok_or(CandumpError::BadHex)?;
            // lib.c writes a CAN FD frame's length with two digits (`[%02d]`), a classic one's
            // with one (`[%d]`, at most 8).
            if len_text.len() == 2 {
                return Err(CandumpError::FdFrame);
            }
            (len, None)
        };
    let mut data = [0u8; 8];
    let mut n = 0u64;
    while let Some(token) = tokens.next() {
        if token == "remote" {
            return Err(CandumpError::RemoteFrame);
        }
        if len > 8 {
            return Err(CandumpError::FdFrame);
        }
        if n == len && token.starts_with('\'') {
            // `candump -a`: the data as ASCII in quotes (a space in the data splits it).
            let closed = match tokens.last() {
                Some(last) => last.ends_with('\''),
                None => token.len() >= 2 && token.ends_with('\''),
            };
            if closed {
                break;
            }
            return Err(CandumpError::TrailingGarbage);
        }
        let byte = match token.as_bytes() {
            &[hi, lo] => hex_value(hi).zip(hex_value(lo)).map(|(h, l)| (h << 4) | l),
            _ => None,
        };
        let Some(byte) = byte else {
            return Err(if n < len {
                CandumpError::BadHex
            } else {
                CandumpError::TrailingGarbage
            });
        };
        let Some(slot) = data.get_mut(n as usize).filter(|_| n < len) else {
            return Err(CandumpError::TrailingGarbage);
        };
        *slot = byte;
        n += 1;
    }
    if len > 8 {
        return Err(CandumpError::FdFrame);
    }
    if n != len {
        return Err(CandumpError::LengthMismatch);
    }
    Ok((
        TimedFrame {
            t_us,
            frame: CanFrame {
                id,
                len: len as u8,
                data,
            },
        },
        raw_dlc,
    ))
}

/// The interface, identifier and `[LEN]` tokens of a screen-format line's rest (after the
/// timestamp's `)`), past `candump -x`'s `RX` / `TX` and its two flag columns (`- -`, or the
/// CAN FD / XL flags), and the tokens after them (the data); `None` if the line has fewer
/// tokens.
fn screen_fields(rest: &str) -> Option<(&str, &str, &str, SplitAsciiWhitespace<'_>)> {
    let mut tokens = rest.split_ascii_whitespace();
    let iface = tokens.next()?;
    let mut id = tokens.next()?;
    if matches!(id, "RX" | "TX") {
        let flag = |t: &str| matches!(t, "-" | "B" | "E" | "S" | "R");
        if !(flag(tokens.next()?) && flag(tokens.next()?)) {
            return None;
        }
        id = tokens.next()?;
    }
    let len = tokens.next()?;
    Some((iface, id, len, tokens))
}

/// Writes `frame` as one candump line on interface `iface`, without a line terminator:
/// `(SSSSSSSSSS.UUUUUU) IFACE ID#DATA`, upper-case hex.
pub fn format_line<W: Write>(frame: &TimedFrame, iface: &str, out: &mut W) -> core::fmt::Result {
    let secs = frame.t_us / 1_000_000;
    let micros = frame.t_us % 1_000_000;
    write!(out, "({secs:010}.{micros:06}) {iface} ")?;
    match frame.frame.id {
        CanId::Standard(id) => write!(out, "{id:03X}#")?,
        CanId::Extended(id) => write!(out, "{id:08X}#")?,
    }
    for byte in frame.frame.payload() {
        write!(out, "{byte:02X}")?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_raw_dlc_suffix_of_a_classic_frame_of_eight() {
        let (f, dlc) = parse_line_and_dlc("(1.000000) can0 123#1122334455667788_9").unwrap();
        assert_eq!(dlc, Some(9));
        assert_eq!(f.frame.len, 8);
        assert_eq!(
            f.frame.payload(),
            &[0x11, 0x22, 0x33, 0x44, 0x55, 0x66, 0x77, 0x88]
        );
        let (_, dlc) = parse_line_and_dlc("(1.000000) can0 123#1122334455667788_f R").unwrap();
        assert_eq!(dlc, Some(15));
        // The same frame without the suffix: no raw DLC, the same bytes.
        let (g, dlc) = parse_line_and_dlc("(1.000000) can0 123#1122334455667788").unwrap();
        assert_eq!((g, dlc), (f, None));
        for bad in [
            "(1.000000) can0 123#1122334455667788_8",
            "(1.000000) can0 123#1122334455667788_",
            "(1.000000) can0 123#1122334455667788_9A",
            "(1.000000) can0 123#11223344556677_9",
            "(1.000000) can0 123#_9",
            "(1.000000) can0 123#1122334455667788_G",
        ] {
            assert_eq!(parse_line(bad), Err(CandumpError::BadRawDlc), "{bad}");
        }
    }

    #[test]
    fn parses_the_documented_example() {
        let f = parse_line("(1700000000.123456) can0 123#DEADBEEF").unwrap();
        assert_eq!(f.t_us, 1_700_000_000_123_456);
        assert_eq!(f.frame.id, CanId::Standard(0x123));
        assert_eq!(f.frame.payload(), &[0xDE, 0xAD, 0xBE, 0xEF]);
    }
}
