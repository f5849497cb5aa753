//! The closed loop on the host: the plant simulator (`crate::sim`: single-track plant,
//! magic-formula tyres, the car's delayed speed loop and steering actuator, sensors on their
//! own clocks) driven by the controller's CONTROL_COMMAND frames through the bus, the node in
//! the loop ([`driver`]), and a simulated planner sending the course's path and obstacles
//! ([`planner`]). Everything between the car and the node is CAN frames, exactly what the node
//! sees on a real bus, and the node's input is recorded as candump so that the very same run
//! replays in QEMU.
//!
//! The tick schedule is the replay's: the first frame (the planner's, at 0.5 ms) puts the first
//! tick at 20 ms, then every 20 ms; a tick gets every frame stamped since the previous one.
//! The car starts at rest at the path's start; a launch (3 m/s, straight ahead) moves it until
//! the node has held a valid position for [`ENGAGE_AFTER_VALID_S`] (a single GNSS antenna gives
//! a heading only in motion) and the controller is tracking: then the drive-by-wire follows
//! CONTROL_COMMAND, with the usual 100 ms command timeout. A run ends past the scored range,
//! at rest under the controller ([`STOPPED_END_S`] after the node last asked the car to drive,
//! [`STOPPED_DRIVING_END_S`] whatever it asks), or at its time limit ([`RunEnd`]).
pub mod driver;
pub mod limits;
pub mod metrics;
pub mod optimal;
pub mod planner;
pub mod plots;
pub mod scenario;

use std::collections::{BTreeMap, VecDeque};

use catmodel::can::codec::{ControlCommand, ControlStatus, StatePosition};
use catmodel::can::counter::CounterChecker;
use catmodel::can::{CanFrame, TimedFrame};
use catmodel::control::path::{
    Path, Projection, Waypoint, ACQUIRE_TIE_M, PROJECTION_AHEAD_M, PROJECTION_BEHIND_M,
};
use catmodel::model::kinematic::Pose;
use catmodel::node::{NodeConfig, PlatformStats, Tick, MAX_RX_FRAMES_PER_TICK};

use crate::csv2can::LogEncoder;
use crate::logcsv::{LogRow, TruthRow};
use crate::sim::config::{Body, Gnss, VehicleConfig};
use crate::sim::plant::PlantState;
use crate::sim::scenario::Command;
use crate::sim::{Rig, SimOptions};
use driver::{Driver, TickReport, IDLE_COMMAND};
use metrics::{Metrics, Scorer};
use scenario::Course;

/// The tick period, us (the node's 20 ms).
const TICK_US: u64 = catmodel::SAMPLE_PERIOD_US;
/// The plant's step, us ([`crate::sim::PLANT_STEP_S`]).
const PLANT_STEP_US: u64 = 1_000;
/// Plant steps per tick.
const STEPS_PER_TICK: u64 = TICK_US / PLANT_STEP_US;
/// Launch speed before the controller is engaged, m/s.
pub const LAUNCH_SPEED_MPS: f64 = 3.0;
/// The controller is engaged once the node has reported a valid position this long, s.
pub const ENGAGE_AFTER_VALID_S: f64 = 1.0;
/// Without a valid CONTROL_COMMAND this long the drive-by-wire brakes (speed 0, steering
/// held), us: Dataspeed's command timeout.
pub const COMMAND_TIMEOUT_US: u64 = 100_000;
/// A command applies this many plant steps after its tick (computation and bus latency, 1 ms).
const COMMAND_LATENCY_STEPS: u64 = 1;
/// Clearance a controller keeps from an obstacle beyond the position estimate's error, m.
pub const OBSTACLE_MARGIN_M: f64 = 1.0;
/// A run ends this long after the car came to rest while engaged, or after the node last
/// commanded it to drive while at rest, whichever is later, s.
pub const STOPPED_END_S: f64 = 3.0;
/// A run ends when the car has been at rest while engaged this long, whatever the node
/// commands, s: a speed loop that has not answered a command to drive by then will not (the
/// slowest speed loop a probe drove, 0.8 s of delay and a 0.9 s lag, set its car off 1.6 s
/// after it was asked).
pub const STOPPED_DRIVING_END_S: f64 = 20.0;
/// The car is at rest below this truth speed, m/s.
const STILL_MPS: f64 = 0.05;
/// The node commands a car at rest to drive with a speed command above this, m/s: the MPC's
/// creep to a path's end ([`catmodel::control::mpc::longitudinal::STOP_CREEP_MPS`]), which a
/// speed loop's standstill hold need not answer, is not a command to drive (a run whose car
/// stopped short of the end, creeping at 0.1-0.2 m/s, would be held on to for
/// [`STOPPED_DRIVING_END_S`]; the van's loop 17 s longer); the probe's car, set off again
/// after its stop for a pedestrian, was asked about 6 m/s.
const DRIVE_COMMAND_MPS: f64 = catmodel::control::mpc::longitudinal::STOP_CREEP_MPS as f64;

/// The GNSS receiver on the car.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Receiver {
    /// Survey grade, RTK fixed: 1 cm white noise and 1 cm bias per axis (NovAtel OEM7
    /// datasheet, RTK: 1 cm + 1 ppm RMS horizontal).
    Rtk,
    /// The vehicle file's receiver (the CAT Vehicle's: 1.2 m RMS horizontal, paper II-A).
    Standard,
}

impl Receiver {
    /// From `rtk` / `standard`.
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "rtk" => Some(Receiver::Rtk),
            "standard" => Some(Receiver::Standard),
            _ => None,
        }
    }

    /// Its name.
    pub fn name(self) -> &'static str {
        match self {
            Receiver::Rtk => "rtk",
            Receiver::Standard => "standard",
        }
    }

    /// The receiver's error model applied to `gnss`.
    pub fn apply(self, gnss: &mut Gnss) {
        if self == Receiver::Rtk {
            gnss.white_noise_m = 0.01;
            gnss.bias_sigma_m = 0.01;
        }
    }
}

/// `--start-offset` is at most this far either side of the path, m (a start further off is not
/// a path the planner would send).
pub const MAX_START_OFFSET_M: f64 = 10.0;

/// How to run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunOptions {
    /// Sensor noise and clocks.
    pub seed: u64,
    /// GNSS receiver.
    pub receiver: Receiver,
    /// Stop after this much simulated time, s.
    pub max_time_s: f64,
    /// A planner that replans: the course's path (a new path id) and obstacles are sent again
    /// this often, s (each time the previous transfer has gone out); `None`: once, at the start.
    pub replan_s: Option<f64>,
    /// The car starts this far to the right of the path's first point (negative: left), m.
    pub start_offset_m: f64,
    /// Inject the vehicle file's sensor faults (`[faults]`: GNSS outages and outliers, lost
    /// bus reports), as `simulate-drive` does.
    pub faults: bool,
    /// The drive-by-wire reports its steering with the other sign (positive to the left): a
    /// wiring or convention fault the node's steering check must find (the commands keep
    /// STEERING_REPORT's sign, as the DBW's interface documents it).
    pub reversed_steering_report: bool,
    /// The speed the launch driver holds until the node takes the car over, m/s
    /// ([`LAUNCH_SPEED_MPS`] unless a test asks for a crawl).
    pub launch_mps: f64,
}

impl RunOptions {
    /// A run of at most 120 s with `seed` and `receiver`, one path, the car on the path's start.
    pub fn new(seed: u64, receiver: Receiver) -> Self {
        Self {
            seed,
            receiver,
            max_time_s: 120.0,
            replan_s: None,
            start_offset_m: 0.0,
            faults: false,
            reversed_steering_report: false,
            launch_mps: LAUNCH_SPEED_MPS,
        }
    }
}

/// One tick of a run, for plots.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Tick time, s.
    pub t_s: f64,
    /// Ground truth (rear axle).
    pub truth: TruthRow,
    /// The node's estimate (east, north, heading).
    pub estimate: Option<(f64, f64, f64)>,
    /// The command the drive-by-wire applies after this tick.
    pub command: ControlCommand,
    /// Whether the controller drives.
    pub engaged: bool,
    /// Steering actuator position, %.
    pub steer_pct: f64,
    /// Truth: station of the rear axle on the path, m.
    pub station_m: f64,
    /// Truth: lateral error of the rear axle from the path, m, positive right.
    pub lateral_m: f64,
}

/// Why a run ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RunEnd {
    /// The car's rear axle passed the scored range's end with room to spare.
    PastCourse,
    /// The car came to rest under the controller (at `since_s`, s) and the node did not
    /// command it to drive for [`STOPPED_END_S`].
    AtRest {
        /// When the car came to rest, s.
        since_s: f64,
    },
    /// The car stayed at rest under the controller for [`STOPPED_DRIVING_END_S`] from
    /// `since_s` (s), the node commanding it to drive within the last [`STOPPED_END_S`].
    AtRestWhileDriving {
        /// When the car came to rest, s.
        since_s: f64,
    },
    /// The run's time limit ([`RunOptions::max_time_s`]).
    TimeLimit,
}

/// Everything a run produced.
#[derive(Debug, Clone)]
pub struct RunOutput {
    /// The course driven.
    pub course: Course,
    /// Every frame the node received, in order (sensors and planner): the session's candump.
    pub inputs: Vec<TimedFrame>,
    /// Every frame sent from the node's place, stamped with its tick time.
    pub outputs: Vec<TimedFrame>,
    /// One record per tick.
    pub samples: Vec<Sample>,
    /// The scores.
    pub metrics: Metrics,
    /// Why it ended.
    pub end: RunEnd,
}

/// The published model file (`models/paper.toml`) made to describe the plant `vehicle`, as its
/// owner's tape measure and data sheet would (README, "A second car"): geometry, body, steering
/// range, rate and lag, antenna, receiver rate (as `identify` writes it, with the outage time it
/// needs) and the linear-tyre single-track model; the identified models stay the CAT
/// Vehicle's. For a plant given without a model file: the node then knows everything of the
/// car that a model file's `[vehicle]` and `[dynamics]` say, and is built by the one reader.
pub fn model_file_for(vehicle: &VehicleConfig) -> anyhow::Result<crate::model_file::ModelFile> {
    let mut file = crate::model_file::load(&crate::model_file::paper_path())?;
    let c = &vehicle.chassis;
    let v = &mut file.vehicle;
    v.wheelbase_m = c.wheelbase_m;
    v.track_m = c.track_m;
    v.max_steer_deg = c.max_steer_deg;
    v.understeer_s2_per_m2 = vehicle.understeer_s2_per_m2();
    v.antenna_ahead_m = vehicle.sensors.gnss.antenna_ahead_of_rear_axle_m;
    v.antenna_left_m = vehicle.sensors.gnss.antenna_left_of_centre_line_m;
    v.width_m = vehicle.body.width_m;
    v.length_m = vehicle.body.length_m;
    v.rear_overhang_m = vehicle.body.rear_overhang_m;
    v.max_steer_rate_pct_per_s = vehicle.steering.rate_limit_pct_per_s;
    v.steer_lag_s = Some(vehicle.steering.lag_s);
    file.dynamics = Some(crate::model_file::DynamicsSection {
        mass_kg: c.mass_kg,
        yaw_inertia_kg_m2: c.yaw_inertia_kg_m2,
        cg_to_front_m: c.cg_to_front_m,
        cg_to_rear_m: c.cg_to_rear_m,
        cornering_front_n_per_rad: vehicle.tyre_front.cornering_stiffness_n_per_rad,
        cornering_rear_n_per_rad: vehicle.tyre_rear.cornering_stiffness_n_per_rad,
    });
    crate::identify::set_receiver_rate(&mut file, 1.0 / vehicle.sensors.gnss.period_s);
    file.control.max_lateral_accel_mps2 = Some(lateral_limit_mps2(vehicle));
    // Through the reader, as any model file: validated, and built as the firmware would.
    let text = crate::model_file::to_toml(&file);
    crate::model_file::parse(&text, std::path::Path::new("<the plant's description>"))
        .map_err(|e| anyhow::anyhow!("{e}"))
}

/// The lateral acceleration a model file declares for the plant `vehicle`, m/s^2: two thirds of
/// what its tyres give (the lower axle's friction coefficient times g), to 0.1 m/s^2, as
/// `models/paper.toml` declares for the CAT Vehicle (docs/controller.md, "A turn faster than
/// the tyres").
pub fn lateral_limit_mps2(vehicle: &VehicleConfig) -> f64 {
    let mu = vehicle
        .tyre_front
        .friction_mu
        .min(vehicle.tyre_rear.friction_mu);
    (2.0 / 3.0 * mu * 9.81 * 10.0).round() / 10.0
}

/// The planner's path as the core's `Path` (for scoring lateral error on truth).
pub fn core_path(course: &Course) -> Path {
    let waypoints: Vec<Waypoint> = course
        .path
        .iter()
        .map(|p| Waypoint {
            east_m: p.east_m as f32,
            north_m: p.north_m as f32,
            speed_mps: p.speed_mps as f32,
            left_m: p.left_m as f32,
            right_m: p.right_m as f32,
        })
        .collect();
    let mut path = Path::new();
    // Note: the scenarios build valid paths (host tests check every one).
    let _ = path.load(&waypoints);
    path
}

/// The drive-by-wire kit's command side: what the car does with CONTROL_COMMAND.
struct DriveByWire {
    /// The launch driver's speed until engaged, m/s.
    launch_mps: f64,
    engaged: bool,
    valid_since_us: Option<u64>,
    counter: CounterChecker,
    last_valid_us: Option<u64>,
    /// (steer %, speed m/s) in force, and the pending one with the step it applies from.
    current: Command,
    pending: Option<(u64, Command)>,
    status_ticks: [u64; 4],
    /// The fallback's ticks by reason (raw `fallback_reason`).
    fallback_ticks: BTreeMap<u8, u64>,
    engaged_at_s: Option<f64>,
}

impl DriveByWire {
    fn new(launch_mps: f64) -> Self {
        Self {
            launch_mps,
            engaged: false,
            valid_since_us: None,
            counter: CounterChecker::new(),
            last_valid_us: None,
            current: Command {
                speed_mps: 0.0,
                steer_pct: 0.0,
            },
            pending: None,
            status_ticks: [0; 4],
            fallback_ticks: BTreeMap::new(),
            engaged_at_s: None,
        }
    }

    /// Reads this tick's frames from the node's place.
    fn receive(&mut self, now_us: u64, step: u64, frames: &[CanFrame]) -> ControlCommand {
        let mut seen = IDLE_COMMAND;
        for f in frames {
            if let Ok((p, _)) = StatePosition::decode(f) {
                if !p.position_valid {
                    self.valid_since_us = None;
                } else if self.valid_since_us.is_none() {
                    self.valid_since_us = Some(now_us);
                }
            }
            let Ok((command, counter)) = ControlCommand::decode(f) else {
                continue;
            };
            if !self.counter.check(counter).accepted() {
                continue;
            }
            seen = command;
            let tracking = matches!(
                command.status,
                ControlStatus::Tracking | ControlStatus::Avoiding
            );
            let settled = self
                .valid_since_us
                .is_some_and(|t| now_us.saturating_sub(t) as f64 >= ENGAGE_AFTER_VALID_S * 1e6);
            if !self.engaged && tracking && settled {
                self.engaged = true;
                self.engaged_at_s = Some(now_us as f64 * 1e-6);
            }
            if self.engaged {
                self.last_valid_us = Some(now_us);
                let steer = command
                    .steer_cmd_pct
                    .map_or(self.current.steer_pct, f64::from);
                let speed = command.speed_cmd_mps.map_or(0.0, f64::from);
                self.pending = Some((
                    step + COMMAND_LATENCY_STEPS,
                    Command {
                        speed_mps: speed,
                        steer_pct: steer,
                    },
                ));
                if let Some(n) = self.status_ticks.get_mut(command.status as usize) {
                    *n += 1;
                }
                if command.status == ControlStatus::Fallback {
                    *self
                        .fallback_ticks
                        .entry(command.fallback as u8)
                        .or_insert(0) += 1;
                }
            }
        }
        seen
    }

    /// The command the car holds during plant step `step` at `t_us`.
    fn command(&mut self, step: u64, t_us: u64) -> Command {
        if let Some((from, c)) = self.pending {
            if step >= from {
                self.current = c;
                self.pending = None;
            }
        }
        if !self.engaged {
            return Command {
                speed_mps: self.launch_mps,
                steer_pct: 0.0,
            };
        }
        if self
            .last_valid_us
            .is_none_or(|t| t_us.saturating_sub(t) > COMMAND_TIMEOUT_US)
        {
            self.current.speed_mps = 0.0;
        }
        self.current
    }
}

/// The course's obstacles where they are now: those that walk set off as the car comes near
/// ([`planner::ObstacleWalk`]).
struct Walkers {
    /// When each set off, s (`None`: not yet, or it does not walk).
    started_s: Vec<Option<f64>>,
    /// Each one's circle now: east, north, radius.
    circles: Vec<(f64, f64, f64)>,
    /// Whether any of them walks.
    moving: bool,
}

impl Walkers {
    fn new(course: &Course) -> Self {
        Self {
            started_s: vec![None; course.obstacles.len()],
            circles: course
                .obstacles
                .iter()
                .map(|o| (o.east_m, o.north_m, o.radius_m))
                .collect(),
            moving: course.obstacles.iter().any(|o| o.walk.is_some()),
        }
    }

    /// At `t_s`, the car's rear axle at `(x, y)`.
    fn step(&mut self, course: &Course, t_s: f64, x: f64, y: f64) {
        let car_x = course.frame.to_course(x, y).0;
        for ((o, started), circle) in course
            .obstacles
            .iter()
            .zip(&mut self.started_s)
            .zip(&mut self.circles)
        {
            let Some(walk) = o.walk else { continue };
            let obstacle_x = course.frame.to_course(o.east_m, o.north_m).0;
            if started.is_none() && obstacle_x - car_x <= walk.start_within_m {
                *started = Some(t_s);
            }
            if let Some(t0) = *started {
                let dt = t_s - t0;
                *circle = (
                    o.east_m + walk.east_mps * dt,
                    o.north_m + walk.north_mps * dt,
                    o.radius_m,
                );
            }
        }
    }
}

/// Runs `course` with `vehicle` (its sensors set for `options.receiver`) and `driver` in the
/// node's place.
pub fn run(
    vehicle: &VehicleConfig,
    course: &Course,
    driver: &mut dyn Driver,
    controller_name: &str,
    options: &RunOptions,
) -> RunOutput {
    let mut vehicle = vehicle.clone();
    options.receiver.apply(&mut vehicle.sensors.gnss);
    let sim_options = SimOptions {
        seed: options.seed,
        faults: options.faults,
        vary_commands: false,
        ..SimOptions::default()
    };
    let initial = start_state(&vehicle, course, options.start_offset_m);
    let mut rig = Rig::new(&vehicle, &sim_options, initial, 0.0);
    let mut walkers = Walkers::new(course);
    let mut planner = PlannerSide::start(
        course,
        sim_options.origin_deg,
        options.replan_s,
        walkers.moving,
    );
    let mut sensors = SensorFrames::new(options.reversed_steering_report);
    let mut receive_queue = VecDeque::new();
    let mut dbw = DriveByWire::new(options.launch_mps);
    let mut scorer = Scorer::new(&vehicle.body, course);
    let mut record = TruthRecord::new(course, &vehicle.body);
    let mut inputs = Vec::new();
    let mut outputs = Vec::new();
    let max_ticks = (options.max_time_s * 1e6 / TICK_US as f64).ceil() as u64;
    let mut end = RunEnd::TimeLimit;

    for n in 1..=max_ticks {
        let t_tick_us = n * TICK_US;
        drive_plant(&mut rig, &mut dbw, &mut walkers, &mut scorer, course);
        // The frames of this tick: the sensors' (logged by now) and the planner's.
        let mut rx = sensors.due(&mut rig, t_tick_us);
        rx.extend(planner.tick_frames(course, &walkers, t_tick_us - TICK_US));
        rx.sort_by_key(|f| f.t_us);
        inputs.extend_from_slice(&rx);
        let (report, tx) = node_tick(driver, &mut receive_queue, rx, t_tick_us);
        let seen = dbw.receive(t_tick_us, rig.steps(), &tx);
        outputs.extend(tx.iter().map(|&frame| TimedFrame {
            t_us: t_tick_us,
            frame,
        }));
        record.tick(t_tick_us, &rig, &report, seen, dbw.engaged);
        if let Some(ended) = record.ended(dbw.engaged) {
            end = ended;
            break;
        }
    }

    let metrics = record.metrics(course, controller_name, options.receiver, &scorer, &dbw);
    RunOutput {
        course: course.clone(),
        inputs,
        outputs,
        samples: record.samples,
        metrics,
        end,
    }
}

/// The car at rest at `course`'s start, heading along the path's first segment.
fn start_state(vehicle: &VehicleConfig, course: &Course, start_offset_m: f64) -> PlantState {
    let start = &course.path[0];
    let heading0 = {
        let next = &course.path[1];
        (next.east_m - start.east_m).atan2(next.north_m - start.north_m)
    };
    let b = vehicle.chassis.cg_to_rear_m;
    // The car's rear axle, `start_offset_m` to the right of the path's first point.
    let off = start_offset_m;
    PlantState {
        x_m: start.east_m + b * heading0.sin() + off * heading0.cos(),
        y_m: start.north_m + b * heading0.cos() - off * heading0.sin(),
        heading_rad: heading0,
        ..PlantState::default()
    }
}

/// The plant over (T_{n-1}, T_n] with the commands in force: the drive-by-wire's command at
/// each step, the obstacles that walk where they are, the body scored against them on truth.
fn drive_plant(
    rig: &mut Rig,
    dbw: &mut DriveByWire,
    walkers: &mut Walkers,
    scorer: &mut Scorer,
    course: &Course,
) {
    for _ in 0..STEPS_PER_TICK {
        let step = rig.steps();
        let t_us = step * PLANT_STEP_US;
        let command = dbw.command(step, t_us);
        rig.step(&command);
        let truth = rig.truth();
        if walkers.moving {
            walkers.step(course, t_us as f64 * 1e-6, truth.x, truth.y);
            scorer.move_obstacles(&walkers.circles);
        }
        scorer.observe(truth.x, truth.y, truth.heading);
    }
}

/// The sensors' side of the bus: the plant's reports, held until their tick and encoded as the
/// car's frames.
struct SensorFrames {
    encoder: LogEncoder,
    /// Reports logged by the plant and not yet due, with their time, us.
    pending_rows: Vec<(i64, LogRow)>,
    /// The drive-by-wire reports its steering with the other sign ([`RunOptions`]).
    reversed_steering_report: bool,
}

impl SensorFrames {
    fn new(reversed_steering_report: bool) -> Self {
        Self {
            encoder: LogEncoder::new(),
            pending_rows: Vec::new(),
            reversed_steering_report,
        }
    }

    /// The frames of every report `rig` has logged at or before the tick at `t_tick_us`.
    fn due(&mut self, rig: &mut Rig, t_tick_us: u64) -> Vec<TimedFrame> {
        self.pending_rows.extend(rig.take_reports());
        self.pending_rows.sort_by_key(|(t, _)| *t);
        let due = self
            .pending_rows
            .partition_point(|(t, _)| *t as u64 <= t_tick_us);
        let mut rx: Vec<TimedFrame> = Vec::new();
        for (_, mut row) in self.pending_rows.drain(..due) {
            if self.reversed_steering_report {
                row.steer = row.steer.map(|s| -s);
            }
            // Note: the simulator's clock starts at 0 and only counts up, so a row's time is
            // never negative (the only error encode_row reports).
            let _ = self.encoder.encode_row(&row, &mut rx);
        }
        rx
    }
}

/// The simulated planner's side of the bus: the course's path and obstacles, sent again every
/// `replan_us` if it replans.
struct PlannerSide {
    planner: planner::Planner,
    /// Whether an obstacle of the course moves ([`Walkers::moving`]).
    moving: bool,
    replan_us: Option<u64>,
    /// When the path was last queued, us (the first transfer: 0).
    last_plan_us: u64,
}

impl PlannerSide {
    /// The planner's first transfer queued: the origin, the course's path and its obstacles.
    fn start(course: &Course, origin_deg: (f64, f64), replan_s: Option<f64>, moving: bool) -> Self {
        let mut planner = planner::Planner::new();
        planner.send_origin(origin_deg.0, origin_deg.1);
        // Note: the scenarios' paths have 2..=256 points and at most 4 obstacles (host tests).
        let _ = planner.send_path(&course.path);
        // A course with an obstacle that moves has the planner send every obstacle each tick
        // where it is (`Planner::obstacle_frames`); the others', queued once behind the path.
        if !moving {
            let _ = planner.send_obstacles(&course.obstacles);
        }
        Self {
            planner,
            moving,
            replan_us: replan_s.map(|s| (s * 1e6).round().max(1.0) as u64),
            last_plan_us: 0,
        }
    }

    /// The planner's frames of the tick that starts at `tick_start_us`, the obstacles that walk
    /// where `walkers` has them.
    fn tick_frames(
        &mut self,
        course: &Course,
        walkers: &Walkers,
        tick_start_us: u64,
    ) -> Vec<TimedFrame> {
        self.replan(course, tick_start_us);
        let mut rx = Vec::new();
        if self.moving {
            // Where the obstacles are at the tick's start, before the queued frames.
            for frame in self.planner.obstacle_frames(&walkers.circles) {
                rx.push(TimedFrame {
                    t_us: tick_start_us + 250,
                    frame,
                });
            }
        }
        for (i, frame) in self.planner.take_tick_frames().into_iter().enumerate() {
            rx.push(TimedFrame {
                t_us: tick_start_us + 500 * (i as u64 + 1),
                frame,
            });
        }
        rx
    }

    /// A planner that replans queues the path and obstacles again once the previous transfer
    /// has gone out and `replan_us` has passed since it was queued.
    fn replan(&mut self, course: &Course, tick_start_us: u64) {
        let Some(every) = self.replan_us else { return };
        if self.planner.pending() == 0 && tick_start_us >= self.last_plan_us + every {
            self.last_plan_us = tick_start_us;
            let _ = self.planner.send_path(&course.path);
            if !self.moving {
                let _ = self.planner.send_obstacles(&course.obstacles);
            }
        }
    }
}

/// The node's tick at `t_tick_us` over this tick's frames `rx` behind those still in
/// `receive_queue`: what it reports and the frames it sends.
fn node_tick(
    driver: &mut dyn Driver,
    receive_queue: &mut VecDeque<TimedFrame>,
    rx: Vec<TimedFrame>,
    t_tick_us: u64,
) -> (TickReport, Vec<CanFrame>) {
    // As the firmware's receive queue and host replay: at most the node's per-tick cap of
    // frames, in arrival order; the rest wait for the next tick.
    receive_queue.extend(rx);
    let take = receive_queue.len().min(MAX_RX_FRAMES_PER_TICK);
    let due: Vec<TimedFrame> = receive_queue.drain(..take).collect();
    let mut tx = Vec::new();
    let tick = Tick {
        now_us: t_tick_us,
        platform: PlatformStats::default(),
    };
    let report = driver.tick(&tick, &due, &mut tx);
    (report, tx)
}

/// The truth's projection onto `path` a tick after `previous`: [`Path::project`]'s, unless it
/// left the window around `previous` (a car more than
/// [`catmodel::control::path::PROJECTION_RESEARCH_M`] off the path,
/// whose search then takes the whole path) for a point no nearer than the window's own by more
/// than [`ACQUIRE_TIE_M`]: then the window's. Where a path's end meets its start (the loop), a
/// car started 6 m or more off it is as near the end as the start, and the whole path's search
/// put it at the end on its second tick; a car that has really come nearer another part of the
/// path is still taken there.
fn follow(path: &Path, x: f64, y: f64, previous: &Projection) -> Option<Projection> {
    let projection = path.project(x as f32, y as f32, Some(previous))?;
    if (projection.station_m - previous.station_m).abs() <= PROJECTION_AHEAD_M {
        return Some(projection);
    }
    match nearest_in_window(path, x, y, previous) {
        Some(near) if near.lateral_m.abs() <= projection.lateral_m.abs() + ACQUIRE_TIE_M => {
            Some(near)
        }
        _ => Some(projection),
    }
}

/// The nearest point to `(x, y)` of the segments from [`PROJECTION_BEHIND_M`] behind to
/// [`PROJECTION_AHEAD_M`] ahead of `previous` (the window [`Path::project`] searches first),
/// in f64: the foot on the nearest segment, or its nearest end (a corner: the distance to it,
/// with the side of the segment's line). `None` for a path of fewer than two points.
fn nearest_in_window(path: &Path, x: f64, y: f64, previous: &Projection) -> Option<Projection> {
    let points = path.points();
    let last_segment = points.len().checked_sub(2)?;
    let hint = previous.segment.min(last_segment);
    let first = path.segment_hint(previous.station_m - PROJECTION_BEHIND_M, hint);
    let last = path
        .segment_hint(previous.station_m + PROJECTION_AHEAD_M, hint)
        .min(last_segment);
    let mut best: Option<(f64, Projection)> = None;
    for i in first..=last {
        let (Some(a), Some(b), Some(s_a)) = (points.get(i), points.get(i + 1), path.station_of(i))
        else {
            continue;
        };
        let (ax, ay) = (f64::from(a.east_m), f64::from(a.north_m));
        let (de, dn) = (f64::from(b.east_m) - ax, f64::from(b.north_m) - ay);
        let length = de.hypot(dn);
        if length <= 0.0 {
            continue;
        }
        let (ue, un) = (de / length, dn / length);
        let (px, py) = (x - ax, y - ay);
        let along = (px * ue + py * un).clamp(0.0, length);
        // Positive to the right of the segment's direction.
        let side = px * un - py * ue;
        let distance = (px - along * ue).hypot(py - along * un);
        if best.as_ref().is_none_or(|(d, _)| distance < *d) {
            best = Some((
                distance,
                Projection {
                    segment: i,
                    station_m: s_a + along as f32,
                    lateral_m: (distance.copysign(side)) as f32,
                },
            ));
        }
    }
    best.map(|(_, p)| p)
}

/// Whether `command` has the car drive: the controller tracking or avoiding with a speed
/// command above [`DRIVE_COMMAND_MPS`].
fn drives(command: &ControlCommand) -> bool {
    matches!(
        command.status,
        ControlStatus::Tracking | ControlStatus::Avoiding
    ) && command
        .speed_cmd_mps
        .is_some_and(|v| f64::from(v) > DRIVE_COMMAND_MPS)
}

/// Records and scores on truth, tick by tick: the samples, and what the metrics take from them.
struct TruthRecord {
    path: Path,
    projection: Option<Projection>,
    /// The course's scored stations, from and to, m.
    scored_stations_m: (f64, f64),
    /// The body's front ahead of the rear axle, m.
    front_ahead_m: f64,
    body_width_m: f64,
    /// Truth speed as the front reached the scored range, m/s.
    entry_speed_mps: Option<f64>,
    /// How far the body was outside the corridor at most in the scored range, m.
    corridor_exit_m: Option<f64>,
    /// When the rear axle reached the start and the end of the scored range, s.
    scored_span_s: (Option<f64>, Option<f64>),
    /// Since when the car has been at rest while engaged, s.
    stopped_since_s: Option<f64>,
    /// The last tick of that rest at which the node commanded the car to drive, s.
    drive_asked_s: Option<f64>,
    samples: Vec<Sample>,
}

impl TruthRecord {
    fn new(course: &Course, body: &Body) -> Self {
        Self {
            path: core_path(course),
            projection: None,
            scored_stations_m: course.scored_stations_m,
            front_ahead_m: body.length_m - body.rear_overhang_m,
            body_width_m: body.width_m,
            entry_speed_mps: None,
            corridor_exit_m: None,
            scored_span_s: (None, None),
            stopped_since_s: None,
            drive_asked_s: None,
            samples: Vec::new(),
        }
    }

    /// Records the tick at `t_tick_us`: the car (`rig`) on the path, the node's `report`, the
    /// command the drive-by-wire `seen` and whether it is `engaged`.
    fn tick(
        &mut self,
        t_tick_us: u64,
        rig: &Rig,
        report: &TickReport,
        seen: ControlCommand,
        engaged: bool,
    ) {
        let (scored_from, scored_to) = self.scored_stations_m;
        let truth = rig.truth();
        self.projection = match self.projection.as_ref() {
            Some(previous) => follow(&self.path, truth.x, truth.y, previous),
            // The car is placed on the path as the node places it (`Path::track` without a
            // previous projection): at the start of a path whose end meets its start (the
            // loop), not at the end. The nearest point of the whole path put a car half a
            // metre left of the loop's start at its end (station 205.64), past the scored
            // range: the run ended at its first tick.
            None => self
                .path
                .track(
                    &Pose::new(truth.x as f32, truth.y as f32, truth.heading as f32),
                    None,
                )
                .map(|t| t.projection),
        };
        let (station, lateral) = self.projection.map_or((f64::NAN, f64::NAN), |p| {
            (f64::from(p.station_m), f64::from(p.lateral_m))
        });
        // The body's sides at the rear axle against the corridor there.
        if station >= scored_from && station <= scored_to {
            if let Some(at) = self
                .projection
                .and_then(|p| self.path.sample(p.station_m, p.segment))
            {
                let exit = metrics::corridor_exit_m(
                    lateral,
                    self.body_width_m,
                    (f64::from(at.left_m), f64::from(at.right_m)),
                );
                self.corridor_exit_m = Some(self.corridor_exit_m.map_or(exit, |e| e.max(exit)));
            }
        }
        let t_s = t_tick_us as f64 * 1e-6;
        if self.entry_speed_mps.is_none() && station + self.front_ahead_m >= scored_from {
            self.entry_speed_mps = Some(truth.speed);
        }
        if station >= scored_from && self.scored_span_s.0.is_none() {
            self.scored_span_s.0 = Some(t_s);
        }
        if station >= scored_to && self.scored_span_s.1.is_none() {
            self.scored_span_s.1 = Some(t_s);
        }
        self.samples.push(Sample {
            t_s,
            truth,
            estimate: report
                .pose
                .map(|p| (f64::from(p.x_m), f64::from(p.y_m), f64::from(p.heading_rad))),
            command: seen,
            engaged,
            steer_pct: rig.steer_pct(),
            station_m: station,
            lateral_m: lateral,
        });
    }

    /// Whether the run ends after the last tick recorded, and why: past the scored range with
    /// room to spare, or at rest while engaged for [`STOPPED_END_S`] after the node last
    /// commanded the car to drive (a car that stopped for a pedestrian is waited for while the
    /// node sets it off again: a slow speed loop answers seconds later; before, the run ended
    /// 3 s after the car came to rest whatever the node commanded), or for
    /// [`STOPPED_DRIVING_END_S`] whatever it commands.
    fn ended(&mut self, engaged: bool) -> Option<RunEnd> {
        let last = self.samples.last()?;
        if engaged && last.truth.speed < STILL_MPS {
            let since = *self.stopped_since_s.get_or_insert(last.t_s);
            if drives(&last.command) {
                self.drive_asked_s = Some(last.t_s);
            }
            let quiet_since = self.drive_asked_s.map_or(since, |t| t.max(since));
            if last.t_s - quiet_since >= STOPPED_END_S {
                return Some(RunEnd::AtRest { since_s: since });
            }
            if last.t_s - since >= STOPPED_DRIVING_END_S {
                return Some(RunEnd::AtRestWhileDriving { since_s: since });
            }
        } else {
            self.stopped_since_s = None;
            self.drive_asked_s = None;
        }
        (last.station_m >= self.scored_stations_m.1 + self.front_ahead_m + 5.0)
            .then_some(RunEnd::PastCourse)
    }

    /// The lateral error's RMS and largest magnitude over the scored range, m.
    fn scored_lateral_m(&self) -> (Option<f64>, Option<f64>) {
        let (scored_from, scored_to) = self.scored_stations_m;
        let scored: Vec<f64> = self
            .samples
            .iter()
            .filter(|s| s.station_m >= scored_from && s.station_m <= scored_to)
            .map(|s| s.lateral_m)
            .collect();
        let lateral_rms = (!scored.is_empty())
            .then(|| (scored.iter().map(|e| e * e).sum::<f64>() / scored.len() as f64).sqrt());
        let lateral_max = scored.iter().map(|e| e.abs()).reduce(f64::max);
        (lateral_rms, lateral_max)
    }

    /// The run's scores: this record's, `scorer`'s cones, gates and obstacles, and the
    /// drive-by-wire's ticks.
    fn metrics(
        &self,
        course: &Course,
        controller_name: &str,
        receiver: Receiver,
        scorer: &Scorer,
        dbw: &DriveByWire,
    ) -> Metrics {
        let (cone_hits, min_cone) = scorer.cones();
        let (lateral_rms, lateral_max) = self.scored_lateral_m();
        // Under the controller: a node that never took the car (no position, a model file
        // its plant refuses) leaves the launch driver rolling through the course, which a
        // black-box probe's run reported as completed.
        let completed = match (self.scored_span_s.1, dbw.engaged_at_s) {
            (Some(end), Some(engaged)) => engaged <= end,
            _ => false,
        };
        let min_obstacle = scorer.obstacle_clearance_m();
        let total_time_s = self.samples.last().map_or(0.0, |s| s.t_s);
        Metrics {
            scenario: course.kind.name().to_string(),
            controller: controller_name.to_string(),
            receiver: receiver.name().to_string(),
            target_speed_mps: course.speed_mps,
            entry_speed_mps: self.entry_speed_mps,
            cone_hits,
            gates_missed: scorer.gates_missed(),
            min_cone_clearance_m: min_cone,
            min_obstacle_clearance_m: min_obstacle,
            completed,
            lateral_rms_m: lateral_rms,
            lateral_max_m: lateral_max,
            corridor_exit_m: self.corridor_exit_m,
            scored_time_s: match self.scored_span_s {
                (Some(a), Some(b)) => Some(b - a),
                _ => None,
            },
            driven_time_s: dbw.engaged_at_s.map_or(0.0, |t| total_time_s - t),
            total_time_s,
            status_ticks: dbw.status_ticks,
            fallback_ticks: {
                let names = fallback_names();
                dbw.fallback_ticks
                    .iter()
                    .map(|(raw, n)| (fallback_name(&names, *raw), *n))
                    .collect()
            },
            clean: completed
                && cone_hits == 0
                && scorer.gates_missed() == 0
                && min_obstacle.is_none_or(|d| d > 0.0)
                // The double lane change is scored by its cones and gates (ISO 3888-2): the
                // body may pass over the lane's edge between two cones.
                // Elsewhere the car must not have left the road: some of its body in the
                // corridor at every tick.
                && (course.kind == scenario::Kind::DoubleLaneChange
                    || self.corridor_exit_m.is_none_or(|e| e < self.body_width_m)),
        }
    }
}

/// `catmodel closed-loop`'s arguments.
#[derive(Debug, Clone)]
pub struct ClosedLoopArgs {
    /// Scenario name ([`scenario::SCENARIO_NAMES`]).
    pub scenario: String,
    /// `mpc` or `pure-pursuit`.
    pub controller: String,
    /// Vehicle file for the plant (default: the CAT Vehicle).
    pub vehicle: Option<std::path::PathBuf>,
    /// Model file for the node (default: the published models).
    pub model: Option<std::path::PathBuf>,
    /// `rtk` or `standard`.
    pub receiver: String,
    /// Target speed, m/s (default: the scenario's).
    pub speed_mps: Option<f64>,
    /// Sensor noise seed.
    pub seed: u64,
    /// The planner sends the path again this often, s (`None`: once).
    pub replan_s: Option<f64>,
    /// The car starts this far to the right of the path's first point, m.
    pub start_offset_m: f64,
    /// Inject the vehicle file's sensor faults.
    pub faults: bool,
    /// Output directory.
    pub out: std::path::PathBuf,
}

/// The controller called `name` (the node's own car from its model file) with a receiver of
/// horizontal RMS error `receiver_rms_m`: obstacles are kept clear by
/// [`OBSTACLE_MARGIN_M`] plus 2.5 times that (the estimate can be that far off; the node does
/// not publish its uncertainty yet).
pub fn controller_named(name: &str, receiver_rms_m: f64) -> anyhow::Result<driver::Controller> {
    match name {
        "pure-pursuit" => Ok(driver::Controller::PurePursuit(
            catmodel::control::pure_pursuit::PurePursuitTuning {
                obstacle_margin_m: (OBSTACLE_MARGIN_M + 2.5 * receiver_rms_m) as f32,
                ..catmodel::control::pure_pursuit::DEFAULT_TUNING
            },
        )),
        "mpc" => Ok(driver::Controller::Mpc),
        other => anyhow::bail!("unknown controller `{other}`; known: mpc, pure-pursuit"),
    }
}

/// Loads the plant's vehicle (`vehicle`, default the CAT Vehicle) and the node's configuration
/// from the car's model file (`model`, default `models/paper.toml`, the CAT Vehicle's; without
/// one, a plant vehicle is described to the node as its model file would: [`model_file_for`]).
pub fn load_setup(
    vehicle: Option<&std::path::Path>,
    model: Option<&std::path::Path>,
) -> anyhow::Result<(VehicleConfig, NodeConfig)> {
    let cfg = match vehicle {
        Some(p) => VehicleConfig::load(p).map_err(|e| anyhow::anyhow!("{e}"))?,
        None => VehicleConfig::default(),
    };
    let node = if vehicle.is_some() && model.is_none() {
        model_file_for(&cfg)?.node_config()
    } else {
        crate::node_config(model)?
    };
    let mut cfg = cfg;
    if vehicle.is_none() && model.is_some() {
        // The CAT Vehicle's plant with the receiver the model file declares, where it declares
        // it: the node uses no fix at another rate (`gnss_rate_mismatch`), and a 5 Hz car's
        // file over the plant's 100 Hz receiver would leave it without a position.
        // (The f32 figures' rounding undone: the published file leaves the plant as it is.)
        let gnss = &mut cfg.sensors.gnss;
        gnss.period_s = 1.0 / node.estimator.declared_gnss_rate_hz();
        let ahead = f64::from(node.estimator.antenna_ahead_m);
        if (ahead - gnss.antenna_ahead_of_rear_axle_m).abs() > 1e-5 {
            gnss.antenna_ahead_of_rear_axle_m = ahead;
        }
    }
    // The node takes its first fix as its origin, as the firmware does (see `driver`).
    Ok((cfg, node))
}

/// The horizontal RMS error of `vehicle`'s GNSS receiver with `receiver`, m.
pub fn receiver_rms_m(vehicle: &VehicleConfig, receiver: Receiver) -> f64 {
    let mut gnss = vehicle.sensors.gnss.clone();
    receiver.apply(&mut gnss);
    (2.0 * (gnss.white_noise_m.powi(2) + gnss.bias_sigma_m.powi(2))).sqrt()
}

/// `catmodel closed-loop`: runs the scenario and writes `session.can.log` (every frame the node
/// received), `session.tx.log` (every frame sent from the node's place), `metrics.json` and the
/// plots into `out`; returns the metrics and the files written.
pub fn command(args: &ClosedLoopArgs) -> anyhow::Result<(Metrics, Vec<std::path::PathBuf>)> {
    let kind = scenario::Kind::from_name(&args.scenario).ok_or_else(|| {
        anyhow::anyhow!(
            "unknown scenario `{}`; known: {}",
            args.scenario,
            scenario::SCENARIO_NAMES.join(", ")
        )
    })?;
    let receiver = Receiver::from_name(&args.receiver).ok_or_else(|| {
        anyhow::anyhow!("unknown receiver `{}`; known: rtk, standard", args.receiver)
    })?;
    let (vehicle, node) = load_setup(args.vehicle.as_deref(), args.model.as_deref())?;
    let controller = controller_named(&args.controller, receiver_rms_m(&vehicle, receiver))?;
    let speed = args.speed_mps.unwrap_or(kind.default_speed_mps());
    if !(speed.is_finite() && speed > 0.0 && speed <= 40.0) {
        anyhow::bail!("--speed {speed}: a target speed is in (0, 40] m/s");
    }
    let course = scenario::course(kind, &vehicle.body, speed);
    let mut driver = driver::NodeDriver::new(node, controller);
    if let Some(r) = args.replan_s {
        if !(r.is_finite() && r >= 0.02) {
            anyhow::bail!("--replan-every {r}: a period of at least 0.02 s");
        }
    }
    if !(args.start_offset_m.is_finite() && args.start_offset_m.abs() <= MAX_START_OFFSET_M) {
        anyhow::bail!(
            "--start-offset {}: at most {MAX_START_OFFSET_M} m either side",
            args.start_offset_m
        );
    }
    let options = RunOptions {
        seed: args.seed,
        receiver,
        max_time_s: 300.0,
        replan_s: args.replan_s,
        start_offset_m: args.start_offset_m,
        faults: args.faults,
        reversed_steering_report: false,
        launch_mps: LAUNCH_SPEED_MPS,
    };
    let output = run(&vehicle, &course, &mut driver, &args.controller, &options);
    if let Some(note) = driver::Driver::gnss_rate_note(&driver) {
        eprintln!("closed-loop: warning: {note}");
    }
    if let Some(note) = driver::Driver::steering_note(&driver) {
        eprintln!("closed-loop: warning: {note}");
    }
    if let Some(note) = slide_note(&args.scenario, &output, &vehicle) {
        eprintln!("closed-loop: warning: {note}");
    }
    if let Some(note) = end_note(&output, options.max_time_s) {
        eprintln!("closed-loop: warning: {note}");
    }
    let mut files = write_session(&args.out, &output)?;
    files.extend(plots::write_plots(&args.out, &output, &vehicle.body)?);
    Ok((output.metrics, files))
}

/// A run whose car slid beyond its tyres' grip ([`crate::sim::slide_summary`]): the course at
/// its speed asks more than the plant's tyres give. The node has no grip limit of its own (its
/// models are linear; the planner's speeds are taken as driveable), so the run measures a car
/// past its grip; before, a spin on the loop at 14 m/s was reported as `lost_path` alone.
pub fn slide_note(scenario: &str, output: &RunOutput, vehicle: &VehicleConfig) -> Option<String> {
    let truth: Vec<_> = output.samples.iter().map(|s| s.truth).collect();
    crate::sim::slide_summary(scenario, &truth, vehicle).map(|slid| {
        format!(
            "{slid}: the course at this speed asks more than the car's tyres give, and the \
             node takes the planner's speeds as driveable (its models are linear, with no grip \
             limit): the run's figures are those of a car beyond its grip"
        )
    })
}

/// Why a run that did not complete the course ended ([`RunEnd`]), with where the car was and
/// what the node last commanded; `None` for a completed run. Before, a session the rig ended
/// 3 s after the car came to rest, with the node commanding it to drive again, said nothing.
pub fn end_note(output: &RunOutput, max_time_s: f64) -> Option<String> {
    if output.metrics.completed {
        return None;
    }
    let last = output.samples.last()?;
    let length = core_path(&output.course).length_m();
    let at = format!(
        "the rear axle at station {:.1} m of the path's {length:.1} m",
        last.station_m
    );
    let command = command_text(&last.command);
    Some(match output.end {
        RunEnd::PastCourse => format!(
            "the session ended not completed: the car passed the course's end ({at}) without \
             the controller having driven it through the scored range ({})",
            output.samples.iter().find(|s| s.engaged).map_or(
                "the node never took it over from the launch driver".to_string(),
                |s| format!("the node took it over at t = {:.2} s, past it", s.t_s)
            )
        ),
        RunEnd::AtRest { since_s } => format!(
            "the session ended not completed: the car came to rest under the controller at \
             t = {since_s:.2} s ({at}) and the node did not command it to drive for \
             {STOPPED_END_S} s (last command: {command}); the rig ends a session {STOPPED_END_S} \
             s after the car comes to rest or the node last asks it to drive, whichever is later"
        ),
        RunEnd::AtRestWhileDriving { since_s } => format!(
            "the session ended not completed: the car stayed at rest from t = {since_s:.2} s \
             ({at}) for {STOPPED_DRIVING_END_S} s while the node commanded it to drive (last \
             command: {command}): the car's speed loop did not answer, and the rig ends a \
             session at rest that long whatever the node commands"
        ),
        RunEnd::TimeLimit => format!(
            "the session ended not completed: its time limit of {max_time_s} s passed ({at}, \
             last command: {command})"
        ),
    })
}

/// A CONTROL_COMMAND as words: its status's DBC name, the speed command, the fallback's reason.
fn command_text(command: &ControlCommand) -> String {
    let status = match command.status {
        ControlStatus::NoPath => "no_path",
        ControlStatus::Tracking => "tracking",
        ControlStatus::Avoiding => "avoiding",
        ControlStatus::Fallback => "fallback",
    };
    let speed = command
        .speed_cmd_mps
        .map_or("no speed".to_string(), |v| format!("speed {v:.2} m/s"));
    if command.status == ControlStatus::Fallback {
        let reason = fallback_name(&fallback_names(), command.fallback as u8);
        format!("status {status} ({reason}), {speed}")
    } else {
        format!("status {status}, {speed}")
    }
}

/// The files [`write_session`] writes into its directory, in order.
pub const SESSION_FILES: [&str; 4] = [
    "session.can.log",
    "session.tx.log",
    "samples.csv",
    "metrics.json",
];

/// Writes a run's files ([`SESSION_FILES`]) into `dir` (created).
pub fn write_session(
    dir: &std::path::Path,
    output: &RunOutput,
) -> anyhow::Result<Vec<std::path::PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|e| anyhow::anyhow!("creating {}: {e}", dir.display()))?;
    let mut written = Vec::new();
    let inputs = dir.join(SESSION_FILES[0]);
    crate::replay::write_file(&inputs, &crate::csv2can::to_candump(&output.inputs))?;
    written.push(inputs);
    let tx = dir.join(SESSION_FILES[1]);
    crate::replay::write_file(&tx, &crate::csv2can::to_candump(&output.outputs))?;
    written.push(tx);
    let samples = dir.join(SESSION_FILES[2]);
    crate::replay::write_file(&samples, &samples_csv(&output.samples))?;
    written.push(samples);
    let metrics = dir.join(SESSION_FILES[3]);
    crate::replay::write_file(&metrics, &serde_json::to_string_pretty(&output.metrics)?)?;
    written.push(metrics);
    Ok(written)
}

/// CONTROL_COMMAND `fallback_reason`'s value names, from the built-in `catmodel.dbc` (the one
/// source of the bus's names; empty if it could not be read, which its tests rule out).
pub fn fallback_names() -> Vec<(i64, String)> {
    crate::dbc::Dbc::catmodel()
        .ok()
        .and_then(|dbc| {
            dbc.message("CONTROL_COMMAND")
                .and_then(|m| m.signal("fallback_reason"))
                .map(|sig| sig.values.clone())
        })
        .unwrap_or_default()
}

/// The DBC's name for the raw `fallback_reason` (the number itself where it has none).
pub fn fallback_name(names: &[(i64, String)], raw: u8) -> String {
    names
        .iter()
        .find(|(v, _)| *v == i64::from(raw))
        .map_or_else(|| raw.to_string(), |(_, name)| name.clone())
}

/// The per-tick records as CSV: `t,x,y,heading,speed,est_x,est_y,est_heading,status,
/// steer_cmd,speed_cmd,steer,engaged,station,lateral,fallback` (truth rear axle; the node's
/// estimate; the command the drive-by-wire received; the actuator's steering; truth station and
/// lateral error on the path; the CONTROL_COMMAND's `fallback_reason` by its DBC name; empty
/// where not available).
pub fn samples_csv(samples: &[Sample]) -> String {
    use std::fmt::Write;
    let names = fallback_names();
    let mut out = String::from(
        "t,x,y,heading,speed,est_x,est_y,est_heading,status,steer_cmd,speed_cmd,steer,engaged,station,lateral,fallback\n",
    );
    let opt = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.4}"));
    for s in samples {
        let (ex, ey, eh) = match s.estimate {
            Some((x, y, h)) => (Some(x), Some(y), Some(h)),
            None => (None, None, None),
        };
        let _ = writeln!(
            out,
            "{:.2},{:.4},{:.4},{:.5},{:.3},{},{},{},{},{},{},{:.2},{},{},{},{}",
            s.t_s,
            s.truth.x,
            s.truth.y,
            s.truth.heading,
            s.truth.speed,
            opt(ex),
            opt(ey),
            opt(eh),
            s.command.status as u8,
            opt(s.command.steer_cmd_pct.map(f64::from)),
            opt(s.command.speed_cmd_mps.map(f64::from)),
            s.steer_pct,
            u8::from(s.engaged),
            opt(s.station_m.is_finite().then_some(s.station_m)),
            opt(s.lateral_m.is_finite().then_some(s.lateral_m)),
            fallback_name(&names, s.command.fallback as u8),
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A record of the crossing at its default speed for the CAT Vehicle.
    fn crossing_record() -> TruthRecord {
        let vehicle = VehicleConfig::default();
        let course = scenario::course(
            scenario::Kind::Crossing,
            &vehicle.body,
            scenario::Kind::Crossing.default_speed_mps(),
        );
        TruthRecord::new(&course, &vehicle.body)
    }

    /// The tick of `record` at `t_s`, the car engaged at `speed_mps` on station 100 m and the
    /// node's `command`; whether the run ends there, and why.
    fn tick(
        record: &mut TruthRecord,
        t_s: f64,
        speed_mps: f64,
        command: ControlCommand,
    ) -> Option<RunEnd> {
        record.samples.push(Sample {
            t_s,
            truth: TruthRow {
                t: t_s,
                speed: speed_mps,
                ..TruthRow::default()
            },
            estimate: None,
            command,
            engaged: true,
            steer_pct: 0.0,
            station_m: 100.0,
            lateral_m: 0.0,
        });
        record.ended(true)
    }

    /// `status` with the speed command `speed_mps`.
    fn command(status: ControlStatus, speed_mps: f32) -> ControlCommand {
        ControlCommand {
            status,
            speed_cmd_mps: Some(speed_mps),
            ..IDLE_COMMAND
        }
    }

    /// The run of ticks 20 ms apart from `from_s` on, the car engaged at the speed and the node
    /// commanding what `at` gives for each tick's time: when it ends, and why (`None` if not
    /// within 60 s).
    fn end_of(from_s: f64, at: impl Fn(f64) -> (f64, ControlCommand)) -> Option<(f64, RunEnd)> {
        let mut record = crossing_record();
        (0..3000).find_map(|k| {
            let t = from_s + 0.02 * f64::from(k);
            let (speed, command) = at(t);
            tick(&mut record, t, speed, command).map(|end| (t, end))
        })
    }

    /// Whether `a` and `b` are the same tick's time.
    fn same_tick(a: f64, b: f64) -> bool {
        (a - b).abs() < 0.01
    }

    /// A car at rest under the controller ends the run 3 s after the node last commanded it to
    /// drive, not 3 s after it came to rest: a black-box probe's car with a slow speed loop
    /// stopped for the crossing's pedestrian, the node set it off again 1.8 s later, and the
    /// rig ended the session 3.0 s after the stop, before the speed loop answered (not
    /// completed, nothing said why).
    #[test]
    fn a_car_at_rest_is_waited_for_while_the_node_sets_it_off() {
        let hold = command(ControlStatus::Fallback, 0.0);
        let go = command(ControlStatus::Tracking, 6.0);
        // At rest from 20 s, asked to drive from 21.8 s to 22.0 s.
        let ended = end_of(20.0, |t| {
            (
                0.0,
                if (21.79..21.99).contains(&t) {
                    go
                } else {
                    hold
                },
            )
        });
        assert!(
            matches!(ended, Some((t, RunEnd::AtRest { since_s })) if same_tick(t, 24.98)
                && same_tick(since_s, 20.0)),
            "{ended:?}"
        );
        // Asked until the car sets off: not ended.
        let ended = end_of(20.0, |t| {
            let speed = if t > 24.0 { 0.5 } else { 0.0 };
            (speed, if t > 21.79 { go } else { hold })
        });
        assert_eq!(ended, None);
    }

    /// A car at rest with the node holding it ends the run 3 s after it came to rest, as before.
    #[test]
    fn a_car_held_at_rest_ends_the_run_after_3_s() {
        let hold = command(ControlStatus::Tracking, 0.0);
        let ended = end_of(10.0, |_| (0.0, hold));
        assert!(
            matches!(ended, Some((t, RunEnd::AtRest { since_s })) if same_tick(t, 13.0)
                && same_tick(since_s, 10.0)),
            "{ended:?}"
        );
    }

    /// A car whose speed loop never answers the node's command to drive ends the run after
    /// [`STOPPED_DRIVING_END_S`] at rest: the run's length stays bounded.
    #[test]
    fn a_car_that_never_answers_ends_the_run_after_20_s_at_rest() {
        let go = command(ControlStatus::Avoiding, 6.0);
        let ended = end_of(10.0, |_| (0.0, go));
        assert!(
            matches!(ended, Some((t, RunEnd::AtRestWhileDriving { since_s }))
                if same_tick(t, 10.0 + STOPPED_DRIVING_END_S) && same_tick(since_s, 10.0)),
            "{ended:?}"
        );
        // Moving for a tick restarts the count.
        let ended = end_of(10.0, |t| (if same_tick(t, 25.0) { 0.5 } else { 0.0 }, go));
        assert!(
            matches!(ended, Some((t, RunEnd::AtRestWhileDriving { since_s }))
                if same_tick(t, 25.02 + STOPPED_DRIVING_END_S) && same_tick(since_s, 25.02)),
            "{ended:?}"
        );
    }
}
