//! A reader of DBC files (the Vector CAN database text format), for `catmodel.dbc`, the single
//! source of truth of the bus: messages (`BO_`, 11-bit ids and 29-bit ids with bit 31 set),
//! signals (`SG_`: start bit, length, byte order, signedness, factor, offset, min/max, unit,
//! receivers, simple multiplexing `M` / `mN`), value tables (`VAL_`), comments (`CM_`), the
//! attributes the bus uses (`GenMsgCycleTime` of a message, `Baudrate`), and the nodes (`BU_`).
//!
//! It is the project's one DBC reader: `catmodel decode` decodes candump logs with it, and
//! `host-tests/tests/dbc.rs` checks the core's descriptor table (`catmodel::can::spec`) against
//! what it reads. Sections a decoder has no use for (`NS_`, `BS_`, attribute definitions,
//! environment variables, signal groups, other attributes) are read past. What it cannot decode
//! correctly is refused with the line it is on: IEEE float signals (`SIG_VALTYPE_`), extended
//! multiplexing (`SG_MUL_VAL_`, `m0M`), signals outside their message.
//!
//! Decoding follows the DBC rules: physical = raw * factor + offset; `@1` little-endian (Intel:
//! the start bit is the least significant bit, bit `b` is bit `b % 8` of byte `b / 8`), `@0`
//! big-endian (Motorola: the start bit is the most significant bit, and the next bit down
//! after bit 0 of a byte is bit 7 of the next byte); `+` unsigned, `-` two's complement.
use std::fmt;

use catmodel::can::CanId;

/// `catmodel.dbc`, built into the binary: the DBC the node's codecs are checked against.
pub const CATMODEL_DBC: &str = include_str!("../../catmodel.dbc");

/// Bit 31 of a `BO_` identifier marks a 29-bit (extended) identifier.
const EXTENDED_FLAG: u64 = 1 << 31;
/// The identifier of Vector's pseudo-message that holds signals belonging to no message.
const INDEPENDENT_SIGNALS_ID: u64 = 0xC000_0000;

/// A DBC file that could not be read: the line and the reason.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DbcError {
    /// 1-based line number.
    pub line: usize,
    /// What is wrong there.
    pub message: String,
}

impl fmt::Display for DbcError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "line {}: {}", self.line, self.message)
    }
}

impl std::error::Error for DbcError {}

/// Byte order of a signal (`@1` / `@0`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ByteOrder {
    /// `@1`, Intel: the start bit is the least significant bit.
    LittleEndian,
    /// `@0`, Motorola: the start bit is the most significant bit.
    BigEndian,
}

/// How a signal takes part in multiplexing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Multiplex {
    /// Always present.
    Plain,
    /// The multiplexer (`M`): its raw value selects which `mN` signals are present.
    Switch,
    /// Present when the multiplexer's raw value is N (`mN`).
    Page(u64),
}

/// One signal of a message.
#[derive(Clone, Debug, PartialEq)]
pub struct Signal {
    /// Name.
    pub name: String,
    /// Start bit: the least significant bit for little-endian, the most significant for
    /// big-endian (DBC numbering: bit `b` is bit `b % 8` of byte `b / 8`).
    pub start_bit: u16,
    /// Length, bits, 1..=64.
    pub len_bits: u16,
    /// Byte order.
    pub byte_order: ByteOrder,
    /// Two's complement (`-`) or unsigned (`+`).
    pub signed: bool,
    /// physical = raw * factor + offset.
    pub factor: f64,
    /// See `factor`.
    pub offset: f64,
    /// Smallest valid physical value (`[min|max]`; both 0 = no limits given).
    pub min: f64,
    /// Largest valid physical value.
    pub max: f64,
    /// Unit text (may be empty).
    pub unit: String,
    /// Receiving nodes.
    pub receivers: Vec<String>,
    /// Multiplexing role.
    pub multiplex: Multiplex,
    /// Value descriptions from `VAL_`: raw value and its name (e.g. `not_available`).
    pub values: Vec<(i64, String)>,
    /// `CM_ SG_` text.
    pub comment: Option<String>,
}

/// One message (`BO_`) and its signals.
#[derive(Clone, Debug, PartialEq)]
pub struct Message {
    /// Identifier (11- or 29-bit).
    pub id: CanId,
    /// Name.
    pub name: String,
    /// Data length, bytes.
    pub dlc: u8,
    /// Sending node.
    pub transmitter: String,
    /// Signals in file order.
    pub signals: Vec<Signal>,
    /// `GenMsgCycleTime`, ms.
    pub cycle_ms: Option<u64>,
    /// `CM_ BO_` text.
    pub comment: Option<String>,
}

/// A whole DBC file.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Dbc {
    /// `VERSION` text.
    pub version: String,
    /// Nodes of `BU_`.
    pub nodes: Vec<String>,
    /// Messages in file order.
    pub messages: Vec<Message>,
    /// The network's `Baudrate` attribute, bit/s.
    pub baudrate: Option<u64>,
    /// The file's general `CM_` text.
    pub comment: Option<String>,
}

/// One signal's value in one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SignalValue<'a> {
    /// The signal.
    pub signal: &'a Signal,
    /// Raw value (sign-extended for signed signals).
    pub raw: i128,
    /// raw * factor + offset.
    pub physical: f64,
    /// The value description of `raw`, if the DBC has one.
    pub label: Option<&'a str>,
}

impl SignalValue<'_> {
    /// Whether the physical value lies within the signal's `[min|max]` (always, without limits).
    pub fn in_range(&self) -> bool {
        let s = self.signal;
        // Half a raw step of slack: min/max are decimal text, the value is raw * factor.
        let slack = 0.5 * s.factor.abs();
        (s.min == 0.0 && s.max == 0.0)
            || (self.physical >= s.min - slack && self.physical <= s.max + slack)
    }
}

impl Signal {
    /// The raw value in `data`, or `None` if the signal reaches past `data`'s end.
    pub fn raw(&self, data: &[u8]) -> Option<i128> {
        let len = u32::from(self.len_bits);
        if !(1..=64).contains(&len) {
            return None;
        }
        let mut bits: u128 = 0;
        match self.byte_order {
            ByteOrder::LittleEndian => {
                for k in (0..len).rev() {
                    bits = bits << 1 | u128::from(bit_at(data, u32::from(self.start_bit) + k)?);
                }
            }
            ByteOrder::BigEndian => {
                let mut pos = u32::from(self.start_bit);
                for k in 0..len {
                    bits = bits << 1 | u128::from(bit_at(data, pos)?);
                    if k + 1 < len {
                        // Down one bit within the byte; from bit 0, to bit 7 of the next byte.
                        pos = if pos % 8 == 0 { pos + 15 } else { pos - 1 };
                    }
                }
            }
        }
        let sign = 1u128 << (len - 1);
        Some(if self.signed && bits & sign != 0 {
            bits as i128 - (1i128 << len)
        } else {
            bits as i128
        })
    }

    /// raw * factor + offset.
    pub fn physical(&self, raw: i128) -> f64 {
        raw as f64 * self.factor + self.offset
    }

    /// The value description of `raw`.
    pub fn label(&self, raw: i128) -> Option<&str> {
        self.values
            .iter()
            .find(|(v, _)| i128::from(*v) == raw)
            .map(|(_, name)| name.as_str())
    }

    /// Decimals that show every physical value exactly: those of the factor and the offset
    /// (0.01 -> 2, 1e-07 -> 7, 10 -> 0).
    pub fn decimals(&self) -> usize {
        decimals_of(self.factor).max(decimals_of(self.offset))
    }

    /// The value of this signal in `data`; `None` if it reaches past `data`'s end.
    pub fn value(&self, data: &[u8]) -> Option<SignalValue<'_>> {
        let raw = self.raw(data)?;
        Some(SignalValue {
            signal: self,
            raw,
            physical: self.physical(raw),
            label: self.label(raw),
        })
    }
}

/// Bit `pos` of `data` in DBC numbering, or `None` past the end.
fn bit_at(data: &[u8], pos: u32) -> Option<u8> {
    let byte = data.get(usize::try_from(pos / 8).ok()?)?;
    Some(byte >> (pos % 8) & 1)
}

/// The fewest decimals (up to 12) that write `x` exactly.
fn decimals_of(x: f64) -> usize {
    (0..=12)
        .find(|&d| {
            let scaled = x * 10f64.powi(d as i32);
            (scaled - scaled.round()).abs() < 1e-9 * scaled.abs().max(1.0)
        })
        .unwrap_or(12)
}

impl Message {
    /// A signal by name.
    pub fn signal(&self, name: &str) -> Option<&Signal> {
        self.signals.iter().find(|s| s.name == name)
    }

    /// The multiplexer signal, if the message has one.
    pub fn multiplexer(&self) -> Option<&Signal> {
        self.signals
            .iter()
            .find(|s| s.multiplex == Multiplex::Switch)
    }

    /// The signals present in `data`, in file order, with their values: the plain ones, the
    /// multiplexer, and the `mN` signals of the page the multiplexer selects. Signals that reach
    /// past `data` (a frame shorter than the DBC's DLC) are left out.
    pub fn decode<'a>(&'a self, data: &[u8]) -> Vec<SignalValue<'a>> {
        let page = self
            .multiplexer()
            .and_then(|m| m.raw(data))
            .and_then(|raw| u64::try_from(raw).ok());
        self.signals
            .iter()
            .filter(|s| match s.multiplex {
                Multiplex::Plain | Multiplex::Switch => true,
                Multiplex::Page(p) => Some(p) == page,
            })
            .filter_map(|s| s.value(data))
            .collect()
    }

    /// The NMEA 2000 / J1939 parameter group number of a 29-bit message (`None` for 11-bit).
    pub fn pgn(&self) -> Option<u32> {
        match self.id {
            CanId::Extended(id) => Some(catmodel::can::spec::n2k_pgn_source(id).0),
            CanId::Standard(_) => None,
        }
    }
}

/// How a frame's identifier matched a message.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum IdMatch {
    /// The identifier is the message's.
    Exact,
    /// A 29-bit identifier with the message's PGN from another priority or source address
    /// (NMEA 2000 receivers are configurable): the frame's source address.
    Pgn {
        /// The frame's source address.
        source: u8,
    },
}

impl Dbc {
    /// `catmodel.dbc` as built into the binary.
    pub fn catmodel() -> Result<Self, DbcError> {
        Self::parse(CATMODEL_DBC)
    }

    /// Reads a DBC text.
    pub fn parse(text: &str) -> Result<Self, DbcError> {
        Parser::new(text)?.file()
    }

    /// A message by name.
    pub fn message(&self, name: &str) -> Option<&Message> {
        self.messages.iter().find(|m| m.name == name)
    }

    /// The message of a frame's identifier: the exact identifier, or for a 29-bit identifier
    /// the message with the same PGN (any priority and source address).
    pub fn message_for(&self, id: CanId) -> Option<(&Message, IdMatch)> {
        if let Some(m) = self.messages.iter().find(|m| m.id == id) {
            return Some((m, IdMatch::Exact));
        }
        let CanId::Extended(raw) = id else {
            return None;
        };
        let (pgn, source) = catmodel::can::spec::n2k_pgn_source(raw);
        self.messages
            .iter()
            .find(|m| m.pgn() == Some(pgn))
            .map(|m| (m, IdMatch::Pgn { source }))
    }
}

// ---------------------------------------------------------------------------------------------
// Tokens

#[derive(Clone, Debug, PartialEq)]
enum Tok {
    /// Keyword or name.
    Ident(String),
    /// Number as written.
    Num(String),
    /// Quoted string, unescaped.
    Str(String),
    /// One of `: | @ ( ) , [ ] ; + -`.
    Punct(char),
}

impl fmt::Display for Tok {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Tok::Ident(s) | Tok::Num(s) => write!(f, "`{s}`"),
            Tok::Str(s) => write!(f, "\"{s}\""),
            Tok::Punct(c) => write!(f, "`{c}`"),
        }
    }
}

/// Splits the text into tokens with their line numbers.
fn tokenize(text: &str) -> Result<Vec<(usize, Tok)>, DbcError> {
    let mut out = Vec::new();
    let mut chars = text.chars().peekable();
    let mut line = 1;
    while let Some(&c) = chars.peek() {
        let start_line = line;
        if c == '\n' {
            line += 1;
            chars.next();
        } else if c.is_whitespace() {
            chars.next();
        } else if c == '"' {
            chars.next();
            let mut s = String::new();
            loop {
                match chars.next() {
                    None => {
                        return Err(DbcError {
                            line: start_line,
                            message: "string not closed".into(),
                        })
                    }
                    Some('"') => break,
                    Some('\\') => {
                        if let Some(e) = chars.next() {
                            line += usize::from(e == '\n');
                            s.push(e);
                        }
                    }
                    Some(ch) => {
                        line += usize::from(ch == '\n');
                        s.push(ch);
                    }
                }
            }
            out.push((start_line, Tok::Str(s)));
        } else if c.is_ascii_alphabetic() || c == '_' {
            let mut s = String::new();
            while let Some(&ch) = chars.peek() {
                if ch.is_ascii_alphanumeric() || ch == '_' {
                    s.push(ch);
                    chars.next();
                } else {
                    break;
                }
            }
            out.push((line, Tok::Ident(s)));
        } else if c.is_ascii_digit() || c == '.' || (c == '-' && starts_number(&chars)) {
            let mut s = String::new();
            s.push(c);
            chars.next();
            while let Some(&ch) = chars.peek() {
                let exponent_sign = (ch == '-' || ch == '+') && s.ends_with(['e', 'E']);
                if ch.is_ascii_digit() || ch == '.' || ch == 'e' || ch == 'E' || exponent_sign {
                    s.push(ch);
                    chars.next();
                } else {
                    break;
                }
            }
            out.push((line, Tok::Num(s)));
        } else if ":|@(),[];+-".contains(c) {
            out.push((line, Tok::Punct(c)));
            chars.next();
        } else {
            return Err(DbcError {
                line,
                message: format!("unexpected character {c:?}"),
            });
        }
    }
    Ok(out)
}

/// Whether the `-` at the front of `chars` starts a negative number (a digit follows).
fn starts_number(chars: &std::iter::Peekable<std::str::Chars<'_>>) -> bool {
    let mut ahead = chars.clone();
    ahead.next();
    ahead.next().is_some_and(|c| c.is_ascii_digit() || c == '.')
}

// ---------------------------------------------------------------------------------------------
// Parser

struct Parser {
    toks: Vec<(usize, Tok)>,
    at: usize,
    /// Line of the last token (for errors at the end of the file).
    last_line: usize,
}

type Parsed<T> = Result<T, DbcError>;

impl Parser {
    fn new(text: &str) -> Parsed<Self> {
        let toks = tokenize(text)?;
        let last_line = toks.last().map_or(1, |t| t.0);
        Ok(Self {
            toks,
            at: 0,
            last_line,
        })
    }

    fn line(&self) -> usize {
        self.toks.get(self.at).map_or(self.last_line, |t| t.0)
    }

    fn peek(&self) -> Option<&Tok> {
        self.toks.get(self.at).map(|t| &t.1)
    }

    fn error<T>(&self, message: impl Into<String>) -> Parsed<T> {
        Err(DbcError {
            line: self.line(),
            message: message.into(),
        })
    }

    fn next(&mut self, what: &str) -> Parsed<Tok> {
        match self.toks.get(self.at) {
            Some((_, t)) => {
                self.at += 1;
                Ok(t.clone())
            }
            None => self.error(format!("file ends where {what} was expected")),
        }
    }

    fn punct(&mut self, c: char) -> Parsed<()> {
        match self.next(&format!("`{c}`"))? {
            Tok::Punct(p) if p == c => Ok(()),
            t => self.back_error(format!("expected `{c}`, found {t}")),
        }
    }

    /// An error about the token just taken.
    fn back_error<T>(&mut self, message: String) -> Parsed<T> {
        self.at = self.at.saturating_sub(1);
        self.error(message)
    }

    fn ident(&mut self, what: &str) -> Parsed<String> {
        match self.next(what)? {
            Tok::Ident(s) => Ok(s),
            t => self.back_error(format!("expected {what}, found {t}")),
        }
    }

    fn string(&mut self, what: &str) -> Parsed<String> {
        match self.next(what)? {
            Tok::Str(s) => Ok(s),
            t => self.back_error(format!("expected {what} (a quoted string), found {t}")),
        }
    }

    fn number_text(&mut self, what: &str) -> Parsed<String> {
        match self.next(what)? {
            Tok::Num(s) => Ok(s),
            t => self.back_error(format!("expected {what}, found {t}")),
        }
    }

    fn float(&mut self, what: &str) -> Parsed<f64> {
        let text = self.number_text(what)?;
        match text.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => self.back_error(format!("{what}: {text:?} is not a finite number")),
        }
    }

    fn integer(&mut self, what: &str) -> Parsed<i64> {
        let text = self.number_text(what)?;
        match text.parse::<i64>() {
            Ok(v) => Ok(v),
            Err(_) => self.back_error(format!("{what}: {text:?} is not an integer")),
        }
    }

    fn unsigned(&mut self, what: &str) -> Parsed<u64> {
        let text = self.number_text(what)?;
        match text.parse::<u64>() {
            Ok(v) => Ok(v),
            Err(_) => self.back_error(format!("{what}: {text:?} is not an unsigned integer")),
        }
    }

    /// Skips to just past the next `;`.
    fn skip_statement(&mut self) -> Parsed<()> {
        while self.next("`;`")? != Tok::Punct(';') {}
        Ok(())
    }

    /// Skips the rest of the current line's tokens (`line` is the statement's line).
    fn skip_line(&mut self, line: usize) {
        while self.toks.get(self.at).is_some_and(|t| t.0 == line) {
            self.at += 1;
        }
    }

    fn file(mut self) -> Parsed<Dbc> {
        let mut dbc = Dbc::default();
        while let Some(tok) = self.peek().cloned() {
            let line = self.line();
            let Tok::Ident(keyword) = tok else {
                return self.error(format!("expected a keyword, found {tok}"));
            };
            self.at += 1;
            match keyword.as_str() {
                "VERSION" => dbc.version = self.string("the version")?,
                "NS_" => {
                    // The list of new symbols: names on the following lines, up to BS_.
                    self.punct(':')?;
                    while matches!(self.peek(), Some(Tok::Ident(k)) if k != "BS_" && k != "BU_") {
                        self.at += 1;
                    }
                }
                "BS_" => self.skip_line(line),
                "BU_" => {
                    self.punct(':')?;
                    while self.toks.get(self.at).is_some_and(|t| t.0 == line) {
                        dbc.nodes.push(self.ident("a node name")?);
                    }
                }
                "BO_" => {
                    if let Some(m) = self.message()? {
                        dbc.messages.push(m);
                    }
                }
                "SG_" => {
                    let signal = self.signal()?;
                    match dbc.messages.last_mut() {
                        Some(m) => self.add_signal(m, signal, line)?,
                        None => {
                            return Err(DbcError {
                                line,
                                message: format!(
                                    "signal `{}` outside a message (no BO_ before it)",
                                    signal.name
                                ),
                            })
                        }
                    }
                }
                "CM_" => self.comment(&mut dbc)?,
                "BA_" => self.attribute(&mut dbc)?,
                "VAL_" => self.value_descriptions(&mut dbc)?,
                "SIG_VALTYPE_" => {
                    return Err(DbcError {
                        line,
                        message: "IEEE float signals (SIG_VALTYPE_) are not supported".into(),
                    })
                }
                "SG_MUL_VAL_" => {
                    return Err(DbcError {
                        line,
                        message: "extended multiplexing (SG_MUL_VAL_) is not supported".into(),
                    })
                }
                // Definitions and sections a decoder does not need; all end with `;`.
                "BA_DEF_" | "BA_DEF_DEF_" | "BA_DEF_REL_" | "BA_DEF_DEF_REL_" | "BA_REL_"
                | "VAL_TABLE_" | "BO_TX_BU_" | "EV_" | "ENVVAR_DATA_" | "SGTYPE_"
                | "SIG_GROUP_" | "SIG_TYPE_REF_" | "SGTYPE_VAL_" | "CAT_DEF_" | "CAT_"
                | "FILTER" => self.skip_statement()?,
                other => {
                    return Err(DbcError {
                        line,
                        message: format!("unknown keyword `{other}`"),
                    })
                }
            }
        }
        Ok(dbc)
    }

    /// `BO_ ID NAME: DLC TRANSMITTER`; `None` for Vector's independent-signals pseudo-message.
    fn message(&mut self) -> Parsed<Option<Message>> {
        let raw = self.unsigned("a message identifier")?;
        let id = if raw & EXTENDED_FLAG != 0 {
            let id = raw & !EXTENDED_FLAG;
            if raw == INDEPENDENT_SIGNALS_ID {
                // Its signals follow; they belong to no frame. Read them into a message that
                // is dropped.
                self.ident("the message name")?;
                self.punct(':')?;
                self.unsigned("the DLC")?;
                self.ident("the transmitter")?;
                while self.peek() == Some(&Tok::Ident("SG_".into())) {
                    self.at += 1;
                    self.signal()?;
                }
                return Ok(None);
            }
            match u32::try_from(id) {
                Ok(id) if id <= 0x1FFF_FFFF => CanId::Extended(id),
                _ => return self.back_error(format!("identifier {raw} is not a 29-bit id")),
            }
        } else {
            match u16::try_from(raw) {
                Ok(id) if id <= 0x7FF => CanId::Standard(id),
                _ => {
                    return self.back_error(format!(
                        "identifier {raw} is above 0x7FF without the extended flag (bit 31)"
                    ))
                }
            }
        };
        let name = self.ident("the message name")?;
        self.punct(':')?;
        let dlc = self.unsigned("the DLC")?;
        let Ok(dlc) = u8::try_from(dlc) else {
            return self.back_error(format!("DLC {dlc} of `{name}` is not a byte count"));
        };
        if dlc > 8 {
            return self.back_error(format!(
                "DLC {dlc} of `{name}`: CAN FD frames are not supported (at most 8 bytes)"
            ));
        }
        let transmitter = self.ident("the transmitter")?;
        Ok(Some(Message {
            id,
            name,
            dlc,
            transmitter,
            signals: Vec::new(),
            cycle_ms: None,
            comment: None,
        }))
    }

    /// `SG_ NAME [M|mN] : START|LEN@ORDER SIGN (FACTOR,OFFSET) [MIN|MAX] "UNIT" RECEIVERS`.
    fn signal(&mut self) -> Parsed<Signal> {
        let line = self.line();
        let name = self.ident("the signal name")?;
        let multiplex = match self.peek() {
            Some(Tok::Ident(m)) => {
                let m = m.clone();
                self.at += 1;
                if m == "M" {
                    Multiplex::Switch
                } else if let Some(page) = m.strip_prefix('m').and_then(|p| p.parse().ok()) {
                    Multiplex::Page(page)
                } else {
                    return self.back_error(format!(
                        "`{name}`: multiplex indicator `{m}` is not `M` or `mN` (extended multiplexing is not supported)"
                    ));
                }
            }
            _ => Multiplex::Plain,
        };
        self.punct(':')?;
        let start_bit = self.unsigned("the start bit")?;
        self.punct('|')?;
        let len_bits = self.unsigned("the length")?;
        self.punct('@')?;
        let byte_order = match self.number_text("the byte order")?.as_str() {
            "1" => ByteOrder::LittleEndian,
            "0" => ByteOrder::BigEndian,
            other => return self.back_error(format!("byte order `{other}` is not 0 or 1")),
        };
        let signed = match self.next("the sign")? {
            Tok::Punct('+') => false,
            Tok::Punct('-') => true,
            t => return self.back_error(format!("expected `+` or `-`, found {t}")),
        };
        self.punct('(')?;
        let factor = self.float("the factor")?;
        self.punct(',')?;
        let offset = self.float("the offset")?;
        self.punct(')')?;
        self.punct('[')?;
        let min = self.float("the minimum")?;
        self.punct('|')?;
        let max = self.float("the maximum")?;
        self.punct(']')?;
        let unit = self.string("the unit")?;
        let mut receivers = Vec::new();
        while self.toks.get(self.at).is_some_and(|t| t.0 == line) {
            match self.next("a receiver")? {
                Tok::Ident(r) => receivers.push(r),
                Tok::Punct(',') => {}
                t => return self.back_error(format!("expected a receiver, found {t}")),
            }
        }
        let (Ok(start_bit), Ok(len_bits)) = (u16::try_from(start_bit), u16::try_from(len_bits))
        else {
            return Err(DbcError {
                line,
                message: format!("`{name}`: start bit or length out of range"),
            });
        };
        if !(1..=64).contains(&len_bits) {
            return Err(DbcError {
                line,
                message: format!("`{name}`: length {len_bits} is not 1..=64 bits"),
            });
        }
        if factor == 0.0 {
            return Err(DbcError {
                line,
                message: format!("`{name}`: factor 0"),
            });
        }
        Ok(Signal {
            name,
            start_bit,
            len_bits,
            byte_order,
            signed,
            factor,
            offset,
            min,
            max,
            unit,
            receivers,
            multiplex,
            values: Vec::new(),
            comment: None,
        })
    }

    /// Adds `signal` to `message` after checking that it fits the DLC and its name is new.
    fn add_signal(&self, message: &mut Message, signal: Signal, line: usize) -> Parsed<()> {
        let bits = usize::from(message.dlc) * 8;
        let zeros = vec![0u8; usize::from(message.dlc)];
        if signal.raw(&zeros).is_none() || usize::from(signal.start_bit) >= bits {
            return Err(DbcError {
                line,
                message: format!(
                    "`{}.{}` (start bit {}, {} bits) does not fit the {}-byte message",
                    message.name, signal.name, signal.start_bit, signal.len_bits, message.dlc
                ),
            });
        }
        if message.signal(&signal.name).is_some() {
            return Err(DbcError {
                line,
                message: format!("`{}.{}` is defined twice", message.name, signal.name),
            });
        }
        if signal.multiplex == Multiplex::Switch && message.multiplexer().is_some() {
            return Err(DbcError {
                line,
                message: format!(
                    "`{}` has a second multiplexer `{}`",
                    message.name, signal.name
                ),
            });
        }
        message.signals.push(signal);
        Ok(())
    }

    /// The message with identifier `raw` as written in a `BO_` line.
    fn message_by_raw(dbc: &mut Dbc, raw: u64, line: usize) -> Parsed<&mut Message> {
        dbc.messages
            .iter_mut()
            .find(|m| bo_raw_id(m.id) == raw)
            .ok_or(DbcError {
                line,
                message: format!("no message with identifier {raw}"),
            })
    }

    /// The signal `name` of the message with identifier `raw`.
    fn signal_by_raw<'d>(
        dbc: &'d mut Dbc,
        raw: u64,
        name: &str,
        line: usize,
    ) -> Parsed<&'d mut Signal> {
        let message = Self::message_by_raw(dbc, raw, line)?;
        let message_name = message.name.clone();
        message
            .signals
            .iter_mut()
            .find(|s| s.name == name)
            .ok_or(DbcError {
                line,
                message: format!("message `{message_name}` has no signal `{name}`"),
            })
    }

    /// `CM_ [BU_ NAME | BO_ ID | SG_ ID NAME | EV_ NAME] "TEXT";`
    fn comment(&mut self, dbc: &mut Dbc) -> Parsed<()> {
        let line = self.line();
        match self.peek().cloned() {
            Some(Tok::Str(text)) => {
                self.at += 1;
                dbc.comment = Some(text);
            }
            Some(Tok::Ident(kind)) => {
                self.at += 1;
                match kind.as_str() {
                    "BO_" => {
                        let raw = self.unsigned("a message identifier")?;
                        let text = self.string("the comment")?;
                        Self::message_by_raw(dbc, raw, line)?.comment = Some(text);
                    }
                    "SG_" => {
                        let raw = self.unsigned("a message identifier")?;
                        let name = self.ident("a signal name")?;
                        let text = self.string("the comment")?;
                        Self::signal_by_raw(dbc, raw, &name, line)?.comment = Some(text);
                    }
                    "BU_" | "EV_" => {
                        self.ident("a name")?;
                        self.string("the comment")?;
                    }
                    other => return self.back_error(format!("unknown comment target `{other}`")),
                }
            }
            _ => return self.error("expected a comment"),
        }
        self.punct(';')
    }

    /// `BA_ "NAME" [BO_ ID | SG_ ID NAME | BU_ NAME] VALUE;`: keeps `GenMsgCycleTime` and the
    /// network's `Baudrate`.
    fn attribute(&mut self, dbc: &mut Dbc) -> Parsed<()> {
        let line = self.line();
        let name = self.string("the attribute name")?;
        match self.peek().cloned() {
            Some(Tok::Ident(kind)) if kind == "BO_" => {
                self.at += 1;
                let raw = self.unsigned("a message identifier")?;
                if name == "GenMsgCycleTime" {
                    let ms = self.unsigned("the cycle time")?;
                    Self::message_by_raw(dbc, raw, line)?.cycle_ms = Some(ms);
                    return self.punct(';');
                }
            }
            Some(Tok::Num(_)) if name == "Baudrate" => {
                dbc.baudrate = Some(self.unsigned("the baud rate")?);
                return self.punct(';');
            }
            _ => {}
        }
        self.skip_statement()
    }

    /// `VAL_ ID NAME (VALUE "TEXT")*;` (a `VAL_` of an environment variable is skipped).
    fn value_descriptions(&mut self, dbc: &mut Dbc) -> Parsed<()> {
        let line = self.line();
        if matches!(self.peek(), Some(Tok::Ident(_))) {
            return self.skip_statement();
        }
        let raw = self.unsigned("a message identifier")?;
        let name = self.ident("a signal name")?;
        let mut values = Vec::new();
        while self.peek() != Some(&Tok::Punct(';')) {
            let value = self.integer("a raw value")?;
            let text = self.string("its description")?;
            values.push((value, text));
        }
        self.punct(';')?;
        Self::signal_by_raw(dbc, raw, &name, line)?.values = values;
        Ok(())
    }
}

/// The identifier as a `BO_` line writes it (bit 31 set for 29-bit ids).
pub fn bo_raw_id(id: CanId) -> u64 {
    match id {
        CanId::Standard(id) => u64::from(id),
        CanId::Extended(id) => u64::from(id) | EXTENDED_FLAG,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SMALL: &str = r#"VERSION "t"
NS_ :
	CM_
	VAL_
BS_:
BU_: A B
BO_ 291 TEST: 8 A
 SG_ le_u12 : 4|12@1+ (0.5,-10) [-10|2037.5] "m" B
 SG_ le_i8 : 16|8@1- (1,0) [-128|127] "" B,A
 SG_ be_u16 : 39|16@0+ (0.01,0) [0|655.35] "m/s" B
 SG_ mux M : 56|2@1+ (1,0) [0|3] "" B
 SG_ on0 m0 : 58|6@1+ (1,0) [0|63] "" B
 SG_ on1 m1 : 58|6@1- (1,0) [-32|31] "" B
BO_ 2566848796 N2K: 8 A
 SG_ v : 0|32@1- (1e-07,0) [-90|90] "deg" B
CM_ "file";
CM_ SG_ 291 le_u12 "a
two-line comment";
BA_DEF_ BO_ "GenMsgCycleTime" INT 0 10000;
BA_ "Baudrate" 250000;
BA_ "GenMsgCycleTime" BO_ 291 20;
VAL_ 291 mux 0 "zero" 1 "one" ;
VAL_ 291 le_i8 -1 "minus one" ;
"#;

    #[test]
    fn reads_messages_signals_and_their_attributes() {
        let dbc = Dbc::parse(SMALL).unwrap();
        assert_eq!(dbc.version, "t");
        assert_eq!(dbc.nodes, ["A", "B"]);
        assert_eq!(dbc.baudrate, Some(250_000));
        assert_eq!(dbc.comment.as_deref(), Some("file"));
        let m = dbc.message("TEST").unwrap();
        assert_eq!(
            (m.id, m.dlc, m.cycle_ms),
            (CanId::Standard(0x123), 8, Some(20))
        );
        let s = m.signal("le_u12").unwrap();
        assert_eq!((s.start_bit, s.len_bits, s.signed), (4, 12, false));
        assert_eq!(
            (s.factor, s.offset, s.min, s.max),
            (0.5, -10.0, -10.0, 2037.5)
        );
        assert_eq!(s.comment.as_deref(), Some("a\ntwo-line comment"));
        assert_eq!(m.signal("le_i8").unwrap().receivers, ["B", "A"]);
        assert_eq!(m.signal("be_u16").unwrap().byte_order, ByteOrder::BigEndian);
        assert_eq!(m.signal("on1").unwrap().multiplex, Multiplex::Page(1));
        assert_eq!(m.multiplexer().unwrap().values[1], (1, "one".to_string()));
        let n2k = dbc.message("N2K").unwrap();
        assert_eq!(n2k.id, CanId::Extended(0x18FF_011C));
        assert_eq!(n2k.pgn(), Some(0xFF01));
    }

    /// Every value worked out by hand from the bit layout.
    #[test]
    fn decodes_a_hand_made_frame() {
        let dbc = Dbc::parse(SMALL).unwrap();
        let m = dbc.message("TEST").unwrap();
        // le_u12 at bits 4..15: raw 0xABC -> bytes 0 = 0xC0, 1 = 0xAB.
        // le_i8 at byte 2: 0xFF = -1.
        // be_u16, start (MSB) bit 39 = bit 7 of byte 4: bytes 4, 5 = 0x12, 0x34 -> 0x1234.
        // mux (bits 56, 57) = 1, on1 (bits 58..63, signed 6) = 0b111110 = -2.
        let data = [0xC0, 0xAB, 0xFF, 0x00, 0x12, 0x34, 0x00, 0b1111_1001];
        let values = m.decode(&data);
        let get = |n: &str| values.iter().find(|v| v.signal.name == n).copied();
        let u12 = get("le_u12").unwrap();
        assert_eq!((u12.raw, u12.physical), (0xABC, 0.5 * 2748.0 - 10.0));
        assert_eq!(get("le_i8").unwrap().raw, -1);
        assert_eq!(get("le_i8").unwrap().label, Some("minus one"));
        assert_eq!(get("be_u16").unwrap().raw, 0x1234);
        assert_eq!(get("mux").unwrap().label, Some("one"));
        assert_eq!(get("on1").unwrap().raw, -2);
        assert!(get("on0").is_none(), "page 0 signal shown on page 1");
        // A frame too short for a signal leaves that signal out.
        assert!(m
            .decode(&data[..2])
            .iter()
            .all(|v| v.signal.name == "le_u12"));
    }

    #[test]
    fn extended_ids_match_by_pgn_from_any_source() {
        let dbc = Dbc::parse(SMALL).unwrap();
        assert_eq!(
            dbc.message_for(CanId::Extended(0x18FF_011C))
                .map(|(m, k)| (&m.name[..], k)),
            Some(("N2K", IdMatch::Exact))
        );
        assert_eq!(
            dbc.message_for(CanId::Extended(0x0CFF_0105))
                .map(|(m, k)| (&m.name[..], k)),
            Some(("N2K", IdMatch::Pgn { source: 5 }))
        );
        assert!(dbc.message_for(CanId::Extended(0x18FE_011C)).is_none());
        assert!(dbc.message_for(CanId::Standard(0x124)).is_none());
    }

    #[test]
    fn decimals_follow_the_factor() {
        let dbc = Dbc::parse(SMALL).unwrap();
        let m = dbc.message("TEST").unwrap();
        assert_eq!(m.signal("le_u12").unwrap().decimals(), 1);
        assert_eq!(m.signal("le_i8").unwrap().decimals(), 0);
        assert_eq!(m.signal("be_u16").unwrap().decimals(), 2);
        assert_eq!(dbc.message("N2K").unwrap().signals[0].decimals(), 7);
    }

    #[test]
    fn errors_name_their_line() {
        let cases = [
            (
                "BO_ 1 A: 8 X\n SG_ s : 60|8@1+ (1,0) [0|1] \"\" X\n",
                2,
                "does not fit",
            ),
            (
                "BO_ 1 A: 8 X\n SG_ s : 0|8@2+ (1,0) [0|1] \"\" X\n",
                2,
                "byte order",
            ),
            (
                "\n SG_ s : 0|8@1+ (1,0) [0|1] \"\" X\n",
                2,
                "outside a message",
            ),
            (
                "BO_ 1 A: 8 X\n\nVAL_ 2 s 0 \"x\" ;\n",
                3,
                "no message with identifier 2",
            ),
            ("BO_ 1 A: 8 X\nCM_ SG_ 1 t \"x\";\n", 2, "has no signal `t`"),
            ("BO_ 4096 A: 8 X\n", 1, "above 0x7FF"),
            ("BO_ 1 A: 64 X\n", 1, "CAN FD"),
            ("VERSION \"x\"\nFOO_ 1;\n", 2, "unknown keyword `FOO_`"),
            ("SIG_VALTYPE_ 1 s : 1;\n", 1, "float"),
            (
                "BO_ 1 A: 8 X\n SG_ s m1M : 0|8@1+ (1,0) [0|1] \"\" X\n",
                2,
                "extended",
            ),
            ("CM_ \"open\n\n", 1, "string not closed"),
            (
                "BO_ 1 A: 8 X\n SG_ s : 0|8@1+ (0,0) [0|1] \"\" X\n",
                2,
                "factor 0",
            ),
        ];
        for (text, line, want) in cases {
            let e = Dbc::parse(text).unwrap_err();
            assert_eq!(e.line, line, "{text:?}: {e}");
            assert!(e.message.contains(want), "{text:?}: {e}");
        }
    }

    #[test]
    fn the_bundled_dbc_reads() {
        let dbc = Dbc::catmodel().unwrap();
        assert_eq!(dbc.messages.len(), catmodel::can::spec::MESSAGES.len());
        assert_eq!(dbc.baudrate, Some(500_000));
    }
}
