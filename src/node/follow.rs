//! Whether the steering report follows the node's own steering commands, or runs against them.
//!
//! While a controller drives, the drive-by-wire turns the wheels towards the node's command,
//! and its STEERING_REPORT follows with the actuator's lag. A report with the other sign than
//! the interface documents (positive to the left: a wiring or convention fault of the DBW)
//! runs against the commands instead: the controllers then see their steering go the wrong
//! way, steer harder, and the car left the loop's path by 3.6 m within 11 s (docs/findings.md).
//! The node's steering check ([`super::steering`]) finds such a car against GNSS, but only
//! after seconds of turning at speed; the commands tell it in under a second.
//!
//! The check: over the ticks that follow a controller's command (status tracking or avoiding),
//! the uncentred correlation of the command sent last tick with the steering reported now,
//! with exponential forgetting ([`FORGET_S`]): `sum(c r) / sqrt(sum(c^2) sum(r^2))`, both in
//! percent of the lock. A following actuator gives nearly +1 (its lag lowers it a little: a
//! sine of 1 Hz behind a 0.1 s lag still gives +0.8); a human steering while the node commands
//! (the DBW not engaged) steers the same path, the same way. Once the commands have swung by
//! at least [`MIN_COMMAND_RMS_PCT`] RMS over [`MIN_TICKS`] ticks and the correlation is below
//! [`REVERSED_CORRELATION`], the report is taken as reversed, latched until the node restarts:
//! a wiring fault does not mend itself while the car drives, and a controller that retried would
//! steer the wrong way again for as long as the check takes.

use crate::can::codec::{ControlCommand, ControlStatus};
use crate::math;
use crate::SAMPLE_PERIOD_S;

/// Time constant of the forgetting, s: about a manoeuvre's swing of the steering.
pub const FORGET_S: f32 = 1.0;
/// The commands' RMS over the forgetting window the check needs before it judges, % of lock:
/// a lane change at 10 m/s asks for 5-10 %; on a straight the commands stay within the
/// steering's noise and say nothing.
pub const MIN_COMMAND_RMS_PCT: f32 = 3.0;
/// Ticks (forgetting counted) the check needs before it judges: 0.5 s.
pub const MIN_TICKS: f32 = 25.0;
/// The correlation below which the report runs against the commands.
pub const REVERSED_CORRELATION: f32 = -0.5;

/// The check's state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SteerFollow {
    /// Forgetting sums: command^2, report^2, command * report (%^2), and the ticks.
    scc: f32,
    srr: f32,
    scr: f32,
    ticks: f32,
    /// The report ran against the commands (latched).
    reversed: bool,
}

impl Default for SteerFollow {
    fn default() -> Self {
        Self::new()
    }
}

impl SteerFollow {
    /// Nothing observed.
    pub const fn new() -> Self {
        Self {
            scc: 0.0,
            srr: 0.0,
            scr: 0.0,
            ticks: 0.0,
            reversed: false,
        }
    }

    /// Whether the steering report has run against the node's commands.
    pub fn reversed(&self) -> bool {
        self.reversed
    }

    /// One tick: `last` is the command sent last tick, `reported_pct` the steering reported
    /// now (% of lock; `None` when invalid or stale). Only a controller's commands count (not
    /// a hold, a fallback's or no path's).
    pub fn observe(&mut self, last: &ControlCommand, reported_pct: Option<f32>) {
        let keep = 1.0 - SAMPLE_PERIOD_S / FORGET_S;
        let driving = matches!(
            last.status,
            ControlStatus::Tracking | ControlStatus::Avoiding
        );
        let (true, Some(c), Some(r)) = (driving, last.steer_cmd_pct, reported_pct) else {
            return;
        };
        if !(c.is_finite() && r.is_finite()) {
            return;
        }
        self.scc = keep * self.scc + c * c;
        self.srr = keep * self.srr + r * r;
        self.scr = keep * self.scr + c * r;
        self.ticks = keep * self.ticks + 1.0;
        let swung = self.ticks >= MIN_TICKS
            && self.scc >= MIN_COMMAND_RMS_PCT * MIN_COMMAND_RMS_PCT * self.ticks;
        // scr / sqrt(scc srr) < REVERSED_CORRELATION, without the root or a division by 0.
        let against = self.scr < 0.0
            && self.scr * self.scr
                > REVERSED_CORRELATION * REVERSED_CORRELATION * self.scc * self.srr;
        if swung && against {
            self.reversed = true;
        }
    }

    /// The correlation over the window (0 before any tick).
    pub fn correlation(&self) -> f32 {
        let d = math::sqrt(self.scc * self.srr);
        if d > 0.0 {
            self.scr / d
        } else {
            0.0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::codec::FallbackCause;

    fn command(status: ControlStatus, pct: f32) -> ControlCommand {
        ControlCommand {
            status,
            fallback: FallbackCause::None,
            steer_cmd_pct: Some(pct),
            speed_cmd_mps: Some(10.0),
        }
    }

    /// A sine of `amplitude` % and `hz`, the actuator following it `lag_ticks` late with
    /// `sign`, for `seconds`.
    fn run(
        check: &mut SteerFollow,
        amplitude: f32,
        hz: f32,
        lag_ticks: usize,
        sign: f32,
        seconds: f32,
    ) {
        let n = (seconds / SAMPLE_PERIOD_S) as usize;
        let c = |k: usize| {
            amplitude * libm::sinf(2.0 * core::f32::consts::PI * hz * k as f32 * SAMPLE_PERIOD_S)
        };
        for k in 1..n {
            let last = command(ControlStatus::Tracking, c(k - 1));
            let r = sign * c(k.saturating_sub(1 + lag_ticks));
            check.observe(&last, Some(r));
        }
    }

    #[test]
    fn a_following_actuator_is_not_reversed_even_when_late() {
        let mut check = SteerFollow::new();
        // 1 Hz swings of 10 % behind a 0.1 s lag: +0.8.
        run(&mut check, 10.0, 1.0, 5, 1.0, 10.0);
        assert!(!check.reversed());
        assert!(check.correlation() > 0.75, "{}", check.correlation());
    }

    #[test]
    fn a_report_with_the_other_sign_is_found_within_a_second() {
        let mut check = SteerFollow::new();
        run(&mut check, 10.0, 0.5, 3, -1.0, 1.0);
        assert!(check.reversed(), "{check:?}");
    }

    #[test]
    fn straight_driving_and_holds_say_nothing() {
        let mut check = SteerFollow::new();
        // Commands within the noise, reported against them: below the swing needed.
        run(&mut check, 1.0, 2.0, 0, -1.0, 10.0);
        assert!(!check.reversed());
        // A fallback's commands do not count, whatever the report.
        for _ in 0..500 {
            check.observe(&command(ControlStatus::Fallback, 20.0), Some(-20.0));
        }
        assert!(!check.reversed());
    }
}
