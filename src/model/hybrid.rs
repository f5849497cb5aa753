//! Hybrid switching between the kinematic and the dynamic lateral model (paper I-B and [18]:
//! kinematic models are accurate at low speed and low lateral acceleration, where tyre slip is
//! negligible; dynamic models above, where the kinematic model's 1/vx-free geometry overstates
//! the yaw rate).
//!
//! Hysteresis plus a minimum dwell make it impossible to chatter: the mode changes at most once
//! per `min_dwell_ticks`, whatever the inputs (proved by a property test).
use crate::image::{Image, ImageError, ImageReader, ImageWriter};

/// The lateral model in use.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Mode {
    /// Eq 8.
    #[default]
    Kinematic,
    /// The linear-tyre single-track model.
    Dynamic,
}

/// Switching thresholds. Immutable configuration; `enter_*` > `exit_*` is the hysteresis.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct HybridConfig {
    /// Kinematic -> dynamic when the speed exceeds this, m/s.
    pub enter_dynamic_speed_mps: f32,
    /// ... or when |lateral acceleration| reaches this, m/s^2.
    pub enter_dynamic_lat_accel_mps2: f32,
    /// Dynamic -> kinematic only when the speed is below this ...
    pub exit_dynamic_speed_mps: f32,
    /// ... and |lateral acceleration| below this, m/s^2.
    pub exit_dynamic_lat_accel_mps2: f32,
    /// Ticks a mode is kept at least, once entered.
    pub min_dwell_ticks: u16,
}

/// A hybrid configuration as a test reference (the node's comes from the model file): kinematic
/// below ~4 m/s and low lateral acceleration, dynamic above 6 m/s or |a_y| >= 2 m/s^2; a mode is
/// kept for at least 0.5 s (25 ticks of 20 ms).
#[cfg(test)]
pub(crate) const DEFAULT_HYBRID: HybridConfig = HybridConfig {
    enter_dynamic_speed_mps: 6.0,
    enter_dynamic_lat_accel_mps2: 2.0,
    exit_dynamic_speed_mps: 4.0,
    exit_dynamic_lat_accel_mps2: 1.5,
    min_dwell_ticks: 25,
};

impl Image for HybridConfig {
    fn write(&self, w: &mut ImageWriter<'_>) {
        let Self {
            enter_dynamic_speed_mps,
            enter_dynamic_lat_accel_mps2,
            exit_dynamic_speed_mps,
            exit_dynamic_lat_accel_mps2,
            min_dwell_ticks,
        } = self;
        for v in [
            enter_dynamic_speed_mps,
            enter_dynamic_lat_accel_mps2,
            exit_dynamic_speed_mps,
            exit_dynamic_lat_accel_mps2,
        ] {
            v.write(w);
        }
        min_dwell_ticks.write(w);
    }
    fn read(r: &mut ImageReader<'_>) -> Result<Self, ImageError> {
        Ok(Self {
            enter_dynamic_speed_mps: f32::read(r)?,
            enter_dynamic_lat_accel_mps2: f32::read(r)?,
            exit_dynamic_speed_mps: f32::read(r)?,
            exit_dynamic_lat_accel_mps2: f32::read(r)?,
            min_dwell_ticks: u16::read(r)?,
        })
    }
}

/// Switch state.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct HybridState {
    /// The current mode.
    pub mode: Mode,
    /// Ticks spent in the current mode (saturating).
    pub ticks_in_mode: u16,
    /// Mode changes since start (saturating).
    pub switches: u32,
}

impl HybridConfig {
    /// Advances the switch by one tick with the current speed and lateral acceleration and
    /// returns the mode to use for this tick. Non-finite inputs never cause a switch.
    pub fn update(&self, state: &mut HybridState, speed_mps: f32, lat_accel_mps2: f32) -> Mode {
        state.ticks_in_mode = state.ticks_in_mode.saturating_add(1);
        if !speed_mps.is_finite() || !lat_accel_mps2.is_finite() {
            return state.mode;
        }
        if state.ticks_in_mode < self.min_dwell_ticks {
            return state.mode;
        }
        let ay = lat_accel_mps2.abs();
        let next = match state.mode {
            Mode::Kinematic
                if speed_mps > self.enter_dynamic_speed_mps
                    || ay >= self.enter_dynamic_lat_accel_mps2 =>
            {
                Mode::Dynamic
            }
            Mode::Dynamic
                if speed_mps < self.exit_dynamic_speed_mps
                    && ay < self.exit_dynamic_lat_accel_mps2 =>
            {
                Mode::Kinematic
            }
            mode => mode,
        };
        if next != state.mode {
            state.mode = next;
            state.ticks_in_mode = 0;
            state.switches = state.switches.saturating_add(1);
        }
        state.mode
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hysteresis_band_keeps_the_mode() {
        let c = DEFAULT_HYBRID;
        let mut s = HybridState::default();
        for _ in 0..100 {
            c.update(&mut s, 5.0, 0.0);
        }
        assert_eq!(s.mode, Mode::Kinematic);
        for _ in 0..100 {
            c.update(&mut s, 7.0, 0.0);
        }
        assert_eq!(s.mode, Mode::Dynamic);
        for _ in 0..100 {
            c.update(&mut s, 5.0, 0.0);
        }
        assert_eq!(
            s.mode,
            Mode::Dynamic,
            "5 m/s is inside the band: stays dynamic"
        );
        for _ in 0..100 {
            c.update(&mut s, 3.0, 1.9);
        }
        assert_eq!(s.mode, Mode::Dynamic, "a_y 1.9 is above the exit threshold");
        for _ in 0..100 {
            c.update(&mut s, 3.0, 0.5);
        }
        assert_eq!(s.mode, Mode::Kinematic);
        assert_eq!(s.switches, 2);
    }

    #[test]
    fn lateral_acceleration_alone_enters_dynamic() {
        let c = DEFAULT_HYBRID;
        let mut s = HybridState::default();
        for _ in 0..30 {
            c.update(&mut s, 3.0, -2.5);
        }
        assert_eq!(s.mode, Mode::Dynamic);
    }
}
