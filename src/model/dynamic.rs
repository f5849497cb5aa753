//! A dynamic (linear-tyre) single-track model: lateral velocity and yaw rate driven by the front
//! wheel angle, for a longitudinal speed held over each step.
//!
//! ```text
//! vy' = -(Cf + Cr)/(m vx) vy + (-vx - (Cf lf - Cr lr)/(m vx)) r + Cf/m delta
//! r'  = -(Cf lf - Cr lr)/(Iz vx) vy - (Cf lf^2 + Cr lr^2)/(Iz vx) r + Cf lf/Iz delta
//! ```
//!
//! vy is positive to the right and r positive clockwise (a right turn), the catmodel convention.
//! The input `delta` of those equations is the tangent of the front wheel angle, not the angle
//! ([`DynamicParams::steer_input`]): the front axle's slip angle is
//! `angle - atan((vy + lf r) / vx)`, zero where `(vy + lf r) / vx = tan(angle)`, so with the
//! tangent the model's low-speed limit is eq 8's `vx tan(angle) / L` exactly, where with the
//! angle it fell 12 % short of it at 34 degrees of lock (the hybrid switch then jumped the
//! yaw rate by that much, and on a full-lock circle at 2.8 m/s the dead-reckoned heading ran
//! 0.25 rad behind the truth; docs/findings.md). Below 0.1 rad the two differ by under 0.4 %.
//!
//! Its steady state is `r = vx delta / (L + K_us vx^2)` with the understeer gradient
//! `K_us = m (Cr lr - Cf lf) / (Cf Cr L)`: for the CAT Vehicle figures (models/paper.toml `[dynamics]`) this is the
//! `0.0015 v^2` term of eq 2 (see [`DynamicParams::understeer_s2_per_m2`]).
//!
//! The model is stiff at low speed (poles ~ -(Cf + Cr)/(m vx)), so each step uses the
//! trapezoidal rule (Tustin), which is A-stable: a 2x2 solve, no exponential, no loss of
//! stability at any speed. Below [`DynamicParams::min_speed_mps`] the 1/vx terms are
//! meaningless and the model falls back to the kinematic steady state (the hybrid switch keeps
//! it out of that range anyway).
use crate::image::{Image, ImageError, ImageReader, ImageWriter};
use crate::math;

/// Mass, geometry and tyre stiffness. Immutable configuration.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DynamicParams {
    /// Mass m, kg.
    pub mass_kg: f32,
    /// Yaw moment of inertia Iz, kg m^2.
    pub yaw_inertia_kg_m2: f32,
    /// Distance from the centre of gravity to the front axle lf, m.
    pub cg_to_front_m: f32,
    /// Distance from the centre of gravity to the rear axle lr, m.
    pub cg_to_rear_m: f32,
    /// Front axle cornering stiffness Cf, N/rad.
    pub cornering_front_n_per_rad: f32,
    /// Rear axle cornering stiffness Cr, N/rad.
    pub cornering_rear_n_per_rad: f32,
    /// Below this speed the model is replaced by its kinematic limit, m/s.
    pub min_speed_mps: f32,
}

/// The CAT Vehicle's figures, as a test reference (the node's come from the model file's
/// `[dynamics]`): 1741 kg, lf 1.142 m, lr 1.478 m, Iz ~2500 kg m^2 (CAT Vehicle simulator body),
/// Cf ~80 kN/rad, Cr ~91 kN/rad (a pair consistent with the 0.0015 understeer term of eq 2).
#[cfg(test)]
pub(crate) const CAT_VEHICLE_DYNAMICS: DynamicParams = DynamicParams {
    mass_kg: 1741.0,
    yaw_inertia_kg_m2: 2500.0,
    cg_to_front_m: 1.142,
    cg_to_rear_m: 1.478,
    cornering_front_n_per_rad: 80_000.0,
    cornering_rear_n_per_rad: 91_000.0,
    min_speed_mps: MIN_SPEED_MPS,
};

/// Below this speed the single-track model's 1/vx terms make it meaningless and it is replaced
/// by its kinematic limit, m/s (a property of the model, not of a car).
pub const MIN_SPEED_MPS: f32 = 1.0;

impl Image for DynamicParams {
    fn write(&self, w: &mut ImageWriter<'_>) {
        let Self {
            mass_kg,
            yaw_inertia_kg_m2,
            cg_to_front_m,
            cg_to_rear_m,
            cornering_front_n_per_rad,
            cornering_rear_n_per_rad,
            min_speed_mps,
        } = self;
        for v in [
            mass_kg,
            yaw_inertia_kg_m2,
            cg_to_front_m,
            cg_to_rear_m,
            cornering_front_n_per_rad,
            cornering_rear_n_per_rad,
            min_speed_mps,
        ] {
            v.write(w);
        }
    }
    fn read(r: &mut ImageReader<'_>) -> Result<Self, ImageError> {
        Ok(Self {
            mass_kg: f32::read(r)?,
            yaw_inertia_kg_m2: f32::read(r)?,
            cg_to_front_m: f32::read(r)?,
            cg_to_rear_m: f32::read(r)?,
            cornering_front_n_per_rad: f32::read(r)?,
            cornering_rear_n_per_rad: f32::read(r)?,
            min_speed_mps: f32::read(r)?,
        })
    }
}

/// Lateral state.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LateralState {
    /// Lateral velocity, positive to the right, m/s.
    pub vy_mps: f32,
    /// Yaw rate, positive clockwise (right turn), rad/s.
    pub yaw_rate_rps: f32,
}

/// The largest wheel angle [`DynamicParams::steer_input`] takes, rad (80 degrees): a model
/// file's lock is below 90 degrees, but the steering check's scale may take an angle past it.
pub const MAX_STEER_ANGLE_RAD: f32 = 1.396;

impl DynamicParams {
    /// The model's input for a front wheel angle: its tangent (module doc), the angle held
    /// within [`MAX_STEER_ANGLE_RAD`]. A NaN angle stays NaN (the callers count a non-finite
    /// yaw rate).
    pub fn steer_input(delta_rad: f32) -> f32 {
        if delta_rad.is_nan() {
            return delta_rad;
        }
        math::tan(math::clamp(
            delta_rad,
            -MAX_STEER_ANGLE_RAD,
            MAX_STEER_ANGLE_RAD,
        ))
    }

    /// The rear axle's sideways velocity in `state`, `v_y - l_r r`, m/s (positive right): the
    /// rear tyres' slip, which eq 8 takes as zero.
    pub fn rear_side_mps(&self, state: &LateralState) -> f32 {
        state.vy_mps - self.cg_to_rear_m * state.yaw_rate_rps
    }

    /// Wheelbase lf + lr, m.
    pub fn wheelbase_m(&self) -> f32 {
        self.cg_to_front_m + self.cg_to_rear_m
    }

    /// Understeer gradient expressed as eq 2's K: steady-state curvature is
    /// `delta / (L (1 + K vx^2))`, K = m (Cr lr - Cf lf) / (Cf Cr L^2), s^2/m^2.
    pub fn understeer_s2_per_m2(&self) -> f32 {
        let l = self.wheelbase_m();
        self.mass_kg
            * (self.cornering_rear_n_per_rad * self.cg_to_rear_m
                - self.cornering_front_n_per_rad * self.cg_to_front_m)
            / (self.cornering_front_n_per_rad * self.cornering_rear_n_per_rad * l * l)
    }

    /// Steady state for a speed and front wheel angle (the initial condition after a switch
    /// from the kinematic model).
    pub fn steady_state(&self, vx_mps: f32, delta_rad: f32) -> LateralState {
        self.steady_state_of_input(vx_mps, Self::steer_input(delta_rad))
    }

    /// [`DynamicParams::steady_state`] for the model's input `u` ([`DynamicParams::steer_input`]).
    fn steady_state_of_input(&self, vx_mps: f32, u: f32) -> LateralState {
        let l = self.wheelbase_m();
        let k = self.understeer_s2_per_m2();
        let r = vx_mps * u / (l * (1.0 + k * vx_mps * vx_mps));
        if vx_mps < self.min_speed_mps {
            return LateralState {
                vy_mps: r * self.cg_to_rear_m,
                yaw_rate_rps: r,
            };
        }
        // From the r' = 0 row: vy = (Cf lf u vx - (Cf lf^2 + Cr lr^2) r) / (Cf lf - Cr lr).
        let cf = self.cornering_front_n_per_rad;
        let cr = self.cornering_rear_n_per_rad;
        let (lf, lr) = (self.cg_to_front_m, self.cg_to_rear_m);
        let denom = cf * lf - cr * lr;
        let vy = if denom != 0.0 {
            (cf * lf * u * vx_mps - (cf * lf * lf + cr * lr * lr) * r) / denom
        } else {
            0.0
        };
        LateralState {
            vy_mps: vy,
            yaw_rate_rps: r,
        }
    }

    /// One trapezoidal step of length `dt_s` with speed `vx_mps` and front wheel angle
    /// `delta_rad` held. Below `min_speed_mps` the state is set to the kinematic steady state.
    pub fn step(&self, state: &mut LateralState, vx_mps: f32, delta_rad: f32, dt_s: f32) {
        self.stepper(delta_rad, dt_s).step(state, vx_mps);
    }

    /// The step's coefficients for a front wheel angle and step length held over many steps
    /// (the horizon): the parameter products and quotients are computed once here, so each
    /// [`LateralStepper::step`] has one division by the speed and one by the determinant.
    pub fn stepper(&self, delta_rad: f32, dt_s: f32) -> LateralStepper {
        let cf = self.cornering_front_n_per_rad;
        let cr = self.cornering_rear_n_per_rad;
        let (lf, lr) = (self.cg_to_front_m, self.cg_to_rear_m);
        let m = self.mass_kg;
        let iz = self.yaw_inertia_kg_m2;
        let h = 0.5 * dt_s;
        let u = Self::steer_input(delta_rad);
        LateralStepper {
            params: *self,
            input: u,
            half_dt_s: h,
            h_a11_vx: -h * (cf + cr) / m,
            h_a12_vx: -h * (cf * lf - cr * lr) / m,
            h_a21_vx: -h * (cf * lf - cr * lr) / iz,
            h_a22_vx: -h * (cf * lf * lf + cr * lr * lr) / iz,
            dt_b1: dt_s * cf / m * u,
            dt_b2: dt_s * cf * lf / iz * u,
        }
    }
}

/// [`DynamicParams::step`] for a fixed wheel angle and step length. The continuous matrix is
/// `A = A_vx / vx + [[0, -vx], [0, 0]]`; the fields hold `h A_vx` (h = dt / 2) and `dt B`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LateralStepper {
    params: DynamicParams,
    /// The model's input, the wheel angle's tangent ([`DynamicParams::steer_input`]).
    input: f32,
    half_dt_s: f32,
    h_a11_vx: f32,
    h_a12_vx: f32,
    h_a21_vx: f32,
    h_a22_vx: f32,
    dt_b1: f32,
    dt_b2: f32,
}

impl LateralStepper {
    /// One trapezoidal step at speed `vx_mps`: `(I - hA) x+ = (I + hA) x + dt B`. Below
    /// `min_speed_mps` the state is set to the kinematic steady state.
    #[inline]
    pub fn step(&self, state: &mut LateralState, vx_mps: f32) {
        if vx_mps < self.params.min_speed_mps {
            *state = self.params.steady_state_of_input(vx_mps, self.input);
            return;
        }
        let inv_vx = 1.0 / vx_mps;
        let p11 = self.h_a11_vx * inv_vx;
        let p12 = self.h_a12_vx * inv_vx - self.half_dt_s * vx_mps;
        let p21 = self.h_a21_vx * inv_vx;
        let p22 = self.h_a22_vx * inv_vx;
        let (x1, x2) = (state.vy_mps, state.yaw_rate_rps);
        let r1 = x1 + (p11 * x1 + p12 * x2) + self.dt_b1;
        let r2 = x2 + (p21 * x1 + p22 * x2) + self.dt_b2;
        let m11 = 1.0 - p11;
        let m22 = 1.0 - p22;
        let det = m11 * m22 - p12 * p21;
        // det > 1 for a stable A (trace < 0, det(A) > 0), so this division is safe; the guard
        // is for non-finite inputs only.
        if det.is_finite() && det != 0.0 {
            let inv_det = 1.0 / det;
            state.vy_mps = (m22 * r1 + p12 * r2) * inv_det;
            state.yaw_rate_rps = (m11 * r2 + p21 * r1) * inv_det;
        }
    }
}

/// One trapezoidal step of [`LateralStepper`] with the speed held over several steps, as a
/// fixed linear map: the horizon holds the speed over each 0.2 s segment
/// ([`LateralStepper::held`]), so its 10 steps share these coefficients.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum HeldStep {
    /// Below the model's minimum speed: its kinematic steady state, as a path curvature (rad
    /// per m driven, positive right) and the centre of gravity's side slip per m driven
    /// (`curvature * lr`).
    Slow {
        /// Yaw per metre driven, rad/m.
        curvature_per_m: f32,
        /// Side slip per metre driven, m/m.
        slip_per_m: f32,
    },
    /// `x+ = m x + g` with `x = [vy, yaw rate]`, for the speed `vx_mps`.
    Fast {
        /// `(I - hA)^-1 (I + hA)`.
        m: [[f32; 2]; 2],
        /// `(I - hA)^-1 dt B delta`.
        g: [f32; 2],
        /// The held speed, m/s.
        vx_mps: f32,
    },
}

impl LateralStepper {
    /// The step for a speed `vx_mps` held over several steps: [`LateralStepper::step`] as a
    /// fixed map (the same trapezoidal rule solved once), or the kinematic steady state below
    /// `min_speed_mps`. A singular or non-finite system leaves the state unchanged, as `step`
    /// does.
    pub fn held(&self, vx_mps: f32) -> HeldStep {
        if vx_mps >= self.params.min_speed_mps {
            self.held_fast(vx_mps)
        } else {
            // Below the minimum speed, and a NaN speed.
            let l = self.params.wheelbase_m();
            let k = self.params.understeer_s2_per_m2();
            let curvature_per_m = self.input / (l * (1.0 + k * vx_mps * vx_mps));
            HeldStep::Slow {
                curvature_per_m,
                slip_per_m: curvature_per_m * self.params.cg_to_rear_m,
            }
        }
    }

    /// [`LateralStepper::held`] at or above the minimum speed.
    fn held_fast(&self, vx_mps: f32) -> HeldStep {
        let inv_vx = 1.0 / vx_mps;
        let p11 = self.h_a11_vx * inv_vx;
        let p12 = self.h_a12_vx * inv_vx - self.half_dt_s * vx_mps;
        let p21 = self.h_a21_vx * inv_vx;
        let p22 = self.h_a22_vx * inv_vx;
        let m11 = 1.0 - p11;
        let m22 = 1.0 - p22;
        let det = m11 * m22 - p12 * p21;
        if !(det.is_finite() && det != 0.0) {
            return HeldStep::Fast {
                m: [[1.0, 0.0], [0.0, 1.0]],
                g: [0.0, 0.0],
                vx_mps,
            };
        }
        let inv_det = 1.0 / det;
        // (I - P)^-1 = [[m22, p12], [p21, m11]] / det, applied to (I + P) and to dt B.
        HeldStep::Fast {
            m: [
                [
                    (m22 * (1.0 + p11) + p12 * p21) * inv_det,
                    2.0 * p12 * inv_det,
                ],
                [
                    2.0 * p21 * inv_det,
                    (p21 * p12 + m11 * (1.0 + p22)) * inv_det,
                ],
            ],
            g: [
                (m22 * self.dt_b1 + p12 * self.dt_b2) * inv_det,
                (p21 * self.dt_b1 + m11 * self.dt_b2) * inv_det,
            ],
            vx_mps,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn understeer_of_the_cat_vehicle_figures_is_eq2s() {
        let k = CAT_VEHICLE_DYNAMICS.understeer_s2_per_m2();
        assert!((k - 0.0015).abs() < 0.0002, "{k}");
    }

    /// Held steering at 10 m/s converges to the analytic steady state.
    #[test]
    fn converges_to_the_steady_state() {
        let p = CAT_VEHICLE_DYNAMICS;
        let mut s = LateralState::default();
        for _ in 0..500 {
            p.step(&mut s, 10.0, 0.05, 0.02);
        }
        let ss = p.steady_state(10.0, 0.05);
        assert!(
            (s.yaw_rate_rps - ss.yaw_rate_rps).abs() < 1e-5,
            "{s:?} vs {ss:?}"
        );
        assert!((s.vy_mps - ss.vy_mps).abs() < 1e-4, "{s:?} vs {ss:?}");
        // r = v tan(delta) / (L (1 + K v^2))
        let k = p.understeer_s2_per_m2();
        let expected = 10.0 * 0.05f32.tan() / (2.62 * (1.0 + k * 100.0));
        assert!((s.yaw_rate_rps - expected).abs() < 1e-5);
    }

    /// At a crawl the model turns as eq 8 does at every wheel angle up to the lock, stepped and
    /// in its steady state: the hybrid switch does not move the yaw rate (with the angle as
    /// the input it was 12 % short at 0.6 rad, 5 % at 0.4).
    #[test]
    fn the_low_speed_limit_is_eq8_at_any_angle() {
        let p = CAT_VEHICLE_DYNAMICS;
        let k = p.understeer_s2_per_m2();
        for delta in [0.05f32, 0.2, 0.4, 0.6, -0.6] {
            let v = 2.0f32;
            let eq8 = v * (delta / (1.0 + k * v * v)).tan() / p.wheelbase_m();
            let mut s = LateralState::default();
            for _ in 0..500 {
                p.step(&mut s, v, delta, 0.02);
            }
            let ss = p.steady_state(v, delta);
            for r in [s.yaw_rate_rps, ss.yaw_rate_rps] {
                assert!((r / eq8 - 1.0).abs() < 0.002, "delta {delta}: {r} vs {eq8}");
            }
        }
    }

    #[test]
    fn stays_stable_at_low_speed_with_large_steps() {
        let p = CAT_VEHICLE_DYNAMICS;
        let mut s = LateralState::default();
        for _ in 0..1000 {
            p.step(&mut s, 1.2, 0.6, 0.02);
            assert!(
                s.yaw_rate_rps.is_finite() && s.yaw_rate_rps.abs() < 1.0,
                "{s:?}"
            );
        }
    }
}
