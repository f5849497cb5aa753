//! Stage 4, drive: the controller that follows the planner's path (the paper's "hybrid
//! predictive controller").
//!
//! The planner's frames (PATH_HEADER, PATH_POINT, PATH_LIMITS, OBSTACLE, LOCAL_ORIGIN) are
//! assembled by [`PlannerInputs`] as they arrive (stage 1). Each tick, with a complete path and
//! a valid position, the configured controller computes the steering and speed commands:
//! - [`Controller::Mpc`], model-predictive control over the identified models
//!   ([`crate::control::mpc`], docs/mpc.md): the reference is the path sampled at the stations
//!   the car is expected to reach (the previous plan's speeds, trapezoidal rule), the body's
//!   ends carry the narrowest corridor between the axle and that end, obstacles are placed
//!   along the path; its plan (the models rolled forward under the planned commands) becomes
//!   the PREDICTION frames;
//! - [`Controller::PurePursuit`], the reference controller it is measured against
//!   ([`crate::control::pure_pursuit`]); the PREDICTION frames stay the node's roll-out.
//!
//! A tick that completes a path of more than [`SHORT_PATH_POINTS`] points (its validation and
//! load over every point) does not also solve: the model-predictive controller sends the
//! previous tick's plan moved on by one tick ([`MpcConfig::coast`]; without a plan from the
//! previous tick, the node holds as below, status 0 if it had no path before, else 3) and
//! solves on the new path in the next tick. So loading a path and solving never add up in one
//! tick (docs/firmware.md, "Worst-case tick").
//!
//! CONTROL_COMMAND goes out every tick: status 0 (no path: speed 0, steering held), 1 tracking,
//! 2 avoiding (an obstacle decided a side), 3 fallback (no valid position or speed model yet,
//! or a heading that has not settled yet, [`super::smoothing::HeadingSettle`]:
//! speed 0, for the driver to drive on until the controller reports tracking; the controller's
//! own fallback: speed 0, steering along the last feasible plan; or the car
//! has lost the path, [`Tracking::has_lost_path`]: speed 0, wheels straight, until the planner
//! sends a new path; latched, so that a noisy estimate straying back into the corridor does
//! not hand the car back to a controller; or the car reports reverse gear: speed 0, steering
//! held, while it does; or the steering report is stale: speed 0, steering held, until a
//! report comes again). Never a NaN: every command is checked finite, else
//! the fallback. Its `fallback_reason` says which of these fallbacks it is ([`FallbackCause`];
//! 0 when the status is not the fallback).
//!
//! The state (about 35 KiB: two paths of 256 points, the controller's warm start and its
//! reference) is kept apart from [`super::Node`] so that a platform can place it in a static:
//! built on the 16 KiB stack it would overflow it. [`Drive::init`] builds it in place in
//! uninitialised RAM (the firmware's way: nothing of it in flash); [`Drive::new`] is `const`
//! (a static initialised with it keeps its 35 KiB image in flash).
use core::mem::MaybeUninit;
use core::ptr::addr_of_mut;

use super::follow::SteerFollow;
use crate::can::codec::{
    ControlCommand, ControlStatus, FallbackCause, ObstacleCircle, PlannerMessage,
};
use crate::control::mpc::longitudinal::{
    SLOW_AHEAD_EXCESS_MPS, SLOW_AHEAD_SHARE, SPEED_LIMIT_SLACK_MPS,
};
use crate::control::mpc::{
    self, FallbackReason, MpcConfig, MpcInput, MpcOutput, MpcState, MpcTuning, ReferencePoint,
    Sample, SidePoint, DEFAULT_TUNING, MAX_OBSTACLES, PLAN_STEPS, STEPS,
};
use crate::control::path::{LateralLimit, Path, PathCar, PathSample, Projection, Tracking};
use crate::control::planner::{ObstacleMotion, PlannerEvent, PlannerInputs};
use crate::control::pure_pursuit::{
    self, CarState as PursuitCar, PurePursuitConfig, PurePursuitState, PurePursuitTuning,
};
use crate::image::{Image, ImageError, ImageReader, ImageWriter};
use crate::in_place::fill;
use crate::model::dynamic::LateralState;
use crate::model::hybrid::Mode;
use crate::model::kinematic::Pose;
use crate::model::predictor::PredictedPoint;
use crate::model::SsBlockState;

use super::estimator::Xy;
use super::smoothing::{HeadingSettle, Smoothing};
use super::stage::{Stage, StageProbe, SHORT_PATH_POINTS};
use super::{NodeConfig, PREDICTION_POINTS, VELOCITY_DELAY_CAP};

/// What a path must leave the car of `config` ([`crate::control::path::Path::validate_for`]):
/// room for its body.
pub fn path_car(config: &NodeConfig) -> PathCar {
    PathCar {
        body_width_m: config.body.width_m,
    }
}

/// Which controller drives.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Controller {
    /// Model-predictive control over the identified models.
    Mpc,
    /// The reference controller: pure pursuit with a PI speed loop.
    PurePursuit,
}

impl Image for Controller {
    fn write(&self, w: &mut ImageWriter<'_>) {
        w.word(match self {
            Controller::Mpc => 0,
            Controller::PurePursuit => 1,
        });
    }
    fn read(r: &mut ImageReader<'_>) -> Result<Self, ImageError> {
        match r.word()? {
            0 => Ok(Controller::Mpc),
            1 => Ok(Controller::PurePursuit),
            _ => Err(r.out_of_range()),
        }
    }
}

/// What the drive stage needs of this tick's estimate and models.
#[derive(Clone, Copy, Debug)]
pub struct DriveInputs<'a> {
    /// Filtered rear-axle pose; `None` while invalid.
    pub pose: Option<Pose>,
    /// The antenna's dead-reckoned position ([`super::estimator::EstimatorState::dead_reckoned`]):
    /// its change over a tick is the car's motion, free of the fixes' jumps.
    pub dead_reckoned: Xy,
    /// The heading's error variance as the estimator reckons it, rad^2.
    pub heading_var_rad2: f32,
    /// The estimator corrected the heading towards a course this tick (the receiver's or the
    /// track's): what the heading's settling counts ([`HeadingSettle`]).
    pub heading_corrected: bool,
    /// Speed, m/s (its magnitude).
    pub speed_mps: f32,
    /// The car reports reverse gear (SPEED_REPORT `direction`): no controller drives it.
    pub reversing: bool,
    /// The active lateral model's state.
    pub lateral: LateralState,
    /// The rear axle's sideways velocity (tyre slip), m/s: its course is the heading turned by
    /// `rear_side / speed`.
    pub rear_side_mps: f32,
    /// Measured centre-tyre steering angle, rad, times `steer_scale`.
    pub steer_rad: f32,
    /// STEERING_REPORT as received, % (`None`: invalid or stale): whether it follows the
    /// node's commands ([`super::follow`]).
    pub steer_report_pct: Option<f32>,
    /// The steering gain the node's steering check uses (1: the model file's,
    /// [`super::steering`]): the controllers' lock and rate limit are scaled by it.
    pub steer_scale: f32,
    /// Lateral model the hybrid switch chose.
    pub mode: Mode,
    /// Eq 5's state after this tick (its next step consumes the command sent now); `None`
    /// until a speed was measured.
    pub speed_model: Option<&'a SsBlockState<2, VELOCITY_DELAY_CAP>>,
}

/// What the drive stage decided this tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DriveOutput {
    /// CONTROL_COMMAND.
    pub command: ControlCommand,
    /// The controller's planned trajectory at the PREDICTION frames' horizons (0.2 .. 2 s),
    /// when it has one (the model-predictive controller, while it drives).
    pub plan: Option<[PredictedPoint; PREDICTION_POINTS]>,
    /// How far the body, as estimated, is outside the corridor, m (measured by the
    /// model-predictive controller's last solve; 0 in its fallback and with pure pursuit).
    pub outside_corridor_m: f32,
}

/// A body outside the corridor by more than this raises NODE_STATUS `outside_corridor`, m:
/// the corridor's rows are soft, and a bend the body cannot sweep
/// inside the corridor, or a reversal the steering cannot follow at the path's speed, was
/// driven outside it while CONTROL_COMMAND said "tracking" (a black-box probe: 0.6 m out of a
/// hairpin for 8.6 s, 2.2 m out of a figure eight at 8 m/s).
pub const OUTSIDE_CORRIDOR_M: f32 = 0.1;

/// What one planner frame did ([`Drive::receive`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Received {
    /// The planner's map origin (1e-7 deg), when a LOCAL_ORIGIN completed it.
    pub origin: Option<(i32, i32)>,
    /// When the frame completed a path (accepted or refused), its stage:
    /// [`Stage::PathComplete`] for a path of more than [`SHORT_PATH_POINTS`] points, else
    /// [`Stage::PathCompleteShort`].
    pub completed: Option<Stage>,
}

/// The reference controller before it has run (`Drive::new` and `Drive::init`).
const IDLE_PURSUIT: PurePursuitState = PurePursuitState {
    integral_mps: 0.0,
    projection: None,
    steer_cmd_pct: 0.0,
};

/// CONTROL_COMMAND before any was sent (`Drive::new` and `Drive::init`).
const NO_COMMAND: ControlCommand = ControlCommand {
    status: ControlStatus::NoPath,
    fallback: FallbackCause::None,
    steer_cmd_pct: Some(0.0),
    speed_cmd_mps: Some(0.0),
};

/// The drive stage's state. See the module doc for why it lives apart from the node.
#[derive(Clone, Debug)]
pub struct Drive {
    planner: PlannerInputs,
    mpc: MpcState,
    mpc_config: Option<MpcConfig>,
    pursuit_tuning: PurePursuitTuning,
    pursuit: PurePursuitState,
    /// The rear axle's projection on the path last tick.
    projection: Option<Projection>,
    /// The last plan's speeds (the reference's stations follow them).
    planned_speeds: Option<[f32; PLAN_STEPS + 1]>,
    /// The solve's reference, filled each tick (kept in place: 3.4 KiB, a quarter of the
    /// controller's stack when it was built there).
    reference: [ReferencePoint; STEPS + 1],
    /// The model-predictive controller's last accepted output (kept in place: it is 0.6 KiB).
    last_plan: Option<MpcOutput>,
    /// ... and it is the previous tick's.
    planned_last_tick: bool,
    /// How far the car has been driven blind along `last_plan` since the position was lost,
    /// m ([`Drive::blind`]); `None` while it is known.
    blind_m: Option<f32>,
    /// A long path completed this tick: no solve until the next ([`Stage::DriveCoast`]).
    path_loaded: bool,
    /// Commands sent last tick.
    last_speed_cmd_mps: f32,
    last_steer_cmd_pct: f32,
    /// CONTROL_COMMAND sent last tick, and where the car was relative to the path.
    last_command: ControlCommand,
    last_tracking: Option<Tracking>,
    /// The position the controllers follow ([`Smoothing`]).
    smoothing: Smoothing,
    /// Whether the heading has settled: until it has, the controllers do not drive.
    heading: HeadingSettle,
    /// The car lost the path ([`Tracking::has_lost_path`]): it stays stopped until a new path
    /// loads, however the noisy estimate judges the next ticks.
    lost_path: bool,
    /// While it stops, a car that lost the path still along it steers the lane hold at this
    /// station (moved on by the distance it drives each tick) and segment hint; `None`:
    /// wheels straight ([`lost_steer_pct`]).
    lost_along: Option<(f32, usize)>,
    /// The controller could not be built for this car (the model file's reader refuses such a
    /// car; kept so that a corrupt image falls back instead of driving).
    unconfigured: bool,
    /// Whether the steering report follows the commands ([`SteerFollow`]).
    follow: SteerFollow,
}

impl Default for Drive {
    fn default() -> Self {
        Self::new()
    }
}

impl Drive {
    /// Nothing received, not configured. `const`: a platform keeps it in a static.
    pub const fn new() -> Self {
        Self {
            planner: PlannerInputs::new(),
            mpc: MpcState::new(),
            mpc_config: None,
            pursuit_tuning: pure_pursuit::DEFAULT_TUNING,
            pursuit: IDLE_PURSUIT,
            projection: None,
            planned_speeds: None,
            reference: [ReferencePoint::ZERO; STEPS + 1],
            last_plan: None,
            planned_last_tick: false,
            blind_m: None,
            path_loaded: false,
            last_speed_cmd_mps: 0.0,
            last_steer_cmd_pct: 0.0,
            last_command: NO_COMMAND,
            last_tracking: None,
            smoothing: Smoothing::new(),
            heading: HeadingSettle::new(),
            lost_path: false,
            lost_along: None,
            unconfigured: true,
            follow: SteerFollow::new(),
        }
    }

    /// Builds [`Drive::new`] in `slot`, in place: the state (35 KiB) is larger than the
    /// firmware's stack, and a static initialised with `Drive::new()` keeps a copy of it in
    /// flash (`crate::in_place`). The firmware keeps `slot` in uninitialised RAM.
    pub fn init(slot: &mut MaybeUninit<Self>) -> &mut Self {
        let p = slot.as_mut_ptr();
        // SAFETY: `p` is valid for writes and aligned (it comes from `slot`); every field of
        // the `Drive` is written exactly once below, through raw pointers (no reference to
        // uninitialised memory is made), the large ones by their own in-place constructors,
        // before `assume_init_mut`.
        unsafe {
            PlannerInputs::init_in_place(addr_of_mut!((*p).planner));
            MpcState::init_in_place(addr_of_mut!((*p).mpc));
            addr_of_mut!((*p).mpc_config).write(None);
            addr_of_mut!((*p).pursuit_tuning).write(pure_pursuit::DEFAULT_TUNING);
            addr_of_mut!((*p).pursuit).write(IDLE_PURSUIT);
            addr_of_mut!((*p).projection).write(None);
            addr_of_mut!((*p).planned_speeds).write(None);
            fill(addr_of_mut!((*p).reference), ReferencePoint::ZERO);
            addr_of_mut!((*p).last_plan).write(None);
            addr_of_mut!((*p).planned_last_tick).write(false);
            addr_of_mut!((*p).blind_m).write(None);
            addr_of_mut!((*p).path_loaded).write(false);
            addr_of_mut!((*p).last_speed_cmd_mps).write(0.0);
            addr_of_mut!((*p).last_steer_cmd_pct).write(0.0);
            addr_of_mut!((*p).last_command).write(NO_COMMAND);
            addr_of_mut!((*p).last_tracking).write(None);
            addr_of_mut!((*p).smoothing).write(Smoothing::new());
            addr_of_mut!((*p).heading).write(HeadingSettle::new());
            addr_of_mut!((*p).lost_path).write(false);
            addr_of_mut!((*p).lost_along).write(None);
            addr_of_mut!((*p).unconfigured).write(true);
            addr_of_mut!((*p).follow).write(SteerFollow::new());
            slot.assume_init_mut()
        }
    }

    /// Forgets everything received and configures the controller for the car of `config`,
    /// in place (the MPC's speed planner is precomputed here: about 0.6 M instructions, once).
    pub fn configure(&mut self, config: &NodeConfig) {
        // Everything in place: this state is too large to pass through the stack.
        self.planner.reset();
        self.mpc.reset();
        self.pursuit = PurePursuitState::default();
        self.projection = None;
        self.planned_speeds = None;
        self.last_plan = None;
        self.planned_last_tick = false;
        self.blind_m = None;
        self.path_loaded = false;
        self.last_speed_cmd_mps = 0.0;
        self.last_steer_cmd_pct = 0.0;
        self.smoothing = Smoothing::for_estimator(&config.estimator);
        self.heading = HeadingSettle::new();
        self.lost_path = false;
        self.lost_along = None;
        self.planner.set_car(path_car(config));
        let tuning = mpc_tuning(config);
        self.set_braking(config, &tuning);
        self.mpc_config = match config.controller {
            Controller::Mpc => MpcConfig::for_node(config, tuning).ok(),
            Controller::PurePursuit => None,
        };
        self.unconfigured = config.controller == Controller::Mpc && self.mpc_config.is_none();
        self.follow = SteerFollow::new();
    }

    /// Whether the steering report has run against the controllers' commands (latched:
    /// [`super::follow`]); the controllers then stop the car.
    pub fn steering_reversed(&self) -> bool {
        self.follow.reversed()
    }

    /// The paths' speed envelope brakes at the active controller's deceleration: the
    /// model-predictive controller's speed reference (`SpeedTuning::decel_mps2` of `tuning`),
    /// pure pursuit's stop (`stop_decel_mps2`). Taken from the tunings, not from the built
    /// configuration: reading the configuration back here made the compiler build it on the
    /// stack before moving it into place (1.3 KiB more stack at boot).
    fn set_braking(&mut self, config: &NodeConfig, tuning: &MpcTuning) {
        let decel = match config.controller {
            Controller::Mpc => tuning.speed.decel_mps2,
            Controller::PurePursuit => self.pursuit_tuning.stop_decel_mps2,
        };
        // A refused value (not finite and positive) leaves the path's braking as it was.
        self.planner.set_braking(decel);
        // The model file's reader takes only a positive, finite limit.
        self.planner
            .set_lateral_limit(config.max_lateral_accel_mps2.map(|a| LateralLimit {
                accel_mps2: a,
                width_m: config.body.width_m,
            }));
    }

    /// What the planner sent so far.
    pub fn planner(&self) -> &PlannerInputs {
        &self.planner
    }

    /// CONTROL_COMMAND as sent last tick.
    pub fn last_command(&self) -> ControlCommand {
        self.last_command
    }

    /// The car relative to the path last tick, when a controller tracked it.
    pub fn last_tracking(&self) -> Option<Tracking> {
        self.last_tracking
    }

    /// Replaces the model-predictive controller's tuning (host tools that sweep it; the node
    /// runs [`mpc_tuning`] otherwise) for the car of `config`; `false` (and the controller
    /// unconfigured: fallback) if the tuning is refused.
    pub fn tune_mpc(&mut self, config: &NodeConfig, tuning: MpcTuning) -> bool {
        self.mpc.reset();
        self.set_braking(config, &tuning);
        self.mpc_config = MpcConfig::for_node(config, tuning).ok();
        self.unconfigured = config.controller == Controller::Mpc && self.mpc_config.is_none();
        self.mpc_config.is_some()
    }

    /// Replaces the reference controller's tuning (host tools that sweep it; the node runs
    /// [`pure_pursuit::DEFAULT_TUNING`] otherwise) for the car of `config`.
    pub fn tune_pursuit(&mut self, config: &NodeConfig, tuning: PurePursuitTuning) {
        self.pursuit_tuning = tuning;
        self.set_braking(config, &mpc_tuning(config));
    }

    /// Applies one planner message received at `t_us` (stage 1).
    pub fn receive(&mut self, message: &PlannerMessage, t_us: u64) -> Received {
        // The points of the path being assembled: a frame that completes it has its whole
        // stream in, so this is the path's length.
        let points = self.planner.receiving().map_or(0, |(_, p, l, _)| p.max(l));
        let completed = |long: &mut bool| {
            *long |= points > SHORT_PATH_POINTS;
            Some(if points > SHORT_PATH_POINTS {
                Stage::PathComplete
            } else {
                Stage::PathCompleteShort
            })
        };
        match self.planner.receive(message, t_us) {
            PlannerEvent::PathActivated(_) => {
                self.new_path();
                Received {
                    origin: None,
                    completed: completed(&mut self.path_loaded),
                }
            }
            PlannerEvent::PathInvalid(..) => Received {
                origin: None,
                completed: completed(&mut self.path_loaded),
            },
            PlannerEvent::Origin { lat_e7, lon_e7 } => Received {
                origin: Some((lat_e7, lon_e7)),
                completed: None,
            },
            PlannerEvent::None => Received::default(),
        }
    }

    /// The local frame moved: a path in the old frame means nothing any more.
    pub fn frame_changed(&mut self) {
        self.planner.drop_path();
        self.new_path();
    }

    /// The node moved its own local frame: the active path, in the old one, is dropped (the
    /// car stops following it: no path). Only that, to keep the estimating tick that moves
    /// the frame within its budget; the controllers start afresh when the next path activates
    /// ([`Self::new_path`]).
    pub fn drop_path(&mut self) {
        self.planner.drop_path();
    }

    fn new_path(&mut self) {
        self.blind_m = None;
        self.mpc.new_path();
        self.pursuit.integral_mps = 0.0;
        self.pursuit.projection = None;
        self.projection = None;
        self.planned_speeds = None;
        self.lost_path = false;
        self.lost_along = None;
    }

    /// Stage 4: this tick's commands. `probe` marks where the model-predictive controller's
    /// problem and solve end ([`Stage::DriveReference`], [`Stage::MpcSolve`]), or its coast
    /// in a tick that loaded a long path ([`Stage::DriveCoast`]).
    pub fn tick<P: StageProbe>(
        &mut self,
        config: &NodeConfig,
        inputs: &DriveInputs<'_>,
        probe: &mut P,
    ) -> DriveOutput {
        self.last_tracking = None;
        let path_loaded = core::mem::take(&mut self.path_loaded);
        let planned_last_tick = core::mem::take(&mut self.planned_last_tick);
        self.follow
            .observe(&self.last_command, inputs.steer_report_pct);
        let out = self.decide(config, inputs, path_loaded, planned_last_tick, probe);
        self.last_command = out.command;
        out
    }

    fn decide<P: StageProbe>(
        &mut self,
        config: &NodeConfig,
        inputs: &DriveInputs<'_>,
        path_loaded: bool,
        planned_last_tick: bool,
        probe: &mut P,
    ) -> DriveOutput {
        let Some(path) = self.planner.path() else {
            self.smoothing.forget();
            return self.hold(ControlStatus::NoPath, FallbackCause::None);
        };
        if inputs.reversing {
            // The controllers and their models drive forwards only: a car in reverse gear is
            // held (speed 0, steering where it was last commanded) until it reports forward,
            // or no direction, again (the control pose's smoothing starts afresh then).
            self.smoothing.forget();
            return self.hold(ControlStatus::Fallback, FallbackCause::Reversing);
        }
        // Counted with a path only: the ticks without one are the estimating ticks, whose
        // bound has no room for it (docs/firmware.md, "Worst-case tick").
        let settled = self.heading.update(
            &config.estimator,
            inputs.pose.is_some(),
            inputs.heading_corrected,
        );
        let (Some(pose), Some(speed_model), true) = (inputs.pose, inputs.speed_model, settled)
        else {
            self.smoothing.forget();
            let cause = if inputs.pose.is_some() && inputs.speed_model.is_some() {
                FallbackCause::HeadingSettling
            } else {
                FallbackCause::NotReady
            };
            if inputs.pose.is_none() {
                if let Some(out) = self.blind(config, inputs.speed_mps, planned_last_tick) {
                    return out;
                }
            }
            self.blind_m = None;
            return self.hold(ControlStatus::Fallback, cause);
        };
        self.blind_m = None;
        let pose = self.smoothing.control_pose(
            &config.estimator,
            pose,
            inputs.dead_reckoned,
            inputs.speed_mps,
            inputs.heading_var_rad2,
        );
        if self.unconfigured {
            return self.hold(ControlStatus::Fallback, FallbackCause::Unconfigured);
        }
        if inputs.steer_scale < 0.0 || self.follow.reversed() {
            // The steering check found the car turning against its steering report
            // ([`super::steering::SteeringCheck::reversed`]: the estimate is right again, the
            // models take the sign), or the report ran against the commands
            // ([`super::follow`]). A command's sign may be as wrong as the report's, so no
            // controller steers: wheels straight, stopped.
            self.last_steer_cmd_pct = 0.0;
            return self.hold(ControlStatus::Fallback, FallbackCause::SteeringReversed);
        }
        if self.lost_path {
            // Latched: a noisy estimate that strays back into the corridor does not hand a
            // car that left it back to a controller; the planner replans (a new path clears
            // it, [`Drive::new_path`]).
            let steer = lost_steer_pct(path, &mut self.lost_along, config, &pose, inputs);
            return self.stop_lost(steer);
        }
        if inputs.steer_report_pct.is_none() {
            // No steering report: the controllers cannot see the wheels, and the heading is
            // dead-reckoned on the last report's angle with a growing bound. The car is held,
            // steering where it was last commanded (the actuator holds it, and the models
            // assume it), until a report comes again; not latched. Tracking on instead, a
            // black-box probe's car came back from 2 s of silence in a 30 m arc 1.1 m outside
            // its corridor (docs/findings.md). The control pose starts afresh on the estimate.
            self.smoothing.forget();
            return self.hold(ControlStatus::Fallback, FallbackCause::SteeringStale);
        }
        // Here, with a path only: the estimating ticks' bound has no room for it.
        if let Some(mpc) = self.mpc_config.as_mut() {
            mpc.set_steer_scale(inputs.steer_scale);
        }
        let output = match (config.controller, self.mpc_config.as_ref()) {
            (Controller::Mpc, Some(mpc)) if path_loaded => {
                // The coast as [`Drive::coast`] does it, written out here: calling the helper
                // from both places cost the estimating tick's bound 127 instructions as the
                // code moved (docs/firmware.md, "Worst-case tick").
                let Some(out) = self.last_plan.as_mut().filter(|_| planned_last_tick) else {
                    // Nothing to move on: the path takes effect next tick.
                    return match self.last_command.status {
                        ControlStatus::NoPath => {
                            self.hold(ControlStatus::NoPath, FallbackCause::None)
                        }
                        _ => self.hold(ControlStatus::Fallback, FallbackCause::PathLoading),
                    };
                };
                mpc.coast(&mut self.mpc, out);
                probe.lap(Stage::DriveCoast);
                self.planned_last_tick = true;
                mpc_command(out)
            }
            (Controller::Mpc, Some(mpc)) => 'solve: {
                let Some(solved) = mpc_tick(
                    mpc,
                    &mut self.mpc,
                    path,
                    (self.planner.obstacles(), self.planner.obstacle_motion()),
                    &mut self.projection,
                    &mut self.planned_speeds,
                    &mut self.reference,
                    pose,
                    inputs,
                    speed_model,
                    self.last_speed_cmd_mps,
                    config,
                    probe,
                ) else {
                    return self.hold(ControlStatus::Fallback, FallbackCause::BadInput);
                };
                let (out, tracking) = match solved {
                    Ok(solved) => solved,
                    Err(Unplanned::Lost(lost)) => {
                        self.last_tracking = Some(lost);
                        self.lost_along = along_when_lost(&lost);
                        let steer =
                            lost_steer_pct(path, &mut self.lost_along, config, &pose, inputs);
                        return self.stop_lost(steer);
                    }
                    Err(Unplanned::LeftWindow(tracking)) => {
                        // The car was found on another part of its path, the rest of the
                        // path searched after its window: no solve in the same tick (the
                        // bound's plan branch has no room for both); the last plan moves on as
                        // in a tick that loads a path, and the next tick solves from the new
                        // projection's window.
                        self.last_tracking = Some(tracking);
                        let out = self.coast(planned_last_tick);
                        probe.lap(Stage::DriveCoast);
                        match out {
                            Some(out) => break 'solve out,
                            None => {
                                return self
                                    .hold(ControlStatus::Fallback, FallbackCause::PositionJumped)
                            }
                        }
                    }
                };
                self.last_tracking = Some(tracking);
                let command = mpc_command(&out);
                if out.status != mpc::ControlStatus::Fallback {
                    self.last_plan = Some(out);
                    self.planned_last_tick = true;
                }
                command
            }
            _ => {
                let car = PursuitCar {
                    pose: Some(pose),
                    speed_mps: inputs.speed_mps,
                    rear_side_mps: inputs.rear_side_mps,
                };
                let mut pursuit = PurePursuitConfig::for_node(config, self.pursuit_tuning);
                pursuit.vehicle.max_steer_rad *= inputs.steer_scale;
                let out = pursuit.process(
                    &mut self.pursuit,
                    Some(path),
                    self.planner.obstacles(),
                    &car,
                );
                self.last_tracking = out.tracking;
                if let Some(lost) = out
                    .tracking
                    .filter(|t| t.has_lost_path(config.body.width_m))
                {
                    self.lost_along = along_when_lost(&lost);
                    let steer = lost_steer_pct(path, &mut self.lost_along, config, &pose, inputs);
                    return self.stop_lost(steer);
                }
                DriveOutput {
                    command: ControlCommand {
                        status: out.status,
                        // Pure pursuit's own fallbacks are all inputs it cannot use: no pose,
                        // a path it cannot project the car on or sample ahead, a non-finite
                        // result (its speed input is checked finite first).
                        fallback: match out.status {
                            ControlStatus::Fallback => FallbackCause::BadInput,
                            _ => FallbackCause::None,
                        },
                        steer_cmd_pct: Some(out.steer_cmd_pct),
                        speed_cmd_mps: Some(out.speed_cmd_mps),
                    },
                    plan: None,
                    outside_corridor_m: 0.0,
                }
            }
        };
        match (output.command.steer_cmd_pct, output.command.speed_cmd_mps) {
            (Some(steer), Some(speed)) if steer.is_finite() && speed.is_finite() => {
                self.last_steer_cmd_pct = steer;
                self.last_speed_cmd_mps = speed;
                output
            }
            _ => self.hold(ControlStatus::Fallback, FallbackCause::NonFiniteCommand),
        }
    }

    /// The car has lost the path ([`Tracking::has_lost_path`]): speed 0, steering `steer_pct`
    /// ([`lost_steer_pct`]).
    fn stop_lost(&mut self, steer_pct: f32) -> DriveOutput {
        self.lost_path = true;
        self.last_steer_cmd_pct = steer_pct;
        self.hold(ControlStatus::Fallback, FallbackCause::LostPath)
    }

    /// The position was lost (no GNSS for longer than the estimator bridges) while the
    /// model-predictive controller drove: the car brakes, steering along the last accepted
    /// plan by the distance it has covered since ([`mpc::MpcConfig::blind_steer_pct`]), and
    /// holds the plan's last steering past its end. That plan was made for the path from the
    /// last position known, and is the best guess of the steering the path asks for; the
    /// steering held at the loss (`hold`) was the middle of a manoeuvre: measured, the CAT
    /// Vehicle swerving past the obstacle at 8 m/s lost its position with -10 % held and
    /// turned 0.28 rad further off while it braked, 5.6 m beside its path when the position
    /// came back (docs/controller.md, "A lost position"). `None` when there is no such plan
    /// (pure pursuit, no plan in the previous tick and not already blind).
    fn blind(
        &mut self,
        config: &NodeConfig,
        speed_mps: f32,
        planned_last_tick: bool,
    ) -> Option<DriveOutput> {
        if config.controller != Controller::Mpc {
            return None;
        }
        // The plan starts at the car of the tick it was made in, one tick before the first
        // blind one.
        let before = match self.blind_m {
            Some(m) => m,
            None if planned_last_tick => 0.0,
            None => return None,
        };
        let (Some(mpc), Some(out)) = (self.mpc_config.as_ref(), self.last_plan.as_ref()) else {
            return None;
        };
        let speed = crate::math::clamp_finite(speed_mps, 0.0, f32::MAX);
        let travelled = before + speed * crate::SAMPLE_PERIOD_S;
        let steer = mpc.blind_steer_pct(&out.plan, travelled, speed);
        self.blind_m = Some(travelled);
        self.last_steer_cmd_pct = steer;
        self.last_speed_cmd_mps = 0.0;
        Some(DriveOutput {
            command: ControlCommand {
                status: ControlStatus::Fallback,
                fallback: FallbackCause::NotReady,
                steer_cmd_pct: Some(steer),
                speed_cmd_mps: Some(0.0),
            },
            plan: None,
            outside_corridor_m: 0.0,
        })
    }

    /// In a tick that does not solve, the last tick's plan moved on by one tick
    /// (`MpcConfig::coast`) and its commands; `None` without a plan of the last tick.
    fn coast(&mut self, planned_last_tick: bool) -> Option<DriveOutput> {
        let (Some(mpc), Some(out)) = (
            self.mpc_config.as_ref(),
            self.last_plan.as_mut().filter(|_| planned_last_tick),
        ) else {
            return None;
        };
        mpc.coast(&mut self.mpc, out);
        self.planned_last_tick = true;
        Some(mpc_command(out))
    }

    /// Speed 0, steering held where it was last commanded.
    fn hold(&mut self, status: ControlStatus, fallback: FallbackCause) -> DriveOutput {
        self.last_speed_cmd_mps = 0.0;
        DriveOutput {
            command: ControlCommand {
                status,
                fallback,
                steer_cmd_pct: Some(self.last_steer_cmd_pct),
                speed_cmd_mps: Some(0.0),
            },
            plan: None,
            outside_corridor_m: 0.0,
        }
    }
}

/// The model-predictive controller's tuning for the car of `config`: [`DEFAULT_TUNING`] (tuned on
/// the CAT Vehicle) with what the car's model file sets: `[control] mpc_lateral_weight_per_m2`
/// (that weight on every path, in place of the tuning's rule for a path that needs the lock),
/// and `[vehicle] steer_lag_s`, from which the steering command leads the plan by the lag plus
/// the tick the command takes to reach the actuator (the built-in lead, 0.07 s, is a 0.05 s
/// lag's: the CAT Vehicle's simulated actuator; docs/controller.md, "A slow steering
/// actuator").
pub fn mpc_tuning(config: &NodeConfig) -> MpcTuning {
    let mut tuning = DEFAULT_TUNING;
    if let Some(lag) = config.steer_lag_s {
        tuning.steer_lead_s = lag + crate::SAMPLE_PERIOD_S;
    }
    if let Some(w) = config.mpc_lateral_weight_per_m2 {
        tuning.weights.lateral_per_m2 = w;
        tuning.line_rule = None;
    } else {
        // Below 0.99: the CAT Vehicle's own file, whose share rounds to either side of 1,
        // keeps the weight it was tuned with.
        let share = steering_agility(config) / REFERENCE_AGILITY_PER_M_S;
        if share < 0.99 {
            tuning.weights.lateral_per_m2 =
                crate::math::max(tuning.weights.lateral_per_m2 * share * share, 1.0);
        }
    }
    tuning
}

/// How fast the car's steering can change its path's curvature: the actuator's rate over the
/// wheelbase, 1/(m s) (small angles: curvature = centre-tyre angle / wheelbase).
fn steering_agility(config: &NodeConfig) -> f32 {
    let rate_rad_per_s = config.max_steer_rate_pct_per_s / crate::vehicle::STEER_PCT_LIMIT
        * config.vehicle.max_steer_rad;
    rate_rad_per_s / config.vehicle.wheelbase_m
}

/// The CAT Vehicle's steering agility (60 %/s of 35.5 deg on a 2.62 m wheelbase), 1/(m s):
/// the built-in lateral weight was tuned on it. A car whose steering changes its curvature
/// more slowly gets the weight times the square of its share of this (1 at least): pulled
/// towards the line with the CAT Vehicle's weight, a slow one swings through it (a 4.8 m
/// wheelbase truck at 40 %/s of 32 deg on an S-curve, docs/findings.md).
pub const REFERENCE_AGILITY_PER_M_S: f32 = 0.6 * 35.5 * core::f32::consts::PI / 180.0 / 2.62;

/// CONTROL_COMMAND and the PREDICTION frames of a model-predictive controller's output.
fn mpc_command(out: &MpcOutput) -> DriveOutput {
    DriveOutput {
        command: ControlCommand {
            status: match out.status {
                mpc::ControlStatus::Tracking => ControlStatus::Tracking,
                mpc::ControlStatus::Avoiding => ControlStatus::Avoiding,
                mpc::ControlStatus::Fallback => ControlStatus::Fallback,
            },
            fallback: match (out.status, out.fallback) {
                (mpc::ControlStatus::Fallback, Some(reason)) => match reason {
                    FallbackReason::BadInput => FallbackCause::BadInput,
                    FallbackReason::NoPassage => FallbackCause::NoPassage,
                    FallbackReason::Solver => FallbackCause::Solver,
                    FallbackReason::ObstacleNotCleared => FallbackCause::ObstacleNotCleared,
                },
                // A fallback the solve did not name (none does today): an input it refused.
                (mpc::ControlStatus::Fallback, None) => FallbackCause::BadInput,
                _ => FallbackCause::None,
            },
            steer_cmd_pct: Some(out.steer_cmd_pct),
            speed_cmd_mps: Some(out.speed_cmd_mps),
        },
        plan: Some(prediction_points(out)),
        outside_corridor_m: out.outside_corridor_m,
    }
}

/// The plan at the PREDICTION frames' horizons: every second 0.1 s step.
fn prediction_points(out: &MpcOutput) -> [PredictedPoint; PREDICTION_POINTS] {
    let mut points = [PredictedPoint::default(); PREDICTION_POINTS];
    for (k, point) in points.iter_mut().enumerate() {
        if let Some(p) = out.plan.get(2 * (k + 1)) {
            *point = PredictedPoint {
                horizon_s: p.t_s,
                x_m: p.x_m,
                y_m: p.y_m,
                heading_rad: p.heading_rad,
                speed_mps: p.speed_mps,
            };
        }
    }
    points
}

/// A car that loses its path turned no further than this from the path's direction brakes
/// along the path's curves ([`lost_steer_pct`]); one turned further, with the wheels straight,
/// rad.
pub const LOST_ALONG_RAD: f32 = core::f32::consts::FRAC_PI_4;

/// Where a car that has just lost its path follows the path's curvature from while it stops:
/// its projection, if it is still along the path (within [`LOST_ALONG_RAD`] of its direction);
/// `None` (wheels straight) if it is turned further.
fn along_when_lost(lost: &Tracking) -> Option<(f32, usize)> {
    let heading = lost.heading_error_rad;
    let along = heading.abs() <= LOST_ALONG_RAD && lost.projection.station_m.is_finite();
    along.then_some((lost.projection.station_m, lost.projection.segment))
}

/// The steering of a car stopping because it has lost its path, %: for one still along it
/// (`along`, [`along_when_lost`]) the lane hold ([`mpc::lane_hold_steer_rad`]) at the station
/// it would have reached had it followed the path (moved on here by this tick's distance,
/// without a search): it turns parallel to the path and brakes on its curves at the offset it
/// has. A car that went wide in a bend and braked with its wheels straight left on the
/// tangent: 3.4 m beside its path at 12.4 m/s, it stopped 15.7 m from it (docs/findings.md).
/// Wheels straight (0) for a car turned across or against the path, which may have spun and
/// whose last command may be full lock.
fn lost_steer_pct(
    path: &Path,
    along: &mut Option<(f32, usize)>,
    config: &NodeConfig,
    pose: &Pose,
    inputs: &DriveInputs<'_>,
) -> f32 {
    let Some((station_m, hint)) = *along else {
        return 0.0;
    };
    let Some(at) = path.sample_geometry(station_m, hint) else {
        *along = None;
        return 0.0;
    };
    let v = crate::math::clamp_finite(inputs.speed_mps, 0.0, f32::MAX);
    let next = station_m + v * crate::SAMPLE_PERIOD_S;
    *along = Some((next, path.segment_hint(next, hint)));
    let heading_error = crate::math::wrap_pi(pose.heading_rad - at.heading_rad);
    let vehicle = &config.vehicle;
    let steer_rad = mpc::lane_hold_steer_rad(vehicle, heading_error, v, at.curvature_per_m);
    let pct = steer_rad / (vehicle.max_steer_rad * inputs.steer_scale) * 100.0;
    if pct.is_finite() {
        crate::math::clamp(pct, -100.0, 100.0)
    } else {
        0.0
    }
}

fn sample(s: &PathSample, corridor: (f32, f32)) -> Sample {
    Sample {
        pose: Pose::new(s.east_m, s.north_m, s.heading_rad),
        left_m: corridor.0,
        right_m: corridor.1,
    }
}

/// Where the corridor binds the body's left and right sides between the rear axle at station
/// `axle_m` and the body's end at `end_m` ([`Path::narrowest_corridor`]); one path sample when
/// both sides bind at the same station (the end's corners, mostly). `hint` and `end_hint`
/// start the searches for the axle's and the end's segments; `end_hint` is then set to the
/// end's, for the next station.
fn side_points(
    path: &Path,
    axle_m: f32,
    end_m: f32,
    hint: usize,
    end_hint: &mut usize,
) -> Option<(SidePoint, SidePoint)> {
    let located = path.narrowest_corridor_located(axle_m, end_m, (hint, *end_hint))?;
    *end_hint = located.to_segment;
    let n = located.narrowest;
    let widths = (n.left_m, n.right_m);
    let left = SidePoint {
        sample: sample(
            &path.sample_geometry(n.left_station_m, located.left_segment)?,
            widths,
        ),
        ahead_m: n.left_station_m - axle_m,
    };
    let right = if n.right_station_m == n.left_station_m {
        left
    } else {
        SidePoint {
            sample: sample(
                &path.sample_geometry(n.right_station_m, located.right_segment)?,
                widths,
            ),
            ahead_m: n.right_station_m - axle_m,
        }
    };
    Some((left, right))
}

/// The reference at the steering plan's stages from the rear axle's station and segment `at`
/// (see [`ReferencePoint`]): the expected stations from the last plan's speeds (the current
/// speed before there is one). `None` when the path cannot be sampled there. Out of line: it
/// keeps the searches' registers and locals out of the solve's caller, whose frame is on the
/// stack through the solve, and costs the same in or out of it.
#[inline(never)]
fn fill_reference(
    mpc: &MpcConfig,
    path: &Path,
    (s0, hint): (f32, usize),
    planned_speeds: Option<[f32; PLAN_STEPS + 1]>,
    inputs: &DriveInputs<'_>,
    reference: &mut [ReferencePoint; STEPS + 1],
) -> Option<()> {
    let body = mpc.body();
    let front = body.length_m - body.rear_overhang_m;
    let rear = body.rear_overhang_m;
    // Expected stations: the last plan's speeds (the current speed before there is one) at
    // the steering plan's stages.
    let stage = mpc.stage();
    let speeds =
        stage.stage_speeds(&planned_speeds.unwrap_or([inputs.speed_mps.max(0.0); PLAN_STEPS + 1]));
    // Every point is written below before the solve reads it (or the tick returns early).
    // The stations ascend: each one's segment is the next one's search start, so the searches
    // walk the path once however far the horizon reaches (the side points' searches from
    // there walk the body's length).
    let mut s = s0;
    let mut seg = hint;
    // The body's ends' segments, each the next station's hint: the ends move on as the
    // stations do, a step or two of the search rather than a body's length from the axle.
    let (mut front_seg, mut rear_seg) = (hint, hint);
    for (k, r) in reference.iter_mut().enumerate() {
        if let (Some(v0), Some(v1)) = (speeds.get(k.wrapping_sub(1)), speeds.get(k)) {
            s += 0.5 * (v0 + v1) * stage.stage_s(k - 1);
        }
        seg = path.segment_hint(s, seg);
        let at = path.sample(s, seg)?;
        let (front_left, front_right) = side_points(path, s, s + front, seg, &mut front_seg)?;
        let (rear_left, rear_right) = side_points(path, s, s - rear, seg, &mut rear_seg)?;
        *r = ReferencePoint {
            at: sample(&at, (at.left_m, at.right_m)),
            curvature_per_m: at.curvature_per_m,
            speed_mps: at.speed_mps,
            front_left,
            front_right,
            rear_left,
            rear_right,
        };
    }
    Some(())
}

/// The obstacles as the solve takes them: each projected onto the path (all in one pass over
/// it, an absent slot taking a present one's place, unused; no pass without one), `ahead_m` from
/// the car's station `s0`. `None` if the path cannot be sampled where one projects. Out of
/// line: its locals are not on the stack through the solve.
#[inline(never)]
fn place_obstacles(
    path: &Path,
    obstacles: &[Option<ObstacleCircle>],
    motion: &[ObstacleMotion],
    s0: f32,
) -> Option<[Option<mpc::Obstacle>; MAX_OBSTACLES]> {
    let mut placed = [None; MAX_OBSTACLES];
    let finite = |o: &&ObstacleCircle| o.east_m.is_finite() && o.north_m.is_finite();
    let mut centres = [(0.0, 0.0); MAX_OBSTACLES];
    let first = obstacles.iter().flatten().find(finite);
    for (c, o) in centres.iter_mut().zip(obstacles) {
        if let Some(o) = o.as_ref().filter(finite).or(first) {
            *c = (o.east_m, o.north_m);
        }
    }
    let projected = match first {
        Some(_) => path.project_each(centres),
        None => [None; MAX_OBSTACLES],
    };
    for (((slot, obstacle), p), m) in placed.iter_mut().zip(obstacles).zip(projected).zip(motion) {
        let (Some(o), Some(p)) = (obstacle.as_ref().filter(finite), p) else {
            continue;
        };
        *slot = Some(place_one(path, o, &p, m, s0)?);
    }
    Some(placed)
}

/// One obstacle at its projection `p` on the path, `ahead_m` from the car's station `s0`, its
/// motion in the path's frame there. Out of line: the loop over the slots would otherwise
/// hold four copies of the sampling (flash).
#[inline(never)]
fn place_one(
    path: &Path,
    o: &ObstacleCircle,
    p: &Projection,
    m: &ObstacleMotion,
    s0: f32,
) -> Option<mpc::Obstacle> {
    let at = path.sample_geometry(p.station_m, p.segment)?;
    let (sh, ch) = path.segment_direction(p.segment).unwrap_or((0.0, 0.0));
    Some(mpc::Obstacle {
        east_m: o.east_m,
        north_m: o.north_m,
        radius_m: o.radius_m,
        ahead_m: p.station_m - s0,
        path_offset_m: p.lateral_m,
        left_m: at.left_m,
        right_m: at.right_m,
        velocity: mpc::ObstacleVelocity {
            east_mps: m.east_mps,
            north_mps: m.north_mps,
            along_mps: m.east_mps * sh + m.north_mps * ch,
            right_mps: m.east_mps * ch - m.north_mps * sh,
        },
    })
}

/// The path's lower target ahead that the speed plan slows for ([`mpc::SlowAhead`]): among
/// the points ahead of the rear axle's station `s0` (on segment `hint`) whose targets are below
/// [`SLOW_AHEAD_SHARE`] of the target where the car is and below its speed `speed_mps` by more
/// than [`SPEED_LIMIT_SLACK_MPS`] and [`SLOW_AHEAD_EXCESS_MPS`], the one that leaves the least room
/// to slow by the speed model's coast-out. `None` without one or without a coast-out.
fn slow_ahead(
    mpc: &MpcConfig,
    path: &Path,
    (s0, hint): (f32, usize),
    speed_mps: f32,
) -> Option<mpc::SlowAhead> {
    let coasted = mpc.speed_planner().coasted_s()?;
    let below = speed_mps - SPEED_LIMIT_SLACK_MPS - SLOW_AHEAD_EXCESS_MPS;
    path.slow_ahead(s0, hint, coasted, (below, SLOW_AHEAD_SHARE))
        .map(|(ahead_m, target_mps)| mpc::SlowAhead {
            ahead_m,
            target_mps,
        })
}

/// Why a tick of the model-predictive controller did not solve, with the car's tracking.
enum Unplanned {
    /// The car has lost the path ([`Tracking::has_lost_path`]).
    Lost(Tracking),
    /// The car left its projection's window ([`Tracking::left_window`]): the rest of the path
    /// was searched for it, and a tick that does so does not also solve.
    LeftWindow(Tracking),
}

/// One model-predictive solve; `None` when the path cannot be sampled, `Err` when the tick
/// does not solve ([`Unplanned`]). Inlined into its one caller: out of line (as the compiler
/// chose once a stale steering report held the car) its frame stacked on the tick's instead of
/// sharing it, 1.2 KiB deeper (`cargo qemu` over a closed-loop session: 11 304 -> 12 496 B,
/// over the 75 % limit of the stack region); its reference is [`fill_reference`]'s.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn mpc_tick<P: StageProbe>(
    mpc: &MpcConfig,
    state: &mut MpcState,
    path: &Path,
    (obstacles, motion): (&[Option<ObstacleCircle>], &[ObstacleMotion]),
    projection: &mut Option<Projection>,
    planned_speeds: &mut Option<[f32; PLAN_STEPS + 1]>,
    reference: &mut [ReferencePoint; STEPS + 1],
    pose: Pose,
    inputs: &DriveInputs<'_>,
    speed_model: &SsBlockState<2, VELOCITY_DELAY_CAP>,
    last_speed_cmd_mps: f32,
    config: &NodeConfig,
    probe: &mut P,
) -> Option<Result<(MpcOutput, Tracking), Unplanned>> {
    let tracking = path.track(&pose, projection.as_ref())?;
    *projection = Some(tracking.projection);
    if tracking.has_lost_path(mpc.body().width_m) {
        // Beside the corridor or facing against the path: the fallback (the caller brakes),
        // for the planner to replan; nothing is solved. The tracking was this tick's reference
        // work (the plan branch's, as when it goes on to a solve: not the common rows').
        probe.lap(Stage::DriveReference);
        return Some(Err(Unplanned::Lost(tracking)));
    }
    if tracking.left_window {
        // The caller moves the last plan on (its lap, [`Stage::DriveCoast`], counts this
        // search: the path-loading branch's, not the plan's).
        return Some(Err(Unplanned::LeftWindow(tracking)));
    }
    let s0 = tracking.projection.station_m;
    let hint = tracking.projection.segment;
    fill_reference(mpc, path, (s0, hint), *planned_speeds, inputs, reference)?;
    let placed = place_obstacles(path, obstacles, motion, s0)?;
    // Eq 5's output now: what its next step returns before the command sent now takes effect
    // (its forecast's first output, the same bits as a step of a copy of the state, without
    // the copy of the delay line on the stack).
    let mut now = [0.0f32; 1];
    config.velocity.forecast(speed_model, 0.0).fill(&mut now);
    let [modelled_mps] = now;
    let input = MpcInput {
        reference,
        obstacles: &placed,
        car: mpc::CarState {
            pose,
            speed_mps: inputs.speed_mps,
            lateral: inputs.lateral,
            steer_rad: inputs.steer_rad,
            mode: inputs.mode,
            speed_model,
            speed_bias_mps: inputs.speed_mps - modelled_mps,
            last_speed_cmd_mps,
        },
        position_uncertainty_m: config.position_uncertainty_m,
        path_max_curvature_per_m: path.max_curvature_per_m(),
        to_end_m: path.stop_ahead_m(s0, hint),
        in_held_turn: path.in_held_turn(hint),
        slow_ahead: slow_ahead(mpc, path, (s0, hint), inputs.speed_mps),
    };
    probe.lap(Stage::DriveReference);
    let out = mpc.solve(state, &input);
    probe.lap(Stage::MpcSolve);
    // Written in place: an array of its own here was one more on the controller's stack.
    let next = planned_speeds.insert([0.0; PLAN_STEPS + 1]);
    for (v, p) in next.iter_mut().zip(&out.plan) {
        *v = p.speed_mps;
    }
    Some(Ok((out, tracking)))
}

#[cfg(test)]
mod tests {
    extern crate std;
    use core::mem::MaybeUninit;
    use std::boxed::Box;
    use std::format;

    use super::Drive;

    /// `Drive::init` builds what `Drive::new` is, whatever the memory held: built over zeros,
    /// over a pattern and over ones (a field it forgot to write would show the pattern).
    #[test]
    fn built_in_place_it_is_new() {
        let new = format!("{:?}", Drive::new());
        for pattern in [0x00u8, 0x5A, 0xFF] {
            let mut slot: Box<MaybeUninit<Drive>> = Box::new_uninit();
            // SAFETY: bytes into a `MaybeUninit`, within its size.
            unsafe {
                slot.as_mut_ptr()
                    .cast::<u8>()
                    .write_bytes(pattern, size_of::<Drive>());
            }
            let built = Drive::init(&mut slot);
            assert_eq!(format!("{built:?}"), new, "over 0x{pattern:02x}");
        }
    }
}
