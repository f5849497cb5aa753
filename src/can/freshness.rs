//! Freshness of the node's inputs (PX4 style: every input carries its timestamp and
//! `is_timed_out(now, last, timeout)` decides). Timeouts are configuration; the last-receive
//! times are state. Time is always an argument (u64 us on the input's time base), never read.

/// The inputs whose freshness the node tracks, in NODE_STATUS page 4 order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Input {
    /// STEERING_REPORT.
    Steer,
    /// SPEED_REPORT.
    Speed,
    /// PEDAL_REPORT.
    Pedal,
    /// GNSS position (PGN 129025) accepted by the node's gate.
    Gnss,
}

/// Number of [`Input`]s.
pub const INPUT_COUNT: usize = 4;

impl Input {
    /// All inputs, in NODE_STATUS page 4 order.
    pub const ALL: [Input; INPUT_COUNT] = [Input::Steer, Input::Speed, Input::Pedal, Input::Gnss];

    /// Index into per-input arrays.
    pub const fn index(self) -> usize {
        match self {
            Input::Steer => 0,
            Input::Speed => 1,
            Input::Pedal => 2,
            Input::Gnss => 3,
        }
    }
}

/// Age value meaning "never received" on NODE_STATUS page 4.
pub const AGE_NEVER: u8 = 255;
/// Largest age NODE_STATUS page 4 can carry, 10 ms units (2.54 s and older).
pub const AGE_MAX: u8 = 254;

/// Whether more than `timeout_us` has passed since `last_us`. A `last_us` in the future (clock
/// reordering) is not timed out. Exactly `timeout_us` old is still fresh.
pub const fn is_timed_out(now_us: u64, last_us: u64, timeout_us: u64) -> bool {
    now_us.saturating_sub(last_us) > timeout_us
}

/// Whether `last_us` lies within `window_us` before `now_us` (the complement of
/// [`is_timed_out`]).
pub const fn is_recent(now_us: u64, last_us: u64, window_us: u64) -> bool {
    !is_timed_out(now_us, last_us, window_us)
}

/// Age for NODE_STATUS: `now - last` in 10 ms units, rounded down, saturating at [`AGE_MAX`];
/// [`AGE_NEVER`] when never received.
pub const fn age_10ms(now_us: u64, last_us: Option<u64>) -> u8 {
    match last_us {
        None => AGE_NEVER,
        Some(last) => {
            // Divided in u32 below 2.54 s: one UDIV on the Cortex-M4 instead of a 64-bit
            // division call; the same value as `(age / 10_000).min(AGE_MAX)`.
            let age_us = now_us.saturating_sub(last);
            if age_us < 2_540_000 {
                (age_us as u32 / 10_000) as u8
            } else {
                AGE_MAX
            }
        }
    }
}

/// Timeouts per input (configuration).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FreshnessConfig {
    /// Timeout of each input, us, indexed by [`Input::index`].
    pub timeout_us: [u64; INPUT_COUNT],
}

impl FreshnessConfig {
    /// 100 ms (5 periods) for the 50 Hz reports, as the Dataspeed kit times out its commands;
    /// 200 ms (2 periods of a 10 Hz receiver) for GNSS.
    pub const DEFAULT: Self = Self {
        timeout_us: [100_000, 100_000, 100_000, 200_000],
    };

    /// The timeout of `input`, us.
    pub const fn timeout_us(&self, input: Input) -> u64 {
        match input {
            Input::Steer => self.timeout_us[0],
            Input::Speed => self.timeout_us[1],
            Input::Pedal => self.timeout_us[2],
            Input::Gnss => self.timeout_us[3],
        }
    }
}

impl Default for FreshnessConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Last receive time of each input (state).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Freshness {
    last_us: [Option<u64>; INPUT_COUNT],
}

impl Freshness {
    /// Nothing received yet.
    pub const fn new() -> Self {
        Self {
            last_us: [None; INPUT_COUNT],
        }
    }

    /// Records a valid, accepted sample of `input` received at `t_us` (an older time than the
    /// one held is ignored).
    pub fn mark(&mut self, input: Input, t_us: u64) {
        if let Some(slot) = self.last_us.get_mut(input.index()) {
            *slot = Some(slot.map_or(t_us, |last| last.max(t_us)));
        }
    }

    /// Last receive time of `input`, us.
    pub fn last_us(&self, input: Input) -> Option<u64> {
        self.last_us.get(input.index()).copied().flatten()
    }

    /// Received, and not timed out at `now_us`.
    pub fn is_fresh(&self, config: &FreshnessConfig, input: Input, now_us: u64) -> bool {
        self.last_us(input)
            .is_some_and(|last| !is_timed_out(now_us, last, config.timeout_us(input)))
    }

    /// Age of `input` for NODE_STATUS page 4 (see [`age_10ms`]).
    pub fn age_10ms(&self, input: Input, now_us: u64) -> u8 {
        age_10ms(now_us, self.last_us(input))
    }

    /// Ages of all inputs in [`Input::ALL`] order, ready for `NodeStatus::Ages`.
    pub fn ages_10ms(&self, now_us: u64) -> [u8; INPUT_COUNT] {
        Input::ALL.map(|input| self.age_10ms(input, now_us))
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn age_divided_in_u32_equals_the_u64_formula_across_the_saturation_point() {
        let reference = |d: u64| (d / 10_000).min(u64::from(super::AGE_MAX)) as u8;
        let huge = [u64::MAX, 1 << 32, (1 << 32) + 5];
        for d in (0..3_000_000u64)
            .step_by(7)
            .chain(2_539_990..2_540_010)
            .chain(huge)
        {
            assert_eq!(super::age_10ms(d, Some(0)), reference(d), "{d}");
        }
        assert_eq!(super::age_10ms(5, Some(10)), 0);
        assert_eq!(super::age_10ms(5, None), super::AGE_NEVER);
    }
}
