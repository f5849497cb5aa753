//! `Node`: one pure 20 ms step that takes the frames received since the last tick and the tick
//! time, and returns the frames to send. The board, QEMU and host replay run exactly this code,
//! so `catmodel replay --tx-out` and the QEMU run produce byte-identical frames.
//!
//! A tick is five stages, each a function over its own part of the state; read [`Node::step`]
//! top to bottom to follow a frame from the bus to a prediction:
//! 1. **receive and validate** ([`inputs`]): decode each frame (DLC, CRC-8, rolling counter,
//!    range; GNSS range and a plausibility gate), count every rejection, keep the latest valid
//!    value of each input with its receive time; then the tick's GNSS fixes go into the
//!    lowpass ([`gnss`]);
//! 2. **models and hybrid switch**: the speed model (eq 5) driven by the commanded speed, the
//!    active lateral model (kinematic eq 8, or the dynamic single-track model) chosen by the
//!    hybrid switch;
//! 3. **estimate**: the heading (receiver COG or the filtered track's course), the filtered,
//!    delay-compensated rear-axle position ([`estimator`]), the dx/dt model (eq 7);
//! 4. **predict**: the 2 s horizon rolled forward ([`crate::model::predictor`]);
//! 5. **publish** ([`publish`]): the state, prediction and status frames, every value checked
//!    finite before it is encoded (non-finite values go out as "not available" and are
//!    counted, health bit `nonfinite_guard`).
//!
//! Never panics on bus data, never allocates, never reads a clock. Its work is bounded for any
//! input: at most [`MAX_RX_FRAMES_PER_TICK`] frames a tick, fixed loop counts everywhere else
//! ([`stage`] writes the structure down; docs/firmware.md, "Worst-case tick").
//!
//! Configuration ([`NodeConfig`]) is everything about the car: built from the model file by
//! `catmodel-model-file` (host) or read from the image the firmware build baked
//! ([`NodeConfig::from_image`]); nothing about a particular car lives in this crate.
pub mod drive;
pub mod estimator;
pub mod follow;
pub mod gnss;
pub mod inputs;
pub mod publish;
pub mod smoothing;
pub mod stage;
pub mod steering;

use core::borrow::BorrowMut;

use crate::can::codec::ControlStatus;
use crate::can::freshness::{FreshnessConfig, Input};
use crate::can::TimedFrame;
use crate::image::{self, Image, ImageError, ImageReader, ImageWriter};
use crate::model::block::{MisoBlock, MisoBlockState, SsBlock, SsBlockState};
use crate::model::dynamic::{DynamicParams, LateralState};
use crate::model::hybrid::{HybridConfig, HybridState, Mode};
use crate::model::kinematic::Pose;
use crate::model::predictor::{self, HorizonConfig, PredictedPoint, PredictorStart};
use crate::vehicle::{Body, VehicleParams};
use crate::{math, SAMPLE_PERIOD_S, SAMPLE_PERIOD_US};
use drive::{Controller, Drive, DriveInputs, DriveOutput};
use estimator::{EstimatorConfig, Rates};
use gnss::Gnss;
use inputs::{GnssMessage, Inputs, Routed, Snapshot};
use publish::Health;
pub use stage::{
    Branch, BranchTaken, Exclusive, NoProbe, Stage, StageBound, StageProbe, GAP_FILL_PER_TICK,
    GNSS_FIXES_PER_TICK, MAX_RX_FRAMES_PER_TICK, PLANNER_FRAMES_PER_TICK, SHORT_PATH_POINTS,
    TICK_STAGES,
};
use steering::SteeringCheck;

/// Most frames one tick can send: 2 state frames, 10 predictions, 1 status page and the
/// controller's command are 14; 16 leaves room.
pub const MAX_TX_FRAMES: usize = 16;
/// Frames a platform's receive queue holds between two ticks (the firmware's app, and `sil`
/// on the host). The acceptance filter admits the node's inputs only (at their highest rates
/// 7 frames per tick), so 64 holds four full ticks of [`MAX_RX_FRAMES_PER_TICK`]; a full queue
/// drops the newest frame and counts it ([`PlatformStats::rx_queue_drops`]).
pub const RX_QUEUE_LEN: usize = 64;
/// Prediction points on the bus (PREDICTION_1..10, every 0.2 s up to 2.0 s).
pub const PREDICTION_POINTS: usize = 10;
/// The heading's standard deviation (the estimate's own, `EstimatorState::heading_var_rad2`)
/// above which STATE_MOTION's `heading_uncertain` is set, rad: 0.1 rad moves a prediction
/// 1 s ahead at 10 m/s by 1 m. Set after the first course sets the heading (0.5 rad) until
/// the courses settle it, and when the track shows the heading off (docs/findings.md: a slide at full lock).
/// The bit is also set while the track has run against the heading and no turn has confirmed
/// it since (`EstimatorState::direction_ambiguous`: a car that reverses without SPEED_REPORT's
/// `direction` saying so).
pub const HEADING_UNCERTAIN_ABOVE_RAD: f32 = 0.1;
/// Longest velocity-model input delay a model file may have: 64 samples = 1.28 s (eq 5 has
/// 21; models identified on the simulator's delayed, lagging speed loop reach ~48); the
/// predictor copies this buffer every tick, so it is not larger.
pub const VELOCITY_DELAY_CAP: usize = 64;
/// Longest input delay of a dx/dt (eq 7) block, samples: eq 7 has none.
pub const DXDT_DELAY_CAP: usize = 1;
/// Words of a [`NodeConfig`] image, at most (the firmware's baked array is sized exactly).
pub const CONFIG_IMAGE_MAX_WORDS: usize = 512;

/// The frames one tick sends, in transmit order.
pub type TxFrames = heapless::Vec<crate::can::CanFrame, MAX_TX_FRAMES>;

/// What only the platform can know; `None` where it cannot measure (sent as "not available").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PlatformStats {
    /// Ticks that started late (missed their 20 ms slot) since boot.
    pub overruns: u32,
    /// Frames dropped because the receive queue was full, since boot.
    pub rx_queue_drops: u32,
    /// Duration of the previous step in microseconds, where a cycle counter exists (board).
    pub last_step_us: Option<u32>,
    /// Deepest stack use seen so far, bytes, where the stack is painted.
    pub stack_high_water_bytes: Option<u32>,
    /// The last reset was caused by the watchdog.
    pub watchdog_reset: bool,
}

/// The input of one tick.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Tick {
    /// The tick's scheduled time, us on the input's time base.
    pub now_us: u64,
    /// Platform counters.
    pub platform: PlatformStats,
}

/// The first tick's time for a stream whose first frame arrived at `first_frame_us`: the first
/// whole multiple of the 20 ms period at or after it (docs/architecture.md, "Tick schedule").
/// Every platform derives its schedule from this one function.
pub const fn first_tick_us(first_frame_us: u64) -> u64 {
    first_frame_us.div_ceil(SAMPLE_PERIOD_US) * SAMPLE_PERIOD_US
}

/// The ticks of a drive in which every frame goes to the first tick at or after its time,
/// however many are due (no receive queue, no cap: the tests' and the stage checks' schedule):
/// each tick's time and the range of `frames` (in time order) it gets, from [`first_tick_us`]
/// of the first frame to the tick that gets the last.
pub fn due_ticks(
    frames: &[TimedFrame],
) -> impl Iterator<Item = (u64, core::ops::Range<usize>)> + '_ {
    let mut now = frames.first().map_or(0, |f| first_tick_us(f.t_us));
    let mut next = 0;
    core::iter::from_fn(move || {
        if next >= frames.len() {
            return None;
        }
        let start = next;
        while frames.get(next).is_some_and(|f| f.t_us <= now) {
            next += 1;
        }
        let tick = (now, start..next);
        now += SAMPLE_PERIOD_US;
        Some(tick)
    })
}

/// Everything the node is configured with: everything about the car. Immutable.
#[derive(Clone, Debug, PartialEq)]
pub struct NodeConfig {
    /// Geometry and steering conversion (eq 2-4).
    pub vehicle: VehicleParams,
    /// The body around the rear axle (corridor and obstacle clearance).
    pub body: Body,
    /// Dynamic single-track model; `None`: the car has none, the node stays kinematic.
    pub dynamics: Option<DynamicParams>,
    /// Hybrid switching thresholds.
    pub hybrid: HybridConfig,
    /// Horizon shape.
    pub horizon: HorizonConfig,
    /// GNSS lowpass (designed for the receiver's rate), lever arm, heading.
    pub estimator: EstimatorConfig,
    /// Internal-controller model, commanded speed -> speed (eq 5), with its input delay.
    pub velocity: SsBlock<2, VELOCITY_DELAY_CAP>,
    /// dx/dt model with inputs [v_m, x, y, phi] (eq 7).
    pub dxdt: MisoBlock<2, 4, DXDT_DELAY_CAP>,
    /// NMEA 2000 source address of the GNSS receiver.
    pub gnss_source: u8,
    /// Local frame origin (lat, lon in 1e-7 deg); `None` = the first valid fix.
    pub origin_e7: Option<(i32, i32)>,
    /// Input timeouts (PX4-style `is_timed_out`): after this an input is stale. For GNSS the
    /// position is then dead-reckoned and flagged.
    pub freshness: FreshnessConfig,
    /// GNSS silent this long: the position is no longer trusted (invalid, filters restart), us.
    pub gnss_lost_us: u64,
    /// A fix farther than this from the predicted position is rejected, m: the most the gate
    /// allows; it learns a tighter one from the receiver ([`gnss::GATE_MEDIANS`]).
    pub gnss_gate_m: f32,
    /// After this many consecutive gate rejections the fixes win: the filters restart there.
    pub gnss_reacquire_fixes: u16,
    /// Speeds are clamped to [0, this], m/s.
    pub max_speed_mps: f32,
    /// Fastest steering change the car's actuator makes, % per second.
    pub max_steer_rate_pct_per_s: f32,
    /// How far the steering trails a ramp command (the actuator's lag plus the drive-by-wire's
    /// delay), s (`None`: not given; the MPC's built-in lead assumes 0.05 s); see
    /// [`drive::mpc_tuning`].
    pub steer_lag_s: Option<f32>,
    /// The controller that follows the planner's path.
    pub controller: Controller,
    /// Bound on the error of the node's position estimate with this receiver (2 sigma), m:
    /// the controller inflates obstacles by it.
    pub position_uncertainty_m: f32,
    /// The MPC's lateral-offset weight for this car, per m^2 (`None`: the tuning's,
    /// [`crate::control::mpc::DEFAULT_TUNING`]); see [`drive::mpc_tuning`].
    pub mpc_lateral_weight_per_m2: Option<f32>,
    /// The car's lateral acceleration at most, m/s^2 (`None`: not given, no limit): the
    /// controllers' paths hold their turns to it ([`crate::control::path::Path::set_lateral_limit`]).
    pub max_lateral_accel_mps2: Option<f32>,
}

impl Image for FreshnessConfig {
    fn write(&self, w: &mut ImageWriter<'_>) {
        self.timeout_us.write(w);
    }
    fn read(r: &mut ImageReader<'_>) -> Result<Self, ImageError> {
        Ok(Self {
            timeout_us: Image::read(r)?,
        })
    }
}

impl Image for NodeConfig {
    fn write(&self, w: &mut ImageWriter<'_>) {
        let Self {
            vehicle,
            body,
            dynamics,
            hybrid,
            horizon,
            estimator,
            velocity,
            dxdt,
            gnss_source,
            origin_e7,
            freshness,
            gnss_lost_us,
            gnss_gate_m,
            gnss_reacquire_fixes,
            max_speed_mps,
            max_steer_rate_pct_per_s,
            steer_lag_s,
            controller,
            position_uncertainty_m,
            mpc_lateral_weight_per_m2,
            max_lateral_accel_mps2,
        } = self;
        vehicle.write(w);
        body.write(w);
        dynamics.write(w);
        hybrid.write(w);
        horizon.write(w);
        estimator.write(w);
        velocity.write(w);
        dxdt.write(w);
        gnss_source.write(w);
        origin_e7.write(w);
        freshness.write(w);
        gnss_lost_us.write(w);
        gnss_gate_m.write(w);
        gnss_reacquire_fixes.write(w);
        max_speed_mps.write(w);
        max_steer_rate_pct_per_s.write(w);
        steer_lag_s.write(w);
        controller.write(w);
        position_uncertainty_m.write(w);
        mpc_lateral_weight_per_m2.write(w);
        max_lateral_accel_mps2.write(w);
    }
    fn read(r: &mut ImageReader<'_>) -> Result<Self, ImageError> {
        Ok(Self {
            vehicle: Image::read(r)?,
            body: Image::read(r)?,
            dynamics: Image::read(r)?,
            hybrid: Image::read(r)?,
            horizon: Image::read(r)?,
            estimator: Image::read(r)?,
            velocity: Image::read(r)?,
            dxdt: Image::read(r)?,
            gnss_source: Image::read(r)?,
            origin_e7: Image::read(r)?,
            freshness: Image::read(r)?,
            gnss_lost_us: Image::read(r)?,
            gnss_gate_m: Image::read(r)?,
            gnss_reacquire_fixes: Image::read(r)?,
            max_speed_mps: Image::read(r)?,
            max_steer_rate_pct_per_s: Image::read(r)?,
            steer_lag_s: Image::read(r)?,
            controller: Image::read(r)?,
            position_uncertainty_m: Image::read(r)?,
            mpc_lateral_weight_per_m2: Image::read(r)?,
            max_lateral_accel_mps2: Image::read(r)?,
        })
    }
}

impl NodeConfig {
    /// Reads a configuration image (see [`crate::image`]): what the firmware runs.
    pub fn from_image(words: &[u32]) -> Result<Self, ImageError> {
        image::decode(words)
    }

    /// This configuration as an image; returns the words used (at most
    /// [`CONFIG_IMAGE_MAX_WORDS`] for every configuration this crate can describe).
    pub fn to_image(&self, words: &mut [u32]) -> usize {
        image::encode(self, words)
    }
}

/// Rejection and event counters since boot (saturating: they never wrap).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Counters {
    /// Frames with a bad CRC.
    pub crc_errors: u32,
    /// Stuck (rejected) or jumping (counted, accepted) rolling counters.
    pub counter_errors: u32,
    /// Known identifiers with the wrong DLC.
    pub dlc_errors: u32,
    /// Values outside their DBC range or carrying an invalid sentinel.
    pub range_errors: u32,
    /// GNSS fixes rejected by the plausibility gate or the geodesy range.
    pub gnss_gate_rejects: u32,
    /// GNSS fixes not used because the receiver runs at another rate than the model file's
    /// `gnss_rate_hz` ([`gnss::RATE_MISMATCH_FIXES`]).
    pub gnss_rate_mismatch: u32,
    /// Identifiers the node does not know (or GNSS from another source).
    pub unknown_ids: u32,
    /// Frames stamped after the tick that received them (clock mismatch), rejected.
    pub time_errors: u32,
    /// Frames beyond [`MAX_RX_FRAMES_PER_TICK`] handed to one tick, not used (the app and host
    /// replay never hand more: they keep the rest for the next tick).
    pub rx_over_cap: u32,
    /// Output values replaced because they were not finite.
    pub nonfinite: u32,
    /// Output values saturated to their field's range.
    pub saturated: u32,
}

fn bump(c: &mut u32) {
    *c = c.saturating_add(1);
}

/// What one tick estimated, for the host tools (replay writes it next to the frames).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TickEstimate {
    /// Filtered, delay-compensated position and heading; `None` while invalid.
    pub pose: Option<Pose>,
    /// Speed used, m/s.
    pub speed_mps: f32,
    /// Lateral model in use.
    pub mode: Mode,
    /// What the drive stage did (anything but `NoPath`: a controller planned this tick).
    pub control: ControlStatus,
    /// The planner's frames (path, limits, obstacles, origin) arrived in this tick: their
    /// assembly ran in stage 1, and a path may have been completed (validated and loaded).
    pub planner_frames: bool,
}

impl TickEstimate {
    /// Whether this tick is one of the controller's (its budget and bound,
    /// `CONTROL_TICK_BUDGET_INSTRUCTIONS`): a controller planned in it, or the planner's frames
    /// were processed in it. Every other tick (the node estimating and predicting, the
    /// features the 25 000-instruction budget was set for) is under `TICK_BUDGET_INSTRUCTIONS`.
    pub fn controller_tick(&self) -> bool {
        self.control != ControlStatus::NoPath || self.planner_frames
    }
}

/// The largest rear-axle slip angle the dead reckoning believes, rad: the linear tyres'
/// slip beyond it is saturation (road tyres peak near 0.1 rad), which the linear model
/// overstates.
const MAX_REAR_SLIP_RAD: f32 = 0.15;

/// The models' state (stage 2).
#[derive(Clone, Debug)]
struct Models {
    /// Eq 5's state; `None` until a first speed was measured (it starts at equilibrium there).
    velocity: Option<SsBlockState<2, VELOCITY_DELAY_CAP>>,
    /// Eq 7's state.
    dxdt: MisoBlockState<2, 4, DXDT_DELAY_CAP>,
    lateral: LateralState,
    hybrid: HybridState,
    /// The active lateral model's yaw rate, rad/s (dead reckoning uses last tick's).
    yaw_rate_rps: f32,
    /// The rear axle's sideways velocity in the lateral model (tyre slip; 0 without a dynamic
    /// model), m/s (dead reckoning uses last tick's).
    rear_side_mps: f32,
    /// The speed the node uses, m/s: its magnitude (dead reckoning uses last tick's).
    speed_mps: f32,
    /// The car reverses (SPEED_REPORT `direction`): it moves backwards at `speed_mps` (dead
    /// reckoning uses last tick's).
    reversing: bool,
    /// The largest yaw rate the car may have that the lateral model does not see, rad/s:
    /// while the steering report is stale the model steers straight on, and the wheels may
    /// have turned since the last report at the actuator's rate (dead reckoning uses last
    /// tick's; 0 with a fresh report).
    unseen_yaw_rps: f32,
    /// The last fresh steering report, %: while the report is stale the models steer with it
    /// (the actuator holds its last command, and a controller holds its command while the
    /// report is stale: `FallbackCause::SteeringStale`).
    last_steer_pct: f32,
}

impl Models {
    /// The speed along the heading, m/s: negative while the car reverses.
    fn velocity_mps(&self) -> f32 {
        signed(self.speed_mps, self.reversing)
    }

    /// The rates the dead reckoning integrates.
    fn rates(&self) -> Rates {
        Rates {
            yaw_rps: self.yaw_rate_rps,
            rear_side_mps: self.rear_side_mps,
        }
    }
}

/// `speed_mps` (a magnitude) along the heading: negative when `reversing`.
#[inline(always)]
fn signed(speed_mps: f32, reversing: bool) -> f32 {
    if reversing {
        -speed_mps
    } else {
        speed_mps
    }
}

/// What stage 2 produced this tick.
#[derive(Clone, Copy, Debug)]
struct Motion {
    /// The speed's magnitude, m/s.
    speed_mps: f32,
    /// The car reverses (SPEED_REPORT `direction`): the kinematic model, with the yaw rate of
    /// a car moving backwards.
    reversing: bool,
    /// Eq 5's output, m/s.
    speed_model_mps: Option<f32>,
    /// The speed command the roll-out holds, m/s.
    speed_cmd_mps: Option<f32>,
    /// The centre tyre's angle the models use: the measured one times `steer_scale`, rad.
    center_steer_rad: f32,
    /// The centre tyre's angle as the model file converts the steering percent, rad.
    measured_steer_rad: f32,
    /// The steering check's gain in use ([`steering`]).
    steer_scale: f32,
    /// The steering report is fresh this tick (stale: the models steer straight on).
    steer_fresh: bool,
    mode: Mode,
}

/// What stage 3 produced this tick.
#[derive(Clone, Copy, Debug)]
struct Estimate {
    pose: Option<Pose>,
    gnss_fresh: bool,
    /// The heading was corrected towards a course this tick.
    heading_corrected: bool,
    /// Eq 7's output, m/s.
    dxdt_mps: Option<f32>,
}

/// The node's mutable state, one part per stage. The drive stage's state is large (see
/// [`drive`]) and lives where the platform put it: `D` is a `&'static mut Drive` in a static
/// on the MCU, a `Box<Drive>` on the host.
#[derive(Clone, Debug)]
pub struct Node<D: BorrowMut<Drive>> {
    config: NodeConfig,
    inputs: Inputs,
    gnss: Gnss,
    models: Models,
    drive: D,
    health: Health,
    steering: SteeringCheck,
    last_tick_us: Option<u64>,
}

impl<D: BorrowMut<Drive>> Node<D> {
    /// A node with fresh state for the car of `config`, driving with `drive` (reset and
    /// configured for that car here).
    pub fn new(config: NodeConfig, mut drive: D) -> Self {
        drive.borrow_mut().configure(&config);
        let models = Models {
            velocity: None,
            dxdt: config.dxdt.zero_state(),
            lateral: LateralState::default(),
            hybrid: HybridState::default(),
            yaw_rate_rps: 0.0,
            rear_side_mps: 0.0,
            speed_mps: 0.0,
            reversing: false,
            unseen_yaw_rps: 0.0,
            last_steer_pct: 0.0,
        };
        Self {
            config,
            inputs: Inputs::default(),
            gnss: Gnss::default(),
            models,
            drive,
            health: Health::default(),
            steering: SteeringCheck::new(),
            last_tick_us: None,
        }
    }

    /// The drive stage: what the planner sent so far (paths, obstacles), the last command.
    pub fn drive(&self) -> &Drive {
        self.drive.borrow()
    }

    /// The drive stage, for host tools that tune the reference controller
    /// ([`Drive::tune_pursuit`]).
    pub fn drive_mut(&mut self) -> &mut Drive {
        self.drive.borrow_mut()
    }

    /// The configuration.
    pub fn config(&self) -> &NodeConfig {
        &self.config
    }

    /// Rejection counters since start.
    pub fn counters(&self) -> &Counters {
        &self.inputs.counters
    }

    /// The latest interval between the GNSS receiver's fixes that was off the model file's
    /// period, us: the receiver's period when NODE_STATUS says `gnss_rate_mismatch`.
    pub fn gnss_off_rate_interval_us(&self) -> Option<u32> {
        self.gnss.off_rate_interval_us()
    }

    /// GNSS fixes that lay beyond the local frame's validity radius
    /// ([`crate::geodesy::VALIDITY_RADIUS_M`]) so far: counted among the gate's rejections on
    /// the bus; the node moves its own frame after enough of them, not a configured or
    /// planner's one.
    pub fn gnss_fixes_beyond_frame(&self) -> u32 {
        self.gnss.fixes_beyond_frame()
    }

    /// The on-line check of the steering's effect on the yaw rate ([`steering`]): its fitted
    /// gain against the model file's and whether the node uses it.
    pub fn steering(&self) -> &SteeringCheck {
        &self.steering
    }

    /// Ticks run.
    pub fn tick_count(&self) -> u32 {
        self.health.tick_count
    }

    /// The local frame's origin once known (lat, lon in 1e-7 deg).
    pub fn origin_e7(&self) -> Option<(i32, i32)> {
        self.gnss.origin_e7()
    }

    /// Runs one tick: consumes `rx` (frames with `t_us <= tick.now_us`, in arrival order; the
    /// first [`MAX_RX_FRAMES_PER_TICK`], any more are counted and not used) and appends this
    /// tick's frames to `tx`. Returns what the tick estimated.
    pub fn step(&mut self, tick: &Tick, rx: &[TimedFrame], tx: &mut TxFrames) -> TickEstimate {
        self.step_probed(tick, rx, tx, &mut NoProbe)
    }

    /// [`Node::step`], telling `probe` where each stage ends ([`stage`]): how the tick's
    /// worst case is measured. Same results as `step`.
    #[inline(always)]
    pub fn step_probed<P: StageProbe>(
        &mut self,
        tick: &Tick,
        rx: &[TimedFrame],
        tx: &mut TxFrames,
        probe: &mut P,
    ) -> TickEstimate {
        let now = tick.now_us;
        let dt_s = self.advance(now);
        probe.lap(Stage::Advance);
        let planner_frames = self.receive(now, rx, probe);
        let snapshot = self.inputs.snapshot(&self.config, now);
        let motion = self.run_models(&snapshot, dt_s);
        probe.lap(Stage::Models);
        let estimate = self.estimate(now, &motion);
        probe.lap(Stage::Estimate);
        let drive = self.run_drive(&motion, &estimate, snapshot.steer_pct, probe);
        probe.lap(Stage::Drive);
        let mut points = [PredictedPoint::default(); PREDICTION_POINTS];
        let predicted = match drive.plan {
            // While the model-predictive controller drives, the path ahead is its plan.
            Some(plan) if estimate.pose.is_some() => {
                points = plan;
                PREDICTION_POINTS
            }
            _ => self.predict(&snapshot, &motion, &estimate, &mut points),
        };
        let horizon = points.get(..predicted).unwrap_or(&[]);
        probe.lap(Stage::Predict);
        self.publish(tick, &snapshot, &motion, &estimate, horizon, &drive, tx);
        probe.lap(Stage::Publish);
        TickEstimate {
            pose: estimate.pose,
            speed_mps: motion.speed_mps,
            mode: motion.mode,
            control: drive.command.status,
            planner_frames,
        }
    }

    /// The time since the last tick (missed ticks are propagated over the real elapsed time, at
    /// most 0.1 s), and the dead reckoning moved over it with last tick's speed and yaw rate,
    /// so that this tick's fixes can be placed against it.
    fn advance(&mut self, now_us: u64) -> f32 {
        let dt_s = match self.last_tick_us {
            Some(prev) if now_us > prev => math::u64_to_f32((now_us - prev).min(100_000)) * 1e-6,
            _ => SAMPLE_PERIOD_S,
        };
        self.last_tick_us = Some(now_us);
        let rates = self.models.rates();
        let velocity_mps = self.models.velocity_mps();
        self.gnss
            .propagate(&self.config.estimator, velocity_mps, rates, dt_s);
        if self.models.unseen_yaw_rps > 0.0 {
            self.gnss.turn_unseen(self.models.unseen_yaw_rps, dt_s);
        }
        self.steering.turned(rates.yaw_rps, velocity_mps, dt_s);
        dt_s
    }

    /// Stage 1: every received frame (the first [`MAX_RX_FRAMES_PER_TICK`]) decoded, validated
    /// and applied, or counted as rejected: the vehicle's reports here, the planner's to the
    /// drive stage; then the planner's map origin, if a LOCAL_ORIGIN completed this tick (the
    /// last one, once per tick); then the tick's GNSS fixes (the first
    /// [`GNSS_FIXES_PER_TICK`], in arrival order) through the GNSS stage, in the tick's frame.
    /// The reports change nothing the GNSS stage reads (it uses last tick's speed), so handling
    /// the fixes after the frames is the same as handling them in between; a fix received
    /// before a LOCAL_ORIGIN of the same tick goes into the new frame (the old frame's filters
    /// are reset by the change anyway).
    ///
    /// A planner frame that completes a path (validation and load over its points) is a stage
    /// of its own ([`Stage::PathComplete`], [`Stage::PathCompleteShort`]). Returns whether a
    /// planner frame was processed (the tick is then a controller tick).
    fn receive<P: StageProbe>(&mut self, now_us: u64, rx: &[TimedFrame], probe: &mut P) -> bool {
        let (frames, over_cap) = rx.split_at(rx.len().min(MAX_RX_FRAMES_PER_TICK));
        let c = &mut self.inputs.counters;
        c.rx_over_cap = c
            .rx_over_cap
            .saturating_add(u32::try_from(over_cap.len()).unwrap_or(u32::MAX));
        let mut fixes = gnss::TickFixes::new();
        let mut origin = None;
        let mut planner_frames = false;
        for frame in frames {
            let mut stage = Stage::Frame;
            match self.inputs.receive(&self.config, now_us, frame) {
                Some(Routed::Gnss(GnssMessage::Fix(fix))) => {
                    if let Err(over) = fixes.push(fix) {
                        bump(&mut self.inputs.counters.gnss_gate_rejects);
                        self.gnss.over_cap(&self.config, over.t_us);
                    }
                }
                Some(Routed::Gnss(GnssMessage::Course(course))) => {
                    self.gnss.receive_course(&self.config, &course);
                }
                Some(Routed::Planner(message)) => {
                    planner_frames = true;
                    let drive = self.drive.borrow_mut();
                    let refused = drive.planner().counters().rejects();
                    let received = drive.receive(&message, now_us);
                    if drive.planner().counters().rejects() != refused {
                        self.health.planner_refused(now_us);
                    }
                    origin = received.origin.or(origin);
                    stage = received.completed.unwrap_or(stage);
                }
                None => {}
            }
            probe.lap(stage);
        }
        if let Some(origin) = origin {
            // LOCAL_ORIGIN: the planner's map origin becomes the node's frame; one the local
            // frame cannot take is a value out of range (counted, the frame in use stays).
            match self.gnss.set_origin(origin) {
                Ok(true) => self.drive.borrow_mut().frame_changed(),
                Ok(false) => {}
                Err(_) => bump(&mut self.inputs.counters.range_errors),
            }
            probe.lap(Stage::Origin);
        }
        self.gnss.receive_fixes(
            &self.config,
            now_us,
            &fixes,
            self.models.velocity_mps(),
            &mut self.inputs,
            probe,
        );
        if self.gnss.take_frame_moved() {
            // The car left the node's own frame and the frame moved with it: a path given in
            // the old one no longer holds (never in a tick with a LOCAL_ORIGIN: a planner's
            // frame is not moved).
            self.drive.borrow_mut().drop_path();
            probe.lap(Stage::Origin);
        }
        planner_frames
    }

    /// Stage 2: the speed model (eq 5) and the lateral model the hybrid switch picks, with the
    /// steering scaled by the gain the steering check found ([`steering`]; 1 while the model
    /// file's steering agrees with the car's).
    fn run_models(&mut self, inputs: &Snapshot, dt_s: f32) -> Motion {
        let cfg = &self.config;
        let m = &mut self.models;
        let steer_scale = self.steering.scale();
        // Stale steering: the wheels where the last report had them (see `unseen_yaw_rps`).
        let steer_pct = inputs.steer_pct.unwrap_or(m.last_steer_pct);
        m.last_steer_pct = steer_pct;
        let measured_steer_rad = cfg.vehicle.steer_pct_to_center_rad(steer_pct);
        let center_steer_rad = steer_scale * measured_steer_rad;

        // Eq 5: started at equilibrium on the first measured speed, then driven by the
        // commanded speed (or, without a command, by the measured speed: hold).
        if m.velocity.is_none() {
            if let Some((v, _)) = inputs.speeds {
                m.velocity = cfg.velocity.steady_state_for_output(v).ok();
            }
        }
        let speed_cmd_mps = inputs.speeds.map(|(_, c)| c);
        let speed_model_mps = m.velocity.as_mut().map(|state| {
            let u = speed_cmd_mps
                .or(inputs.speeds.map(|(v, _)| v))
                .unwrap_or(m.speed_mps);
            cfg.velocity.step(state, u)
        });
        let speed_mps = math::clamp_finite(
            inputs
                .speeds
                .map(|(v, _)| v)
                .or(speed_model_mps)
                .unwrap_or(0.0),
            0.0,
            cfg.max_speed_mps,
        );
        m.speed_mps = speed_mps;
        // Reversing: the car moves backwards, and the kinematic model's yaw rate takes the
        // motion's sign; the dynamic model (tyre slip angles of a car moving forwards) does
        // not hold, so the car is taken as one without it: the kinematic model, no slip.
        let reversing = inputs.reversing;
        m.reversing = reversing;
        let dynamics = cfg.dynamics.as_ref().filter(|_| !reversing);

        // Stale steering: the models steer with the last report's angle (an actuator holds its
        // last command, and the controllers hold theirs while the report is stale), and the
        // wheels may have turned since, either way, at the actuator's rate over the report's
        // age, at most to the lock: the most the kinematic curvature (without understeer, the
        // most it is) can differ from the one the models use, as a yaw rate at this speed.
        // Steering straight on instead, a car held on a 30 m arc at 10 m/s was dead-reckoned
        // 0.33 rad/s off its turn, and the heading ran 0.21 rad behind exact courses
        // (docs/findings.md).
        m.unseen_yaw_rps = match inputs.steer_pct {
            Some(_) => 0.0,
            None => {
                let age = inputs.ages_10ms.get(Input::Steer as usize).copied();
                let age_s = f32::from(age.unwrap_or(crate::can::freshness::AGE_MAX)) * 0.01;
                let swing_rad = cfg
                    .vehicle
                    .steer_pct_to_center_rad(cfg.max_steer_rate_pct_per_s * age_s);
                let lock_rad = cfg.vehicle.steer_pct_to_center_rad(100.0);
                let held_rad = center_steer_rad.abs();
                let k = |rad: f32| cfg.vehicle.curvature_per_m(rad, 0.0);
                let held = k(held_rad);
                let further = k(math::min(held_rad + swing_rad, lock_rad)) - held;
                let back = held - k(math::max(held_rad - swing_rad, -lock_rad));
                speed_mps * math::max(math::max(further, back), 0.0)
            }
        };
        let yaw_kin =
            signed(speed_mps, reversing) * cfg.vehicle.curvature_per_m(center_steer_rad, speed_mps);
        let mode = match dynamics {
            Some(_) => cfg
                .hybrid
                .update(&mut m.hybrid, speed_mps, speed_mps * m.yaw_rate_rps),
            None => Mode::Kinematic,
        };
        match (mode, dynamics) {
            (Mode::Dynamic, Some(dynamics)) => {
                dynamics.step(&mut m.lateral, speed_mps, center_steer_rad, dt_s);
                m.yaw_rate_rps = m.lateral.yaw_rate_rps;
            }
            (_, dynamics) => {
                m.lateral = match dynamics {
                    Some(d) => d.steady_state(speed_mps, center_steer_rad),
                    None => LateralState {
                        vy_mps: 0.0,
                        yaw_rate_rps: yaw_kin,
                    },
                };
                m.yaw_rate_rps = yaw_kin;
            }
        }
        if !m.yaw_rate_rps.is_finite() {
            m.yaw_rate_rps = 0.0;
            bump(&mut self.inputs.counters.nonfinite);
        }
        // Either mode's lateral state is the dynamic model's when the car has one (its steady
        // state in the kinematic mode), so the rear axle's slip is there in both.
        m.rear_side_mps = match dynamics {
            Some(d) => {
                let side = d.rear_side_mps(&m.lateral);
                let most = MAX_REAR_SLIP_RAD * speed_mps;
                if side.is_finite() {
                    math::clamp(side, -most, most)
                } else {
                    0.0
                }
            }
            None => 0.0,
        };
        Motion {
            speed_mps,
            reversing,
            speed_model_mps,
            speed_cmd_mps,
            center_steer_rad,
            measured_steer_rad,
            steer_scale,
            steer_fresh: inputs.steer_pct.is_some(),
            mode,
        }
    }

    /// Stage 3: heading, filtered rear-axle position, and eq 7 on it.
    fn estimate(&mut self, now_us: u64, motion: &Motion) -> Estimate {
        let cfg = &self.config;
        let velocity_mps = signed(motion.speed_mps, motion.reversing);
        let (pose, gnss_fresh, measured_heading) =
            self.gnss
                .estimate(cfg, now_us, velocity_mps, self.models.rates(), &self.inputs);
        // The check compares the measured turn with the one the steering gave the models: a
        // tick without a steering report gave them none (a sensor logged at 5 Hz, stale
        // between its reports, read as a steering 1.7 times the model file's: a black-box
        // probe, docs/findings.md), and restarts the check's block; so does a negative speed
        // (reversing): the check learns from driving forwards.
        self.steering.observe(
            measured_heading.filter(|_| motion.steer_fresh),
            velocity_mps,
        );
        // Eq 7: inputs [v_m, x, y, phi] with phi the steering angle, rad.
        let dxdt_mps = pose.map(|p| {
            cfg.dxdt.step(
                &mut self.models.dxdt,
                &[motion.speed_mps, p.x_m, p.y_m, motion.measured_steer_rad],
            )
        });
        Estimate {
            pose,
            gnss_fresh,
            heading_corrected: measured_heading.is_some(),
            dxdt_mps,
        }
    }

    /// Stage 4: the controller's commands (CONTROL_COMMAND), and its plan while it drives.
    fn run_drive<P: StageProbe>(
        &mut self,
        motion: &Motion,
        estimate: &Estimate,
        steer_report_pct: Option<f32>,
        probe: &mut P,
    ) -> DriveOutput {
        let inputs = DriveInputs {
            pose: estimate.pose,
            dead_reckoned: self.gnss.dead_reckoned(),
            heading_var_rad2: self.gnss.heading_var_rad2(),
            heading_corrected: estimate.heading_corrected,
            speed_mps: motion.speed_mps,
            reversing: motion.reversing,
            lateral: self.models.lateral,
            rear_side_mps: self.models.rear_side_mps,
            steer_rad: motion.center_steer_rad,
            steer_report_pct,
            steer_scale: motion.steer_scale,
            mode: motion.mode,
            speed_model: self.models.velocity.as_ref(),
        };
        self.drive.borrow_mut().tick(&self.config, &inputs, probe)
    }

    /// Stage 5: the horizon into `points`; returns how many were predicted. Without fresh
    /// steering the path ahead is unknown: no predictions (the state still goes out, flagged
    /// `steer_stale`).
    fn predict(
        &self,
        inputs: &Snapshot,
        motion: &Motion,
        estimate: &Estimate,
        points: &mut [PredictedPoint; PREDICTION_POINTS],
    ) -> usize {
        let cfg = &self.config;
        let (Some(pose), Some(velocity), Some(v_model), Some(_)) = (
            estimate.pose,
            self.models.velocity.as_ref(),
            motion.speed_model_mps,
            inputs.steer_pct,
        ) else {
            return 0;
        };
        let start = PredictorStart {
            pose,
            speed_mps: motion.speed_mps,
            speed_bias_mps: motion.speed_mps - v_model,
            center_steer_rad: motion.center_steer_rad,
            lateral: self.models.lateral,
            mode: motion.mode,
            reversing: motion.reversing,
        };
        // Eq 5 along the horizon: the commands in its delay line, then the latest one held.
        let u_hold = motion.speed_cmd_mps.unwrap_or(motion.speed_mps);
        let mut speeds = cfg.velocity.forecast(velocity, u_hold);
        predictor::rollout(
            &cfg.horizon,
            &cfg.vehicle,
            cfg.dynamics.as_ref(),
            &start,
            |block| speeds.fill(block),
            points,
        )
    }

    /// Stage 6: this tick's frames.
    #[allow(clippy::too_many_arguments)]
    fn publish(
        &mut self,
        tick: &Tick,
        inputs: &Snapshot,
        motion: &Motion,
        estimate: &Estimate,
        predictions: &[PredictedPoint],
        drive: &DriveOutput,
        tx: &mut TxFrames,
    ) {
        let out = publish::Outputs {
            pose: estimate.pose,
            heading_uncertain: self.gnss.heading_var_rad2()
                > HEADING_UNCERTAIN_ABOVE_RAD * HEADING_UNCERTAIN_ABOVE_RAD
                || self.gnss.direction_ambiguous(),
            gnss_fresh: estimate.gnss_fresh,
            gnss_rejected_us: self.gnss.last_reject_us(),
            gnss_rate_mismatch: self.gnss.rate_mismatch(),
            steering_mismatch: self.steering.mismatch() || self.drive.borrow().steering_reversed(),
            outside_corridor: drive.outside_corridor_m > drive::OUTSIDE_CORRIDOR_M,
            mode: motion.mode,
            speed_mps: motion.speed_mps,
            yaw_rate_rps: self.models.yaw_rate_rps,
            speed_model_mps: motion.speed_model_mps,
            dxdt_mps: estimate.dxdt_mps,
            predictions,
            command: drive.command,
        };
        self.health
            .publish(tick, inputs, &mut self.inputs.counters, &out, tx);
    }
}

/// Whether `input` is fresh at `now_us` (see [`FreshnessConfig`]).
fn fresh(
    config: &NodeConfig,
    freshness: &crate::can::freshness::Freshness,
    input: Input,
    now_us: u64,
) -> bool {
    freshness.is_fresh(&config.freshness, input, now_us)
}
