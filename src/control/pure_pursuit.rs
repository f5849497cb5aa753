//! The reference controller: pure pursuit (Coulter, "Implementation of the Pure Pursuit Path
//! Tracking Algorithm", CMU-RI-TR-92-01, 1992) with a lookahead that grows with speed, and a PI
//! speed loop around the car's own speed controller. It reads the same path and obstacles and
//! writes the same CONTROL_COMMAND as the model-predictive controller, which is measured
//! against it (docs/controller.md).
//!
//! Steering: the goal point is the path point `lookahead` metres of station ahead of the rear
//! axle's projection; the arc from the rear axle, tangent to its course (the heading turned by
//! the rear tyres' slip angle, from the node's lateral model), through the
//! goal has curvature `kappa = 2 sin(alpha) / d` (alpha the goal's bearing from the heading, d
//! its distance); the steering is eq 2 inverted for that curvature at the current speed:
//! `delta = atan(kappa L) (1 + K v^2)`.
//!
//! Speed: the path's target speed a preview time ahead (the car's speed loop lags by its 0.4 s
//! input delay), limited so that the car can stop at `stop_decel_mps2`, after its response
//! time, before the path's end and with its front bumper a margin short of any obstacle whose
//! circle, grown by half the body width and the margin, reaches the path ahead (pure pursuit
//! cannot steer around one: it stops, and stays stopped while the obstacle is there). The car
//! tracks a speed command itself; a PI loop on the speed error trims its steady-state error
//! only: the correction is limited to `speed_correction_limit_mps`, and the integral runs only
//! while the error is within that limit (integral separation, so a launch winds nothing up).
//!
//! Never panics, never returns a non-finite command: a non-finite intermediate falls back to
//! the previous steering and zero speed (status fallback).
use crate::can::codec::{ControlStatus, ObstacleCircle};
use crate::math;
use crate::model::kinematic::Pose;
use crate::node::NodeConfig;
use crate::vehicle::{Body, VehicleParams, STEER_PCT_LIMIT};

use super::path::{Path, Projection, Tracking};

/// The controller's own numbers (immutable); [`DEFAULT_TUNING`] is the tuned set
/// (docs/controller.md).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PurePursuitTuning {
    /// Lookahead at standstill, m.
    pub lookahead_min_m: f32,
    /// Lookahead growth with speed, s: lookahead = min + this * speed.
    pub lookahead_time_s: f32,
    /// Longest lookahead, m.
    pub lookahead_max_m: f32,
    /// Speed loop proportional gain, (m/s) of command per (m/s) of error.
    pub speed_kp: f32,
    /// Speed loop integral gain, 1/s.
    pub speed_ki_per_s: f32,
    /// The PI correction (and its integral) stays within +- this, m/s; the integral only runs
    /// while the error is within it.
    pub speed_correction_limit_mps: f32,
    /// The car's speed response to a command, s: the input delay and the lag of its speed loop
    /// (eq 5: 0.42 s delay, poles near 1.2 s^-1); a stop is planned after this much travel.
    pub speed_response_s: f32,
    /// The target speed is read this far ahead of the car (at its speed), s.
    pub speed_preview_s: f32,
    /// Deceleration the speed limit plans with, to stop at the path's end or before an
    /// obstacle, m/s^2.
    pub stop_decel_mps2: f32,
    /// Clearance kept from an obstacle when stopping, m (grow it by the position estimate's
    /// error).
    pub obstacle_margin_m: f32,
}

/// The tuned reference controller (docs/controller.md, "Pure pursuit tuning": a sweep of the
/// lookahead's two parameters on the double lane change for the highest clean speed; the best
/// lies on a ridge of lookaheads near 7.5 m at that speed, and this is its middle).
pub const DEFAULT_TUNING: PurePursuitTuning = PurePursuitTuning {
    lookahead_min_m: 3.0,
    lookahead_time_s: 0.55,
    lookahead_max_m: 30.0,
    speed_kp: 0.3,
    speed_ki_per_s: 0.1,
    speed_correction_limit_mps: 1.0,
    speed_response_s: 1.0,
    speed_preview_s: 0.6,
    stop_decel_mps2: 1.5,
    obstacle_margin_m: 1.0,
};

/// The controller for one car (immutable): its tuning and what it needs of the car.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PurePursuitConfig {
    /// The controller's own numbers.
    pub tuning: PurePursuitTuning,
    /// Geometry and steering conversion (eq 2).
    pub vehicle: VehicleParams,
    /// The body around the rear axle (obstacle checks).
    pub body: Body,
    /// Largest speed command, m/s.
    pub max_speed_mps: f32,
    /// Control period, s.
    pub period_s: f32,
}

/// The state between ticks.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PurePursuitState {
    /// Integral of the speed error, m/s.
    pub integral_mps: f32,
    /// Last tick's projection (keeps the projection in order along a looping path).
    pub projection: Option<Projection>,
    /// Last steering command, %.
    pub steer_cmd_pct: f32,
}

/// What the controller knows of the car this tick: the node's estimate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CarState {
    /// Rear-axle pose, local frame; `None` while the node has no valid position.
    pub pose: Option<Pose>,
    /// Speed, m/s.
    pub speed_mps: f32,
    /// The rear axle's sideways velocity (tyre slip, from the node's lateral model; 0 in the
    /// kinematic model), m/s, positive right.
    pub rear_side_mps: f32,
}

/// One tick's output.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PursuitOutput {
    /// What CONTROL_COMMAND says.
    pub status: ControlStatus,
    /// Steering command, %, -100..=100, positive = right.
    pub steer_cmd_pct: f32,
    /// Speed command, m/s, >= 0.
    pub speed_cmd_mps: f32,
    /// The car relative to the path, when tracking.
    pub tracking: Option<Tracking>,
    /// The goal point (east, north), when tracking.
    pub goal: Option<(f32, f32)>,
}

impl PurePursuitConfig {
    /// The controller with `tuning` for the car the node is configured for (its model file).
    pub fn for_node(node: &NodeConfig, tuning: PurePursuitTuning) -> Self {
        Self {
            tuning,
            vehicle: node.vehicle,
            body: node.body,
            max_speed_mps: node.max_speed_mps,
            period_s: crate::SAMPLE_PERIOD_S,
        }
    }

    /// Lookahead at `speed_mps`, m.
    pub fn lookahead_m(&self, speed_mps: f32) -> f32 {
        let t = &self.tuning;
        (t.lookahead_min_m + t.lookahead_time_s * speed_mps.max(0.0)).min(t.lookahead_max_m)
    }

    /// One tick: steering and speed commands for `car` on `path` (`None`: no path), with the
    /// active `obstacles`.
    pub fn process(
        &self,
        state: &mut PurePursuitState,
        path: Option<&Path>,
        obstacles: &[Option<ObstacleCircle>],
        car: &CarState,
    ) -> PursuitOutput {
        let hold = |state: &mut PurePursuitState, status| {
            state.integral_mps = 0.0;
            PursuitOutput {
                status,
                steer_cmd_pct: state.steer_cmd_pct,
                speed_cmd_mps: 0.0,
                tracking: None,
                goal: None,
            }
        };
        let Some(path) = path.filter(|p| !p.is_empty()) else {
            state.projection = None;
            return hold(state, ControlStatus::NoPath);
        };
        let Some(pose) = car.pose else {
            return hold(state, ControlStatus::Fallback);
        };
        let speed = if car.speed_mps.is_finite() {
            car.speed_mps.max(0.0)
        } else {
            0.0
        };
        let Some(tracking) = path.track(&pose, state.projection.as_ref()) else {
            return hold(state, ControlStatus::Fallback);
        };
        if tracking.has_lost_path(self.body.width_m) {
            // Beside the corridor or facing against the path: brake with the wheels straight
            // (along a line, not the circle the last command would hold) for the planner to
            // replan.
            state.projection = Some(tracking.projection);
            state.steer_cmd_pct = 0.0;
            let mut out = hold(state, ControlStatus::Fallback);
            out.tracking = Some(tracking);
            return out;
        }
        let station = tracking.projection.station_m;
        let segment = tracking.projection.segment;

        // Steering: the arc through the goal point.
        let lookahead = self.lookahead_m(speed);
        let Some(goal) = path.sample(station + lookahead, segment) else {
            return hold(state, ControlStatus::Fallback);
        };
        let (dx, dy) = (goal.east_m - pose.x_m, goal.north_m - pose.y_m);
        // The arc starts along the rear axle's course: the heading turned by its slip angle.
        let slip_rad = if speed > 0.5 {
            math::atan(car.rear_side_mps / speed)
        } else {
            0.0
        };
        let (sin_slip, cos_slip) = math::sin_cos(slip_rad);
        let sin_course = pose.sin_heading * cos_slip + pose.cos_heading * sin_slip;
        let cos_course = pose.cos_heading * cos_slip - pose.sin_heading * sin_slip;
        let forward = dx * sin_course + dy * cos_course;
        let right = dx * cos_course - dy * sin_course;
        let d2 = dx * dx + dy * dy;
        // 2 sin(alpha) / d = 2 right / d^2.
        let curvature = if d2 > 1e-6 { 2.0 * right / d2 } else { 0.0 };
        let curvature = if forward < 0.0 {
            // The goal is behind (the car overshot the path's end): steer towards it fully.
            curvature.signum() * 2.0 / lookahead.max(1e-3)
        } else {
            curvature
        };
        let vehicle = &self.vehicle;
        let center_rad = math::atan(curvature * vehicle.wheelbase_m)
            * (1.0 + vehicle.understeer_s2_per_m2 * speed * speed);
        let steer_pct = (center_rad / vehicle.max_steer_rad * STEER_PCT_LIMIT)
            .clamp(-STEER_PCT_LIMIT, STEER_PCT_LIMIT);

        // Speed: previewed target, limited by stopping distance, then PI.
        let preview = path.sample(station + speed * self.tuning.speed_preview_s, segment);
        let mut target = preview.map_or(0.0, |p| p.speed_mps);
        let mut stop_at_m = path.length_m() - station;
        if let Some(d) = self.obstacle_ahead_m(path, station, obstacles) {
            stop_at_m = stop_at_m.min(d);
        }
        let braking_room = stop_at_m - speed * self.tuning.speed_response_s;
        let stop_limit = math::sqrt(2.0 * self.tuning.stop_decel_mps2 * braking_room.max(0.0));
        target = target.min(stop_limit).min(self.max_speed_mps);
        let error = target - speed;
        let limit = self.tuning.speed_correction_limit_mps;
        let integral = if error.abs() < limit {
            math::clamp(
                state.integral_mps + self.tuning.speed_ki_per_s * error * self.period_s,
                -limit,
                limit,
            )
        } else {
            state.integral_mps
        };
        let speed_cmd = if target <= 0.0 {
            0.0
        } else {
            let correction = math::clamp(self.tuning.speed_kp * error + integral, -limit, limit);
            // The correction never commands past what still stops in time.
            math::clamp(
                (target + correction).min(stop_limit),
                0.0,
                self.max_speed_mps,
            )
        };

        if !(steer_pct.is_finite() && speed_cmd.is_finite() && integral.is_finite()) {
            return hold(state, ControlStatus::Fallback);
        }
        state.integral_mps = if target <= 0.0 { 0.0 } else { integral };
        state.projection = Some(tracking.projection);
        state.steer_cmd_pct = steer_pct;
        PursuitOutput {
            status: ControlStatus::Tracking,
            steer_cmd_pct: steer_pct,
            speed_cmd_mps: speed_cmd,
            tracking: Some(tracking),
            goal: Some((goal.east_m, goal.north_m)),
        }
    }

    /// How far the rear axle may still travel along the path before the body's front comes
    /// within the margin of an active obstacle that reaches the path (its circle, grown by half
    /// the body width and the margin, overlaps the path), m; 0 when already there. Obstacles
    /// behind the car's front are ignored once the rear axle has passed them. `None` if no
    /// obstacle blocks the path.
    fn obstacle_ahead_m(
        &self,
        path: &Path,
        station: f32,
        obstacles: &[Option<ObstacleCircle>],
    ) -> Option<f32> {
        let mut nearest: Option<f32> = None;
        for o in obstacles.iter().flatten() {
            let Some(p) = path.project(o.east_m, o.north_m, None) else {
                continue;
            };
            let margin = self.tuning.obstacle_margin_m;
            let reach = o.radius_m + 0.5 * self.body.width_m + margin;
            if p.lateral_m.abs() > reach || p.station_m < station {
                continue;
            }
            // The front bumper stops `margin` short of the circle's near side.
            let front = self.body.length_m - self.body.rear_overhang_m;
            let free = p.station_m - o.radius_m - margin - front - station;
            let d = free.max(0.0);
            nearest = Some(nearest.map_or(d, |n: f32| n.min(d)));
        }
        nearest
    }
}
