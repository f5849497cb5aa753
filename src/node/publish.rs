//! Stage 6, publish: the tick's frames in transmit order: STATE_POSITION, STATE_MOTION,
//! PREDICTION_1..10 (relative to the current pose), one NODE_STATUS page (the pages cycle;
//! page 5 carries the models' outputs) and CONTROL_COMMAND. All share the tick's rolling counter. Every value is checked finite and
//! saturated to its field by the codec; what was substituted is counted and flagged in the next
//! health page.
use crate::can::codec::{
    ControlCommand, EncodeReport, HealthFlags, ModelMode, ModelOutputs, NodeStatus, Prediction,
    PredictionPoint, StateMotion, StatePosition,
};
use crate::can::CanFrame;
use crate::math;
use crate::model::hybrid::Mode;
use crate::model::kinematic::Pose;
use crate::model::predictor::PredictedPoint;

use super::inputs::Snapshot;
use super::{Counters, Tick, TxFrames};

/// Status pages, one per tick, cycling.
const STATUS_PAGES: u32 = crate::can::spec::STATUS_PAGES as u32;
/// "Recently" in the health bits: within the last second, us.
const RECENT_US: u64 = 1_000_000;

/// `Some(t)` within [`RECENT_US`] of `now`.
fn recent(now_us: u64, t_us: Option<u64>) -> bool {
    matches!(t_us, Some(t) if now_us.saturating_sub(t) <= RECENT_US)
}

/// What the earlier stages produced, for the frames.
#[derive(Clone, Copy, Debug)]
pub struct Outputs<'a> {
    /// Filtered rear-axle pose; `None` while invalid.
    pub pose: Option<Pose>,
    /// The heading's standard deviation is above [`super::HEADING_UNCERTAIN_ABOVE_RAD`], or
    /// the track ran against it and no turn has confirmed it since.
    pub heading_uncertain: bool,
    /// GNSS within its timeout.
    pub gnss_fresh: bool,
    /// When a fix was last rejected.
    pub gnss_rejected_us: Option<u64>,
    /// The receiver's fixes come at another rate than the model file declares.
    pub gnss_rate_mismatch: bool,
    /// The node uses a steering gain other than the model file's.
    pub steering_mismatch: bool,
    /// The body is outside the corridor ([`crate::node::drive::DriveOutput`]).
    pub outside_corridor: bool,
    /// Lateral model in use.
    pub mode: Mode,
    /// Speed used, m/s.
    pub speed_mps: f32,
    /// Yaw rate of the active lateral model, rad/s.
    pub yaw_rate_rps: f32,
    /// Eq 5's output, m/s.
    pub speed_model_mps: Option<f32>,
    /// Eq 7's output, m/s.
    pub dxdt_mps: Option<f32>,
    /// The predicted points (empty without a prediction).
    pub predictions: &'a [PredictedPoint],
    /// The controller's command.
    pub command: ControlCommand,
}

/// The publishing stage's state: the tick counter and what the health bits remember.
#[derive(Clone, Copy, Debug, Default)]
pub struct Health {
    /// Ticks run.
    pub tick_count: u32,
    /// What the previous tick's encoding substituted.
    last_report: EncodeReport,
    /// Platform overrun count seen at the previous tick, and when it last grew.
    overruns_seen: u32,
    last_overrun_us: Option<u64>,
    /// Range errors at the previous tick, and when they last grew.
    range_errors_seen: u32,
    last_range_error_us: Option<u64>,
    /// When the node last refused a planner frame or path ([`Health::planner_refused`]).
    last_planner_reject_us: Option<u64>,
}

impl Health {
    /// The node refused a planner frame or path at `now_us` (stage 1, as the frame arrives:
    /// nothing to compare in the ticks without planner frames).
    pub fn planner_refused(&mut self, now_us: u64) {
        self.last_planner_reject_us = Some(now_us);
    }

    /// Appends this tick's frames to `tx` and advances the tick counter.
    pub fn publish(
        &mut self,
        tick: &Tick,
        inputs: &Snapshot,
        counters: &mut Counters,
        out: &Outputs<'_>,
        tx: &mut TxFrames,
    ) {
        let now = tick.now_us;
        let counter = (self.tick_count & 0x0F) as u8;
        let mut report = EncodeReport::default();
        if tick.platform.overruns > self.overruns_seen {
            self.last_overrun_us = Some(now);
        }
        self.overruns_seen = tick.platform.overruns;
        if counters.range_errors > self.range_errors_seen {
            self.last_range_error_us = Some(now);
        }
        self.range_errors_seen = counters.range_errors;
        let gnss_rejected = recent(now, out.gnss_rejected_us);
        let r = &mut report;
        put(tx, r, |f| {
            position_frame(out, gnss_rejected).encode_into(counter, f)
        });
        put(tx, r, |f| motion_frame(out).encode_into(counter, f));
        for (i, point) in PredictionPoint::all().enumerate() {
            let predicted = match (out.pose, out.predictions.get(i)) {
                (Some(p), Some(q)) => Some((p, q)),
                _ => None,
            };
            let prediction = Prediction {
                point,
                dx_m: predicted.map(|(p, q)| q.x_m - p.x_m),
                dy_m: predicted.map(|(p, q)| q.y_m - p.y_m),
                dheading_rad: predicted.map(|(p, q)| math::wrap_pi(q.heading_rad - p.heading_rad)),
                speed_mps: predicted.map(|(_, q)| q.speed_mps),
            };
            put(tx, r, |f| prediction.encode_into(counter, f));
        }
        let status = self.status_page(tick, inputs, counters, out, gnss_rejected);
        put(tx, r, |f| status.encode_into(counter, f));
        put(tx, r, |f| out.command.encode_into(counter, f));
        counters.nonfinite = counters
            .nonfinite
            .saturating_add(u32::from(report.non_finite));
        counters.saturated = counters
            .saturated
            .saturating_add(u32::from(report.saturated));
        self.last_report = report;
        self.tick_count = self.tick_count.wrapping_add(1);
    }

    /// This tick's NODE_STATUS page.
    fn status_page(
        &self,
        tick: &Tick,
        inputs: &Snapshot,
        counters: &Counters,
        out: &Outputs<'_>,
        gnss_rejected: bool,
    ) -> NodeStatus {
        let now = tick.now_us;
        let c = counters;
        match self.tick_count % STATUS_PAGES {
            0 => NodeStatus::Health {
                mode: model_mode(out.mode),
                health: HealthFlags {
                    steer_stale: inputs.steer_pct.is_none(),
                    speed_stale: inputs.speeds.is_none(),
                    pedal_stale: !inputs.pedal_fresh,
                    gnss_stale: !out.gnss_fresh,
                    gnss_rejected_recently: gnss_rejected,
                    position_invalid: out.pose.is_none(),
                    prediction_saturated: self.last_report.saturated > 0,
                    nonfinite_guard: self.last_report.non_finite > 0 || c.nonfinite > 0,
                    watchdog_reset: tick.platform.watchdog_reset,
                    overrun_recently: recent(now, self.last_overrun_us),
                    input_invalid: recent(now, self.last_range_error_us),
                    planner_refused_recently: recent(now, self.last_planner_reject_us),
                    gnss_rate_mismatch: out.gnss_rate_mismatch,
                    steering_mismatch: out.steering_mismatch,
                    outside_corridor: out.outside_corridor,
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
            // Frames lost for capacity: the platform's receive queue, and any beyond the
            // node's per-tick cap (which the app and host replay never hand it).
            3 => NodeStatus::Platform {
                tick_count: self.tick_count,
                rx_queue_drops: tick.platform.rx_queue_drops.saturating_add(c.rx_over_cap),
            },
            4 => NodeStatus::Ages {
                ages_10ms: inputs.ages_10ms,
                stack_high_water_bytes: tick.platform.stack_high_water_bytes,
            },
            _ => NodeStatus::Model(ModelOutputs {
                speed_model_mps: out.speed_model_mps,
                dxdt_model_mps: out.dxdt_mps,
                lat_accel_mps2: Some(out.speed_mps * out.yaw_rate_rps),
            }),
        }
    }
}

fn model_mode(mode: Mode) -> ModelMode {
    match mode {
        Mode::Kinematic => ModelMode::Kinematic,
        Mode::Dynamic => ModelMode::Dynamic,
    }
}

/// Appends a frame to `tx`, encoded by `encode` in its place (moving a frame costs a library
/// memcpy on the Cortex-M4), and merges what the encoder substituted into `report`.
#[inline(always)]
fn put(
    tx: &mut TxFrames,
    report: &mut EncodeReport,
    encode: impl FnOnce(&mut CanFrame) -> EncodeReport,
) {
    // Note: capacity 16 >= 2 + 10 + 1 + 1 frames, so no slot is ever refused.
    if tx.push(CanFrame::EMPTY).is_ok() {
        if let Some(frame) = tx.last_mut() {
            report.merge(&encode(frame));
        }
    }
}

/// STATE_POSITION.
fn position_frame(out: &Outputs<'_>, gnss_rejected: bool) -> StatePosition {
    StatePosition {
        position_valid: out.pose.is_some(),
        gnss_fresh: out.gnss_fresh,
        gnss_rejected,
        east_m: out.pose.map(|p| p.x_m),
        north_m: out.pose.map(|p| p.y_m),
    }
}

/// STATE_MOTION.
fn motion_frame(out: &Outputs<'_>) -> StateMotion {
    StateMotion {
        mode: model_mode(out.mode),
        heading_uncertain: out.pose.is_some() && out.heading_uncertain,
        heading_rad: out.pose.map(|p| p.heading_rad),
        speed_mps: Some(out.speed_mps),
        yaw_rate_radps: Some(out.yaw_rate_rps),
    }
}
