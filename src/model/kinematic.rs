//! The kinematic bicycle model of eq 8, with inputs u = [v, delta] and state z = [x, y, theta]:
//!
//! ```text
//! x' = v sin(theta)        x east, m
//! y' = v cos(theta)        y north, m
//! theta' = v tan(delta) / L  heading clockwise from north, rad
//! ```
//!
//! Discretized exactly for inputs held over a step (zero-order hold): with constant speed and
//! curvature the car drives an arc, whose chord has length `v dt sinc(dtheta / 2)` in the
//! direction `theta + dtheta / 2`. The step carries `(sin theta, cos theta)` and rotates them
//! twice by half the increment, whose sine and cosine come from short series (multiplications
//! only): no transcendental function in the horizon roll-out (|dtheta| < 0.1 rad per 20 ms step
//! even at 30 m/s on full lock, where the series' truncation is < 1e-11).
use crate::math;

/// Pose and its heading's sine and cosine (kept in step with `heading_rad`).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Pose {
    /// East, m.
    pub x_m: f32,
    /// North, m.
    pub y_m: f32,
    /// Heading clockwise from north, rad, wrapped to [-pi, pi).
    pub heading_rad: f32,
    /// sin(heading).
    pub sin_heading: f32,
    /// cos(heading).
    pub cos_heading: f32,
}

impl Pose {
    /// A pose at (x, y) with the given heading.
    pub fn new(x_m: f32, y_m: f32, heading_rad: f32) -> Self {
        let heading_rad = math::wrap_pi(heading_rad);
        let (sin_heading, cos_heading) = math::sin_cos(heading_rad);
        Self {
            x_m,
            y_m,
            heading_rad,
            sin_heading,
            cos_heading,
        }
    }

    /// Moves along an arc: speed `v_mps` held for `dt_s` with yaw increment `dtheta_rad`, and
    /// optionally a lateral (rightward) velocity `vy_mps` (the dynamic model's side slip).
    /// Accurate to f32 rounding for |dtheta_rad| <= 0.5 (see [`half_turn`]); the node's
    /// increments stay below 0.1 rad per 20 ms step.
    #[inline]
    pub fn advance(&mut self, v_mps: f32, vy_mps: f32, dtheta_rad: f32, dt_s: f32) {
        let (sinc, s_half, c_half) = half_turn(dtheta_rad);
        // Mid-step heading direction = heading rotated by half the increment.
        let sin_mid = self.sin_heading * c_half + self.cos_heading * s_half;
        let cos_mid = self.cos_heading * c_half - self.sin_heading * s_half;
        let chord_m = v_mps * dt_s * sinc;
        let side_m = vy_mps * dt_s * sinc;
        // Forward along the mid heading, and to its right: right of heading theta is the
        // direction theta + 90 deg = (cos theta, -sin theta) in (east, north).
        self.x_m += chord_m * sin_mid + side_m * cos_mid;
        self.y_m += chord_m * cos_mid - side_m * sin_mid;
        self.turn_from_mid(sin_mid, cos_mid, s_half, c_half, dtheta_rad);
    }

    /// [`Pose::advance`] without side slip (`vy_mps = 0`), the kinematic model's step.
    #[inline]
    pub fn advance_no_slip(&mut self, v_mps: f32, dtheta_rad: f32, dt_s: f32) {
        let (sinc, s_half, c_half) = half_turn(dtheta_rad);
        let sin_mid = self.sin_heading * c_half + self.cos_heading * s_half;
        let cos_mid = self.cos_heading * c_half - self.sin_heading * s_half;
        let chord_m = v_mps * dt_s * sinc;
        self.x_m += chord_m * sin_mid;
        self.y_m += chord_m * cos_mid;
        self.turn_from_mid(sin_mid, cos_mid, s_half, c_half, dtheta_rad);
    }

    /// Moves `arc_m` along a path of constant curvature `curvature_per_m` (1/m, positive =
    /// right) in one step, for a turn of any size ([`any_turn`]: the same fixed work whatever
    /// the turn). With the curvature held, eq 8's path is that circle whatever the speed
    /// profile, so this equals the per-step [`Pose::advance_no_slip`] over the same distance
    /// up to f32 rounding, at the cost of one step.
    pub fn advance_arc(&mut self, arc_m: f32, curvature_per_m: f32) {
        let turn_rad = arc_m * curvature_per_m;
        self.advance_by(arc_m, 0.0, turn_rad, any_turn(turn_rad));
    }

    /// Moves the pose over a segment driven with side slip: `forward_m` along and `side_m` to the
    /// right of the heading (the integrals of v and vy over the segment) while the heading
    /// turns by `turn_rad`, as one arc with the forward and side components held, in one step
    /// for a turn of any size (as [`Pose::advance_arc`]). Over a segment whose yaw rate and
    /// slip vary (a transient), it differs from stepping [`Pose::advance`] per sample to first
    /// order in that variation; the predictor adds that first-order term back
    /// ([`Pose::shift_right`], `predictor::rollout`).
    pub fn advance_segment(&mut self, forward_m: f32, side_m: f32, turn_rad: f32) {
        self.advance_by(forward_m, side_m, turn_rad, any_turn(turn_rad));
    }

    /// The arc step: `forward_m` and `side_m` held while turning `turn_rad`, with the turn's
    /// `(sinc, sin, cos)` of half the turn.
    #[inline(always)]
    fn advance_by(
        &mut self,
        forward_m: f32,
        side_m: f32,
        turn_rad: f32,
        (sinc, s_half, c_half): (f32, f32, f32),
    ) {
        let sin_mid = self.sin_heading * c_half + self.cos_heading * s_half;
        let cos_mid = self.cos_heading * c_half - self.sin_heading * s_half;
        let chord_m = forward_m * sinc;
        let side_m = side_m * sinc;
        self.x_m += chord_m * sin_mid + side_m * cos_mid;
        self.y_m += chord_m * cos_mid - side_m * sin_mid;
        self.turn_from_mid(sin_mid, cos_mid, s_half, c_half, turn_rad);
    }

    /// Moves the position `right_m` to the right of the current heading (negative: left).
    #[inline]
    pub fn shift_right(&mut self, right_m: f32) {
        // Right of heading theta (clockwise from north) is (cos theta, -sin theta) in (east, north).
        self.x_m += right_m * self.cos_heading;
        self.y_m -= right_m * self.sin_heading;
    }

    /// The end-of-step heading: the mid-step direction rotated by the second half increment.
    #[inline(always)]
    fn turn_from_mid(&mut self, sin_mid: f32, cos_mid: f32, s_half: f32, c_half: f32, d: f32) {
        let sin_new = sin_mid * c_half + cos_mid * s_half;
        let cos_new = cos_mid * c_half - sin_mid * s_half;
        // One Newton step towards unit norm, 1/sqrt(n) ~ (3 - n) / 2 near n = 1: keeps f32
        // rounding from accumulating over long roll-outs without a square root.
        let fix = 0.5 * (3.0 - (sin_new * sin_new + cos_new * cos_new));
        self.sin_heading = sin_new * fix;
        self.cos_heading = cos_new * fix;
        self.heading_rad = math::wrap_pi(self.heading_rad + d);
    }
}

/// 1/n! rounded to f32, for the short series below.
const INV_6: f32 = 1.0 / 6.0;
const INV_12: f32 = 1.0 / 12.0;
const INV_20: f32 = 1.0 / 20.0;
const INV_30: f32 = 1.0 / 30.0;
const INV_42: f32 = 1.0 / 42.0;

/// For a yaw increment `d` (|d| <= 0.5 rad), with a = d / 2: `(sin(a) / a, sin a, cos a)` by
/// their Taylor series to a^6 / 7! and a^6 / 6!; truncation < 5e-11 and < 4e-10 at
/// |a| = 0.25, < 1e-15 at the node's |a| <= 0.05 (f32 rounding dominates; see tests).
/// Multiplications only, no division.
#[inline(always)]
pub fn half_turn(d: f32) -> (f32, f32, f32) {
    let a = 0.5 * d;
    let a2 = a * a;
    let sinc = 1.0 - a2 * INV_6 * (1.0 - a2 * INV_20 * (1.0 - a2 * INV_42));
    let c = 1.0 - 0.5 * a2 * (1.0 - a2 * INV_12 * (1.0 - a2 * INV_30));
    (sinc, a * sinc, c)
}

/// [`half_turn`] where its series is accurate (|d| <= 0.5 rad), the exact half-angle sine and
/// cosine beyond ([`math::sin_cos`], |d / 2| > 0.25 so the division is safe): one step for a
/// turn of any size, a fixed amount of work on either branch. Non-finite `d` gives NaN.
#[inline(always)]
pub fn any_turn(d: f32) -> (f32, f32, f32) {
    if d.abs() <= 0.5 {
        return half_turn(d);
    }
    let a = 0.5 * d;
    let (s, c) = math::sin_cos_inlined(a);
    (s / a, s, c)
}

/// Yaw rate of eq 8, `v tan(delta) / L`, rad/s, given the path curvature `tan(delta) / L`.
#[inline]
pub fn yaw_rate_rps(speed_mps: f32, curvature_per_m: f32) -> f32 {
    speed_mps * curvature_per_m
}

/// One step of eq 8: inputs speed (m/s) and path curvature `tan(delta) / L` (1/m) held for
/// `dt_s`. Returns the yaw rate used, rad/s.
pub fn step(pose: &mut Pose, speed_mps: f32, curvature_per_m: f32, dt_s: f32) -> f32 {
    let yaw_rate = yaw_rate_rps(speed_mps, curvature_per_m);
    pose.advance_no_slip(speed_mps, yaw_rate * dt_s, dt_s);
    yaw_rate
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against f64 over |d| <= 0.5: the series' truncation is below f32 rounding.
    #[test]
    fn half_turn_is_accurate_over_its_range() {
        let mut worst = [0.0f64; 3];
        for i in -50_000..=50_000 {
            let d = i as f32 * 1e-5;
            let a = 0.5 * d as f64;
            let (sinc, s, c) = half_turn(d);
            let exact_sinc = if a == 0.0 { 1.0 } else { a.sin() / a };
            worst[0] = worst[0].max((sinc as f64 - exact_sinc).abs());
            worst[1] = worst[1].max((s as f64 - a.sin()).abs());
            worst[2] = worst[2].max((c as f64 - a.cos()).abs());
        }
        // f32 rounding near 1 is 6e-8 (half an ulp), a few roundings in the Horner chain.
        assert!(
            worst[0] < 1.2e-7 && worst[1] < 6e-8 && worst[2] < 1.2e-7,
            "{worst:?}"
        );
        assert_eq!(half_turn(0.0), (1.0, 0.0, 1.0));
    }

    /// A full circle of radius R = 1 / kappa returns to the start, exactly on the circle.
    #[test]
    fn constant_curvature_drives_a_circle() {
        let radius_m = 8.0f32;
        let speed = 5.0f32;
        let dt = 0.02f32;
        let mut pose = Pose::new(0.0, 0.0, 0.0);
        let steps = (2.0 * core::f32::consts::PI * radius_m / speed / dt).round() as usize;
        let mut max_off = 0.0f32;
        for _ in 0..steps {
            step(&mut pose, speed, 1.0 / radius_m, dt);
            // Right turn from heading north: centre at (R, 0).
            let r = ((pose.x_m - radius_m).powi(2) + pose.y_m.powi(2)).sqrt();
            max_off = max_off.max((r - radius_m).abs());
        }
        assert!(max_off < 1e-3, "left the circle by {max_off} m");
        assert!(pose.x_m.abs() < 0.05 && pose.y_m.abs() < 0.05, "{pose:?}");
        let norm = pose.sin_heading.powi(2) + pose.cos_heading.powi(2);
        assert!((norm - 1.0).abs() < 1e-5);
    }

    /// One arc equals many small steps on the same circle, for small and large turns.
    #[test]
    fn advance_arc_matches_small_steps() {
        for (speed, kappa) in [(5.0f32, 0.1f32), (20.0, -0.05), (40.0, 0.27), (3.0, 0.0)] {
            let mut stepped = Pose::new(1.0, -2.0, 0.3);
            let mut arc = stepped;
            let dt = 0.02;
            for _ in 0..10 {
                step(&mut stepped, speed, kappa, dt);
            }
            arc.advance_arc(10.0 * speed * dt, kappa);
            let d = ((stepped.x_m - arc.x_m).powi(2) + (stepped.y_m - arc.y_m).powi(2)).sqrt();
            assert!(
                d < 2e-5 * (1.0 + speed),
                "{speed} {kappa}: {stepped:?} {arc:?}"
            );
            assert!(
                (stepped.heading_rad - arc.heading_rad).abs() < 1e-5,
                "{stepped:?} {arc:?}"
            );
            assert!((stepped.sin_heading - arc.sin_heading).abs() < 1e-5);
        }
        // Half a circle of radius 4 m in one call (turn pi): ends 8 m to the east (right turn
        // from north), heading south.
        let mut p = Pose::new(0.0, 0.0, 0.0);
        p.advance_arc(4.0 * core::f32::consts::PI, 0.25);
        assert!((p.x_m - 8.0).abs() < 1e-4 && p.y_m.abs() < 1e-4, "{p:?}");
        assert!((p.cos_heading + 1.0).abs() < 1e-6, "{p:?}");
    }

    /// Straight line: heading east at 10 m/s for 1 s moves 10 m east, nothing north.
    #[test]
    fn straight_line_heading_east() {
        let mut pose = Pose::new(1.0, 2.0, core::f32::consts::FRAC_PI_2);
        for _ in 0..50 {
            step(&mut pose, 10.0, 0.0, 0.02);
        }
        assert!(
            (pose.x_m - 11.0).abs() < 1e-4 && (pose.y_m - 2.0).abs() < 1e-4,
            "{pose:?}"
        );
    }
}
