//! Instructions per solve of the model-predictive controller (`catmodel::control::mpc`) on QEMU
//! `-M netduinoplus2` with the shipped profile, `firmware`; run by `cargo xtask bench-target`
//! (docs/mpc.md, "Cost on the target").
//!
//! Method as `catmodel-qemu-bench`: TIM2 counts one per executed instruction under
//! `-icount shift=0`; each solve is timed between two reads of the counter, the cost of an empty
//! timed call subtracted. The controller is the one of the baked car (`MpcConfig::for_node`
//! on the firmware's own configuration, default tuning).
//!
//! Scenarios are small closed loops on the MCU, so that warm starts are what they are in
//! operation: the car is the controller's own dynamic model with the steering actuator's rate
//! limit and a 50 ms lag, and eq 5 as its speed loop:
//! - `mpc_dlc`: ISO 3888-2 double lane change at 13.5 m/s (tracking, corridor constraints);
//! - `mpc_obstacle`: straight road, one obstacle passed at 10 m/s (avoiding);
//! - `mpc_blocked`: an obstacle that leaves no room (status 3, the fallback);
//! - `mpc_worst_dynamic`, `mpc_worst_kinematic`, `mpc_worst_standing` (the obstacles stand,
//!   in a row passed on alternate sides): four large obstacles beside the road so that
//!   every stage has all its rows, a corridor narrower than the car so that every corridor row
//!   gives way from the start, the car 1.5 m off its path so that the tracking targets taper,
//!   and no early exit: the worst case.
//!
//! Then the parts of a solve (`mpc_part_*`: problem build with every row, Riccati
//! factorisation, one ADMM iteration with and without the residual check, the speed plan),
//! from which docs/mpc.md sums the bound; the stack depth of a worst-case solve; and, with the
//! feature `tinympc`, TinyMPC (`tinympc-rs` 0.2) on the same lateral model at one speed.
//!
//! Output (semihosting stderr): `bench KEY NAME CALLS MIN MEDIAN MAX WHAT` lines as the other
//! bench, `mpc-info` lines, then `bench-overhead N` and `bench-done`.
#![no_std]
#![no_main]

use core::hint::black_box;
use core::ptr::addr_of_mut;

use catmodel::control::mpc::admm::{AdmmSettings, Problem, Workspace};
use catmodel::control::mpc::lateral::{self, InflatedObstacle, LateralSetup, Linearisation};
use catmodel::control::mpc::longitudinal::{SpeedStart, SpeedState};
use catmodel::control::mpc::{
    CarState, FallbackReason, MpcConfig, MpcInput, MpcOutput, MpcState, MpcTuning, Obstacle,
    ObstacleSide, ObstacleVelocity, ReferencePoint, Sample, SidePoint, StageClock, DEFAULT_TUNING,
    MAX_OBSTACLES, NX, PLAN_STEPS, ROWS, STEPS, STEP_S,
};
use catmodel::math;
use catmodel::model::dynamic::{DynamicParams, LateralState};
use catmodel::model::hybrid::Mode;
use catmodel::model::kinematic::Pose;
use catmodel::model::{SsBlock, SsBlockState};
use catmodel::node::NodeConfig;
use catmodel::vehicle::Body;
use catmodel_firmware::platform::qemu::icount;
use cortex_m_rt::entry;
use defmt_semihosting as _;
use nalgebra::SVector;

/// Instructions of an empty timed call; subtracted from every measurement.
static mut OVERHEAD: u32 = 0;

/// Runs `f` between two reads of the instruction counter: returns its result and the
/// instructions it took (minus the timing overhead).
#[inline(always)]
fn timed<R>(f: impl FnOnce() -> R) -> (R, u32) {
    // Safety: written once in `main` before any measurement; single-threaded, no interrupts.
    icount::timed(unsafe { OVERHEAD }, f)
}

fn fail(message: &str) -> ! {
    semihosting::eprintln!("catmodel-qemu-mpc-bench: error: {message}");
    semihosting::process::exit(3)
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    semihosting::eprintln!("catmodel-qemu-mpc-bench: panic: {info}");
    semihosting::process::exit(101)
}

/// Solves kept per scenario.
const CAP: usize = 400;

/// Instructions, iterations and factorisations of one scenario's solves.
struct Stats {
    instructions: [u32; CAP],
    iterations: [u16; CAP],
    factorisations: [u16; CAP],
    len: usize,
}

impl Stats {
    const EMPTY: Self = Self {
        instructions: [0; CAP],
        iterations: [0; CAP],
        factorisations: [0; CAP],
        len: 0,
    };

    fn push(&mut self, instructions: u32, out: &MpcOutput) {
        if let (Some(i), Some(n), Some(f)) = (
            self.instructions.get_mut(self.len),
            self.iterations.get_mut(self.len),
            self.factorisations.get_mut(self.len),
        ) {
            *i = instructions;
            *n = out.iterations;
            *f = out.factorisations;
            self.len += 1;
        }
    }

    fn report(&mut self, key: &str, name: &str, what: &str) {
        let n = self.len;
        let mid = n.div_ceil(2).saturating_sub(1);
        let instr = self.instructions.get_mut(..n).unwrap_or(&mut []);
        instr.sort_unstable();
        let (min, med, max) = (
            instr.first().copied().unwrap_or(0),
            instr.get(mid).copied().unwrap_or(0),
            instr.last().copied().unwrap_or(0),
        );
        let iters = self.iterations.get_mut(..n).unwrap_or(&mut []);
        iters.sort_unstable();
        let (imin, imed, imax) = (
            iters.first().copied().unwrap_or(0),
            iters.get(mid).copied().unwrap_or(0),
            iters.last().copied().unwrap_or(0),
        );
        let fmax = self
            .factorisations
            .get(..n)
            .and_then(|f| f.iter().max())
            .copied()
            .unwrap_or(0);
        semihosting::eprintln!(
            "bench\t{key}\t{name}\t{n}\t{min}\t{med}\t{max}\t{what}; ADMM iterations {imin} / {imed} / {imax}, factorisations at most {fmax}"
        );
        *self = Self::EMPTY;
    }
}

/// The big state lives in .bss: the stack region is 16 KiB (memory.x).
struct Statics {
    stats: Stats,
    state: MpcState,
    problem: Problem<NX, STEPS, ROWS>,
    workspace: Workspace<NX, STEPS, ROWS>,
}

fn statics() -> &'static mut Statics {
    static mut STATICS: Statics = Statics {
        stats: Stats::EMPTY,
        state: MpcState::new(),
        problem: Problem::zeroed(),
        workspace: Workspace::new(),
    };
    // SAFETY: called once, from `main`; single-threaded.
    unsafe { &mut *addr_of_mut!(STATICS) }
}

/// A road along north whose centre line is `p(s)` metres to the left at station `s`.
trait Road {
    /// Offset to the left, its first and second derivative.
    fn lateral(&self, s: f32) -> (f32, f32, f32);
    /// Corridor (left, right) at `s`.
    fn corridor(&self, s: f32) -> (f32, f32);

    fn pose(&self, s: f32) -> Pose {
        let (p, dp, _) = self.lateral(s);
        Pose::new(-p, s, math::atan2(-dp, 1.0))
    }
    fn curvature(&self, s: f32) -> f32 {
        let (_, dp, ddp) = self.lateral(s);
        let n = 1.0 + dp * dp;
        -ddp / (n * math::sqrt(n))
    }
    /// Where the corridor binds the body's sides between the axle at `axle` and the end at
    /// `end` (as the node's `Path::narrowest_corridor`: the narrowest, ties to the farther
    /// station), every 0.25 m: the left and right side points.
    fn side_points(&self, axle: f32, end: f32) -> (SidePoint, SidePoint) {
        let step = if end >= axle { 0.25 } else { -0.25 };
        let n = ((end - axle) / step) as usize;
        let (mut left, mut right) = ((f32::INFINITY, axle), (f32::INFINITY, axle));
        for i in 0..=n + 1 {
            let s = if i > n { end } else { axle + step * i as f32 };
            let (l, r) = self.corridor(s);
            for (best, w) in [(&mut left, l), (&mut right, r)] {
                if w <= best.0 + 0.01 {
                    best.1 = s;
                }
                best.0 = best.0.min(w);
            }
        }
        let widths = (left.0, right.0);
        let point = |station: f32| SidePoint {
            sample: self.sample(station, widths),
            ahead_m: station - axle,
        };
        (point(left.1), point(right.1))
    }
    fn sample(&self, s: f32, c: (f32, f32)) -> Sample {
        Sample {
            pose: self.pose(s),
            left_m: c.0,
            right_m: c.1,
        }
    }
    /// The controller's reference from station `s0` at the planned speeds, as the glue would
    /// sample it (stations by the trapezoidal rule, corridors at the body's ends).
    fn reference(
        &self,
        body: &Body,
        s0: f32,
        speeds: &[f32; PLAN_STEPS + 1],
        target: f32,
    ) -> [ReferencePoint; STEPS + 1] {
        let front = body.length_m - body.rear_overhang_m;
        let rear = body.rear_overhang_m;
        let mut s = s0;
        let mut prev = speeds.first().copied().unwrap_or(0.0);
        let mut it = speeds.iter();
        core::array::from_fn(|k| {
            let v = it.next().copied().unwrap_or(prev);
            if k > 0 {
                s += 0.5 * (prev + v) * STEP_S;
            }
            prev = v;
            let (front_left, front_right) = self.side_points(s, s + front);
            let (rear_left, rear_right) = self.side_points(s, s - rear);
            ReferencePoint {
                at: self.sample(s, self.corridor(s)),
                curvature_per_m: self.curvature(s),
                speed_mps: target,
                front_left,
                front_right,
                rear_left,
                rear_right,
            }
        })
    }
}

/// ISO 3888-2 for a car of width b (lengths 12, 13.5, 11, 12.5, 12 m; widths 1.1 b + 0.25,
/// b + 1, 1.3 b + 0.25), lane change to the left after `lead` m.
struct DoubleLaneChange {
    s2: f32,
    s3: f32,
    s4: f32,
    s5: f32,
    centre3: f32,
    half_w1: f32,
    half_w5: f32,
    lane3_left: f32,
    lane3_right: f32,
}

impl DoubleLaneChange {
    fn new(b: f32, lead: f32) -> Self {
        let w1 = 1.1 * b + 0.25;
        let w3 = b + 1.0;
        let w5 = 1.3 * b + 0.25;
        let s2 = lead + 12.0;
        let s3 = s2 + 13.5;
        let s4 = s3 + 11.0;
        let lane3_right = w1 / 2.0 + 1.0;
        Self {
            s2,
            s3,
            s4,
            s5: s4 + 12.5,
            centre3: lane3_right + 0.5 * w3,
            half_w1: w1 / 2.0,
            half_w5: w5 / 2.0,
            lane3_left: lane3_right + w3,
            lane3_right,
        }
    }

    /// A cosine blend from 0 to 1 over [a, b]: value and two derivatives.
    fn blend(a: f32, b: f32, s: f32) -> (f32, f32, f32) {
        let l = b - a;
        let t = (s - a) / l;
        if t <= 0.0 {
            return (0.0, 0.0, 0.0);
        }
        if t >= 1.0 {
            return (1.0, 0.0, 0.0);
        }
        let w = core::f32::consts::PI / l;
        let (sn, cs) = math::sin_cos(core::f32::consts::PI * t);
        (0.5 - 0.5 * cs, 0.5 * w * sn, 0.5 * w * w * cs)
    }
}

impl Road for DoubleLaneChange {
    fn lateral(&self, s: f32) -> (f32, f32, f32) {
        let c = self.centre3;
        if s < self.s3 {
            let (b, db, ddb) = Self::blend(self.s2, self.s3, s);
            (c * b, c * db, c * ddb)
        } else {
            let (b, db, ddb) = Self::blend(self.s4, self.s5, s);
            (c * (1.0 - b), -c * db, -c * ddb)
        }
    }
    fn corridor(&self, s: f32) -> (f32, f32) {
        let (p, _, _) = self.lateral(s);
        if s < self.s2 {
            (self.half_w1, self.half_w1)
        } else if s < self.s3 {
            (self.lane3_left - p, p + self.half_w1)
        } else if s < self.s4 {
            (self.lane3_left - p, p - self.lane3_right)
        } else if s < self.s5 {
            (self.lane3_left - p, p + self.half_w5)
        } else {
            (self.half_w5, self.half_w5)
        }
    }
}

struct Straight {
    half_width: f32,
}

impl Road for Straight {
    fn lateral(&self, _s: f32) -> (f32, f32, f32) {
        (0.0, 0.0, 0.0)
    }
    fn corridor(&self, _s: f32) -> (f32, f32) {
        (self.half_width, self.half_width)
    }
}

/// The MCU's stand-in for the car: the controller's dynamic model, the steering actuator's
/// rate limit and a 50 ms lag, eq 5 as the speed loop.
struct Car {
    pose: Pose,
    v: f32,
    lat: LateralState,
    steer: f32,
    steer_limited: f32,
    speed_model_state: SsBlockState<2>,
    plant_speed_state: SsBlockState<2>,
    last_cmd: f32,
    planned: [f32; PLAN_STEPS + 1],
}

struct Bench<'a> {
    node: &'a NodeConfig,
    mpc: &'a MpcConfig,
    dynamics: DynamicParams,
    rate_rad_per_s: f32,
}

impl Bench<'_> {
    fn car(&self, pose: Pose, v: f32) -> Car {
        let eq5 = &self.node.velocity;
        let st = eq5
            .steady_state_for_output(v)
            .unwrap_or_else(|_| eq5.zero_state());
        Car {
            pose,
            v,
            lat: LateralState::default(),
            steer: 0.0,
            steer_limited: 0.0,
            speed_model_state: st,
            plant_speed_state: st,
            last_cmd: v / eq5.dc_gain().unwrap_or(1.0),
            planned: [v; PLAN_STEPS + 1],
        }
    }

    fn input<'b>(
        &self,
        car: &'b Car,
        reference: &'b [ReferencePoint; STEPS + 1],
        obstacles: &'b [Option<Obstacle>; MAX_OBSTACLES],
    ) -> MpcInput<'b> {
        let mut peek = car.speed_model_state;
        let modelled = self.node.velocity.step(&mut peek, 0.0);
        MpcInput {
            reference,
            obstacles,
            car: CarState {
                pose: car.pose,
                speed_mps: car.v,
                lateral: car.lat,
                steer_rad: car.steer,
                mode: if car.v > 5.0 {
                    Mode::Dynamic
                } else {
                    Mode::Kinematic
                },
                speed_model: &car.speed_model_state,
                speed_bias_mps: car.v - modelled,
                last_speed_cmd_mps: car.last_cmd,
            },
            position_uncertainty_m: 0.1,
            // The rule's weight changes no work of the solve.
            path_max_curvature_per_m: 0.0,
            // The stand-in car drives on: no path end within its horizon.
            to_end_m: f32::INFINITY,
            in_held_turn: false,
            slow_ahead: None,
        }
    }

    /// One timed solve and 20 ms of the stand-in car.
    fn tick(
        &self,
        mpc: &MpcConfig,
        road: &dyn Road,
        car: &mut Car,
        obstacles: &[Option<Obstacle>; MAX_OBSTACLES],
        target: f32,
        st: &mut Statics,
    ) -> MpcOutput {
        // Station: one Newton step of the projection from the north coordinate.
        let p = road.pose(car.pose.y_m);
        let s = car.pose.y_m
            + (car.pose.x_m - p.x_m) * p.sin_heading
            + (car.pose.y_m - p.y_m) * p.cos_heading;
        let reference = road.reference(&self.node.body, s, &car.planned, target);
        let input = self.input(car, &reference, obstacles);
        let (out, n) = timed(|| mpc.solve(&mut st.state, black_box(&input)));
        st.stats.push(n, &out);
        for (p, pt) in car.planned.iter_mut().zip(&out.plan) {
            *p = pt.speed_mps;
        }
        let cmd = out.steer_cmd_pct / 100.0 * self.node.vehicle.max_steer_rad;
        let step = self.rate_rad_per_s * 0.02;
        car.steer_limited += (cmd - car.steer_limited).clamp(-step, step);
        // 50 ms lag at 20 ms: 1 - e^(-0.4).
        car.steer += 0.33 * (car.steer_limited - car.steer);
        let before = car.lat;
        self.dynamics
            .step(&mut car.lat, car.v.max(1.0), car.steer, 0.02);
        let r = 0.5 * (before.yaw_rate_rps + car.lat.yaw_rate_rps);
        let vy = 0.5 * (before.vy_mps + car.lat.vy_mps) - self.dynamics.cg_to_rear_m * r;
        car.pose.advance(car.v, vy, r * 0.02, 0.02);
        let eq5: &SsBlock<2> = &self.node.velocity;
        car.v = eq5
            .step(&mut car.plant_speed_state, out.speed_cmd_mps)
            .max(0.0);
        eq5.step(&mut car.speed_model_state, out.speed_cmd_mps);
        car.last_cmd = out.speed_cmd_mps;
        out
    }
}

/// An obstacle on the straight road, placed along it as the glue would.
fn on_straight(east: f32, north: f32, r: f32, car: &Car, half_width: f32) -> Obstacle {
    Obstacle {
        east_m: east,
        north_m: north,
        radius_m: r,
        ahead_m: north - car.pose.y_m,
        path_offset_m: east,
        left_m: half_width,
        right_m: half_width,
        velocity: ObstacleVelocity::ZERO,
    }
}

/// Four large obstacles beside the road: every stage has every row. They move (oncoming, and
/// drifting towards the road below the crossing speed): a moving obstacle's row is the
/// dearer, found over the segment between where it would have braked and where it goes on
/// (`lateral::obstacle_row`), which here reaches past both ends of the body.
fn worst_obstacles(car: &Car) -> [Option<Obstacle>; MAX_OBSTACLES] {
    let y0 = car.pose.y_m;
    core::array::from_fn(|i| {
        let side = if i % 2 == 0 { 1.0 } else { -1.0 };
        let mut o = on_straight(side * 35.0, y0 + 8.0 * i as f32, 30.0, car, 25.0);
        o.velocity = ObstacleVelocity {
            east_mps: -side * 0.2,
            north_mps: -12.0,
            along_mps: -12.0,
            right_mps: -side * 0.2,
        };
        Some(o)
    })
}

/// Four large standing obstacles beside the road, left and right in turn, 12 m apart: every
/// stage has every row, and each passed on the other side from the one before asks the car to
/// shift across between them by 1 m, a shift made only slower than it goes
/// (`MpcConfig::decide_sides`, docs/mpc.md "Obstacles in a row"): every pair's check and
/// every slowing's cap of the speed targets run, and the plans, which cannot keep the body out
/// of the circles, end in the fallback's braking roll-out after the whole solve. Standing,
/// their rows are the cheaper. A car longer than about 10 m has no run between them: the far
/// ones leave no passage and are not placed (spaced by the body's length, the circles leave
/// some stages' rows free: 402 000 at most on the random files tried, against 421 000-430 000).
fn standing_worst_obstacles(car: &Car) -> [Option<Obstacle>; MAX_OBSTACLES] {
    let y0 = car.pose.y_m;
    core::array::from_fn(|i| {
        let side = if i % 2 == 0 { 1.0 } else { -1.0 };
        Some(on_straight(
            side * 31.0,
            y0 + 8.0 + 12.0 * i as f32,
            30.0,
            car,
            25.0,
        ))
    })
}

#[inline(never)]
fn run_scenarios(b: &Bench, st: &mut Statics) {
    let none = [None; MAX_OBSTACLES];
    // Double lane change.
    let road = DoubleLaneChange::new(b.node.body.width_m, 40.0);
    let v = 13.5;
    let mut car = b.car(road.pose(0.0), v);
    st.state.reset();
    for _ in 0..400 {
        b.tick(b.mpc, &road, &mut car, &none, v, st);
        if car.pose.y_m > 95.0 {
            break;
        }
    }
    st.stats.report(
        "mpc_dlc",
        "MPC solve, double lane change",
        "ISO 3888-2 at 13.5 m/s, tick by tick",
    );
    // One obstacle to pass.
    let road = Straight { half_width: 3.5 };
    let v = 10.0;
    let mut car = b.car(road.pose(0.0), v);
    st.state.reset();
    let mut obstacles = none;
    for _ in 0..350 {
        obstacles[0] = Some(on_straight(0.3, 40.0, 0.5, &car, road.half_width));
        b.tick(b.mpc, &road, &mut car, &obstacles, v, st);
    }
    st.stats.report(
        "mpc_obstacle",
        "MPC solve, obstacle passed",
        "straight road, obstacle 0.3 m right of the centre, 10 m/s",
    );
    // No room: the stop short of it, then the fallback at rest.
    let road = Straight { half_width: 1.5 };
    let v = 8.0;
    let mut car = b.car(road.pose(0.0), v);
    st.state.reset();
    let mut obstacles = none;
    for _ in 0..200 {
        obstacles[1] = Some(on_straight(0.0, 30.0, 1.0, &car, road.half_width));
        b.tick(b.mpc, &road, &mut car, &obstacles, v, st);
    }
    st.stats.report(
        "mpc_blocked",
        "MPC solve, no room (stop)",
        "obstacle across a 3 m corridor, 8 m/s: stopped short of it by the speed plan, status 3 at rest",
    );
}

/// Every row active, no early exit: the worst case, in both modes.
#[inline(never)]
fn run_worst(b: &Bench, worst: &MpcConfig, st: &mut Statics) {
    // A corridor narrower than the car: the body starts outside it on both sides, so the
    // corridor's give (`lateral::relax_corridor`) runs on every corridor row of every stage.
    // The node refuses such a path from the planner (`PathError::Corridor`); the solver is
    // given it here directly, a case beyond the worst the node can meet.
    let road = Straight { half_width: 0.25 };
    type Placing = fn(&Car) -> [Option<Obstacle>; MAX_OBSTACLES];
    let cases: [(f32, &str, &str, Placing); 3] = [
        (
            15.0,
            "mpc_worst_dynamic",
            "MPC solve, worst case (dynamic)",
            worst_obstacles,
        ),
        (
            4.0,
            "mpc_worst_kinematic",
            "MPC solve, worst case (kinematic)",
            worst_obstacles,
        ),
        (
            4.0,
            "mpc_worst_standing",
            "MPC solve, worst case (kinematic, standing obstacles in a row)",
            standing_worst_obstacles,
        ),
    ];
    for (v, key, name, placing) in cases {
        // 1.5 m off the path: beyond `return_from_m`, so the tracking cost's targets taper too
        // (`lateral::taper_reference`).
        let mut car = b.car(Pose::new(1.5, 0.0, 0.05), v);
        st.state.reset();
        for _ in 0..100 {
            let obstacles = placing(&car);
            b.tick(worst, &road, &mut car, &obstacles, v, st);
        }
        st.stats.report(
            key,
            name,
            "every row of every stage active, every iteration run",
        );
    }
}

/// A solve's end when it runs every iteration and then falls back (`mpc_part_fallback_end`):
/// the plans did not clear an obstacle (`FallbackReason::ObstacleNotCleared`: the steering
/// ramped to the lane's, the braking speed plan, its roll-out), or their states were not
/// finite (`FallbackReason::Solver`: the workspace forgotten, the last plan's steering, the
/// braking speed plan, its roll-out), against the end a solve takes otherwise (the roll-out of
/// its plan). The difference, the dearer fallback's, is added to the worst-case solve
/// (`xtask/src/bound.rs`): the worst-case rows end either way, and a whole solve on a long car
/// that ends in the fallback is reached by no row (docs/findings.md). Both ends roll the same
/// model out, so the difference is the same in either lateral mode: timed at one speed.
#[inline(never)]
fn run_fallback_end(b: &Bench, worst: &MpcConfig, st: &mut Statics) {
    let road = Straight { half_width: 0.25 };
    let v = 15.0f32;
    let mut car = b.car(Pose::new(1.5, 0.0, 0.05), v);
    st.state.reset();
    // A few solves first, so that the last plan the Solver fallback reads is a plan.
    for _ in 0..5 {
        let obstacles = worst_obstacles(&car);
        b.tick(worst, &road, &mut car, &obstacles, v, st);
    }
    let obstacles = worst_obstacles(&car);
    let reference = road.reference(&b.node.body, 0.0, &car.planned, v);
    let input = b.input(&car, &reference, &obstacles);
    let start = SpeedStart {
        model_state: &car.speed_model_state,
        bias_mps: 0.0,
        planning_bias_mps: 0.0,
        speed_mps: car.v,
        last_command_mps: car.last_cmd,
        in_held_turn: false,
        slow_ahead: None,
    };
    let steer = [car.steer; STEPS + 1];
    let (_, normal) = timed(|| worst.rollout(black_box(&input), &steer, &car.planned));
    // The Solver fallback first: it reads the last plan, which the other one forgets.
    let ws = &mut st.workspace;
    let (_, forget) = timed(|| ws.forget());
    let (_, solver) = timed(|| {
        worst.fallback(
            &mut st.state,
            black_box(&input),
            &start,
            FallbackReason::Solver,
        )
    });
    let (_, not_cleared) = timed(|| {
        worst.fallback(
            &mut st.state,
            black_box(&input),
            &start,
            FallbackReason::ObstacleNotCleared,
        )
    });
    let extra = not_cleared
        .max(solver.saturating_add(forget))
        .saturating_sub(normal);
    semihosting::eprintln!(
        "bench\tmpc_part_fallback_end\tMPC part: a solve's end in the fallback\t1\t{extra}\t{extra}\t{extra}\tthe dearer fallback after a whole solve, less the roll-out of a plan"
    );
}

/// The parts of a worst-case solve (every row active), each timed alone.
#[inline(never)]
fn run_parts(b: &Bench, st: &mut Statics) {
    let road = Straight { half_width: 25.0 };
    let v = 15.0f32;
    let car = b.car(Pose::new(0.0, 0.0, 0.0), v);
    let reference = road.reference(&b.node.body, 0.0, &[v; PLAN_STEPS + 1], v);
    let speeds = [v; STEPS + 1];
    let obstacles: [Option<(InflatedObstacle, ObstacleSide)>; MAX_OBSTACLES] =
        core::array::from_fn(|i| {
            worst_obstacles(&car).get(i).copied().flatten().map(|o| {
                (
                    InflatedObstacle::new(&o, o.radius_m + 0.7),
                    if o.east_m > 0.0 {
                        ObstacleSide::Left
                    } else {
                        ObstacleSide::Right
                    },
                )
            })
        });
    let setup = LateralSetup {
        vehicle: &b.node.vehicle,
        dynamics: Some(&b.dynamics),
        body: &b.node.body,
        weights: &DEFAULT_TUNING.weights,
        mode: Mode::Dynamic,
        speeds_mps: &speeds,
        max_steer_rad: b.node.vehicle.max_steer_rad,
        max_steer_rate_rad_per_s: b.rate_rad_per_s,
        // The bundled car's; a slower car's clock costs the same (the same loops, each stage's
        // length one of two values).
        stage: &StageClock::UNIFORM,
    };
    let lin = Linearisation {
        e_psi: [0.02; STEPS + 1],
        delta: [0.01; STEPS + 1],
    };
    let p = &mut st.problem;
    let (built, build) =
        timed(|| lateral::build(p, &setup, &reference, &lin, &obstacles, (20.0, 0.6)));
    if built.is_err() {
        fail("the worst-case problem does not build");
    }
    let active = p
        .stages
        .iter()
        .flat_map(|s| s.rows.iter())
        .filter(|r| r.active)
        .count();
    let ws = &mut st.workspace;
    ws.cold_start(p);
    let (_, factor) = timed(|| ws.factor(p));
    let x0 = SVector::<f32, NX>::from([0.3, 0.02, 0.05, 0.01, 0.02]);
    let one = |check: bool| AdmmSettings {
        max_iterations: 1,
        primal_tolerance: -1.0,
        dual_tolerance: -1.0,
        relaxation: DEFAULT_TUNING.admm.relaxation,
        // With one iteration, it is the last and checks; a check cadence beyond it does not.
        check_every: if check { 1 } else { 2 },
        rho_update_every: 0,
    };
    let (_, checked) = timed(|| ws.iterate(p, &x0, &one(true)));
    let two = AdmmSettings {
        max_iterations: 2,
        ..one(false)
    };
    // Two iterations, of which only the last checks: the unchecked one is the difference.
    let (_, both) = timed(|| ws.iterate(p, &x0, &two));
    let unchecked = both.saturating_sub(checked);
    let eq5_state = car.speed_model_state;
    let start = SpeedStart {
        model_state: &eq5_state,
        bias_mps: 0.0,
        planning_bias_mps: 0.0,
        speed_mps: v,
        last_command_mps: car.last_cmd,
        in_held_turn: false,
        slow_ahead: None,
    };
    let mut speed_state = SpeedState::new();
    let (_, speed) = timed(|| {
        b.mpc.speed_planner().plan(
            &mut speed_state,
            &start,
            &[v + 2.0; PLAN_STEPS + 1],
            f32::INFINITY,
        )
    });
    for (key, name, n, what) in [
        (
            "mpc_part_build",
            "MPC part: lateral problem",
            build,
            "linearise, discretise, rows: all 20 stages, every row",
        ),
        (
            "mpc_part_factor",
            "MPC part: Riccati factorisation",
            factor,
            "gains of the 20 stages",
        ),
        (
            "mpc_part_iteration",
            "MPC part: ADMM iteration",
            unchecked,
            "backward and forward sweep, every row",
        ),
        (
            "mpc_part_iteration_checked",
            "MPC part: ADMM iteration with residuals",
            checked,
            "the same, computing residuals (every 5th and the last)",
        ),
        (
            "mpc_part_speed",
            "MPC part: speed plan",
            speed,
            "free response, reference, 10 ADMM iterations",
        ),
    ] {
        semihosting::eprintln!("bench\t{key}\t{name}\t1\t{n}\t{n}\t{n}\t{what}");
    }
    semihosting::eprintln!("mpc-info\tactive rows in the worst-case problem\t{active}");
}

/// Bytes of stack a worst-case solve uses: the stack region below the current frame is painted,
/// the lowest word overwritten afterwards marks the depth.
#[inline(never)]
fn run_stack(b: &Bench, worst: &MpcConfig, st: &mut Statics) {
    extern "C" {
        static _stack_end: u32;
    }
    const PAINT: u32 = 0xA5A5_5A5A;
    let road = Straight { half_width: 25.0 };
    let v = 15.0;
    let car = b.car(Pose::new(0.5, 0.0, 0.05), v);
    let obstacles = worst_obstacles(&car);
    let reference = road.reference(&b.node.body, 0.0, &car.planned, v);
    let input = b.input(&car, &reference, &obstacles);
    st.state.reset();
    let bottom = core::ptr::addr_of!(_stack_end) as usize;
    let sp = cortex_m::register::msp::read() as usize;
    // Leave this frame (and a margin for the painting loop) alone.
    let top = (sp - 256) & !3;
    for a in (bottom..top).step_by(4) {
        // SAFETY: stack memory below the live frames, word-aligned, inside the stack region.
        unsafe { (a as *mut u32).write_volatile(PAINT) };
    }
    let sp_before = cortex_m::register::msp::read() as usize;
    black_box(worst.solve(&mut st.state, black_box(&input)));
    let mut used = 0;
    for a in (bottom..top).step_by(4) {
        // SAFETY: as above.
        if unsafe { (a as *const u32).read_volatile() } != PAINT {
            used = sp_before.saturating_sub(a);
            break;
        }
    }
    semihosting::eprintln!("mpc-info\tstack of a worst-case solve, bytes\t{used}");
    semihosting::eprintln!(
        "mpc-info\tsizes, bytes: MpcState {}, MpcConfig {}, MpcOutput {}",
        core::mem::size_of::<MpcState>(),
        core::mem::size_of::<MpcConfig>(),
        core::mem::size_of::<MpcOutput>()
    );
}

#[cfg(feature = "tinympc")]
mod tiny {
    //! TinyMPC (tinympc-rs 0.2) on the lateral model at one speed (its cache is for one fixed
    //! model): 5 states, 1 input, 15 stages, the steering rate and range and the lateral offset
    //! as boxes (its projections act on the state, not on the body's corner rows), residuals
    //! every 5 iterations, 30 iterations per solve.
    use super::*;
    use nalgebra034 as na;
    use tinympc_rs::policy::FixedPolicy;
    use tinympc_rs::project::{dim::Lift, time::Fixed, Box as Boxed, ProjectMultiExt as _};
    use tinympc_rs::Solver;

    #[inline(never)]
    pub fn run(b: &Bench) {
        let p = &b.dynamics;
        let v = 15.0f32;
        let (cf, cr) = (p.cornering_front_n_per_rad, p.cornering_rear_n_per_rad);
        let (lf, lr, m, iz) = (
            p.cg_to_front_m,
            p.cg_to_rear_m,
            p.mass_kg,
            p.yaw_inertia_kg_m2,
        );
        let mut f = nalgebra::SMatrix::<f32, NX, NX>::zeros();
        for (i, j, x) in [
            (0, 1, v),
            (0, 2, 1.0),
            (0, 3, -lr),
            (1, 3, 1.0),
            (2, 2, -(cf + cr) / (m * v)),
            (2, 3, -v - (cf * lf - cr * lr) / (m * v)),
            (2, 4, cf / m),
            (3, 2, -(cf * lf - cr * lr) / (iz * v)),
            (3, 3, -(cf * lf * lf + cr * lr * lr) / (iz * v)),
            (3, 4, cf * lf / iz),
        ] {
            if let Some(e) = f.get_mut((i, j)) {
                *e = x;
            }
        }
        let Some((a, bm, _)) = lateral::tustin(&f, &nalgebra::SVector::zeros(), STEP_S) else {
            fail("tustin");
        };
        let a = na::SMatrix::<f32, 5, 5>::from_fn(|i, j| a.get((i, j)).copied().unwrap_or(0.0));
        let bm = na::SMatrix::<f32, 5, 1>::from_fn(|i, _| bm.get(i).copied().unwrap_or(0.0));
        let w = &DEFAULT_TUNING.weights;
        let q = na::SMatrix::<f32, 5, 5>::from_diagonal(&na::SVector::<f32, 5>::from([
            w.lateral_per_m2,
            w.heading_per_rad2,
            w.lateral_speed_per_mps2,
            w.yaw_rate_per_rps2,
            w.steer_per_rad2,
        ]));
        let r = na::SMatrix::<f32, 1, 1>::from_element(w.steer_rate);
        let s = na::SMatrix::<f32, 5, 1>::zeros();
        let (policy, cache) = timed(|| FixedPolicy::new(w.rho_corridor, 200, &a, &bm, &q, &r, &s));
        let Ok(policy) = policy else {
            fail("tinympc policy")
        };
        // HX = 16 states (x_0 .. x_15), HU = 15 inputs: the lateral problem's horizon.
        let mut mpc: Solver<f32, FixedPolicy<f32, 5, 1>, 5, 1, 16, 15> = Solver::new(a, bm, policy);
        mpc.config.max_iter = 30;
        mpc.config.do_check = 5;
        mpc.config.prim_tol = -1.0;
        mpc.config.dual_tol = -1.0;
        mpc.config.relaxation = DEFAULT_TUNING.admm.relaxation;
        let max_steer = b.node.vehicle.max_steer_rad;
        let x_box = Lift::new(
            [0, 4],
            Boxed {
                lower: na::SVector::<f32, 2>::from([-1.0, -max_steer]),
                upper: na::SVector::<f32, 2>::from([1.0, max_steer]),
            },
        );
        let u_box = Lift::new(
            [0],
            Boxed {
                lower: na::SVector::<f32, 1>::from([-b.rate_rad_per_s]),
                upper: na::SVector::<f32, 1>::from([b.rate_rad_per_s]),
            },
        );
        let mut x_con = [Fixed::new(&x_box).constraint_owned()];
        let mut u_con = [Fixed::new(&u_box).constraint_owned()];
        let x_ref = na::SMatrix::<f32, 5, 16>::zeros();
        let mut n = [0u32; 20];
        for (k, t) in n.iter_mut().enumerate() {
            let x_now = na::SVector::<f32, 5>::from([1.5 - 0.05 * k as f32, 0.0, 0.0, 0.0, 0.0]);
            let (_, i) = timed(|| {
                let sol = mpc
                    .initial_condition(x_now)
                    .x_reference(&x_ref)
                    .x_constraints(x_con.as_mut())
                    .u_constraints(u_con.as_mut())
                    .solve();
                sol.u_now()
            });
            *t = i;
        }
        n.sort_unstable();
        let (min, med, max) = (n[0], n[10], n[19]);
        semihosting::eprintln!(
            "bench\ttinympc_solve\tTinyMPC solve, for comparison\t20\t{min}\t{med}\t{max}\ttinympc-rs 0.2, lateral model at 15 m/s (LTI), 15 stages, 2 boxes, 30 iterations"
        );
        semihosting::eprintln!(
            "bench\ttinympc_cache\tTinyMPC cache, for comparison\t1\t{cache}\t{cache}\t{cache}\tits precomputation for one model (200 Riccati steps); an LTV model needs it per tick"
        );
    }
}

/// `MpcConfig::for_node` into `slot`, or the bench stops. One function per value built, so
/// that no frame holds more than one of them (the benches run on the firmware's 16 KiB stack).
#[inline(never)]
fn init_controller(slot: &mut Option<MpcConfig>, node: &NodeConfig, tuning: MpcTuning) -> u32 {
    let (mpc, instructions) = timed(|| MpcConfig::for_node(node, tuning));
    match mpc {
        Ok(c) => *slot = Some(c),
        Err(_) => fail("the controller's configuration is refused"),
    }
    instructions
}

/// The baked car into `slot`, or the bench stops.
#[inline(never)]
fn init_node(slot: &mut Option<NodeConfig>) {
    match catmodel_firmware::baked::node_config() {
        Ok(n) => *slot = Some(n),
        Err(_) => fail("the baked configuration does not load"),
    }
}

/// The car, its controller and the worst-case variant (no early exit), in statics.
fn configure() -> (&'static NodeConfig, &'static MpcConfig, &'static MpcConfig) {
    static mut NODE: Option<NodeConfig> = None;
    static mut MPC: Option<MpcConfig> = None;
    static mut WORST: Option<MpcConfig> = None;
    // SAFETY: the only references, taken once; single-threaded.
    let (node, mpc, worst) = unsafe {
        (
            &mut *addr_of_mut!(NODE),
            &mut *addr_of_mut!(MPC),
            &mut *addr_of_mut!(WORST),
        )
    };
    init_node(node);
    let Some(node) = node.as_ref() else {
        fail("no configuration");
    };
    let instructions = init_controller(mpc, node, DEFAULT_TUNING);
    semihosting::eprintln!("mpc-info\tMpcConfig::for_node, instructions\t{instructions}");
    let mut tuning = DEFAULT_TUNING;
    tuning.admm.primal_tolerance = -1.0;
    init_controller(worst, node, tuning);
    match (mpc.as_ref(), worst.as_ref()) {
        (Some(m), Some(w)) => (node, m, w),
        _ => fail("no controller"),
    }
}

#[entry]
fn main() -> ! {
    icount::init();
    let overhead = icount::calibrate();
    // Safety: the only write, before any read; single-threaded, no interrupts enabled.
    unsafe { OVERHEAD = overhead };
    let (node, mpc, worst) = configure();
    let Some(dynamics) = node.dynamics else {
        fail("the baked car has no [dynamics]: the bench needs the dynamic model");
    };
    let bench = Bench {
        node,
        mpc,
        dynamics,
        rate_rad_per_s: node.max_steer_rate_pct_per_s / 100.0 * node.vehicle.max_steer_rad,
    };
    let st = statics();
    run_scenarios(&bench, st);
    run_worst(&bench, worst, st);
    run_fallback_end(&bench, worst, st);
    run_parts(&bench, st);
    run_stack(&bench, worst, st);
    #[cfg(feature = "tinympc")]
    tiny::run(&bench);
    semihosting::eprintln!("bench-overhead\t{overhead}");
    semihosting::eprintln!("bench-done");
    semihosting::process::exit(0)
}
