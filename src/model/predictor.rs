//! The horizon predictor: rolls the current state forward (default 2.0 s in 0.02 s steps) with
//! the velocity model driven by the commanded speed and the active lateral model, and returns
//! the path the planner gets.
//!
//! Inputs held over the horizon: the commanded speed (the velocity model's input delay line
//! already holds the commands of the next 0.42 s, so the first 21 steps use the real future
//! commands) and the measured steering. The velocity model's output is corrected by the
//! current difference between measured and modelled speed (an output-disturbance estimate, as
//! in MPC), so the prediction starts at the measured speed.
//!
//! Cost: no transcendental call per step. The kinematic curvature `tan(delta_eff(v)) / L` is
//! evaluated once, at the current speed, and held over the horizon (eq 2's understeer term
//! changes it by under 2 % for a 2 m/s speed change at 5 m/s). With the curvature held the
//! kinematic path is a circle whatever the speed, so the kinematic roll-out only sums the
//! distance per step and moves the pose once per output point ([`Pose::advance_arc`]). The
//! dynamic roll-out steps the lateral model and the pose every 20 ms, with the lateral
//! model's coefficients for the held steering computed once
//! ([`super::dynamic::DynamicParams::stepper`]).
use super::dynamic::{DynamicParams, LateralState};
use super::hybrid::Mode;
use super::kinematic::Pose;
use crate::vehicle::VehicleParams;

/// Horizon shape. Immutable configuration.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct HorizonConfig {
    /// Steps of `dt_s` to roll forward.
    pub steps: u16,
    /// Step length, s; must equal the velocity model's sample time.
    pub dt_s: f32,
    /// Emit a point every this many steps.
    pub output_every: u16,
    /// Predicted speeds are clamped to [0, max_speed_mps].
    pub max_speed_mps: f32,
}

/// 2.0 s ahead in 20 ms steps, a point every 0.2 s (10 points).
pub const DEFAULT_HORIZON: HorizonConfig = HorizonConfig {
    steps: 100,
    dt_s: crate::SAMPLE_PERIOD_S,
    output_every: 10,
    max_speed_mps: 60.0,
};

impl HorizonConfig {
    /// Number of points a roll-out emits.
    pub fn points(&self) -> usize {
        usize::from(self.steps.checked_div(self.output_every).unwrap_or(0))
    }
}

/// The state the roll-out starts from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PredictorStart {
    /// Current pose (filtered position, estimated heading).
    pub pose: Pose,
    /// Measured speed now, m/s.
    pub speed_mps: f32,
    /// Measured speed minus the velocity model's current output, m/s.
    pub speed_bias_mps: f32,
    /// Latest commanded speed, m/s.
    pub speed_cmd_mps: f32,
    /// Latest measured centre-tyre steering angle, rad (positive right).
    pub center_steer_rad: f32,
    /// Current lateral state (used by the dynamic model).
    pub lateral: LateralState,
    /// Lateral model for this roll-out.
    pub mode: Mode,
}

/// One predicted point.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PredictedPoint {
    /// Time ahead of the tick, s.
    pub horizon_s: f32,
    /// East, m.
    pub x_m: f32,
    /// North, m.
    pub y_m: f32,
    /// Heading clockwise from north, rad.
    pub heading_rad: f32,
    /// Speed, m/s.
    pub speed_mps: f32,
}

/// Rolls forward. `speed_model_step` advances a copy of the velocity model by one step with the
/// given commanded speed and returns its output (m/s). Fills `out` with up to `out.len()`
/// points and returns how many were written.
pub fn rollout(
    horizon: &HorizonConfig,
    vehicle: &VehicleParams,
    dynamics: &DynamicParams,
    start: &PredictorStart,
    mut speed_model_step: impl FnMut(f32) -> f32,
    out: &mut [PredictedPoint],
) -> usize {
    let mut pose = start.pose;
    let mut lateral = start.lateral;
    let dt = horizon.dt_s;
    let every = horizon.output_every.max(1);
    let mut written = 0usize;
    let curvature_per_m = vehicle.curvature_per_m(start.center_steer_rad, start.speed_mps);
    let lateral_step = dynamics.stepper(start.center_steer_rad, dt);
    let mut slot = out.iter_mut();
    let mut until_point = every;
    // Kinematic: distance driven since the last point (the path is the circle of the held
    // curvature, so only the distance matters; see `Pose::advance_arc`).
    let mut arc_m = 0.0f32;
    for k in 1..=horizon.steps {
        let v_model = speed_model_step(start.speed_cmd_mps);
        let v = clamp_speed(v_model + start.speed_bias_mps, horizon.max_speed_mps);
        match start.mode {
            Mode::Kinematic => arc_m += v * dt,
            Mode::Dynamic => {
                lateral_step.step(&mut lateral, v);
                pose.advance(v, lateral.vy_mps, lateral.yaw_rate_rps * dt, dt);
            }
        }
        until_point -= 1;
        if until_point == 0 {
            until_point = every;
            let Some(point) = slot.next() else {
                break;
            };
            if start.mode == Mode::Kinematic {
                pose.advance_arc(arc_m, curvature_per_m);
                arc_m = 0.0;
            }
            *point = PredictedPoint {
                horizon_s: f32::from(k) * dt,
                x_m: pose.x_m,
                y_m: pose.y_m,
                heading_rad: pose.heading_rad,
                speed_mps: v,
            };
            written += 1;
        }
    }
    written
}

/// `v` limited to [0, max_mps], 0 if not finite (comparisons only: `f32::clamp`'s assertion
/// would link float formatting into the firmware).
fn clamp_speed(v: f32, max_mps: f32) -> f32 {
    if !v.is_finite() {
        return 0.0;
    }
    let mut x = v;
    if x < 0.0 {
        x = 0.0;
    }
    if x > max_mps {
        x = max_mps;
    }
    x
}

#[cfg(test)]
mod tests {
    use super::super::dynamic::CAT_VEHICLE_DYNAMICS;
    use super::*;
    use crate::vehicle::CAT_VEHICLE;

    fn start(mode: Mode, steer_rad: f32, speed: f32) -> PredictorStart {
        PredictorStart {
            pose: Pose::new(0.0, 0.0, 0.0),
            speed_mps: speed,
            speed_bias_mps: 0.0,
            speed_cmd_mps: speed,
            center_steer_rad: steer_rad,
            lateral: CAT_VEHICLE_DYNAMICS.steady_state(speed, steer_rad),
            mode,
        }
    }

    /// Constant speed straight north: point k is k * 0.2 s * v north.
    #[test]
    fn straight_constant_speed() {
        let mut out = [PredictedPoint::default(); 10];
        let s = start(Mode::Kinematic, 0.0, 5.0);
        let n = rollout(
            &DEFAULT_HORIZON,
            &CAT_VEHICLE,
            &CAT_VEHICLE_DYNAMICS,
            &s,
            |_| 5.0,
            &mut out,
        );
        assert_eq!(n, 10);
        for (i, p) in out.iter().enumerate() {
            let t = 0.2 * (i + 1) as f32;
            assert!((p.horizon_s - t).abs() < 1e-5);
            assert!(
                (p.y_m - 5.0 * t).abs() < 1e-4 && p.x_m.abs() < 1e-6,
                "{p:?}"
            );
        }
    }

    /// In steady cornering the kinematic (with eq 2 understeer) and dynamic models agree on the
    /// yaw rate, so their 2 s paths end close together.
    #[test]
    fn kinematic_and_dynamic_agree_in_steady_cornering() {
        let mut kin = [PredictedPoint::default(); 10];
        let mut dynm = [PredictedPoint::default(); 10];
        let steer = 0.1;
        rollout(
            &DEFAULT_HORIZON,
            &CAT_VEHICLE,
            &CAT_VEHICLE_DYNAMICS,
            &start(Mode::Kinematic, steer, 8.0),
            |_| 8.0,
            &mut kin,
        );
        rollout(
            &DEFAULT_HORIZON,
            &CAT_VEHICLE,
            &CAT_VEHICLE_DYNAMICS,
            &start(Mode::Dynamic, steer, 8.0),
            |_| 8.0,
            &mut dynm,
        );
        let (a, b) = (kin[9], dynm[9]);
        assert!((a.heading_rad - b.heading_rad).abs() < 0.01, "{a:?} {b:?}");
        // The dynamic model adds the side slip of the centre of gravity (vy ~ 0.2 m/s here, so
        // ~0.4 m over 2 s, rotating with the car); the kinematic model has none.
        assert!(
            ((a.x_m - b.x_m).powi(2) + (a.y_m - b.y_m).powi(2)).sqrt() < 0.6,
            "{a:?} {b:?}"
        );
        assert!(
            a.x_m > 0.5,
            "a right turn from heading north bends east: {a:?}"
        );
    }

    #[test]
    fn non_finite_speed_model_output_never_leaves_the_predictor() {
        let mut out = [PredictedPoint::default(); 10];
        let s = start(Mode::Dynamic, 0.2, 7.0);
        rollout(
            &DEFAULT_HORIZON,
            &CAT_VEHICLE,
            &CAT_VEHICLE_DYNAMICS,
            &s,
            |_| f32::NAN,
            &mut out,
        );
        for p in out {
            assert!(
                p.x_m.is_finite() && p.y_m.is_finite() && p.speed_mps.is_finite(),
                "{p:?}"
            );
        }
    }
}
