//! The wheel speed's unit, checked against the GNSS track (review finding 04), and its sign in
//! reverse, against the commands ([`unsigned_reverse`]).
//!
//! The log schema's speeds are m/s, and its range (-10..80 m/s) cannot tell km/h or mph in town
//! from m/s on a motorway: a training set in km/h (37 at most) was identified with exit 0 and
//! a steering gain of 0.34 instead of 0.99 (mph: 0.50). The GNSS fixes measure the distance
//! the car went independently of `vel`, so the ratio of the two tells the unit: about 1 in
//! m/s, 3.6 in km/h, 2.237 in mph, 57.3 when `lat`/`lon` are radians.
//!
//! It is measured robustly, for slow and noisy receivers alike: over *stretches* of the drive
//! where the car moves (every wheel speed sample above [`MOVING`]), the fixes are regular (no
//! gap over [`MAX_GAP_PERIODS`] of the receiver's periods) and the stretch is long (at least
//! [`MIN_STRETCH_S`] and [`MIN_STRETCH_M`] along the track): a standard receiver's 1-2 m error
//! is mostly a bias that moves slowly and cancels between the stretch's ends, and its white
//! noise is small beside 10 m. The track's length is the sum of chords between fixes at least
//! [`MIN_CHORD_M`] apart, and more for a receiver whose white noise is larger ([`NOISE_CHORD`]):
//! on a turn a single chord is shorter than the arc; short chords would add the noise's length. The ratio is the median over the stretches, so a few bad ones (an
//! outlier fix, a stop inside a stretch) do not move it.
//!
//! Like is compared with like (review finding 01 of the third probe): the wheel speed is the
//! rear axle's, the track the antenna's, and on a turn an antenna `a` ahead of and `l` left
//! of the rear axle runs another circle than the axle: of radius `hypot(R - l, a)` where the
//! axle runs `R`. A 12 m bus with its antenna 6.5 m ahead gave 0.68 on its full-lock circles
//! in m/s, and its correct logs were refused. So the distance compared with the track is the
//! *antenna's*, predicted from the wheel speed and the car file's geometry
//! ([`LeverArm`]): the antenna's velocity is `v_rear + omega x r_antenna`, and with the rear
//! axle's path curvature `kappa = omega / v` its speed is
//! `|v| hypot(1 - kappa l, kappa a)`. The curvature comes from the steering through the
//! kinematic model (eq 8, `kappa = tan(delta) / L`), not from the GNSS course, because:
//!
//! - it is a ratio of lengths, free of the speed's unit: the correction is the same whatever
//!   unit `vel` is in, so km/h still reads 3.6 times what m/s reads, and mph 2.237 (an
//!   `omega` from the course rate, against a `vel` in km/h, would not be);
//! - the steering sensor has none of the receiver's noise, where the course's is multiplied by
//!   the lever arm: 0.1 rad of course noise on a 3 m chord is 0.65 m at 6.5 m ahead, and it
//!   enters squared (`hypot`), a bias, not noise that averages out;
//! - the slip at speed, which the kinematic model leaves out (an understeering car turns less
//!   than its wheels say), matters little: the correction is second order in `kappa a` and
//!   first in `kappa l`, and `kappa` is small at speed (4 m/s^2 at 20 m/s: 0.01 /m; 1.5 m
//!   left moves the ratio 1.5 %, 6.5 m ahead 0.2 %); where the correction is large, on the
//!   full-lock circles, the car is slow and follows its wheels (the simulated bus: its rear
//!   axle ran 6.14 m where eq 8 says 5.9 m, the corrected ratio 1.01 instead of 1).
//!   The understeer term of eq 2 would need the speed, in the unit being checked.
//!
//! With the antenna on the rear axle (or driving straight) the correction is exactly 1: the
//! check is what it was. The steering is taken as the log schema's (percent of the lock,
//! positive = right); one of the other sign matters only through `l` and is the steering
//! check's to refuse (`identify::steering_gain_problem`).

use super::stats::{median, median_interval};

/// Wheel speed above which a sample counts as moving, in the log's unit (m/s, or whatever the
/// log holds: the test is only that the car is not standing).
pub const MOVING: f64 = 0.5;
/// Shortest stretch, s: at least two of a 1 Hz receiver's fixes, and a baseline over which
/// the receiver's slow error changes little.
pub const MIN_STRETCH_S: f64 = 2.0;
/// Shortest stretch along the track, m: beside a standard receiver's 0.3-0.4 m of white noise
/// per fix, a few per cent.
pub const MIN_STRETCH_M: f64 = 10.0;
/// Longest stretch, s: a stretch that takes longer to cover its length is a crawl.
pub const MAX_STRETCH_S: f64 = 30.0;
/// Shortest chord summed into the track's length, m: at least this, and [`NOISE_CHORD`] times
/// the fixes' own white noise.
pub const MIN_CHORD_M: f64 = 3.0;
/// Shortest chord in the fixes' white noise per axis ([`WheelTrack::fix_noise_m`]). A chord
/// between two fixes carries `sqrt(2)` times that noise across it, which lengthens it by about
/// the square of that over twice the chord squared, and the first chord that reaches the
/// shortest length is more often one the noise lengthened: at 7 noises, a few per cent (a
/// 10 Hz receiver with 2 m of white noise per axis: 14 m chords; the 3 m chords summed the
/// noise, and the track read 4.5 times longer than the wheel's distance). A standard
/// receiver's 0.3-0.4 m keeps [`MIN_CHORD_M`].
pub const NOISE_CHORD: f64 = 7.0;
/// A gap between fixes over this many of the receiver's periods (the median interval) breaks
/// a stretch: an outage, not a stretch measured.
pub const MAX_GAP_PERIODS: f64 = 2.5;
/// A chord's ratio of wheel to chord distance must be within this factor of the log's own
/// (the median over all its chords): a chord to an outlier fix (tens of metres in a fraction
/// of a second) is not, and the fix is skipped; the noise of a standard receiver moves a
/// chord's ratio by some 20 %, a steady turn little.
pub const MAX_CHORD_SPREAD: f64 = 1.6;
/// A chord counts when the track's points at its ends, medians over half a second, are at
/// least this share of it apart: noise lengthens a chord, not the medians' line.
pub const REAL_CHORD_SHARE: f64 = 0.8;
/// A chord counts when the track through the point at its middle fix is at most this times
/// the chord's line: on an arc of 1.7 rad, the chord is 13 % shorter than the arc, the track
/// through the middle 10 % longer than the chord. A 1 Hz receiver's 3 m chords on a full-lock
/// circle of 3.6 m at 2.4 m/s (1.33 rad) are measured.
pub const STRAIGHT_CHORD: f64 = 1.1;
/// Stretches needed to judge a log.
pub const MIN_STRETCHES: usize = 5;
/// The accepted ratio of wheel distance (moved to the antenna, [`LeverArm`]) to track
/// distance: m/s with every error the check allows for (a wheel speed a few per cent off, the
/// kinematic model's error on a turn, a car file's antenna a little off) inside, km/h (3.6)
/// and mph (2.237) far outside.
pub const ACCEPTED_RATIO: std::ops::RangeInclusive<f64> = 0.8..=1.25;

/// Where the GNSS antenna sits on the car and how the steering bends the rear axle's path:
/// what moves the wheel speed (the rear axle's) to the antenna (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LeverArm {
    /// Antenna ahead of the rear axle, m.
    pub ahead_m: f64,
    /// Antenna left of the centre line, m.
    pub left_m: f64,
    /// Wheelbase, m.
    pub wheelbase_m: f64,
    /// Centre-tyre angle at 100 % steering, degrees.
    pub max_steer_deg: f64,
}

impl LeverArm {
    /// The car file's antenna and steering geometry.
    pub fn of(vehicle: &crate::model_file::VehicleSection) -> Self {
        Self {
            ahead_m: vehicle.antenna_ahead_m,
            left_m: vehicle.antenna_left_m,
            wheelbase_m: vehicle.wheelbase_m,
            max_steer_deg: vehicle.max_steer_deg,
        }
    }

    /// An antenna on the rear axle: the wheel speed is the antenna's.
    pub const NONE: Self = Self {
        ahead_m: 0.0,
        left_m: 0.0,
        wheelbase_m: 1.0,
        max_steer_deg: 0.0,
    };

    /// Whether the antenna is off the rear axle's centre.
    pub fn is_off_the_axle(&self) -> bool {
        self.ahead_m != 0.0 || self.left_m != 0.0
    }

    /// The antenna's speed over the rear axle's at a steering of `steer_pct` (percent of the
    /// lock, positive = right), by the kinematic model: `hypot(1 - kappa l, kappa a)` with
    /// the rear axle's curvature `kappa = tan(delta) / L`, positive to the left. Exactly 1
    /// straight ahead or with the antenna on the axle.
    pub fn antenna_speed_factor(&self, steer_pct: f64) -> f64 {
        let delta_right = steer_pct.clamp(-100.0, 100.0) / 100.0 * self.max_steer_deg.to_radians();
        let kappa_left = -delta_right.tan() / self.wheelbase_m;
        (1.0 - kappa_left * self.left_m).hypot(kappa_left * self.ahead_m)
    }
}

/// The wheel speed against the GNSS track over one log.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedScale {
    /// Median over the stretches of (distance by the wheel speed, moved to the antenna) /
    /// (distance along the track): 1 when `vel` is in m/s.
    pub ratio: f64,
    /// Stretches it is the median of.
    pub stretches: usize,
    /// The antenna the wheel speed was moved to, ahead of and left of the rear axle, m
    /// (`None`: on the axle, the wheel speed as it is).
    pub antenna_m: Option<(f64, f64)>,
}

/// A ratio within this fraction of a unit's factor names the unit: wide enough for the tight
/// turns of a circle (the kinematic model's error at full lock, a car file's antenna a little
/// off), narrow enough that km/h (3.06..4.14) and mph (1.90..2.57) do not meet.
const NAMED_UNIT_TOLERANCE: f64 = 0.15;

/// The speed unit a ratio of a speed to the same speed in m/s names, with its factor: km/h
/// (3.6) or mph (2.237), within [`NAMED_UNIT_TOLERANCE`]; `None` for any other ratio. The one
/// rule for `vel` (its distance over the GNSS track's) and `input_vel` (the command over the
/// speed it settles to, [`command_unit_problem`]).
/// The factor comes with its label as printed (`3.6`, `2.237`).
fn named_speed_unit(ratio: f64) -> Option<(&'static str, f64, &'static str)> {
    [("km/h", 3.6, "3.6"), ("mph", 2.236_936, "2.237")]
        .into_iter()
        .find(|&(_, factor, _)| (ratio / factor - 1.0).abs() < NAMED_UNIT_TOLERANCE)
}

/// What a ratio of wheel to track distance most likely means, if it is not m/s.
fn likely_cause(ratio: f64) -> String {
    let near = |x: f64| (ratio / x - 1.0).abs() < NAMED_UNIT_TOLERANCE;
    if let Some((unit, _, factor)) = named_speed_unit(ratio) {
        format!(
            "`vel` looks like {unit} ({factor} times m/s): the log schema's speeds are m/s; \
             divide `vel` and `input_vel` by {factor}"
        )
    } else if near(180.0 / std::f64::consts::PI) {
        "`lat` and `lon` look like radians (the track is 57.3 times too short): the schema's \
         are degrees"
            .into()
    } else if ratio < 1.0 {
        "the GNSS track is longer than the wheel speed says: check the unit of `vel` (m/s) and \
         of `lat`/`lon` (degrees), and that they come from one car"
            .into()
    } else {
        "the wheel speed is faster than the GNSS track: check the unit of `vel` (m/s) and of \
         `lat`/`lon` (degrees), and that they come from one car"
            .into()
    }
}

/// Why the speed model's steady-state gain `dc_gain` (m/s of speed per unit of `input_vel`)
/// says the command `input_vel` is not in m/s, if it does: outside
/// [`crate::model_file::SPEED_DC_GAIN_RANGE`] and its inverse naming a unit by
/// [`named_speed_unit`] (km/h settles at 1/3.6 = 0.278, mph at 0.447). The wheel speed `vel`
/// is judged by the GNSS track before ([`SpeedScale::problem`]); the command has only the
/// speed it settles to.
pub fn command_unit_problem(dc_gain: f64) -> Option<String> {
    let (lo, hi) = crate::model_file::SPEED_DC_GAIN_RANGE;
    if !dc_gain.is_finite() || dc_gain <= 0.0 || (lo..=hi).contains(&dc_gain) {
        return None;
    }
    let (unit, value, factor) = named_speed_unit(1.0 / dc_gain)?;
    Some(format!(
        "the speed settles at {dc_gain:.3} times the command `input_vel` (1/{factor} = {:.3} \
         if `input_vel` is in {unit} and `vel` in m/s): `input_vel` looks like {unit}; the log \
         schema's speeds are m/s; divide `input_vel` by {factor}",
        1.0 / value
    ))
}

/// The command must have held its value this long, s, ...
const SETTLED_COMMAND_HELD_S: f64 = 5.0;
/// ... within this, m/s, ...
const SETTLED_COMMAND_BAND_MPS: f64 = 0.05;
/// ... and the speed must have moved less than this over the last [`SETTLED_SPEED_S`], m/s,
/// for a sample to show where the speed settles for the command: a slow speed loop still
/// rising after the hold (a truck-like car's 0.6 m/s^2 from 0 to 10 m/s takes 17 s) is not
/// settled, and would read as a gain near km/h's.
const SETTLED_SPEED_CHANGE_MPS: f64 = 0.1;
/// See [`SETTLED_SPEED_CHANGE_MPS`], s.
const SETTLED_SPEED_S: f64 = 2.0;
/// Settled samples needed to judge the command's unit (2 s on the 20 ms grid).
const SETTLED_MIN_SAMPLES: usize = 100;

/// The speed the car settles to over its command, before any fit: the median of `vel /
/// input_vel` over the samples of the grid `t` where the command (at least 1 m/s) has held
/// within [`SETTLED_COMMAND_BAND_MPS`] for [`SETTLED_COMMAND_HELD_S`] and the speed (moving)
/// has settled ([`SETTLED_SPEED_CHANGE_MPS`]); `None` with fewer than
/// [`SETTLED_MIN_SAMPLES`] such samples.
pub fn settled_command_gain(t: &[f64], vel: &[f64], cmd: &[f64]) -> Option<f64> {
    let n = t.len().min(vel.len()).min(cmd.len());
    let mut gains = Vec::new();
    let mut held_from = 0;
    let mut speed_from = 0;
    for k in 0..n {
        if (cmd[k] - cmd[held_from]).abs() > SETTLED_COMMAND_BAND_MPS {
            held_from = k;
        }
        while t[k] - t[speed_from] > SETTLED_SPEED_S {
            speed_from += 1;
        }
        let held = t[k] - t[held_from] >= SETTLED_COMMAND_HELD_S;
        let settled = t[k] - t[speed_from] >= 0.9 * SETTLED_SPEED_S
            && (vel[k] - vel[speed_from]).abs() < SETTLED_SPEED_CHANGE_MPS;
        if held && settled && cmd[k] >= 1.0 && vel[k] > MOVING {
            gains.push(vel[k] / cmd[k]);
        }
    }
    (gains.len() >= SETTLED_MIN_SAMPLES).then(|| median(&mut gains))
}

/// Why `input_vel` is not in m/s by the speed it settles to, before any fit
/// ([`settled_command_gain`] named by [`command_unit_problem`]): a black-box probe's command in
/// km/h was also taken for a command the car did not follow, in every log, before the speed
/// model's gain named its unit after the fit.
pub fn settled_command_problem(t: &[f64], vel: &[f64], cmd: &[f64]) -> Option<String> {
    command_unit_problem(settled_command_gain(t, vel, cmd)?)
}

impl SpeedScale {
    /// Why the log's wheel speed cannot be m/s, or `None` when the ratio is within
    /// [`ACCEPTED_RATIO`].
    pub fn problem(&self) -> Option<String> {
        if ACCEPTED_RATIO.contains(&self.ratio) {
            return None;
        }
        let moved = match self.antenna_m {
            Some((ahead, left)) => format!(
                "; the wheel speed moved to the antenna, {ahead} m ahead of and {left} m left \
                 of the rear axle, by the steering"
            ),
            None => String::new(),
        };
        let cause = likely_cause(self.ratio);
        let check_car = if self.antenna_m.is_some() && !cause.contains("looks like") {
            ", and the car file's antenna and steering"
        } else {
            ""
        };
        Some(format!(
            "the wheel speed `vel` is {:.2} times the speed along the GNSS track (the median \
             over {} stretches where the car moves, each at least {MIN_STRETCH_S} s and \
             {MIN_STRETCH_M} m along the track{moved}; m/s gives {}..{}): {cause}{check_car}",
            self.ratio,
            self.stretches,
            ACCEPTED_RATIO.start(),
            ACCEPTED_RATIO.end(),
        ))
    }
}

/// Cumulative distance by the wheel speed at each sample, moved to the antenna by
/// `factor` (trapezoids; reversing counts as distance too).
fn wheel_distance(t: &[f64], v: &[f64], factor: &[f64]) -> Vec<f64> {
    let mut out = Vec::with_capacity(t.len());
    let mut d = 0.0;
    for k in 0..t.len() {
        if k > 0 {
            d +=
                0.5 * (v[k].abs() * factor[k] + v[k - 1].abs() * factor[k - 1]) * (t[k] - t[k - 1]);
        }
        out.push(d);
    }
    out
}

/// [`LeverArm::antenna_speed_factor`] at each time of `at`, by the steering samples
/// `(ts, steer_pct)` (sorted by time; the first and last held outside them; 1 without any).
fn antenna_factors(at: &[f64], ts: &[f64], steer_pct: &[f64], lever: &LeverArm) -> Vec<f64> {
    if !lever.is_off_the_axle() || ts.is_empty() {
        return vec![1.0; at.len()];
    }
    let (first, last) = (steer_pct[0], steer_pct[steer_pct.len() - 1]);
    at.iter()
        .map(|&t| {
            let s = if t <= ts[0] {
                first
            } else {
                interpolate(ts, steer_pct, t).unwrap_or(last)
            };
            lever.antenna_speed_factor(s)
        })
        .collect()
}

/// Linear interpolation of the series `(t, y)` (sorted by `t`) at `at`; `None` outside it.
fn interpolate(t: &[f64], y: &[f64], at: f64) -> Option<f64> {
    let i = t.partition_point(|x| *x <= at);
    if i == 0 {
        return None;
    }
    if i == t.len() {
        return (t[i - 1] == at).then(|| y[i - 1]);
    }
    let (t0, t1) = (t[i - 1], t[i]);
    let w = if t1 > t0 { (at - t0) / (t1 - t0) } else { 0.0 };
    Some(y[i - 1] + (y[i] - y[i - 1]) * w)
}

/// The steering samples of a log, `(t, steer_pct)`, sorted by time.
pub type Steering<'a> = (&'a [f64], &'a [f64]);

/// The wheel's distance and the GNSS track of one log, side by side: what [`speed_scale`]
/// and [`disagreement`] compare.
pub struct WheelTrack<'a> {
    tv: &'a [f64],
    vel: &'a [f64],
    /// Cumulative distance by the wheel speed at each of `tv`, moved to the antenna.
    wheel: Vec<f64>,
    tg: &'a [f64],
    east: &'a [f64],
    north: &'a [f64],
    /// Longest interval between fixes that is not an outage, s.
    max_gap: f64,
    /// Longest interval between wheel speed samples that is not a pause, s.
    max_wheel_gap: f64,
    /// Where the wheel speed was moved to.
    lever: LeverArm,
    /// The fixes' white noise per axis, m ([`fix_noise`]).
    fix_noise_m: f64,
}

impl<'a> WheelTrack<'a> {
    /// The wheel speed samples `(tv, vel)`, the steering `(ts, steer_pct)` and the fixes `(tg,
    /// east, north)` in metres (each sorted by time), the antenna where `lever` puts it;
    /// `None` with fewer than two samples of either.
    pub fn new(
        (tv, vel): (&'a [f64], &'a [f64]),
        (ts, steer_pct): Steering,
        lever: &LeverArm,
        tg: &'a [f64],
        east: &'a [f64],
        north: &'a [f64],
    ) -> Option<Self> {
        if tv.len() < 2 || tg.len() < 2 {
            return None;
        }
        let factor = antenna_factors(tv, ts, steer_pct, lever);
        let max_gap = MAX_GAP_PERIODS * median_interval(tg);
        Some(Self {
            tv,
            vel,
            wheel: wheel_distance(tv, vel, &factor),
            tg,
            east,
            north,
            max_gap,
            // The wheel speed's own gaps break a stretch too (a sensor pause is not a distance).
            max_wheel_gap: MAX_GAP_PERIODS * median_interval(tv),
            lever: *lever,
            fix_noise_m: fix_noise(tg, east, north, max_gap),
        })
    }

    /// Shortest chord summed into the track's length, m: [`MIN_CHORD_M`], or [`NOISE_CHORD`]
    /// times the fixes' noise if longer.
    pub fn min_chord_m(&self) -> f64 {
        MIN_CHORD_M.max(NOISE_CHORD * self.fix_noise_m)
    }

    /// Whether the wheel speed is reported without a pause from `a` to `b`, s.
    fn wheel_regular(&self, a: f64, b: f64) -> Option<std::ops::RangeInclusive<usize>> {
        let tv = self.tv;
        let lo = tv.partition_point(|t| *t < a);
        let hi = tv.partition_point(|t| *t <= b);
        (lo > 0
            && hi < tv.len()
            && tv[lo - 1..=hi]
                .windows(2)
                .all(|w| w[1] - w[0] <= self.max_wheel_gap))
        .then(|| lo - 1..=hi)
    }

    /// Whether the car moves from `a` to `b` by every wheel speed sample, reported without a
    /// pause.
    fn moving_between(&self, a: f64, b: f64) -> bool {
        self.wheel_regular(a, b)
            .is_some_and(|r| self.vel[r].iter().all(|v| v.abs() >= MOVING))
    }

    /// The wheel's distance between fixes `i` and `j`.
    fn wheel_between(&self, i: usize, j: usize) -> Option<f64> {
        Some(
            interpolate(self.tv, &self.wheel, self.tg[j])?
                - interpolate(self.tv, &self.wheel, self.tg[i])?,
        )
    }

    /// The straight line from fix `i` to fix `j`, m.
    fn chord(&self, i: usize, j: usize) -> f64 {
        (self.east[j] - self.east[i]).hypot(self.north[j] - self.north[i])
    }
}

/// The white noise of the fixes `(tg, east, north)` per axis, m: the median over both axes of
/// each fix's distance from the cubic through its two neighbours on either side (no gap over
/// `max_gap` among them), weighed for the neighbours' own noise, over the median of that for
/// noise of unit deviation. The car's own motion moves a fix off that cubic by the change of
/// its acceleration: a 1 Hz receiver on a full-lock circle at 2.4 m/s (3.6 m), 0.08 m, where
/// the line between the neighbours is 0.6 m off. A receiver that repeats or interpolates its
/// fixes reads less than its noise, and the chords keep [`MIN_CHORD_M`]. 0 with no five fixes
/// to judge by.
fn fix_noise(tg: &[f64], east: &[f64], north: &[f64], max_gap: f64) -> f64 {
    let mut residuals = Vec::new();
    for k in 2..tg.len().saturating_sub(2) {
        let around = [k - 2, k - 1, k + 1, k + 2];
        if (k - 2..k + 2).any(|m| !(tg[m + 1] > tg[m] && tg[m + 1] - tg[m] <= max_gap)) {
            continue;
        }
        // Lagrange weights of the cubic through the four neighbours, at tg[k].
        let weights = around.map(|m| {
            around
                .iter()
                .filter(|&&n| n != m)
                .map(|&n| (tg[k] - tg[n]) / (tg[m] - tg[n]))
                .product::<f64>()
        });
        // The residual's deviation for noise of unit deviation on every fix.
        let scale = (1.0 + weights.iter().map(|w| w * w).sum::<f64>()).sqrt();
        for p in [east, north] {
            let cubic: f64 = around.iter().zip(weights).map(|(&m, w)| w * p[m]).sum();
            residuals.push((p[k] - cubic).abs() / scale);
        }
    }
    if residuals.is_empty() {
        return 0.0;
    }
    median(&mut residuals) / super::stats::MEDIAN_ABS_UNIT_NORMAL
}

/// [`SpeedScale`] of a log ([`WheelTrack`]). `None` when the log has fewer than
/// [`MIN_STRETCHES`] stretches to judge by (a parked car, a log too short).
pub fn speed_scale(wt: &WheelTrack) -> Option<SpeedScale> {
    let (tg, lever) = (wt.tg, &wt.lever);
    let max_gap = wt.max_gap;
    let moving_between = |a: f64, b: f64| wt.moving_between(a, b);
    let wheel_between = |i: usize, j: usize| wt.wheel_between(i, j);
    let chord = |i: usize, j: usize| wt.chord(i, j);
    let min_chord = wt.min_chord_m();
    // A chord the noise made long is not measured: the track's own points at its ends (medians
    // over half a second, [`TrackMeasure`]) must be at least [`REAL_CHORD_SHARE`] of it apart.
    // Nor is one across a bend: through the point at its middle fix, the track must be at most
    // [`STRAIGHT_CHORD`] times that line. On a full-lock circle under a metre or two of white
    // noise per fix, where the shortest chord is most of the circle's width, no chord is
    // measured, and the log is not judged rather than read as another unit.
    let measure = TrackMeasure {
        half_s: TRACK_POINT_S,
        ..TrackMeasure::new(wt)
    };
    let points: Vec<(f64, f64)> = tg.iter().map(|&t| measure.point(t)).collect();
    let between = |i: usize, j: usize| {
        let (p, q) = (points[i], points[j]);
        (q.0 - p.0).hypot(q.1 - p.1)
    };
    let real = |i: usize, j: usize, c: f64| {
        let line = between(i, j);
        let m = (i + j) / 2;
        line >= REAL_CHORD_SHARE * c
            && (j - i < 2 || between(i, m) + between(m, j) <= STRAIGHT_CHORD * line)
    };

    // 1. The log's own ratio, roughly: the median over every chord of `min_chord` along the
    // track while moving. The median ignores the few chords to an outlier fix; it is what the
    // chords of a stretch must agree with.
    let mut rough = Vec::new();
    let mut last = 0;
    for k in 1..tg.len() {
        if tg[k] - tg[k - 1] > max_gap {
            last = k;
            continue;
        }
        let c = chord(last, k);
        if c >= min_chord && real(last, k, c) {
            if moving_between(tg[last], tg[k]) {
                if let Some(w) = wheel_between(last, k) {
                    rough.push(w / c);
                }
            }
            last = k;
        }
    }
    if rough.len() < MIN_STRETCHES {
        return None;
    }
    let rough = median(&mut rough);
    let agrees = |r: f64| r >= rough / MAX_CHORD_SPREAD && r <= rough * MAX_CHORD_SPREAD;

    // 2. Stretches: walk the track from `start`, summing chords of at least `min_chord` that
    // agree with the log (a chord to an outlier fix does not: that fix is skipped), until the
    // stretch is long enough; a gap in the fixes or a crawl ends it, and so does a start that
    // no chord agrees with (the start is the outlier).
    let mut ratios = Vec::new();
    let mut start = 0;
    while start + 1 < tg.len() {
        let (mut length, mut last, mut end) = (0.0, start, None);
        let mut refused = 0;
        let mut k = start + 1;
        while k < tg.len() {
            if tg[k] - tg[k - 1] > max_gap
                || tg[k] - tg[start] > MAX_STRETCH_S
                || refused > MAX_REFUSED_CHORDS
            {
                break;
            }
            let c = chord(last, k);
            if c >= min_chord && real(last, k, c) {
                match wheel_between(last, k) {
                    Some(w) if agrees(w / c) => {
                        length += c;
                        last = k;
                        refused = 0;
                        if length >= MIN_STRETCH_M && tg[k] - tg[start] >= MIN_STRETCH_S {
                            end = Some(k);
                            break;
                        }
                    }
                    _ => refused += 1,
                }
            }
            k += 1;
        }
        let Some(end) = end else {
            // Nothing measured from this start: the next fix starts the next stretch.
            start = if last > start { last } else { start + 1 };
            continue;
        };
        if moving_between(tg[start], tg[end]) {
            if let Some(w) = wheel_between(start, end) {
                ratios.push(w / length);
            }
        }
        start = end;
    }
    if ratios.len() < MIN_STRETCHES {
        return None;
    }
    Some(SpeedScale {
        ratio: median(&mut ratios),
        stretches: ratios.len(),
        antenna_m: lever
            .is_off_the_axle()
            .then_some((lever.ahead_m, lever.left_m)),
    })
}

/// Length of the windows in which [`disagreement`] compares the wheel with the track, s.
pub const WINDOW_S: f64 = 2.5;
/// A window disagrees when the wheel's distance and the track's differ by more than this, m
/// (a standard receiver's error moves a 2.5 s track by a metre or so; fixes 0.5 s late move
/// it by half a second of the change of speed over the window, 2.5 m braking at 5 m/s^2) ...
pub const DISAGREE_MIN_M: f64 = 5.0;
/// ... and by more than this share of the longer of the two (a wheel speed a few per cent off,
/// the kinematic model's error on a turn, fixes 0.5 s late under the hardest braking are far
/// inside).
pub const DISAGREE_SHARE: f64 = 0.5;
/// Windows in a row that must disagree, the same way, before the span is named: one alone may
/// be a few fixes off the track together.
pub const DISAGREE_WINDOWS: usize = 2;

/// A span of a log over which the wheel speed and the GNSS track disagree: a wheel speed that
/// sticks at the last value while the car stops or speeds up, or drops to zero while it moves
/// (black-box probe: a `vel` stuck for 20 s passed without a word; stuck through a stop, it
/// took the speed model's fit from 82 % to 63 % and the lateral fit was refused for the
/// receiver's course, which was right).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Disagreement {
    /// Start and end of the span, s (the log's time).
    pub from_s: f64,
    /// See `from_s`.
    pub to_s: f64,
    /// The distance by the wheel speed over the span, moved to the antenna, m.
    pub wheel_m: f64,
    /// The distance along the GNSS track, m.
    pub track_m: f64,
    /// The windows compared, s: [`WINDOW_S`], or three of a slow receiver's periods.
    pub window_s: f64,
    /// Most of the span's fixes repeat the one before exactly: the fixes stood still, not the
    /// wheel speed.
    pub repeated_fixes: bool,
    /// The wheel speed held one value exactly over the span while the track's speed changed
    /// ([`held_speed`]): `(the value, the track's slowest and fastest window, m/s)`.
    pub held: Option<(f64, f64, f64)>,
    /// The track went further while the wheel speed and the speed commands both say the car
    /// stood, from a second before the span to its end ([`stood_by_its_sensors`]): the
    /// receiver's, not the wheel speed's.
    pub car_stood: bool,
    /// The span starts within two windows of the log's first fix: the receiver may still have
    /// been converging after a cold start (its first fixes tens of metres off).
    pub from_first_fix: bool,
}

/// Whether every wheel speed `(tv, vel)` and speed command `(tc, cmd)` sample from `a` to `b`
/// s is under [`MOVING`], with at least one of each: the car stood by both (a wheel speed
/// that drops to zero while the car is asked to move does not).
pub fn stood_by_its_sensors(
    (tv, vel): (&[f64], &[f64]),
    (tc, cmd): (&[f64], &[f64]),
    a: f64,
    b: f64,
) -> bool {
    let still = |t: &[f64], x: &[f64]| {
        let lo = t.partition_point(|s| *s < a);
        let hi = t.partition_point(|s| *s <= b);
        hi > lo && x[lo..hi].iter().all(|v| v.abs() < MOVING)
    };
    still(tv, vel) && still(tc, cmd)
}

/// How long before a span the car must have stood by its sensors for the track's motion to be
/// the receiver's, s: a car that stops has stood a second.
pub const STOOD_BEFORE_S: f64 = 1.0;

impl Disagreement {
    /// The problem in words, with what to do.
    pub fn problem(&self) -> String {
        if let Some((value, slowest, fastest)) = self.held {
            return format!(
                "the wheel speed `vel` holds {value} exactly from t = {:.1} to {:.1} s while the \
                 GNSS track's speed goes from {slowest:.1} to {fastest:.1} m/s (its slowest and \
                 fastest {:.1} s, measured the way noise cannot widen): a wheel speed that \
                 sticks at its last value. The speed model would be fitted to it: split the log \
                 there (the parts before and after are logs of their own), or fix the sensor",
                self.from_s, self.to_s, self.window_s
            );
        }
        if self.car_stood {
            return format!(
                "the GNSS track moves {:.1} m from t = {:.1} to {:.1} s while the wheel speed \
                 `vel` ({:.1} m) and the speed commands `input_vel` say the car stands: the \
                 receiver's fixes, re-converging after an outage or drifting (or a car carried: \
                 a ferry, a trailer). The dx/dt model would be fitted to a track that moves at \
                 a standstill: cut the span out or split the log there (the parts before and \
                 after are logs of their own)",
                self.track_m, self.from_s, self.to_s, self.wheel_m
            );
        }
        let what = if self.repeated_fixes {
            "the wheel speed says the car went further than the GNSS track does, and most of \
             the span's fixes repeat the one before exactly: a receiver or recorder that holds \
             its last fix through an outage (drop the repeated fixes: the log's reader bridges \
             an outage)"
        } else if self.wheel_m > self.track_m {
            "the wheel speed says the car went further than the GNSS track does: a wheel speed \
             that sticks at its last value while the car slows or stops"
        } else {
            "the GNSS track says the car went further than the wheel speed does: a wheel speed \
             that sticks or drops to zero while the car moves, or a car carried (a ferry, a \
             trailer)"
        };
        format!(
            "the wheel speed `vel` disagrees with the GNSS track from t = {:.1} to {:.1} s: \
             {:.1} m by the wheel speed, {:.1} m along the track (every {:.1} s of the \
             span differs by more than {DISAGREE_MIN_M} m and {:.0} %); {}{what}, or fixes of \
             another receiver. The speed model would be fitted to it: split the log there (the \
             parts before and after are logs of their own), or fix the sensor",
            self.from_s,
            self.to_s,
            self.wheel_m,
            self.track_m,
            self.window_s,
            DISAGREE_SHARE * 100.0,
            if self.from_first_fix {
                "the span starts at the log's first fixes: most likely a receiver still \
                 converging after a cold start (its first fixes tens of metres off, moving \
                 towards the track): cut the log's first seconds until its fixes settle; else "
            } else {
                ""
            }
        )
    }
}

/// The longest span of a log ([`WheelTrack`]) over which the wheel speed and the GNSS track
/// disagree: the log is cut into windows of [`WINDOW_S`] (three periods
/// of a slow receiver) between fixes, each with regular fixes and wheel speed samples (an
/// outage or a sensor's pause ends a span). In each, the wheel's distance moved to the antenna
/// is compared with the track, measured the way that cannot make a healthy log disagree
/// ([`TrackMeasure`]): that the track went further than the wheel, by the straight line
/// between its ends (a receiver's noise does not lengthen it, a bend only shortens it); that
/// it went less far, by its length ([`TrackMeasure::length`]: noise and bends only lengthen
/// it). [`DISAGREE_WINDOWS`] windows in a row that differ, the same way, by more than
/// [`DISAGREE_MIN_M`] and [`DISAGREE_SHARE`] of the longer make a span; where the track went
/// further, the two windows' straight lines must also go on one way (over both, at least half
/// their sum): fixes that jump off the track and come back, which the log's reader leaves in
/// for a receiver under 3 Hz, do not. `None` when nothing disagrees.
pub fn disagreement(wt: &WheelTrack) -> Option<Disagreement> {
    let measure = TrackMeasure::new(wt);
    let (window, windows) = windows(wt);
    let mut best: Option<(usize, Disagreement)> = None;
    // The current run of windows that disagree: (windows, the track went further, the span,
    // where the run's last window started).
    let mut run: Option<(usize, bool, Disagreement, f64)> = None;
    for w in &windows {
        let (a, b) = (w.from_s, w.to_s);
        let differs =
            |w: f64, g: f64| (w - g).abs() > DISAGREE_MIN_M.max(DISAGREE_SHARE * w.max(g));
        let verdict = w.wheel_m.and_then(|w| {
            let line = measure.line(a, b);
            if line > w && differs(w, line) {
                return Some((true, w, line));
            }
            let length = measure.length(a, b);
            (w > length && differs(w, length)).then_some((false, w, length))
        });
        run = match (run, verdict) {
            (Some((n, further, mut d, last_from)), Some((f, w, g)))
                if f == further
                    && (!further
                        || measure.line(last_from, b)
                            >= 0.5 * (measure.line(last_from, a) + g)) =>
            {
                d.to_s = b;
                d.wheel_m += w;
                d.track_m += g;
                Some((n + 1, further, d, a))
            }
            (_, Some((f, w, g))) => Some((
                1,
                f,
                Disagreement {
                    from_s: a,
                    to_s: b,
                    wheel_m: w,
                    track_m: g,
                    window_s: window,
                    repeated_fixes: false,
                    held: None,
                    car_stood: false,
                    from_first_fix: false,
                },
                a,
            )),
            (_, None) => None,
        };
        if let Some((n, _, d, _)) = run {
            if n >= DISAGREE_WINDOWS && best.is_none_or(|(m, _)| n > m) {
                best = Some((n, d));
            }
        }
    }
    best.map(|(_, mut d)| {
        d.repeated_fixes = repeats_fixes(wt, d.from_s, d.to_s);
        d
    })
}

/// Windows in a row over which the wheel speed must hold one value before [`held_speed`]
/// judges it (7.5 s at [`WINDOW_S`]).
pub const HELD_WINDOWS: usize = 3;
/// The share of its fastest window by which the track's slowest must be slower (and by
/// [`DISAGREE_MIN_M`]) for a held wheel speed to be named: a wheel speed of 1 km/h steps holds
/// while the car's speed stays within the step, 14 % at 2 m/s (and under 5 m a window).
pub const HELD_CHANGE_SHARE: f64 = 0.3;

/// The longest span of a log ([`WheelTrack`]) over which the wheel speed holds one value,
/// bit for bit, while the GNSS track's speed changes: a sensor stuck at its last value while
/// the car speeds up or slows by less than [`disagreement`]'s half (the black-box probe's
/// `vel` held at 8 m/s while the car went 8 -> 12.5 -> 4.7 m/s). A healthy wheel speed holds a
/// value only while the car's speed stays within its resolution. Over [`HELD_WINDOWS`]
/// windows or more of one held value (at least [`MOVING`]), the track's distance in its
/// fastest window, by the straight line (which noise does not lengthen), must beat its
/// distance in the slowest, by the length (which noise does not shorten), by more than
/// [`DISAGREE_MIN_M`] and [`HELD_CHANGE_SHARE`] of the former. Whatever the wheel speed's
/// scale, then: a log in another unit or a tyre a few per cent off holds as the track does.
pub fn held_speed(wt: &WheelTrack) -> Option<Disagreement> {
    let measure = TrackMeasure::new(wt);
    let (window, windows) = windows(wt);
    let held_value = |w: &Window| {
        let r = w.wheel.clone()?;
        let v = wt.vel[*r.start()];
        (v.abs() >= MOVING && wt.vel[r].iter().all(|x| x.to_bits() == v.to_bits())).then_some(v)
    };
    let mut best: Option<(usize, Disagreement)> = None;
    let mut k = 0;
    while k < windows.len() {
        let Some(v) = held_value(&windows[k]) else {
            k += 1;
            continue;
        };
        // The run of windows, each following the last without a gap, that hold `v`.
        let mut end = k + 1;
        while end < windows.len()
            && windows[end].from_s == windows[end - 1].to_s
            && held_value(&windows[end]).is_some_and(|x| x.to_bits() == v.to_bits())
        {
            end += 1;
        }
        let run = &windows[k..end];
        k = end;
        if run.len() < HELD_WINDOWS {
            continue;
        }
        let per_s = |m: f64, w: &Window| m / (w.to_s - w.from_s);
        let fastest = run
            .iter()
            .map(|w| (measure.line(w.from_s, w.to_s), w))
            .max_by(|x, y| per_s(x.0, x.1).total_cmp(&per_s(y.0, y.1)));
        let slowest = run
            .iter()
            .map(|w| (measure.length(w.from_s, w.to_s), w))
            .min_by(|x, y| per_s(x.0, x.1).total_cmp(&per_s(y.0, y.1)));
        let (Some((fast_m, fast)), Some((slow_m, slow))) = (fastest, slowest) else {
            continue;
        };
        // Compared over one window's time: the slowest's distance at its speed.
        let slow_at = per_s(slow_m, slow) * (fast.to_s - fast.from_s);
        if fast_m - slow_at <= DISAGREE_MIN_M.max(HELD_CHANGE_SHARE * fast_m) {
            continue;
        }
        if best.is_none_or(|(n, _)| run.len() > n) {
            let (from_s, to_s) = (run[0].from_s, run[run.len() - 1].to_s);
            best = Some((
                run.len(),
                Disagreement {
                    from_s,
                    to_s,
                    wheel_m: run.iter().filter_map(|w| w.wheel_m).sum(),
                    track_m: measure.length(from_s, to_s),
                    window_s: window,
                    repeated_fixes: false,
                    held: Some((v, per_s(slow_m, slow), per_s(fast_m, fast))),
                    car_stood: false,
                    from_first_fix: false,
                },
            ));
        }
    }
    best.map(|(_, d)| d)
}

/// One window [`disagreement`] and [`held_speed`] compare the wheel with the track in.
struct Window {
    /// First and last fix's time, s.
    from_s: f64,
    /// See `from_s`.
    to_s: f64,
    /// The wheel speed samples over it, when they are regular and the window long enough.
    wheel: Option<std::ops::RangeInclusive<usize>>,
    /// The wheel's distance over it, moved to the antenna, m, with `wheel`.
    wheel_m: Option<f64>,
}

/// The windows of a log: [`WINDOW_S`] (three periods of a slow receiver) between fixes, each
/// starting where the last ended, or after the outage that ended it; with the window's length.
fn windows(wt: &WheelTrack) -> (f64, Vec<Window>) {
    let tg = wt.tg;
    // A slow receiver's window spans three of its periods (four fixes).
    let period = wt.max_gap / MAX_GAP_PERIODS;
    let window = WINDOW_S.max(3.0 * period);
    let mut out = Vec::new();
    let mut i = 0;
    while i + 1 < tg.len() {
        let mut j = i;
        while j + 1 < tg.len()
            && tg[j + 1] - tg[i] <= window + 0.25 * period
            && tg[j + 1] - tg[j] <= wt.max_gap
        {
            j += 1;
        }
        let (a, b) = (tg[i], tg[j]);
        let wheel = (b - a >= 0.75 * window)
            .then(|| wt.wheel_regular(a, b))
            .flatten();
        let wheel_m = wheel.as_ref().and_then(|_| wt.wheel_between(i, j));
        out.push(Window {
            from_s: a,
            to_s: b,
            wheel: wheel_m.and(wheel),
            wheel_m,
        });
        i = if j > i { j } else { i + 1 };
    }
    (window, out)
}

/// Whether most of the fixes from `a` to `b` s repeat the one before exactly: a receiver or
/// recorder that holds its last fix through an outage, not a wheel speed that sticks.
fn repeats_fixes(wt: &WheelTrack, a: f64, b: f64) -> bool {
    let lo = wt.tg.partition_point(|t| *t < a);
    let hi = wt.tg.partition_point(|t| *t <= b);
    let repeated = (lo.max(1)..hi)
        .filter(|&k| wt.east[k] == wt.east[k - 1] && wt.north[k] == wt.north[k - 1])
        .count();
    hi > lo + 1 && 2 * repeated > hi - lo
}

/// Least spacing of the points along a window's track, s: on a turn at speed the chord
/// between points 0.5 s apart is within a per cent of the arc.
const TRACK_POINT_S: f64 = 0.5;

/// The track at any time: the median of the fixes within half a second (at least
/// [`MAX_GAP_PERIODS`] of the receiver's periods: five fixes) of it, so that a fast receiver's
/// white noise averages out and a fix or two far off the track move nothing; measured between
/// two times as a straight line or a length.
struct TrackMeasure<'a> {
    wt: &'a WheelTrack<'a>,
    /// Half the span of the fixes a point is the median of, s.
    half_s: f64,
    /// Spacing of the points of [`Self::length`], s.
    spacing_s: f64,
}

impl<'a> TrackMeasure<'a> {
    fn new(wt: &'a WheelTrack<'a>) -> Self {
        Self {
            wt,
            half_s: TRACK_POINT_S.max(wt.max_gap),
            spacing_s: TRACK_POINT_S.max(wt.max_gap),
        }
    }

    /// The track at `t`, s: the median east and north of the fixes within `half_s`, or the
    /// nearest fix when none is.
    fn point(&self, t: f64) -> (f64, f64) {
        let wt = self.wt;
        let lo = wt.tg.partition_point(|x| *x < t - self.half_s);
        let hi = wt.tg.partition_point(|x| *x <= t + self.half_s);
        if hi > lo {
            return (
                median(&mut wt.east[lo..hi].to_vec()),
                median(&mut wt.north[lo..hi].to_vec()),
            );
        }
        let k = wt.tg.partition_point(|x| *x < t).min(wt.tg.len() - 1);
        let k = if k > 0 && t - wt.tg[k - 1] < wt.tg[k] - t {
            k - 1
        } else {
            k
        };
        (wt.east[k], wt.north[k])
    }

    /// The straight line from the track at `a` to the track at `b`, m.
    fn line(&self, a: f64, b: f64) -> f64 {
        let (p, q) = (self.point(a), self.point(b));
        (q.0 - p.0).hypot(q.1 - p.1)
    }

    /// The length of the track from `a` to `b`: the polyline through its points every
    /// [`TRACK_POINT_S`] (or the receiver's [`MAX_GAP_PERIODS`] periods if longer). A standing
    /// car's noise lengthens it by a metre or two in a window (at 2 Hz with 0.6 m of white
    /// noise, fix by fix: 6 m).
    fn length(&self, a: f64, b: f64) -> f64 {
        let steps = ((b - a) / self.spacing_s).round().max(1.0) as usize;
        let mut last = self.point(a);
        let mut length = 0.0;
        for m in 1..=steps {
            let p = self.point(a + (b - a) * m as f64 / steps as f64);
            length += (p.0 - last.0).hypot(p.1 - last.1);
            last = p;
        }
        length
    }
}

/// Chords refused in a row before a stretch's start counts as an outlier itself.
const MAX_REFUSED_CHORDS: usize = 3;

/// A reverse command (`input_vel` below this, m/s) held ...
pub const REVERSE_COMMAND_MPS: f64 = -0.3;
/// ... this long has been taken by any car's speed loop, s: eq 5's 0.42 s delay and 1.2 s time
/// constant twice over; the wheel speed is negative from there on.
pub const REVERSE_SETTLE_S: f64 = 3.0;
/// A car rolling forward when reverse is asked for first brakes to a stop, at least this hard,
/// m/s^2 (the settling starts after it).
const REVERSE_BRAKING_MPS2: f64 = 2.0;
/// Shortest stretch after the settling that is judged, s.
const REVERSE_JUDGED_S: f64 = 0.5;

/// A wheel speed without its sign (black-box probe: a `vel` that is the speed's magnitude,
/// positive while the car reversed 12 m under a signed `input_vel`, gave a speed delay of
/// 0.20 s instead of 0.84 and a training fit of 83.4 %, exit 0 and no note, and the validation
/// on a drive without reversing hid it). The log schema's `vel` is negative in reverse; a wheel
/// speed sensor that reports a magnitude keeps it positive. Each stretch of `e` where
/// `input_vel` has asked for reverse (below [`REVERSE_COMMAND_MPS`]) for more than
/// [`REVERSE_SETTLE_S`] (and the time to brake from the speed it started at) is judged over
/// the rest of the stretch (at least [`REVERSE_JUDGED_S`]): a wheel speed never below
/// -0.1 m/s whose median is above [`MOVING`] is not the schema's. `None` when every such
/// stretch goes backwards, or there is none.
pub fn unsigned_reverse(e: &super::preprocess::Experiment) -> Option<String> {
    let settle = (REVERSE_SETTLE_S / e.ts_s).round() as usize;
    let judged = (REVERSE_JUDGED_S / e.ts_s).round() as usize;
    let n = e.len().min(e.vel.len()).min(e.input_vel.len());
    let mut found: Vec<(f64, f64, f64, f64)> = Vec::new();
    let mut k = 0;
    while k < n {
        if e.input_vel[k] >= REVERSE_COMMAND_MPS {
            k += 1;
            continue;
        }
        let start = k;
        while k < n && e.input_vel[k] < REVERSE_COMMAND_MPS {
            k += 1;
        }
        // A car still rolling forward first brakes to a stop.
        let braking = (e.vel[start].max(0.0) / REVERSE_BRAKING_MPS2 / e.ts_s).round() as usize;
        if k - start < settle + braking + judged {
            continue;
        }
        let tail = start + settle + braking..k;
        let mut vel = e.vel[tail.clone()].to_vec();
        if vel.iter().any(|v| *v < -0.1) {
            continue;
        }
        let median = median(&mut vel);
        if median > MOVING {
            let command = e.input_vel[tail.clone()].iter().sum::<f64>() / tail.len() as f64;
            found.push((e.t[start], e.t[k - 1], command, median));
        }
    }
    let &(t0, t1, command, median) = found.first()?;
    Some(format!(
        "`vel` stays positive while `input_vel` asks for reverse (t = {t0:.1} to {t1:.1} s: \
         `input_vel` {command:.2} m/s, `vel` {median:+.2} m/s once the speed loop had taken it; \
         {} such stretch(es)): the wheel speed looks unsigned (its magnitude); the log schema's `vel` is \
         negative in reverse: give it the sign of the direction of travel, or cut the reversing \
         out",
        found.len()
    ))
}

/// Latency of the fixes behind the wheel speed that is named, s: a receiver's own (u-blox
/// and NovAtel data sheets: 20-100 ms) passes unremarked; and it is named only at this many
/// standard errors from 0, and beyond what the interval between fixes leaves unresolved
/// ([`gnss_latency_named_above_s`]).
pub const GNSS_LATENCY_NOTE_S: f64 = 0.1;
/// See [`GNSS_LATENCY_NOTE_S`].
pub const GNSS_LATENCY_SIGMAS: f64 = 4.0;
/// How much of the interval between fixes a lag from [`gnss_latency`] may be off by, either
/// way, whatever the noise: half. The track knows the car's distance only at its fixes; between
/// two of them it is the grid's straight line, its speed the mean over the interval, so a
/// change of speed anywhere within an interval changes only that mean. For a step of the wheel
/// speed by `d` at a share `p` of the interval `T`, the wheel speed shifted so that its step
/// falls at a share `u` of the same interval leaves a residual of `d^2 T (u (1 - p)^2 + (1 - u)
/// p^2)` there, linear in `u`: least at the interval's nearer end, a lag off by `p T` or
/// `(1 - p) T`, up to `T / 2` (the filters both signals share smooth the step without moving
/// it). Speed changes at random phases to the fixes average this out; those that keep one
/// phase (a drive's commands and a receiver's fixes on whole seconds) do not, and the
/// standard error, from the residual's scatter, does not see it. A black-box probe's 1 Hz
/// receiver read 0.12 s +- 0.02 late without any latency (the VW Polo's plant with an RTK
/// receiver at 1 Hz, `turn-left` seed 16: 0.118 s +- 0.018), and such drives 0.10 to 0.16 s
/// early (`identify::tests::fixes_on_time_are_not_named_late_at_any_receiver_rate`).
pub const GNSS_LATENCY_RESOLUTION_PERIODS: f64 = 0.5;

/// The lag beyond which [`gnss_latency`]'s estimate from fixes at `gnss_rate_hz` (the log's
/// median interval) is named, s: [`GNSS_LATENCY_NOTE_S`] beyond what the interval between
/// fixes leaves unresolved ([`GNSS_LATENCY_RESOLUTION_PERIODS`]): 0.105 s at 100 Hz, 0.15 s
/// at 10 Hz, 0.6 s at 1 Hz; above the search's 1 s below 1 Hz (0.5 Hz: 1.1 s), where no lag
/// is named.
pub fn gnss_latency_named_above_s(gnss_rate_hz: f64) -> f64 {
    let interval_s = if gnss_rate_hz.is_finite() && gnss_rate_hz > 0.0 {
        1.0 / gnss_rate_hz
    } else {
        0.0
    };
    GNSS_LATENCY_NOTE_S + GNSS_LATENCY_RESOLUTION_PERIODS * interval_s
}
/// Lags searched each way, s; and, when the least residual lies at that search's edge, the
/// wider search's (fixes stamped 1.2-1.5 s late by a receiver's clock behind the logger's: a
/// black-box probe). The wider search alone takes fewer moving samples (every lag's
/// neighbourhood must move), and read a 5 Hz receiver's fixes on time as the wheel speed
/// 0.23 s late.
const GNSS_LATENCY_SEARCH_S: f64 = 1.0;
pub const GNSS_LATENCY_WIDE_SEARCH_S: f64 = 2.5;
/// Moving samples needed for a latency estimate (20 s at 50 Hz).
const GNSS_LATENCY_MIN_SAMPLES: usize = 1000;
/// The residual's errors are counted as one independent error per this long, s (the
/// lowpass's and the track's own correlation: conservative).
const GNSS_LATENCY_ERROR_S: f64 = 0.5;

/// How late the fixes are behind the wheel speed, s (positive: the track's speed changes after
/// the wheel's), with its standard error: the lag `tau` that best fits the speed along the GNSS
/// track (the filtered track's `hypot(dx, dy)`) with the wheel speed `tau` earlier times a
/// scale (the antenna's lever arm on turns, a tyre's radius), by least squares over the
/// samples where the car moves, searched to [`GNSS_LATENCY_SEARCH_S`] each way (then to
/// [`GNSS_LATENCY_WIDE_SEARCH_S`] if the least residual is at the edge) on the 20 ms
/// grid and refined between grid points by a parabola through the least residual. Both went
/// through the same filter, so it adds no lag of its own. The standard error is the
/// residual's over the wheel's acceleration, `sqrt(s^2 w / sum a^2)` with the errors
/// correlated over `w` samples ([`GNSS_LATENCY_ERROR_S`]). `None` with too few moving
/// samples or a least residual at the search's edge (black-box probe: fixes 0.3 s late,
/// timestamped at their arrival, moved the lateral model's time constant from 0.04 to 0.14 s
/// without a word).
pub fn gnss_latency(e: &super::preprocess::Experiment) -> Option<(f64, f64)> {
    gnss_latency_within(e, GNSS_LATENCY_SEARCH_S)
        .or_else(|| gnss_latency_within(e, GNSS_LATENCY_WIDE_SEARCH_S))
}

/// [`gnss_latency`] searched to `search_s` each way.
fn gnss_latency_within(e: &super::preprocess::Experiment, search_s: f64) -> Option<(f64, f64)> {
    let n = e.len().min(e.vel.len()).min(e.dx.len()).min(e.dy.len());
    let max_lag = (search_s / e.ts_s).round() as usize;
    if n < 2 * max_lag + 3 {
        return None;
    }
    let track: Vec<f64> = (0..n).map(|k| e.dx[k].hypot(e.dy[k])).collect();
    // Samples whose neighbourhood, every lag included, is moving.
    let moving: Vec<usize> = (1 + max_lag..n - 1 - max_lag)
        .filter(|&k| {
            !e.in_gnss_gap(k) && e.vel[k - max_lag..=k + max_lag].iter().all(|v| *v > MOVING)
        })
        .collect();
    if moving.len() < GNSS_LATENCY_MIN_SAMPLES {
        return None;
    }
    // The residual at a lag of `lag` samples, the scale fitted.
    let residual = |lag: isize| {
        let shifted = |k: usize| e.vel[(k as isize - lag) as usize];
        let (tw, ww) = moving.iter().fold((0.0, 0.0), |(tw, ww), &k| {
            (tw + track[k] * shifted(k), ww + shifted(k) * shifted(k))
        });
        let scale = tw / ww;
        moving
            .iter()
            .map(|&k| (track[k] - scale * shifted(k)).powi(2))
            .sum::<f64>()
    };
    let lags: Vec<f64> = (-(max_lag as isize)..=max_lag as isize)
        .map(residual)
        .collect();
    let i = (0..lags.len()).min_by(|a, b| lags[*a].total_cmp(&lags[*b]))?;
    if i == 0 || i + 1 == lags.len() || !lags[i].is_finite() {
        return None;
    }
    let (before, least, after) = (lags[i - 1], lags[i], lags[i + 1]);
    let curvature = before - 2.0 * least + after;
    let shift = if curvature > 0.0 {
        0.5 * (before - after) / curvature
    } else {
        0.0
    };
    let lag = (i as f64 - max_lag as f64 + shift) * e.ts_s;
    let accel: f64 = moving
        .iter()
        .map(|&k| ((e.vel[k + 1] - e.vel[k - 1]) / (2.0 * e.ts_s)).powi(2))
        .sum();
    let window = GNSS_LATENCY_ERROR_S / e.ts_s;
    let s2 = least / (moving.len() as f64 - 2.0);
    let std_error = (s2 * window / accel).sqrt();
    (lag.is_finite() && std_error.is_finite()).then_some((lag, std_error))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The speed model's gain names a command in km/h (1/3.6) or mph (1/2.237) by the rule that
    /// names a wheel speed's unit; a gain in range or near no unit names none.
    #[test]
    fn a_command_in_another_unit_is_named_by_the_speed_models_gain() {
        let kmh = command_unit_problem(0.2769).expect("km/h");
        assert!(
            kmh.contains("looks like km/h") && kmh.contains("by 3.6"),
            "{kmh}"
        );
        let mph = command_unit_problem(0.447).expect("mph");
        assert!(
            mph.contains("looks like mph") && mph.contains("by 2.237"),
            "{mph}"
        );
        for gain in [1.0, 0.6, 0.1, 3.6, f64::NAN] {
            assert_eq!(command_unit_problem(gain), None, "{gain}");
        }
    }

    /// A drive at `v` m/s due east for 60 s, wheel speed at 50 Hz scaled by `unit`, fixes at
    /// `rate_hz` with an alternating +-0.4 m error.
    fn drive(v: f64, unit: f64, rate_hz: f64) -> Option<SpeedScale> {
        let tv: Vec<f64> = (0..3000).map(|k| k as f64 * 0.02).collect();
        let vel = vec![v * unit; tv.len()];
        let n = (60.0 * rate_hz) as usize;
        let tg: Vec<f64> = (0..n).map(|k| k as f64 / rate_hz).collect();
        let east: Vec<f64> = tg
            .iter()
            .enumerate()
            .map(|(k, t)| v * t + if k % 2 == 0 { 0.4 } else { -0.4 })
            .collect();
        let north = vec![0.0; n];
        let wt = WheelTrack::new((&tv, &vel), (&[], &[]), &LeverArm::NONE, &tg, &east, &north)?;
        speed_scale(&wt)
    }

    /// A drive of 120 s at `v` m/s, straight or on a circle of `radius_m`, wheel speed at
    /// 50 Hz scaled by `unit`, fixes at `rate_hz` with white noise of `sigma_m` per axis.
    fn noisy_drive(
        v: f64,
        unit: f64,
        rate_hz: f64,
        sigma_m: f64,
        radius_m: Option<f64>,
        seed: u64,
    ) -> (f64, Option<SpeedScale>) {
        use crate::sim::rng::{SimRng, Stream};
        let tv: Vec<f64> = (0..6000).map(|k| k as f64 * 0.02).collect();
        let vel = vec![v * unit; tv.len()];
        let tg: Vec<f64> = (0..(120.0 * rate_hz) as usize)
            .map(|k| k as f64 / rate_hz)
            .collect();
        let mut rng = SimRng::new(seed, Stream::Gnss);
        let (mut east, mut north) = (Vec::new(), Vec::new());
        for t in &tg {
            let s = v * t;
            let (e, n) = match radius_m {
                Some(r) => (r * (s / r).sin(), r * (1.0 - (s / r).cos())),
                None => (s, 0.0),
            };
            east.push(e + sigma_m * rng.normal());
            north.push(n + sigma_m * rng.normal());
        }
        let wt = WheelTrack::new((&tv, &vel), (&[], &[]), &LeverArm::NONE, &tg, &east, &north)
            .expect("samples");
        (wt.fix_noise_m, speed_scale(&wt))
    }

    /// The unit is told on receivers of every rate and white noise up to 2 m per axis
    /// (black-box probe: a 10 Hz receiver with 2 m read 0.22 times the wheel's distance, and
    /// a log in m/s was refused as another unit), on straight roads and a circle; on a
    /// full-lock circle narrower than the noise lets chords be measured, the log is not judged
    /// rather than misread.
    #[test]
    fn the_unit_is_told_through_a_noisy_receiver() {
        for (k, rate) in [1.0, 2.0, 5.0, 10.0, 20.0, 100.0].into_iter().enumerate() {
            for sigma in [0.0, 0.3, 1.0, 2.0] {
                for (v, radius) in [
                    (3.0, None),
                    (20.0, None),
                    (8.0, Some(30.0)),
                    (2.4, Some(3.6)),
                ] {
                    let seed = k as u64 * 16 + (sigma * 4.0) as u64;
                    let case = format!("{rate} Hz, {sigma} m, {v} m/s, radius {radius:?}");
                    let (noise, s) = noisy_drive(v, 1.0, rate, sigma, radius, seed);
                    // The noise is measured from 5 Hz whatever the path (at 1 Hz the car's
                    // own motion adds to it on the circle).
                    if rate >= 5.0 {
                        assert!((noise - sigma).abs() < 0.1 + 0.1 * sigma, "{case}: {noise}");
                    }
                    let (_, kmh) = noisy_drive(v, 3.6, rate, sigma, radius, seed);
                    let (Some(s), Some(kmh)) = (s, kmh) else {
                        // Judged in one unit, judged in the other.
                        assert_eq!((s, kmh.is_some()), (None, false), "{case}");
                        assert!(radius == Some(3.6) && sigma >= 1.0, "{case}: not judged");
                        continue;
                    };
                    assert!((s.ratio - 1.0).abs() < 0.1, "{case}: {s:?}");
                    assert_eq!(s.problem(), None, "{case}");
                    assert!(
                        kmh.problem().unwrap().contains("looks like km/h"),
                        "{case}: {kmh:?}"
                    );
                }
            }
        }
    }

    /// The antenna's speed over the rear axle's is the ratio of their kinematic circles.
    #[test]
    fn the_antenna_speed_factor_is_the_ratio_of_the_kinematic_circles() {
        let bus = LeverArm {
            ahead_m: 6.5,
            left_m: 0.0,
            wheelbase_m: 5.9,
            max_steer_deg: 45.0,
        };
        // Full lock either way: the rear axle runs L / tan(45 deg) = 5.9 m, the antenna
        // hypot(5.9, 6.5) = 8.78 m.
        for steer in [100.0, -100.0] {
            let f = bus.antenna_speed_factor(steer);
            assert!((f - 5.9_f64.hypot(6.5) / 5.9).abs() < 1e-12, "{f}");
        }
        assert_eq!(bus.antenna_speed_factor(0.0), 1.0);
        assert_eq!(LeverArm::NONE.antenna_speed_factor(100.0), 1.0);
        // 1.75 m left: inside a left-hand circle (steering negative), outside a right-hand one.
        let left = LeverArm {
            ahead_m: 0.0,
            left_m: 1.75,
            ..bus
        };
        let f = left.antenna_speed_factor(-100.0);
        assert!((f - (5.9 - 1.75) / 5.9).abs() < 1e-12, "{f}");
        let f = left.antenna_speed_factor(100.0);
        assert!((f - (5.9 + 1.75) / 5.9).abs() < 1e-12, "{f}");
    }

    #[test]
    fn the_ratio_tells_the_unit() {
        for rate in [1.0, 5.0, 10.0, 100.0] {
            let s = drive(5.0, 1.0, rate).expect("judged");
            assert!((s.ratio - 1.0).abs() < 0.02, "{rate} Hz: {s:?}");
            assert_eq!(s.problem(), None);
            let kmh = drive(5.0, 3.6, rate).expect("judged");
            assert!((kmh.ratio - 3.6).abs() < 0.1, "{rate} Hz: {kmh:?}");
            assert!(
                kmh.problem().unwrap().contains("looks like km/h"),
                "{kmh:?}"
            );
            let mph = drive(5.0, 2.236_936, rate).expect("judged");
            assert!(mph.problem().unwrap().contains("looks like mph"), "{mph:?}");
        }
        // A parked car: nothing to judge by.
        assert_eq!(drive(0.0, 1.0, 10.0), None);
    }
}
