//! Typed codecs of every message of `catmodel.dbc`, in physical units.
//!
//! Every codec goes through the descriptor table of [`super::spec`] and its generic bit packer,
//! so the DBC test that checks the table checks the codecs too.
//!
//! Encoding never emits garbage: a non-finite physical value, or one outside the signal's DBC
//! range, goes on the bus as the signal's "not available" raw value and is counted in the
//! [`EncodeReport`] (so the node can raise its health bits). Event counters on NODE_STATUS
//! saturate at their largest raw value instead of wrapping.
//!
//! Decoding checks, in this order: identifier, DLC, CRC (protected messages), then every
//! signal's range. A signal carrying its "invalid" sentinel decodes to `None` (the sender says
//! it has no value), except where the whole message would be meaningless (a position fix without
//! latitude or longitude), which is [`DecodeError::Invalid`].
use super::crc::frame_crc;
use super::frame::{CanFrame, CanId};
use super::spec::{self, sig, Integrity, MessageSpec, SignalSpec};

/// Why a frame was not accepted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DecodeError {
    /// The identifier (or NMEA 2000 PGN) is not this message's.
    WrongId,
    /// NMEA 2000 PGN matches but the source address is not the configured receiver.
    WrongSource {
        /// Source address found.
        got: u8,
    },
    /// No message of `catmodel.dbc` has this identifier.
    UnknownId,
    /// Data length code differs from the DBC's.
    Dlc {
        /// DLC of the DBC.
        expected: u8,
        /// DLC received.
        got: u8,
    },
    /// Byte 7 does not hold the CRC-8/SAE-J1850 of identifier and payload.
    Crc {
        /// CRC computed here.
        expected: u8,
        /// CRC received.
        got: u8,
    },
    /// A raw value outside the signal's DBC range (and not its sentinel).
    OutOfRange {
        /// Signal name.
        signal: &'static str,
    },
    /// A signal without which the message means nothing carries its "invalid" sentinel.
    Invalid {
        /// Signal name.
        signal: &'static str,
    },
}

/// What an encoder had to substitute.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct EncodeReport {
    /// Physical values sent as "not available" because they were `None`.
    pub absent: u8,
    /// Physical values sent as "not available" because they were NaN or infinite.
    pub non_finite: u8,
    /// Physical values sent as "not available" because they were outside the DBC range.
    pub out_of_range: u8,
    /// Event counters that saturated at their largest raw value.
    pub saturated: u8,
}

impl EncodeReport {
    /// Whether any present value was replaced (non-finite, out of range or saturated).
    pub const fn any_substituted(&self) -> bool {
        self.non_finite > 0 || self.out_of_range > 0 || self.saturated > 0
    }

    /// Adds another report's counts.
    pub fn merge(&mut self, other: &EncodeReport) {
        self.absent = self.absent.saturating_add(other.absent);
        self.non_finite = self.non_finite.saturating_add(other.non_finite);
        self.out_of_range = self.out_of_range.saturating_add(other.out_of_range);
        self.saturated = self.saturated.saturating_add(other.saturated);
    }
}

/// Which model the node runs (STATE_MOTION and NODE_STATUS page 0 `mode`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ModelMode {
    /// Kinematic bicycle model (eq 8), raw 0.
    #[default]
    Kinematic,
    /// Dynamic bicycle model, raw 1.
    Dynamic,
}

impl ModelMode {
    const fn raw(self) -> i64 {
        match self {
            ModelMode::Kinematic => 0,
            ModelMode::Dynamic => 1,
        }
    }
    const fn from_raw(raw: i64) -> Self {
        if raw == 0 {
            ModelMode::Kinematic
        } else {
            ModelMode::Dynamic
        }
    }
}

/// Builds one frame of a message from physical values.
///
/// The writer's and the reader's per-signal methods are `#[inline(always)]`: inlined, the
/// signal's place, width and limits are constants and the packing folds to a few instructions;
/// called with the signal in a variable, each costs its whole general form (measured by `cargo
/// xtask bench-target`: STEERING_REPORT's decode 137 inlined, 251 not; PREDICTION_k's encode
/// 270 and 439).
struct Writer {
    spec: &'static MessageSpec,
    data: [u8; 8],
    report: EncodeReport,
}

impl Writer {
    const fn new(spec: &'static MessageSpec) -> Self {
        Self {
            spec,
            data: [0; 8],
            report: EncodeReport {
                absent: 0,
                non_finite: 0,
                out_of_range: 0,
                saturated: 0,
            },
        }
    }

    /// A physical value, or "not available" (counted) when absent, non-finite or out of range.
    #[inline(always)]
    fn phys(&mut self, s: &SignalSpec, value: Option<f32>) {
        let raw = match value {
            None => {
                self.report.absent = self.report.absent.saturating_add(1);
                None
            }
            Some(v) if !v.is_finite() => {
                self.report.non_finite = self.report.non_finite.saturating_add(1);
                None
            }
            Some(v) => {
                let raw = s.to_raw(v);
                if raw.is_none() {
                    self.report.out_of_range = self.report.out_of_range.saturating_add(1);
                }
                raw
            }
        };
        // Note: every float signal of the table has a sentinel; `raw_min` is the fallback.
        let raw = raw.unwrap_or(s.not_available_raw.unwrap_or(s.raw_min));
        s.write_raw(&mut self.data, raw);
    }

    /// An integer already known to be in range (flags, enums, N2K fields).
    #[inline(always)]
    fn raw(&mut self, s: &SignalSpec, raw: i64) {
        s.write_raw(&mut self.data, raw);
    }

    /// An integer that must be within the signal's limits; outside them the sentinel, or for a
    /// signal without one `raw_min - 1` (PATH_HEADER `count`: 1), goes out so that receivers
    /// reject it, and it is counted.
    #[inline(always)]
    fn checked(&mut self, s: &SignalSpec, raw: i64) {
        let raw = if s.in_range(raw) {
            raw
        } else {
            self.report.out_of_range = self.report.out_of_range.saturating_add(1);
            s.not_available_raw.unwrap_or(s.raw_min.wrapping_sub(1))
        };
        s.write_raw(&mut self.data, raw);
    }

    #[inline(always)]
    fn flag(&mut self, s: &SignalSpec, on: bool) {
        s.write_raw(&mut self.data, i64::from(on));
    }

    /// One-bit flags in the payload's first 32 bits, gathered into a word and written at once:
    /// the health page's fourteen in one read-modify-write of the payload instead of fourteen
    /// (each a 64-bit mask, shift and merge on a 32-bit core: 5 686 -> 5 212 instructions for
    /// the publish stage in QEMU). A flag elsewhere, or wider, goes through
    /// [`SignalSpec::write_raw`]. The flags' bits must still be clear (a fresh payload).
    fn flags<const N: usize>(&mut self, specs: &[&SignalSpec; N], on: [bool; N]) {
        let mut word = 0u32;
        for (s, on) in specs.iter().zip(on) {
            if s.len_bits == 1 && s.start_bit < 32 {
                word |= u32::from(on) << s.start_bit;
            } else {
                s.write_raw(&mut self.data, i64::from(on));
            }
        }
        self.data = (u64::from_le_bytes(self.data) | u64::from(word)).to_le_bytes();
    }

    /// An event counter, saturating at `raw_max`.
    #[inline(always)]
    fn count(&mut self, s: &SignalSpec, value: u32) {
        let raw = if i64::from(value) > s.raw_max {
            self.report.saturated = self.report.saturated.saturating_add(1);
            s.raw_max
        } else {
            i64::from(value)
        };
        s.write_raw(&mut self.data, raw);
    }

    /// An optional measurement, saturating at `raw_max`, sentinel when absent.
    #[inline(always)]
    fn count_or_na(&mut self, s: &SignalSpec, value: Option<u32>) {
        match value {
            Some(v) => self.count(s, v),
            None => s.write_raw(&mut self.data, s.not_available_raw.unwrap_or(s.raw_max)),
        }
    }

    /// Writes counter and CRC (protected messages) and returns the frame.
    fn finish(self, id: CanId, counter: u8) -> (CanFrame, EncodeReport) {
        let mut frame = CanFrame::EMPTY;
        let report = self.finish_into(id, counter, &mut frame);
        (frame, report)
    }

    /// [`Writer::finish`] into `out` (in place: no frame is moved on the way to the node's
    /// transmit list, each move being a library `memcpy` on the Cortex-M4).
    fn finish_into(mut self, id: CanId, counter: u8, out: &mut CanFrame) -> EncodeReport {
        if let Integrity::CounterCrc(counter_spec) = self.spec.integrity {
            counter_spec.write_raw(&mut self.data, i64::from(counter & 0x0F));
            let crc = frame_crc(id, &self.data);
            sig::CRC.write_raw(&mut self.data, i64::from(crc));
        }
        out.id = id;
        out.len = self.spec.dlc;
        out.data = self.data;
        self.report
    }
}

/// Reads one checked frame of a message.
struct Reader {
    data: [u8; 8],
    counter: u8,
}

impl Reader {
    /// Checks DLC and (protected messages) CRC; the identifier is checked by the caller.
    fn new(spec: &MessageSpec, frame: &CanFrame) -> Result<Self, DecodeError> {
        if frame.len != spec.dlc {
            return Err(DecodeError::Dlc {
                expected: spec.dlc,
                got: frame.len,
            });
        }
        let mut counter = 0;
        if let Integrity::CounterCrc(counter_spec) = spec.integrity {
            let expected = frame_crc(frame.id, &frame.data);
            let got = sig::CRC.read_raw(&frame.data) as u8;
            if expected != got {
                return Err(DecodeError::Crc { expected, got });
            }
            counter = counter_spec.read_raw(&frame.data) as u8;
        }
        Ok(Self {
            data: frame.data,
            counter,
        })
    }

    /// Checks a standard identifier, then as [`Reader::new`].
    fn standard(spec: &MessageSpec, frame: &CanFrame) -> Result<Self, DecodeError> {
        if frame.id != spec.id {
            return Err(DecodeError::WrongId);
        }
        Self::new(spec, frame)
    }

    /// Checks an NMEA 2000 PGN (any priority) and source address, then as [`Reader::new`].
    fn n2k(spec: &MessageSpec, frame: &CanFrame, source: u8) -> Result<Self, DecodeError> {
        let (CanId::Extended(id), CanId::Extended(spec_id)) = (frame.id, spec.id) else {
            return Err(DecodeError::WrongId);
        };
        let (pgn, src) = spec::n2k_pgn_source(id);
        if pgn != spec::n2k_pgn_source(spec_id).0 {
            return Err(DecodeError::WrongId);
        }
        if src != source {
            return Err(DecodeError::WrongSource { got: src });
        }
        Self::new(spec, frame)
    }

    /// Raw value, range-checked; the sentinel reads as `None`.
    #[inline(always)]
    fn raw(&self, s: &SignalSpec) -> Result<Option<i64>, DecodeError> {
        let raw = s.read_raw(&self.data);
        if Some(raw) == s.not_available_raw {
            Ok(None)
        } else if s.in_range(raw) {
            Ok(Some(raw))
        } else {
            Err(DecodeError::OutOfRange { signal: s.name })
        }
    }

    #[inline(always)]
    fn phys(&self, s: &SignalSpec) -> Result<Option<f32>, DecodeError> {
        Ok(self.raw(s)?.map(|raw| s.to_physical(raw)))
    }

    /// A raw value that must be present (no sentinel, or sentinel = [`DecodeError::Invalid`]).
    #[inline(always)]
    fn required(&self, s: &SignalSpec) -> Result<i64, DecodeError> {
        self.raw(s)?.ok_or(DecodeError::Invalid { signal: s.name })
    }

    /// A physical value that must be present ([`DecodeError::Invalid`] for the sentinel).
    #[inline(always)]
    fn required_phys(&self, s: &SignalSpec) -> Result<f32, DecodeError> {
        Ok(s.to_physical(self.required(s)?))
    }

    #[inline(always)]
    fn flag(&self, s: &SignalSpec) -> bool {
        s.read_raw(&self.data) != 0
    }

    /// The raw value of a signal whose every raw value is valid (its range is its full width,
    /// no sentinel): nothing to check.
    #[inline(always)]
    fn field(&self, s: &SignalSpec) -> i64 {
        s.read_raw(&self.data)
    }

    #[inline(always)]
    fn count(&self, s: &SignalSpec) -> Result<u32, DecodeError> {
        Ok(self.required(s)? as u32)
    }
}

// ---------------------------------------------------------------------------------------------
// Inputs

/// STEERING_REPORT (0x100): measured steering.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SteeringReport {
    /// Steering, % of full lock, -100..=100, positive = right; `None` = the DBW reports invalid.
    pub steer_pct: Option<f32>,
}

impl SteeringReport {
    /// The frame, with `counter` (4 bits) and its CRC.
    pub fn encode(&self, counter: u8) -> CanFrame {
        self.encode_with_report(counter).0
    }
    /// As [`Self::encode`], with what had to be substituted.
    pub fn encode_with_report(&self, counter: u8) -> (CanFrame, EncodeReport) {
        let mut w = Writer::new(&spec::STEERING_REPORT);
        w.phys(&sig::STEER_PCT, self.steer_pct);
        w.finish(spec::STEERING_REPORT.id, counter)
    }
    /// The message and its rolling counter.
    pub fn decode(frame: &CanFrame) -> Result<(Self, u8), DecodeError> {
        let r = Reader::standard(&spec::STEERING_REPORT, frame)?;
        let msg = Self {
            steer_pct: r.phys(&sig::STEER_PCT)?,
        };
        Ok((msg, r.counter))
    }
}

/// SPEED_REPORT `direction`: which way the car moves, as its drive-by-wire kit reports it
/// (its gear). The speed itself has no sign. The discriminant is the raw value; `catmodel.dbc`
/// names each (`VAL_ 257 direction`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Direction {
    /// The kit does not report it (every log from before the signal): the node takes the
    /// car as moving forwards, as it always did.
    #[default]
    NotReported = 0,
    /// Forward gear.
    Forward = 1,
    /// Reverse gear: the car moves backwards at the reported speed.
    Reverse = 2,
    /// The kit reports that it does not know: taken as [`Direction::NotReported`], and
    /// counted as an input that carried its invalid value.
    Invalid = 3,
}

impl Direction {
    /// `raw` (two bits: every value is one).
    const fn from_raw(raw: i64) -> Self {
        match raw {
            1 => Direction::Forward,
            2 => Direction::Reverse,
            3 => Direction::Invalid,
            _ => Direction::NotReported,
        }
    }
}

/// SPEED_REPORT (0x101): measured and commanded speed, and the direction of motion.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SpeedReport {
    /// Measured speed, m/s (its magnitude: forwards or backwards as `direction` says);
    /// `None` = invalid.
    pub speed_mps: Option<f32>,
    /// Commanded speed, m/s; `None` = invalid.
    pub speed_cmd_mps: Option<f32>,
    /// Which way the car moves ([`Direction::NotReported`] from a kit that does not say).
    pub direction: Direction,
}

impl SpeedReport {
    /// The frame, with `counter` (4 bits) and its CRC.
    pub fn encode(&self, counter: u8) -> CanFrame {
        self.encode_with_report(counter).0
    }
    /// As [`Self::encode`], with what had to be substituted.
    pub fn encode_with_report(&self, counter: u8) -> (CanFrame, EncodeReport) {
        let mut w = Writer::new(&spec::SPEED_REPORT);
        w.phys(&sig::SPEED_MPS, self.speed_mps);
        w.phys(&sig::SPEED_CMD_MPS, self.speed_cmd_mps);
        w.raw(&sig::DIRECTION, self.direction as i64);
        w.finish(spec::SPEED_REPORT.id, counter)
    }
    /// The message and its rolling counter.
    pub fn decode(frame: &CanFrame) -> Result<(Self, u8), DecodeError> {
        let r = Reader::standard(&spec::SPEED_REPORT, frame)?;
        let msg = Self {
            speed_mps: r.phys(&sig::SPEED_MPS)?,
            speed_cmd_mps: r.phys(&sig::SPEED_CMD_MPS)?,
            direction: Direction::from_raw(r.field(&sig::DIRECTION)),
        };
        Ok((msg, r.counter))
    }
}

/// PEDAL_REPORT (0x102): accelerator and brake pedals.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PedalReport {
    /// Accelerator pedal, %, 0..=100; `None` = invalid.
    pub accel_pct: Option<f32>,
    /// Brake pedal, %, 0..=100; `None` = invalid.
    pub brake_pct: Option<f32>,
}

impl PedalReport {
    /// The frame, with `counter` (4 bits) and its CRC.
    pub fn encode(&self, counter: u8) -> CanFrame {
        self.encode_with_report(counter).0
    }
    /// As [`Self::encode`], with what had to be substituted.
    pub fn encode_with_report(&self, counter: u8) -> (CanFrame, EncodeReport) {
        let mut w = Writer::new(&spec::PEDAL_REPORT);
        w.phys(&sig::ACCEL_PCT, self.accel_pct);
        w.phys(&sig::BRAKE_PCT, self.brake_pct);
        w.finish(spec::PEDAL_REPORT.id, counter)
    }
    /// The message and its rolling counter.
    pub fn decode(frame: &CanFrame) -> Result<(Self, u8), DecodeError> {
        let r = Reader::standard(&spec::PEDAL_REPORT, frame)?;
        let msg = Self {
            accel_pct: r.phys(&sig::ACCEL_PCT)?,
            brake_pct: r.phys(&sig::BRAKE_PCT)?,
        };
        Ok((msg, r.counter))
    }
}

/// NMEA 2000 PGN 129025 "Position, Rapid Update". Kept in integer 1e-7 degrees: an f32 of
/// degrees would lose about a metre.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GnssPosition {
    /// Latitude, 1e-7 deg, -90e7..=90e7.
    pub lat_e7: i32,
    /// Longitude, 1e-7 deg, -180e7..=180e7.
    pub lon_e7: i32,
}

impl GnssPosition {
    /// The frame from `source` (priority 2). Out-of-range coordinates go out as "not
    /// available" (0x7FFFFFFF) and are counted.
    pub fn encode(&self, source: u8) -> CanFrame {
        self.encode_with_report(source).0
    }
    /// As [`Self::encode`], with what had to be substituted.
    pub fn encode_with_report(&self, source: u8) -> (CanFrame, EncodeReport) {
        let mut w = Writer::new(&spec::GNSS_POSITION_RAPID);
        for (s, v) in [
            (&sig::LATITUDE_DEG, self.lat_e7),
            (&sig::LONGITUDE_DEG, self.lon_e7),
        ] {
            let v = i64::from(v);
            if s.in_range(v) {
                w.raw(s, v);
            } else {
                w.report.out_of_range = w.report.out_of_range.saturating_add(1);
                w.raw(s, s.not_available_raw.unwrap_or(0));
            }
        }
        let id = spec::n2k_id(spec::N2K_PRIORITY, spec::PGN_POSITION_RAPID, source);
        w.finish(CanId::Extended(id), 0)
    }
    /// The fix, if the frame is PGN 129025 from `source` and both coordinates are available
    /// and in range (plausibility against the previous fix is the node's gate).
    pub fn decode(frame: &CanFrame, source: u8) -> Result<Self, DecodeError> {
        let r = Reader::n2k(&spec::GNSS_POSITION_RAPID, frame, source)?;
        Ok(Self {
            lat_e7: r.required(&sig::LATITUDE_DEG)? as i32,
            lon_e7: r.required(&sig::LONGITUDE_DEG)? as i32,
        })
    }
}

/// NMEA 2000 PGN 129026 "COG & SOG, Rapid Update".
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GnssCogSog {
    /// Sequence identifier tying related PGNs together.
    pub sid: u8,
    /// Direction reference: 0 true, 1 magnetic, 2 error, 3 null.
    pub cog_reference: u8,
    /// Course over ground, rad, 0..=2 pi, clockwise from north; `None` = not available.
    pub cog_rad: Option<f32>,
    /// Speed over ground, m/s; `None` = not available.
    pub sog_mps: Option<f32>,
}

impl GnssCogSog {
    /// The frame from `source` (priority 2); reserved bits are 1 as NMEA 2000 requires.
    pub fn encode(&self, source: u8) -> CanFrame {
        self.encode_with_report(source).0
    }
    /// As [`Self::encode`], with what had to be substituted.
    pub fn encode_with_report(&self, source: u8) -> (CanFrame, EncodeReport) {
        let mut w = Writer::new(&spec::GNSS_COG_SOG_RAPID);
        w.data = [0xFF; 8];
        w.raw(&sig::SID, i64::from(self.sid));
        w.raw(&sig::COG_REFERENCE, i64::from(self.cog_reference & 0x3));
        w.phys(&sig::COG_RAD, self.cog_rad);
        w.phys(&sig::SOG_MPS, self.sog_mps);
        let id = spec::n2k_id(spec::N2K_PRIORITY, spec::PGN_COG_SOG_RAPID, source);
        w.finish(CanId::Extended(id), 0)
    }
    /// The message, if the frame is PGN 129026 from `source`.
    pub fn decode(frame: &CanFrame, source: u8) -> Result<Self, DecodeError> {
        let r = Reader::n2k(&spec::GNSS_COG_SOG_RAPID, frame, source)?;
        Ok(Self {
            sid: r.required(&sig::SID)? as u8,
            cog_reference: r.required(&sig::COG_REFERENCE)? as u8,
            cog_rad: r.phys(&sig::COG_RAD)?,
            sog_mps: r.phys(&sig::SOG_MPS)?,
        })
    }
}

// ---------------------------------------------------------------------------------------------
// Inputs from the planner (docs/bus.md, "The controller's messages")

/// PATH_HEADER (0x200): a new path `path_id` of `count` points follows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PathHeader {
    /// Path identifier, 0..=15 (only the low 4 bits are sent).
    pub path_id: u8,
    /// Number of points, 2..=[`spec::MAX_PATH_POINTS`].
    pub count: u16,
}

impl PathHeader {
    /// The frame, with `counter` (4 bits) and its CRC. A `count` outside 2..=256 goes out as 0,
    /// which every receiver rejects, and is counted in the report.
    pub fn encode(&self, counter: u8) -> CanFrame {
        self.encode_with_report(counter).0
    }
    /// As [`Self::encode`], with what had to be substituted.
    pub fn encode_with_report(&self, counter: u8) -> (CanFrame, EncodeReport) {
        let mut w = Writer::new(&spec::PATH_HEADER);
        w.raw(&sig::PATH_ID, i64::from(self.path_id & 0x0F));
        w.checked(&sig::PATH_COUNT, i64::from(self.count));
        w.finish(spec::PATH_HEADER.id, counter)
    }
    /// The message and its counter.
    pub fn decode(frame: &CanFrame) -> Result<(Self, u8), DecodeError> {
        let r = Reader::standard(&spec::PATH_HEADER, frame)?;
        let msg = Self {
            path_id: r.required(&sig::PATH_ID)? as u8,
            count: r.required(&sig::PATH_COUNT)? as u16,
        };
        Ok((msg, r.counter))
    }
}

/// PATH_POINT (0x201): point `index` of path `path_id`, the rear axle's position there in the
/// node's local frame.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PathPoint {
    /// Path identifier, 0..=15.
    pub path_id: u8,
    /// Point index, 0..count-1.
    pub index: u8,
    /// East of the local origin, m, |east| <= 10 485.74, 0.02 m resolution.
    pub east_m: f32,
    /// North of the local origin, m, same range.
    pub north_m: f32,
}

impl PathPoint {
    /// The frame, with `counter` and its CRC. A coordinate outside the range (or not finite)
    /// goes out as "not available", which receivers reject, and is counted in the report.
    pub fn encode(&self, counter: u8) -> CanFrame {
        self.encode_with_report(counter).0
    }
    /// As [`Self::encode`], with what had to be substituted.
    pub fn encode_with_report(&self, counter: u8) -> (CanFrame, EncodeReport) {
        let mut w = Writer::new(&spec::PATH_POINT);
        w.raw(&sig::PATH_ID, i64::from(self.path_id & 0x0F));
        w.raw(&sig::PATH_INDEX, i64::from(self.index));
        w.phys(&sig::PATH_EAST_M, Some(self.east_m));
        w.phys(&sig::PATH_NORTH_M, Some(self.north_m));
        w.finish(spec::PATH_POINT.id, counter)
    }
    /// The message and its counter; a coordinate "not available" is [`DecodeError::Invalid`].
    pub fn decode(frame: &CanFrame) -> Result<(Self, u8), DecodeError> {
        let r = Reader::standard(&spec::PATH_POINT, frame)?;
        let msg = Self {
            path_id: r.required(&sig::PATH_ID)? as u8,
            index: r.required(&sig::PATH_INDEX)? as u8,
            east_m: r.required_phys(&sig::PATH_EAST_M)?,
            north_m: r.required_phys(&sig::PATH_NORTH_M)?,
        };
        Ok((msg, r.counter))
    }
}

/// PATH_LIMITS (0x202): target speed and corridor at point `index` of path `path_id`.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PathLimits {
    /// Path identifier, 0..=15.
    pub path_id: u8,
    /// Point index, 0..count-1.
    pub index: u8,
    /// Target speed at the point, m/s, 0..=40.94.
    pub speed_mps: f32,
    /// How far the body may stray to the left of the point, m, 0..=163.82.
    pub left_m: f32,
    /// How far the body may stray to the right of the point, m, 0..=163.82.
    pub right_m: f32,
}

impl PathLimits {
    /// The frame, with `counter` and its CRC; out-of-range values go out as "not available"
    /// (rejected by receivers) and are counted.
    pub fn encode(&self, counter: u8) -> CanFrame {
        self.encode_with_report(counter).0
    }
    /// As [`Self::encode`], with what had to be substituted.
    pub fn encode_with_report(&self, counter: u8) -> (CanFrame, EncodeReport) {
        let mut w = Writer::new(&spec::PATH_LIMITS);
        w.raw(&sig::PATH_ID, i64::from(self.path_id & 0x0F));
        w.raw(&sig::PATH_INDEX, i64::from(self.index));
        w.phys(&sig::PATH_SPEED_MPS, Some(self.speed_mps));
        w.phys(&sig::PATH_LEFT_M, Some(self.left_m));
        w.phys(&sig::PATH_RIGHT_M, Some(self.right_m));
        w.finish(spec::PATH_LIMITS.id, counter)
    }
    /// The message and its counter; a value "not available" is [`DecodeError::Invalid`].
    pub fn decode(frame: &CanFrame) -> Result<(Self, u8), DecodeError> {
        let r = Reader::standard(&spec::PATH_LIMITS, frame)?;
        let msg = Self {
            path_id: r.required(&sig::PATH_ID)? as u8,
            index: r.required(&sig::PATH_INDEX)? as u8,
            speed_mps: r.required_phys(&sig::PATH_SPEED_MPS)?,
            left_m: r.required_phys(&sig::PATH_LEFT_M)?,
            right_m: r.required_phys(&sig::PATH_RIGHT_M)?,
        };
        Ok((msg, r.counter))
    }
}

/// OBSTACLE (0x203): slot `obstacle_id` holds a circle the body keeps clear of, or is cleared.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Obstacle {
    /// Slot, 0..=3 (only the low 2 bits are sent).
    pub obstacle_id: u8,
    /// The circle, or `None`: the slot is cleared (`active` = 0, position "not available").
    pub circle: Option<ObstacleCircle>,
}

/// Where an obstacle is, in the node's local frame.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ObstacleCircle {
    /// Centre east of the local origin, m, 0.02 m resolution.
    pub east_m: f32,
    /// Centre north of the local origin, m.
    pub north_m: f32,
    /// Radius, m, 0..=12.75, 0.05 m resolution.
    pub radius_m: f32,
}

impl Obstacle {
    /// The frame, with `counter` and its CRC. An active obstacle with a value out of range
    /// goes out with that value "not available" (rejected by receivers), counted.
    pub fn encode(&self, counter: u8) -> CanFrame {
        self.encode_with_report(counter).0
    }
    /// As [`Self::encode`], with what had to be substituted.
    pub fn encode_with_report(&self, counter: u8) -> (CanFrame, EncodeReport) {
        let mut w = Writer::new(&spec::OBSTACLE);
        w.raw(&sig::OBSTACLE_ID, i64::from(self.obstacle_id & 0x03));
        w.flag(&sig::OBSTACLE_ACTIVE, self.circle.is_some());
        match self.circle {
            Some(c) => {
                w.phys(&sig::OBSTACLE_EAST_M, Some(c.east_m));
                w.phys(&sig::OBSTACLE_NORTH_M, Some(c.north_m));
                w.phys(&sig::OBSTACLE_RADIUS_M, Some(c.radius_m));
            }
            None => {
                let na = |s: &SignalSpec| s.not_available_raw.unwrap_or(0);
                w.raw(&sig::OBSTACLE_EAST_M, na(&sig::OBSTACLE_EAST_M));
                w.raw(&sig::OBSTACLE_NORTH_M, na(&sig::OBSTACLE_NORTH_M));
            }
        }
        w.finish(spec::OBSTACLE.id, counter)
    }
    /// The message and its counter. An active obstacle needs its centre
    /// ([`DecodeError::Invalid`] otherwise); a cleared slot's other fields are ignored.
    pub fn decode(frame: &CanFrame) -> Result<(Self, u8), DecodeError> {
        let r = Reader::standard(&spec::OBSTACLE, frame)?;
        let circle = if r.flag(&sig::OBSTACLE_ACTIVE) {
            Some(ObstacleCircle {
                east_m: r.required_phys(&sig::OBSTACLE_EAST_M)?,
                north_m: r.required_phys(&sig::OBSTACLE_NORTH_M)?,
                radius_m: r.required_phys(&sig::OBSTACLE_RADIUS_M)?,
            })
        } else {
            None
        };
        let msg = Self {
            obstacle_id: r.required(&sig::OBSTACLE_ID)? as u8,
            circle,
        };
        Ok((msg, r.counter))
    }
}

/// LOCAL_ORIGIN (0x204): one page of the planner's map origin. The origin is the latitude
/// page followed by the longitude page with the next counter value (see
/// `catmodel::control::planner`). Kept in integer 1e-7 degrees, like [`GnssPosition`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LocalOrigin {
    /// Page 0: latitude, 1e-7 deg, -90e7..=90e7.
    Latitude {
        /// Latitude, 1e-7 deg.
        lat_e7: i32,
    },
    /// Page 1: longitude, 1e-7 deg, -180e7..=180e7.
    Longitude {
        /// Longitude, 1e-7 deg.
        lon_e7: i32,
    },
}

impl LocalOrigin {
    /// The frame, with `counter` and its CRC; a coordinate out of range goes out as "not
    /// available" (rejected by receivers), counted.
    pub fn encode(&self, counter: u8) -> CanFrame {
        self.encode_with_report(counter).0
    }
    /// As [`Self::encode`], with what had to be substituted.
    pub fn encode_with_report(&self, counter: u8) -> (CanFrame, EncodeReport) {
        let mut w = Writer::new(&spec::LOCAL_ORIGIN);
        let (page, s, v) = match *self {
            LocalOrigin::Latitude { lat_e7 } => (0, &sig::ORIGIN_LATITUDE_DEG, lat_e7),
            LocalOrigin::Longitude { lon_e7 } => (1, &sig::ORIGIN_LONGITUDE_DEG, lon_e7),
        };
        w.raw(&sig::ORIGIN_PAGE, page);
        let v = i64::from(v);
        if s.in_range(v) {
            w.raw(s, v);
        } else {
            w.report.out_of_range = w.report.out_of_range.saturating_add(1);
            w.raw(s, s.not_available_raw.unwrap_or(0));
        }
        w.finish(spec::LOCAL_ORIGIN.id, counter)
    }
    /// The page and its counter; a coordinate "not available" is [`DecodeError::Invalid`].
    pub fn decode(frame: &CanFrame) -> Result<(Self, u8), DecodeError> {
        let r = Reader::standard(&spec::LOCAL_ORIGIN, frame)?;
        let msg = if r.flag(&sig::ORIGIN_PAGE) {
            LocalOrigin::Longitude {
                lon_e7: r.required(&sig::ORIGIN_LONGITUDE_DEG)? as i32,
            }
        } else {
            LocalOrigin::Latitude {
                lat_e7: r.required(&sig::ORIGIN_LATITUDE_DEG)? as i32,
            }
        };
        Ok((msg, r.counter))
    }
}

/// Any message from the planner, as [`decode_planner`] classifies it, with its rolling counter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PlannerMessage {
    /// 0x200.
    PathHeader(PathHeader, u8),
    /// 0x201.
    PathPoint(PathPoint, u8),
    /// 0x202.
    PathLimits(PathLimits, u8),
    /// 0x203.
    Obstacle(Obstacle, u8),
    /// 0x204.
    LocalOrigin(LocalOrigin, u8),
}

impl PlannerMessage {
    /// The kinds of planner message, each with its own rolling counter.
    pub const KINDS: usize = 5;

    /// The message's kind (0..[`Self::KINDS`], in the order of the variants: the index of its
    /// counter's checker) and its rolling counter.
    pub fn counter(&self) -> (usize, u8) {
        match *self {
            PlannerMessage::PathHeader(_, c) => (0, c),
            PlannerMessage::PathPoint(_, c) => (1, c),
            PlannerMessage::PathLimits(_, c) => (2, c),
            PlannerMessage::Obstacle(_, c) => (3, c),
            PlannerMessage::LocalOrigin(_, c) => (4, c),
        }
    }
}

/// Decodes any frame from the planner; [`DecodeError::UnknownId`] for other identifiers.
/// Kept apart from [`decode_input`] (the vehicle's reports), which is unchanged.
pub fn decode_planner(frame: &CanFrame) -> Result<PlannerMessage, DecodeError> {
    match frame.id {
        id if id == spec::PATH_HEADER.id => {
            PathHeader::decode(frame).map(|(m, c)| PlannerMessage::PathHeader(m, c))
        }
        id if id == spec::PATH_POINT.id => {
            PathPoint::decode(frame).map(|(m, c)| PlannerMessage::PathPoint(m, c))
        }
        id if id == spec::PATH_LIMITS.id => {
            PathLimits::decode(frame).map(|(m, c)| PlannerMessage::PathLimits(m, c))
        }
        id if id == spec::OBSTACLE.id => {
            Obstacle::decode(frame).map(|(m, c)| PlannerMessage::Obstacle(m, c))
        }
        id if id == spec::LOCAL_ORIGIN.id => {
            LocalOrigin::decode(frame).map(|(m, c)| PlannerMessage::LocalOrigin(m, c))
        }
        _ => Err(DecodeError::UnknownId),
    }
}

/// Any input message, as [`decode_input`] classifies it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum InputMessage {
    /// 0x100 and its rolling counter.
    Steering(SteeringReport, u8),
    /// 0x101 and its rolling counter.
    Speed(SpeedReport, u8),
    /// 0x102 and its rolling counter.
    Pedal(PedalReport, u8),
    /// PGN 129025.
    GnssPosition(GnssPosition),
    /// PGN 129026.
    GnssCogSog(GnssCogSog),
}

/// Decodes any input frame; [`DecodeError::UnknownId`] for identifiers that are not inputs
/// (GNSS PGNs from another source are [`DecodeError::WrongSource`]).
pub fn decode_input(frame: &CanFrame, gnss_source: u8) -> Result<InputMessage, DecodeError> {
    match frame.id {
        id if id == spec::STEERING_REPORT.id => {
            SteeringReport::decode(frame).map(|(m, c)| InputMessage::Steering(m, c))
        }
        id if id == spec::SPEED_REPORT.id => {
            SpeedReport::decode(frame).map(|(m, c)| InputMessage::Speed(m, c))
        }
        id if id == spec::PEDAL_REPORT.id => {
            PedalReport::decode(frame).map(|(m, c)| InputMessage::Pedal(m, c))
        }
        CanId::Extended(raw) => match spec::n2k_pgn_source(raw).0 {
            spec::PGN_POSITION_RAPID => {
                GnssPosition::decode(frame, gnss_source).map(InputMessage::GnssPosition)
            }
            spec::PGN_COG_SOG_RAPID => {
                GnssCogSog::decode(frame, gnss_source).map(InputMessage::GnssCogSog)
            }
            _ => Err(DecodeError::UnknownId),
        },
        CanId::Standard(_) => Err(DecodeError::UnknownId),
    }
}

// ---------------------------------------------------------------------------------------------
// Outputs

/// STATE_POSITION (0x300): flags and the filtered position in the local east/north frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StatePosition {
    /// The position is valid.
    pub position_valid: bool,
    /// A GNSS fix arrived within its timeout.
    pub gnss_fresh: bool,
    /// The last GNSS fix was rejected by the plausibility gate.
    pub gnss_rejected: bool,
    /// East of the origin, m, |x| <= 83 886.07; `None` = not available.
    pub east_m: Option<f32>,
    /// North of the origin, m, |y| <= 83 886.07; `None` = not available.
    pub north_m: Option<f32>,
}

impl StatePosition {
    /// The frame, with `counter` (the tick sequence number mod 16) and its CRC.
    pub fn encode(&self, counter: u8) -> CanFrame {
        self.encode_with_report(counter).0
    }
    /// As [`Self::encode`], with what had to be substituted.
    pub fn encode_with_report(&self, counter: u8) -> (CanFrame, EncodeReport) {
        let mut frame = CanFrame::EMPTY;
        let report = self.encode_into(counter, &mut frame);
        (frame, report)
    }
    /// As [`Self::encode_with_report`], into `out` (in place).
    pub fn encode_into(&self, counter: u8, out: &mut CanFrame) -> EncodeReport {
        let mut w = Writer::new(&spec::STATE_POSITION);
        w.flag(&sig::POSITION_VALID, self.position_valid);
        w.flag(&sig::GNSS_FRESH, self.gnss_fresh);
        w.flag(&sig::GNSS_REJECTED, self.gnss_rejected);
        w.phys(&sig::EAST_M, self.east_m);
        w.phys(&sig::NORTH_M, self.north_m);
        w.finish_into(spec::STATE_POSITION.id, counter, out)
    }
    /// The message and its counter.
    pub fn decode(frame: &CanFrame) -> Result<(Self, u8), DecodeError> {
        let r = Reader::standard(&spec::STATE_POSITION, frame)?;
        let msg = Self {
            position_valid: r.flag(&sig::POSITION_VALID),
            gnss_fresh: r.flag(&sig::GNSS_FRESH),
            gnss_rejected: r.flag(&sig::GNSS_REJECTED),
            east_m: r.phys(&sig::EAST_M)?,
            north_m: r.phys(&sig::NORTH_M)?,
        };
        Ok((msg, r.counter))
    }
}

/// STATE_MOTION (0x301): model mode, heading, speed and yaw rate.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StateMotion {
    /// Model in use.
    pub mode: ModelMode,
    /// The heading's standard deviation is above the node's bound (`heading_uncertain`).
    pub heading_uncertain: bool,
    /// Heading, rad, clockwise from north, [-pi, pi]; `None` = not available.
    pub heading_rad: Option<f32>,
    /// Speed, m/s; `None` = not available.
    pub speed_mps: Option<f32>,
    /// Yaw rate, rad/s, clockwise positive; `None` = not available.
    pub yaw_rate_radps: Option<f32>,
}

impl StateMotion {
    /// The frame, with `counter` and its CRC.
    pub fn encode(&self, counter: u8) -> CanFrame {
        self.encode_with_report(counter).0
    }
    /// As [`Self::encode`], with what had to be substituted.
    pub fn encode_with_report(&self, counter: u8) -> (CanFrame, EncodeReport) {
        let mut frame = CanFrame::EMPTY;
        let report = self.encode_into(counter, &mut frame);
        (frame, report)
    }
    /// As [`Self::encode_with_report`], into `out` (in place).
    pub fn encode_into(&self, counter: u8, out: &mut CanFrame) -> EncodeReport {
        let mut w = Writer::new(&spec::STATE_MOTION);
        w.raw(&sig::MODE, self.mode.raw());
        w.flag(&sig::HEADING_UNCERTAIN, self.heading_uncertain);
        w.phys(&sig::HEADING_RAD, self.heading_rad);
        w.phys(&sig::STATE_SPEED_MPS, self.speed_mps);
        w.phys(&sig::YAW_RATE_RADPS, self.yaw_rate_radps);
        w.finish_into(spec::STATE_MOTION.id, counter, out)
    }
    /// The message and its counter.
    pub fn decode(frame: &CanFrame) -> Result<(Self, u8), DecodeError> {
        let r = Reader::standard(&spec::STATE_MOTION, frame)?;
        let msg = Self {
            mode: ModelMode::from_raw(sig::MODE.read_raw(&r.data)),
            heading_uncertain: r.flag(&sig::HEADING_UNCERTAIN),
            heading_rad: r.phys(&sig::HEADING_RAD)?,
            speed_mps: r.phys(&sig::STATE_SPEED_MPS)?,
            yaw_rate_radps: r.phys(&sig::YAW_RATE_RADPS)?,
        };
        Ok((msg, r.counter))
    }
}

/// The identified models' outputs of one tick (NODE_STATUS page 5).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ModelOutputs {
    /// Velocity-model output (eq 5), m/s; `None` = not available.
    pub speed_model_mps: Option<f32>,
    /// dx/dt model output (eq 7), m/s; `None` = not available.
    pub dxdt_model_mps: Option<f32>,
    /// Lateral acceleration, m/s^2, positive = right; `None` = not available.
    pub lat_accel_mps2: Option<f32>,
}

/// Which prediction point, 1..=10 (point k is k * 0.2 s ahead); always a valid index.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct PredictionPoint(u8);

impl PredictionPoint {
    /// Point `k`, 1..=10.
    pub const fn new(k: u8) -> Option<Self> {
        if k >= 1 && k as usize <= spec::PREDICTION_POINTS {
            Some(Self(k))
        } else {
            None
        }
    }
    /// The point's number k, 1..=10.
    pub const fn k(self) -> u8 {
        self.0
    }
    /// Horizon, us (k * 200 000).
    pub const fn horizon_us(self) -> u64 {
        self.0 as u64 * spec::PREDICTION_STEP_US
    }
    /// All ten points, nearest first.
    pub fn all() -> impl Iterator<Item = Self> {
        (1..=spec::PREDICTION_POINTS as u8).map(Self)
    }
    fn spec(self) -> &'static MessageSpec {
        // Note: `self.0` is 1..=10 by construction; the fallback is never taken.
        spec::PREDICTIONS
            .get(usize::from(self.0).wrapping_sub(1))
            .unwrap_or(&spec::PREDICTIONS[0])
    }
}

/// PREDICTION_k (0x310 + k - 1): point k of the horizon, relative to this tick's
/// STATE_POSITION and STATE_MOTION heading. Out-of-range values go out as the raw minimum
/// ("not available / saturated").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prediction {
    /// Which point.
    pub point: PredictionPoint,
    /// East displacement, m, |dx| <= 81.91; `None` = not available.
    pub dx_m: Option<f32>,
    /// North displacement, m, |dy| <= 81.91; `None` = not available.
    pub dy_m: Option<f32>,
    /// Heading change, rad, |dh| <= 2.047; `None` = not available.
    pub dheading_rad: Option<f32>,
    /// Speed, m/s, 0..=40.94; `None` = not available.
    pub speed_mps: Option<f32>,
}

impl Prediction {
    /// The frame, with `counter` and its CRC.
    pub fn encode(&self, counter: u8) -> CanFrame {
        self.encode_with_report(counter).0
    }
    /// As [`Self::encode`], with what had to be substituted.
    pub fn encode_with_report(&self, counter: u8) -> (CanFrame, EncodeReport) {
        let mut frame = CanFrame::EMPTY;
        let report = self.encode_into(counter, &mut frame);
        (frame, report)
    }
    /// As [`Self::encode_with_report`], into `out` (in place).
    pub fn encode_into(&self, counter: u8, out: &mut CanFrame) -> EncodeReport {
        let spec = self.point.spec();
        let mut w = Writer::new(spec);
        w.phys(&sig::DX_M, self.dx_m);
        w.phys(&sig::DY_M, self.dy_m);
        w.phys(&sig::DHEADING_RAD, self.dheading_rad);
        w.phys(&sig::PRED_SPEED_MPS, self.speed_mps);
        w.finish_into(spec.id, counter, out)
    }
    /// The message (any of 0x310..=0x319) and its counter.
    pub fn decode(frame: &CanFrame) -> Result<(Self, u8), DecodeError> {
        let CanId::Standard(id) = frame.id else {
            return Err(DecodeError::WrongId);
        };
        let point = id
            .checked_sub(spec::PREDICTION_BASE_ID)
            .and_then(|i| u8::try_from(i + 1).ok())
            .and_then(PredictionPoint::new)
            .ok_or(DecodeError::WrongId)?;
        let r = Reader::new(point.spec(), frame)?;
        let msg = Self {
            point,
            dx_m: r.phys(&sig::DX_M)?,
            dy_m: r.phys(&sig::DY_M)?,
            dheading_rad: r.phys(&sig::DHEADING_RAD)?,
            speed_mps: r.phys(&sig::PRED_SPEED_MPS)?,
        };
        Ok((msg, r.counter))
    }
}

/// What the controller is doing (CONTROL_COMMAND `status`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ControlStatus {
    /// No complete path: the command holds the car (speed 0), raw 0.
    #[default]
    NoPath,
    /// Following the path, raw 1.
    Tracking,
    /// Following the path around an obstacle, raw 2.
    Avoiding,
    /// The controller could not plan (infeasible, inputs stale): its documented fallback,
    /// raw 3.
    Fallback,
}

impl ControlStatus {
    const fn raw(self) -> i64 {
        match self {
            ControlStatus::NoPath => 0,
            ControlStatus::Tracking => 1,
            ControlStatus::Avoiding => 2,
            ControlStatus::Fallback => 3,
        }
    }
    const fn from_raw(raw: i64) -> Self {
        match raw {
            1 => ControlStatus::Tracking,
            2 => ControlStatus::Avoiding,
            3 => ControlStatus::Fallback,
            _ => ControlStatus::NoPath,
        }
    }
}

/// Why the controller is in its fallback (CONTROL_COMMAND `fallback_reason`): for the planner
/// and whoever reads a log to tell a car that waits from one that stopped, and why. The
/// discriminant is the raw value; `catmodel.dbc` names each (`VAL_ 800 fallback_reason`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum FallbackCause {
    /// Not in the fallback (status 0, 1 or 2).
    #[default]
    None = 0,
    /// No valid position or speed model yet.
    NotReady = 1,
    /// The heading has not settled since the car started moving with a path.
    HeadingSettling = 2,
    /// The controller's tuning from the model file was refused: it never plans.
    Unconfigured = 3,
    /// A new path was loaded this tick and there is no plan of the last tick to move on; the
    /// controller plans on it next tick.
    PathLoading = 4,
    /// The car has lost its path (beside the corridor or facing against it): stopped with the
    /// wheels straight until the planner sends a new path.
    LostPath = 5,
    /// An input the controller cannot use (non-finite, out of range, a path it cannot sample
    /// there).
    BadInput = 6,
    /// An obstacle leaves no room for the body on either side within the corridor.
    NoPassage = 7,
    /// The steering problem could not be built or solved.
    Solver = 8,
    /// The plan after the iteration cap still enters an obstacle's inflated circle.
    ObstacleNotCleared = 9,
    /// The controller's command was not finite.
    NonFiniteCommand = 10,
    /// The steering turns the car the other way than its report says (the node's steering
    /// check, NODE_STATUS `steering_mismatch`): stopped with the wheels straight, since the
    /// commands' sign may be as wrong as the report's.
    SteeringReversed = 11,
    /// The car's position left the window of the path it was being followed on (more than
    /// 5 m from it: a position that jumped, or was reset elsewhere) and there is no plan of
    /// the last tick to move on: the whole path was searched for it this tick, and the
    /// controller plans from there next tick.
    PositionJumped = 12,
    /// The car reports reverse gear (SPEED_REPORT `direction`): the controllers do not drive
    /// backwards, so the car is held (speed 0, steering where it was last commanded) until it
    /// reports forward, or no direction, again.
    Reversing = 13,
    /// STEERING_REPORT is stale (no valid report for longer than its timeout) while a
    /// controller would drive: without the wheels' angle the controllers cannot steer, and the
    /// heading is dead-reckoned on the last report's, so the car is held (speed 0, steering
    /// where it was last commanded, as the actuator holds it) until a report comes again. Not
    /// latched: the first fresh report hands the car back to the controller.
    SteeringStale = 14,
}

impl FallbackCause {
    /// Every cause, by raw value.
    pub const ALL: [FallbackCause; 15] = [
        FallbackCause::None,
        FallbackCause::NotReady,
        FallbackCause::HeadingSettling,
        FallbackCause::Unconfigured,
        FallbackCause::PathLoading,
        FallbackCause::LostPath,
        FallbackCause::BadInput,
        FallbackCause::NoPassage,
        FallbackCause::Solver,
        FallbackCause::ObstacleNotCleared,
        FallbackCause::NonFiniteCommand,
        FallbackCause::SteeringReversed,
        FallbackCause::PositionJumped,
        FallbackCause::Reversing,
        FallbackCause::SteeringStale,
    ];

    /// `raw` within the signal's range (0..=14, checked by the reader).
    fn from_raw(raw: i64) -> Self {
        usize::try_from(raw)
            .ok()
            .and_then(|i| Self::ALL.get(i))
            .copied()
            .unwrap_or_default()
    }
}

/// CONTROL_COMMAND (0x320): the controller's steering and speed commands of this tick.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ControlCommand {
    /// What the controller is doing.
    pub status: ControlStatus,
    /// Why, when `status` is the fallback ([`FallbackCause::None`] otherwise).
    pub fallback: FallbackCause,
    /// Steering command, % of full lock, -100..=100, positive = right (as STEERING_REPORT);
    /// `None` = not available.
    pub steer_cmd_pct: Option<f32>,
    /// Speed command, m/s; `None` = not available.
    pub speed_cmd_mps: Option<f32>,
}

impl ControlCommand {
    /// The frame, with `counter` and its CRC.
    pub fn encode(&self, counter: u8) -> CanFrame {
        self.encode_with_report(counter).0
    }
    /// As [`Self::encode`], with what had to be substituted.
    pub fn encode_with_report(&self, counter: u8) -> (CanFrame, EncodeReport) {
        let mut frame = CanFrame::EMPTY;
        let report = self.encode_into(counter, &mut frame);
        (frame, report)
    }
    /// As [`Self::encode_with_report`], into `out` (in place).
    pub fn encode_into(&self, counter: u8, out: &mut CanFrame) -> EncodeReport {
        let mut w = Writer::new(&spec::CONTROL_COMMAND);
        w.raw(&sig::COMMAND_STATUS, self.status.raw());
        w.phys(&sig::STEER_CMD_PCT, self.steer_cmd_pct);
        w.phys(&sig::COMMAND_SPEED_MPS, self.speed_cmd_mps);
        w.raw(&sig::FALLBACK_REASON, i64::from(self.fallback as u8));
        w.finish_into(spec::CONTROL_COMMAND.id, counter, out)
    }
    /// The message and its counter.
    pub fn decode(frame: &CanFrame) -> Result<(Self, u8), DecodeError> {
        let r = Reader::standard(&spec::CONTROL_COMMAND, frame)?;
        let msg = Self {
            status: ControlStatus::from_raw(r.required(&sig::COMMAND_STATUS)?),
            fallback: FallbackCause::from_raw(r.required(&sig::FALLBACK_REASON)?),
            steer_cmd_pct: r.phys(&sig::STEER_CMD_PCT)?,
            speed_cmd_mps: r.phys(&sig::COMMAND_SPEED_MPS)?,
        };
        Ok((msg, r.counter))
    }
}

/// NODE_STATUS page 0 health bits.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct HealthFlags {
    /// Steering report timed out.
    pub steer_stale: bool,
    /// Speed report timed out.
    pub speed_stale: bool,
    /// Pedal report timed out.
    pub pedal_stale: bool,
    /// GNSS timed out.
    pub gnss_stale: bool,
    /// A GNSS fix was rejected within the last second.
    pub gnss_rejected_recently: bool,
    /// No valid position.
    pub position_invalid: bool,
    /// A prediction value of this tick went out as "not available".
    pub prediction_saturated: bool,
    /// A non-finite value was caught this tick.
    pub nonfinite_guard: bool,
    /// The last reset was the watchdog's.
    pub watchdog_reset: bool,
    /// A tick overran within the last second.
    pub overrun_recently: bool,
    /// An input carried its "invalid" sentinel within the last second.
    pub input_invalid: bool,
    /// The node refused a planner frame or path within the last second.
    pub planner_refused_recently: bool,
    /// The GNSS receiver's fixes come at another rate than the model file declares: they are
    /// not used.
    pub gnss_rate_mismatch: bool,
    /// The car turns by another share of its steering than the model file says: the node uses
    /// the gain it measured.
    pub steering_mismatch: bool,
    /// The car's body, as the node estimates it, is more than
    /// [`crate::node::drive::OUTSIDE_CORRIDOR_M`] outside the corridor.
    pub outside_corridor: bool,
}

const HEALTH_BITS: [&SignalSpec; 15] = [
    &sig::STEER_STALE,
    &sig::SPEED_STALE,
    &sig::PEDAL_STALE,
    &sig::GNSS_STALE,
    &sig::GNSS_REJECTED_RECENTLY,
    &sig::POSITION_INVALID,
    &sig::PREDICTION_SATURATED,
    &sig::NONFINITE_GUARD,
    &sig::WATCHDOG_RESET,
    &sig::OVERRUN_RECENTLY,
    &sig::INPUT_INVALID,
    &sig::PLANNER_REFUSED_RECENTLY,
    &sig::GNSS_RATE_MISMATCH,
    &sig::STEERING_MISMATCH,
    &sig::OUTSIDE_CORRIDOR,
];

impl HealthFlags {
    const fn as_array(&self) -> [bool; 15] {
        [
            self.steer_stale,
            self.speed_stale,
            self.pedal_stale,
            self.gnss_stale,
            self.gnss_rejected_recently,
            self.position_invalid,
            self.prediction_saturated,
            self.nonfinite_guard,
            self.watchdog_reset,
            self.overrun_recently,
            self.input_invalid,
            self.planner_refused_recently,
            self.gnss_rate_mismatch,
            self.steering_mismatch,
            self.outside_corridor,
        ]
    }
    const fn from_array(b: [bool; 15]) -> Self {
        Self {
            steer_stale: b[0],
            speed_stale: b[1],
            pedal_stale: b[2],
            gnss_stale: b[3],
            gnss_rejected_recently: b[4],
            position_invalid: b[5],
            prediction_saturated: b[6],
            nonfinite_guard: b[7],
            watchdog_reset: b[8],
            overrun_recently: b[9],
            input_invalid: b[10],
            planner_refused_recently: b[11],
            gnss_rate_mismatch: b[12],
            steering_mismatch: b[13],
            outside_corridor: b[14],
        }
    }
}

/// NODE_STATUS (0x3F0), one page per tick (page = tick sequence number mod 6). Counters are
/// given as u32 and saturate at the field's maximum on the bus.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum NodeStatus {
    /// Page 0.
    Health {
        /// Model in use.
        mode: ModelMode,
        /// Health bits.
        health: HealthFlags,
        /// Ticks that overran since boot (saturates at 65 535).
        overrun_count: u32,
        /// Duration of the previous step, us (saturates at 65 534); `None` = not measured.
        last_step_us: Option<u32>,
    },
    /// Page 1.
    RxErrors {
        /// Frames with a bad CRC.
        crc_errors: u32,
        /// Stuck or jumping rolling counters.
        counter_errors: u32,
        /// Known identifiers with the wrong DLC.
        dlc_errors: u32,
    },
    /// Page 2.
    RxRejects {
        /// Values outside their DBC range.
        range_errors: u32,
        /// GNSS fixes rejected by the plausibility gate.
        gnss_gate_rejects: u32,
        /// Identifiers the node does not know.
        unknown_ids: u32,
    },
    /// Page 3.
    Platform {
        /// Ticks since boot (32 bits, saturating).
        tick_count: u32,
        /// Frames dropped by a full receive queue.
        rx_queue_drops: u32,
    },
    /// Page 4.
    Ages {
        /// Ages of the last steering, speed, pedal and GNSS input, 10 ms units, 254 =
        /// saturated, 255 = never received (see [`super::freshness::age_10ms`]).
        ages_10ms: [u8; 4],
        /// Deepest stack use, bytes (saturates at 65 534); `None` = not measured.
        stack_high_water_bytes: Option<u32>,
    },
    /// Page 5: the identified models' outputs (50 Hz / 6: diagnostics; the page took over the
    /// former STATE_MODEL frame's slot so that CONTROL_COMMAND fits the bus budget).
    Model(ModelOutputs),
}

const AGE_SIGNALS: [&SignalSpec; 4] = [
    &sig::STEER_AGE,
    &sig::SPEED_AGE,
    &sig::PEDAL_AGE,
    &sig::GNSS_AGE,
];

impl NodeStatus {
    /// The multiplexer page of this variant, 0..=5.
    pub const fn page(&self) -> u8 {
        match self {
            NodeStatus::Health { .. } => 0,
            NodeStatus::RxErrors { .. } => 1,
            NodeStatus::RxRejects { .. } => 2,
            NodeStatus::Platform { .. } => 3,
            NodeStatus::Ages { .. } => 4,
            NodeStatus::Model(_) => 5,
        }
    }

    /// The frame, with `counter` and its CRC.
    pub fn encode(&self, counter: u8) -> CanFrame {
        self.encode_with_report(counter).0
    }

    /// As [`Self::encode`], with what saturated.
    pub fn encode_with_report(&self, counter: u8) -> (CanFrame, EncodeReport) {
        let mut frame = CanFrame::EMPTY;
        let report = self.encode_into(counter, &mut frame);
        (frame, report)
    }
    /// As [`Self::encode_with_report`], into `out` (in place).
    pub fn encode_into(&self, counter: u8, out: &mut CanFrame) -> EncodeReport {
        let mut w = Writer::new(&spec::NODE_STATUS);
        w.raw(&sig::PAGE, i64::from(self.page()));
        match *self {
            NodeStatus::Health {
                mode,
                health,
                overrun_count,
                last_step_us,
            } => {
                w.raw(&sig::STATUS_MODE, mode.raw());
                w.flags(&HEALTH_BITS, health.as_array());
                w.count(&sig::OVERRUN_COUNT, overrun_count);
                w.count_or_na(&sig::LAST_STEP_US, last_step_us);
            }
            NodeStatus::RxErrors {
                crc_errors,
                counter_errors,
                dlc_errors,
            } => {
                w.count(&sig::CRC_ERRORS, crc_errors);
                w.count(&sig::COUNTER_ERRORS, counter_errors);
                w.count(&sig::DLC_ERRORS, dlc_errors);
            }
            NodeStatus::RxRejects {
                range_errors,
                gnss_gate_rejects,
                unknown_ids,
            } => {
                w.count(&sig::RANGE_ERRORS, range_errors);
                w.count(&sig::GNSS_GATE_REJECTS, gnss_gate_rejects);
                w.count(&sig::UNKNOWN_IDS, unknown_ids);
            }
            NodeStatus::Platform {
                tick_count,
                rx_queue_drops,
            } => {
                w.count(&sig::TICK_COUNT, tick_count);
                w.count(&sig::RX_QUEUE_DROPS, rx_queue_drops);
            }
            NodeStatus::Ages {
                ages_10ms,
                stack_high_water_bytes,
            } => {
                for (s, age) in AGE_SIGNALS.iter().zip(ages_10ms) {
                    w.raw(s, i64::from(age));
                }
                w.count_or_na(&sig::STACK_HIGH_WATER_BYTES, stack_high_water_bytes);
            }
            NodeStatus::Model(m) => {
                w.phys(&sig::SPEED_MODEL_MPS, m.speed_model_mps);
                w.phys(&sig::DXDT_MODEL_MPS, m.dxdt_model_mps);
                w.phys(&sig::LAT_ACCEL_MPS2, m.lat_accel_mps2);
            }
        }
        w.finish_into(spec::NODE_STATUS.id, counter, out)
    }

    /// The page and its counter.
    pub fn decode(frame: &CanFrame) -> Result<(Self, u8), DecodeError> {
        let r = Reader::standard(&spec::NODE_STATUS, frame)?;
        let msg = match r.required(&sig::PAGE)? {
            0 => {
                let mut bits = [false; HEALTH_BITS.len()];
                for (b, s) in bits.iter_mut().zip(HEALTH_BITS) {
                    *b = r.flag(s);
                }
                NodeStatus::Health {
                    mode: ModelMode::from_raw(sig::STATUS_MODE.read_raw(&r.data)),
                    health: HealthFlags::from_array(bits),
                    overrun_count: r.count(&sig::OVERRUN_COUNT)?,
                    last_step_us: r.raw(&sig::LAST_STEP_US)?.map(|v| v as u32),
                }
            }
            1 => NodeStatus::RxErrors {
                crc_errors: r.count(&sig::CRC_ERRORS)?,
                counter_errors: r.count(&sig::COUNTER_ERRORS)?,
                dlc_errors: r.count(&sig::DLC_ERRORS)?,
            },
            2 => NodeStatus::RxRejects {
                range_errors: r.count(&sig::RANGE_ERRORS)?,
                gnss_gate_rejects: r.count(&sig::GNSS_GATE_REJECTS)?,
                unknown_ids: r.count(&sig::UNKNOWN_IDS)?,
            },
            3 => NodeStatus::Platform {
                tick_count: r.count(&sig::TICK_COUNT)?,
                rx_queue_drops: r.count(&sig::RX_QUEUE_DROPS)?,
            },
            5 => NodeStatus::Model(ModelOutputs {
                speed_model_mps: r.phys(&sig::SPEED_MODEL_MPS)?,
                dxdt_model_mps: r.phys(&sig::DXDT_MODEL_MPS)?,
                lat_accel_mps2: r.phys(&sig::LAT_ACCEL_MPS2)?,
            }),
            _ => {
                let mut ages_10ms = [0u8; 4];
                for (a, s) in ages_10ms.iter_mut().zip(AGE_SIGNALS) {
                    *a = s.read_raw(&r.data) as u8;
                }
                NodeStatus::Ages {
                    ages_10ms,
                    stack_high_water_bytes: r.raw(&sig::STACK_HIGH_WATER_BYTES)?.map(|v| v as u32),
                }
            }
        };
        Ok((msg, r.counter))
    }
}
