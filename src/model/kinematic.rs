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
//! direction `theta + dtheta / 2`. The step carries `(sin theta, cos theta)` and rotates them by
//! the increment with short series instead of calling sin/cos: no transcendental function in the
//! horizon roll-out (|dtheta| <= 0.2 rad per 20 ms step at 30 m/s on full lock; the 7th-order
//! truncation error there is < 3e-9).
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
    pub fn advance(&mut self, v_mps: f32, vy_mps: f32, dtheta_rad: f32, dt_s: f32) {
        let half = 0.5 * dtheta_rad;
        let (s_half, c_half) = small_sin_cos(half);
        // Mid-step heading direction = heading rotated by half the increment.
        let sin_mid = self.sin_heading * c_half + self.cos_heading * s_half;
        let cos_mid = self.cos_heading * c_half - self.sin_heading * s_half;
        let chord_m = v_mps * dt_s * sinc_small(half);
        let side_m = vy_mps * dt_s * sinc_small(half);
        // Forward along the mid heading, and to its right: right of heading theta is the
        // direction theta + 90 deg = (cos theta, -sin theta) in (east, north).
        self.x_m += chord_m * sin_mid + side_m * cos_mid;
        self.y_m += chord_m * cos_mid - side_m * sin_mid;
        let (s, c) = small_sin_cos(dtheta_rad);
        let sin_new = self.sin_heading * c + self.cos_heading * s;
        let cos_new = self.cos_heading * c - self.sin_heading * s;
        // One Newton step towards unit norm, 1/sqrt(n) ~ (3 - n) / 2 near n = 1: keeps f32
        // rounding from accumulating over long roll-outs without a square root.
        let fix = 0.5 * (3.0 - (sin_new * sin_new + cos_new * cos_new));
        self.sin_heading = sin_new * fix;
        self.cos_heading = cos_new * fix;
        self.heading_rad = math::wrap_pi(self.heading_rad + dtheta_rad);
    }
}

/// sin and cos of a small angle (|a| <= 0.25 rad) by their Taylor series to the 7th / 8th
/// order; relative error < 1e-9 in that range (see tests), so f32 rounding dominates.
#[inline]
pub fn small_sin_cos(a: f32) -> (f32, f32) {
    let a2 = a * a;
    let s = a * (1.0 - a2 / 6.0 * (1.0 - a2 / 20.0 * (1.0 - a2 / 42.0)));
    let c = 1.0 - a2 / 2.0 * (1.0 - a2 / 12.0 * (1.0 - a2 / 30.0 * (1.0 - a2 / 56.0)));
    (s, c)
}

/// sin(a) / a for small |a| (1 at a = 0), same series.
#[inline]
fn sinc_small(a: f32) -> f32 {
    let a2 = a * a;
    1.0 - a2 / 6.0 * (1.0 - a2 / 20.0 * (1.0 - a2 / 42.0))
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
    pose.advance(speed_mps, 0.0, yaw_rate * dt_s, dt_s);
    yaw_rate
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_sin_cos_is_accurate_over_its_range() {
        let mut worst = 0.0f64;
        for i in -2500..=2500 {
            let a = i as f64 * 1e-4;
            let (s, c) = small_sin_cos(a as f32);
            worst = worst
                .max((s as f64 - a.sin()).abs())
                .max((c as f64 - a.cos()).abs());
        }
        assert!(worst < 2e-7, "{worst}");
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
