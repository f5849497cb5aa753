//! The position the controllers follow: the estimate, with the jumps a slow, noisy receiver's
//! fixes put into it spread out by as much as the receiver's measured noise calls for.
//!
//! Between fixes the estimate moves with the dead reckoning; at a fix it jumps by the new
//! fix's noise and by the dead reckoning's drift since the last one. With a survey-grade
//! receiver the jumps are centimetres, mostly drift, and must be followed at once; with an
//! uncorrected receiver at 5 Hz they are half a metre to a metre (the filter's window holds
//! three fixes), and a controller steering at each step drives a car with slow steering into a
//! growing oscillation (docs/controller.md, "Slow receivers"). Which of the two a receiver is,
//! the node learns on line: the control pose tracks the mean square of the estimate's jumps
//! against the dead reckoning over the lowpass's window ([`JUMP_WINDOW_S`] of them), and
//! weighs them as a steady-state Kalman filter weighs a measurement of that noise against the
//! dead reckoning's drift over a window:
//! - the window is the lowpass's (its taps and span: 30 fixes at 100 Hz; three fixes, 0.6 s,
//!   at 5 Hz; one fix at 1 Hz), counted in ticks, one per fix at most (a 100 Hz receiver's
//!   30 fixes: 30 ticks, 0.6 s): within it the filtered fixes share their noise, so from one
//!   fix to the next a fast receiver's estimate moves by millimetres whatever its noise, and
//!   measured per fix a standard receiver at 100 Hz looked survey-grade (docs/findings.md);
//! - the dead reckoning drifts as it moves: over a window of `d` metres a heading error of
//!   `sigma` radians puts it `sigma d` across the track and a wheel-speed scale error
//!   [`SPEED_SCALE_ERROR`] puts it that share of `d` along it, so the process noise per window
//!   is `q = (heading variance + SPEED_SCALE_ERROR^2) d^2 + DRIFT_FLOOR_M2_PER_S x window`,
//!   with the heading's variance as the estimator's heading filter reckons it and a floor
//!   that does not move with the car (a survey-grade receiver at a stop is followed as it is);
//! - the heading's variance is a design figure of the heading filter, set for a standard
//!   receiver's chords; where the dead reckoning drifts less the drift is measured as well:
//!   over [`DRIFT_LAG_WINDOWS`] windows the noise's part of the jump is the same `2 r` as over
//!   one, the drift's grows (`n` times over `n` windows for a random walk, `n^2` times for a
//!   steady drift), so `(long_ms - short_ms) / (n - 1)` bounds the drift per window from
//!   above; averaged over [`DRIFT_AVERAGE_S`] and taken with two standard errors of that
//!   average added (a slow receiver's few windows say little, and its bound stays the
//!   distance's). The lesser of the two bounds is the process noise, never below the floor;
//! - a window's jump is the difference of two estimates' errors and the drift between them,
//!   mean square `2 r + q`: measurement noise `r = (jump_ms - q_ms) / 2`, with `q_ms` the
//!   drift allowed for over the same windows (each from the distance its dead reckoning moved
//!   and the heading's variance then, at most the measured bound), averaged as the jumps are;
//! - the correction per window `K = P / (P + r)` with `P = (q + sqrt(q^2 + 4 q r)) / 2` (the
//!   scalar Riccati equation's fixed point, `q` the lesser bound, the distance's at this
//!   tick's speed): 1 for a receiver whose jumps are no larger than the drift (RTK: the
//!   estimate as it is), about `sqrt(q / r)` for a noisy one, so a noisy receiver is smoothed
//!   most where the car moves least and the dead reckoning drifts least;
//! - spread over the window's ticks as a complementary filter: the smoothed antenna moves
//!   with the dead reckoning and is pulled towards the estimate by `g` per tick, with
//!   `(1 - g)^ticks = 1 - K` (`g = -ln(1 - K) / ticks`, at most 1). The lowpass acts only on
//!   the estimate's difference from the dead reckoning, so the car's own motion passes
//!   without lag.
//!
//! The controllers (and so this) start only once the heading has settled
//! ([`HeadingSettle`]: the first heading, from a short chord
//! of a slow receiver's fixes, can be tenths of a radian out, and the dead reckoning would carry
//! it into the position). A difference beyond [`SNAP_M`] (a restarted estimate, a moved
//! origin) is taken at once.
use crate::math;
use crate::model::kinematic::Pose;

use super::estimator::{EstimatorConfig, Xy};

/// The most the dead reckoning is allowed to drift, as a random walk, m^2/s: the process
/// noise per window is at most this times the lowpass's window (0.03 m^2 over a 5 Hz
/// receiver's 0.6 s), whatever the distance driven. Tuned on slow receivers at speed
/// (docs/controller.md, "Slow receivers"); the distance's bound below is the lesser where the
/// car moves slowly.
pub const DRIFT_DIFFUSION_M2_PER_S: f32 = 0.05;

/// The dead reckoning's drift that does not come with the distance it moves, as a random
/// walk, m^2/s: the process noise per window when the car stands (0.003 m^2 over a 100 Hz
/// receiver's 0.6 s window, a 0.055 m jump: a survey-grade receiver's are millimetres to
/// centimetres and pass as they are). docs/controller.md, "Slow receivers", for the settings.
pub const DRIFT_FLOOR_M2_PER_S: f32 = 0.005;

/// The wheel speed's scale error the dead reckoning is allowed: its drift along the track per
/// metre driven (a tyre's rolling radius varies by about 2 % with its wear, pressure and load).
pub const SPEED_SCALE_ERROR: f32 = 0.02;

/// The jumps' mean square is averaged over about this long, s (a running mean until then).
pub const JUMP_WINDOW_S: f32 = 5.0;

/// The longer lag the drift is measured over, windows (2.4 s at 100 Hz, 4 s at 1 Hz).
pub const DRIFT_LAG_WINDOWS: usize = 4;

/// The jumps over one window and over [`DRIFT_LAG_WINDOWS`] are averaged over about this long
/// for the drift's measurement, s: longer than the noise's, as a difference of two means
/// scatters more than either.
pub const DRIFT_AVERAGE_S: f32 = 20.0;

/// A difference between the estimate and the smoothed position beyond this is taken at once,
/// m; a jump beyond it is not noise and stays out of the mean square.
pub const SNAP_M: f32 = 3.0;

/// The control pose's state ([`Smoothing::control_pose`]).
#[derive(Clone, Copy, Debug)]
pub struct Smoothing {
    /// The smoothed antenna and the dead reckoning it was last moved with.
    last: Option<(Xy, Xy)>,
    /// The estimate's antenna less the dead reckoning, and the dead reckoning, at the start of
    /// this window.
    window_start: Option<(Xy, Xy)>,
    /// Ticks since the window started.
    window_ticks: u32,
    /// Mean square of the estimate's jumps against the dead reckoning per window, m^2.
    jump_ms: f32,
    /// The drift allowed for over the same windows, averaged as the jumps are, m^2.
    drift_ms: f32,
    /// Windows in the mean square (saturating at [`JUMP_WINDOW_S`]'s).
    windows: u32,
    /// Ticks per window: the lowpass's window, at least one tick.
    window_len_ticks: u32,
    /// Process noise per window at this tick's speed, from the distance, m^2.
    drift_var: f32,
    /// The estimate's antenna less the dead reckoning at the last [`DRIFT_LAG_WINDOWS`]
    /// windows' ends (ring, newest at `ends_head`).
    ends: [Xy; DRIFT_LAG_WINDOWS],
    ends_head: usize,
    /// Windows' ends in `ends` in a row (since the last [`Self::forget`]).
    ends_len: u32,
    /// Mean square of the jumps over [`DRIFT_LAG_WINDOWS`] windows, m^2.
    long_ms: f32,
    /// Mean square of the jumps over one window, averaged as `long_ms`, m^2.
    short_ms: f32,
}

impl Smoothing {
    /// No receiver known: the estimate as it is. `const`: the drive stage is built at compile
    /// time.
    pub const fn new() -> Self {
        Self {
            last: None,
            window_start: None,
            window_ticks: 0,
            jump_ms: 0.0,
            drift_ms: 0.0,
            windows: 0,
            window_len_ticks: 1,
            drift_var: 0.0,
            ends: [Xy { x_m: 0.0, y_m: 0.0 }; DRIFT_LAG_WINDOWS],
            ends_head: 0,
            ends_len: 0,
            long_ms: 0.0,
            short_ms: 0.0,
        }
    }

    /// For the receiver of `cfg`; nothing measured yet. The jumps are measured over the
    /// lowpass's window (its taps and span, `2 x group delay + 1` fixes): within it the
    /// filtered fixes share their noise, and what they jump by from one fix to the next is
    /// the noise divided by the window's length (a 100 Hz receiver's 30 fixes; docs/findings.md).
    pub fn for_estimator(cfg: &EstimatorConfig) -> Self {
        let tick_s = crate::SAMPLE_PERIOD_S;
        let period_s = if cfg.gnss_period_s.is_finite() {
            math::max(cfg.gnss_period_s, tick_s)
        } else {
            tick_s
        };
        let window_fixes = if cfg.group_delay_fixes.is_finite() {
            math::max(2.0 * cfg.group_delay_fixes + 1.0, 1.0)
        } else {
            1.0
        };
        // At most a minute of ticks: any real receiver's window is seconds.
        let ticks = math::clamp(libm::roundf(window_fixes * period_s / tick_s), 1.0, 3000.0);
        let window_len_ticks = ticks as u32;
        Self {
            window_len_ticks,
            drift_var: drift_var_m2(window_len_ticks, 0.0, 0.0),
            ..Self::new()
        }
    }

    /// Forgets the smoothed position (no pose, no path: nobody follows it): the next pose is
    /// taken as it is. The jumps' statistics (the receiver's) are kept; the windows' ends are
    /// not (a lag across the gap would not be one).
    pub fn forget(&mut self) {
        self.last = None;
        self.window_start = None;
        self.window_ticks = 0;
        self.ends_len = 0;
    }

    /// The drift per window measured from the jumps over one window and over
    /// [`DRIFT_LAG_WINDOWS`], an upper bound, m^2: the growth of the jumps' mean square with
    /// the lag, as a random walk's (a steady drift grows faster and is overestimated), plus
    /// two standard errors of the average; `None` until a long lag has been seen.
    fn measured_drift(&self) -> Option<f32> {
        if (self.ends_len as usize) < DRIFT_LAG_WINDOWS {
            return None;
        }
        let lags = (DRIFT_LAG_WINDOWS - 1) as f32;
        let n = math::max(math::min(self.windows as f32, self.drift_windows()), 1.0);
        let growth = math::max(self.long_ms - self.short_ms, 0.0) / lags;
        Some(growth + 2.0 * math::sqrt(2.0 / n) * self.long_ms / lags)
    }

    /// Windows in [`DRIFT_AVERAGE_S`], at least one.
    fn drift_windows(&self) -> f32 {
        math::max(
            DRIFT_AVERAGE_S / (self.window_len_ticks as f32 * crate::SAMPLE_PERIOD_S),
            1.0,
        )
    }

    /// The pull towards the estimate per tick for the jumps measured so far (1: none).
    ///
    /// Over a window the jump is the difference of two estimates' errors, uncorrelated a
    /// window apart, and of the dead reckoning's drift in between: its mean square is
    /// `2 r + q`, so the measurement noise is `r = (jump_ms - q_ms) / 2` (none when the jumps
    /// are no larger than the drift allowed for: a survey-grade receiver is followed as it
    /// is).
    pub fn gain(&self) -> f32 {
        let (q, q_ms) = match self.measured_drift() {
            Some(measured) => {
                // Both bounds are at least the floor; the measured one may be below it.
                let floor =
                    DRIFT_FLOOR_M2_PER_S * self.window_len_ticks as f32 * crate::SAMPLE_PERIOD_S;
                let measured = math::max(measured, floor);
                (
                    math::min(self.drift_var, measured),
                    math::min(self.drift_ms, measured),
                )
            }
            None => (self.drift_var, self.drift_ms),
        };
        let r = 0.5 * (self.jump_ms - q_ms);
        if !(r > 0.0 && q > 0.0) {
            return 1.0;
        }
        let p = 0.5 * (q + math::sqrt(q * q + 4.0 * q * r));
        // 1 - K, in (0, 1): r and p are positive and finite (the jumps are bounded by SNAP_M).
        let keep = r / (p + r);
        if keep.is_nan() || keep <= 0.0 {
            return 1.0;
        }
        math::clamp(-libm::logf(keep) / self.window_len_ticks as f32, 0.0, 1.0)
    }

    /// This tick's control pose for the estimate `pose` (rear axle), the dead reckoning, the
    /// speed and the heading's variance as the estimator reckons it (rad^2).
    pub fn control_pose(
        &mut self,
        cfg: &EstimatorConfig,
        pose: Pose,
        dead_reckoned: Xy,
        speed_mps: f32,
        heading_var_rad2: f32,
    ) -> Pose {
        let (s, c) = (pose.sin_heading, pose.cos_heading);
        // The estimate's antenna (`EstimatorState::position` inverted).
        let lever = Xy {
            x_m: cfg.antenna_ahead_m * s - cfg.antenna_left_m * c,
            y_m: cfg.antenna_ahead_m * c + cfg.antenna_left_m * s,
        };
        let estimate = Xy {
            x_m: pose.x_m + lever.x_m,
            y_m: pose.y_m + lever.y_m,
        };
        let speed = math::clamp_finite(speed_mps, 0.0, f32::MAX);
        let window_m = speed * self.window_len_ticks as f32 * crate::SAMPLE_PERIOD_S;
        self.drift_var = drift_var_m2(self.window_len_ticks, heading_var_rad2, window_m);
        self.measure(
            Xy {
                x_m: estimate.x_m - dead_reckoned.x_m,
                y_m: estimate.y_m - dead_reckoned.y_m,
            },
            dead_reckoned,
            heading_var_rad2,
        );
        let gain = self.gain();
        let smoothed = match self.last {
            Some((last, odo)) if gain < 1.0 => {
                let moved = Xy {
                    x_m: last.x_m + (dead_reckoned.x_m - odo.x_m),
                    y_m: last.y_m + (dead_reckoned.y_m - odo.y_m),
                };
                let (dx, dy) = (estimate.x_m - moved.x_m, estimate.y_m - moved.y_m);
                (dx * dx + dy * dy <= SNAP_M * SNAP_M).then_some(Xy {
                    x_m: moved.x_m + gain * dx,
                    y_m: moved.y_m + gain * dy,
                })
            }
            _ => None,
        };
        self.last = Some((smoothed.unwrap_or(estimate), dead_reckoned));
        match smoothed {
            Some(antenna) => Pose {
                x_m: antenna.x_m - lever.x_m,
                y_m: antenna.y_m - lever.y_m,
                ..pose
            },
            // Not smoothing: the estimate exactly as it is.
            None => pose,
        }
    }

    /// Counts this tick into the window; at its end adds the window's jump of the estimate
    /// against the dead reckoning (`offset`: the estimate's antenna less the dead reckoning)
    /// to the mean square, and the drift allowed for over the distance the dead reckoning
    /// moved in it to its own.
    fn measure(&mut self, offset: Xy, dead_reckoned: Xy, heading_var_rad2: f32) {
        let Some((start, start_odo)) = self.window_start else {
            self.window_start = Some((offset, dead_reckoned));
            self.window_ticks = 0;
            return;
        };
        self.window_ticks += 1;
        if self.window_ticks < self.window_len_ticks {
            return;
        }
        let (jx, jy) = (offset.x_m - start.x_m, offset.y_m - start.y_m);
        let j2 = jx * jx + jy * jy;
        if j2 <= SNAP_M * SNAP_M {
            let window_s = self.window_len_ticks as f32 * crate::SAMPLE_PERIOD_S;
            let windows = math::max(JUMP_WINDOW_S / window_s, 1.0);
            self.windows = self.windows.saturating_add(1);
            let n = math::min(self.windows as f32, windows);
            self.jump_ms += (j2 - self.jump_ms) / n;
            let moved_m = math::sqrt(
                (dead_reckoned.x_m - start_odo.x_m) * (dead_reckoned.x_m - start_odo.x_m)
                    + (dead_reckoned.y_m - start_odo.y_m) * (dead_reckoned.y_m - start_odo.y_m),
            );
            let q = drift_var_m2(self.window_len_ticks, heading_var_rad2, moved_m);
            self.drift_ms += (q - self.drift_ms) / n;
            // The ring's oldest end is DRIFT_LAG_WINDOWS windows before this one's.
            let oldest = (self.ends_head + 1) % DRIFT_LAG_WINDOWS;
            if let (true, Some(old)) = (
                self.ends_len as usize >= DRIFT_LAG_WINDOWS,
                self.ends.get(oldest),
            ) {
                let (lx, ly) = (offset.x_m - old.x_m, offset.y_m - old.y_m);
                let l2 = lx * lx + ly * ly;
                if l2 <= SNAP_M * SNAP_M {
                    let m = math::min(self.windows as f32, self.drift_windows());
                    self.long_ms += (l2 - self.long_ms) / m;
                    self.short_ms += (j2 - self.short_ms) / m;
                }
            }
        }
        self.ends_head = (self.ends_head + 1) % DRIFT_LAG_WINDOWS;
        if let Some(end) = self.ends.get_mut(self.ends_head) {
            *end = offset;
        }
        self.ends_len = self.ends_len.saturating_add(1);
        self.window_start = Some((offset, dead_reckoned));
        self.window_ticks = 0;
    }
}

/// The process noise over a window of `window_ticks` in which the dead reckoning moves
/// `moved_m` with the heading's variance `heading_var_rad2`, m^2: the heading's error and the
/// wheel speed's scale error times the distance, and the floor over the window's time. A
/// variance or a distance that is not finite and positive counts as none; the result is
/// finite (the heading's variance is at most 1 rad^2 and a window at most a minute).
fn drift_var_m2(window_ticks: u32, heading_var_rad2: f32, moved_m: f32) -> f32 {
    let var = math::clamp_finite(heading_var_rad2, 0.0, 1.0);
    let d = math::clamp_finite(moved_m, 0.0, 1.0e4);
    let window_s = window_ticks as f32 * crate::SAMPLE_PERIOD_S;
    math::min(
        (var + SPEED_SCALE_ERROR * SPEED_SCALE_ERROR) * d * d + DRIFT_FLOOR_M2_PER_S * window_s,
        DRIFT_DIFFUSION_M2_PER_S * window_s,
    )
}

impl Default for Smoothing {
    fn default() -> Self {
        Self::new()
    }
}

/// The heading counts as settled after this many time constants of its course correction
/// ([`HeadingSettle`]): the first heading's error is down to 5 %.
pub const HEADING_SETTLE_TIME_CONSTANTS: f32 = 3.0;

/// Whether the heading has settled, for the controllers to start. The first course comes from
/// a short chord of fixes; with a slow receiver it can be tenths of a radian out (0.36 rad at
/// 1 Hz), and a controller that drives on it steers at an error of its own making. The
/// estimator corrects the heading towards the course on the ticks the car moves at
/// `course_min_speed_mps` or faster with a heading and a course to correct it by (the
/// receiver's, or a chord of the track at least `course_min_baseline_m` long); after
/// [`HEADING_SETTLE_TIME_CONSTANTS`] of its complementary filter's time constant
/// (`1 / course_gain` such ticks: 6 s at 1 Hz, 1.2 s at 100 Hz) the first heading's error is
/// gone (the chords' gain is the course gain
/// while the heading's variance is large and falls with the chord's length after: from a
/// 0.5 rad start at 3 m/s with a standard receiver, 0.02-0.07 rad are left 1.2 s after the
/// corrections begin, `estimator::tests::heading_at_a_crawl_with_a_noisy_receiver`). Only the
/// ticks that corrected the heading count: a car held at 1.9 m/s with a 5 Hz receiver and no
/// course of its own draws chords of 1.2 m, which correct nothing, and counting its ticks by
/// the speed alone settled a first heading 0.53 rad off (docs/findings.md, "A heading settled
/// by time alone"). Once settled it stays so (the heading
/// is never forgotten; dead reckoning carries it through GNSS gaps). Counted in the drive stage
/// from the tick's pose and the estimator's word, and only while there is a path: the estimator's stages and
/// the ticks without a path make up the estimating tick's bound, which has no room for it
/// (docs/firmware.md, "Worst-case tick"). So a car driven before the planner's first path
/// waits the settling time again once the path is in.
#[derive(Clone, Copy, Debug, Default)]
pub struct HeadingSettle {
    /// Ticks with a pose on which the estimator corrected the heading, until settled.
    ticks: u32,
    settled: bool,
}

impl HeadingSettle {
    /// Nothing seen. `const`: the drive stage is built at compile time.
    pub const fn new() -> Self {
        Self {
            ticks: 0,
            settled: false,
        }
    }

    /// This tick: a pose (`has_pose`: position and heading), and whether the estimator
    /// corrected the heading towards a course (`corrected`); returns whether the heading has
    /// settled.
    pub fn update(&mut self, cfg: &EstimatorConfig, has_pose: bool, corrected: bool) -> bool {
        if !self.settled && has_pose && corrected {
            self.ticks = self.ticks.saturating_add(1);
            // A filter that never corrects (gain 0) is as settled as it will be.
            self.settled = cfg.course_gain <= 0.0
                || self.ticks as f32 * cfg.course_gain >= HEADING_SETTLE_TIME_CONSTANTS;
        }
        self.settled
    }
}
