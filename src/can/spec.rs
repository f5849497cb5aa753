//! The descriptor table of `catmodel.dbc`: one [`MessageSpec`] per message, one [`SignalSpec`]
//! per signal, and the generic, panic-free little-endian (Intel) bit packer that every typed codec
//! in [`super::codec`] goes through. `host-tests/tests/dbc.rs` checks this table against the DBC,
//! field by field, so the DBC stays the single source of truth.
//!
//! Raw limits are integers (`raw_min..=raw_max`); the physical value is `raw * scale + offset`.
//! Keeping the limits raw avoids f32 rounding on 32-bit signals (latitude in 1e-7 deg).
use super::frame::{CanFrame, CanId};

/// Name of our node in the DBC (`BU_`).
pub const NODE_CATMODEL: &str = "CATMODEL";
/// The drive-by-wire kit that sends the steering, speed and pedal reports.
pub const NODE_DBW: &str = "DBW";
/// The NMEA 2000 GNSS receiver.
pub const NODE_GNSS: &str = "GNSS";
/// The motion planner that consumes our predictions, state and status.
pub const NODE_PLANNER: &str = "PLANNER";

/// 2^bits for bits < 63 (saturating beyond), usable in const context.
const fn pow2(bits: u8) -> i64 {
    match 1i64.checked_shl(bits as u32) {
        Some(v) if bits < 63 => v,
        _ => i64::MAX,
    }
}

/// How a signal takes part in multiplexing (DBC `M` / `mN`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mux {
    /// Present in every frame of the message.
    Plain,
    /// The multiplexer switch itself (the page number).
    Switch,
    /// Present only when the switch equals this page.
    Page(u8),
}

/// One signal: position, width, signedness, scaling, raw limits, unit and its
/// "not available" sentinel. Byte order is always little-endian (Intel, `@1` in the DBC).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SignalSpec {
    /// Signal name, as in the DBC.
    pub name: &'static str,
    /// Least significant bit, Intel numbering (bit `b` = byte `b / 8`, bit `b % 8`).
    pub start_bit: u8,
    /// Width in bits, 1..=32.
    pub len_bits: u8,
    /// Two's complement signed.
    pub signed: bool,
    /// Physical = raw * scale + offset.
    pub scale: f32,
    /// Physical = raw * scale + offset.
    pub offset: f32,
    /// Smallest valid raw value (DBC minimum = raw_min * scale + offset).
    pub raw_min: i64,
    /// Largest valid raw value (DBC maximum = raw_max * scale + offset).
    pub raw_max: i64,
    /// Physical unit, as in the DBC.
    pub unit: &'static str,
    /// Multiplexing role.
    pub mux: Mux,
    /// Raw value meaning "invalid / not available", outside `raw_min..=raw_max`.
    pub not_available_raw: Option<i64>,
}

/// Raw magnitudes below this (2^22) convert between raw and physical exactly in f32.
const EXACT_BELOW: u64 = 1 << 22;

/// [`SignalSpec::to_raw`]'s fast path holds below this magnitude (2^30: `as i32` exact).
const WIDE_ABOVE: f32 = 1_073_741_824.0;

/// The adjacent f32 of a finite non-zero `x` in the direction of `toward` (core has no
/// `next_up` on the embedded target's MSRV path; bit arithmetic is exact).
fn next_toward(x: f32, toward: f32) -> f32 {
    let bits = x.to_bits();
    let up = (toward > x) == (x > 0.0);
    f32::from_bits(if up { bits + 1 } else { bits - 1 })
}

impl SignalSpec {
    /// An unsigned integer signal with unit scale covering its full width.
    pub const fn uint(name: &'static str, start_bit: u8, len_bits: u8) -> Self {
        Self {
            name,
            start_bit,
            len_bits,
            signed: false,
            scale: 1.0,
            offset: 0.0,
            raw_min: 0,
            raw_max: pow2(len_bits).wrapping_sub(1),
            unit: "",
            mux: Mux::Plain,
            not_available_raw: None,
        }
    }

    /// A signed integer signal with unit scale covering its full width.
    pub const fn int(name: &'static str, start_bit: u8, len_bits: u8) -> Self {
        Self {
            signed: true,
            raw_min: pow2(len_bits.saturating_sub(1)).wrapping_neg(),
            raw_max: pow2(len_bits.saturating_sub(1)).wrapping_sub(1),
            ..Self::uint(name, start_bit, len_bits)
        }
    }

    /// With a scale and a unit.
    pub const fn scaled(self, scale: f32, unit: &'static str) -> Self {
        Self {
            scale,
            unit,
            ..self
        }
    }

    /// With raw limits.
    pub const fn raw_range(self, raw_min: i64, raw_max: i64) -> Self {
        Self {
            raw_min,
            raw_max,
            ..self
        }
    }

    /// With a "not available" sentinel.
    pub const fn na(self, raw: i64) -> Self {
        Self {
            not_available_raw: Some(raw),
            ..self
        }
    }

    /// Only present on multiplexer page `page`.
    pub const fn on_page(self, page: u8) -> Self {
        Self {
            mux: Mux::Page(page),
            ..self
        }
    }

    /// As the multiplexer switch.
    pub const fn switch(self) -> Self {
        Self {
            mux: Mux::Switch,
            ..self
        }
    }

    /// The bit mask of the signal's width (all ones in the low `len_bits` bits).
    fn mask(&self) -> u64 {
        1u64.checked_shl(u32::from(self.len_bits))
            .map_or(u64::MAX, |m| m.wrapping_sub(1))
    }

    /// The signal's place when it lies within one 32-bit half of the payload: the half (0:
    /// bits 0..32, 1: bits 32..64), the shift within it and the width's mask. `None` when it
    /// straddles bit 32, is wider than 32 bits or empty.
    #[inline(always)]
    fn in_half(&self) -> Option<(u32, u32, u32)> {
        let start = u32::from(self.start_bit);
        let len = u32::from(self.len_bits);
        let end = start + len;
        if len == 0 || len > 32 || end > 64 || start / 32 != (end - 1) / 32 {
            return None;
        }
        Some((start / 32, start % 32, u32::MAX.wrapping_shr(32 - len)))
    }

    /// Reads the raw value (sign-extended when signed). Bits outside the 64-bit payload read 0.
    ///
    /// A signal within one 32-bit half is read with 32-bit shifts: where the signal is not a
    /// constant (a message's counter, read through its [`Integrity`]) a variable 64-bit shift
    /// and mask are some twenty instructions on the Cortex-M4, a 32-bit one two. Where it is
    /// a constant both fold to the same code.
    #[inline(always)]
    pub fn read_raw(&self, data: &[u8; 8]) -> i64 {
        let word = u64::from_le_bytes(*data);
        if let Some((half, shift, mask)) = self.in_half() {
            let w = if half == 0 {
                word as u32
            } else {
                (word >> 32) as u32
            };
            let bits = w.wrapping_shr(shift) & mask;
            return if self.signed {
                let sign = 1u32.wrapping_shl(u32::from(self.len_bits) - 1);
                i64::from((bits ^ sign).wrapping_sub(sign) as i32)
            } else {
                i64::from(bits)
            };
        }
        let bits = word.checked_shr(u32::from(self.start_bit)).unwrap_or(0) & self.mask();
        if self.signed && self.len_bits > 0 && self.len_bits < 64 {
            let sign = 1u64 << (self.len_bits - 1);
            // Two's complement sign extension: (bits ^ sign) - sign, in wrapping arithmetic.
            (bits ^ sign).wrapping_sub(sign) as i64
        } else {
            bits as i64
        }
    }

    /// Writes `raw` (truncated to the signal's width) into `data`, leaving other bits alone;
    /// within one 32-bit half with 32-bit shifts, as [`Self::read_raw`].
    #[inline(always)]
    pub fn write_raw(&self, data: &mut [u8; 8], raw: i64) {
        let word = u64::from_le_bytes(*data);
        if let Some((half, shift, mask)) = self.in_half() {
            let (mut lo, mut hi) = (word as u32, (word >> 32) as u32);
            let w = if half == 0 { &mut lo } else { &mut hi };
            *w = (*w & !mask.wrapping_shl(shift)) | ((raw as u32) & mask).wrapping_shl(shift);
            *data = ((u64::from(hi) << 32) | u64::from(lo)).to_le_bytes();
            return;
        }
        let shift = u32::from(self.start_bit);
        let mask = self.mask().checked_shl(shift).unwrap_or(0);
        let value = (raw as u64).checked_shl(shift).unwrap_or(0) & mask;
        *data = ((word & !mask) | value).to_le_bytes();
    }

    /// Whether `raw` is within the signal's valid limits.
    pub const fn in_range(&self, raw: i64) -> bool {
        raw >= self.raw_min && raw <= self.raw_max
    }

    /// Physical value of a raw value (f32: exact for raw values up to 2^24).
    pub fn to_physical(&self, raw: i64) -> f32 {
        let physical = crate::math::i64_to_f32(raw) * self.scale + self.offset;
        if raw.unsigned_abs() >= EXACT_BELOW {
            return self.exact_physical(raw, physical);
        }
        physical
    }

    /// Above 2^22 (24-bit signals such as positions near their range limits) the nearest f32
    /// to `raw * scale` can divide back to a neighbouring raw value; then the adjacent f32 that
    /// [`Self::to_raw`] maps back to `raw` is returned, so that encoding is the exact inverse
    /// of decoding. Out of line: the node's own values never get here.
    #[cold]
    #[inline(never)]
    fn exact_physical(&self, raw: i64, physical: f32) -> f32 {
        if self.to_raw(physical) == Some(raw) {
            return physical;
        }
        for candidate in [
            next_toward(physical, f32::NEG_INFINITY),
            next_toward(physical, f32::INFINITY),
        ] {
            if self.to_raw(candidate) == Some(raw) {
                return candidate;
            }
        }
        physical
    }

    /// Raw value of a physical one, rounded to nearest (halves away from zero); `None` if
    /// `physical` is not finite or the rounded value is outside `raw_min..=raw_max` (the caller
    /// then sends "not available").
    ///
    /// Below 2^30 in magnitude (every float signal of the table: their limits are below 2^24)
    /// the rounding is one truncating VCVT and the remainder, which is exact in f32, and the
    /// limits are compared as integers: about half the instructions of `libm::roundf` and float
    /// comparisons on the Cortex-M4, and the same rounding as `libm::roundf` for every `f32`
    /// (`tests::to_raw_*`). Larger
    /// values, and NaN, go to [`Self::wide_raw`].
    #[inline]
    pub fn to_raw(&self, physical: f32) -> Option<i64> {
        let scaled = (physical - self.offset) / self.scale;
        // NaN fails the comparison and goes the wide way too.
        #[allow(clippy::neg_cmp_op_on_partial_ord)]
        if !(scaled.abs() < WIDE_ABOVE) {
            return self.wide_raw(scaled);
        }
        // `scaled as i32` truncates towards zero and is exact below 2^30; so is the remainder
        // (an f32 minus its own integer part).
        let truncated = scaled as i32;
        let rest = scaled - truncated as f32;
        let raw = i64::from(truncated + i32::from(rest >= 0.5) - i32::from(rest <= -0.5));
        if self.in_range(raw) {
            Some(raw)
        } else {
            None
        }
    }

    /// [`Self::to_raw`] of a scaled value beyond 2^30 in magnitude, or NaN: out of line.
    #[cold]
    #[inline(never)]
    fn wide_raw(&self, scaled: f32) -> Option<i64> {
        let raw = libm::roundf(scaled);
        // NaN and infinities fail; beyond 2^24 every f32 is an integer and `as i64` exact.
        if raw.is_finite() && self.in_range(raw as i64) {
            Some(raw as i64)
        } else {
            None
        }
    }
}

/// How a message is protected.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Integrity {
    /// 4-bit rolling counter (the given signal) and CRC-8/SAE-J1850 in byte 7.
    CounterCrc(SignalSpec),
    /// No counter or CRC (NMEA 2000): range and plausibility checks instead.
    RangeOnly,
}

/// One message: identifier, length, cycle time, sender, receivers and signals.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MessageSpec {
    /// Message name, as in the DBC.
    pub name: &'static str,
    /// Identifier (for NMEA 2000: priority 2, the default source address 0x1C).
    pub id: CanId,
    /// Data length code.
    pub dlc: u8,
    /// Nominal transmit period, ms (DBC attribute `GenMsgCycleTime`).
    pub cycle_ms: u16,
    /// Sending node.
    pub transmitter: &'static str,
    /// Receiving nodes of every signal.
    pub receivers: &'static [&'static str],
    /// Every signal, counter and CRC included.
    pub signals: &'static [SignalSpec],
    /// Counter and CRC, or none.
    pub integrity: Integrity,
}

impl MessageSpec {
    /// The signal called `name`.
    pub fn signal(&self, name: &str) -> Option<&SignalSpec> {
        self.signals.iter().find(|s| s.name == name)
    }

    /// An all-zero frame of this message's identifier and length.
    pub const fn empty_frame(&self) -> CanFrame {
        CanFrame {
            id: self.id,
            len: self.dlc,
            data: [0; 8],
        }
    }
}

/// Signal definitions, shared by the table and the typed codecs.
pub mod sig {
    use super::SignalSpec;

    /// Rolling counter of the inputs (bits 52..55).
    pub const COUNTER_IN: SignalSpec = SignalSpec::uint("counter", 52, 4);
    /// Rolling counter of the outputs (bits 0..3).
    pub const COUNTER_OUT: SignalSpec = SignalSpec::uint("counter", 0, 4);
    /// CRC-8/SAE-J1850, byte 7.
    pub const CRC: SignalSpec = SignalSpec::uint("crc", 56, 8);

    /// Steering, % of full lock, positive = right; -32768 = invalid.
    pub const STEER_PCT: SignalSpec = SignalSpec::int("steer_pct", 0, 16)
        .scaled(0.01, "%")
        .raw_range(-10_000, 10_000)
        .na(-32_768);
    /// Measured speed; 0xFFFF = invalid.
    pub const SPEED_MPS: SignalSpec = SignalSpec::uint("speed_mps", 0, 16)
        .scaled(0.01, "m/s")
        .raw_range(0, 65_534)
        .na(0xFFFF);
    /// Commanded speed; 0xFFFF = invalid.
    pub const SPEED_CMD_MPS: SignalSpec = SignalSpec::uint("speed_cmd_mps", 16, 16)
        .scaled(0.01, "m/s")
        .raw_range(0, 65_534)
        .na(0xFFFF);
    /// SPEED_REPORT: which way the car moves (its gear), `codec::Direction`: 0 not reported,
    /// 1 forward, 2 reverse, 3 invalid. Every log before the signal has 0 in these bits.
    pub const DIRECTION: SignalSpec = SignalSpec::uint("direction", 32, 2);
    /// Accelerator pedal; 0xFFFF = invalid.
    pub const ACCEL_PCT: SignalSpec = SignalSpec::uint("accel_pct", 0, 16)
        .scaled(0.01, "%")
        .raw_range(0, 10_000)
        .na(0xFFFF);
    /// Brake pedal; 0xFFFF = invalid.
    pub const BRAKE_PCT: SignalSpec = SignalSpec::uint("brake_pct", 16, 16)
        .scaled(0.01, "%")
        .raw_range(0, 10_000)
        .na(0xFFFF);

    /// NMEA 2000 PGN 129025 latitude, 1e-7 deg; 0x7FFFFFFF = not available.
    pub const LATITUDE_DEG: SignalSpec = SignalSpec::int("latitude_deg", 0, 32)
        .scaled(1e-7, "deg")
        .raw_range(-900_000_000, 900_000_000)
        .na(0x7FFF_FFFF);
    /// NMEA 2000 PGN 129025 longitude, 1e-7 deg; 0x7FFFFFFF = not available.
    pub const LONGITUDE_DEG: SignalSpec = SignalSpec::int("longitude_deg", 32, 32)
        .scaled(1e-7, "deg")
        .raw_range(-1_800_000_000, 1_800_000_000)
        .na(0x7FFF_FFFF);
    /// NMEA 2000 sequence identifier (ties 129026 to 129025 of the same fix).
    pub const SID: SignalSpec = SignalSpec::uint("sid", 0, 8);
    /// NMEA 2000 direction reference: 0 true, 1 magnetic, 2 error, 3 null.
    pub const COG_REFERENCE: SignalSpec = SignalSpec::uint("cog_reference", 8, 2);
    /// Course over ground, 1e-4 rad, [0, 2 pi]; 0xFFFF = not available.
    pub const COG_RAD: SignalSpec = SignalSpec::uint("cog_rad", 16, 16)
        .scaled(1e-4, "rad")
        .raw_range(0, 62_832)
        .na(0xFFFF);
    /// Speed over ground, 0.01 m/s; 0xFFFF = not available (0xFFFD..0xFFFE reserved by N2K).
    pub const SOG_MPS: SignalSpec = SignalSpec::uint("sog_mps", 32, 16)
        .scaled(0.01, "m/s")
        .raw_range(0, 65_532)
        .na(0xFFFF);

    /// STATE_POSITION flag: the position below is valid.
    pub const POSITION_VALID: SignalSpec = SignalSpec::uint("position_valid", 4, 1);
    /// STATE_POSITION flag: a GNSS fix arrived within its timeout.
    pub const GNSS_FRESH: SignalSpec = SignalSpec::uint("gnss_fresh", 5, 1);
    /// STATE_POSITION flag: the last GNSS fix was rejected by the plausibility gate.
    pub const GNSS_REJECTED: SignalSpec = SignalSpec::uint("gnss_rejected", 6, 1);
    /// East of the local origin, 0.01 m; raw minimum = not available.
    pub const EAST_M: SignalSpec = SignalSpec::int("east_m", 8, 24)
        .scaled(0.01, "m")
        .raw_range(-8_388_607, 8_388_607)
        .na(-8_388_608);
    /// North of the local origin, 0.01 m; raw minimum = not available.
    pub const NORTH_M: SignalSpec = SignalSpec::int("north_m", 32, 24)
        .scaled(0.01, "m")
        .raw_range(-8_388_607, 8_388_607)
        .na(-8_388_608);

    /// Model in use: 0 kinematic, 1 dynamic (STATE_MOTION).
    pub const MODE: SignalSpec = SignalSpec::uint("mode", 4, 1);
    /// 1 while the heading's own standard deviation is above
    /// [`HEADING_UNCERTAIN_ABOVE_RAD`](crate::node::HEADING_UNCERTAIN_ABOVE_RAD): just after
    /// the first course set it, or after the track showed it off (a slide the lateral model
    /// did not see); 0 otherwise and while there is no heading.
    pub const HEADING_UNCERTAIN: SignalSpec = SignalSpec::uint("heading_uncertain", 5, 1);
    /// Heading, clockwise from north, 0.001 rad, [-pi, pi]; -32768 = not available.
    pub const HEADING_RAD: SignalSpec = SignalSpec::int("heading_rad", 8, 16)
        .scaled(0.001, "rad")
        .raw_range(-3_142, 3_142)
        .na(-32_768);
    /// Filtered speed, 0.01 m/s; 0xFFFF = not available.
    pub const STATE_SPEED_MPS: SignalSpec = SignalSpec::uint("speed_mps", 24, 16)
        .scaled(0.01, "m/s")
        .raw_range(0, 65_534)
        .na(0xFFFF);
    /// Yaw rate, clockwise positive, 0.001 rad/s; -32768 = not available.
    pub const YAW_RATE_RADPS: SignalSpec = SignalSpec::int("yaw_rate_radps", 40, 16)
        .scaled(0.001, "rad/s")
        .raw_range(-32_767, 32_767)
        .na(-32_768);

    /// Prediction: east displacement from the tick's STATE_POSITION, 0.01 m.
    pub const DX_M: SignalSpec = SignalSpec::int("dx_m", 4, 14)
        .scaled(0.01, "m")
        .raw_range(-8_191, 8_191)
        .na(-8_192);
    /// Prediction: north displacement from the tick's STATE_POSITION, 0.01 m.
    pub const DY_M: SignalSpec = SignalSpec::int("dy_m", 18, 14)
        .scaled(0.01, "m")
        .raw_range(-8_191, 8_191)
        .na(-8_192);
    /// Prediction: heading change from the tick's heading, 0.001 rad.
    pub const DHEADING_RAD: SignalSpec = SignalSpec::int("dheading_rad", 32, 12)
        .scaled(0.001, "rad")
        .raw_range(-2_047, 2_047)
        .na(-2_048);
    /// Prediction: speed, 0.01 m/s; 0xFFF = not available.
    pub const PRED_SPEED_MPS: SignalSpec = SignalSpec::uint("speed_mps", 44, 12)
        .scaled(0.01, "m/s")
        .raw_range(0, 4_094)
        .na(0xFFF);

    /// Planner messages: which path, 0..15 (a new id replaces the path once complete).
    pub const PATH_ID: SignalSpec = SignalSpec::uint("path_id", 4, 4);
    /// PATH_HEADER: number of points of the path, 2..=256.
    pub const PATH_COUNT: SignalSpec =
        SignalSpec::uint("count", 8, 9).raw_range(2, super::MAX_PATH_POINTS as i64);
    /// PATH_POINT / PATH_LIMITS: index of the point, 0..count-1.
    pub const PATH_INDEX: SignalSpec = SignalSpec::uint("index", 8, 8);
    /// PATH_POINT: rear-axle path point east of the local origin, 0.02 m, +-10.49 km.
    pub const PATH_EAST_M: SignalSpec = SignalSpec::int("east_m", 16, 20)
        .scaled(0.02, "m")
        .raw_range(-524_287, 524_287)
        .na(-524_288);
    /// PATH_POINT: north of the local origin, 0.02 m.
    pub const PATH_NORTH_M: SignalSpec = SignalSpec::int("north_m", 36, 20)
        .scaled(0.02, "m")
        .raw_range(-524_287, 524_287)
        .na(-524_288);
    /// PATH_LIMITS: target speed at the point, 0.01 m/s; 0xFFF = not available (rejected).
    pub const PATH_SPEED_MPS: SignalSpec = SignalSpec::uint("speed_mps", 16, 12)
        .scaled(0.01, "m/s")
        .raw_range(0, 4_094)
        .na(0xFFF);
    /// PATH_LIMITS: how far the body may stray left of the point, 0.01 m.
    pub const PATH_LEFT_M: SignalSpec = SignalSpec::uint("left_m", 28, 14)
        .scaled(0.01, "m")
        .raw_range(0, 16_382)
        .na(0x3FFF);
    /// PATH_LIMITS: how far the body may stray right of the point, 0.01 m.
    pub const PATH_RIGHT_M: SignalSpec = SignalSpec::uint("right_m", 42, 14)
        .scaled(0.01, "m")
        .raw_range(0, 16_382)
        .na(0x3FFF);

    /// OBSTACLE: slot, 0..3.
    pub const OBSTACLE_ID: SignalSpec = SignalSpec::uint("obstacle_id", 4, 2);
    /// OBSTACLE: 1 = the slot holds an obstacle, 0 = the slot is cleared.
    pub const OBSTACLE_ACTIVE: SignalSpec = SignalSpec::uint("active", 6, 1);
    /// OBSTACLE: centre east of the local origin, 0.02 m.
    pub const OBSTACLE_EAST_M: SignalSpec = SignalSpec::int("east_m", 8, 20)
        .scaled(0.02, "m")
        .raw_range(-524_287, 524_287)
        .na(-524_288);
    /// OBSTACLE: centre north of the local origin, 0.02 m.
    pub const OBSTACLE_NORTH_M: SignalSpec = SignalSpec::int("north_m", 28, 20)
        .scaled(0.02, "m")
        .raw_range(-524_287, 524_287)
        .na(-524_288);
    /// OBSTACLE: radius of the circle the body keeps clear of, 0.05 m, 0..12.7 m; 0xFF = not
    /// available.
    pub const OBSTACLE_RADIUS_M: SignalSpec = SignalSpec::uint("radius_m", 48, 8)
        .scaled(0.05, "m")
        .raw_range(0, 254)
        .na(0xFF);

    /// LOCAL_ORIGIN page: 0 latitude, 1 longitude (multiplexer switch).
    pub const ORIGIN_PAGE: SignalSpec = SignalSpec::uint("page", 4, 1).switch();
    /// LOCAL_ORIGIN page 0: latitude of the planner's map origin, 1e-7 deg (as PGN 129025).
    pub const ORIGIN_LATITUDE_DEG: SignalSpec = SignalSpec::int("latitude_deg", 8, 32)
        .scaled(1e-7, "deg")
        .raw_range(-900_000_000, 900_000_000)
        .na(0x7FFF_FFFF)
        .on_page(0);
    /// LOCAL_ORIGIN page 1: longitude of the planner's map origin, 1e-7 deg.
    pub const ORIGIN_LONGITUDE_DEG: SignalSpec = SignalSpec::int("longitude_deg", 8, 32)
        .scaled(1e-7, "deg")
        .raw_range(-1_800_000_000, 1_800_000_000)
        .na(0x7FFF_FFFF)
        .on_page(1);

    /// CONTROL_COMMAND: 0 no path, 1 tracking, 2 avoiding, 3 fallback.
    pub const COMMAND_STATUS: SignalSpec = SignalSpec::uint("status", 4, 2);
    /// CONTROL_COMMAND: steering command, % of full lock, positive = right (as
    /// STEERING_REPORT); -32768 = not available.
    pub const STEER_CMD_PCT: SignalSpec = SignalSpec::int("steer_cmd_pct", 8, 16)
        .scaled(0.01, "%")
        .raw_range(-10_000, 10_000)
        .na(-32_768);
    /// CONTROL_COMMAND: speed command, 0.01 m/s; 0xFFFF = not available.
    pub const COMMAND_SPEED_MPS: SignalSpec = SignalSpec::uint("speed_cmd_mps", 24, 16)
        .scaled(0.01, "m/s")
        .raw_range(0, 65_534)
        .na(0xFFFF);
    /// CONTROL_COMMAND: why the status is the fallback (0 when it is not; `FallbackCause`).
    pub const FALLBACK_REASON: SignalSpec =
        SignalSpec::uint("fallback_reason", 40, 4).raw_range(0, 14);

    /// NODE_STATUS page number (multiplexer switch).
    pub const PAGE: SignalSpec = SignalSpec::uint("page", 4, 4).raw_range(0, 5).switch();
    /// Page 0: model in use, 0 kinematic, 1 dynamic.
    pub const STATUS_MODE: SignalSpec = SignalSpec::uint("mode", 8, 1).on_page(0);
    /// Page 0 health bit.
    pub const STEER_STALE: SignalSpec = SignalSpec::uint("steer_stale", 9, 1).on_page(0);
    /// Page 0 health bit.
    pub const SPEED_STALE: SignalSpec = SignalSpec::uint("speed_stale", 10, 1).on_page(0);
    /// Page 0 health bit.
    pub const PEDAL_STALE: SignalSpec = SignalSpec::uint("pedal_stale", 11, 1).on_page(0);
    /// Page 0 health bit.
    pub const GNSS_STALE: SignalSpec = SignalSpec::uint("gnss_stale", 12, 1).on_page(0);
    /// Page 0 health bit: a GNSS fix was rejected within the last second.
    pub const GNSS_REJECTED_RECENTLY: SignalSpec =
        SignalSpec::uint("gnss_rejected_recently", 13, 1).on_page(0);
    /// Page 0 health bit.
    pub const POSITION_INVALID: SignalSpec = SignalSpec::uint("position_invalid", 14, 1).on_page(0);
    /// Page 0 health bit: a prediction field of this tick went out as "not available".
    pub const PREDICTION_SATURATED: SignalSpec =
        SignalSpec::uint("prediction_saturated", 15, 1).on_page(0);
    /// Page 0 health bit: a non-finite value was caught this tick.
    pub const NONFINITE_GUARD: SignalSpec = SignalSpec::uint("nonfinite_guard", 16, 1).on_page(0);
    /// Page 0 health bit: the last reset was the watchdog's.
    pub const WATCHDOG_RESET: SignalSpec = SignalSpec::uint("watchdog_reset", 17, 1).on_page(0);
    /// Page 0 health bit: a tick overran within the last second.
    pub const OVERRUN_RECENTLY: SignalSpec = SignalSpec::uint("overrun_recently", 18, 1).on_page(0);
    /// Page 0 health bit: an input carried its "invalid" sentinel within the last second.
    pub const INPUT_INVALID: SignalSpec = SignalSpec::uint("input_invalid", 19, 1).on_page(0);
    /// Page 0 health bit: the node refused a planner frame or path within the last second (a
    /// stuck counter, a duplicate or stray index, an abandoned or invalid path, a longitude
    /// page without its latitude page; [`crate::control::planner::PlannerCounters::rejects`]).
    pub const PLANNER_REFUSED_RECENTLY: SignalSpec =
        SignalSpec::uint("planner_refused_recently", 20, 1).on_page(0);
    /// Page 0 health bit: the GNSS receiver's fixes come at another rate than the model file
    /// declares (`gnss_rate_hz`), and the node does not use them
    /// ([`crate::node::gnss::RATE_MISMATCH_FIXES`]).
    pub const GNSS_RATE_MISMATCH: SignalSpec =
        SignalSpec::uint("gnss_rate_mismatch", 21, 1).on_page(0);
    /// Page 0 health bit: the car turns by another share of its steering than the model file
    /// says, and the node uses the gain it measured ([`crate::node::steering`]).
    pub const STEERING_MISMATCH: SignalSpec =
        SignalSpec::uint("steering_mismatch", 22, 1).on_page(0);
    /// Page 0 health bit: the car's body, as the node estimates it, is more than
    /// [`crate::node::drive::OUTSIDE_CORRIDOR_M`] outside the corridor while the controller
    /// drives (the corridor's rows are soft: a bend the body cannot sweep inside it, a reversal
    /// the steering cannot follow at the path's speed).
    pub const OUTSIDE_CORRIDOR: SignalSpec = SignalSpec::uint("outside_corridor", 23, 1).on_page(0);
    /// Page 0: ticks that overran since boot, saturating.
    pub const OVERRUN_COUNT: SignalSpec = SignalSpec::uint("overrun_count", 24, 16).on_page(0);
    /// Page 0: duration of the previous step, us; 0xFFFF = not available.
    pub const LAST_STEP_US: SignalSpec = SignalSpec::uint("last_step_us", 40, 16)
        .scaled(1.0, "us")
        .raw_range(0, 0xFFFE)
        .na(0xFFFF)
        .on_page(0);
    /// Page 1: frames with a bad CRC, saturating.
    pub const CRC_ERRORS: SignalSpec = SignalSpec::uint("crc_errors", 8, 16).on_page(1);
    /// Page 1: frames with a stuck counter, plus counter jumps, saturating.
    pub const COUNTER_ERRORS: SignalSpec = SignalSpec::uint("counter_errors", 24, 16).on_page(1);
    /// Page 1: frames of a known id with the wrong length, saturating.
    pub const DLC_ERRORS: SignalSpec = SignalSpec::uint("dlc_errors", 40, 16).on_page(1);
    /// Page 2: frames with a value outside its DBC range, saturating.
    pub const RANGE_ERRORS: SignalSpec = SignalSpec::uint("range_errors", 8, 16).on_page(2);
    /// Page 2: GNSS fixes rejected by the plausibility gate, saturating.
    pub const GNSS_GATE_REJECTS: SignalSpec =
        SignalSpec::uint("gnss_gate_rejects", 24, 16).on_page(2);
    /// Page 2: frames of identifiers the node does not know, saturating.
    pub const UNKNOWN_IDS: SignalSpec = SignalSpec::uint("unknown_ids", 40, 16).on_page(2);
    /// Page 3: ticks since boot, saturating.
    pub const TICK_COUNT: SignalSpec = SignalSpec::uint("tick_count", 8, 32).on_page(3);
    /// Page 3: frames dropped by a full receive queue, saturating.
    pub const RX_QUEUE_DROPS: SignalSpec = SignalSpec::uint("rx_queue_drops", 40, 16).on_page(3);
    /// Page 4: age of the last steering report, 10 ms, 254 = saturated, 255 = never.
    pub const STEER_AGE: SignalSpec = SignalSpec::uint("steer_age", 8, 8)
        .scaled(10.0, "ms")
        .raw_range(0, 254)
        .na(255)
        .on_page(4);
    /// Page 4: age of the last speed report.
    pub const SPEED_AGE: SignalSpec = SignalSpec::uint("speed_age", 16, 8)
        .scaled(10.0, "ms")
        .raw_range(0, 254)
        .na(255)
        .on_page(4);
    /// Page 4: age of the last pedal report.
    pub const PEDAL_AGE: SignalSpec = SignalSpec::uint("pedal_age", 24, 8)
        .scaled(10.0, "ms")
        .raw_range(0, 254)
        .na(255)
        .on_page(4);
    /// Page 4: age of the last accepted GNSS fix.
    pub const GNSS_AGE: SignalSpec = SignalSpec::uint("gnss_age", 32, 8)
        .scaled(10.0, "ms")
        .raw_range(0, 254)
        .na(255)
        .on_page(4);
    /// Page 4: deepest stack use, bytes; 0xFFFF = not available.
    pub const STACK_HIGH_WATER_BYTES: SignalSpec =
        SignalSpec::uint("stack_high_water_bytes", 40, 16)
            .scaled(1.0, "B")
            .raw_range(0, 0xFFFE)
            .na(0xFFFF)
            .on_page(4);
    /// Page 5: velocity-model output (eq 5), 0.01 m/s; 0xFFFF = not available.
    pub const SPEED_MODEL_MPS: SignalSpec = SignalSpec::uint("speed_model_mps", 8, 16)
        .scaled(0.01, "m/s")
        .raw_range(0, 65_534)
        .na(0xFFFF)
        .on_page(5);
    /// Page 5: dx/dt model output (eq 7), 0.01 m/s; -32768 = not available.
    pub const DXDT_MODEL_MPS: SignalSpec = SignalSpec::int("dxdt_model_mps", 24, 16)
        .scaled(0.01, "m/s")
        .raw_range(-32_767, 32_767)
        .na(-32_768)
        .on_page(5);
    /// Page 5: lateral acceleration, 0.01 m/s^2, positive = right; -32768 = not available.
    pub const LAT_ACCEL_MPS2: SignalSpec = SignalSpec::int("lat_accel_mps2", 40, 16)
        .scaled(0.01, "m/s^2")
        .raw_range(-32_767, 32_767)
        .na(-32_768)
        .on_page(5);
}

use sig::*;

const TO_NODE: &[&str] = &[NODE_CATMODEL];
const TO_PLANNER: &[&str] = &[NODE_PLANNER];
const TO_DBW_AND_PLANNER: &[&str] = &[NODE_DBW, NODE_PLANNER];

/// Most points a path may have: the 8-bit `index` of PATH_POINT / PATH_LIMITS (0..=255).
/// At 0.5-1 m spacing that is 128-256 m of path, more than the 2 s horizon needs at any speed
/// the car reaches; the node holds two paths (the active one and the one arriving).
pub const MAX_PATH_POINTS: usize = 256;
/// Obstacle slots of OBSTACLE (`obstacle_id` 0..=3).
pub const OBSTACLE_SLOTS: usize = 4;

/// NMEA 2000 priority our GNSS identifiers carry (the PGNs' default).
pub const N2K_PRIORITY: u32 = 2;
/// NMEA 2000 source address of the GNSS receiver unless configured otherwise.
pub const N2K_DEFAULT_SOURCE: u8 = 0x1C;
/// NMEA 2000 PGN "Position, Rapid Update".
pub const PGN_POSITION_RAPID: u32 = 129_025;
/// NMEA 2000 PGN "COG & SOG, Rapid Update".
pub const PGN_COG_SOG_RAPID: u32 = 129_026;

/// The 29-bit identifier of an NMEA 2000 (ISO 11783 / J1939) PDU2 broadcast.
pub const fn n2k_id(priority: u32, pgn: u32, source: u8) -> u32 {
    ((priority & 0x7) << 26) | ((pgn & 0x3_FFFF) << 8) | source as u32
}

/// `(pgn, source)` of a 29-bit identifier (J1939 rules: PDU1 PGNs drop the destination byte).
pub const fn n2k_pgn_source(id: u32) -> (u32, u8) {
    let pf = (id >> 16) & 0xFF;
    let pgn = if pf < 240 {
        (id >> 8) & 0x3_FF00
    } else {
        (id >> 8) & 0x3_FFFF
    };
    (pgn, id as u8)
}

/// The PGN field of a 29-bit identifier as an acceptance filter masks it: bits 8..25
/// (reserved, data page, PDU format, PDU specific), priority and source address left out.
pub const N2K_PGN_FIELD_MASK: u32 = 0x3_FFFF << 8;

/// The node's inputs with standard identifiers: the vehicle's reports and the planner's
/// messages (the acceptance filter admits exactly these, and the two GNSS PGNs).
pub const NODE_INPUT_STANDARD: [&MessageSpec; 8] = [
    &STEERING_REPORT,
    &SPEED_REPORT,
    &PEDAL_REPORT,
    &PATH_HEADER,
    &PATH_POINT,
    &PATH_LIMITS,
    &OBSTACLE,
    &LOCAL_ORIGIN,
];

/// Whether a frame with `id` is one of the node's inputs, by its identifier alone: the bus
/// interface's acceptance filter. The board programs it into bxCAN's filter banks (the 50 Hz
/// reports and the planner's messages by identifier, the GNSS PGNs from any source at any
/// priority); the app's receive
/// loop (QEMU) and host replay apply it in software, so frames it refuses never reach the node
/// and never take a place among a tick's frames.
pub fn is_node_input(id: CanId) -> bool {
    match id {
        CanId::Standard(_) => NODE_INPUT_STANDARD.iter().any(|spec| spec.id == id),
        CanId::Extended(raw) => {
            let pgn = (raw & N2K_PGN_FIELD_MASK) >> 8;
            pgn == PGN_POSITION_RAPID || pgn == PGN_COG_SOG_RAPID
        }
    }
}

/// Input 0x100, 50 Hz.
pub const STEERING_REPORT: MessageSpec = MessageSpec {
    name: "STEERING_REPORT",
    id: CanId::Standard(0x100),
    dlc: 8,
    cycle_ms: 20,
    transmitter: NODE_DBW,
    receivers: TO_NODE,
    signals: &[STEER_PCT, COUNTER_IN, CRC],
    integrity: Integrity::CounterCrc(COUNTER_IN),
};
/// Input 0x101, 50 Hz.
pub const SPEED_REPORT: MessageSpec = MessageSpec {
    name: "SPEED_REPORT",
    id: CanId::Standard(0x101),
    dlc: 8,
    cycle_ms: 20,
    transmitter: NODE_DBW,
    receivers: TO_NODE,
    signals: &[SPEED_MPS, SPEED_CMD_MPS, DIRECTION, COUNTER_IN, CRC],
    integrity: Integrity::CounterCrc(COUNTER_IN),
};
/// Input 0x102, 50 Hz.
pub const PEDAL_REPORT: MessageSpec = MessageSpec {
    name: "PEDAL_REPORT",
    id: CanId::Standard(0x102),
    dlc: 8,
    cycle_ms: 20,
    transmitter: NODE_DBW,
    receivers: TO_NODE,
    signals: &[ACCEL_PCT, BRAKE_PCT, COUNTER_IN, CRC],
    integrity: Integrity::CounterCrc(COUNTER_IN),
};
/// Input: NMEA 2000 PGN 129025, typically 10 Hz.
pub const GNSS_POSITION_RAPID: MessageSpec = MessageSpec {
    name: "GNSS_POSITION_RAPID",
    id: CanId::Extended(n2k_id(N2K_PRIORITY, PGN_POSITION_RAPID, N2K_DEFAULT_SOURCE)),
    dlc: 8,
    cycle_ms: 100,
    transmitter: NODE_GNSS,
    receivers: TO_NODE,
    signals: &[LATITUDE_DEG, LONGITUDE_DEG],
    integrity: Integrity::RangeOnly,
};
/// Input: NMEA 2000 PGN 129026, typically 10 Hz.
pub const GNSS_COG_SOG_RAPID: MessageSpec = MessageSpec {
    name: "GNSS_COG_SOG_RAPID",
    id: CanId::Extended(n2k_id(N2K_PRIORITY, PGN_COG_SOG_RAPID, N2K_DEFAULT_SOURCE)),
    dlc: 8,
    cycle_ms: 100,
    transmitter: NODE_GNSS,
    receivers: TO_NODE,
    signals: &[SID, COG_REFERENCE, COG_RAD, SOG_MPS],
    integrity: Integrity::RangeOnly,
};
/// Input 0x200 from the planner, on a new path: announces `path_id` and its point count.
pub const PATH_HEADER: MessageSpec = MessageSpec {
    name: "PATH_HEADER",
    id: CanId::Standard(0x200),
    dlc: 8,
    cycle_ms: 0,
    transmitter: NODE_PLANNER,
    receivers: TO_NODE,
    signals: &[COUNTER_OUT, PATH_ID, PATH_COUNT, CRC],
    integrity: Integrity::CounterCrc(COUNTER_OUT),
};
/// Input 0x201 from the planner: one point of the path (the rear axle's), in index order.
pub const PATH_POINT: MessageSpec = MessageSpec {
    name: "PATH_POINT",
    id: CanId::Standard(0x201),
    dlc: 8,
    cycle_ms: 0,
    transmitter: NODE_PLANNER,
    receivers: TO_NODE,
    signals: &[
        COUNTER_OUT,
        PATH_ID,
        PATH_INDEX,
        PATH_EAST_M,
        PATH_NORTH_M,
        CRC,
    ],
    integrity: Integrity::CounterCrc(COUNTER_OUT),
};
/// Input 0x202 from the planner: target speed and corridor at one point, in index order.
pub const PATH_LIMITS: MessageSpec = MessageSpec {
    name: "PATH_LIMITS",
    id: CanId::Standard(0x202),
    dlc: 8,
    cycle_ms: 0,
    transmitter: NODE_PLANNER,
    receivers: TO_NODE,
    signals: &[
        COUNTER_OUT,
        PATH_ID,
        PATH_INDEX,
        PATH_SPEED_MPS,
        PATH_LEFT_M,
        PATH_RIGHT_M,
        CRC,
    ],
    integrity: Integrity::CounterCrc(COUNTER_OUT),
};
/// Input 0x203 from the planner: one obstacle slot, set or cleared.
pub const OBSTACLE: MessageSpec = MessageSpec {
    name: "OBSTACLE",
    id: CanId::Standard(0x203),
    dlc: 8,
    cycle_ms: 0,
    transmitter: NODE_PLANNER,
    receivers: TO_NODE,
    signals: &[
        COUNTER_OUT,
        OBSTACLE_ID,
        OBSTACLE_ACTIVE,
        OBSTACLE_EAST_M,
        OBSTACLE_NORTH_M,
        OBSTACLE_RADIUS_M,
        CRC,
    ],
    integrity: Integrity::CounterCrc(COUNTER_OUT),
};
/// Input 0x204 from the planner: its map origin, latitude then longitude (two pages with
/// consecutive counters: 32-bit coordinates, counter and CRC do not fit one frame).
pub const LOCAL_ORIGIN: MessageSpec = MessageSpec {
    name: "LOCAL_ORIGIN",
    id: CanId::Standard(0x204),
    dlc: 8,
    cycle_ms: 0,
    transmitter: NODE_PLANNER,
    receivers: TO_NODE,
    signals: &[
        COUNTER_OUT,
        ORIGIN_PAGE,
        ORIGIN_LATITUDE_DEG,
        ORIGIN_LONGITUDE_DEG,
        CRC,
    ],
    integrity: Integrity::CounterCrc(COUNTER_OUT),
};
/// Output 0x300, every tick.
pub const STATE_POSITION: MessageSpec = MessageSpec {
    name: "STATE_POSITION",
    id: CanId::Standard(0x300),
    dlc: 8,
    cycle_ms: 20,
    transmitter: NODE_CATMODEL,
    receivers: TO_PLANNER,
    signals: &[
        COUNTER_OUT,
        POSITION_VALID,
        GNSS_FRESH,
        GNSS_REJECTED,
        EAST_M,
        NORTH_M,
        CRC,
    ],
    integrity: Integrity::CounterCrc(COUNTER_OUT),
};
/// Output 0x301, every tick.
pub const STATE_MOTION: MessageSpec = MessageSpec {
    name: "STATE_MOTION",
    id: CanId::Standard(0x301),
    dlc: 8,
    cycle_ms: 20,
    transmitter: NODE_CATMODEL,
    receivers: TO_PLANNER,
    signals: &[
        COUNTER_OUT,
        MODE,
        HEADING_UNCERTAIN,
        HEADING_RAD,
        STATE_SPEED_MPS,
        YAW_RATE_RADPS,
        CRC,
    ],
    integrity: Integrity::CounterCrc(COUNTER_OUT),
};
/// Number of prediction points (PREDICTION_1..PREDICTION_10, point k at k * 0.2 s).
pub const PREDICTION_POINTS: usize = 10;
/// Identifier of PREDICTION_1; PREDICTION_k is `PREDICTION_BASE_ID + k - 1`.
pub const PREDICTION_BASE_ID: u16 = 0x310;
/// Horizon step between prediction points, us (0.2 s).
pub const PREDICTION_STEP_US: u64 = 200_000;

const PREDICTION_SIGNALS: &[SignalSpec] =
    &[COUNTER_OUT, DX_M, DY_M, DHEADING_RAD, PRED_SPEED_MPS, CRC];

const fn prediction(name: &'static str, k: u16) -> MessageSpec {
    MessageSpec {
        name,
        id: CanId::Standard(PREDICTION_BASE_ID + k - 1),
        dlc: 8,
        cycle_ms: 20,
        transmitter: NODE_CATMODEL,
        receivers: TO_PLANNER,
        signals: PREDICTION_SIGNALS,
        integrity: Integrity::CounterCrc(COUNTER_OUT),
    }
}

/// Outputs 0x310..=0x319, every tick.
pub static PREDICTIONS: [MessageSpec; PREDICTION_POINTS] = [
    prediction("PREDICTION_1", 1),
    prediction("PREDICTION_2", 2),
    prediction("PREDICTION_3", 3),
    prediction("PREDICTION_4", 4),
    prediction("PREDICTION_5", 5),
    prediction("PREDICTION_6", 6),
    prediction("PREDICTION_7", 7),
    prediction("PREDICTION_8", 8),
    prediction("PREDICTION_9", 9),
    prediction("PREDICTION_10", 10),
];

/// Output 0x320, every tick: the controller's commands to the drive-by-wire kit.
pub const CONTROL_COMMAND: MessageSpec = MessageSpec {
    name: "CONTROL_COMMAND",
    id: CanId::Standard(0x320),
    dlc: 8,
    cycle_ms: 20,
    transmitter: NODE_CATMODEL,
    receivers: TO_DBW_AND_PLANNER,
    signals: &[
        COUNTER_OUT,
        COMMAND_STATUS,
        STEER_CMD_PCT,
        COMMAND_SPEED_MPS,
        FALLBACK_REASON,
        CRC,
    ],
    integrity: Integrity::CounterCrc(COUNTER_OUT),
};

/// Number of NODE_STATUS pages; page `tick % STATUS_PAGES` goes out each tick.
pub const STATUS_PAGES: u8 = 6;

/// Output 0x3F0, every tick, one multiplexed page per tick.
pub const NODE_STATUS: MessageSpec = MessageSpec {
    name: "NODE_STATUS",
    id: CanId::Standard(0x3F0),
    dlc: 8,
    cycle_ms: 20,
    transmitter: NODE_CATMODEL,
    receivers: TO_PLANNER,
    signals: &[
        COUNTER_OUT,
        PAGE,
        STATUS_MODE,
        STEER_STALE,
        SPEED_STALE,
        PEDAL_STALE,
        GNSS_STALE,
        GNSS_REJECTED_RECENTLY,
        POSITION_INVALID,
        PREDICTION_SATURATED,
        NONFINITE_GUARD,
        WATCHDOG_RESET,
        OVERRUN_RECENTLY,
        INPUT_INVALID,
        PLANNER_REFUSED_RECENTLY,
        GNSS_RATE_MISMATCH,
        STEERING_MISMATCH,
        OUTSIDE_CORRIDOR,
        OVERRUN_COUNT,
        LAST_STEP_US,
        CRC_ERRORS,
        COUNTER_ERRORS,
        DLC_ERRORS,
        RANGE_ERRORS,
        GNSS_GATE_REJECTS,
        UNKNOWN_IDS,
        TICK_COUNT,
        RX_QUEUE_DROPS,
        STEER_AGE,
        SPEED_AGE,
        PEDAL_AGE,
        GNSS_AGE,
        STACK_HIGH_WATER_BYTES,
        SPEED_MODEL_MPS,
        DXDT_MODEL_MPS,
        LAT_ACCEL_MPS2,
        CRC,
    ],
    integrity: Integrity::CounterCrc(COUNTER_OUT),
};

/// The node's inputs, in DBC order: the first messages of [`MESSAGES`].
pub const NODE_INPUTS: [&MessageSpec; 10] = [
    &STEERING_REPORT,
    &SPEED_REPORT,
    &PEDAL_REPORT,
    &GNSS_POSITION_RAPID,
    &GNSS_COG_SOG_RAPID,
    &PATH_HEADER,
    &PATH_POINT,
    &PATH_LIMITS,
    &OBSTACLE,
    &LOCAL_ORIGIN,
];

/// The node's outputs, in DBC order: the messages of [`MESSAGES`] after [`NODE_INPUTS`].
pub const NODE_OUTPUTS: [&MessageSpec; 14] = [
    &STATE_POSITION,
    &STATE_MOTION,
    &PREDICTIONS[0],
    &PREDICTIONS[1],
    &PREDICTIONS[2],
    &PREDICTIONS[3],
    &PREDICTIONS[4],
    &PREDICTIONS[5],
    &PREDICTIONS[6],
    &PREDICTIONS[7],
    &PREDICTIONS[8],
    &PREDICTIONS[9],
    &CONTROL_COMMAND,
    &NODE_STATUS,
];

/// Every message of `catmodel.dbc`, inputs first, in DBC order.
pub static MESSAGES: [&MessageSpec; 24] = {
    let [i0, i1, i2, i3, i4, i5, i6, i7, i8, i9] = NODE_INPUTS;
    let [o0, o1, o2, o3, o4, o5, o6, o7, o8, o9, o10, o11, o12, o13] = NODE_OUTPUTS;
    [
        i0, i1, i2, i3, i4, i5, i6, i7, i8, i9, o0, o1, o2, o3, o4, o5, o6, o7, o8, o9, o10, o11,
        o12, o13,
    ]
};

/// The index in [`NODE_INPUTS`] of the message a frame with `id` is to the node: standard
/// identifiers exactly, the GNSS PGNs from any source at any priority (the acceptance filter's
/// rule, [`is_node_input`]); `None` for a frame that is not one of its inputs.
pub fn node_input_index(id: CanId) -> Option<usize> {
    NODE_INPUTS.iter().position(|spec| match (spec.id, id) {
        (CanId::Standard(_), CanId::Standard(_)) => spec.id == id,
        (CanId::Extended(ours), CanId::Extended(raw)) => {
            ours & N2K_PGN_FIELD_MASK == raw & N2K_PGN_FIELD_MASK
        }
        _ => false,
    })
}

/// Worst-case length in bits of a classic CAN data frame with `dlc` data bytes, bit stuffing
/// included (Davis et al. 2007: `8s + g + 13 + floor((g + 8s - 1) / 4)`, g = 34 for 11-bit and
/// 54 for 29-bit identifiers; interframe space included).
pub const fn worst_case_frame_bits(extended: bool, dlc: u8) -> u32 {
    let g: u32 = if extended { 54 } else { 34 };
    let s = dlc as u32 * 8;
    s + g + 13 + (g + s - 1) / 4
}

/// Frame length without stuff bits (SOF to the end of the interframe space).
pub const fn nominal_frame_bits(extended: bool, dlc: u8) -> u32 {
    let g: u32 = if extended { 54 } else { 34 };
    dlc as u32 * 8 + g + 13
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_input_index_agrees_with_the_acceptance_filter() {
        // Every input by its own identifier; the GNSS PGNs from another source and priority
        // (the filter's rule); outputs and strangers are no input.
        for (i, spec) in NODE_INPUTS.iter().enumerate() {
            assert_eq!(node_input_index(spec.id), Some(i), "{}", spec.name);
            assert!(is_node_input(spec.id), "{}", spec.name);
        }
        let other_source = CanId::Extended(n2k_id(6, PGN_COG_SOG_RAPID, 0x42));
        assert_eq!(node_input_index(other_source), Some(4));
        assert!(is_node_input(other_source));
        for spec in NODE_OUTPUTS {
            assert_eq!(node_input_index(spec.id), None, "{}", spec.name);
            assert!(!is_node_input(spec.id), "{}", spec.name);
        }
        for id in [
            CanId::Standard(0x7FF),
            CanId::Extended(0x100),
            CanId::Extended(0x1234_5678),
        ] {
            assert_eq!(node_input_index(id), None);
            assert!(!is_node_input(id));
        }
        assert_eq!(MESSAGES.len(), NODE_INPUTS.len() + NODE_OUTPUTS.len());
    }

    /// Independent references: the packer bit by bit over the payload's bytes (Intel order:
    /// bit `b` is bit `b % 8` of byte `b / 8`), the rounding in f64 (`f64::round`, halves away
    /// from zero, of the same f32 quotient) with the limits compared as integers.
    mod reference {
        use super::SignalSpec;

        fn bit(data: &[u8; 8], b: u32) -> u64 {
            u64::from((data[(b / 8) as usize] >> (b % 8)) & 1)
        }

        pub fn read_raw(s: &SignalSpec, data: &[u8; 8]) -> i64 {
            let len = u32::from(s.len_bits);
            let start = u32::from(s.start_bit);
            let mut value = 0i64;
            for i in 0..len {
                if start + i < 64 {
                    value |= (bit(data, start + i) as i64) << i;
                }
            }
            // Two's complement: the top bit weighs -2^(len - 1).
            if s.signed && len > 0 && value >> (len - 1) & 1 == 1 {
                value -= 1i64 << len;
            }
            value
        }

        pub fn write_raw(s: &SignalSpec, data: &mut [u8; 8], raw: i64) {
            let start = u32::from(s.start_bit);
            for i in 0..u32::from(s.len_bits) {
                let b = start + i;
                if b < 64 {
                    let byte = &mut data[(b / 8) as usize];
                    *byte &= !(1 << (b % 8));
                    *byte |= (((raw >> i) & 1) as u8) << (b % 8);
                }
            }
        }

        pub fn to_raw(s: &SignalSpec, physical: f32) -> Option<i64> {
            let rounded = f64::from((physical - s.offset) / s.scale).round();
            // NaN and infinities fail; `as i64` saturates beyond any limit of the table.
            (rounded.is_finite() && (s.raw_min..=s.raw_max).contains(&(rounded as i64)))
                .then_some(rounded as i64)
        }
    }

    /// Every signal of the table, the counters and the CRC.
    fn signals() -> impl Iterator<Item = &'static SignalSpec> {
        MESSAGES.iter().flat_map(|m| m.signals.iter()).chain([
            &sig::COUNTER_IN,
            &sig::COUNTER_OUT,
            &sig::CRC,
        ])
    }

    /// A small deterministic generator (xorshift64*), so that the sweep is the same every run.
    fn next(state: &mut u64) -> u64 {
        *state ^= *state >> 12;
        *state ^= *state << 25;
        *state ^= *state >> 27;
        state.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// The physical values a signal's rounding can go wrong at: its raw limits, one and a half
    /// and a half raw step either side of them and of zero, the f32 neighbours of each, and
    /// the values that are not numbers.
    fn edge_values(s: &SignalSpec) -> Vec<f32> {
        let mut raws: Vec<f64> = Vec::new();
        for base in [s.raw_min as f64, s.raw_max as f64, 0.0, 1.0, -1.0] {
            for d in [-1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5] {
                raws.push(base + d);
            }
        }
        let mut values = vec![f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 0.0, -0.0];
        for raw in raws {
            let v = (raw * f64::from(s.scale) + f64::from(s.offset)) as f32;
            let mut lower = v;
            let mut upper = v;
            for _ in 0..3 {
                lower = f32::from_bits(if lower > 0.0 {
                    lower.to_bits() - 1
                } else {
                    lower.to_bits() + 1
                });
                upper = f32::from_bits(if upper >= 0.0 {
                    upper.to_bits() + 1
                } else {
                    upper.to_bits() - 1
                });
                values.extend([lower, upper]);
            }
            values.push(v);
        }
        values
    }

    #[test]
    fn to_raw_matches_rounding_half_away_from_zero_at_every_edge() {
        for s in signals() {
            for v in edge_values(s) {
                assert_eq!(s.to_raw(v), reference::to_raw(s, v), "{} at {v:e}", s.name);
            }
        }
    }

    #[test]
    fn to_raw_matches_the_reference_over_random_bit_patterns_and_halves() {
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        for s in signals() {
            for _ in 0..20_000 {
                // Any f32 at all, and values near the signal's range: halves of a raw step,
                // where rounding ties.
                let any = f32::from_bits(next(&mut state) as u32);
                let span = (s.raw_max - s.raw_min) as f64 * 1.2;
                let r = (next(&mut state) >> 11) as f64 / (1u64 << 53) as f64;
                let raw = (s.raw_min as f64 - 0.1 * span + r * span).round() + 0.5;
                let half = (raw * f64::from(s.scale) + f64::from(s.offset)) as f32;
                for v in [any, half] {
                    assert_eq!(s.to_raw(v), reference::to_raw(s, v), "{} at {v:e}", s.name);
                }
            }
        }
    }

    #[test]
    fn to_raw_rounds_halves_away_from_zero() {
        let s = SignalSpec::int("t", 0, 16);
        for (v, raw) in [
            (2.5, 3),
            (-2.5, -3),
            (0.5, 1),
            (-0.5, -1),
            (0.49999997, 0),
            (1.4999999, 1),
        ] {
            assert_eq!(s.to_raw(v), Some(raw), "{v}");
        }
        assert_eq!(s.to_raw(32_767.4), Some(32_767));
        assert_eq!(s.to_raw(32_767.5), None);
        assert_eq!(s.to_raw(-32_768.5), None);
        assert_eq!(s.to_raw(f32::NAN), None);
        assert_eq!(s.to_raw(3.0e9), None);
    }

    #[test]
    fn packing_matches_the_64_bit_reference_for_every_place_and_width() {
        let mut state = 0x0123_4567_89AB_CDEFu64;
        for start in 0..64u8 {
            for len in 1..=32u8.min(64 - start) {
                for signed in [false, true] {
                    let s = SignalSpec {
                        signed,
                        ..SignalSpec::uint("t", start, len)
                    };
                    for _ in 0..8 {
                        let data = next(&mut state).to_le_bytes();
                        let raw = next(&mut state) as i64;
                        assert_eq!(s.read_raw(&data), reference::read_raw(&s, &data));
                        let (mut fast, mut slow) = (data, data);
                        s.write_raw(&mut fast, raw);
                        reference::write_raw(&s, &mut slow, raw);
                        assert_eq!(fast, slow, "bit {start}, {len} bits, raw {raw:#x}");
                    }
                }
            }
        }
    }
}
