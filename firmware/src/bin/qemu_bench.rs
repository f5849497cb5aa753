//! Instructions per call of each component of the node, on QEMU `-M netduinoplus2` with the
//! shipped profile, `firmware`. Run it with `cargo xtask bench-target` (docs/firmware.md, "Per
//! component"), which builds it, runs it and prints the table.
//!
//! Method: TIM2 counts one per executed instruction under `-icount shift=0` (the same counter
//! `cargo qemu` reads around each tick, [`icount`]). Every call is timed on its own, between two
//! reads of the counter; the cost of an empty timed call (the two reads and the `black_box`
//! barriers) is measured first and subtracted. Inputs and outputs go through
//! `core::hint::black_box`, so nothing is constant-folded or moved out of the window.
//!
//! Inputs are realistic and vary: the drive bundled in the firmware (`data/bundled.can.log`,
//! 15 s: standstill, acceleration to 5 m/s, left and right turns) is replayed through the node
//! once per group of components, and each component is called through the public API the node
//! uses, with its own state driven by that drive's values (the node's own frames, estimates and
//! inputs). Components are not measured inside `Node::step` (its code is inlined into one
//! function), so a component's row is the cost of that call alone.
//!
//! Output (semihosting stderr), one line per component, tab-separated:
//! `bench KEY NAME CALLS MIN MEDIAN MAX WHAT`; then `bench-overhead N` and `bench-done`.
#![no_std]
#![no_main]

use core::hint::black_box;

use catmodel::can::codec::{
    decode_input, ControlCommand, EncodeReport, GnssCogSog, InputMessage, NodeStatus, Prediction,
    StateMotion, StatePosition,
};
use catmodel::can::{candump, CanFrame, TimedFrame};
use catmodel::geodesy::LocalFrame;
use catmodel::model::dynamic::LateralState;
use catmodel::model::hybrid::Mode;
use catmodel::model::kinematic::{self, Pose};
use catmodel::model::predictor::{self, PredictedPoint, PredictorStart};
use catmodel::model::{MisoBlockState, SsBlockState};
use catmodel::node::drive::Drive;
use catmodel::node::{
    first_tick_us, Node, NodeConfig, PlatformStats, Tick, TickEstimate, TxFrames,
    PREDICTION_POINTS, VELOCITY_DELAY_CAP,
};
use catmodel::signal::{FirState, MovingAverageState};
use catmodel::{math, SAMPLE_PERIOD_S, SAMPLE_PERIOD_US};
use catmodel_firmware::baked::FirmwareNode;
use catmodel_firmware::platform::qemu::{icount, run::BUNDLED_DRIVE};
use cortex_m_rt::entry;
// The `defmt` feature is on for the core's types; nothing here logs through it, but a global
// logger must exist for any dependency that does.
use defmt_semihosting as _;

/// Calls kept per component (the first ones; the bundled drive has 1 496 GNSS fixes and 748
/// ticks).
const CAP: usize = 1536;

/// Instruction counts of one component's calls (the first `N`), as u16 to keep the stores
/// small (every component is far below 65 535; a count above it is stored as 65 535, which the
/// `--check` budgets of `cargo xtask bench-target` reject).
struct Samples<const N: usize> {
    n: [u16; N],
    len: usize,
}

/// The usual number of calls kept.
type Calls = Samples<CAP>;

impl<const N: usize> Samples<N> {
    fn push(&mut self, instructions: u32) {
        if let Some(slot) = self.n.get_mut(self.len) {
            *slot = u16::try_from(instructions).unwrap_or(u16::MAX);
            self.len += 1;
        }
    }

    /// min, median (nearest rank), max.
    fn stats(&mut self) -> (u32, u32, u32) {
        let values = self.n.get_mut(..self.len).unwrap_or(&mut []);
        values.sort_unstable();
        let at = |i: usize| values.get(i).copied().map_or(0, u32::from);
        let median = self.len.div_ceil(2).saturating_sub(1);
        (at(0), at(median), at(self.len.saturating_sub(1)))
    }

    /// Prints the component's line.
    fn report(&mut self, key: &str, name: &str, what: &str) {
        let (min, median, max) = self.stats();
        semihosting::eprintln!(
            "bench\t{key}\t{name}\t{}\t{min}\t{median}\t{max}\t{what}",
            self.len
        );
    }
}

/// A `&'static mut` to a fresh, zeroed sample store of type `$t`, one static per use site.
/// The stores (3 KiB each, 81 KiB in all) live in .bss: on the stack they would not fit its
/// 16 KiB region (memory.x). Each use site runs once (one call per benchmark group).
macro_rules! samples {
    ($t:ty) => {{
        static mut STORE: $t = zeroed_store();
        // SAFETY: the enclosing benchmark function runs once, so this is the only reference.
        unsafe { &mut *core::ptr::addr_of_mut!(STORE) }
    }};
}

/// The all-zero value of a sample store (or an array of them): `Samples { n: [0; N], len: 0 }`,
/// empty.
const fn zeroed_store<T>() -> T {
    // SAFETY: every store type is made of `u16` / `usize` fields and arrays of them, for which
    // all-zero bytes are a valid value.
    unsafe { core::mem::zeroed() }
}

/// Instructions of an empty timed call; subtracted from every measurement.
static mut OVERHEAD: u32 = 0;

/// Runs `f` between two reads of the instruction counter: returns its result and the
/// instructions it took (minus the timing overhead).
#[inline(always)]
fn timed<R>(f: impl FnOnce() -> R) -> (R, u32) {
    // Safety: written once in `main` before any measurement; single-threaded, no interrupts.
    icount::timed(unsafe { OVERHEAD }, f)
}

/// The latest measured inputs, decoded from the received frames (not timed).
#[derive(Clone, Copy, Default)]
struct Inputs {
    steer_pct: Option<f32>,
    speed_mps: Option<f32>,
    speed_cmd_mps: Option<f32>,
}

/// What one replayed tick offers to the benchmarks.
struct View<'a> {
    index: u32,
    config: &'a NodeConfig,
    rx: &'a [TimedFrame],
    tx: &'a TxFrames,
    estimate: TickEstimate,
    inputs: Inputs,
}

impl View<'_> {
    /// Centre steering angle, rad (eq 2's input), as the node computes it.
    fn center_steer_rad(&self) -> f32 {
        self.config
            .vehicle
            .steer_pct_to_center_rad(self.inputs.steer_pct.unwrap_or(0.0))
    }

    /// Commanded speed, or the measured one without a command (as the node drives eq 5).
    fn speed_cmd_mps(&self) -> f32 {
        self.inputs
            .speed_cmd_mps
            .or(self.inputs.speed_mps)
            .unwrap_or(self.estimate.speed_mps)
    }
}

/// The drive stage of the benchmark's nodes (35 KiB: a static).
static mut BENCH_DRIVE: Drive = Drive::new();

/// A node of the baked model on [`BENCH_DRIVE`], configured afresh. Each replay builds one and
/// drops it before the next replay builds another.
fn fresh_node() -> FirmwareNode {
    let Ok(config) = catmodel_firmware::baked::node_config() else {
        fail("the baked model does not build")
    };
    // SAFETY: single-threaded; the node made by the previous call (the only holder of this
    // reference) was dropped at the end of its replay.
    let drive = unsafe { &mut *core::ptr::addr_of_mut!(BENCH_DRIVE) };
    Node::new(config, drive)
}

/// Replays the bundled drive through a fresh node exactly as host replay does (ticks on the
/// 20 ms grid from the first frame, each given the frames stamped at or before it); `step`
/// runs `Node::step`, `each` sees every tick after it.
fn replay(
    mut step: impl FnMut(&mut FirmwareNode, &Tick, &[TimedFrame], &mut TxFrames) -> TickEstimate,
    mut each: impl FnMut(&View),
) {
    let mut node = fresh_node();
    let config = node.config().clone();
    let mut rx: heapless::Vec<TimedFrame, 64> = heapless::Vec::new();
    let mut inputs = Inputs::default();
    let mut tick_us: Option<u64> = None;
    let mut index = 0u32;
    let mut run_tick =
        |node: &mut FirmwareNode, now_us: u64, rx: &[TimedFrame], inputs: &mut Inputs| {
            for f in rx {
                match decode_input(&f.frame, config.gnss_source) {
                    Ok(InputMessage::Steering(m, _)) => inputs.steer_pct = m.steer_pct,
                    Ok(InputMessage::Speed(m, _)) => {
                        inputs.speed_mps = m.speed_mps;
                        inputs.speed_cmd_mps = m.speed_cmd_mps;
                    }
                    _ => {}
                }
            }
            let tick = Tick {
                now_us,
                platform: PlatformStats::default(),
            };
            let mut tx = TxFrames::new();
            let estimate = step(node, &tick, rx, &mut tx);
            each(&View {
                index,
                config: &config,
                rx,
                tx: &tx,
                estimate,
                inputs: *inputs,
            });
            index += 1;
        };
    for line in BUNDLED_DRIVE.split(|&b| b == b'\n') {
        let Some(frame) = core::str::from_utf8(line)
            .ok()
            .and_then(|text| candump::parse_line(text).ok())
        else {
            continue;
        };
        let now = *tick_us.get_or_insert(first_tick_us(frame.t_us));
        let mut now = now;
        while frame.t_us > now {
            run_tick(&mut node, now, &rx, &mut inputs);
            rx.clear();
            now += SAMPLE_PERIOD_US;
        }
        tick_us = Some(now);
        if rx.push(frame).is_err() {
            fail("more than 64 frames in one tick");
        }
    }
    if let Some(now) = tick_us {
        run_tick(&mut node, now, &rx, &mut inputs);
    }
}

fn node_step(
    node: &mut FirmwareNode,
    tick: &Tick,
    rx: &[TimedFrame],
    tx: &mut TxFrames,
) -> TickEstimate {
    node.step(tick, rx, tx)
}

/// `Node::step`: every tick, and the ticks with a valid position (filters warm, the horizon
/// rolled out, 14 frames out).
fn bench_tick() {
    let all = samples!(Calls);
    let running = samples!(Calls);
    replay(
        |node, tick, rx, tx| {
            let (estimate, n) =
                timed(|| black_box(node).step(black_box(tick), black_box(rx), black_box(tx)));
            all.push(n);
            if estimate.pose.is_some() {
                running.push(n);
            }
            estimate
        },
        |_| {},
    );
    running.report(
        "tick_running",
        "whole tick, running",
        "Node::step on a tick with a valid position: drain ~5 frames (decode, CRC, counters, 2 GNSS fixes through geodesy and the lowpass), eq 5, eq 7, lateral model, 2 s horizon, encode 14 frames",
    );
    all.report(
        "tick_all",
        "whole tick, every tick",
        "Node::step on every tick of the drive, start-up included (no position yet: no horizon, fewer outputs)",
    );
}

/// The paper's GNSS lowpass, one axis: the 21-tap FIR, then the 10-sample moving average.
fn bench_gnss_filters() {
    let fir = samples!(Calls);
    let ma = samples!(Calls);
    let mut frame: Option<LocalFrame> = None;
    let mut fir_state = FirState::default();
    let mut ma_state = MovingAverageState::default();
    let mut primed = false;
    replay(node_step, |view| {
        let cfg = &view.config.estimator;
        for f in view.rx {
            let Ok(InputMessage::GnssPosition(p)) = decode_input(&f.frame, view.config.gnss_source)
            else {
                continue;
            };
            let local = frame.get_or_insert_with(|| {
                LocalFrame::new(p.lat_e7, p.lon_e7).unwrap_or_else(|_| fail("bad origin"))
            });
            let Ok(enu) = local.to_local(p.lat_e7, p.lon_e7) else {
                continue;
            };
            if !primed {
                fir_state.prime(enu.east_m);
                ma_state.prime(enu.east_m);
                primed = true;
            }
            let (y, n) = timed(|| {
                cfg.fir
                    .process(black_box(&mut fir_state), black_box(enu.east_m))
            });
            fir.push(n);
            let (_, n) = timed(|| cfg.ma.process(black_box(&mut ma_state), black_box(y)));
            ma.push(n);
        }
    });
    fir.report(
        "gnss_fir",
        "GNSS FIR lowpass step",
        "Fir<21>::process: one GNSS fix, one axis (east, m), 21-tap FIR (paper II-C)",
    );
    ma.report(
        "moving_average",
        "moving average step",
        "MovingAverage<10>::process: the FIR output of one fix, one axis, 10-sample span",
    );
}

/// The node's models, each with its own state driven by the drive.
fn bench_models() {
    let velocity = samples!(Calls);
    let dxdt = samples!(Calls);
    let kin = samples!(Calls);
    let kin_steer = samples!(Calls);
    let kin_textbook = samples!(Calls);
    let dynamic = samples!(Calls);
    let mut velocity_state: Option<SsBlockState<2, VELOCITY_DELAY_CAP>> = None;
    let mut dxdt_state: Option<MisoBlockState<2, 4, 1>> = None;
    let mut pose: Option<Pose> = None;
    let mut textbook: Option<Pose> = None;
    let mut lateral = LateralState::default();
    replay(node_step, |view| {
        let cfg = view.config;
        let speed = view.estimate.speed_mps;
        let steer = view.center_steer_rad();
        if velocity_state.is_none() {
            if let Some(v) = view.inputs.speed_mps {
                velocity_state = cfg.velocity.steady_state_for_output(v).ok();
            }
        }
        if let Some(state) = velocity_state.as_mut() {
            let u = view.speed_cmd_mps();
            let (_, n) = timed(|| cfg.velocity.step(black_box(state), black_box(u)));
            velocity.push(n);
        }
        if let Some(p) = view.estimate.pose {
            let state = dxdt_state.get_or_insert_with(|| cfg.dxdt.zero_state());
            let u = [speed, p.x_m, p.y_m, steer];
            let (_, n) = timed(|| cfg.dxdt.step(black_box(state), black_box(&u)));
            dxdt.push(n);
            let own = pose.get_or_insert(p);
            // Curvature from the steering (eq 2, a tangent) given: eq 8's pose update alone.
            let curvature = cfg.vehicle.curvature_per_m(steer, speed);
            let (_, n) = timed(|| {
                kinematic::step(
                    black_box(&mut *own),
                    black_box(speed),
                    black_box(curvature),
                    SAMPLE_PERIOD_S,
                )
            });
            kin.push(n);
            // The same from the steering angle: eq 2's curvature, then eq 8.
            let (_, n) = timed(|| {
                let (steer, speed) = (black_box(steer), black_box(speed));
                let curvature = cfg.vehicle.curvature_per_m(steer, speed);
                kinematic::step(black_box(&mut *own), speed, curvature, SAMPLE_PERIOD_S)
            });
            kin_steer.push(n);
            // Reference, not a node component: eq 8 as printed (forward Euler, x' = v sin,
            // y' = v cos, theta' = v tan(delta) / L), sin, cos and tan every step.
            let own = textbook.get_or_insert(p);
            let (_, n) = timed(|| {
                let (steer, speed) = (black_box(steer), black_box(speed));
                let q = black_box(&mut *own);
                let (sin, cos) = math::sin_cos(q.heading_rad);
                let delta = cfg.vehicle.effective_steer_rad(steer, speed);
                let yaw_rate = speed * math::tan(delta) / cfg.vehicle.wheelbase_m;
                q.x_m += speed * sin * SAMPLE_PERIOD_S;
                q.y_m += speed * cos * SAMPLE_PERIOD_S;
                q.heading_rad = math::wrap_pi(q.heading_rad + yaw_rate * SAMPLE_PERIOD_S);
            });
            kin_textbook.push(n);
            // The node's own pose is the truth; keep ours from drifting away from it.
            if view.index % 50 == 0 {
                *own = p;
                pose = Some(p);
            }
        }
        // A car without a dynamic model has no dynamic step to time.
        let Some(dynamics) = cfg.dynamics.as_ref() else {
            return;
        };
        let (_, n) = timed(|| {
            dynamics.step(
                black_box(&mut lateral),
                black_box(speed),
                black_box(steer),
                SAMPLE_PERIOD_S,
            )
        });
        dynamic.push(n);
    });
    velocity.report(
        "velocity_eq5",
        "velocity model step (eq 5)",
        "SsBlock<2, 64>::step: commanded speed through the 21-sample input delay line, then the 2-state ZOH state space (y = C x + D u, x = A x + B u)",
    );
    dxdt.report(
        "dxdt_eq7",
        "dx/dt model step (eq 7)",
        "MisoBlock<2, 4, 1>::step: [v, x, y, phi] through four 2-state ZOH state-space blocks, outputs summed",
    );
    kin.report(
        "kinematic_eq8",
        "kinematic model step (eq 8)",
        "kinematic::step: pose (x, y, heading) advanced one 20 ms arc at given speed and curvature (series sin/cos, no transcendental call)",
    );
    kin_steer.report(
        "kinematic_eq2_eq8",
        "kinematic step from steering (eq 2 + 8)",
        "VehicleParams::curvature_per_m (understeer, tan) then kinematic::step: the kinematic model from the same inputs as eq 5/7 (speed, steering angle)",
    );
    kin_textbook.report(
        "kinematic_textbook",
        "(reference) eq 8 as printed, Euler",
        "not node code: x += v sin(theta) dt, y += v cos(theta) dt, theta += v tan(delta_eff) / L dt with math::sin_cos and math::tan every step (what a direct implementation of eq 8 costs)",
    );
    dynamic.report(
        "dynamic_step",
        "dynamic model step",
        "DynamicParams::step: lateral bicycle model (vy, yaw rate), one trapezoidal 20 ms step, coefficients built for the steering angle (as the node calls it each tick)",
    );
}

/// One horizon roll-out per tick, the node's way: eq 5's forecast from its state, then
/// `predictor::rollout` over 2 s (100 steps of eq 5 plus the lateral model, 10 points).
fn bench_rollouts() {
    let kinematic = samples!(Calls);
    let dynamic = samples!(Calls);
    let mut velocity_state: Option<SsBlockState<2, VELOCITY_DELAY_CAP>> = None;
    let mut lateral = LateralState::default();
    replay(node_step, |view| {
        let cfg = view.config;
        let speed = view.estimate.speed_mps;
        let steer = view.center_steer_rad();
        let Some(dynamics) = cfg.dynamics.as_ref() else {
            return;
        };
        if velocity_state.is_none() {
            if let Some(v) = view.inputs.speed_mps {
                velocity_state = cfg.velocity.steady_state_for_output(v).ok();
            }
        }
        dynamics.step(&mut lateral, speed, steer, SAMPLE_PERIOD_S);
        let (Some(state), Some(pose)) = (velocity_state.as_mut(), view.estimate.pose) else {
            return;
        };
        let cmd = view.speed_cmd_mps();
        let v_model = cfg.velocity.step(state, cmd);
        // The roll-outs of a car that is moving (below 1 m/s the dynamic model is the
        // kinematic steady state and the hybrid switch never picks it).
        if speed < dynamics.min_speed_mps {
            return;
        }
        for (mode, samples) in [
            (Mode::Kinematic, &mut *kinematic),
            (Mode::Dynamic, &mut *dynamic),
        ] {
            let start = PredictorStart {
                pose,
                speed_mps: speed,
                speed_bias_mps: speed - v_model,
                center_steer_rad: steer,
                lateral: match mode {
                    Mode::Kinematic => dynamics.steady_state(speed, steer),
                    Mode::Dynamic => lateral,
                },
                mode,
                reversing: false,
            };
            let mut points = [PredictedPoint::default(); PREDICTION_POINTS];
            let vel_state = *state;
            let (_, n) = timed(|| {
                let mut speeds = cfg.velocity.forecast(black_box(&vel_state), black_box(cmd));
                predictor::rollout(
                    &cfg.horizon,
                    &cfg.vehicle,
                    Some(dynamics),
                    black_box(&start),
                    |block| speeds.fill(block),
                    black_box(&mut points),
                )
            });
            samples.push(n);
        }
    });
    kinematic.report(
        "rollout_kinematic",
        "horizon roll-out, kinematic",
        "eq 5's forecast from its state + predictor::rollout: 100 steps of eq 5 (2 s), distance summed, pose moved along the held curvature once per point, 10 points",
    );
    dynamic.report(
        "rollout_dynamic",
        "horizon roll-out, dynamic",
        "eq 5's forecast + predictor::rollout: 100 steps of eq 5, the lateral model in 5 steps of 40 ms per point with the segment's mean speed held, the pose once per point (with side slip), 10 points",
    );
}

/// Frame decode of every input kind (`decode_input`, as the node calls it), on the drive's own
/// frames. The drive has no COG/SOG frames: those are made each tick from the node's heading
/// and speed.
fn bench_decode() {
    let kinds = samples!([Calls; 5]);
    replay(node_step, |view| {
        let source = view.config.gnss_source;
        let heading = view.estimate.pose.map_or(0.0, |p| p.heading_rad);
        let cog = GnssCogSog {
            sid: view.index as u8,
            cog_reference: 0,
            cog_rad: Some(if heading < 0.0 {
                heading + 2.0 * core::f32::consts::PI
            } else {
                heading
            }),
            sog_mps: Some(view.estimate.speed_mps),
        }
        .encode(source);
        let frames = view
            .rx
            .iter()
            .map(|f| &f.frame)
            .chain(core::iter::once(&cog));
        for frame in frames {
            let (msg, n) = timed(|| decode_input(black_box(frame), black_box(source)));
            let kind = match msg {
                Ok(InputMessage::Steering(..)) => 0,
                Ok(InputMessage::Speed(..)) => 1,
                Ok(InputMessage::Pedal(..)) => 2,
                Ok(InputMessage::GnssPosition(..)) => 3,
                Ok(InputMessage::GnssCogSog(..)) => 4,
                Err(_) => continue,
            };
            if let Some(s) = kinds.get_mut(kind) {
                s.push(n);
            }
        }
    });
    let rows = [
        ("decode_steering", "decode STEERING_REPORT (0x100)"),
        ("decode_speed", "decode SPEED_REPORT (0x101)"),
        ("decode_pedal", "decode PEDAL_REPORT (0x102)"),
        ("decode_gnss_position", "decode GNSS position (PGN 129025)"),
        ("decode_gnss_cog_sog", "decode GNSS COG/SOG (PGN 129026)"),
    ];
    for (s, (key, name)) in kinds.iter_mut().zip(rows) {
        s.report(
            key,
            name,
            "decode_input on a valid frame: identifier dispatch, DLC, CRC-8 (50 Hz reports), rolling counter out, signals unpacked and range-checked",
        );
    }
}

/// An output message, as decoded back from the node's frames.
#[derive(Clone, Copy)]
enum Output {
    Position(StatePosition),
    Motion(StateMotion),
    Prediction(Prediction),
    Status(NodeStatus),
    Control(ControlCommand),
}

impl Output {
    fn decode(frame: &CanFrame) -> Option<(Self, u8)> {
        if let Ok((m, c)) = StatePosition::decode(frame) {
            return Some((Self::Position(m), c));
        }
        if let Ok((m, c)) = StateMotion::decode(frame) {
            return Some((Self::Motion(m), c));
        }
        if let Ok((m, c)) = Prediction::decode(frame) {
            return Some((Self::Prediction(m), c));
        }
        if let Ok((m, c)) = ControlCommand::decode(frame) {
            return Some((Self::Control(m), c));
        }
        NodeStatus::decode(frame)
            .ok()
            .map(|(m, c)| (Self::Status(m), c))
    }

    #[inline(always)]
    fn encode(&self, counter: u8) -> (CanFrame, EncodeReport) {
        match self {
            Self::Position(m) => m.encode_with_report(counter),
            Self::Motion(m) => m.encode_with_report(counter),
            Self::Prediction(m) => m.encode_with_report(counter),
            Self::Status(m) => m.encode_with_report(counter),
            Self::Control(m) => m.encode_with_report(counter),
        }
    }
}

/// Frame encode of every output kind (`encode_with_report`, as the node calls it), on the
/// messages the node sent, and the whole set of one tick.
fn bench_encode() {
    let kinds = samples!([Calls; 3]);
    // Ten a tick; the first 3 840 (about half the drive's: the store of all of them did not fit
    // in RAM beside the drive stage once the controller's horizon grew to 2 s).
    let predictions = samples!(Samples<{ 5 * CAP / 2 }>);
    let set = samples!(Calls);
    replay(node_step, |view| {
        // A running node's messages (position valid, predictions made).
        if view.estimate.pose.is_none() {
            return;
        }
        let mut outputs: heapless::Vec<(Output, u8), 16> = heapless::Vec::new();
        for frame in view.tx {
            if let Some(out) = Output::decode(frame) {
                let _ = outputs.push(out);
            }
        }
        let [position, motion, status] = &mut *kinds;
        for (out, counter) in &outputs {
            // Each kind's own encoder, called directly.
            let c = *counter;
            match out {
                Output::Position(m) => {
                    position.push(timed(|| black_box(m).encode_with_report(black_box(c))).1)
                }
                Output::Motion(m) => {
                    motion.push(timed(|| black_box(m).encode_with_report(black_box(c))).1)
                }
                Output::Prediction(m) => {
                    predictions.push(timed(|| black_box(m).encode_with_report(black_box(c))).1)
                }
                Output::Status(m) => {
                    status.push(timed(|| black_box(m).encode_with_report(black_box(c))).1)
                }
                // Part of the tick's set below; no row of its own.
                Output::Control(_) => {}
            }
        }
        if view.tx.len() == outputs.len() {
            // Frames go to `black_box`, not into a `TxFrames`: pushing them in this loop cost
            // ~330 more instructions a frame, for a reason not found (a push timed alone is ~20,
            // and `Node::step` calls no memcpy); see docs/firmware.md.
            let (_, n) = timed(|| {
                let mut report = EncodeReport::default();
                for (out, counter) in black_box(&outputs) {
                    let (frame, r) = out.encode(*counter);
                    report.merge(&r);
                    black_box(frame);
                }
                report
            });
            set.push(n);
        }
    });
    const WHAT: &str = "encode_with_report on a running tick's message: finite check, scale, round and saturate each signal, pack bits, counter, CRC-8";
    let [position, motion, status] = &mut *kinds;
    position.report(
        "encode_state_position",
        "encode STATE_POSITION (0x300)",
        WHAT,
    );
    motion.report("encode_state_motion", "encode STATE_MOTION (0x301)", WHAT);
    predictions.report(
        "encode_prediction",
        "encode PREDICTION_k (0x310..0x319)",
        WHAT,
    );
    status.report(
        "encode_node_status",
        "encode NODE_STATUS (0x3F0, 6 pages)",
        WHAT,
    );
    set.report(
        "encode_tick_set",
        "encode a whole tick's frames",
        "the 14 frames of a running tick (2 state, 10 predictions, 1 status page, CONTROL_COMMAND) encoded, reports merged (the frames are not stored)",
    );
}

#[entry]
fn main() -> ! {
    icount::init();
    let overhead = icount::calibrate();
    // Safety: the only write, before any read; single-threaded, no interrupts enabled.
    unsafe { OVERHEAD = overhead };
    semihosting::eprintln!("bench-overhead\t{overhead}");
    bench_gnss_filters();
    bench_models();
    bench_rollouts();
    bench_decode();
    bench_encode();
    bench_tick();
    semihosting::eprintln!("bench-done");
    semihosting::process::exit(0)
}

fn fail(message: &str) -> ! {
    semihosting::eprintln!("catmodel-qemu-bench: error: {message}");
    semihosting::process::exit(3)
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    semihosting::eprintln!("catmodel-qemu-bench: panic: {info}");
    semihosting::process::exit(101)
}
