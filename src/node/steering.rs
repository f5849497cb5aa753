//! The steering's effect on the yaw rate, checked against GNSS while the car drives.
//!
//! Every yaw rate the node uses (the dead reckoning's, the predictions', the controllers'
//! plans) comes from the model file: the steering percent times `max_steer_deg` and the
//! `[lateral] steer_gain` is the centre tyre's angle, and the lateral model turns that into a
//! yaw rate. A file that overstates the steering (a steering ratio measured wrong, another
//! car's file, a worn rack) makes the dead-reckoned heading turn faster than the car between
//! GNSS corrections, the heading settles off the truth by what the corrections cannot take
//! back, and a controller that believes its steering is stronger than it is leaves the path:
//! with the steering 20 % weaker than declared, 2 m off at 12 m/s while reporting "tracking"
//! (docs/findings.md).
//!
//! The check: over blocks of [`BLOCK_S`] of driving, the heading change the GNSS course
//! measured (the estimator's heading before its correction plus the error it measured,
//! [`super::estimator::EstimatorState::correct_heading_on_track`]) against the turn the
//! lateral model integrated from the steering as the model file gives it. A weighted
//! least-squares fit of `measured = gain * modelled + curvature_offset * distance` over the
//! blocks, each weighted by its speed squared up to [`FULL_WEIGHT_SPEED_MPS`] (a course's error
//! goes as 1 / the chord's length), with exponential forgetting ([`FORGET_S`]) and a prior at
//! the file's gain: the offset term takes a steering sensor's zero error (a constant
//! curvature), so that it is not read as a gain; a steady circle, where turn and distance are
//! proportional, leaves the two apart undetermined, and the gain's information (its
//! variance's inverse with the offset marginalised) stays low. The gain's standard deviation
//! comes from the residuals' scatter. When the information reaches [`MIN_INFO_RAD2`], after
//! [`MIN_BLOCKS`] blocks, and the gain is more than [`ENGAGE`] and [`MIN_SIGMAS`] standard
//! deviations off 1, the node uses it: every steering angle it reads is scaled by it before
//! the models, and the controllers' lock and rate with it (their commands divided by it);
//! NODE_STATUS says `steering_mismatch` while it does. A negative gain is a steering reported
//! with the other sign: the models take it as well (the estimate turns as the car does), and
//! the controllers stop the car (CONTROL_COMMAND `fallback_reason` `steering_reversed`),
//! since the commands' sign may be as wrong as the report's. Within [`RELEASE`] of 1 again the
//! file's steering is used as it is. A car whose model file is right does not engage it
//! (measured: 3.0 standard deviations at most over the accuracy bar's drives and the
//! closed-loop rig's, docs/findings.md): its frames are those of a node without the check.
use crate::math;

/// Length of a block of driving the fit takes as one observation, s.
pub const BLOCK_S: f32 = 1.0;
/// Time constant of the fit's forgetting, s: blocks this old weigh 1/e.
pub const FORGET_S: f32 = 60.0;
/// The prior's weight on the file's gain (1), as modelled turn squared, rad^2.
pub const PRIOR_TURN_RAD2: f32 = 0.1;
/// The prior's weight on no curvature offset, as distance squared, m^2.
pub const PRIOR_DISTANCE_M2: f32 = 100.0;
/// The gain's information the node needs before it acts on it, rad^2.
pub const MIN_INFO_RAD2: f32 = 0.5;
/// Blocks (forgetting counted) the fit needs before it acts: the scatter of its residuals is
/// the measure of the blocks' error.
pub const MIN_BLOCKS: f32 = 5.0;
/// How many standard deviations of its fit the gain must be from 1 for the node to act on it.
pub const MIN_SIGMAS: f32 = 5.0;
/// How far from 1 the gain must be for the node to use it.
pub const ENGAGE: f32 = 0.10;
/// How close to 1 the gain must come back for the node to drop it.
pub const RELEASE: f32 = 0.05;
/// The gains the node uses at most and at least: past them the file is not this car's. A
/// negative gain is the steering reported with the other sign: the node uses the same
/// magnitudes negated (the models then turn the car the way it turns), and its controllers
/// do not drive ([`SteeringCheck::reversed`]).
pub const SCALE_RANGE: (f32, f32) = (0.5, 2.0);
/// Blocks are driven at this speed or faster, m/s: below it a standard receiver's course is
/// too noisy for a block to say anything.
pub const MIN_SPEED_MPS: f32 = 4.0;
/// Blocks driven at this mean speed or faster weigh fully; slower ones as the speed squared
/// (a course's error goes as 1 / the chord's length), m/s.
pub const FULL_WEIGHT_SPEED_MPS: f32 = 10.0;
/// A block whose measured turn is further than this (plus [`OUTLIER_PER_MODELLED`] of the
/// modelled turn) from the fit's is not taken (a heading jump: a course after a multipath
/// burst), rad.
pub const OUTLIER_RAD: f32 = 0.1;
/// The share of the modelled turn a block's measured turn may be off the fit's and still be
/// taken: a steering reported with the other sign (a report positive to the left, the
/// schema's is to the right) turns the car by minus the modelled turn, 2 |modelled| off a fit
/// at the file's gain; with a half (before) every such block was an outlier, the fit never
/// saw one, and a node on such a car dead-reckoned its heading 1.7 rad off without a word
/// (docs/findings.md).
pub const OUTLIER_PER_MODELLED: f32 = 2.5;

/// A block whose lateral acceleration, the measured turn's mean rate times the speed, is above
/// this is not taken, m/s^2: the lateral model is
/// linear in the steering, the tyres are not near their grip, and there the car turns less than
/// the model says whatever the steering's scale. A magic-formula tyre of a passenger car on dry
/// asphalt (the plant's: shape 1.9, curvature -0.5, friction 0.9) gives 95 % of its linear force
/// at 4 m/s^2 and 80 % at 7.4 m/s^2. The bound sits above the 5 m/s^2 (6.25 by a file 25 % too
/// strong) of the rig's loop at 10 m/s, where a wrong steering is found
/// (`closed_loop::a_steering_weaker_than_the_model_file_says_is_found_and_used`), and below the
/// 8.5-9.8 m/s^2 of the loop at 13-14 m/s, where the car spins: there the check read the tyres'
/// saturation as a steering 0.86 times the file's, which the node used and the host advised
/// (docs/findings.md). On a slippery road the tyres leave their linear range below it; the
/// check does not know the road.
pub const LINEAR_LATERAL_MPS2: f32 = 7.0;

/// The check's state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SteeringCheck {
    /// Turn the lateral model integrated in this block, at the file's steering, rad.
    block_modelled_rad: f32,
    /// Distance driven in this block, m.
    block_distance_m: f32,
    /// Heading change measured in this block, rad.
    block_measured_rad: f32,
    /// Time in this block, s.
    block_s: f32,
    /// The heading measured last tick (a block runs while every tick has one).
    last_measured_rad: Option<f32>,
    /// The fit's sums: modelled^2, modelled * distance, distance^2, modelled * measured,
    /// distance * measured.
    sxx: f32,
    sxd: f32,
    sdd: f32,
    sxy: f32,
    sdy: f32,
    /// measured^2, and the number of blocks (both forgetting).
    syy: f32,
    blocks: f32,
    /// The fitted gain.
    gain: f32,
    /// The gain's information, rad^2.
    info_rad2: f32,
    /// The fit's residual sum of squares, rad^2.
    rss_rad2: f32,
    /// The gain in use (1: the file's steering).
    scale: f32,
    /// The gain the models used this tick (the one the turn is divided by).
    applied: f32,
}

impl Default for SteeringCheck {
    fn default() -> Self {
        Self::new()
    }
}

impl SteeringCheck {
    /// Nothing observed: the file's steering.
    pub const fn new() -> Self {
        Self {
            block_modelled_rad: 0.0,
            block_distance_m: 0.0,
            block_measured_rad: 0.0,
            block_s: 0.0,
            last_measured_rad: None,
            sxx: 0.0,
            sxd: 0.0,
            sdd: 0.0,
            sxy: 0.0,
            sdy: 0.0,
            syy: 0.0,
            blocks: 0.0,
            gain: 1.0,
            info_rad2: 0.0,
            rss_rad2: 0.0,
            scale: 1.0,
            applied: 1.0,
        }
    }

    /// The gain the models apply to the steering this tick (1 unless a mismatch is
    /// established).
    pub fn scale(&mut self) -> f32 {
        self.applied = self.scale;
        self.scale
    }

    /// The fitted gain and its information, rad^2 (the gain is 1 with none).
    pub fn fit(&self) -> (f32, f32) {
        (self.gain, self.info_rad2)
    }

    /// The fitted gain's standard deviation from the residuals' scatter; `None` before
    /// [`MIN_BLOCKS`] blocks.
    pub fn gain_std(&self) -> Option<f32> {
        let dof = self.blocks - 2.0;
        (self.blocks >= MIN_BLOCKS && self.info_rad2 > 0.0)
            .then(|| math::sqrt(self.rss_rad2 / (dof * self.info_rad2)))
    }

    /// Whether the node uses a gain other than the file's.
    pub fn mismatch(&self) -> bool {
        self.scale != 1.0
    }

    /// Whether the steering turns the car the other way than its report says: the gain in
    /// use is negative. The estimate uses it (the models turn as the car does); the
    /// controllers do not drive, since a command's sign may be as wrong as the report's.
    pub fn reversed(&self) -> bool {
        self.scale < 0.0
    }

    /// The dead reckoning turned at `yaw_rps` (from the steering scaled by the gain applied
    /// then, negative for a reversed steering) and drove at `speed_mps` for `dt_s`.
    pub fn turned(&mut self, yaw_rps: f32, speed_mps: f32, dt_s: f32) {
        self.block_modelled_rad += yaw_rps * dt_s / self.applied;
        self.block_distance_m += speed_mps * dt_s;
        self.block_s += dt_s;
    }

    /// This tick's measured heading (`None`: no course measured this tick, or too slow).
    pub fn observe(&mut self, measured_rad: Option<f32>, speed_mps: f32) {
        let measured = measured_rad.filter(|m| m.is_finite() && speed_mps >= MIN_SPEED_MPS);
        let (Some(now), Some(last)) = (measured, self.last_measured_rad) else {
            self.last_measured_rad = measured;
            self.restart_block();
            return;
        };
        self.last_measured_rad = Some(now);
        self.block_measured_rad += math::wrap_pi(now - last);
        if self.block_s < BLOCK_S {
            return;
        }
        let (x, d, y, block_s) = (
            self.block_modelled_rad,
            self.block_distance_m,
            self.block_measured_rad,
            self.block_s,
        );
        self.restart_block();
        if !(x.is_finite() && d.is_finite() && y.is_finite()) {
            return;
        }
        // The measured turn's mean rate times the speed (the model's, from a file whose
        // steering is off, would be off by as much).
        let measured_mps2 = y.abs() * d / (block_s * block_s);
        if measured_mps2 > LINEAR_LATERAL_MPS2 {
            return;
        }
        let residual = y - self.gain * x - self.offset_per_m() * d;
        if residual.abs() > OUTLIER_RAD + OUTLIER_PER_MODELLED * x.abs() {
            return;
        }
        let keep = 1.0 - BLOCK_S / FORGET_S;
        // A course's error goes as 1 / the chord's length: a block's weight as its speed^2.
        let w = {
            let share = d / (block_s * FULL_WEIGHT_SPEED_MPS);
            math::min(share * share, 1.0)
        };
        self.sxx = keep * self.sxx + w * x * x;
        self.sxd = keep * self.sxd + w * x * d;
        self.sdd = keep * self.sdd + w * d * d;
        self.sxy = keep * self.sxy + w * x * y;
        self.sdy = keep * self.sdy + w * d * y;
        self.syy = keep * self.syy + w * y * y;
        self.blocks = keep * self.blocks + 1.0;
        self.solve();
    }

    /// The fitted curvature offset, 1/m.
    fn offset_per_m(&self) -> f32 {
        let a22 = self.sdd + PRIOR_DISTANCE_M2;
        (self.sdy - self.sxd * self.gain) / a22
    }

    fn restart_block(&mut self) {
        self.block_modelled_rad = 0.0;
        self.block_distance_m = 0.0;
        self.block_measured_rad = 0.0;
        self.block_s = 0.0;
    }

    /// The normal equations with the priors, the gain, its information and the gain in use.
    fn solve(&mut self) {
        // The prior is the file's gain, 1, or for a steering found reversed its negation: the
        // file's magnitude is still the best guess of the car's.
        let prior_gain = if self.scale < 0.0 { -1.0 } else { 1.0 };
        let a11 = self.sxx + PRIOR_TURN_RAD2;
        let a12 = self.sxd;
        let a22 = self.sdd + PRIOR_DISTANCE_M2;
        let b1 = self.sxy + prior_gain * PRIOR_TURN_RAD2;
        let b2 = self.sdy;
        let det = a11 * a22 - a12 * a12;
        if det.is_nan() || det <= 0.0 {
            return;
        }
        let gain = (b1 * a22 - a12 * b2) / det;
        let offset = (a11 * b2 - a12 * b1) / det;
        if !(gain.is_finite() && offset.is_finite()) {
            return;
        }
        self.gain = gain;
        self.info_rad2 = det / a22;
        // The residuals' sum of squares, the priors' pseudo-observations included; its
        // scatter per block over the gain's information is the gain's variance.
        let rss = math::max(self.syy + PRIOR_TURN_RAD2 - gain * b1 - offset * b2, 0.0);
        self.rss_rad2 = rss;
        let dof = self.blocks - 2.0;
        let off = if gain > 1.0 { gain - 1.0 } else { 1.0 - gain };
        let significant = self.blocks >= MIN_BLOCKS
            && self.info_rad2 >= MIN_INFO_RAD2
            && off * off * self.info_rad2 * dof > MIN_SIGMAS * MIN_SIGMAS * rss;
        let engaged = self.scale != 1.0;
        self.scale = if (!engaged && significant && off > ENGAGE) || (engaged && off >= RELEASE) {
            if gain < 0.0 {
                -math::clamp(-gain, SCALE_RANGE.0, SCALE_RANGE.1)
            } else {
                math::clamp(gain, SCALE_RANGE.0, SCALE_RANGE.1)
            }
        } else {
            1.0
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Turns per block of the tests' drives, rad: within 4 m/s^2 at 10 m/s with a gain of up
    /// to 1.3, the tyres' linear range.
    const TURNS: [f32; 5] = [0.3, -0.25, 0.0, 0.2, -0.3];

    /// Drives `blocks` blocks of 1 s at 10 m/s, turning by `turn(i)` rad per block as the model
    /// says (at the gain the check applies), the car turning `true_gain` times the file's
    /// model plus `offset` 1/m; the measured heading carries `noise(i)`.
    fn drive(
        check: &mut SteeringCheck,
        blocks: usize,
        true_gain: f32,
        offset_per_m: f32,
        turn: impl Fn(usize) -> f32,
        noise: impl Fn(usize) -> f32,
    ) {
        let ticks = 50;
        let dt = BLOCK_S / ticks as f32;
        let v = 10.0;
        let mut heading = 0.0f32;
        check.observe(Some(0.0), v);
        for i in 0..blocks {
            let yaw_file = turn(i) / BLOCK_S;
            for t in 0..ticks {
                let scale = check.scale();
                check.turned(yaw_file * scale, v, dt);
                heading += (true_gain * yaw_file + offset_per_m * v) * dt;
                let n = if t + 1 == ticks { noise(i) } else { 0.0 };
                check.observe(Some(math::wrap_pi(heading + n)), v);
            }
        }
    }

    #[test]
    fn a_weaker_steering_is_found_and_used() {
        let mut check = SteeringCheck::new();
        let turns = |i: usize| TURNS[i % 5];
        drive(&mut check, 90, 0.8, 0.0, turns, |_| 0.0);
        let (gain, info) = check.fit();
        assert!((gain - 0.8).abs() < 0.02, "{gain} {check:?}");
        assert!(info > MIN_INFO_RAD2);
        assert!(check.mismatch());
        assert!((check.scale() - gain).abs() < 1e-6);
    }

    /// A steering reported with the other sign: the car turns by minus what the file's
    /// model says. Found within the blocks a weaker steering takes, used negated.
    #[test]
    fn a_reversed_steering_is_found_and_used() {
        let mut check = SteeringCheck::new();
        let turns = |i: usize| TURNS[i % 5];
        drive(&mut check, 120, -1.0, 0.0, turns, |_| 0.0);
        let (gain, _) = check.fit();
        assert!((gain + 1.0).abs() < 0.05, "{gain} {check:?}");
        assert!(check.mismatch() && check.reversed());
        assert!((check.scale() - gain).abs() < 1e-6);
    }

    #[test]
    fn the_files_steering_is_kept_within_noise_and_an_offset() {
        let mut check = SteeringCheck::new();
        let turns = |i: usize| TURNS[i % 5];
        // 0.02 rad of course error, alternating, and a zero error of 0.001 1/m (0.15 deg of
        // centre-tyre angle on a 2.6 m wheelbase).
        let noise = |i: usize| if i.is_multiple_of(2) { 0.02 } else { -0.02 };
        drive(&mut check, 120, 1.0, 0.001, turns, noise);
        let (gain, _) = check.fit();
        assert!((gain - 1.0).abs() < 0.05, "{gain}");
        assert!(!check.mismatch());
        assert_eq!(check.scale(), 1.0);
    }

    #[test]
    fn a_steady_circle_does_not_tell_a_gain_from_an_offset() {
        // A circle whose turn the file overstates by a quarter: an offset explains it as well.
        let mut check = SteeringCheck::new();
        drive(&mut check, 60, 0.8, 0.0, |_| 0.5, |_| 0.0);
        assert!(!check.mismatch(), "{:?}", check.fit());
    }

    #[test]
    fn a_mismatch_is_dropped_when_the_steering_comes_back() {
        let mut check = SteeringCheck::new();
        let turns = |i: usize| TURNS[i % 5];
        drive(&mut check, 30, 1.3, 0.0, turns, |_| 0.0);
        assert!(check.mismatch());
        drive(&mut check, 600, 1.0, 0.0, turns, |_| 0.0);
        assert!(!check.mismatch(), "{:?}", check.fit());
    }

    /// A car driven past its grip turns less than the linear model says, whatever its
    /// steering's scale: blocks above [`LINEAR_LATERAL_MPS2`] are not read as a weaker
    /// steering (the rig's loop at 14 m/s had the node use 0.86). Below it the same car is.
    #[test]
    fn a_car_past_its_grip_is_not_taken_for_a_weaker_steering() {
        let mut check = SteeringCheck::new();
        // 0.8-1.0 rad in a second at 10 m/s, one way (a block that straddles a reversal turns
        // less on average): 8-10 m/s^2 asked, 6.4-8 turned, all beyond the bound.
        let turns = |i: usize| [1.0, 0.95, 1.0, 0.9, 0.95][i % 5];
        drive(&mut check, 120, 0.8, 0.0, turns, |_| 0.0);
        assert_eq!(check.fit(), (1.0, 0.0));
        assert!(!check.mismatch());
        let gentle = |i: usize| TURNS[i % 5];
        drive(&mut check, 90, 0.8, 0.0, gentle, |_| 0.0);
        assert!(check.mismatch(), "{:?}", check.fit());
    }

    #[test]
    fn no_course_or_a_crawl_restarts_the_block() {
        let mut check = SteeringCheck::new();
        check.observe(Some(0.0), 10.0);
        check.turned(0.5, 10.0, 0.5);
        check.observe(None, 10.0);
        check.turned(0.5, 10.0, 0.6);
        check.observe(Some(0.0), 10.0);
        check.turned(0.5, 2.0, 0.6);
        check.observe(Some(0.3), 2.0);
        assert_eq!(check.fit(), (1.0, 0.0));
    }
}
