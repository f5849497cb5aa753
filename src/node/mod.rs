//! `Node`: one pure 20 ms step that takes the frames received since the last tick and the tick
//! time, and returns the frames to send. The board, QEMU and host replay run exactly this code,
//! so `catmodel replay --tx-out` and the QEMU run produce byte-identical frames.
//!
//! Each tick: decode and validate the received frames (CRC, rolling counter, DLC, range; GNSS
//! range and a plausibility gate), every rejection counted; update freshness; feed GNSS fixes
//! through the paper's lowpass with its group delay compensated ([`estimator`]); estimate the
//! heading; step the velocity model (eq 5), the dx/dt model (eq 7) and the active lateral model
//! (hybrid switch); roll the horizon forward; encode the output frames.
//!
//! Never panics on bus data, never allocates, never reads a clock; every output value is
//! checked finite before it is encoded (non-finite values go out as "not available" and are
//! counted, health bit `nonfinite_guard`).
pub mod baked {
    //! The model file baked in at build time (build.rs: `models/paper.toml`, or
    //! `$CATMODEL_MODEL`): what the firmware runs.
    use super::NodeModels;
    use crate::model::hybrid::HybridConfig;
    use crate::model::tf::{ModelError, TransferFunction};
    use crate::vehicle::VehicleParams;
    include!(concat!(env!("OUT_DIR"), "/baked_model.rs"));
}
pub mod estimator;

use crate::can::codec::{
    decode_input, DecodeError, EncodeReport, HealthFlags, InputMessage, ModelMode, ModelOutputs,
    NodeStatus, Prediction, PredictionPoint, StateMotion, StatePosition,
};
use crate::can::{freshness, CanFrame, TimedFrame};
use crate::geodesy::LocalFrame;
use crate::model::block::{MisoBlock, MisoBlockState, SsBlock, SsBlockState};
use crate::model::dynamic::{DynamicParams, LateralState, CAT_VEHICLE_DYNAMICS};
use crate::model::hybrid::{HybridConfig, HybridState, Mode, DEFAULT_HYBRID};
use crate::model::kinematic::Pose;
use crate::model::paper;
use crate::model::predictor::{self, HorizonConfig, PredictedPoint, PredictorStart};
use crate::model::tf::{ModelError, TransferFunction};
use crate::vehicle::{VehicleParams, CAT_VEHICLE};
use crate::{math, SAMPLE_PERIOD_S, SAMPLE_PERIOD_US};
use estimator::{EstimatorConfig, EstimatorState, Xy};

/// Most frames one tick can send: 2 state frames, 10 predictions, 1 status page and the
/// controller's command are 14; 16 leaves room.
pub const MAX_TX_FRAMES: usize = 16;
/// Prediction points on the bus (PREDICTION_1..10, every 0.2 s up to 2.0 s).
pub const PREDICTION_POINTS: usize = 10;
/// Longest velocity-model input delay a model file may have: 64 samples = 1.28 s (eq 5 has
/// 21; models identified on the simulator's delayed, lagging speed loop reach ~48); the
/// predictor copies this buffer every tick, so it is not larger.
pub const VELOCITY_DELAY_CAP: usize = 64;
/// Status pages, one per tick, cycling.
const STATUS_PAGES: u32 = crate::can::spec::STATUS_PAGES as u32;

/// The frames one tick sends, in transmit order.
pub type TxFrames = heapless::Vec<CanFrame, MAX_TX_FRAMES>;

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

/// The first tick's time for a stream whose first frame arrived at `first_frame_us`: rounded up
/// to a whole multiple of the 20 ms period (docs/architecture.md, "Tick schedule").
pub const fn first_tick_us(first_frame_us: u64) -> u64 {
    first_frame_us.div_ceil(SAMPLE_PERIOD_US) * SAMPLE_PERIOD_US
}

/// Input timeouts, us (PX4-style `is_timed_out`; Dataspeed: 100 ms for 50 Hz reports).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Timeouts {
    /// Steering report.
    pub steer_us: u64,
    /// Speed report.
    pub speed_us: u64,
    /// Pedal report.
    pub pedal_us: u64,
    /// GNSS position: after this the position is dead-reckoned and flagged.
    pub gnss_us: u64,
    /// GNSS silent this long: the position is no longer trusted (invalid, filters restart).
    pub gnss_lost_us: u64,
}

/// 100 ms for the 50 Hz reports (5 missed frames), 200 ms for 100 Hz GNSS, 2 s of dead
/// reckoning at most.
pub const DEFAULT_TIMEOUTS: Timeouts = Timeouts {
    steer_us: 100_000,
    speed_us: 100_000,
    pedal_us: 100_000,
    gnss_us: 200_000,
    gnss_lost_us: 2_000_000,
};

/// Everything the node is configured with. Immutable.
#[derive(Clone, Debug)]
pub struct NodeConfig {
    /// Geometry and steering conversion (eq 2-4).
    pub vehicle: VehicleParams,
    /// Dynamic bicycle model.
    pub dynamics: DynamicParams,
    /// Hybrid switching thresholds.
    pub hybrid: HybridConfig,
    /// Horizon shape.
    pub horizon: HorizonConfig,
    /// GNSS lowpass, delay compensation, heading.
    pub estimator: EstimatorConfig,
    /// GNSS fix period, s (the rate the lowpass was designed for).
    pub gnss_period_s: f32,
    /// Internal-controller model, commanded speed -> speed (eq 5), with its input delay.
    pub velocity: SsBlock<2, VELOCITY_DELAY_CAP>,
    /// dx/dt model with inputs [v_m, x, y, phi] (eq 7).
    pub dxdt: MisoBlock<2, 4, 1>,
    /// NMEA 2000 source address of the GNSS receiver.
    pub gnss_source: u8,
    /// Local frame origin (lat, lon in 1e-7 deg); `None` = the first valid fix.
    pub origin_e7: Option<(i32, i32)>,
    /// Input timeouts.
    pub timeouts: Timeouts,
    /// A fix farther than this from the predicted position is rejected, m.
    pub gnss_gate_m: f32,
    /// After this many consecutive gate rejections the fixes win: the filters restart there.
    pub gnss_reacquire_fixes: u16,
    /// Speeds are clamped to [0, this], m/s.
    pub max_speed_mps: f32,
}

/// What a model file carries (`models/paper.toml`, or one `catmodel identify` wrote): the
/// vehicle, the hybrid thresholds and the identified continuous-time models, discretized
/// (ZOH, f64) when the node is configured.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NodeModels {
    /// Geometry and steering conversion (eq 2-4).
    pub vehicle: VehicleParams,
    /// Hybrid switching thresholds.
    pub hybrid: HybridConfig,
    /// Commanded speed -> speed, with its input delay (eq 5's role); at most 2nd order.
    pub velocity: TransferFunction,
    /// dx/dt from [v_m, x, y, phi] (eq 7's role).
    pub dxdt: [TransferFunction; 4],
    /// Sample time, s (0.02: a delay must be a whole number of samples).
    pub ts_s: f64,
}

impl NodeModels {
    /// The published models (eq 5, eq 7) on the CAT Vehicle.
    pub const fn paper() -> Self {
        Self {
            vehicle: CAT_VEHICLE,
            hybrid: DEFAULT_HYBRID,
            velocity: paper::EQ5_INTERNAL_CONTROLLER,
            dxdt: paper::EQ7_DX_DT,
            // f64 0.02 exactly: f64::from(0.02f32) would make 0.42 s a fractional delay.
            ts_s: paper::PAPER_TS_S,
        }
    }
}

impl NodeConfig {
    /// The models baked in at build time (see [`baked`]): the firmware's configuration.
    pub fn baked() -> Result<Self, ModelError> {
        Self::with_models(&baked::baked_models()?)
    }

    /// The published models (eq 5, eq 7) on the CAT Vehicle, the paper's GNSS lowpass (20th
    /// order FIR, cutoff 2 Hz at the receiver's 100 Hz, then a 10-sample moving average).
    pub fn paper() -> Result<Self, ModelError> {
        Self::with_models(&NodeModels::paper())
    }

    /// The node for `models`, with the paper's GNSS lowpass and the default timeouts and
    /// gates. Fails if a model cannot be realized in the node's fixed-size blocks (speed model
    /// above 2nd order, delay beyond the delay line, not a whole number of samples, unstable
    /// discretization producing non-finite matrices).
    pub fn with_models(models: &NodeModels) -> Result<Self, ModelError> {
        let velocity = SsBlock::from_tf(&models.velocity, models.ts_s)?;
        let dxdt = MisoBlock::from_tfs(&models.dxdt, models.ts_s)?;
        let estimator =
            EstimatorConfig::paper(GNSS_RATE_HZ, GNSS_CUTOFF_HZ, CAT_VEHICLE_ANTENNA_AHEAD_M)
                .ok_or(ModelError::NotFinite)?;
        Ok(Self {
            vehicle: models.vehicle,
            dynamics: CAT_VEHICLE_DYNAMICS,
            hybrid: models.hybrid,
            horizon: predictor::DEFAULT_HORIZON,
            estimator,
            gnss_period_s: (1.0 / GNSS_RATE_HZ) as f32,
            velocity,
            dxdt,
            gnss_source: crate::can::spec::N2K_DEFAULT_SOURCE,
            origin_e7: None,
            timeouts: DEFAULT_TIMEOUTS,
            gnss_gate_m: 10.0,
            gnss_reacquire_fixes: 100,
            max_speed_mps: 60.0,
        })
    }
}

/// GNSS rate of the paper's receiver (NovAtel, "every 0.01 seconds", paper II-B), Hz.
pub const GNSS_RATE_HZ: f64 = 100.0;
/// GNSS antenna ahead of the rear axle on the CAT Vehicle, m: above the centre of gravity
/// (CG to rear axle 1.478 m), where the simulator mounts it. The predicted positions are the
/// rear axle's (eq 8's reference point).
pub const CAT_VEHICLE_ANTENNA_AHEAD_M: f32 = 1.478;
/// Lowpass cutoff for GNSS, Hz: passes the car's motion (manoeuvres < 1 Hz), removes the
/// receiver's white noise.
pub const GNSS_CUTOFF_HZ: f64 = 2.0;

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
    /// Identifiers the node does not know (or GNSS from another source).
    pub unknown_ids: u32,
    /// Frames stamped after the tick that received them (clock mismatch), rejected.
    pub time_errors: u32,
    /// Output values replaced because they were not finite.
    pub nonfinite: u32,
    /// Output values saturated to their field's range.
    pub saturated: u32,
}

fn bump(c: &mut u32) {
    *c = c.saturating_add(1);
}

/// Latest value of a 50 Hz input with its time and rolling counter.
#[derive(Clone, Copy, Debug, Default)]
struct Latest<T> {
    value: Option<T>,
    t_us: Option<u64>,
    counter: Option<u8>,
}

impl<T: Copy> Latest<T> {
    /// Accepts a report unless its counter did not change (a stuck sender repeating itself);
    /// a jump (missed frames) is counted but the value is used. Returns false if rejected.
    fn accept(&mut self, value: T, counter: u8, t_us: u64, counters: &mut Counters) -> bool {
        if let Some(prev) = self.counter {
            if prev == counter {
                bump(&mut counters.counter_errors);
                return false;
            }
            if (prev + 1) & 0x0F != counter {
                bump(&mut counters.counter_errors);
            }
        }
        self.counter = Some(counter);
        self.value = Some(value);
        self.t_us = Some(t_us);
        true
    }

    fn fresh(&self, now_us: u64, timeout_us: u64) -> Option<T> {
        match self.t_us {
            Some(t) if now_us.saturating_sub(t) <= timeout_us => self.value,
            _ => None,
        }
    }
}

/// The node's mutable state.
#[derive(Clone, Debug)]
pub struct Node {
    config: NodeConfig,
    frame: Option<LocalFrame>,
    estimator: EstimatorState,
    velocity: Option<SsBlockState<2, VELOCITY_DELAY_CAP>>,
    dxdt: MisoBlockState<2, 4, 1>,
    lateral: LateralState,
    hybrid: HybridState,
    steer_pct: Latest<f32>,
    speed: Latest<(f32, f32)>,
    pedal: Latest<(f32, f32)>,
    gnss_t_us: Option<u64>,
    cog: Option<(f32, u64)>,
    gnss_rejects_in_row: u16,
    last_gnss_reject_us: Option<u64>,
    yaw_rate_rps: f32,
    speed_mps: f32,
    last_tick_us: Option<u64>,
    tick_count: u32,
    counters: Counters,
    last_report: EncodeReport,
    /// Platform overrun count seen at the previous tick, and when it last grew.
    overruns_seen: u32,
    last_overrun_us: Option<u64>,
    /// Range errors at the previous tick, and when they last grew.
    range_errors_seen: u32,
    last_range_error_us: Option<u64>,
}

/// "Recently" in the health bits: within the last second, us.
const RECENT_US: u64 = 1_000_000;

/// `Some(t)` within [`RECENT_US`] of `now`.
fn recent(now_us: u64, t_us: Option<u64>) -> bool {
    matches!(t_us, Some(t) if now_us.saturating_sub(t) <= RECENT_US)
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
}

impl Node {
    /// A node with fresh state.
    pub fn new(config: NodeConfig) -> Self {
        let dxdt = config.dxdt.zero_state();
        Self {
            config,
            frame: None,
            estimator: EstimatorState::default(),
            velocity: None,
            dxdt,
            lateral: LateralState::default(),
            hybrid: HybridState::default(),
            steer_pct: Latest::default(),
            speed: Latest::default(),
            pedal: Latest::default(),
            gnss_t_us: None,
            cog: None,
            gnss_rejects_in_row: 0,
            last_gnss_reject_us: None,
            yaw_rate_rps: 0.0,
            speed_mps: 0.0,
            last_tick_us: None,
            tick_count: 0,
            counters: Counters::default(),
            last_report: EncodeReport::default(),
            overruns_seen: 0,
            last_overrun_us: None,
            range_errors_seen: 0,
            last_range_error_us: None,
        }
    }

    /// The configuration.
    pub fn config(&self) -> &NodeConfig {
        &self.config
    }

    /// Rejection counters since start.
    pub fn counters(&self) -> &Counters {
        &self.counters
    }

    /// Ticks run.
    pub fn tick_count(&self) -> u32 {
        self.tick_count
    }

    /// The local frame's origin once known (lat, lon in 1e-7 deg).
    pub fn origin_e7(&self) -> Option<(i32, i32)> {
        self.frame.map(|f| (f.origin_lat_e7(), f.origin_lon_e7()))
    }

    /// Runs one tick: consumes `rx` (frames with `t_us <= tick.now_us`, in arrival order) and
    /// appends this tick's frames to `tx`. Returns what the tick estimated.
    pub fn step(&mut self, tick: &Tick, rx: &[TimedFrame], tx: &mut TxFrames) -> TickEstimate {
        let now = tick.now_us;
        let dt_s = match self.last_tick_us {
            // Missed ticks (overruns) are propagated over the real elapsed time, at most 0.1 s.
            Some(prev) if now > prev => math::u64_to_f32((now - prev).min(100_000)) * 1e-6,
            _ => SAMPLE_PERIOD_S,
        };
        self.last_tick_us = Some(now);
        self.estimator.propagate(
            &self.config.estimator,
            self.speed_mps,
            self.yaw_rate_rps,
            dt_s,
        );

        for f in rx {
            self.receive(now, f);
        }

        let cfg = &self.config;
        let to = cfg.timeouts;
        let steer_pct = self.steer_pct.fresh(now, to.steer_us);
        let speeds = self.speed.fresh(now, to.speed_us);
        let center_steer_rad = cfg
            .vehicle
            .steer_pct_to_center_rad(steer_pct.unwrap_or(0.0));

        // Velocity model (eq 5): started at equilibrium on the first measured speed, then driven
        // by the commanded speed (or, without a command, by the measured speed: hold).
        if self.velocity.is_none() {
            if let Some((v, _)) = speeds {
                self.velocity = cfg.velocity.steady_state_for_output(v).ok();
            }
        }
        let speed_cmd = speeds.map(|(_, c)| c);
        let mut speed_model = None;
        if let Some(state) = self.velocity.as_mut() {
            let u = speed_cmd
                .or(speeds.map(|(v, _)| v))
                .unwrap_or(self.speed_mps);
            speed_model = Some(cfg.velocity.step(state, u));
        }
        let speed_mps = clamp_finite(
            speeds.map(|(v, _)| v).or(speed_model).unwrap_or(0.0),
            0.0,
            cfg.max_speed_mps,
        );
        self.speed_mps = speed_mps;

        // Lateral model and hybrid switch.
        let yaw_kin = speed_mps * cfg.vehicle.curvature_per_m(center_steer_rad, speed_mps);
        let mode = cfg
            .hybrid
            .update(&mut self.hybrid, speed_mps, speed_mps * self.yaw_rate_rps);
        match mode {
            Mode::Kinematic => {
                self.lateral = cfg.dynamics.steady_state(speed_mps, center_steer_rad);
                self.yaw_rate_rps = yaw_kin;
            }
            Mode::Dynamic => {
                cfg.dynamics
                    .step(&mut self.lateral, speed_mps, center_steer_rad, dt_s);
                self.yaw_rate_rps = self.lateral.yaw_rate_rps;
            }
        }
        if !self.yaw_rate_rps.is_finite() {
            self.yaw_rate_rps = 0.0;
            bump(&mut self.counters.nonfinite);
        }

        // Heading: receiver COG when fresh and moving, else the filtered track's course.
        let moving = speed_mps >= cfg.estimator.course_min_speed_mps;
        match self.cog {
            Some((cog, t)) if moving && now.saturating_sub(t) <= to.gnss_us => {
                let age_s = math::u64_to_f32(now.saturating_sub(t)) * 1e-6;
                self.estimator.correct_heading(
                    &cfg.estimator,
                    cog,
                    age_s,
                    speed_mps,
                    self.yaw_rate_rps,
                );
            }
            _ if moving => {
                if let Some((course, age_fixes)) = self.estimator.track_course(&cfg.estimator) {
                    let age_s = age_fixes * cfg.gnss_period_s;
                    self.estimator.correct_heading(
                        &cfg.estimator,
                        course,
                        age_s,
                        speed_mps,
                        self.yaw_rate_rps,
                    );
                }
            }
            _ => {}
        }

        // Position: filtered and delay-compensated; dead-reckoned through short GNSS gaps.
        let gnss_age = self.gnss_t_us.map(|t| now.saturating_sub(t));
        let gnss_fresh = matches!(gnss_age, Some(a) if a <= to.gnss_us);
        if matches!(gnss_age, Some(a) if a > to.gnss_lost_us) && self.estimator.fixes() > 0 {
            self.estimator.reset();
        }
        let pose = match (
            self.estimator.position(&cfg.estimator),
            self.estimator.heading_rad(),
        ) {
            (Some(p), Some(h)) if p.x_m.is_finite() && p.y_m.is_finite() && h.is_finite() => {
                Some(Pose::new(p.x_m, p.y_m, h))
            }
            _ => None,
        };

        // dx/dt model (eq 7): inputs [v_m, x, y, phi] with phi the steering angle, rad.
        let dxdt = pose.map(|p| {
            cfg.dxdt
                .step(&mut self.dxdt, &[speed_mps, p.x_m, p.y_m, center_steer_rad])
        });

        // Horizon.
        let mut points = [PredictedPoint::default(); PREDICTION_POINTS];
        let mut n_points = 0;
        // Without fresh steering the path ahead is unknown: no predictions (the state still
        // goes out, flagged `steer_stale`).
        let rollout_inputs = match (pose, self.velocity, speed_model, steer_pct) {
            (Some(p), Some(v), Some(m), Some(_)) => Some((p, v, m)),
            _ => None,
        };
        if let Some((p, vel_state, v_model)) = rollout_inputs {
            let mut rollout_state = vel_state;
            let start = PredictorStart {
                pose: p,
                speed_mps,
                speed_bias_mps: speed_mps - v_model,
                speed_cmd_mps: speed_cmd.unwrap_or(speed_mps),
                center_steer_rad,
                lateral: self.lateral,
                mode,
            };
            let velocity = &cfg.velocity;
            n_points = predictor::rollout(
                &cfg.horizon,
                &cfg.vehicle,
                &cfg.dynamics,
                &start,
                |u| velocity.step(&mut rollout_state, u),
                &mut points,
            );
        }

        // Outputs.
        let counter = (self.tick_count & 0x0F) as u8;
        let mut report = EncodeReport::default();
        let gnss_rejected = recent(now, self.last_gnss_reject_us);
        if tick.platform.overruns > self.overruns_seen {
            self.last_overrun_us = Some(now);
        }
        self.overruns_seen = tick.platform.overruns;
        if self.counters.range_errors > self.range_errors_seen {
            self.last_range_error_us = Some(now);
        }
        self.range_errors_seen = self.counters.range_errors;
        let model_mode = match mode {
            Mode::Kinematic => ModelMode::Kinematic,
            Mode::Dynamic => ModelMode::Dynamic,
        };
        let mut push = |(frame, r): (CanFrame, EncodeReport), report: &mut EncodeReport| {
            report.merge(&r);
            // Note: capacity 16 >= 2 + 10 + 1 frames; a full buffer would only lose frames
            // already counted in `MAX_TX_FRAMES`'s derivation.
            let _ = tx.push(frame);
        };
        push(
            StatePosition {
                position_valid: pose.is_some(),
                gnss_fresh,
                gnss_rejected,
                east_m: pose.map(|p| p.x_m),
                north_m: pose.map(|p| p.y_m),
            }
            .encode_with_report(counter),
            &mut report,
        );
        push(
            StateMotion {
                mode: model_mode,
                heading_rad: pose.map(|p| p.heading_rad),
                speed_mps: Some(speed_mps),
                yaw_rate_radps: Some(self.yaw_rate_rps),
            }
            .encode_with_report(counter),
            &mut report,
        );
        for (i, point) in PredictionPoint::all().enumerate() {
            let predicted = match (pose, points.get(i)) {
                (Some(p), Some(q)) if i < n_points => Some((p, q)),
                _ => None,
            };
            push(
                Prediction {
                    point,
                    dx_m: predicted.map(|(p, q)| q.x_m - p.x_m),
                    dy_m: predicted.map(|(p, q)| q.y_m - p.y_m),
                    dheading_rad: predicted
                        .map(|(p, q)| math::wrap_pi(q.heading_rad - p.heading_rad)),
                    speed_mps: predicted.map(|(_, q)| q.speed_mps),
                }
                .encode_with_report(counter),
                &mut report,
            );
        }
        let c = self.counters;
        let ages = [
            freshness::age_10ms(now, self.steer_pct.t_us),
            freshness::age_10ms(now, self.speed.t_us),
            freshness::age_10ms(now, self.pedal.t_us),
            freshness::age_10ms(now, self.gnss_t_us),
        ];
        let status = match self.tick_count % STATUS_PAGES {
            0 => NodeStatus::Health {
                mode: model_mode,
                health: HealthFlags {
                    steer_stale: steer_pct.is_none(),
                    speed_stale: speeds.is_none(),
                    pedal_stale: self.pedal.fresh(now, to.pedal_us).is_none(),
                    gnss_stale: !gnss_fresh,
                    gnss_rejected_recently: gnss_rejected,
                    position_invalid: pose.is_none(),
                    prediction_saturated: self.last_report.saturated > 0,
                    nonfinite_guard: self.last_report.non_finite > 0 || c.nonfinite > 0,
                    watchdog_reset: tick.platform.watchdog_reset,
                    overrun_recently: recent(now, self.last_overrun_us),
                    input_invalid: recent(now, self.last_range_error_us),
                },
                overrun_count: tick.platform.overruns,
                last_step_us: tick.platform.last_step_us,
            },
            1 => NodeStatus::RxErrors {
                crc_errors: c.crc_errors,
                counter_errors: c.counter_errors,
                dlc_errors: c.dlc_errors,
            },
            2 => NodeStatus::RxRejects {
                range_errors: c.range_errors,
                gnss_gate_rejects: c.gnss_gate_rejects,
                unknown_ids: c.unknown_ids,
            },
            3 => NodeStatus::Platform {
                tick_count: self.tick_count,
                rx_queue_drops: tick.platform.rx_queue_drops,
            },
            4 => NodeStatus::Ages {
                ages_10ms: ages,
                stack_high_water_bytes: tick.platform.stack_high_water_bytes,
            },
            _ => NodeStatus::Model(ModelOutputs {
                speed_model_mps: speed_model,
                dxdt_model_mps: dxdt,
                lat_accel_mps2: Some(speed_mps * self.yaw_rate_rps),
            }),
        };
        push(status.encode_with_report(counter), &mut report);
        self.counters.nonfinite = self
            .counters
            .nonfinite
            .saturating_add(u32::from(report.non_finite));
        self.counters.saturated = self
            .counters
            .saturated
            .saturating_add(u32::from(report.saturated));
        self.last_report = report;
        self.tick_count = self.tick_count.wrapping_add(1);
        TickEstimate {
            pose,
            speed_mps,
            mode,
        }
    }

    /// Decodes and applies one received frame; every rejection is counted.
    fn receive(&mut self, now_us: u64, f: &TimedFrame) {
        if f.t_us > now_us {
            bump(&mut self.counters.time_errors);
            return;
        }
        let msg = match decode_input(&f.frame, self.config.gnss_source) {
            Ok(m) => m,
            Err(e) => {
                let c = &mut self.counters;
                bump(match e {
                    DecodeError::Crc { .. } => &mut c.crc_errors,
                    DecodeError::Dlc { .. } => &mut c.dlc_errors,
                    DecodeError::OutOfRange { .. } | DecodeError::Invalid { .. } => {
                        &mut c.range_errors
                    }
                    DecodeError::UnknownId
                    | DecodeError::WrongId
                    | DecodeError::WrongSource { .. } => &mut c.unknown_ids,
                });
                return;
            }
        };
        match msg {
            InputMessage::Steering(m, counter) => match m.steer_pct {
                Some(p) => {
                    self.steer_pct
                        .accept(p, counter, f.t_us, &mut self.counters);
                }
                None => bump(&mut self.counters.range_errors),
            },
            InputMessage::Speed(m, counter) => match (m.speed_mps, m.speed_cmd_mps) {
                (Some(v), cmd) => {
                    let cmd = cmd.unwrap_or(v);
                    self.speed
                        .accept((v, cmd), counter, f.t_us, &mut self.counters);
                }
                _ => bump(&mut self.counters.range_errors),
            },
            InputMessage::Pedal(m, counter) => {
                let value = (m.accel_pct.unwrap_or(0.0), m.brake_pct.unwrap_or(0.0));
                self.pedal
                    .accept(value, counter, f.t_us, &mut self.counters);
            }
            InputMessage::GnssPosition(p) => self.receive_fix(now_us, f.t_us, p.lat_e7, p.lon_e7),
            InputMessage::GnssCogSog(c) => {
                if let (Some(cog), Some(sog)) = (c.cog_rad, c.sog_mps) {
                    // COG is meaningless when standing still.
                    if sog >= self.config.estimator.course_min_speed_mps && c.cog_reference == 0 {
                        self.cog = Some((math::wrap_pi(cog), f.t_us));
                    }
                }
            }
        }
    }

    fn receive_fix(&mut self, now_us: u64, t_us: u64, lat_e7: i32, lon_e7: i32) {
        if self.frame.is_none() {
            let origin = self.config.origin_e7.unwrap_or((lat_e7, lon_e7));
            match LocalFrame::new(origin.0, origin.1) {
                Ok(frame) => self.frame = Some(frame),
                Err(_) => {
                    bump(&mut self.counters.gnss_gate_rejects);
                    return;
                }
            }
        }
        let Some(enu) = self.frame.and_then(|fr| fr.to_local(lat_e7, lon_e7).ok()) else {
            bump(&mut self.counters.gnss_gate_rejects);
            self.last_gnss_reject_us = Some(t_us);
            return;
        };
        let fix = Xy {
            x_m: enu.east_m,
            y_m: enu.north_m,
        };
        let cfg = &self.config;
        // Plausibility gate against where the car should be; repeated rejections mean the car
        // really is there (e.g. after a long gap): restart the filters on the fixes.
        if let Some(p) = self.estimator.antenna_position(&cfg.estimator) {
            let (dx, dy) = (fix.x_m - p.x_m, fix.y_m - p.y_m);
            if dx * dx + dy * dy > cfg.gnss_gate_m * cfg.gnss_gate_m {
                self.gnss_rejects_in_row = self.gnss_rejects_in_row.saturating_add(1);
                bump(&mut self.counters.gnss_gate_rejects);
                self.last_gnss_reject_us = Some(t_us);
                if self.gnss_rejects_in_row < cfg.gnss_reacquire_fixes {
                    return;
                }
                self.estimator.reset();
            }
        }
        self.gnss_rejects_in_row = 0;
        let age_s = math::u64_to_f32(now_us.saturating_sub(t_us)) * 1e-6;
        // The lowpass assumes one fix per period. Fixes missing since the last accepted one
        // (a dropout, or fixes the gate rejected) are filled with where dead reckoning puts
        // the antenna at those instants, oldest first; no more than the filters remember.
        if let Some(prev) = self.gnss_t_us {
            let gap_periods =
                math::u64_to_f32(t_us.saturating_sub(prev)) * 1e-6 / cfg.gnss_period_s;
            let missing = ((gap_periods + 0.5) as u32)
                .saturating_sub(1)
                .min(estimator::GAP_FILL_MAX_FIXES);
            for k in (1..=missing).rev() {
                let age_k = age_s + k as f32 * cfg.gnss_period_s;
                if let Some(p) =
                    self.estimator
                        .dead_reckoned_antenna(&cfg.estimator, age_k, self.speed_mps)
                {
                    self.estimator
                        .add_fix(&cfg.estimator, p, age_k, self.speed_mps);
                }
            }
        }
        self.estimator
            .add_fix(&cfg.estimator, fix, age_s, self.speed_mps);
        self.gnss_t_us = Some(t_us);
    }
}

/// `v` limited to [lo, hi], `lo` if not finite. Comparisons only: `f32::clamp` asserts
/// `lo <= hi` with a formatted panic message, which links float formatting (~20 KiB of flash).
fn clamp_finite(v: f32, lo: f32, hi: f32) -> f32 {
    if !v.is_finite() {
        return lo;
    }
    let mut x = v;
    if x < lo {
        x = lo;
    }
    if x > hi {
        x = hi;
    }
    x
}
