//! Properties of the input decoders and of the candump parser that assert on every generated
//! case, against references written here from the DBC's rules (not from the code under test):
//!
//! - every frame of a protected input (steering, speed, pedals) with a random payload, counter,
//!   DLC and CRC (right or wrong, about half of each) is classified exactly: a wrong DLC is a
//!   DLC error, then a wrong CRC a CRC error, then every signal is checked against its DBC range
//!   (a value outside is an out-of-range error naming it, the invalid sentinel of a required
//!   signal an invalid error naming it), and a frame that decodes re-encodes to itself;
//! - every line made from a valid candump line by a few random edits (about half stay valid) is
//!   parsed exactly when a reference grammar of the candump format accepts it, to the frame the
//!   grammar reads.
use catmodel::can::candump::{format_line, parse_line, MAX_IFACE_LEN};
use catmodel::can::codec::{decode_input, DecodeError, InputMessage};
use catmodel::can::spec::{self, MessageSpec, SignalSpec};
use catmodel::can::{CanFrame, CanId, TimedFrame};
use proptest::prelude::*;
use proptest::strategy::ValueTree;

/// CRC-8/SAE-J1850 (poly 0x1D, init 0xFF, xorout 0xFF, no reflection), bit by bit.
fn reference_crc(bytes: &[u8]) -> u8 {
    let mut crc = 0xFFu8;
    for &b in bytes {
        crc ^= b;
        for _ in 0..8 {
            crc = if crc & 0x80 != 0 {
                (crc << 1) ^ 0x1D
            } else {
                crc << 1
            };
        }
    }
    crc ^ 0xFF
}

#[test]
fn reference_crc_has_the_catalogue_check_value() {
    assert_eq!(reference_crc(b"123456789"), 0x4B);
}

/// The CRC our frames carry in byte 7: over the identifier's two bytes, then bytes 0..6.
fn frame_crc(id: u16, data: &[u8; 8]) -> u8 {
    let mut covered = vec![(id >> 8) as u8, id as u8];
    covered.extend_from_slice(&data[..7]);
    reference_crc(&covered)
}

/// A signal's raw value (Intel bit numbering, two's complement when signed).
fn raw(signal: &SignalSpec, data: &[u8; 8]) -> i64 {
    let word = u64::from_le_bytes(*data);
    let len = u32::from(signal.len_bits);
    let bits = (word >> signal.start_bit) & ((1u64 << len) - 1);
    if signal.signed && bits >> (len - 1) == 1 {
        bits as i64 - (1i64 << len)
    } else {
        bits as i64
    }
}

const PROTECTED_INPUTS: [MessageSpec; 3] = [
    spec::STEERING_REPORT,
    spec::SPEED_REPORT,
    spec::PEDAL_REPORT,
];

/// What the DBC says about a frame of `m` with a correct DLC and CRC: `Ok` or the errors the
/// decoder may report (each naming its signal).
fn range_verdicts(m: &MessageSpec, data: &[u8; 8]) -> Vec<DecodeError> {
    let mut errors = Vec::new();
    for s in m.signals {
        if s.name == "counter" || s.name == "crc" {
            continue;
        }
        let r = raw(s, data);
        if Some(r) == s.not_available_raw {
            errors.push(DecodeError::Invalid { signal: s.name });
        } else if r < s.raw_min || r > s.raw_max {
            errors.push(DecodeError::OutOfRange { signal: s.name });
        }
    }
    errors
}

fn counter_of(msg: &InputMessage) -> Option<u8> {
    match msg {
        InputMessage::Steering(_, c) | InputMessage::Speed(_, c) | InputMessage::Pedal(_, c) => {
            Some(*c)
        }
        _ => None,
    }
}

fn encode_again(msg: &InputMessage) -> Option<CanFrame> {
    match msg {
        InputMessage::Steering(m, c) => Some(m.encode(*c)),
        InputMessage::Speed(m, c) => Some(m.encode(*c)),
        InputMessage::Pedal(m, c) => Some(m.encode(*c)),
        _ => None,
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 4096, ..ProptestConfig::default() })]

    #[test]
    fn protected_inputs_are_classified_exactly(
        which in 0usize..3,
        payload in any::<[u8; 7]>(),
        counter in 0u8..16,
        dlc_ok in any::<bool>(),
        bad_len in 0u8..=8,
        crc_ok in any::<bool>(),
        crc_flip in 1u8..=255,
        in_range in any::<bool>(),
        edge in 0u8..6,
    ) {
        let m = PROTECTED_INPUTS[which];
        let CanId::Standard(id) = m.id else { unreachable!("protected inputs are 11-bit") };
        let mut data = [0u8; 8];
        data[..7].copy_from_slice(&payload);
        // Half the cases put each signal at a raw value inside its range or just outside it
        // (the edges are where an off-by-one hides), so that valid frames are common; the
        // others keep the random bits.
        if in_range {
            for s in m.signals.iter().filter(|s| s.name != "counter" && s.name != "crc") {
                let span = (s.raw_max - s.raw_min) as u64 + 1;
                let pick = match edge {
                    0 => s.raw_min,
                    1 => s.raw_max,
                    2 => s.raw_min - 1,
                    3 => s.raw_max + 1,
                    _ => s.raw_min + (u64::from_le_bytes(data) % span) as i64,
                };
                let bits = (pick as u64) & ((1u64 << s.len_bits) - 1);
                let mut word = u64::from_le_bytes(data);
                word &= !(((1u64 << s.len_bits) - 1) << s.start_bit);
                word |= bits << s.start_bit;
                data = word.to_le_bytes();
            }
        }
        // The counter in bits 52..55 (COUNTER_IN).
        let mut word = u64::from_le_bytes(data);
        word = (word & !(0xF << 52)) | (u64::from(counter) << 52);
        data = word.to_le_bytes();
        let crc = frame_crc(id, &data);
        data[7] = if crc_ok { crc } else { crc ^ crc_flip };
        let len = if dlc_ok { m.dlc } else if bad_len == m.dlc { 0 } else { bad_len };
        let frame = CanFrame { id: m.id, len, data };
        let result = decode_input(&frame, spec::N2K_DEFAULT_SOURCE);
        if len != m.dlc {
            prop_assert_eq!(result, Err(DecodeError::Dlc { expected: m.dlc, got: len }));
        } else if data[7] != crc {
            prop_assert_eq!(result, Err(DecodeError::Crc { expected: crc, got: data[7] }));
        } else {
            let verdicts = range_verdicts(&m, &data);
            match result {
                Ok(msg) => {
                    // Accepted: nothing out of range (an optional signal may be "not available").
                    prop_assert!(
                        verdicts.iter().all(|v| matches!(v, DecodeError::Invalid { .. })),
                        "{} accepted with {:?}", m.name, verdicts
                    );
                    prop_assert_eq!(counter_of(&msg), Some(counter));
                    let again = encode_again(&msg).unwrap();
                    prop_assert_eq!(decode_input(&again, spec::N2K_DEFAULT_SOURCE), Ok(msg));
                }
                Err(e) => prop_assert!(verdicts.contains(&e), "{}: {:?} not in {:?}", m.name, e, verdicts),
            }
        }
    }
}

/// The candump format as a grammar, independently of the parser: `(SECONDS.UUUUUU) IFACE
/// ID#DATA` with 1-20 second digits, exactly 6 decimals, one or more spaces, an interface of
/// 1-15 printable ASCII characters, 3 hex digits (<= 0x7FF) or 8 (<= 0x1FFFFFFF), 0-8 bytes as
/// hex pairs, optionally ` R` or ` T` (`candump -x`), with only whitespace around the line.
/// Returns the frame it describes.
fn grammar(line: &str) -> Option<TimedFrame> {
    let line = line.trim();
    let rest = line.strip_prefix('(')?;
    let close = rest.find(')')?;
    let (stamp, rest) = (&rest[..close], &rest[close + 1..]);
    let (secs, frac) = stamp.split_once('.')?;
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|c| c.is_ascii_digit());
    if !digits(secs) || secs.len() > 20 || frac.len() != 6 || !digits(frac) {
        return None;
    }
    let t_us = secs
        .parse::<u128>()
        .ok()?
        .checked_mul(1_000_000)?
        .checked_add(frac.parse::<u128>().ok()?)?;
    let t_us = u64::try_from(t_us).ok()?;
    let rest = rest.strip_prefix(' ')?.trim_start_matches(' ');
    let space = rest.find(' ')?;
    let (iface, frame) = (&rest[..space], &rest[space + 1..]);
    let frame = match frame.len().checked_sub(2).map(|n| frame.split_at(n)) {
        Some((frame, " R" | " T")) => frame,
        _ => frame,
    };
    if iface.is_empty()
        || iface.len() > MAX_IFACE_LEN
        || !iface.bytes().all(|c| c.is_ascii_graphic())
    {
        return None;
    }
    let (id_text, data_text) = frame.split_once('#')?;
    let hex = |s: &str| s.bytes().all(|c| c.is_ascii_hexdigit());
    if !hex(id_text) || !hex(data_text) || data_text.len() % 2 != 0 || data_text.len() > 16 {
        return None;
    }
    let value = u32::from_str_radix(id_text, 16).ok()?;
    let id = match (id_text.len(), value) {
        (3, v) if v <= 0x7FF => CanId::Standard(v as u16),
        (8, v) if v <= 0x1FFF_FFFF => CanId::Extended(v),
        _ => return None,
    };
    let bytes: Vec<u8> = (0..data_text.len() / 2)
        .map(|i| u8::from_str_radix(&data_text[2 * i..2 * i + 2], 16).unwrap())
        .collect();
    Some(TimedFrame {
        t_us,
        frame: CanFrame::new(id, &bytes).unwrap(),
    })
}

/// Characters the edits use: the format's own, a few that break it, whitespace.
const ALPHABET: &[u8] = b"0123456789ABCDEFabcdefxXrR().# \t-_";

#[derive(Clone, Debug)]
enum Edit {
    Insert(usize, u8),
    Delete(usize),
    Replace(usize, u8),
}

fn apply(line: &str, edits: &[Edit]) -> String {
    let mut bytes = line.as_bytes().to_vec();
    for e in edits {
        let n = bytes.len().max(1);
        match *e {
            Edit::Insert(at, c) => bytes.insert(at % (n + 1).min(bytes.len() + 1), c),
            Edit::Delete(at) if !bytes.is_empty() => {
                bytes.remove(at % bytes.len());
            }
            Edit::Replace(at, c) if !bytes.is_empty() => {
                let i = at % bytes.len();
                bytes[i] = c;
            }
            _ => {}
        }
    }
    String::from_utf8(bytes).unwrap()
}

fn arb_edit() -> impl Strategy<Value = Edit> {
    let c = (0..ALPHABET.len()).prop_map(|i| ALPHABET[i]);
    prop_oneof![
        (any::<usize>(), c.clone()).prop_map(|(at, c)| Edit::Insert(at, c)),
        any::<usize>().prop_map(Edit::Delete),
        (any::<usize>(), c).prop_map(|(at, c)| Edit::Replace(at, c)),
    ]
}

fn arb_frame() -> impl Strategy<Value = TimedFrame> {
    let id = prop_oneof![
        (0u16..=0x7FF).prop_map(CanId::Standard),
        (0u32..=0x1FFF_FFFF).prop_map(CanId::Extended),
    ];
    (
        0u64..=99_999_999_999_999_999,
        id,
        proptest::collection::vec(any::<u8>(), 0..=8),
    )
        .prop_map(|(t_us, id, data)| TimedFrame {
            t_us,
            frame: CanFrame::new(id, &data).unwrap(),
        })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 4096, ..ProptestConfig::default() })]

    #[test]
    fn near_valid_candump_lines_parse_exactly_when_the_grammar_accepts_them(
        frame in arb_frame(),
        iface in "[a-z][a-z0-9]{0,6}",
        edits in proptest::collection::vec(arb_edit(), 0..=2),
        trailing in prop_oneof![Just(""), Just("\r"), Just(" \t"), Just("\n")],
    ) {
        let mut line = String::new();
        format_line(&frame, &iface, &mut line).unwrap();
        let line = apply(&line, &edits) + trailing;
        prop_assert_eq!(parse_line(&line).ok(), grammar(&line), "{:?}", line);
    }
}

/// The edits keep both outcomes common: the property checks valid and invalid lines alike.
#[test]
fn near_valid_lines_are_about_half_valid() {
    let mut runner = proptest::test_runner::TestRunner::deterministic();
    let strategy = (arb_frame(), proptest::collection::vec(arb_edit(), 0..=2));
    let (mut valid, total) = (0, 2000);
    for _ in 0..total {
        let (frame, edits) = strategy.new_tree(&mut runner).unwrap().current();
        let mut line = String::new();
        format_line(&frame, "can0", &mut line).unwrap();
        if grammar(&apply(&line, &edits)).is_some() {
            valid += 1;
        }
    }
    assert!(
        (total / 5..=4 * total / 5).contains(&valid),
        "{valid} of {total} valid"
    );
}
