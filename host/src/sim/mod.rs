//! The plant simulator behind `catmodel simulate-drive`: every log the project is tested on
//! comes from here, since there is no real car.
//!
//! ```text
//! scenario commands (speed m/s, steering %)
//!   -> car internals: speed command -> transport delay -> PI loop -> accel limits -> powertrain lag
//!                     steering command -> rate limit -> actuator lag
//!   -> plant: nonlinear single-track model, magic-formula tyres, load transfer (RK4, 1 ms)
//!   -> sensors on their own clocks: speed / steering / pedal reports at 50 Hz, GNSS at 100 Hz
//!   -> log rows (docs/logs.md schema) + ground truth at 100 Hz
//! ```
//! Deterministic for a given seed on every platform: ChaCha8 streams, and only IEEE arithmetic
//! and the pure-Rust `libm` (never std's platform-dependent transcendental functions).
//!
//! Owns: the simulation. Never: reads files other than a vehicle file it is given, or the clock.
pub mod config;
pub mod controller;
pub mod geo;
pub mod plant;
pub mod rng;
pub mod scenario;
pub mod sensors;

use crate::logcsv::{self, LogError, LogRow, TruthRow};
use config::VehicleConfig;
use controller::{SpeedController, SteeringActuator};
use plant::{Plant, PlantInput, PlantState};
use rng::{SimRng, Stream};
use scenario::{Command, Scenario};
use sensors::{Held, SensorSuite, Snapshot};
use std::path::{Path, PathBuf};

/// Plant and actuator integration step, s (1 ms).
pub const PLANT_STEP_S: f64 = 0.001;
/// Ground-truth rows every this many plant steps (100 Hz).
pub const TRUTH_EVERY_STEPS: usize = 10;

/// How to run a scenario.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimOptions {
    /// Repetition number: noise, clocks and command variations.
    pub seed: u64,
    /// Inject sensor faults (GNSS outages and outliers, lost bus reports).
    pub faults: bool,
    /// Apply the seed's small variations to the scenario's commands (a repetition by a human).
    /// Off for tests that need the exact commands.
    pub vary_commands: bool,
    /// Origin of the local frame (latitude, longitude), degrees.
    pub origin_deg: (f64, f64),
}

impl Default for SimOptions {
    fn default() -> Self {
        Self {
            seed: 0,
            faults: false,
            vary_commands: true,
            origin_deg: (geo::ORIGIN_LAT_DEG, geo::ORIGIN_LON_DEG),
        }
    }
}

/// Everything a run produces.
#[derive(Debug, Clone, PartialEq)]
pub struct SimOutput {
    /// The commands actually driven (after the seed's variations).
    pub scenario: Scenario,
    /// Log rows, strictly increasing in time, each sensor on its own clock.
    pub log: Vec<LogRow>,
    /// Ground truth at 100 Hz (rear-axle centre, heading, yaw rate, speed).
    pub truth: Vec<TruthRow>,
}

/// Why a run could not start.
#[derive(Debug)]
pub enum SimError {
    /// No built-in scenario has this name.
    UnknownScenario(String),
    /// The vehicle file is unusable.
    Config(config::ConfigError),
}

impl std::fmt::Display for SimError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SimError::UnknownScenario(n) => write!(
                f,
                "unknown scenario `{n}`; known: {}",
                scenario::SCENARIO_NAMES.join(", ")
            ),
            SimError::Config(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for SimError {}

/// Runs the built-in scenario `name`, with the vehicle file `vehicle` or the CAT Vehicle.
pub fn run_named(
    name: &str,
    vehicle: Option<&Path>,
    options: &SimOptions,
) -> Result<SimOutput, SimError> {
    run_named_on(name, &load_vehicle(vehicle)?, options)
}

/// The vehicle file `vehicle`, or the CAT Vehicle.
pub fn load_vehicle(vehicle: Option<&Path>) -> Result<VehicleConfig, SimError> {
    match vehicle {
        Some(p) => VehicleConfig::load(p).map_err(SimError::Config),
        None => Ok(VehicleConfig::default()),
    }
}

/// Runs the built-in scenario `name` on the plant `cfg`. This is what `catmodel simulate-drive`
/// calls (after `--receiver` changed the vehicle's GNSS receiver).
pub fn run_named_on(
    name: &str,
    cfg: &VehicleConfig,
    options: &SimOptions,
) -> Result<SimOutput, SimError> {
    let base =
        Scenario::builtin(name).ok_or_else(|| SimError::UnknownScenario(name.to_string()))?;
    Ok(simulate(&base, cfg, options))
}

/// The rear axle's sideslip (its velocity's angle off the heading, the rear tyres' slip
/// angle) beyond which the car slides, rad: a car in its tyres' linear range slips a few
/// hundredths of a radian.
pub const SLIDE_RAD: f64 = 0.1;
/// Sliding for longer than this in all, s, is named.
pub const SLIDE_NAMED_S: f64 = 0.5;

/// When the car of a simulated drive slid beyond its tyres' grip (the rear axle's sideslip over
/// [`SLIDE_RAD`] at more than 3 m/s, for [`SLIDE_NAMED_S`] or longer in all): a warning with the
/// time, the largest sideslip and lateral acceleration against the tyres' `mu g`. A drive
/// beyond the grip is not one the identified models (linear, or the kinematic bicycle)
/// describe: a black-box probe's 220 kg kart spun in the built-in validation drive (sideslip
/// 1.28 rad), and `identify` then blamed the validation drive's fit on "another car, another
/// speed-loop setting, or a fault".
pub fn slide_warning(name: &str, truth: &[TruthRow], cfg: &VehicleConfig) -> Option<String> {
    slide_summary(name, truth, cfg).map(|slid| {
        format!(
            "{slid}: the scenario asks more than this car has; a drive beyond the grip is not \
             one the identified models describe, so do not train or validate on it"
        )
    })
}

/// How long and how far the car of `truth` slid beyond its tyres' grip, when it did for
/// [`SLIDE_NAMED_S`] or more: "NAME: the car slid ..." (the first half of
/// [`slide_warning`], for a caller with its own advice).
pub fn slide_summary(name: &str, truth: &[TruthRow], cfg: &VehicleConfig) -> Option<String> {
    let mu_g = cfg.tyre_front.friction_mu.min(cfg.tyre_rear.friction_mu) * 9.81;
    let (mut sliding_s, mut first, mut worst_rad, mut worst_g) = (0.0, None, 0.0f64, 0.0f64);
    for w in truth.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        let dt = b.t - a.t;
        let (dx, dy) = (b.x - a.x, b.y - a.y);
        if dt <= 0.0 || b.speed <= 3.0 || dx.hypot(dy) <= 0.0 {
            continue;
        }
        // Heading clockwise from north, as the truth's: the course is atan2(east, north).
        let course = dx.atan2(dy);
        let slip = (course - b.heading + std::f64::consts::PI)
            .rem_euclid(2.0 * std::f64::consts::PI)
            - std::f64::consts::PI;
        if slip.abs() > SLIDE_RAD {
            sliding_s += dt;
            first.get_or_insert(b.t);
            worst_rad = worst_rad.max(slip.abs());
            worst_g = worst_g.max((b.yaw_rate * b.speed).abs());
        }
    }
    let first = first?;
    (sliding_s >= SLIDE_NAMED_S).then(|| {
        format!(
            "{name}: the car slid beyond its tyres' grip for {sliding_s:.1} s, from t = \
             {first:.1} s (the rear axle's sideslip up to {worst_rad:.2} rad, the yaw rate times \
             the speed up to {worst_g:.1} m/s^2 against the tyres' mu g of {mu_g:.1})"
        )
    })
}

/// Writes `DIR/NAME.csv` (log) and `DIR/NAME.truth.csv`, creating `dir`; returns both paths.
pub fn write_outputs(
    dir: &Path,
    name: &str,
    output: &SimOutput,
) -> Result<(PathBuf, PathBuf), LogError> {
    std::fs::create_dir_all(dir).map_err(|e| LogError {
        path: dir.to_path_buf(),
        line: 0,
        char_column: 0,
        column: None,
        kind: logcsv::LogErrorKind::Io(e),
    })?;
    let log_path = dir.join(format!("{name}.csv"));
    let truth_path = dir.join(format!("{name}.truth.csv"));
    logcsv::write_log(&log_path, &output.log)?;
    logcsv::write_truth(&truth_path, &output.truth)?;
    Ok((log_path, truth_path))
}

fn wrap_pi(a: f64) -> f64 {
    let two_pi = 2.0 * core::f64::consts::PI;
    let w = a - two_pi * libm::floor((a + core::f64::consts::PI) / two_pi);
    // w in [-pi, pi); report pi rather than -pi.
    if w <= -core::f64::consts::PI {
        w + two_pi
    } else {
        w
    }
}

fn round_to(x: f64, inv_resolution: f64) -> f64 {
    libm::round(x * inv_resolution) / inv_resolution
}

/// The car as its bus sees it: the plant behind its steering actuator and speed controller,
/// and the sensors on their own clocks, stepped [`PLANT_STEP_S`] at a time with the commands
/// the car holds. [`simulate`] drives it from a scenario's command list; the closed loop
/// (`crate::closed_loop`) from the controller's CONTROL_COMMAND frames.
#[derive(Debug, Clone)]
pub struct Rig {
    plant: Plant,
    state: PlantState,
    steering: SteeringActuator,
    speed_ctl: SpeedController,
    /// `None`: a rig without sensors (the offline optimiser knows the state exactly).
    sensors: Option<SensorSuite>,
    cg_to_rear_m: f64,
    antenna_ahead_m: f64,
    antenna_left_m: f64,
    max_steer_rad: f64,
    ax_mps2: f64,
    steer_pct: f64,
    snapshot: Snapshot,
    step: u64,
}

impl Rig {
    /// The car at rest at `initial` (CG state), steering at `steer_pct`, the clock at 0.
    /// `cfg` should have passed [`VehicleConfig::validate`].
    pub fn new(
        cfg: &VehicleConfig,
        options: &SimOptions,
        initial: PlantState,
        steer_pct: f64,
    ) -> Self {
        let dt = PLANT_STEP_S;
        let plant = Plant::new(cfg);
        let cg_to_rear_m = plant.cg_to_rear_m();
        let mut rig = Self {
            plant,
            state: initial,
            steering: SteeringActuator::new(&cfg.steering, dt, steer_pct),
            speed_ctl: SpeedController::new(&cfg.speed_controller, cfg.chassis.mass_kg, dt),
            sensors: Some(SensorSuite::new(
                &cfg.sensors.bus,
                &cfg.sensors.gnss,
                options.faults.then_some(&cfg.faults),
                options.seed,
                options.origin_deg,
            )),
            cg_to_rear_m,
            antenna_ahead_m: cfg.sensors.gnss.antenna_ahead_of_rear_axle_m,
            antenna_left_m: cfg.sensors.gnss.antenna_left_of_centre_line_m,
            max_steer_rad: cfg.chassis.max_steer_deg.to_radians(),
            ax_mps2: 0.0,
            steer_pct,
            snapshot: Snapshot::default(),
            step: 0,
        };
        rig.snapshot = rig.snapshot_now();
        rig
    }

    fn snapshot_now(&self) -> Snapshot {
        let s = &self.state;
        let (sin_h, cos_h) = (libm::sin(s.heading_rad), libm::cos(s.heading_rad));
        let ahead = self.antenna_ahead_m - self.cg_to_rear_m;
        // The heading is clockwise from north: ahead is (sin, cos), left (-cos, sin).
        let left = self.antenna_left_m;
        Snapshot {
            speed_mps: s.vx_mps,
            steer_pct: self.steer_pct,
            antenna_east_m: s.x_m + ahead * sin_h - left * cos_h,
            antenna_north_m: s.y_m + ahead * cos_h + left * sin_h,
        }
    }

    /// Steps taken so far.
    pub fn steps(&self) -> u64 {
        self.step
    }

    /// Time of the next step's start, s.
    pub fn time_s(&self) -> f64 {
        self.step as f64 * PLANT_STEP_S
    }

    /// The plant's state (CG motion).
    pub fn state(&self) -> &PlantState {
        &self.state
    }

    /// The steering actuator's position, %.
    pub fn steer_pct(&self) -> f64 {
        self.steer_pct
    }

    /// Distance from the CG to the rear axle, m.
    pub fn cg_to_rear_m(&self) -> f64 {
        self.cg_to_rear_m
    }

    /// Ground truth now: rear-axle centre, heading, yaw rate, speed over ground there.
    pub fn truth(&self) -> TruthRow {
        let state = &self.state;
        let b = self.cg_to_rear_m;
        let (sin_h, cos_h) = (libm::sin(state.heading_rad), libm::cos(state.heading_rad));
        let v_lat_rear = state.vy_mps - b * state.yaw_rate_rps;
        let micro = 1e6;
        TruthRow {
            t: round_to(self.time_s(), micro),
            x: round_to(state.x_m - b * sin_h, micro),
            y: round_to(state.y_m - b * cos_h, micro),
            heading: round_to(wrap_pi(state.heading_rad), micro),
            yaw_rate: round_to(state.yaw_rate_rps, micro),
            speed: round_to(
                libm::sqrt(state.vx_mps * state.vx_mps + v_lat_rear * v_lat_rear),
                micro,
            ),
        }
    }

    /// One plant step with `command` held (speed command as sent, before the car's delay).
    pub fn step(&mut self, command: &Command) {
        let dt = PLANT_STEP_S;
        let t0 = self.time_s();
        self.steer_pct = self.steering.step(command.steer_pct);
        let drive = self.speed_ctl.step(command.speed_mps, self.state.vx_mps);
        let input = PlantInput {
            steer_rad: self.steer_pct / 100.0 * self.max_steer_rad,
            drive_force_n: drive.drive_force_n,
            brake_force_n: drive.brake_force_n,
        };
        self.ax_mps2 = self.plant.step(&mut self.state, &input, self.ax_mps2, dt);
        let s1 = self.snapshot_now();
        let held = Held {
            command_mps: command.speed_mps,
            accel_pct: drive.accel_pct,
            brake_pct: drive.brake_pct,
        };
        if let Some(sensors) = self.sensors.as_mut() {
            sensors.observe(t0, t0 + dt, &self.snapshot, &s1, &held);
        }
        self.snapshot = s1;
        self.step += 1;
    }

    /// Takes the sensor reports produced so far, in production order (each stream in time
    /// order), with their log times in microseconds.
    pub fn take_reports(&mut self) -> Vec<(i64, LogRow)> {
        self.sensors
            .as_mut()
            .map(|s| std::mem::take(&mut s.rows))
            .unwrap_or_default()
    }

    /// The same rig without its sensors: nothing is measured, the state is known exactly.
    pub fn without_sensors(mut self) -> Self {
        self.sensors = None;
        self
    }
}

/// Runs `base` (varied by the seed unless `options.vary_commands` is false) on the car `cfg`.
/// `cfg` should have passed [`VehicleConfig::validate`] (what [`VehicleConfig::load`] does).
pub fn simulate(base: &Scenario, cfg: &VehicleConfig, options: &SimOptions) -> SimOutput {
    let scenario = if options.vary_commands {
        base.varied(&mut SimRng::new(options.seed, Stream::Commands))
    } else {
        base.clone()
    };
    let dt = PLANT_STEP_S;
    let initial = PlantState {
        heading_rad: scenario.initial_heading_rad,
        ..Default::default()
    };
    let first = scenario.command_at(0.0);
    let mut rig = Rig::new(cfg, options, initial, first.steer_pct);
    let n_steps = libm::round(scenario.duration_s() / dt) as usize;
    let mut truth = Vec::with_capacity(n_steps / TRUTH_EVERY_STEPS + 1);
    for k in 0..n_steps {
        if k % TRUTH_EVERY_STEPS == 0 {
            truth.push(rig.truth());
        }
        let command = scenario.command_at(rig.time_s());
        rig.step(&command);
    }

    SimOutput {
        scenario,
        log: merge_rows(rig.take_reports()),
        truth,
    }
}

/// Sorts the reports by log time and merges reports logged in the same microsecond into one row.
fn merge_rows(mut rows: Vec<(i64, LogRow)>) -> Vec<LogRow> {
    rows.sort_by_key(|(t, _)| *t);
    let mut out: Vec<LogRow> = Vec::with_capacity(rows.len());
    let mut last_t: Option<i64> = None;
    for (t, row) in rows {
        match out.last_mut() {
            Some(prev) if last_t == Some(t) => prev.merge(&row),
            _ => out.push(row),
        }
        last_t = Some(t);
    }
    out
}
