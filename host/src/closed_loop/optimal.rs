//! The physical limit of the double lane change for a car: the highest entry speed at which
//! *some* steering profile takes the plant through the ISO 3888-2 track without touching a
//! cone, found with perfect knowledge of the plant (the simulator itself, noise-free, its state
//! known exactly).
//!
//! Method:
//! - The car is brought to the speed on the run-up (speed command held at the speed, steering
//!   0), and its whole state (plant, steering actuator, the speed controller with its delay
//!   line) is kept [`START_BEFORE_TRACK_M`] before the first cones. Every trial starts from
//!   that state, the speed command held.
//! - A steering profile is a steering *command* per knot, [`KNOT_S`] apart, linear in between
//!   and held after the last; the car's own actuator (rate limit, lag) turns it into the
//!   steering the tyres get, so every profile tried is one the car can execute.
//! - A trial runs until the body has passed the last cone (or has turned more than 90 degrees
//!   off the course: a spin). Its residuals: per cone, `max(0, MARGIN - clearance)` (the body's
//!   smallest distance to that cone over the trial); per gate (a pair of cones), how far
//!   outside the lane the rear axle crossed it (the car must go through the track, not around
//!   it); for a spin, one large residual; and a small weight on the knots' differences (keeps
//!   the problem well-posed where no cone constrains a knot).
//! - Levenberg-Marquardt on those residuals, the Jacobian by forward differences (one trial
//!   per knot, run on two threads), from several starts: the path's curvature turned into
//!   steering with three previews ([`PREVIEWS_S`]), the best profile at the previous speed
//!   stretched in time, and pure pursuit run on the exact state (the reference controller with
//!   perfect knowledge). A speed is *passable* when a trial has every cone clearance > 0.
//! - The limit: from a passable speed up in [`SCAN_STEP_MPS`] steps to the first speed no start
//!   passes, then bisection to [`TOLERANCE_MPS`].
//!
//! How we know it finds the limit, and what it cannot promise: the starts include every profile
//! that a controller here produces with perfect knowledge, so the optimiser's limit is never
//! below a known passing profile's (a test checks it against pure pursuit on the exact state);
//! above that it is a local search, so its limit is a lower bound on the true one. Two checks
//! say the bound is tight: more starts (`--starts` style restarts in the test) do not raise it by
//! more than the tolerance, and the failing speed just above it fails from every start with
//! the cones' residual stuck at a positive minimum.
use std::sync::Arc;

use catmodel::control::pure_pursuit::{CarState, PurePursuitConfig, PurePursuitState};
use catmodel::model::kinematic::Pose;
use catmodel::vehicle::VehicleParams;
use nalgebra::{DMatrix, DVector};

use super::core_path;
use super::metrics::Scorer;
use super::scenario::{self, Course, Kind};
use crate::sim::config::VehicleConfig;
use crate::sim::plant::PlantState;
use crate::sim::scenario::Command;
use crate::sim::{Rig, SimOptions, PLANT_STEP_S};

/// Steering knots are this far apart, s: 12 ticks of 20 ms (the command is set every tick).
pub const KNOT_S: f64 = 0.24;
/// Ticks per knot.
const TICKS_PER_KNOT: usize = 12;
/// The command period, s.
const TICK_S: f64 = 0.02;
/// Every trial starts with the rear axle this far before the track (the body's front 6 m before
/// the first cones), m.
pub const START_BEFORE_TRACK_M: f64 = 10.0;
/// Cone residuals push clearances above this, m.
pub const MARGIN_M: f64 = 0.03;
/// Weight of the knot-difference residuals (per % of command change).
const SMOOTHNESS_WEIGHT: f64 = 0.002;
/// Forward-difference step of the Jacobian, % of steering command.
const JACOBIAN_STEP_PCT: f64 = 0.5;
/// Levenberg-Marquardt iterations per start.
const ITERATIONS: usize = 30;
/// Previews of the curvature feed-forward starts, s.
pub const PREVIEWS_S: [f64; 3] = [0.1, 0.3, 0.5];
/// Continuation step over speed, m/s.
pub const SCAN_STEP_MPS: f64 = 0.25;
/// The search ends after this many consecutive speeds that no start passes.
pub const FAILURES_TO_STOP: usize = 2;
/// Variants of the previous speed's profile tried as starts: time shift (s) and gain.
pub const VARIANTS: [(f64, f64); 7] = [
    (0.0, 1.0),
    (0.1, 1.0),
    (0.1, 1.1),
    (0.0, 1.1),
    (0.2, 1.1),
    (-0.1, 1.1),
    (0.2, 1.0),
];

/// The outcome of one trial.
#[derive(Debug, Clone, PartialEq)]
pub struct Trial {
    /// Smallest clearance of the body to each cone, m.
    pub cone_clearance_m: Vec<f64>,
    /// How far outside each gate the rear axle crossed it, m (`None`: not reached).
    pub gate_miss_m: Vec<Option<f64>>,
    /// The car turned more than 90 degrees off the course.
    pub spun: bool,
}

impl Trial {
    /// No cone touched, every gate passed through, no spin.
    pub fn clean(&self) -> bool {
        !self.spun
            && self.cone_clearance_m.iter().all(|d| *d > 0.0)
            && self.gate_miss_m.iter().all(|m| *m == Some(0.0))
    }

    /// The smallest clearance to any cone, m.
    pub fn min_clearance_m(&self) -> f64 {
        self.cone_clearance_m
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min)
    }
}

/// The state of a trial at the start of a tick.
#[derive(Clone)]
struct Checkpoint {
    rig: Rig,
    scorer: Scorer,
    tick: usize,
}

/// The track at one speed, and the car on it just before the first cones.
#[derive(Clone)]
pub struct TrackAtSpeed {
    vehicle: Arc<VehicleConfig>,
    course: Arc<Course>,
    speed_mps: f64,
    start: Rig,
    /// Rear-axle course `x` where a trial ends: the rear bumper past the last cone.
    end_x_m: f64,
    knots: usize,
}

/// The course frame's `x` and heading offset of the rear axle of `rig`.
fn rear_axle(rig: &Rig) -> (f64, f64, f64) {
    let s = rig.state();
    let b = rig.cg_to_rear_m();
    (
        s.x_m - b * s.heading_rad.sin(),
        s.y_m - b * s.heading_rad.cos(),
        s.heading_rad,
    )
}

impl TrackAtSpeed {
    /// Brings the car (no sensors) to `speed_mps` on the run-up of the double lane change.
    pub fn new(vehicle: &VehicleConfig, speed_mps: f64) -> Self {
        let course = scenario::course(Kind::DoubleLaneChange, &vehicle.body, speed_mps);
        let start_point = &course.path[0];
        let heading = course.frame.heading_rad;
        let b = vehicle.chassis.cg_to_rear_m;
        let initial = PlantState {
            x_m: start_point.east_m + b * heading.sin(),
            y_m: start_point.north_m + b * heading.cos(),
            heading_rad: heading,
            ..PlantState::default()
        };
        let options = SimOptions {
            vary_commands: false,
            ..SimOptions::default()
        };
        let mut rig = Rig::new(vehicle, &options, initial, 0.0).without_sensors();
        let command = Command {
            speed_mps,
            steer_pct: 0.0,
        };
        loop {
            let (x, y, _) = rear_axle(&rig);
            if course.frame.to_course(x, y).0 >= -START_BEFORE_TRACK_M {
                break;
            }
            rig.step(&command);
        }
        let last_lane = course.lanes.last().map_or(0.0, |l| l.x_end_m);
        let end_x_m = last_lane + vehicle.body.rear_overhang_m + scenario::CONE_RADIUS_M;
        let duration = (end_x_m + START_BEFORE_TRACK_M) / speed_mps + 1.0;
        Self {
            vehicle: Arc::new(vehicle.clone()),
            course: Arc::new(course),
            speed_mps,
            start: rig,
            end_x_m,
            knots: (duration / KNOT_S).ceil() as usize + 1,
        }
    }

    /// Number of knots of a profile.
    pub fn knots(&self) -> usize {
        self.knots
    }

    /// The truth speed at the start of the trials, m/s.
    pub fn entry_speed_mps(&self) -> f64 {
        self.start.state().vx_mps
    }

    /// Runs the steering command profile `knots_pct` from the start state.
    pub fn trial(&self, knots_pct: &[f64]) -> Trial {
        self.run_from(&self.begin(), |t, _| knot_value(knots_pct, t), None)
    }

    /// The state at the start of the trials.
    fn begin(&self) -> Checkpoint {
        Checkpoint {
            rig: self.start.clone(),
            scorer: Scorer::new(&self.vehicle.body, &self.course),
            tick: 0,
        }
    }

    /// Runs from `from` with a steering law `command(t, rig)` evaluated every tick (20 ms) and
    /// held in between; with `checkpoints`, keeps the state at every knot's first tick.
    fn run_from(
        &self,
        from: &Checkpoint,
        mut command: impl FnMut(f64, &Rig) -> f64,
        mut checkpoints: Option<&mut Vec<Checkpoint>>,
    ) -> Trial {
        let mut now = from.clone();
        let per_tick = (TICK_S / PLANT_STEP_S).round() as u64;
        let last_tick = (self.knots + 4) * TICKS_PER_KNOT;
        let mut spun = false;
        'ticks: while now.tick < last_tick {
            if let Some(c) = checkpoints.as_deref_mut() {
                if now.tick.is_multiple_of(TICKS_PER_KNOT) {
                    c.push(now.clone());
                }
            }
            let steer = command(now.tick as f64 * TICK_S, &now.rig);
            for _ in 0..per_tick {
                now.rig.step(&Command {
                    speed_mps: self.speed_mps,
                    steer_pct: steer,
                });
                let (x, y, heading) = rear_axle(&now.rig);
                now.scorer.observe(x, y, heading);
                let off =
                    (heading - self.course.frame.heading_rad).rem_euclid(std::f64::consts::TAU);
                if off > std::f64::consts::FRAC_PI_2 && off < 1.5 * std::f64::consts::PI {
                    spun = true;
                    break 'ticks;
                }
                if self.course.frame.to_course(x, y).0 >= self.end_x_m {
                    break 'ticks;
                }
            }
            now.tick += 1;
        }
        Trial {
            cone_clearance_m: now.scorer.cone_clearances_m().to_vec(),
            gate_miss_m: now.scorer.gate_misses_m().to_vec(),
            spun,
        }
    }

    /// Runs a profile, keeping the state at every knot (for the Jacobian).
    fn trial_with_checkpoints(&self, knots_pct: &[f64]) -> (Trial, Vec<Checkpoint>) {
        let mut checkpoints = Vec::with_capacity(self.knots + 4);
        let trial = self.run_from(
            &self.begin(),
            |t, _| knot_value(knots_pct, t),
            Some(&mut checkpoints),
        );
        (trial, checkpoints)
    }

    /// Runs `knots_pct` and records, every tick, the time (s), the rear axle (east, north,
    /// heading), the speed (m/s) and the actuator's steering (%): for the figure.
    pub fn record(&self, knots_pct: &[f64]) -> Vec<[f64; 6]> {
        let mut rows = Vec::new();
        self.run_from(
            &self.begin(),
            |t, rig| {
                let (x, y, heading) = rear_axle(rig);
                rows.push([t, x, y, heading, rig.state().vx_mps, rig.steer_pct()]);
                knot_value(knots_pct, t)
            },
            None,
        );
        rows
    }

    /// The course driven.
    pub fn course(&self) -> &Course {
        &self.course
    }

    /// Pure pursuit with `config` on the exact state: the steering it commands at each knot time
    /// (a start for the search), and its own trial.
    pub fn pursuit(&self, config: &PurePursuitConfig) -> (Vec<f64>, Trial) {
        let path = core_path(&self.course);
        let mut state = PurePursuitState::default();
        let mut profile = vec![0.0; self.knots];
        let trial = self.run_from(
            &self.begin(),
            |t, rig| {
                let (x, y, heading) = rear_axle(rig);
                let plant = rig.state();
                let car = CarState {
                    pose: Some(Pose::new(x as f32, y as f32, heading as f32)),
                    speed_mps: plant.vx_mps as f32,
                    rear_side_mps: (plant.vy_mps - rig.cg_to_rear_m() * plant.yaw_rate_rps) as f32,
                };
                let out = config.process(&mut state, Some(&path), &[], &car);
                let steer = f64::from(out.steer_cmd_pct);
                let k = (t / KNOT_S).round() as usize;
                if (t - k as f64 * KNOT_S).abs() < 0.011 {
                    if let Some(p) = profile.get_mut(k) {
                        *p = steer;
                    }
                }
                steer
            },
            None,
        );
        // Knots after the trial ended hold the last command.
        let last = (0..self.knots)
            .rev()
            .find(|&k| profile[k] != 0.0)
            .unwrap_or(0);
        let hold = profile[last];
        for p in profile.iter_mut().skip(last + 1) {
            *p = hold;
        }
        (profile, trial)
    }

    /// The path's curvature as steering (eq 2 inverted at this speed), `preview_s` ahead.
    pub fn feedforward(&self, vehicle: &VehicleParams, preview_s: f64) -> Vec<f64> {
        let path = core_path(&self.course);
        let (x, y, _) = rear_axle(&self.start);
        let s0 = path
            .project(x as f32, y as f32, None)
            .map_or(0.0, |p| f64::from(p.station_m));
        (0..self.knots)
            .map(|k| {
                let s = s0 + self.speed_mps * (k as f64 * KNOT_S + preview_s);
                let kappa = path
                    .sample(s as f32, 0)
                    .map_or(0.0, |p| f64::from(p.curvature_per_m));
                let v = self.speed_mps;
                let centre = (kappa * f64::from(vehicle.wheelbase_m)).atan()
                    * (1.0 + f64::from(vehicle.understeer_s2_per_m2) * v * v);
                (100.0 * centre / f64::from(vehicle.max_steer_rad)).clamp(-100.0, 100.0)
            })
            .collect()
    }

    /// Residuals of a trial (see the module doc).
    fn residuals(&self, knots_pct: &[f64], trial: &Trial) -> DVector<f64> {
        let cones = trial.cone_clearance_m.len();
        let gates = trial.gate_miss_m.len();
        let mut r = DVector::zeros(cones + gates + 1 + knots_pct.len().saturating_sub(1));
        for (i, d) in trial.cone_clearance_m.iter().enumerate() {
            r[i] = (MARGIN_M - d).max(0.0);
        }
        for (i, m) in trial.gate_miss_m.iter().enumerate() {
            // A gate not reached (a spin ended the trial) counts as missed by 5 m.
            r[cones + i] = m.unwrap_or(5.0);
        }
        r[cones + gates] = if trial.spun { 10.0 } else { 0.0 };
        for (i, w) in knots_pct.windows(2).enumerate() {
            r[cones + gates + 1 + i] = SMOOTHNESS_WEIGHT * (w[1] - w[0]);
        }
        r
    }

    /// Levenberg-Marquardt from `start`; returns the best profile and its trial (clean before
    /// not clean, then the larger clearance, or the lower cost), stopping at the first trial
    /// with every cone [`MARGIN_M`] clear.
    pub fn optimise(&self, start: &[f64]) -> (Vec<f64>, Trial) {
        let n = self.knots;
        let mut x: Vec<f64> = (0..n)
            .map(|k| start.get(k).copied().unwrap_or(0.0))
            .collect();
        let (mut trial, mut checkpoints) = self.trial_with_checkpoints(&x);
        let mut r = self.residuals(&x, &trial);
        let mut cost = r.norm_squared();
        let mut best = (x.clone(), trial.clone(), cost);
        let mut lambda = 1e-2;
        for _ in 0..ITERATIONS {
            if trial.clean() && trial.min_clearance_m() >= MARGIN_M {
                break;
            }
            let jacobian = self.jacobian(&x, &r, &checkpoints);
            let jt = jacobian.transpose();
            let jtj = &jt * &jacobian;
            let g = &jt * &r;
            let mut improved = false;
            for _ in 0..8 {
                let mut a = jtj.clone();
                for i in 0..n {
                    a[(i, i)] += lambda * (jtj[(i, i)] + 1e-6);
                }
                let Some(step) = a.lu().solve(&(-&g)) else {
                    lambda *= 10.0;
                    continue;
                };
                let candidate: Vec<f64> = x
                    .iter()
                    .zip(step.iter())
                    .map(|(xi, di)| (xi + di).clamp(-100.0, 100.0))
                    .collect();
                let (t, cp) = self.trial_with_checkpoints(&candidate);
                let rc = self.residuals(&candidate, &t);
                let c = rc.norm_squared();
                if c < cost {
                    (x, trial, r, cost, checkpoints) = (candidate, t, rc, c, cp);
                    lambda = (lambda / 3.0).max(1e-7);
                    improved = true;
                    break;
                }
                lambda *= 4.0;
            }
            let better = match (trial.clean(), best.1.clean()) {
                (true, false) => true,
                (false, true) => false,
                (true, true) => trial.min_clearance_m() > best.1.min_clearance_m(),
                (false, false) => cost < best.2,
            };
            if better {
                best = (x.clone(), trial.clone(), cost);
            }
            if !improved {
                break;
            }
        }
        (best.0, best.1)
    }

    /// Forward-difference Jacobian of the residuals at `x` (one trial per knot, two threads).
    /// Knot `i` only changes the command after knot `i - 1`: its trial restarts from that
    /// knot's checkpoint of the unperturbed trial (bit-identical to a run from the start).
    fn jacobian(&self, x: &[f64], r: &DVector<f64>, checkpoints: &[Checkpoint]) -> DMatrix<f64> {
        let n = x.len();
        let columns: Vec<DVector<f64>> = std::thread::scope(|scope| {
            let half = n.div_ceil(2);
            let handles: Vec<_> = [0..half, half..n]
                .into_iter()
                .map(|range| {
                    scope.spawn(move || {
                        range
                            .map(|i| {
                                let mut xi = x.to_vec();
                                xi[i] += JACOBIAN_STEP_PCT;
                                let from = i.saturating_sub(1);
                                let t = match checkpoints.get(from) {
                                    Some(c) => self.run_from(c, |t, _| knot_value(&xi, t), None),
                                    // The trial ended before this knot: it cannot matter.
                                    None => self.trial(&xi),
                                };
                                (self.residuals(&xi, &t) - r) / JACOBIAN_STEP_PCT
                            })
                            .collect::<Vec<_>>()
                    })
                })
                .collect();
            handles
                .into_iter()
                .flat_map(|h| h.join().unwrap_or_default())
                .collect()
        });
        DMatrix::from_columns(&columns)
    }
}

/// The command at time `t` of a knot profile (linear between knots, held after the last).
fn knot_value(knots: &[f64], t: f64) -> f64 {
    let f = (t / KNOT_S).max(0.0);
    let i = f.floor() as usize;
    match (knots.get(i), knots.get(i + 1)) {
        (Some(a), Some(b)) => a + (b - a) * (f - i as f64),
        (Some(a), None) => *a,
        _ => knots.last().copied().unwrap_or(0.0),
    }
}

/// The profile `previous` (knots at `from_mps`) stretched for `to_mps`: the same steering at the
/// same place on the track.
pub fn stretch(previous: &[f64], from_mps: f64, to_mps: f64, knots: usize) -> Vec<f64> {
    (0..knots)
        .map(|k| knot_value(previous, k as f64 * KNOT_S * to_mps / from_mps))
        .collect()
}

/// One speed's search result.
#[derive(Debug, Clone, PartialEq)]
pub struct SpeedResult {
    /// Speed command held, m/s.
    pub speed_mps: f64,
    /// Truth speed at the start of the trials, m/s.
    pub entry_speed_mps: f64,
    /// The best profile's smallest cone clearance, m.
    pub min_clearance_m: f64,
    /// Whether some start led to a clean trial.
    pub passable: bool,
    /// The best profile (steering command per knot, %).
    pub profile: Vec<f64>,
    /// Starts tried.
    pub starts_tried: usize,
}

/// `profile` delayed by `shift_s` (a later command) and scaled by `gain`.
fn variant(profile: &[f64], shift_s: f64, gain: f64) -> Vec<f64> {
    (0..profile.len())
        .map(|k| gain * knot_value(profile, (k as f64 * KNOT_S - shift_s).max(0.0)))
        .collect()
}

/// Searches one speed: the previous passing profiles (stretched to this speed, nearest speed
/// first, each in its [`VARIANTS`]), then pure pursuit on the exact state, then the curvature
/// feed-forward at each of [`PREVIEWS_S`]; stops at the first start whose optimum clears every
/// cone by [`MARGIN_M`].
pub fn search_speed(
    vehicle: &VehicleConfig,
    params: &VehicleParams,
    pursuit: &PurePursuitConfig,
    speed_mps: f64,
    previous: &[SpeedResult],
) -> SpeedResult {
    let track = TrackAtSpeed::new(vehicle, speed_mps);
    let n = track.knots();
    let mut starts: Vec<Vec<f64>> = Vec::new();
    for p in previous.iter().rev().filter(|p| p.passable).take(2) {
        let stretched = stretch(&p.profile, p.speed_mps, speed_mps, n);
        starts.extend(VARIANTS.iter().map(|&(s, g)| variant(&stretched, s, g)));
    }
    let (pp_profile, pp_trial) = track.pursuit(pursuit);
    let mut best: Option<(Vec<f64>, Trial)> = pp_trial
        .clean()
        .then(|| (pp_profile.clone(), pp_trial.clone()));
    starts.push(pp_profile);
    for preview in PREVIEWS_S {
        starts.push(track.feedforward(params, preview));
    }
    let mut tried = 0;
    for s in &starts {
        if best
            .as_ref()
            .is_some_and(|(_, t)| t.clean() && t.min_clearance_m() >= MARGIN_M)
        {
            break;
        }
        tried += 1;
        let (x, t) = track.optimise(s);
        let better = match &best {
            None => true,
            Some((_, b)) => {
                (t.clean() && !b.clean())
                    || (t.clean() == b.clean() && t.min_clearance_m() > b.min_clearance_m())
            }
        };
        if better {
            best = Some((x, t));
        }
    }
    let (profile, trial) = best.unwrap_or_else(|| (vec![0.0; n], track.trial(&vec![0.0; n])));
    SpeedResult {
        speed_mps,
        entry_speed_mps: track.entry_speed_mps(),
        min_clearance_m: trial.min_clearance_m(),
        passable: trial.clean(),
        profile,
        starts_tried: tried,
    }
}

/// The limit: continuation from `from_mps` (which should be passable) up in
/// [`SCAN_STEP_MPS`] steps, each speed warm-started from the passing profiles below it, until
/// [`FAILURES_TO_STOP`] consecutive speeds fail (or `to_mps`); the highest passable speed, and
/// every speed searched in order.
pub fn limit(
    vehicle: &VehicleConfig,
    params: &VehicleParams,
    pursuit: &PurePursuitConfig,
    from_mps: f64,
    to_mps: f64,
) -> (Option<SpeedResult>, Vec<SpeedResult>) {
    let mut log: Vec<SpeedResult> = Vec::new();
    let mut failures = 0;
    let mut v = from_mps;
    while v <= to_mps + 1e-9 && failures < FAILURES_TO_STOP {
        let r = search_speed(vehicle, params, pursuit, v, &log);
        failures = if r.passable { 0 } else { failures + 1 };
        log.push(r);
        v += SCAN_STEP_MPS;
    }
    let best = log.iter().rev().find(|r| r.passable).cloned();
    (best, log)
}
