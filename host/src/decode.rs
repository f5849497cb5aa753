//! `catmodel decode FILE.log`: a candump log as decoded signals, with `catmodel.dbc` (the DBC the
//! node's codecs are checked against, built into the binary and read by [`crate::dbc`]).
//!
//! Every frame is shown, in log order: its time, identifier, message name, the result of the
//! integrity checks, and its signals (only the multiplexed page a NODE_STATUS frame carries).
//! Frames whose identifier the DBC lacks are shown as `unknown` with their payload, never
//! dropped. The integrity checks are the node's own functions: the CRC-8/SAE-J1850 of byte 7
//! ([`catmodel::can::crc::frame_crc`]) and the rolling counter
//! ([`catmodel::can::counter::CounterChecker`], one per identifier), for every message whose DBC
//! entry has the `counter` and `crc` signals; NMEA 2000 frames have neither.
//!
//! Two formats:
//! - a table (default): one line per frame, signals as `name=value unit`, aligned per message;
//! - `--csv`: long format, one row per signal (`t_s,id,message,check,signal,raw,value,unit,label,data`),
//!   which pandas reads directly (`pd.read_csv`, then `pivot_table` or a filter on `signal`).
//!
//! The check column, in both: `ok` (CRC right, counter in sequence or the first seen), `crc-error`,
//! `stuck` (the counter did not change), `jump+N` (N frames missed), `dlc-N` (N bytes, not the
//! DBC's length), `-` (a message without counter and CRC), `sa=0xNN` (an NMEA 2000 frame
//! matched by its PGN from another source address), `unknown-id`.
use std::collections::{BTreeMap, BTreeSet};
use std::io::Write;
use std::path::Path;

use anyhow::{bail, Context, Result};
use catmodel::can::counter::{CounterCheck, CounterChecker};
use catmodel::can::crc::frame_crc;
use catmodel::can::{CanId, TimedFrame};

use crate::dbc::{ByteOrder, Dbc, IdMatch, Message, Signal, SignalValue};

/// Output format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// Aligned text, one line per frame.
    Table,
    /// Long CSV, one row per signal.
    Csv,
}

/// The CSV header.
pub const CSV_HEADER: &str = "t_s,id,message,check,signal,raw,value,unit,label,data";

/// Which frames to show: messages of the DBC, and identifiers the DBC may not have.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Selection {
    /// Names of selected messages.
    names: BTreeSet<String>,
    /// Selected identifiers.
    ids: BTreeSet<CanId>,
}

impl Selection {
    /// From `--messages` items: a message name (any case), a name prefix ending in `*`
    /// (`PREDICTION_*`), or an identifier in hex as candump writes it (`300`, `0x3F0`,
    /// `09F8011C`: 3 digits or fewer = 11-bit, more = 29-bit). An empty list selects everything.
    pub fn parse(dbc: &Dbc, items: &[String]) -> Result<Option<Self>> {
        if items.is_empty() {
            return Ok(None);
        }
        let mut selection = Self::default();
        for item in items.iter().map(|i| i.trim()).filter(|i| !i.is_empty()) {
            let upper = item.to_ascii_uppercase();
            let matched: Vec<&Message> = match upper.strip_suffix('*') {
                Some(prefix) => dbc
                    .messages
                    .iter()
                    .filter(|m| m.name.starts_with(prefix))
                    .collect(),
                None => dbc.messages.iter().filter(|m| m.name == upper).collect(),
            };
            if !matched.is_empty() {
                selection
                    .names
                    .extend(matched.iter().map(|m| m.name.clone()));
            } else if let Some(id) = parse_id(item) {
                selection.ids.insert(id);
            } else {
                let names: Vec<&str> = dbc.messages.iter().map(|m| m.name.as_str()).collect();
                bail!(
                    "--messages: {item:?} is neither a message of catmodel.dbc nor a hex identifier; messages: {}",
                    names.join(", ")
                );
            }
        }
        if selection.names.is_empty() && selection.ids.is_empty() {
            // `--messages ''` or `--messages ,`: a selection of nothing shows nothing, as if
            // the log held none of its messages.
            bail!("--messages: no message named (give names, NAME* or hex identifiers, or leave the option out for all)");
        }
        Ok(Some(selection))
    }

    fn contains(&self, id: CanId, message: Option<&Message>) -> bool {
        self.ids.contains(&id) || message.is_some_and(|m| self.names.contains(&m.name))
    }
}

/// A hex identifier: `0x` optional; up to 3 digits (<= 0x7FF) = 11-bit, otherwise 29-bit.
fn parse_id(text: &str) -> Option<CanId> {
    let hex = text
        .strip_prefix("0x")
        .or_else(|| text.strip_prefix("0X"))
        .unwrap_or(text);
    if hex.is_empty() || hex.len() > 8 {
        return None;
    }
    let value = u32::from_str_radix(hex, 16).ok()?;
    let id = if hex.len() <= 3 && value <= 0x7FF {
        CanId::Standard(value as u16)
    } else {
        CanId::Extended(value)
    };
    id.is_valid().then_some(id)
}

/// The integrity verdict of one frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Check {
    /// CRC right; counter first seen or in sequence.
    Ok,
    /// Byte 7 is not the CRC the node computes.
    CrcError {
        /// Byte 7.
        found: u8,
        /// [`frame_crc`] of the frame.
        expected: u8,
    },
    /// Counter unchanged from the previous frame of this identifier.
    Stuck,
    /// Counter skipped `missed` values.
    Jump {
        /// Frames missed.
        missed: u8,
    },
    /// Payload length differs from the DBC's DLC.
    Dlc {
        /// Bytes received.
        len: u8,
    },
    /// A message without counter and CRC (NMEA 2000).
    Unprotected,
    /// A 29-bit frame matched by its PGN, from another source address.
    OtherSource {
        /// The frame's source address.
        source: u8,
    },
    /// The DBC has no message with this identifier.
    UnknownId,
}

impl std::fmt::Display for Check {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Check::Ok => f.write_str("ok"),
            Check::CrcError { .. } => f.write_str("crc-error"),
            Check::Stuck => f.write_str("stuck"),
            Check::Jump { missed } => write!(f, "jump+{missed}"),
            Check::Dlc { len } => write!(f, "dlc-{len}"),
            Check::Unprotected => f.write_str("-"),
            Check::OtherSource { source } => write!(f, "sa=0x{source:02X}"),
            Check::UnknownId => f.write_str("unknown-id"),
        }
    }
}

/// One frame, decoded.
#[derive(Clone, Debug, PartialEq)]
pub struct DecodedFrame<'a> {
    /// The frame as read.
    pub frame: TimedFrame,
    /// Its message, if the DBC has it.
    pub message: Option<&'a Message>,
    /// Integrity verdict.
    pub check: Check,
    /// Signals present in the frame (multiplexed ones of its page only).
    pub signals: Vec<SignalValue<'a>>,
}

/// Counts over a whole log (every frame, selected or not).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Summary {
    /// Frames read.
    pub frames: u64,
    /// Frames shown.
    pub shown: u64,
    /// Frames per message name.
    pub per_message: BTreeMap<String, u64>,
    /// CRC errors.
    pub crc_errors: u64,
    /// Counter jumps and frames they missed.
    pub counter_jumps: u64,
    /// Frames missed in all jumps.
    pub missed_frames: u64,
    /// Stuck counters.
    pub counter_stuck: u64,
    /// Frames with a length other than the DBC's.
    pub dlc_errors: u64,
    /// Frames with identifiers the DBC lacks, per identifier.
    pub unknown_ids: BTreeMap<CanId, u64>,
}

/// Whether a message carries the node's integrity fields: a `counter` and a little-endian
/// 8-bit `crc` in byte 7, the layout [`frame_crc`] checks.
fn protected(message: &Message) -> bool {
    message.signal("counter").is_some()
        && message.signal("crc").is_some_and(|s| {
            (s.start_bit, s.len_bits, s.byte_order) == (56, 8, ByteOrder::LittleEndian)
        })
}

/// Decodes frames one at a time, keeping one counter checker per identifier.
pub struct Decoder<'a> {
    dbc: &'a Dbc,
    counters: BTreeMap<CanId, CounterChecker>,
}

impl<'a> Decoder<'a> {
    /// A decoder that has seen no frame.
    pub fn new(dbc: &'a Dbc) -> Self {
        Self {
            dbc,
            counters: BTreeMap::new(),
        }
    }

    /// Decodes one frame; the counter check compares with the previous frame of its identifier.
    pub fn decode(&mut self, frame: &TimedFrame) -> DecodedFrame<'a> {
        let f = &frame.frame;
        let Some((message, how)) = self.dbc.message_for(f.id) else {
            return DecodedFrame {
                frame: *frame,
                message: None,
                check: Check::UnknownId,
                signals: Vec::new(),
            };
        };
        let signals = message.decode(f.payload());
        let check = if f.len != message.dlc {
            Check::Dlc { len: f.len }
        } else if let IdMatch::Pgn { source } = how {
            Check::OtherSource { source }
        } else if !protected(message) {
            Check::Unprotected
        } else {
            let expected = frame_crc(f.id, &f.data);
            let found = f.data[7];
            if found != expected {
                Check::CrcError { found, expected }
            } else {
                let counter = signal_raw(&signals, "counter").unwrap_or(0) as u8;
                match self.counters.entry(f.id).or_default().check(counter) {
                    CounterCheck::First | CounterCheck::InSequence => Check::Ok,
                    CounterCheck::Stuck => Check::Stuck,
                    CounterCheck::Jump { missed } => Check::Jump { missed },
                }
            }
        };
        DecodedFrame {
            frame: *frame,
            message: Some(message),
            check,
            signals,
        }
    }
}

fn signal_raw(signals: &[SignalValue<'_>], name: &str) -> Option<i128> {
    signals
        .iter()
        .find(|v| v.signal.name == name)
        .map(|v| v.raw)
}

impl Summary {
    fn count(&mut self, d: &DecodedFrame<'_>, shown: bool) {
        self.frames += 1;
        self.shown += u64::from(shown);
        if let Some(m) = d.message {
            *self.per_message.entry(m.name.clone()).or_default() += 1;
        }
        match d.check {
            Check::CrcError { .. } => self.crc_errors += 1,
            Check::Stuck => self.counter_stuck += 1,
            Check::Jump { missed } => {
                self.counter_jumps += 1;
                self.missed_frames += u64::from(missed);
            }
            Check::Dlc { .. } => self.dlc_errors += 1,
            Check::UnknownId => *self.unknown_ids.entry(d.frame.frame.id).or_default() += 1,
            Check::Ok | Check::Unprotected | Check::OtherSource { .. } => {}
        }
    }

    /// One paragraph for stderr.
    pub fn describe(&self) -> String {
        let unknown: u64 = self.unknown_ids.values().sum();
        let mut s = format!(
            "decoded {} frames ({} shown) with catmodel.dbc: {} crc errors, {} counter jumps ({} frames missed), {} stuck counters, {} dlc errors, {} frames with unknown ids",
            self.frames,
            self.shown,
            self.crc_errors,
            self.counter_jumps,
            self.missed_frames,
            self.counter_stuck,
            self.dlc_errors,
            unknown
        );
        if !self.unknown_ids.is_empty() {
            let ids: Vec<String> = self
                .unknown_ids
                .iter()
                .map(|(id, n)| format!("{} x{n}", id_text(*id)))
                .collect();
            s.push_str(&format!(" ({})", ids.join(", ")));
        }
        s
    }
}

/// The identifier as candump writes it: 3 or 8 hex digits.
pub fn id_text(id: CanId) -> String {
    match id {
        CanId::Standard(id) => format!("{id:03X}"),
        CanId::Extended(id) => format!("{id:08X}"),
    }
}

fn time_text(t_us: u64) -> String {
    format!("{}.{:06}", t_us / 1_000_000, t_us % 1_000_000)
}

fn data_text(frame: &TimedFrame) -> String {
    frame
        .frame
        .payload()
        .iter()
        .map(|b| format!("{b:02X}"))
        .collect()
}

/// The physical value at the signal's resolution, or the value description when the DBC has
/// one for the raw value.
fn value_text(v: &SignalValue<'_>) -> String {
    match v.label {
        Some(label) => label.to_string(),
        None => format!("{:.*}", v.signal.decimals(), v.physical),
    }
}

/// Width of a signal's numbers (its raw extremes at its resolution): the column its values
/// are right-aligned in, so that frames of one message line up. A longer value description
/// (`not_available`) overflows it.
fn value_width(s: &Signal) -> usize {
    let len = u32::from(s.len_bits.clamp(1, 64));
    let (lo, hi): (i128, i128) = if s.signed {
        (-(1i128 << (len - 1)), (1i128 << (len - 1)) - 1)
    } else {
        (0, (1i128 << len) - 1)
    };
    let number = |raw: i128| format!("{:.*}", s.decimals(), s.physical(raw)).len();
    number(lo).max(number(hi))
}

/// Writes decoded frames in one of the two formats.
struct Writer<'w, W: Write> {
    out: &'w mut W,
    format: Format,
    t_width: usize,
    name_width: usize,
}

impl<W: Write> Writer<'_, W> {
    fn header(&mut self) -> std::io::Result<()> {
        match self.format {
            Format::Csv => writeln!(self.out, "{CSV_HEADER}"),
            Format::Table => writeln!(
                self.out,
                "{:>tw$}  {:<8}  {:<nw$}  {:<10}  signals (name=value unit)",
                "t_s",
                "id",
                "message",
                "check",
                tw = self.t_width,
                nw = self.name_width
            ),
        }
    }

    fn frame(&mut self, d: &DecodedFrame<'_>) -> std::io::Result<()> {
        let t = time_text(d.frame.t_us);
        let id = id_text(d.frame.frame.id);
        let name = d.message.map_or("unknown", |m| m.name.as_str());
        match self.format {
            Format::Table => {
                write!(
                    self.out,
                    "{t:>tw$}  {id:<8}  {name:<nw$}  {:<10}",
                    d.check.to_string(),
                    tw = self.t_width,
                    nw = self.name_width
                )?;
                if d.message.is_none() {
                    write!(self.out, "  data={}", data_text(&d.frame))?;
                }
                for v in &d.signals {
                    let s = v.signal;
                    if s.name == "crc" {
                        if let Check::CrcError { found, expected } = d.check {
                            write!(self.out, "  crc=0x{found:02X} (expected 0x{expected:02X})")?;
                        }
                        continue;
                    }
                    let unit = if s.unit.is_empty() || v.label.is_some() {
                        String::new()
                    } else {
                        format!(" {}", s.unit)
                    };
                    write!(
                        self.out,
                        "  {}={:>w$}{unit}",
                        s.name,
                        value_text(v),
                        w = value_width(s)
                    )?;
                }
                writeln!(self.out)
            }
            Format::Csv => {
                let data = data_text(&d.frame);
                let check = d.check.to_string();
                if d.signals.is_empty() {
                    return writeln!(
                        self.out,
                        "{t},{id},{},{check},,,,,,{data}",
                        csv_field(if d.message.is_some() { name } else { "" })
                    );
                }
                for v in &d.signals {
                    let s = v.signal;
                    // An out-of-range raw value (a "not available" sentinel) has no physical
                    // value: an empty cell, NaN in pandas; the label says why.
                    let (value, label) = if v.in_range() {
                        (
                            format!("{:.*}", s.decimals(), v.physical),
                            v.label.unwrap_or(""),
                        )
                    } else {
                        (String::new(), v.label.unwrap_or("out_of_range"))
                    };
                    writeln!(
                        self.out,
                        "{t},{id},{},{check},{},{},{value},{},{},{data}",
                        csv_field(name),
                        csv_field(&s.name),
                        v.raw,
                        csv_field(&s.unit),
                        csv_field(label)
                    )?;
                }
                Ok(())
            }
        }
    }
}

/// A CSV field, quoted when it holds a comma, a quote or a line break.
fn csv_field(text: &str) -> String {
    if text.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.to_string()
    }
}

/// Decodes `frames` into `out`; returns the counts over every frame.
pub fn decode_frames<W: Write>(
    dbc: &Dbc,
    frames: &[TimedFrame],
    selection: Option<&Selection>,
    format: Format,
    out: &mut W,
) -> std::io::Result<Summary> {
    let t_width = frames
        .iter()
        .map(|f| time_text(f.t_us).len())
        .max()
        .unwrap_or(3)
        .max(3);
    let name_width = dbc
        .messages
        .iter()
        .map(|m| m.name.len())
        .max()
        .unwrap_or(0)
        .max("unknown".len());
    let mut writer = Writer {
        out,
        format,
        t_width,
        name_width,
    };
    writer.header()?;
    let mut decoder = Decoder::new(dbc);
    let mut summary = Summary::default();
    for frame in frames {
        let d = decoder.decode(frame);
        let shown = selection.is_none_or(|s| s.contains(frame.frame.id, d.message));
        summary.count(&d, shown);
        if shown {
            writer.frame(&d)?;
        }
    }
    Ok(summary)
}

/// `catmodel decode LOG [--interface NAME] [--messages ...] [--csv]`: decodes the log (its
/// frames on `interface` only, if given) to stdout, the summary to
/// stderr. A closed stdout (`| head`) ends the output quietly.
pub fn run(log: &Path, interface: Option<&str>, messages: &[String], format: Format) -> Result<()> {
    let dbc = Dbc::catmodel().map_err(|e| anyhow::anyhow!("catmodel.dbc: {e}"))?;
    let selection = Selection::parse(&dbc, messages)?;
    let crate::replay::CandumpLog {
        frames,
        unsupported,
        ..
    } = crate::replay::read_candump_reporting(log, interface)?;
    if unsupported > 0 {
        eprintln!("skipped {unsupported} remote/FD/error frames (not decoded)");
    }
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    let written = decode_frames(&dbc, &frames, selection.as_ref(), format, &mut out)
        .and_then(|summary| out.flush().map(|()| summary));
    match written {
        Ok(summary) => {
            eprintln!("{}", summary.describe());
            Ok(())
        }
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        Err(e) => Err(e).context("writing to stdout"),
    }
}
