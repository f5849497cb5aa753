//! Vehicle geometry and the steering conversion of paper II-C: steering percent -> angle of an
//! imaginary centre tyre -> radius of curvature (eq 2) -> Ackermann inner/outer wheel angles
//! (eq 3, eq 4).
//!
//! Sign convention, everywhere in catmodel: positive steering is a right turn (paper, circle
//! experiments), and heading is measured clockwise from north, so a right turn makes the heading
//! grow. Curvatures and yaw rates carry that sign.
//!
//! Eq 2 as printed, `r = tan(delta / (1 + 0.0015 v^2)) / L`, is a curvature (1/m), not a radius:
//! the CAT Vehicle software it comes from ("from TORC") computes
//! `R = L / tan(delta / (1 + 0.0015 v^2))`. We implement the physically consistent form, where
//! the speed term is an understeer correction: the faster the car, the larger the radius for the
//! same steering.
use crate::image::{Image, ImageError, ImageReader, ImageWriter};
use crate::math;

/// Geometry and steering of a car. Immutable configuration.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct VehicleParams {
    /// Wheelbase L, m.
    pub wheelbase_m: f32,
    /// Track (tread) T, m.
    pub track_m: f32,
    /// Centre-tyre angle at 100 % steering, rad.
    pub max_steer_rad: f32,
    /// Understeer term K of eq 2: delta_eff = delta / (1 + K v^2), s^2/m^2.
    pub understeer_s2_per_m2: f32,
}

/// The CAT Vehicle (Ford Escape Hybrid), as a test reference: L = 2.62 m and T = 1.55 m
/// (CAT Vehicle ROS package), 100 % = 35.5 deg at the imaginary centre tyre and
/// K = 0.0015 s^2/m^2 (paper II-C, eq 2). The node's numbers come from the model file.
#[cfg(test)]
pub(crate) const CAT_VEHICLE: VehicleParams = VehicleParams {
    wheelbase_m: 2.62,
    track_m: 1.55,
    max_steer_rad: 35.5 * core::f32::consts::PI / 180.0,
    understeer_s2_per_m2: 0.0015,
};

/// The car's body around the rear axle (the reference point of eq 8): what must stay inside a
/// corridor and clear of obstacles. Immutable configuration, from the model file's `[vehicle]`.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Body {
    /// Overall width, m (mirrors folded).
    pub width_m: f32,
    /// Overall length, m.
    pub length_m: f32,
    /// Rear bumper behind the rear axle, m.
    pub rear_overhang_m: f32,
}

impl Image for VehicleParams {
    fn write(&self, w: &mut ImageWriter<'_>) {
        let Self {
            wheelbase_m,
            track_m,
            max_steer_rad,
            understeer_s2_per_m2,
        } = self;
        for v in [wheelbase_m, track_m, max_steer_rad, understeer_s2_per_m2] {
            v.write(w);
        }
    }
    fn read(r: &mut ImageReader<'_>) -> Result<Self, ImageError> {
        Ok(Self {
            wheelbase_m: f32::read(r)?,
            track_m: f32::read(r)?,
            max_steer_rad: f32::read(r)?,
            understeer_s2_per_m2: f32::read(r)?,
        })
    }
}

impl Image for Body {
    fn write(&self, w: &mut ImageWriter<'_>) {
        let Self {
            width_m,
            length_m,
            rear_overhang_m,
        } = self;
        for v in [width_m, length_m, rear_overhang_m] {
            v.write(w);
        }
    }
    fn read(r: &mut ImageReader<'_>) -> Result<Self, ImageError> {
        Ok(Self {
            width_m: f32::read(r)?,
            length_m: f32::read(r)?,
            rear_overhang_m: f32::read(r)?,
        })
    }
}

/// Steering percent accepted by [`VehicleParams::steer_pct_to_center_rad`]: the car reports
/// -100..100 %.
pub const STEER_PCT_LIMIT: f32 = 100.0;

/// Front wheel angles from Ackermann geometry (eq 3, eq 4), rad, with the sign of the turn.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct WheelAngles {
    /// Inner wheel (the right wheel in a right turn), eq 3.
    pub inner_rad: f32,
    /// Outer wheel, eq 4.
    pub outer_rad: f32,
    /// Left front wheel.
    pub left_rad: f32,
    /// Right front wheel.
    pub right_rad: f32,
}

impl VehicleParams {
    /// Centre-tyre angle from steering percent, `delta = 35.5 deg / 100 * p_m` (paper II-C),
    /// rad. The input is clamped to +-100 % (the car's range); a non-finite input gives 0
    /// (straight ahead) so that no NaN can propagate: callers validate before (the bus codec
    /// rejects such values and counts them).
    pub fn steer_pct_to_center_rad(&self, steer_pct: f32) -> f32 {
        if !steer_pct.is_finite() {
            return 0.0;
        }
        steer_pct.clamp(-STEER_PCT_LIMIT, STEER_PCT_LIMIT) / STEER_PCT_LIMIT * self.max_steer_rad
    }

    /// Understeer-corrected centre angle `delta / (1 + K v^2)` (the argument of tan in eq 2),
    /// rad; `speed_mps` is the speed over ground, m/s.
    pub fn effective_steer_rad(&self, center_rad: f32, speed_mps: f32) -> f32 {
        center_rad / (1.0 + self.understeer_s2_per_m2 * speed_mps * speed_mps)
    }

    /// Signed path curvature `tan(delta / (1 + K v^2)) / L`, 1/m (eq 2 as printed, which is
    /// this curvature); positive = turning right. Exactly 0 for delta = 0.
    pub fn curvature_per_m(&self, center_rad: f32, speed_mps: f32) -> f32 {
        math::tan(self.effective_steer_rad(center_rad, speed_mps)) / self.wheelbase_m
    }

    /// Radius of curvature of the rear-axle centre `R = L / tan(delta / (1 + K v^2))`, m
    /// (eq 2, physically consistent form; see the module doc). Signed like the steering;
    /// `None` when driving straight (delta = 0: infinite radius).
    pub fn radius_m(&self, center_rad: f32, speed_mps: f32) -> Option<f32> {
        let tan_delta = math::tan(self.effective_steer_rad(center_rad, speed_mps));
        if tan_delta == 0.0 || !tan_delta.is_finite() {
            return None;
        }
        Some(self.wheelbase_m / tan_delta)
    }

    /// Ackermann front wheel angles for a turn of radius `|radius_m|` (eq 3, eq 4):
    /// `delta_i = atan(L / (r - T/2))`, `delta_o = atan(L / (r + T/2))`, both with the sign of
    /// the turn. `None` radius (straight ahead) gives all zeros exactly.
    ///
    /// Eq 3 needs r > T/2; a radius inside the inner wheel's track (not reachable with 35.5 deg
    /// on this car: R_min = 3.67 m) is handled by atan2, which keeps the inner wheel angle
    /// continuous beyond 90 deg instead of flipping sign.
    pub fn ackermann(&self, radius_m: Option<f32>) -> WheelAngles {
        let Some(r_signed) = radius_m.filter(|r| r.is_finite() && *r != 0.0) else {
            return WheelAngles {
                inner_rad: 0.0,
                outer_rad: 0.0,
                left_rad: 0.0,
                right_rad: 0.0,
            };
        };
        let sign = if r_signed > 0.0 { 1.0 } else { -1.0 };
        let r = r_signed * sign;
        let half_track_m = 0.5 * self.track_m;
        let inner_rad = sign * math::atan2(self.wheelbase_m, r - half_track_m);
        let outer_rad = sign * math::atan2(self.wheelbase_m, r + half_track_m);
        // In a right turn (sign > 0) the right wheel is the inner one.
        let (left_rad, right_rad) = if sign > 0.0 {
            (outer_rad, inner_rad)
        } else {
            (inner_rad, outer_rad)
        };
        WheelAngles {
            inner_rad,
            outer_rad,
            left_rad,
            right_rad,
        }
    }

    /// The whole conversion of paper II-C: steering percent and speed -> wheel angles.
    pub fn wheel_angles(&self, steer_pct: f32, speed_mps: f32) -> WheelAngles {
        let center_rad = self.steer_pct_to_center_rad(steer_pct);
        self.ackermann(self.radius_m(center_rad, speed_mps))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Hand-derived: 50 % = 17.75 deg; at v = 0, R = 2.62 / tan(17.75 deg) = 2.62 / 0.320134
    /// = 8.18488 m; inner = atan(2.62 / (8.18488 - 0.775)) = atan(0.353590) = 19.4727 deg,
    /// outer = atan(2.62 / 8.95988) = atan(0.292414) = 16.2997 deg.
    #[test]
    fn half_right_at_standstill_matches_hand_computation() {
        let p = CAT_VEHICLE;
        let center = p.steer_pct_to_center_rad(50.0);
        assert!((center.to_degrees() - 17.75).abs() < 1e-4);
        let r = p.radius_m(center, 0.0).unwrap();
        assert!((r - 8.18488).abs() < 1e-3, "{r}");
        let w = p.ackermann(Some(r));
        assert!((w.inner_rad.to_degrees() - 19.4727).abs() < 1e-3, "{w:?}");
        assert!((w.outer_rad.to_degrees() - 16.2997).abs() < 1e-3, "{w:?}");
        assert_eq!(w.right_rad, w.inner_rad);
        assert_eq!(w.left_rad, w.outer_rad);
    }

    /// Left turn is the mirror image of the right turn, left wheel inner.
    #[test]
    fn left_turn_mirrors_right_turn() {
        let p = CAT_VEHICLE;
        let right = p.wheel_angles(40.0, 5.0);
        let left = p.wheel_angles(-40.0, 5.0);
        assert_eq!(left.inner_rad, -right.inner_rad);
        assert_eq!(left.left_rad, -right.right_rad);
        assert!(left.left_rad.abs() > left.right_rad.abs());
    }

    #[test]
    fn straight_ahead_is_exact() {
        let p = CAT_VEHICLE;
        assert_eq!(p.radius_m(0.0, 10.0), None);
        assert_eq!(p.curvature_per_m(0.0, 10.0), 0.0);
        let w = p.wheel_angles(0.0, 10.0);
        assert_eq!(
            (w.inner_rad, w.outer_rad, w.left_rad, w.right_rad),
            (0.0, 0.0, 0.0, 0.0)
        );
    }

    /// Hand-derived understeer: at 10 m/s, 1 + 0.0015 * 100 = 1.15, so 100 % = 35.5 / 1.15 =
    /// 30.8696 deg and R = 2.62 / tan(30.8696 deg) = 2.62 / 0.597768 = 4.38298 m.
    #[test]
    fn understeer_widens_the_radius_with_speed() {
        let p = CAT_VEHICLE;
        let center = p.steer_pct_to_center_rad(100.0);
        let r0 = p.radius_m(center, 0.0).unwrap();
        let r10 = p.radius_m(center, 10.0).unwrap();
        assert!((r0 - 2.62 / 35.5f32.to_radians().tan()).abs() < 1e-4);
        assert!((r10 - 4.38298).abs() < 1e-3, "{r10}");
        assert!((p.curvature_per_m(center, 10.0) * r10 - 1.0).abs() < 1e-6);
    }

    #[test]
    fn bad_steering_input_never_makes_nan() {
        let p = CAT_VEHICLE;
        for pct in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 1e30, -1e30] {
            let w = p.wheel_angles(pct, 5.0);
            assert!(
                w.inner_rad.is_finite() && w.outer_rad.is_finite(),
                "{pct}: {w:?}"
            );
        }
        assert_eq!(p.steer_pct_to_center_rad(250.0), p.max_steer_rad);
    }
}
