//! Model-predictive control over the identified models (the paper's "hybrid predictive
//! controller"): every tick, a speed plan and a steering plan over the next 2 s, from which the
//! node sends the first commands and the planned trajectory.
//!
//! Decoupled in two problems solved in sequence (docs/mpc.md has the formulation, the solver,
//! the measurements behind the choices and the bounds):
//! 1. [`longitudinal`]: the speed commands, through the eq 5-form speed model with its input
//!    delay (a condensed QP, the delay handled exactly by the prediction);
//! 2. [`lateral`]: the steering, through an error-state model along the reference linearised
//!    about the previous plan and the planned speeds: the kinematic model (eq 8) or the
//!    identified dynamic model, as the hybrid switch chose; steering range and rate, the four
//!    body corners inside the corridor, each obstacle as a half-space per step on the side
//!    chosen for it (the discrete decision: more room, with hysteresis), inflated by its radius,
//!    the node's position uncertainty and a margin; solved by [`admm`].
//!
//! Everything is f32 with sizes fixed at compile time, no allocation, a fixed iteration cap,
//! warm starts from the previous solution moved one tick ahead. A problem that cannot be solved
//! (an obstacle with no side that fits the corridor, a plan that still hits an obstacle after the
//! cap, non-finite input) gives status 3 and the documented fallback, never a NaN: brake (speed
//! command 0) and steer along the last feasible plan (holding its last steering once it has run
//! out; the measured steering when there is none), or, for an obstacle the plans do not clear,
//! along the lane at the offset the car has.
//!
//! Frames: x east, y north (m); headings clockwise from north (rad); offsets and steering
//! positive to the right.
pub mod admm;
pub mod lateral;
pub mod longitudinal;

use core::ptr::addr_of_mut;

use nalgebra::SVector;

use self::admm::{AdmmSettings, Problem, SolveError, Workspace};
use self::lateral::{BuildError, InflatedObstacle, LateralSetup, Linearisation};
pub use self::longitudinal::SlowAhead;
use self::longitudinal::{SpeedPlanError, SpeedPlanner, SpeedStart, SpeedState, SpeedTuning};
use crate::math::{self, clamp, finite_or, max, min};
use crate::model::dynamic::{DynamicParams, LateralState};
use crate::model::hybrid::Mode;
use crate::model::kinematic::Pose;
use crate::model::{SsBlock, SsBlockState};
use crate::node::NodeConfig;
use crate::vehicle::{Body, VehicleParams, STEER_PCT_LIMIT};

/// MPC steps of the steering problem: 20 x 0.1 s = 2 s, as long as the plan the node sends (it
/// was 15: on the rig the lane change's limit rose by 0.7 m/s on the CAT Vehicle and 2.1 m/s on
/// the hatchback with 20, at 12 ADMM iterations instead of 20 for less work per solve;
/// docs/controller.md, "A 2 s horizon").
pub const STEPS: usize = 20;
/// Steps of the plan the node sends: 20 x 0.1 s = 2 s, the PREDICTION frames' horizon. The
/// speed plan covers it all; beyond [`STEPS`] (none now) the steering plan would hold its last
/// value, and the speed plan's caps would need the reference's last distance along it held
/// (`MpcConfig::solve`: a compile-time check asks for the two to be equal).
pub const PLAN_STEPS: usize = 20;
const _: () = assert!(PLAN_STEPS == STEPS);
/// MPC step, s (every 5th node tick: the PREDICTION frames are every 0.2 s = 2 steps).
pub const STEP_S: f32 = 0.1;
/// The fallback for an obstacle the plans do not clear brakes along the lane: it steers
/// towards a point this far ahead (at the car's speed) on the line parallel to the path through
/// the car, s ([`FallbackReason::ObstacleNotCleared`]).
pub const LANE_HOLD_PREVIEW_S: f32 = 1.0;
/// ... and at least this far, m (at a crawl).
pub const LANE_HOLD_MIN_PREVIEW_M: f32 = 3.0;
/// Longest steering lead, s: three stages of the plan.
pub const MAX_STEER_LEAD_S: f32 = 0.3;
/// Node ticks (20 ms, [`crate::SAMPLE_PERIOD_S`]) per MPC step.
pub const TICKS_PER_STEP: usize = 5;
/// Stages of [`STEP_S`] at the start of every steering plan ([`StageClock`]): the first second.
pub const FINE_STAGES: usize = 10;
/// Node ticks per later stage at most ([`StageClock`]): 0.3 s stages, a 4 s horizon.
pub const MAX_LATE_TICKS: usize = 3 * TICKS_PER_STEP;
/// How fast a car's steering changes the curvature it drives, at least, for the steering plan's
/// 2 s horizon, 1/m per s (the steering rate limit over the wheelbase: the CAT Vehicle's 21.3
/// deg/s over 2.62 m is 0.142, the hatchback's 0.169; the horizon was tuned on those two cars).
/// A slower car's horizon is longer in proportion ([`StageClock`]).
pub const TUNED_CURVATURE_RATE_PER_M_S: f32 = 0.14;
/// Obstacles the controller keeps clear of (the OBSTACLE frame's `obstacle_id` 0..3).
pub const MAX_OBSTACLES: usize = 4;
/// Lateral states (see [`lateral`]).
pub const NX: usize = 5;
/// Constraint rows per stage: four corners, one per obstacle.
pub const ROWS: usize = 4 + MAX_OBSTACLES;

/// A point of the path with the corridor there.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// Path pose (rear-axle path; heading along the path).
    pub pose: Pose,
    /// How far the body may stray to the left of the path here, m (may be +inf).
    pub left_m: f32,
    /// ... and to the right, m.
    pub right_m: f32,
}

/// The point of one side of one half of the body (axle to front end, axle to rear end) where
/// the corridor binds it: the path and corridor at the station where the corridor is narrowest
/// over that half ([`crate::control::path::Path::narrowest_corridor`]). The corridor row keeps
/// the body's side there inside: at the end's corner while the lane goes on past it, at a lane's
/// last point when the lane ends beside the front half and its first point when it starts
/// beside the rear half, where the body turning out of the lane (into it) meets its edge. (A
/// lane's first point beside the front half and its last beside the rear half are not held:
/// the stretch's end farther from the axle is, docs/controller.md "Where the corridor binds the
/// body".)
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SidePoint {
    /// Path pose and corridor there (the row reads the side's width only).
    pub sample: Sample,
    /// Its station minus the rear axle's (`at`'s), m: in `0 ..= length_m - rear_overhang_m` for
    /// the front half, `-rear_overhang_m ..= 0` for the rear half.
    pub ahead_m: f32,
}

/// The reference at one MPC step: the path where the car is expected at step k.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReferencePoint {
    /// Path at the rear axle's expected station.
    pub at: Sample,
    /// Signed path curvature there, 1/m (positive = turning right).
    pub curvature_per_m: f32,
    /// Target speed there, m/s.
    pub speed_mps: f32,
    /// Where the corridor binds the body's left side between the axle and the front end.
    pub front_left: SidePoint,
    /// ... its right side between the axle and the front end.
    pub front_right: SidePoint,
    /// ... its left side between the rear end and the axle.
    pub rear_left: SidePoint,
    /// ... its right side between the rear end and the axle.
    pub rear_right: SidePoint,
}

impl ReferencePoint {
    /// Everything zero (north, straight, no corridor): the contents of a reference buffer
    /// before it is filled. `const`, so that a platform can keep the buffer in a static.
    pub const ZERO: Self = {
        let sample = Sample {
            pose: Pose {
                x_m: 0.0,
                y_m: 0.0,
                heading_rad: 0.0,
                sin_heading: 0.0,
                cos_heading: 1.0,
            },
            left_m: 0.0,
            right_m: 0.0,
        };
        let side = SidePoint {
            sample,
            ahead_m: 0.0,
        };
        Self {
            at: sample,
            curvature_per_m: 0.0,
            speed_mps: 0.0,
            front_left: side,
            front_right: side,
            rear_left: side,
            rear_right: side,
        }
    };
}

/// A circular obstacle, in the frame of the path, with where it lies along the path (the
/// passing side is decided on these, whether or not the obstacle is within the horizon yet).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Obstacle {
    /// Centre, east, m.
    pub east_m: f32,
    /// Centre, north, m.
    pub north_m: f32,
    /// Radius, m.
    pub radius_m: f32,
    /// Station of the centre's projection on the path minus the rear axle's station now, m
    /// (negative: behind).
    pub ahead_m: f32,
    /// The centre's offset from the path there, m, positive right.
    pub path_offset_m: f32,
    /// The corridor at that station, m (as [`Sample::left_m`]).
    pub left_m: f32,
    /// The corridor at that station, m (as [`Sample::right_m`]).
    pub right_m: f32,
    /// How it moves ([`ObstacleVelocity::ZERO`]: it stands).
    pub velocity: ObstacleVelocity,
}

/// An obstacle's velocity, in the local frame and in the path's where it lies: the solve
/// places it where it will be at each stage, and decides the side it is passed on by where it
/// will be when the car reaches it. A component that is not finite is a bad input (status 3).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ObstacleVelocity {
    /// East, m/s.
    pub east_mps: f32,
    /// North, m/s.
    pub north_mps: f32,
    /// Along the path at its station, m/s.
    pub along_mps: f32,
    /// Across the path there, m/s, positive right.
    pub right_mps: f32,
}

impl ObstacleVelocity {
    /// Standing still.
    pub const ZERO: Self = Self {
        east_mps: 0.0,
        north_mps: 0.0,
        along_mps: 0.0,
        right_mps: 0.0,
    };
}

/// Which side of an obstacle the car passes on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ObstacleSide {
    /// The car passes to the left of the obstacle (the obstacle is on its right).
    Left,
    /// The car passes to the right of it.
    Right,
}

/// The car now.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CarState<'a> {
    /// Rear-axle pose (the node's estimate).
    pub pose: Pose,
    /// Measured speed, m/s.
    pub speed_mps: f32,
    /// Lateral state (the dynamic model's; ignored in the kinematic mode).
    pub lateral: LateralState,
    /// Measured centre-tyre steering angle, rad.
    pub steer_rad: f32,
    /// Lateral model chosen by the hybrid switch.
    pub mode: Mode,
    /// The node's speed-model state, its next step being the command sent now.
    pub speed_model: &'a SsBlockState<2>,
    /// Measured minus modelled speed now, m/s.
    pub speed_bias_mps: f32,
    /// Speed command sent last, m/s.
    pub last_speed_cmd_mps: f32,
}

/// One solve's input.
#[derive(Clone, Copy, Debug)]
pub struct MpcInput<'a> {
    /// The reference at steps 0..=STEPS.
    pub reference: &'a [ReferencePoint; STEPS + 1],
    /// Active obstacles (slot = `obstacle_id`).
    pub obstacles: &'a [Option<Obstacle>; MAX_OBSTACLES],
    /// The car.
    pub car: CarState<'a>,
    /// Bound on the error of the position estimate, m (the estimator's 2-sigma or worse):
    /// obstacles are inflated by it.
    pub position_uncertainty_m: f32,
    /// The largest reference curvature of the whole path, 1/m (either sign; for
    /// [`MpcTuning::line_rule`]).
    pub path_max_curvature_per_m: f32,
    /// Distance along the path from the rear axle's projection to the path's end, m (infinite:
    /// a path without an end): the speed plan stops there ([`SpeedPlanner::reference`]).
    pub to_end_m: f32,
    /// The rear axle is in a turn whose speed the path's lateral limit holds
    /// ([`crate::control::path::Path::in_held_turn`]): the speed commands do not lead
    /// ([`SpeedPlanner::command_band`]).
    pub in_held_turn: bool,
    /// The path's lower target ahead the speed plan slows for beyond its horizon too
    /// ([`SlowAhead`]); `None`: none.
    pub slow_ahead: Option<SlowAhead>,
}

/// Cost weights and ADMM penalties of the lateral problem.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Weights {
    /// Lateral offset, per m^2.
    pub lateral_per_m2: f32,
    /// Heading error, per rad^2.
    pub heading_per_rad2: f32,
    /// Lateral speed (dynamic mode), per (m/s)^2.
    pub lateral_speed_per_mps2: f32,
    /// Yaw rate (dynamic mode), per (rad/s)^2.
    pub yaw_rate_per_rps2: f32,
    /// Steering away from the path's feedforward, per rad^2.
    pub steer_per_rad2: f32,
    /// Steering rate, per (rad/s)^2.
    pub steer_rate: f32,
    /// The last step's state weights are this many times the others (terminal cost).
    pub terminal_factor: f32,
    /// Exact-penalty weight of the corridor, per m outside.
    pub corridor_weight_per_m: f32,
    /// The body's corners are kept this far inside the corridor, m, but never by more than
    /// half the room the body has on a side (a lane 0.2 m wider than the car keeps 0.05 m):
    /// the corner rows are linearised about the previous plan and soft, so a plan on the edge
    /// ends up a few centimetres outside (measured on the closed-loop rig: up to 0.04 m at
    /// 5-8 m/s, a cone touched), while a full margin in the narrow lanes leaves the plan no room
    /// at speed (docs/controller.md).
    pub corridor_margin_m: f32,
    /// Exact-penalty weight of an obstacle, per m inside its inflated circle.
    pub obstacle_weight_per_m: f32,
    /// ADMM penalty of the corridor rows, per m^2.
    pub rho_corridor: f32,
    /// ADMM penalty of the obstacle rows, per m^2.
    pub rho_obstacle: f32,
    /// ADMM penalty of the steering range, per rad^2.
    pub rho_steer: f32,
    /// ADMM penalty of the steering-rate bounds, per (rad/s)^2.
    pub rho_steer_rate: f32,
}

/// Controller tuning. Immutable configuration.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MpcTuning {
    /// Lateral problem weights.
    pub weights: Weights,
    /// Lateral solver settings (the iteration cap bounds the worst case).
    pub admm: AdmmSettings,
    /// Speed plan.
    pub speed: SpeedTuning,
    /// The steering command is the plan's steering this long after the tick, beyond the
    /// commanded ramp's own tick: the actuator's lag plus the tick the command takes to reach
    /// it, s (a first-order lag follows a ramp its time constant behind). Within the plan's
    /// first stage the ramp plus the first stage's rate times this; a lead that reaches past
    /// the stage takes the plan's steering there. 0 ..= [`MAX_STEER_LEAD_S`].
    pub steer_lead_s: f32,
    /// The plan starts from the steering the controller commanded (its own ramp, which the
    /// actuator follows after the bus and its lag), not from the steering report, which is
    /// older than the command it answers: planning from it closes a loop through the actuator's
    /// delay that oscillates (a 20 ms old report alone makes the double lane change unclean at
    /// 5 m/s). The commanded steering is trusted within the distance the actuator covers in
    /// this time at its rate limit from the report, s; further off (the actuator did not follow:
    /// saturation, a driver's hand) the plan starts that far from the report.
    pub steer_trust_s: f32,
    /// Share of the actuator's rate limit the plan may use (the rest is for feedback), 0..1.
    pub steer_rate_share: f32,
    /// A car that starts outside its corridor returns at this lateral acceleration: the
    /// corridor rows give way by the start's violation, tapering over the return's duration
    /// (`lateral::relax_corridor`), m/s^2.
    pub corridor_return_mps2: f32,
    /// A lateral error beyond this at the start is returned at `corridor_return_mps2` too: the
    /// tracking cost's target tapers (`lateral::taper_reference`), m.
    pub return_from_m: f32,
    /// That return is also no faster than this much heading allows at the speed the car has
    /// (a lateral speed of `v sin h` at its fastest, `v` at least 1 m/s): a slow car is not
    /// asked for a heading it would carry into the speed it picks up
    /// (`lateral::taper_reference`), rad.
    pub return_heading_rad: f32,
    /// Added to each obstacle's radius (besides the position uncertainty), m.
    pub obstacle_margin_m: f32,
    /// The other side of an obstacle must have this much more room to change the decision, m.
    pub side_hysteresis_m: f32,
    /// A plan whose body enters an inflated obstacle by more than this within `stop_delay_s`
    /// (two ticks in a row), or further out for more than `obstacle_persist_ticks` ticks in a
    /// row, is not accepted, m.
    pub obstacle_tolerance_m: f32,
    /// See `obstacle_tolerance_m`.
    pub obstacle_persist_ticks: u16,
    /// How far beyond the body's front at the end of the horizon an obstacle already pulls the
    /// plan's last stages to its side, as time at the current speed, s (lateral::terminal_row).
    pub preview_s: f32,
    /// While an obstacle is in the problem, the plan's heading error is kept within this, rad,
    /// at each stage where the last plan's came within half of it, in an obstacle slot no
    /// obstacle row or terminal row takes there (`lateral::heading_row`): the stages' stations advance at the planned speed along the
    /// path, which a car turned far from it does not, and a plan free to turn a short car
    /// 90 degrees at its horizon's end "passed" an obstacle that way, postponed the swerve
    /// from tick to tick and braked or hit it (docs/findings.md).
    pub obstacle_heading_rad: f32,
    /// Time from a speed command of 0 to full braking (the speed loop's delay and rise), s:
    /// an obstacle that leaves no room is acted on once it is within the stopping distance
    /// `v stop_delay + v^2 / (2 decel)` (or the horizon, if that reaches further).
    pub stop_delay_s: f32,
    /// The lateral weight for a path the car cannot follow closely (`None`: the weights' always).
    pub line_rule: Option<LineRule>,
}

/// A path whose tightest point asks for `lock_share` of the car's steering lock or more
/// (`atan(L kappa_max)`, the kinematic steady state, with the path's largest reference
/// curvature) is weighed with `lateral_per_m2` instead of [`Weights::lateral_per_m2`]: pulled
/// hard towards a line it can follow only at full lock, a car starts its swings late (the van
/// of docs/controller.md, "A car the line asks too much of").
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LineRule {
    /// Share of the lock from which the rule applies.
    pub lock_share: f32,
    /// The lateral weight then, per m^2.
    pub lateral_per_m2: f32,
}

/// Tuned on the built-in plant (docs/mpc.md, "Tuning").
pub const DEFAULT_TUNING: MpcTuning = MpcTuning {
    weights: Weights {
        lateral_per_m2: 10.0,
        heading_per_rad2: 10.0,
        lateral_speed_per_mps2: 0.0,
        yaw_rate_per_rps2: 0.0,
        steer_per_rad2: 1.0,
        steer_rate: 1.0,
        terminal_factor: 5.0,
        corridor_weight_per_m: 1000.0,
        corridor_margin_m: 0.15,
        obstacle_weight_per_m: 3000.0,
        rho_corridor: 50.0,
        rho_obstacle: 50.0,
        rho_steer: 300.0,
        rho_steer_rate: 10.0,
    },
    admm: AdmmSettings {
        max_iterations: 12,
        primal_tolerance: 0.005,
        dual_tolerance: 0.05,
        relaxation: 1.6,
        check_every: 5,
        rho_update_every: 10,
    },
    speed: SpeedTuning {
        speed_weight: 1.0,
        command_change_weight: 0.5,
        // The car's limit is the model file's `max_speed_mps` (at most the reader's 80 m/s);
        // a tuning of 30 m/s once capped every path silently (docs/findings.md).
        max_speed_mps: 80.0,
        accel_mps2: 1.5,
        decel_mps2: 3.0,
        iterations: 10,
        bias_time_constant_s: 1.5,
        command_lead_mps: 2.0,
        command_band_mps: 0.5,
        command_band_per_mps: 0.5,
    },
    steer_lead_s: 0.07,
    steer_trust_s: 0.15,
    steer_rate_share: 0.9,
    corridor_return_mps2: 1.0,
    return_from_m: 1.0,
    return_heading_rad: 0.2,
    obstacle_margin_m: 0.6,
    side_hysteresis_m: 0.5,
    obstacle_tolerance_m: 0.25,
    obstacle_persist_ticks: 10,
    // Eq 5: 0.42 s delay, then a rise with time constant ~1.2 s; the simulator's speed loop:
    // 0.4 s delay + 0.4 s actuator lag. 0.8 s covers the plant, conservatively.
    stop_delay_s: 0.8,
    preview_s: 1.5,
    obstacle_heading_rad: 0.6,
    // The lane change's path asks 0.47 of the CAT Vehicle's lock, 0.40 of the hatchback's,
    // 0.87 of the van's (on the node's reference); the van is clean to 9.38 m/s at 1, 5.38 at 10.
    line_rule: Some(LineRule {
        lock_share: 0.75,
        lateral_per_m2: 1.0,
    }),
};

/// Why a configuration is refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MpcConfigError {
    /// A body dimension, limit or weight is not positive and finite (or out of its range).
    BadParameter(&'static str),
    /// The speed planner could not be built.
    Speed(SpeedPlanError),
}

/// The steering plan's clock: [`STEPS`] stages, the first [`FINE_STAGES`] (or all) of
/// [`STEP_S`], the rest of `late_ticks` node ticks each. The speed plan and the PREDICTION
/// frames keep their 0.1 s steps ([`PLAN_STEPS`]); the steering plan reads the speed plan's
/// speeds at its stages (held past its 2 s) and the plan that is sent reads the steering plan
/// at its own steps.
///
/// The horizon has to see a steering reversal coming in time to make it: reversing the
/// steering a path's curvature asks for takes the curvature's change over the rate at which
/// the car's steering changes its curvature (the rate limit over the wheelbase, at small
/// angles). The horizon of 2 s was tuned on cars at least as quick as
/// [`TUNED_CURVATURE_RATE_PER_M_S`]; a slower car's horizon is longer in proportion, so that
/// it sees as much of a reversal, up to 4 s: its first second keeps the 0.1 s stages that
/// the plan's first commands need, the later stages are longer (rounded up to whole ticks, at
/// most [`MAX_LATE_TICKS`]). The count of stages, and so the solve's cost, is the same for
/// every car. Measured (docs/controller.md, "A car whose steering is slow for its wheelbase"):
/// uniformly longer stages helped a slow truck through an S-curve but cost slow cars the lane
/// change's precision.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StageClock {
    /// Stages of [`STEP_S`] at the start.
    fine: usize,
    /// Node ticks per later stage.
    late_ticks: usize,
    /// A later stage, s.
    late_s: f32,
    /// A later stage in steps of the speed plan.
    late_plan_steps: f32,
}

impl StageClock {
    /// Every stage [`STEP_S`]: the tuning's 2 s.
    pub const UNIFORM: Self = Self {
        fine: STEPS,
        late_ticks: TICKS_PER_STEP,
        late_s: STEP_S,
        late_plan_steps: 1.0,
    };

    /// The clock of a car whose steering turns at most `max_steer_rate_rad_per_s` (centre-tyre
    /// angle) on a `wheelbase_m` wheelbase; [`Self::UNIFORM`] for a car as quick as
    /// [`TUNED_CURVATURE_RATE_PER_M_S`] or quicker, or if either is not positive and finite.
    pub fn for_steering(wheelbase_m: f32, max_steer_rate_rad_per_s: f32) -> Self {
        let agility = max_steer_rate_rad_per_s / wheelbase_m;
        let want_s = STEPS as f32 * STEP_S * TUNED_CURVATURE_RATE_PER_M_S / agility;
        let fine_s = FINE_STAGES as f32 * STEP_S;
        let late = (STEPS - FINE_STAGES) as f32;
        let mut ticks = TICKS_PER_STEP;
        // A NaN compares false; a rate of 0 (+inf) stops at the cap.
        while ticks < MAX_LATE_TICKS
            && fine_s + late * ticks as f32 * crate::SAMPLE_PERIOD_S < want_s
        {
            ticks += 1;
        }
        Self::with_late_ticks(ticks)
    }

    /// [`FINE_STAGES`] of [`STEP_S`], then stages of `ticks` node ticks (within
    /// [`TICKS_PER_STEP`] ..= [`MAX_LATE_TICKS`]); [`Self::UNIFORM`] for [`TICKS_PER_STEP`].
    pub fn with_late_ticks(ticks: usize) -> Self {
        let ticks = ticks.clamp(TICKS_PER_STEP, MAX_LATE_TICKS);
        if ticks == TICKS_PER_STEP {
            return Self::UNIFORM;
        }
        let late_plan_steps = ticks as f32 / TICKS_PER_STEP as f32;
        Self {
            fine: FINE_STAGES,
            late_ticks: ticks,
            late_s: STEP_S * late_plan_steps,
            late_plan_steps,
        }
    }

    /// Node ticks of stage `k` (from `x_k` to `x_{k+1}`).
    pub fn stage_ticks(&self, k: usize) -> usize {
        if k < self.fine {
            TICKS_PER_STEP
        } else {
            self.late_ticks
        }
    }

    /// Stage `k`'s length, s.
    pub fn stage_s(&self, k: usize) -> f32 {
        if k < self.fine {
            STEP_S
        } else {
            self.late_s
        }
    }

    /// The time of `x_k` from now, s.
    pub fn time_s(&self, k: usize) -> f32 {
        if k <= self.fine {
            k as f32 * STEP_S
        } else {
            self.fine as f32 * STEP_S + (k - self.fine) as f32 * self.late_s
        }
    }

    /// The steering plan's horizon, s.
    pub fn horizon_s(&self) -> f32 {
        self.time_s(STEPS)
    }

    /// The (fractional) stage index of the time `t_s` from now.
    pub fn index_at_s(&self, t_s: f32) -> f32 {
        let fine_s = self.fine as f32 * STEP_S;
        if t_s <= fine_s {
            t_s / STEP_S
        } else {
            self.fine as f32 + (t_s - fine_s) / self.late_s
        }
    }

    /// The (fractional) stage index `ticks` node ticks after `x_k`.
    pub fn index_after(&self, k: usize, ticks: usize) -> f32 {
        let fine_left = self.fine.saturating_sub(k) * TICKS_PER_STEP;
        if ticks <= fine_left {
            k as f32 + ticks as f32 / TICKS_PER_STEP as f32
        } else {
            let from = k.max(self.fine);
            from as f32 + (ticks - fine_left) as f32 / self.late_ticks as f32
        }
    }

    /// Per stage, the share of it one node tick is (the warm start's shift).
    pub fn tick_shares(&self) -> [f32; STEPS] {
        core::array::from_fn(|k| 1.0 / self.stage_ticks(k) as f32)
    }

    /// The speed plan's speeds (at its steps) at the stages, held past its end.
    pub fn stage_speeds(&self, plan: &[f32; PLAN_STEPS + 1]) -> [f32; STEPS + 1] {
        core::array::from_fn(|k| {
            let at = if k <= self.fine {
                k as f32
            } else {
                self.fine as f32 + (k - self.fine) as f32 * self.late_plan_steps
            };
            interpolate(plan, at)
        })
    }

    /// The steering plan (at its stages) at step `k` of the speed plan.
    fn at_plan_step(&self, steer: &[f32; STEPS + 1], k: usize) -> f32 {
        interpolate(steer, self.index_after(0, k * TICKS_PER_STEP))
    }
}

/// The controller's configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct MpcConfig {
    vehicle: VehicleParams,
    dynamics: Option<DynamicParams>,
    body: Body,
    /// The steering actuator's rate limit, rad/s (centre-tyre angle).
    max_steer_rate_rad_per_s: f32,
    tuning: MpcTuning,
    speed: SpeedPlanner,
    /// The lock and the rate limit as the model file gives them (`vehicle.max_steer_rad` and
    /// `max_steer_rate_rad_per_s` are these times the steering gain in use, [`Self::set_steer_scale`]).
    file_steer: (f32, f32),
    /// The steering plan's stages, from the model file's steering and wheelbase.
    stage: StageClock,
}

/// What the controller sends.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ControlStatus {
    /// Following the path (CONTROL_COMMAND status 1).
    Tracking,
    /// Following the path with an obstacle in the horizon (status 2).
    Avoiding,
    /// The fallback (status 3): braking along the last feasible plan.
    Fallback,
}

impl ControlStatus {
    /// The CONTROL_COMMAND `status` value.
    pub fn code(self) -> u8 {
        match self {
            ControlStatus::Tracking => 1,
            ControlStatus::Avoiding => 2,
            ControlStatus::Fallback => 3,
        }
    }
}

/// How far short of an obstacle that leaves no passage the speed plan stops the body's front,
/// beyond the obstacle's inflated circle, m: what a car whose speed loop answers later than its
/// model runs past a planned stop (docs/findings.md, "Not fixed yet": 1.0-1.15 m past a path's
/// end on `scripts/sil-sim.py`'s slow loops).
pub const NO_PASSAGE_STANDOFF_M: f32 = 1.0;
/// Below this speed, within [`NO_PASSAGE_NEAR_M`] of its stop short of an obstacle that
/// leaves no passage, the car has stopped for it: status 3, `NoPassage`, speed 0, m/s (the speed
/// plan's last command before the stop, a creep of 0.3 m/s, does not move a car whose speed loop
/// has its own offset: the pickup of docs/findings.md stood at 0.32 m/s commanded).
pub const NO_PASSAGE_AT_REST_MPS: f32 = 0.3;
/// Within this distance of its stop short of an obstacle that leaves no passage, the car is
/// stopping for it whatever its speed (at rest the stopping distance and the horizon are
/// nothing), and at rest it has stopped for it, m: a speed loop that answers sooner than its
/// model stops the car up to 0.75 m short of a planned stop (docs/findings.md).
pub const NO_PASSAGE_NEAR_M: f32 = 2.0;

/// An obstacle moving across the path faster than this is passed behind, m/s.
pub const CROSSING_MPS: f32 = 0.3;
/// The least speed at which the car is taken to close in on a moving obstacle when its side
/// is decided, m/s.
pub const MEET_CLOSING_MPS: f32 = 2.0;

/// Where the speed plan stops for the nearest obstacle that leaves no passage.
#[derive(Clone, Copy, Debug, PartialEq)]
struct NoPassageStop {
    /// The stop's distance ahead of the car along the path (the body's front
    /// [`NO_PASSAGE_STANDOFF_M`] short of the inflated circle), m.
    at_m: f32,
    /// Within the stopping distance or the horizon: the car is stopping for it.
    in_reach: bool,
}

/// No passage at an obstacle whose inflated circle the body's front reaches in `clear_m`: the
/// speed plan stops the front [`NO_PASSAGE_STANDOFF_M`] short of it, wherever it is (an
/// obstacle that moves on, a slower car ahead, takes the stop with it and the car follows),
/// unless `stop` is nearer; returns the stop as the speed plan's zone (where, speed 0). Nearer
/// than the car can stop (`stopping_m`), braking at once.
fn stop_short(
    stop: &mut Option<NoPassageStop>,
    clear_m: f32,
    stopping_m: f32,
    reach_m: f32,
) -> Result<Option<(f32, f32)>, FallbackReason> {
    // Not nearer than it can stop, or NaN: braking at once.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    if !(stopping_m <= clear_m) {
        return Err(FallbackReason::NoPassage);
    }
    let at_m = clear_m - NO_PASSAGE_STANDOFF_M;
    if stop.as_ref().is_none_or(|n| at_m < n.at_m) {
        *stop = Some(NoPassageStop {
            at_m,
            in_reach: clear_m <= reach_m || at_m <= NO_PASSAGE_NEAR_M,
        });
    }
    Ok(Some((at_m, 0.0)))
}

/// The car's rear axle right of the reference's first point, m.
fn lateral_offset_m(input: &MpcInput) -> f32 {
    let car = &input.car.pose;
    let at = &input.reference[0].at.pose;
    (car.x_m - at.x_m) * at.cos_heading - (car.y_m - at.y_m) * at.sin_heading
}

/// What [`MpcConfig::decide_sides`] decided.
struct Sides {
    /// Per obstacle slot: the inflated circle and its side, for the obstacles the plan passes.
    placed: [Option<(InflatedObstacle, ObstacleSide)>; MAX_OBSTACLES],
    /// The stop for the nearest obstacle that leaves no passage, if any.
    stop: Option<NoPassageStop>,
    /// Per obstacle slot, what the speed plan is held to for it: how far ahead, m, and at
    /// what speed at most from there, m/s: the stop short of one that leaves no passage
    /// (speed 0), or the start of the shift across to it from a nearer one passed on the other
    /// side and the fastest speed that makes it.
    slow: [Option<(f32, f32)>; MAX_OBSTACLES],
    /// Bit `i` set: obstacle slot `i` is alongside the car and being overtaken
    /// ([`MpcConfig::overtakes`]); a plan that enters it does not make the car brake.
    overtaken: u8,
}

/// Why the fallback was taken.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FallbackReason {
    /// A non-finite or out-of-range input (pose, speed, reference, obstacle).
    BadInput,
    /// An obstacle leaves no room for the body on either side within the corridor, and the car
    /// has stopped short of it (or is nearer than it can stop: braking at once).
    NoPassage,
    /// The lateral problem could not be built or solved (non-finite data).
    Solver,
    /// The plan after the iteration cap still enters an inflated obstacle.
    ObstacleNotCleared,
}

/// One point of the plan.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PlanPoint {
    /// Time ahead, s.
    pub t_s: f32,
    /// East, m (rear axle).
    pub x_m: f32,
    /// North, m.
    pub y_m: f32,
    /// Heading clockwise from north, rad.
    pub heading_rad: f32,
    /// Speed, m/s.
    pub speed_mps: f32,
    /// Steering (centre tyre), rad.
    pub steer_rad: f32,
}

/// What one solve produced.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MpcOutput {
    /// Steering command, % (STEERING_REPORT's unit and sign), within +-100.
    pub steer_cmd_pct: f32,
    /// Speed command, m/s, >= 0.
    pub speed_cmd_mps: f32,
    /// Status.
    pub status: ControlStatus,
    /// Why, when the status is the fallback.
    pub fallback: Option<FallbackReason>,
    /// The planned trajectory: the models rolled forward under the planned commands, every
    /// 0.1 s from now (point 0) to 2 s.
    pub plan: [PlanPoint; PLAN_STEPS + 1],
    /// Lateral ADMM iterations run.
    pub iterations: u16,
    /// Riccati factorisations of the lateral problem (1 + the penalty rebalances).
    pub factorisations: u16,
    /// Lateral primal residual after the last iteration (row units: m or rad).
    pub primal_residual: f32,
    /// Lateral dual residual.
    pub dual_residual: f32,
    /// Largest corridor violation of the plan's body corners, m (0 inside), against the
    /// corridor as relaxed for a car that starts outside it (`lateral::relax_corridor`).
    pub corridor_violation_m: f32,
    /// How far the body's corners are outside the corridor at the start (the car as the node
    /// estimates it now), m (0 inside; the corridor margin within its edges not counted).
    pub outside_corridor_m: f32,
    /// Passing side chosen for each obstacle slot (`None`: no obstacle, or not in reach).
    pub sides: [Option<ObstacleSide>; MAX_OBSTACLES],
}

/// The controller's state: warm starts, the side decisions, the last feasible plan.
#[derive(Clone, Debug)]
pub struct MpcState {
    workspace: Workspace<NX, STEPS, ROWS>,
    problem: Problem<NX, STEPS, ROWS>,
    speed: SpeedState,
    /// Linearisation for the next solve (the last plan's heading error and steering).
    lin: Option<Linearisation>,
    sides: [Option<ObstacleSide>; MAX_OBSTACLES],
    /// Per obstacle slot: it left no passage last tick (it takes `side_hysteresis_m` more room
    /// to pass it from then on: see `decide_sides`).
    blocked: [bool; MAX_OBSTACLES],
    /// Per obstacle slot: the speed the car shifts across to it at from a nearer one passed on
    /// the other side, m/s, held until it is passed; 0 or below: no speed does, held until the
    /// car is at a crawl; infinite: none (see `decide_sides`).
    pair_mps: [f32; MAX_OBSTACLES],
    /// Steering of the last accepted plan, and ticks since it was made.
    last_steer_plan: Option<([f32; STEPS + 1], u32)>,
    /// Ticks in a row whose plan entered an inflated obstacle beyond the tolerance.
    obstacle_violation_ticks: u16,
    /// The car brakes for an obstacle its plans did not clear
    /// ([`FallbackReason::ObstacleNotCleared`]): it goes on braking until a plan enters no
    /// inflated obstacle at all (or the path is new), instead of taking the first plan back
    /// that enters one by no more than the tolerance.
    obstacle_braking: bool,
    /// The commanded steering ramp (without the lead) after the last accepted solve, rad.
    steer_ramp_rad: Option<f32>,
}

impl Default for MpcState {
    fn default() -> Self {
        Self::new()
    }
}

impl MpcState {
    /// No solve yet. `const`, so that the firmware can keep the state (13 KiB) in a static
    /// rather than build it on its 16 KiB stack.
    pub const fn new() -> Self {
        Self {
            workspace: Workspace::new(),
            problem: Problem::zeroed(),
            speed: SpeedState::new(),
            lin: None,
            sides: [None; MAX_OBSTACLES],
            blocked: [false; MAX_OBSTACLES],
            pair_mps: [f32::INFINITY; MAX_OBSTACLES],
            last_steer_plan: None,
            obstacle_violation_ticks: 0,
            obstacle_braking: false,
            steer_ramp_rad: None,
        }
    }

    /// Writes [`MpcState::new`] into `slot` in place (`crate::in_place`).
    ///
    /// # Safety
    ///
    /// `slot` must be valid for writes of an `MpcState` and aligned for it.
    pub(crate) unsafe fn init_in_place(slot: *mut Self) {
        // SAFETY: every field of the `MpcState` the caller vouches for, once each; the solver's
        // workspace and problem by their own in-place constructors.
        unsafe {
            Workspace::init_in_place(addr_of_mut!((*slot).workspace));
            Problem::init_in_place(addr_of_mut!((*slot).problem));
            addr_of_mut!((*slot).speed).write(SpeedState::new());
            addr_of_mut!((*slot).lin).write(None);
            addr_of_mut!((*slot).sides).write([None; MAX_OBSTACLES]);
            addr_of_mut!((*slot).blocked).write([false; MAX_OBSTACLES]);
            addr_of_mut!((*slot).pair_mps).write([f32::INFINITY; MAX_OBSTACLES]);
            addr_of_mut!((*slot).last_steer_plan).write(None);
            addr_of_mut!((*slot).obstacle_violation_ticks).write(0);
            addr_of_mut!((*slot).obstacle_braking).write(false);
            addr_of_mut!((*slot).steer_ramp_rad).write(None);
        }
    }

    /// Forgets the warm start and the side decisions (a new path), in place (the state is
    /// 13 KiB: a fresh value would be built on the stack first).
    pub fn reset(&mut self) {
        self.speed = SpeedState::new();
        self.new_path();
    }

    /// A new path: forgets what belongs to the old one (the lateral warm start, the side
    /// decisions, the stop at its end) and keeps what the speed plan learnt of the car (its
    /// warm start in time, the speed bias and how well the model fits: [`SpeedState::new_path`]).
    /// Reset with every path, a planner that replans every 0.5-2 s restarted the speed plan's
    /// corrections each time, and a car whose speed loop its model does not describe surged
    /// 0.66 m/s over an 8 m/s limit (docs/findings.md).
    pub fn new_path(&mut self) {
        self.speed.new_path();
        // With `lin` `None` the next solve cold-starts: what it reads of the old path's solve
        // is forgotten, not the whole workspace rewritten (`Workspace::forget`).
        self.workspace.forget();
        self.lin = None;
        self.sides = [None; MAX_OBSTACLES];
        self.blocked = [false; MAX_OBSTACLES];
        self.pair_mps = [f32::INFINITY; MAX_OBSTACLES];
        self.last_steer_plan = None;
        self.obstacle_violation_ticks = 0;
        self.obstacle_braking = false;
        self.steer_ramp_rad = None;
    }
}

impl MpcConfig {
    /// Checks the parameters and precomputes the speed planner. Without `dynamics` the
    /// controller plans with the kinematic model at every speed.
    pub fn new(
        vehicle: VehicleParams,
        dynamics: Option<DynamicParams>,
        body: Body,
        max_steer_rate_rad_per_s: f32,
        speed_model: &SsBlock<2>,
        tuning: MpcTuning,
    ) -> Result<Self, MpcConfigError> {
        let positive = |v: f32| v.is_finite() && v > 0.0;
        let checks: [(bool, &'static str); 18] = [
            (positive(body.width_m), "body width_m"),
            (positive(body.length_m), "body length_m"),
            (
                body.rear_overhang_m.is_finite()
                    && body.rear_overhang_m >= 0.0
                    && body.rear_overhang_m < body.length_m,
                "body rear_overhang_m",
            ),
            (positive(max_steer_rate_rad_per_s), "steering rate limit"),
            (positive(vehicle.max_steer_rad), "vehicle max_steer"),
            (positive(vehicle.wheelbase_m), "vehicle wheelbase_m"),
            (
                tuning.steer_lead_s.is_finite()
                    && (0.0..=MAX_STEER_LEAD_S).contains(&tuning.steer_lead_s),
                "steer_lead_s (0 .. 0.3 s)",
            ),
            (
                tuning.steer_trust_s.is_finite() && tuning.steer_trust_s >= 0.0,
                "steer_trust_s (>= 0)",
            ),
            (
                positive(tuning.steer_rate_share) && tuning.steer_rate_share <= 1.0,
                "steer_rate_share (0 .. 1)",
            ),
            (
                tuning.admm.relaxation > 0.0 && tuning.admm.relaxation < 2.0,
                "ADMM relaxation (0 .. 2)",
            ),
            (weights_ok(&tuning.weights), "lateral weights"),
            (
                tuning.line_rule.is_none_or(|r| {
                    positive(r.lock_share)
                        && r.lateral_per_m2.is_finite()
                        && r.lateral_per_m2 >= 0.0
                }),
                "line_rule",
            ),
            (positive(tuning.stop_delay_s), "stop_delay_s"),
            (
                positive(tuning.corridor_return_mps2),
                "corridor_return_mps2",
            ),
            (
                tuning.return_from_m.is_finite() && tuning.return_from_m >= 0.0,
                "return_from_m (>= 0)",
            ),
            (
                tuning.obstacle_heading_rad > 0.0 && tuning.obstacle_heading_rad < 1.5,
                "obstacle_heading_rad (0 < h < 1.5)",
            ),
            (
                tuning.return_heading_rad > 0.0 && tuning.return_heading_rad <= 0.5,
                "return_heading_rad (0 < h <= 0.5)",
            ),
            (
                tuning.preview_s.is_finite() && tuning.preview_s >= 0.0,
                "preview_s",
            ),
        ];
        if let Some((_, what)) = checks.iter().find(|(ok, _)| !ok) {
            return Err(MpcConfigError::BadParameter(what));
        }
        let speed = SpeedPlanner::new(speed_model, tuning.speed).map_err(MpcConfigError::Speed)?;
        Ok(Self {
            file_steer: (vehicle.max_steer_rad, max_steer_rate_rad_per_s),
            stage: StageClock::for_steering(vehicle.wheelbase_m, max_steer_rate_rad_per_s),
            vehicle,
            dynamics,
            body,
            max_steer_rate_rad_per_s,
            tuning,
            speed,
        })
    }

    /// Plans with the steering turning the car `scale` times what the model file says (the
    /// node's steering check, [`crate::node::steering`]): the lock and the rate limit in
    /// centre-tyre angle are scaled, and so the conversion of the plan's angles to percent.
    /// Not finite or not positive: ignored.
    pub fn set_steer_scale(&mut self, scale: f32) {
        if scale.is_finite() && scale > 0.0 {
            self.vehicle.max_steer_rad = self.file_steer.0 * scale;
            self.max_steer_rate_rad_per_s = self.file_steer.1 * scale;
        }
    }

    /// The controller of the car a node is configured for: its geometry, body, dynamic model
    /// (if any), steering actuator rate limit and speed model, from the model file
    /// (`[vehicle]`, `[dynamics]`, `[speed]`); the plan's speed never exceeds the node's
    /// `max_speed_mps` nor the tuning's.
    pub fn for_node(node: &NodeConfig, tuning: MpcTuning) -> Result<Self, MpcConfigError> {
        let rate_rad_per_s =
            node.max_steer_rate_pct_per_s / STEER_PCT_LIMIT * node.vehicle.max_steer_rad;
        let mut tuning = tuning;
        tuning.speed.max_speed_mps = min(tuning.speed.max_speed_mps, node.max_speed_mps);
        Self::new(
            node.vehicle,
            node.dynamics,
            node.body,
            rate_rad_per_s,
            &node.velocity,
            tuning,
        )
    }

    /// The tuning.
    pub fn tuning(&self) -> &MpcTuning {
        &self.tuning
    }

    /// The body.
    pub fn body(&self) -> &Body {
        &self.body
    }

    /// The speed planner.
    pub fn speed_planner(&self) -> &SpeedPlanner {
        &self.speed
    }

    /// The steering plan's stages.
    pub fn stage(&self) -> &StageClock {
        &self.stage
    }

    /// Plans on `clock`'s stages instead of the ones the car's steering gives
    /// ([`StageClock::for_steering`]); for comparisons (a controller state planned on other
    /// stages is to be reset first).
    pub fn set_stage(&mut self, clock: StageClock) {
        self.stage = clock;
    }

    /// One solve: the commands to send now and the plan.
    pub fn solve(&self, state: &mut MpcState, input: &MpcInput) -> MpcOutput {
        let car = &input.car;
        let bias_mps = finite_or(car.speed_bias_mps, 0.0);
        let planning_bias_mps = state
            .speed
            .filter_bias(bias_mps, self.speed.tuning().bias_time_constant_s);
        let speed_start = SpeedStart {
            model_state: car.speed_model,
            bias_mps,
            planning_bias_mps,
            speed_mps: car.speed_mps,
            last_command_mps: car.last_speed_cmd_mps,
            in_held_turn: input.in_held_turn,
            slow_ahead: input.slow_ahead,
        };
        if !input_ok(input) {
            return self.fallback(state, input, &speed_start, FallbackReason::BadInput);
        }
        // 1. Obstacles: inflate, decide sides; where one leaves no passage, where to stop.
        let Sides {
            placed: obstacles,
            stop,
            slow,
            overtaken,
        } = match self.decide_sides(state, input) {
            Ok(o) => o,
            Err(reason) => return self.fallback(state, input, &speed_start, reason),
        };
        // 2. Speed plan.
        // Speed targets over the plan; beyond the reference, its last point's; short of an
        // obstacle that leaves no passage, no faster than stops before it; short of a shift
        // across between obstacles in a row, no faster than slows to the shift's speed.
        let last_target = input.reference.last().map_or(0.0, |r| r.speed_mps);
        let mut targets = [last_target; PLAN_STEPS + 1];
        for (t, r) in targets.iter_mut().zip(input.reference.iter()) {
            *t = r.speed_mps;
        }
        // Each stage's distance along the reference from its first point, measured once for
        // every cap (the plan's stages are the reference's: `PLAN_STEPS == STEPS`).
        let mut along = [0.0f32; PLAN_STEPS + 1];
        let mut along_m = 0.0;
        for (d, (p, r)) in along
            .iter_mut()
            .skip(1)
            .zip(input.reference.iter().zip(input.reference.iter().skip(1)))
        {
            let (dx, dy) = (r.at.pose.x_m - p.at.pose.x_m, r.at.pose.y_m - p.at.pose.y_m);
            along_m += math::sqrt(dx * dx + dy * dy);
            *d = along_m;
        }
        for zone in slow.iter().flatten() {
            self.cap_to_stop(&mut targets, &along, *zone);
        }
        let speed_plan = self
            .speed
            .plan(&mut state.speed, &speed_start, &targets, input.to_end_m);
        if stop.as_ref().is_some_and(|s| s.at_m <= NO_PASSAGE_NEAR_M)
            && finite_or(car.speed_mps, 0.0) < NO_PASSAGE_AT_REST_MPS
        {
            // Stopped short of it: no passage (status 3), until it moves on or goes.
            return self.fallback(state, input, &speed_start, FallbackReason::NoPassage);
        }
        // 3. Lateral problem about the previous plan.
        let x0 = self.initial_state(input, state.steer_ramp_rad);
        let speeds = self.stage.stage_speeds(&speed_plan.speeds_mps);
        let lin = self.linearisation(state, input, &x0, &speeds);
        let weights = self.weights_for(input);
        let setup = self.setup(self.mode(input), &speeds, &weights);
        let preview_m = max(car.speed_mps, 0.0) * self.tuning.preview_s;
        let built = lateral::build(
            &mut state.problem,
            &setup,
            input.reference,
            &lin,
            &obstacles,
            (preview_m, self.tuning.obstacle_heading_rad),
        );
        let masks = match built {
            Ok(m) => m,
            Err(BuildError::Discretisation) => {
                return self.fallback(state, input, &speed_start, FallbackReason::Solver);
            }
        };
        let start_outside_m = lateral::relax_corridor(
            &mut state.problem,
            &x0,
            (
                self.tuning.corridor_return_mps2,
                speeds.first().copied().unwrap_or(0.0),
                self.tuning.return_heading_rad,
            ),
            &self.stage,
        );
        lateral::taper_reference(
            &mut state.problem,
            &x0,
            &speeds,
            &self.stage,
            self.tuning.corridor_return_mps2,
            self.tuning.return_from_m,
            self.tuning.return_heading_rad,
        );
        // Avoiding: some obstacle reaches the body within the horizon, or the car stops for
        // one within reach.
        let avoiding = stop.as_ref().is_some_and(|s| s.in_reach)
            || state
                .problem
                .stages
                .iter()
                .zip(&masks.heading)
                .any(|(st, heading)| {
                    let mut slots = st.rows.iter().skip(lateral::ROW_OBSTACLE);
                    (0..MAX_OBSTACLES)
                        .any(|i| slots.next().is_some_and(|r| r.active) && heading & (1 << i) == 0)
                });
        if state.lin.is_some() {
            state.workspace.shift_each(&self.stage.tick_shares());
        } else {
            state.workspace.cold_start(&state.problem);
        }
        let report = match admm::solve(&mut state.workspace, &state.problem, &x0, &self.tuning.admm)
        {
            Ok(r) => r,
            Err(SolveError::BadPivot | SolveError::NonFinite) => {
                // The fallback forgets the linearisation, so the next solve cold-starts: what
                // the workspace keeps is then overwritten before it is read
                // (`Workspace::forget`; a reset costs 4 400 instructions more at the end of a
                // whole solve, which the bound counts).
                state.workspace.forget();
                return self.fallback(state, input, &speed_start, FallbackReason::Solver);
            }
        };
        // 4. The plan as sent: inputs within their bounds exactly, states rolled from x0.
        let mut planned_rates = [0.0f32; STEPS];
        for (r, it) in planned_rates.iter_mut().zip(&state.workspace.stages) {
            *r = it.u;
        }
        let (states, rates) = self.clamped_rollout(&state.problem, &x0, &planned_rates);
        if states.iter().any(|x| x.iter().any(|v| !v.is_finite())) {
            state.workspace.forget();
            return self.fallback(state, input, &speed_start, FallbackReason::Solver);
        }
        // The plan may still enter an obstacle after the iteration cap: at once within the time
        // braking needs to take hold (then only braking can help), or for several ticks in a
        // row further out (a solve that has not converged yet resolves it on the next ticks).
        let imminent = self.stage.index_at_s(self.tuning.stop_delay_s) as usize;
        // Nor is an obstacle the car is overtaking alongside: braking keeps it beside the car
        // longer, where driving on takes the car past it sooner.
        // Braking for an obstacle its plans did not clear, the car takes a plan back only
        // when it ends beside the obstacle too: one that ends short of it, not aside, would
        // drive the car on into it beyond the horizon.
        // Heading rows (lateral::heading_row) are no obstacle's: never an obstacle violation.
        let mut mask = if state.obstacle_braking {
            [overtaken; STEPS]
        } else {
            masks.terminal.map(|m| m | overtaken)
        };
        for (m, heading) in mask.iter_mut().zip(&masks.heading) {
            *m |= heading;
        }
        let v = violations(&state.problem, &states, &mask, imminent);
        let corridor_violation_m = v.corridor_m;
        // Braking for an obstacle already, a plan is taken back only when it clears every
        // one: a plan that reaches the obstacle by the tolerance at its horizon's end, taken
        // back and dropped again ticks later, sped a braking car up towards the obstacle it
        // could not clear (docs/findings.md).
        let tolerance = if state.obstacle_braking {
            0.0
        } else {
            self.tuning.obstacle_tolerance_m
        };
        if v.obstacle_m > tolerance {
            state.obstacle_violation_ticks = state.obstacle_violation_ticks.saturating_add(1);
        } else {
            state.obstacle_violation_ticks = 0;
        }
        // An imminent violation must show in two ticks in a row: one noisy position fix can
        // put a single plan's first stages inside (20 ms of latency is far below the speed
        // loop's 0.4 s delay).
        if (v.obstacle_imminent_m > tolerance && state.obstacle_violation_ticks >= 2)
            || state.obstacle_violation_ticks > self.tuning.obstacle_persist_ticks
            || (state.obstacle_braking && state.obstacle_violation_ticks > 0)
        {
            return self.fallback(
                state,
                input,
                &speed_start,
                FallbackReason::ObstacleNotCleared,
            );
        }
        state.obstacle_braking = false;
        let mut steer = [0.0f32; STEPS + 1];
        let mut e_psi = [0.0f32; STEPS + 1];
        for ((s, e), x) in steer.iter_mut().zip(e_psi.iter_mut()).zip(states.iter()) {
            *s = x.get(lateral::DELTA).copied().unwrap_or(0.0);
            *e = x.get(lateral::EPSI).copied().unwrap_or(0.0);
        }
        state.lin = Some(Linearisation {
            e_psi,
            delta: steer,
        });
        state.last_steer_plan = Some((steer, 0));
        let first_rate = rates.first().copied().unwrap_or(0.0);
        // The ramp moves on by one tick of the planned rate; the command leads it by the
        // actuator's lag.
        let ramp_rad = steer.first().copied().unwrap_or(0.0) + crate::SAMPLE_PERIOD_S * first_rate;
        state.steer_ramp_rad = Some(ramp_rad);
        // Within the first stage the first stage's rate; a lead that reaches past it takes the
        // plan's steering there (its next stages' rates, a reversal among them).
        let lead_at = self
            .stage
            .index_at_s(crate::SAMPLE_PERIOD_S + self.tuning.steer_lead_s);
        let steer_cmd_rad = if lead_at <= 1.0 {
            ramp_rad + self.tuning.steer_lead_s * first_rate
        } else {
            interpolate(&steer, lead_at)
        };
        let plan = self.rollout(input, &steer, &speed_plan.speeds_mps);
        MpcOutput {
            steer_cmd_pct: self.steer_pct(steer_cmd_rad),
            speed_cmd_mps: speed_plan.command_mps,
            status: if avoiding {
                ControlStatus::Avoiding
            } else {
                ControlStatus::Tracking
            },
            fallback: None,
            plan,
            iterations: report.iterations,
            factorisations: state.workspace.factorisations,
            primal_residual: report.primal_residual,
            dual_residual: report.dual_residual,
            corridor_violation_m,
            // The rows keep the corridor margin inside the corridor's edges (less where the
            // room is narrower than two margins): beyond them by the margin is outside it.
            outside_corridor_m: max(start_outside_m - weights.corridor_margin_m, 0.0),
            sides: state.sides,
        }
    }

    /// A tick without a solve: `out`, the previous tick's accepted output, moved on by one
    /// tick along its own plan (in place: it is 0.6 KiB), and the warm start aged by the same
    /// tick (the next solve starts where it would have after two solves). The steering ramp
    /// moves on at the plan's first rate (the plan holds it over the first step), the speed
    /// command is the first knot's (it holds for 0.2 s), the plan is the same trajectory seen
    /// one tick later. The node's drive stage runs it in a tick that completes a long path, so
    /// that no tick both loads a path and solves (docs/firmware.md, "Worst-case tick"). Its
    /// cost is fixed: no loop depends on the data.
    pub fn coast(&self, state: &mut MpcState, out: &mut MpcOutput) {
        let shares = self.stage.tick_shares();
        if let Some(lin) = state.lin.as_mut() {
            shift_values(&mut lin.e_psi, &shares);
            shift_values(&mut lin.delta, &shares);
            state.workspace.shift_each(&shares);
        }
        let tick_steps = 1.0 / TICKS_PER_STEP as f32;
        state.speed.shift();
        if let Some((_, age)) = &mut state.last_steer_plan {
            *age = age.saturating_add(1);
        }
        let steer_at = |k: usize| out.plan.get(k).map_or(0.0, |p| p.steer_rad);
        let tick_rad = (steer_at(1) - steer_at(0)) * tick_steps;
        if let Some(ramp) = &mut state.steer_ramp_rad {
            *ramp += tick_rad;
        }
        let steer_pct = out.steer_cmd_pct + tick_rad / self.vehicle.max_steer_rad * STEER_PCT_LIMIT;
        out.steer_cmd_pct = clamp(
            finite_or(steer_pct, out.steer_cmd_pct),
            -STEER_PCT_LIMIT,
            STEER_PCT_LIMIT,
        );
        // Point k becomes the old plan a fifth of a step after k: it reads points k and k + 1
        // only, so the points move first to last; the last one extrapolates the old last step.
        let point = |k: usize| out.plan.get(k).copied().unwrap_or_default();
        let last_step = (point(PLAN_STEPS - 1), point(PLAN_STEPS));
        for k in 0..=PLAN_STEPS {
            let (a, b, f) = match (out.plan.get(k), out.plan.get(k + 1)) {
                (Some(a), Some(b)) => (*a, *b, tick_steps),
                _ => (last_step.0, last_step.1, 1.0 + tick_steps),
            };
            if let Some(p) = out.plan.get_mut(k) {
                *p = PlanPoint {
                    t_s: k as f32 * STEP_S,
                    ..between(&a, &b, f)
                };
            }
        }
        out.iterations = 0;
        out.factorisations = 0;
    }

    /// The steering, %, of a car driven blind along `plan` (an accepted plan, as it was made)
    /// `travelled_m` after the plan's start at `speed_mps`: the plan's steering where the
    /// plan had covered that distance plus what the car covers in the steering lead, its
    /// last steering past its end. Indexed by distance, not time, so that a car braking along
    /// it turns where the plan turned (its curvature along its arc, to the kinematic model's
    /// first order) instead of sooner. Its cost is fixed: one pass over the plan's points.
    pub fn blind_steer_pct(
        &self,
        plan: &[PlanPoint; PLAN_STEPS + 1],
        travelled_m: f32,
        speed_mps: f32,
    ) -> f32 {
        let at_m = finite_or(travelled_m, 0.0)
            + max(finite_or(speed_mps, 0.0), 0.0) * self.tuning.steer_lead_s;
        let mut covered = 0.0f32;
        let mut steer = plan.first().map_or(0.0, |p| p.steer_rad);
        for pair in plan.windows(2) {
            let [a, b] = pair else {
                continue;
            };
            let step_m = max(0.5 * (a.speed_mps + b.speed_mps) * (b.t_s - a.t_s), 0.0);
            if covered + step_m >= at_m && step_m > 0.0 {
                let f = clamp((at_m - covered) / step_m, 0.0, 1.0);
                steer = a.steer_rad + f * (b.steer_rad - a.steer_rad);
                return self.steer_pct(steer);
            }
            covered += step_m;
            steer = b.steer_rad;
        }
        self.steer_pct(steer)
    }

    /// The lateral model of this solve: the hybrid switch's choice, kinematic if the car has no
    /// dynamic model.
    /// The model the steering is planned with: the dynamic one whenever the car has one and
    /// moves faster than its lower speed limit, else the kinematic one. Not the node's hybrid
    /// switch (which still picks the model of the node's own predictions and yaw rate): the
    /// linear single-track model is the kinematic one plus tyre slip, which vanishes at low
    /// speed, so it is right at every speed it is defined for, while a switch in the middle of a
    /// manoeuvre (the lateral acceleration of a lane change at 4 m/s crosses the switch's
    /// threshold) changes the plan's model and its initial state under a running solve; on the
    /// closed-loop rig the double lane change at 4-5 m/s touched a cone with the switch's
    /// choice and was clean with this one (docs/controller.md).
    fn mode(&self, input: &MpcInput) -> Mode {
        match &self.dynamics {
            Some(d) if input.car.speed_mps >= d.min_speed_mps => Mode::Dynamic,
            _ => Mode::Kinematic,
        }
    }

    fn setup<'a>(
        &'a self,
        mode: Mode,
        speeds: &'a [f32; STEPS + 1],
        weights: &'a Weights,
    ) -> LateralSetup<'a> {
        LateralSetup {
            vehicle: &self.vehicle,
            dynamics: self.dynamics.as_ref(),
            body: &self.body,
            weights,
            mode,
            speeds_mps: speeds,
            max_steer_rad: self.vehicle.max_steer_rad,
            max_steer_rate_rad_per_s: self.max_steer_rate_rad_per_s * self.tuning.steer_rate_share,
            stage: &self.stage,
        }
    }

    /// The weights of this solve: the tuning's, with [`MpcTuning::line_rule`]'s lateral weight
    /// when the path asks for that share of the lock (a non-finite curvature never applies it).
    fn weights_for(&self, input: &MpcInput) -> Weights {
        let mut weights = self.tuning.weights;
        if let Some(rule) = self.tuning.line_rule {
            let kappa = input.path_max_curvature_per_m;
            let demand_rad =
                math::atan(self.vehicle.wheelbase_m * if kappa < 0.0 { -kappa } else { kappa });
            if demand_rad >= rule.lock_share * self.vehicle.max_steer_rad {
                weights.lateral_per_m2 = rule.lateral_per_m2;
            }
        }
        weights
    }

    /// Error state now: offsets from the reference's first point.
    fn initial_state(&self, input: &MpcInput, steer_ramp_rad: Option<f32>) -> SVector<f32, NX> {
        let car = &input.car;
        let at = &input.reference[0].at.pose;
        let e_y = lateral_offset_m(input);
        let e_psi = math::wrap_pi(car.pose.heading_rad - at.heading_rad);
        let (vy, r) = match self.mode(input) {
            Mode::Dynamic => (car.lateral.vy_mps, car.lateral.yaw_rate_rps),
            Mode::Kinematic => (0.0, 0.0),
        };
        let trust_rad = self.max_steer_rate_rad_per_s * self.tuning.steer_trust_s;
        let start = match steer_ramp_rad {
            Some(ramp) => clamp(ramp, car.steer_rad - trust_rad, car.steer_rad + trust_rad),
            None => car.steer_rad,
        };
        let delta = clamp(
            start,
            -self.vehicle.max_steer_rad,
            self.vehicle.max_steer_rad,
        );
        SVector::<f32, NX>::from([e_y, e_psi, vy, r, delta])
    }

    /// The previous plan moved one tick ahead, or (first solve) the current heading error and
    /// the path's feedforward steering.
    fn linearisation(
        &self,
        state: &MpcState,
        input: &MpcInput,
        x0: &SVector<f32, NX>,
        speeds: &[f32; STEPS + 1],
    ) -> Linearisation {
        let e0 = x0.get(lateral::EPSI).copied().unwrap_or(0.0);
        let d0 = x0.get(lateral::DELTA).copied().unwrap_or(0.0);
        let mut lin = match &state.lin {
            Some(prev) => {
                let shares = self.stage.tick_shares();
                let mut l = *prev;
                shift_values(&mut l.e_psi, &shares);
                shift_values(&mut l.delta, &shares);
                l
            }
            None => {
                let mut l = Linearisation {
                    e_psi: [e0; STEPS + 1],
                    delta: [0.0; STEPS + 1],
                };
                let understeer = self.vehicle.understeer_s2_per_m2;
                for ((d, r), v) in l
                    .delta
                    .iter_mut()
                    .zip(input.reference.iter())
                    .zip(speeds.iter())
                {
                    *d = lateral::feedforward_steer_rad(
                        self.vehicle.wheelbase_m,
                        understeer,
                        *v,
                        r.curvature_per_m,
                    );
                }
                l
            }
        };
        // Stage 0 is the present: linearise there at the measured values.
        if let Some(e) = lin.e_psi.first_mut() {
            *e = e0;
        }
        if let Some(d) = lin.delta.first_mut() {
            *d = d0;
        }
        lin
    }

    /// Per obstacle: inflated circle and the side to pass it on (more room, with hysteresis),
    /// from where it lies along the path; and for the obstacles that leave room on neither
    /// side, where the car stops short of the nearest ([`NoPassageStop`]). Errors when such an
    /// obstacle is nearer than the car can stop before its inflated circle (braking at once).
    fn decide_sides(
        &self,
        state: &mut MpcState,
        input: &MpcInput,
    ) -> Result<Sides, FallbackReason> {
        let mut out = [None; MAX_OBSTACLES];
        let mut stop: Option<NoPassageStop> = None;
        let t = &self.tuning;
        let body = &self.body;
        let front = body.length_m - body.rear_overhang_m;
        let v = max(input.car.speed_mps, 0.0);
        let stopping_m = v * t.stop_delay_s + v * v / (2.0 * t.speed.decel_mps2);
        let reach_m = max(stopping_m, horizon_m(input));
        // A car at a crawl passes an obstacle only if it can get beside it before its front
        // reaches it: a sideways shift of d at full lock takes 2 sqrt(R d - d^2 / 4) forward
        // (two opposite arcs of the lock's radius R), the plan's tolerance of an obstacle
        // allowed. One stopped 3.5 m short of an object set off when a side seemed to open,
        // at the path's speed, could not swerve, and rolled into it on the speed loop's delay
        // before its fallback held (docs/findings.md). Faster, the plan and its fallback decide.
        let crawl = v < MEET_CLOSING_MPS;
        let lock_r = self.vehicle.wheelbase_m / math::tan(self.vehicle.max_steer_rad);
        let car_offset_m = lateral_offset_m(input);
        let mut overtaken = 0u8;
        let mut slow = [None; MAX_OBSTACLES];
        for (i, ((((slot, zone), memory), blocked), ob)) in out
            .iter_mut()
            .zip(slow.iter_mut())
            .zip(state.sides.iter_mut())
            .zip(state.blocked.iter_mut())
            .zip(input.obstacles)
            .enumerate()
        {
            let r = ob.map_or(0.0, |o| {
                o.radius_m + input.position_uncertainty_m + t.obstacle_margin_m
            });
            let Some(ob) = ob
                .as_ref()
                .filter(|o| o.ahead_m + r >= -body.rear_overhang_m)
            else {
                // None, or passed: forget the decisions.
                *memory = None;
                *blocked = false;
                if let Some(v) = state.pair_mps.get_mut(i) {
                    *v = f32::INFINITY;
                }
                continue;
            };
            // Room between the corridor's edge and the inflated circle on each side, and what
            // the plan's rows need there: the body and the corner rows' margin from the edge.
            // Through less, no plan satisfies its own rows: the pickup of docs/findings.md
            // (2.05 m wide, 2.15 m of room, a 0.15 m margin) fought the corridor beside the
            // obstacle, fell back and passed it by 0.29 m where 0.6 m was planned.
            // Where a moving obstacle will be across the path when the body's front reaches
            // its circle: closing in at the car's speed less the obstacle's along the path,
            // 2 m/s at least (a car at rest sets off), within the horizon; the corridor where
            // it is now.
            // It may also have braked by then (lateral::OBSTACLE_BRAKE_MPS2): the rows keep
            // the body clear of everywhere between, so the room is what both leave.
            let closing_mps = max(v - ob.velocity.along_mps, MEET_CLOSING_MPS);
            let gap_m = max(ob.ahead_m - front - r, 0.0);
            let meet_s = min(gap_m / closing_mps, self.stage.horizon_s());
            let inflated = InflatedObstacle::new(ob, r);
            if self.overtakes(ob, r, v, car_offset_m) {
                // Beside the car already: there is no stopping short of it, and no passing
                // behind it. The car keeps to its side of it (the rows push it away as far as
                // the corridor lets them) and drives on past it.
                let side = if ob.path_offset_m < car_offset_m {
                    ObstacleSide::Right
                } else {
                    ObstacleSide::Left
                };
                overtaken |= 1 << i;
                *blocked = false;
                *memory = Some(side);
                *slot = Some((inflated, side));
                continue;
            }
            let offset_m = ob.path_offset_m + ob.velocity.right_mps * meet_s;
            let braked_m = ob.path_offset_m + ob.velocity.right_mps * inflated.braked_s(meet_s);
            let (leftmost_m, rightmost_m) = (min(offset_m, braked_m), max(offset_m, braked_m));
            let room_left = (leftmost_m - r) + ob.left_m;
            let room_right = ob.right_m - (rightmost_m + r);
            let need = body.width_m
                + lateral::corridor_margin_m(&t.weights, ob.left_m, ob.right_m, 0.5 * body.width_m);
            let room = |s: ObstacleSide| match s {
                ObstacleSide::Left => room_left,
                ObstacleSide::Right => room_right,
            };
            let swerves = |s: ObstacleSide| {
                let half = 0.5 * body.width_m;
                let shift = match s {
                    ObstacleSide::Left => car_offset_m + half - (leftmost_m - r),
                    ObstacleSide::Right => rightmost_m + r - (car_offset_m - half),
                };
                let d = clamp(shift - t.obstacle_tolerance_m, 0.0, 2.0 * lock_r);
                !crawl || gap_m <= 0.0 || 2.0 * math::sqrt(lock_r * d - 0.25 * d * d) <= gap_m
            };
            let other = |s: ObstacleSide| match s {
                ObstacleSide::Left => ObstacleSide::Right,
                ObstacleSide::Right => ObstacleSide::Left,
            };
            // One that crosses the path is passed behind, never ahead of it: the side it
            // leaves, whatever the room (the other side's room closes as it comes).
            let behind = if ob.velocity.right_mps > CROSSING_MPS {
                Some(ObstacleSide::Left)
            } else if ob.velocity.right_mps < -CROSSING_MPS {
                Some(ObstacleSide::Right)
            } else {
                None
            };
            let keep = memory.filter(|s| {
                behind.is_none_or(|b| b == *s)
                    && swerves(*s)
                    && room(*s) >= need
                    && room(other(*s)) < room(*s) + t.side_hysteresis_m
            });
            let side = match keep {
                Some(s) => s,
                None => {
                    let s = match behind {
                        Some(b) => b,
                        None if room_left >= room_right => ObstacleSide::Left,
                        None => ObstacleSide::Right,
                    };
                    // Once it left no passage, it takes the hysteresis's room more to pass:
                    // room within the position's noise of the need flipped the judgement
                    // from tick to tick, and the pickup of docs/findings.md squeezed past
                    // where it had been stopping.
                    let hysteresis = if *blocked { t.side_hysteresis_m } else { 0.0 };
                    if room(s) < need + hysteresis || room(s).is_nan() || !swerves(s) {
                        *memory = None;
                        *blocked = true;
                        *zone = stop_short(&mut stop, ob.ahead_m - r - front, stopping_m, reach_m)?;
                        continue;
                    }
                    s
                }
            };
            *blocked = false;
            *memory = Some(side);
            *slot = Some((inflated, side));
        }
        // Obstacles in a row passed on opposite sides: between them the car shifts across by
        // what both ask, in the run between the body clear of the nearer one's centre and its
        // front at the farther one's. A shift no speed makes there leaves no passage at the
        // farther one, until the car is at a crawl and judges it from where it is (above);
        // one made only slower than the car goes, slows it before the shift starts
        // (docs/mpc.md, "Obstacles in a row"). A slalom of circles 15 m apart, each passable
        // alone, was hit at 3.6-4.2 m/s on the model's own car: the pair was found only when
        // the second came within the horizon (docs/findings.md).
        for (j, (held, slow_j)) in state.pair_mps.iter_mut().zip(slow.iter_mut()).enumerate() {
            if crawl && *held <= 0.0 {
                *held = f32::INFINITY;
            }
            let Some(Some((far, far_side))) = out.get(j).copied() else {
                continue;
            };
            if far.speed_mps > CROSSING_MPS || overtaken & (1 << j) != 0 {
                continue;
            }
            let mut start_m = 0.0;
            for (i, placed) in out.iter().enumerate() {
                let Some((near, near_side)) = placed else {
                    continue;
                };
                // Nearer: ahead of it along the path, or (abreast) in a lower slot.
                if near.speed_mps > CROSSING_MPS
                    || (near.ahead_m, i) >= (far.ahead_m, j)
                    || *near_side == far_side
                {
                    continue;
                }
                let apart_m = far.path_offset_m - near.path_offset_m;
                let shift_m = match near_side {
                    ObstacleSide::Left => apart_m,
                    ObstacleSide::Right => -apart_m,
                } + near.radius_m
                    + far.radius_m
                    + body.width_m
                    - t.obstacle_tolerance_m;
                if shift_m > 0.0 {
                    let run_m = far.ahead_m - near.ahead_m - body.length_m;
                    *held = min(*held, self.shift_speed_mps(shift_m, run_m));
                    start_m = max(start_m, near.ahead_m + body.rear_overhang_m);
                }
            }
            if *held > 0.0 {
                // Slow by the latest start; the nearer ones passed, held until this one is.
                *slow_j = (*held < f32::INFINITY).then_some((start_m, *held));
                continue;
            }
            if let Some(slot) = out.get_mut(j) {
                *slot = None;
            }
            if let (Some(memory), Some(blocked)) =
                (state.sides.get_mut(j), state.blocked.get_mut(j))
            {
                *memory = None;
                *blocked = true;
            }
            *slow_j = stop_short(
                &mut stop,
                far.ahead_m - far.radius_m - front,
                stopping_m,
                reach_m,
            )?;
        }
        Ok(Sides {
            placed: out,
            stop,
            slow,
            overtaken,
        })
    }

    /// The fastest speed at which the car shifts sideways by `shift_m` within `run_m` of
    /// travel, m/s, and back to straight: the kinematic model to first order in the heading,
    /// the curvature ramped at the steering rate the plan may use and held within the lock
    /// (the sideways jerk `v^2 c` bang-bang: `shift = v^2 c T^3 / 32` over `run = v T`; at
    /// the lock `run = v p + sqrt(v^2 p^2 + 4 shift R)`, `p` the time from straight to the
    /// lock, `R` its radius). 0 or below: not at any speed (`run < 2 sqrt(shift R)`, or no run
    /// at all: `mpc_properties::the_speed_of_a_shift_is_the_one_at_which_the_fastest_manoeuvre_makes_it`
    /// flies the manoeuvre at the speed given).
    pub fn shift_speed_mps(&self, shift_m: f32, run_m: f32) -> f32 {
        let wheelbase = self.vehicle.wheelbase_m;
        let lock_per_m = math::tan(self.vehicle.max_steer_rad) / wheelbase;
        let rate_per_m_s = self.max_steer_rate_rad_per_s * self.tuning.steer_rate_share / wheelbase;
        let cubic = run_m * run_m * run_m * rate_per_m_s / (32.0 * shift_m);
        let to_lock = cubic * lock_per_m / rate_per_m_s;
        if shift_m <= 2.0 * to_lock * to_lock * lock_per_m {
            return cubic;
        }
        let at_lock = (run_m * run_m - 4.0 * shift_m / lock_per_m) * rate_per_m_s
            / (2.0 * run_m * lock_per_m);
        // No run (the two within the body's length of each other): no speed.
        if run_m > 0.0 {
            at_lock
        } else {
            0.0
        }
    }

    /// Whether the car is alongside obstacle `ob` (its circle, not inflated, reaches back past
    /// the body's front) and overtaking it: faster along the path, and its rear past the circle
    /// inflated to `r` sooner at its speed `v_mps` than braking drops its front behind that
    /// circle. Braking is taken at its best, [`lateral::OBSTACLE_BRAKE_MPS2`] after the speed
    /// loop's `stop_delay_s`, and the car's stop is not modelled (both favour braking, the
    /// fallback's way). A slower car that changes into the car's lane beside its front half is
    /// such an obstacle: braking for it, the car stayed beside it while it came across, and it
    /// ran into the car's side (`scripts/sil-moving.py --scenario cutin`, docs/bus.md).
    /// Beside, not ahead: its centre is outside the body's width (the car's lateral offset from
    /// the path `car_offset_m`). One whose circle the front has reached, in line with the body,
    /// has been hit, and is braked for: a black-box probe's car that could not stop for an
    /// object 8 m ahead at 8 m/s, once its front reached the circle, took it for one it was
    /// overtaking, said "avoiding" and sped up through it (docs/findings.md).
    fn overtakes(&self, ob: &Obstacle, r: f32, v_mps: f32, car_offset_m: f32) -> bool {
        let front = self.body.length_m - self.body.rear_overhang_m;
        let closing = v_mps - ob.velocity.along_mps;
        let beside = (ob.path_offset_m - car_offset_m).abs() >= 0.5 * self.body.width_m;
        if !(ob.ahead_m - ob.radius_m < front && closing > 0.0 && beside) {
            return false;
        }
        let past_s = (ob.ahead_m + r + self.body.rear_overhang_m) / closing;
        // Braking: the gap still closes at `closing` over the delay, then the car falls back
        // at `a`: `a tau^2 / 2 - closing tau = closing delay + back`.
        let (a, delay) = (lateral::OBSTACLE_BRAKE_MPS2, self.tuning.stop_delay_s);
        let back_m = front - (ob.ahead_m - r);
        let under = closing * closing + 2.0 * a * (closing * delay + back_m);
        let behind_s = delay + (closing + math::sqrt(max(under, 0.0))) / a;
        past_s < behind_s
    }

    /// Caps each stage's speed target at the speed from which the car slows to `floor_mps`
    /// (0: stops) by `at_m` ahead (`along_m`: the stage's distance along the reference from
    /// its first point): after the `stop_delay_s` the speed loop takes to take hold, at the
    /// speed plan's deceleration, `v t + (v^2 - floor^2) / 2a = d`; `floor_mps` at least.
    fn cap_to_stop(
        &self,
        targets: &mut [f32; PLAN_STEPS + 1],
        along_m: &[f32; PLAN_STEPS + 1],
        (at_m, floor_mps): (f32, f32),
    ) {
        let a = self.tuning.speed.decel_mps2;
        let t = self.tuning.stop_delay_s;
        let base = t * t + floor_mps * floor_mps / (a * a);
        for (target, along) in targets.iter_mut().zip(along_m) {
            let d = max(at_m - along, 0.0);
            *target = min(
                *target,
                max(a * (math::sqrt(base + 2.0 * d / a) - t), floor_mps),
            );
        }
    }

    /// Re-rolls the linear model from `x0` with the solver's inputs clamped to the rate bounds
    /// and the steering kept in its range (the plan that is sent meets both exactly).
    fn clamped_rollout(
        &self,
        p: &Problem<NX, STEPS, ROWS>,
        x0: &SVector<f32, NX>,
        u: &[f32; STEPS],
    ) -> ([SVector<f32, NX>; STEPS + 1], [f32; STEPS]) {
        let mut states = [*x0; STEPS + 1];
        let mut rates = [0.0f32; STEPS];
        let max = self.vehicle.max_steer_rad;
        let mut x = *x0;
        for (k, (st, uk)) in p.stages.iter().zip(u).enumerate() {
            let delta = x.get(lateral::DELTA).copied().unwrap_or(0.0);
            // delta_{k+1} = delta_k + h u exactly (trapezoidal integrator).
            let h = self.stage.stage_s(k);
            let to_range_lo = (-max - delta) / h;
            let to_range_hi = (max - delta) / h;
            let mut rate = clamp(finite_or(*uk, 0.0), st.u_lower, st.u_upper);
            rate = clamp(rate, to_range_lo, to_range_hi);
            if let Some(r) = rates.get_mut(k) {
                *r = rate;
            }
            x = st.a * x + st.b * rate + st.c;
            if let Some(s) = states.get_mut(k + 1) {
                *s = x;
            }
        }
        (states, rates)
    }

    /// The planned trajectory: the lateral model of this solve's mode rolled forward from the
    /// car's pose under the planned steering (at its stages, read at the speed plan's steps: a
    /// stage is at least a step, so the steering plan covers the speed plan) and speeds.
    /// Public for the controller's benchmark, which times a solve's end (`qemu_mpc_bench`).
    pub fn rollout(
        &self,
        input: &MpcInput,
        steer: &[f32; STEPS + 1],
        speeds: &[f32; PLAN_STEPS + 1],
    ) -> [PlanPoint; PLAN_STEPS + 1] {
        let car = &input.car;
        let mut pose = car.pose;
        let mut lat = car.lateral;
        let dynamics = match self.mode(input) {
            Mode::Dynamic => self.dynamics.as_ref(),
            Mode::Kinematic => None,
        };
        let mut plan = [PlanPoint::default(); PLAN_STEPS + 1];
        let mut prev_steer = steer.first().copied().unwrap_or(0.0);
        let mut prev_speed = speeds.first().copied().unwrap_or(0.0);
        for (k, (pt, v)) in plan.iter_mut().zip(speeds).enumerate() {
            let s = self.stage.at_plan_step(steer, k);
            if k > 0 {
                let v_mid = 0.5 * (prev_speed + v);
                let d_mid = 0.5 * (prev_steer + s);
                match dynamics {
                    None => {
                        let kappa = self.vehicle.curvature_per_m(d_mid, v_mid);
                        pose.advance_no_slip(v_mid, kappa * v_mid * STEP_S, STEP_S);
                    }
                    Some(dynamics) => {
                        let before = lat;
                        dynamics.step(&mut lat, v_mid, d_mid, STEP_S);
                        let r_mid = 0.5 * (before.yaw_rate_rps + lat.yaw_rate_rps);
                        let vy_rear =
                            0.5 * (dynamics.rear_side_mps(&before) + dynamics.rear_side_mps(&lat));
                        pose.advance(v_mid, vy_rear, r_mid * STEP_S, STEP_S);
                    }
                }
            }
            prev_steer = s;
            prev_speed = *v;
            *pt = PlanPoint {
                t_s: k as f32 * STEP_S,
                x_m: pose.x_m,
                y_m: pose.y_m,
                heading_rad: pose.heading_rad,
                speed_mps: *v,
                steer_rad: s,
            };
        }
        plan
    }

    /// Status 3: speed command 0; steering along the last accepted plan while it lasts, else
    /// the measured steering held (0 if that is not finite). Public for the controller's
    /// benchmark: a solve can run every iteration and then end here instead of in
    /// [`Self::rollout`], and the bound adds the difference (`qemu_mpc_bench`,
    /// `mpc_part_fallback_end`).
    pub fn fallback(
        &self,
        state: &mut MpcState,
        input: &MpcInput,
        speed_start: &SpeedStart,
        reason: FallbackReason,
    ) -> MpcOutput {
        let measured = finite_or(input.car.steer_rad, 0.0);
        let mut steer = [measured; STEPS + 1];
        if reason == FallbackReason::ObstacleNotCleared {
            // The plans that led here kept entering the obstacle: their steering is not
            // followed (nor held once they run out, which beside an obstacle passed on one side
            // and returned from on the other turns the car back into it). The car brakes along
            // the path's direction at the offset it has, the steering ramped there at the
            // actuator's rate.
            let target = self.lane_hold_steer_rad(input);
            let mut held = measured;
            for (k, s) in steer.iter_mut().enumerate().skip(1) {
                let step = self.max_steer_rate_rad_per_s * self.stage.stage_s(k - 1);
                held += clamp(target - held, -step, step);
                *s = held;
            }
            state.last_steer_plan = None;
            state.obstacle_braking = true;
        } else if let Some((plan, age)) = &mut state.last_steer_plan {
            *age = age.saturating_add(1);
            // The plan was made `age` ticks ago: stage k now is `age` ticks after its stage k.
            let age = *age as usize;
            for (k, s) in steer.iter_mut().enumerate() {
                *s = interpolate(plan, self.stage.index_after(k, age));
            }
        }
        state.lin = None;
        state.steer_ramp_rad = None;
        let speeds = self.speed.stop(speed_start).speeds_mps;
        let lead = self.stage.index_at_s(self.tuning.steer_lead_s);
        let steer_cmd_rad = interpolate(&steer, lead);
        let plan = if pose_ok(&input.car.pose) {
            self.rollout(input, &steer, &speeds)
        } else {
            [PlanPoint::default(); PLAN_STEPS + 1]
        };
        MpcOutput {
            steer_cmd_pct: self.steer_pct(steer_cmd_rad),
            speed_cmd_mps: 0.0,
            status: ControlStatus::Fallback,
            fallback: Some(reason),
            plan,
            iterations: 0,
            factorisations: 0,
            primal_residual: 0.0,
            dual_residual: 0.0,
            corridor_violation_m: 0.0,
            outside_corridor_m: 0.0,
            sides: state.sides,
        }
    }

    /// [`lane_hold_steer_rad`] at the reference's first point (the car's station).
    fn lane_hold_steer_rad(&self, input: &MpcInput) -> f32 {
        let Some(r) = input.reference.first() else {
            return 0.0;
        };
        let heading_error = math::wrap_pi(input.car.pose.heading_rad - r.at.pose.heading_rad);
        lane_hold_steer_rad(
            &self.vehicle,
            heading_error,
            input.car.speed_mps,
            r.curvature_per_m,
        )
    }

    /// Centre-tyre angle to steering percent, within +-100 (0 if not finite).
    fn steer_pct(&self, rad: f32) -> f32 {
        let pct = rad / self.vehicle.max_steer_rad * STEER_PCT_LIMIT;
        clamp(finite_or(pct, 0.0), -STEER_PCT_LIMIT, STEER_PCT_LIMIT)
    }
}

/// The steering that turns a car `heading_error_rad` off the path's direction (positive:
/// turned right of it) at `speed_mps` to that direction and holds it there, on a path of
/// `curvature_per_m` at its station: pure pursuit of a point [`LANE_HOLD_PREVIEW_S`] ahead on
/// the line parallel to the path through the car, at least [`LANE_HOLD_MIN_PREVIEW_M`], plus
/// the steering of the path's curvature, within the steering range. Braking along the lane at
/// the offset the car has, neither towards an obstacle beside it nor off the road (the
/// fallback's), nor on across the path's bends (a car that has lost its path,
/// `node::drive`).
pub fn lane_hold_steer_rad(
    vehicle: &VehicleParams,
    heading_error_rad: f32,
    speed_mps: f32,
    curvature_per_m: f32,
) -> f32 {
    let v = max(finite_or(speed_mps, 0.0), 0.0);
    let preview = max(v * LANE_HOLD_PREVIEW_S, LANE_HOLD_MIN_PREVIEW_M);
    let l = vehicle.wheelbase_m;
    let (sin_e, _) = math::sin_cos(heading_error_rad);
    let turn = math::atan(-2.0 * l * sin_e / preview);
    let ff = lateral::feedforward_steer_rad(l, vehicle.understeer_s2_per_m2, v, curvature_per_m);
    let max_steer = vehicle.max_steer_rad;
    clamp(finite_or(ff + turn, 0.0), -max_steer, max_steer)
}

/// The last reference point's station ahead of the first, m (along the first's heading: the
/// chord, which is the arc to within 1 % for turns up to 0.5 rad over the horizon).
fn horizon_m(input: &MpcInput) -> f32 {
    match (input.reference.first(), input.reference.last()) {
        (Some(a), Some(b)) => {
            let (dx, dy) = (b.at.pose.x_m - a.at.pose.x_m, b.at.pose.y_m - a.at.pose.y_m);
            dx * a.at.pose.sin_heading + dy * a.at.pose.cos_heading
        }
        _ => 0.0,
    }
}

/// How far a plan's body leaves the corridor and enters the inflated obstacles.
struct Violations {
    /// Largest corridor violation, m.
    corridor_m: f32,
    /// Largest obstacle violation, m.
    obstacle_m: f32,
    /// Largest obstacle violation in the first `imminent` stages, m.
    obstacle_imminent_m: f32,
}

/// Largest corridor and obstacle violations of the rows over the planned states.
fn violations(
    p: &Problem<NX, STEPS, ROWS>,
    states: &[SVector<f32, NX>; STEPS + 1],
    terminal_mask: &[u8; STEPS],
    imminent: usize,
) -> Violations {
    let mut v = Violations {
        corridor_m: 0.0,
        obstacle_m: 0.0,
        obstacle_imminent_m: 0.0,
    };
    for (k, ((st, x), mask)) in p
        .stages
        .iter()
        .zip(states.iter().skip(1))
        .zip(terminal_mask)
        .enumerate()
    {
        for (i, row) in st.rows.iter().enumerate() {
            if !row.active {
                continue;
            }
            let g = row.violation(row.eval(x));
            match i.checked_sub(lateral::ROW_OBSTACLE) {
                None => v.corridor_m = max(v.corridor_m, g),
                // Terminal rows (lateral::terminal_row) pull the plan aside early; they are
                // not expected to hold yet.
                Some(slot) if mask & (1 << slot) != 0 => {}
                Some(_) => {
                    v.obstacle_m = max(v.obstacle_m, g);
                    if k < imminent {
                        v.obstacle_imminent_m = max(v.obstacle_imminent_m, g);
                    }
                }
            }
        }
    }
    v
}

/// Linear interpolation in a per-step sequence at fractional step `at` (held beyond the ends).
fn interpolate<const N: usize>(v: &[f32; N], at: f32) -> f32 {
    let at = clamp(at, 0.0, N.saturating_sub(1) as f32);
    // `as` truncates towards zero (at >= 0): the step at or before `at`.
    let i = at as usize;
    let frac = at - i as f32;
    let a = v.get(i).copied().unwrap_or(0.0);
    let b = v.get(i + 1).copied().unwrap_or(a);
    a + (b - a) * frac
}

/// The point `f` of the way from `a` to `b` (beyond `b` for `f` > 1): linear, the heading
/// along the shorter way, the speed not below 0.
fn between(a: &PlanPoint, b: &PlanPoint, f: f32) -> PlanPoint {
    let mix = |x: f32, y: f32| x + (y - x) * f;
    PlanPoint {
        t_s: mix(a.t_s, b.t_s),
        x_m: mix(a.x_m, b.x_m),
        y_m: mix(a.y_m, b.y_m),
        heading_rad: math::wrap_pi(
            a.heading_rad + math::wrap_pi(b.heading_rad - a.heading_rad) * f,
        ),
        speed_mps: max(mix(a.speed_mps, b.speed_mps), 0.0),
        steer_rad: mix(a.steer_rad, b.steer_rad),
    }
}

/// Each value moved its stage's share `f[i]` of the way to the next one (the last held).
fn shift_values(v: &mut [f32; STEPS + 1], f: &[f32; STEPS]) {
    let old = *v;
    for ((i, cur), f) in v.iter_mut().enumerate().zip(f) {
        if let Some(next) = old.get(i + 1) {
            *cur += (next - *cur) * f;
        }
    }
}

/// Every field finite, by one test of their sum (a NaN or an infinity in any one, or values
/// too large to add, is not; fewer instructions and less flash than a test each).
fn pose_ok(p: &Pose) -> bool {
    (p.x_m + p.y_m + p.heading_rad + p.sin_heading + p.cos_heading).is_finite()
}

fn sample_ok(s: &Sample) -> bool {
    pose_ok(&s.pose)
        && !s.left_m.is_nan()
        && !s.right_m.is_nan()
        && s.left_m > -1e6
        && s.right_m > -1e6
}

fn weights_ok(w: &Weights) -> bool {
    let nonneg = |v: f32| v.is_finite() && v >= 0.0;
    let positive = |v: f32| v.is_finite() && v > 0.0;
    nonneg(w.lateral_per_m2)
        && nonneg(w.heading_per_rad2)
        && nonneg(w.lateral_speed_per_mps2)
        && nonneg(w.yaw_rate_per_rps2)
        && nonneg(w.steer_per_rad2)
        && positive(w.steer_rate)
        && positive(w.terminal_factor)
        && positive(w.corridor_weight_per_m)
        && nonneg(w.corridor_margin_m)
        && positive(w.obstacle_weight_per_m)
        && positive(w.rho_corridor)
        && positive(w.rho_obstacle)
        && positive(w.rho_steer)
        && positive(w.rho_steer_rate)
}

/// Every number the solve reads is finite (corridor widths may be +inf: unbounded).
fn input_ok(input: &MpcInput) -> bool {
    let car = &input.car;
    let reference_ok = input.reference.iter().all(|r| {
        sample_ok(&r.at)
            && [r.front_left, r.front_right, r.rear_left, r.rear_right]
                .iter()
                .all(|p| sample_ok(&p.sample) && p.ahead_m.is_finite())
            && r.curvature_per_m.is_finite()
            && r.speed_mps.is_finite()
    });
    // The fields that must be finite by one test of their sum, as in `pose_ok`.
    let obstacles_ok = input.obstacles.iter().flatten().all(|o| {
        let v = &o.velocity;
        let sum = o.east_m
            + o.north_m
            + o.radius_m
            + o.ahead_m
            + o.path_offset_m
            + v.east_mps
            + v.north_mps
            + v.along_mps
            + v.right_mps;
        sum.is_finite() && o.radius_m >= 0.0 && !o.left_m.is_nan() && !o.right_m.is_nan()
    });
    pose_ok(&car.pose)
        && car.speed_mps.is_finite()
        && car.steer_rad.is_finite()
        && car.lateral.vy_mps.is_finite()
        && car.lateral.yaw_rate_rps.is_finite()
        && input.position_uncertainty_m.is_finite()
        && input.position_uncertainty_m >= 0.0
        && !input.to_end_m.is_nan()
        && reference_ok
        && obstacles_ok
}
