//! Sensors logged slower than the bus, and what that costs the delays `identify` fits. The
//! steering and speed reports come every 20 ms on the bus; a telemetry logger that samples
//! them at 1-5 Hz keeps a step of the command only to within its interval. The training logs'
//! intervals are named in `replay`'s and `csv2can`'s words (one [`ReportIntervals`] and
//! [`replay::slow_reports`] for all three), with the resolution they leave the speed and
//! lateral models' delays; a speed delay shorter than that resolution is no figure at all.
//! Never refuses by itself: [`SlowSensors::problem`] is the CLI's to refuse (`--force`).
use catmodel::can::freshness::FreshnessConfig;

use super::preprocess::Experiment;
use crate::replay::{self, ReportIntervals};

/// A delay fitted from signals sampled every `T` is known to `T` times this at best, either
/// way: a step of `input_vel` logged every `T` came anywhere in the interval before the sample
/// that shows it, and the grid's straight line between the two samples puts it at the middle
/// (`units::GNSS_LATENCY_RESOLUTION_PERIODS` is the same bound for the fixes' timing). A
/// black-box probe's paper-sized set with `vel`, `input_vel` and `steer` kept at 1 Hz fitted a
/// speed delay of 0.68 s for the 0.88 s of the same drives at 50 Hz (0.90 s at 10 Hz, 0.88 s at
/// 5 Hz), without a note: the drives' steps keep one phase to the whole seconds.
pub const DELAY_RESOLUTION_INTERVALS: f64 = 0.5;

/// What the training logs' sensor rates say of the fitted delays.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SlowSensors {
    /// The steering or speed logged slower than the node's timeouts, and what it costs the
    /// delays; `None` when both come within them.
    pub note: Option<String>,
    /// The speed model's delay is shorter than the resolution the speed's interval leaves
    /// it: the fitted figure means nothing (it could be 0).
    pub problem: Option<String>,
}

/// The training logs' steering and speed intervals ([`Experiment::report_intervals`], pooled
/// against `freshness`'s timeouts, the base model file's), against the fitted speed delay
/// `speed_delay_s` and the lateral model's `lateral_delay_s` (none without a lateral model).
pub fn slow_sensors(
    training: &[Experiment],
    freshness: &FreshnessConfig,
    speed_delay_s: f64,
    lateral_delay_s: Option<f64>,
) -> SlowSensors {
    let [steer, speed] =
        ReportIntervals::pooled(freshness, training.iter().map(|e| &e.report_intervals));
    let slow = replay::slow_reports(&[steer.clone(), speed.clone()]);
    if slow.is_empty() {
        return SlowSensors::default();
    }
    // The interval of a report slower than its timeout, s.
    let slow_interval_s = |r: &ReportIntervals| {
        r.median_and_stale_share()
            .filter(|(median, _)| *median > r.timeout_us)
            .map(|(median, _)| median as f64 * 1e-6)
    };
    let mut costs = Vec::new();
    let mut problem = None;
    if let Some(interval) = slow_interval_s(&speed) {
        let resolution = DELAY_RESOLUTION_INTERVALS * interval;
        costs.push(format!(
            "a step of `input_vel` logged every {interval:.3} s came anywhere in the interval \
             before the sample that shows it, so the speed model's delay, {speed_delay_s:.2} s, \
             is known to +-{resolution:.2} s at best"
        ));
        if resolution >= speed_delay_s {
            problem = Some(format!(
                "the speed model's delay, {speed_delay_s:.2} s, is within the +-{resolution:.2} \
                 s that `vel` and `input_vel` logged every {interval:.3} s (median) leave it: \
                 the car's delay could be anything from 0 to {:.2} s, and the fitted figure \
                 means nothing (nor the speed model's response, which the delay shapes); log \
                 the speed at the bus's 50 Hz (record every frame: candump -l)",
                speed_delay_s + resolution
            ));
        }
    }
    if let (Some(interval), Some(delay)) = (slow_interval_s(&steer), lateral_delay_s) {
        costs.push(format!(
            "the lateral model's delay and lag, from `steer` every {interval:.3} s, to \
             +-{:.2} s (its delay: {delay:.2} s)",
            DELAY_RESOLUTION_INTERVALS * interval
        ));
    }
    let note = format!(
        "the training logs' `steer` and `vel` rows come further apart than the node's timeouts \
         (the base model file's): {}. A delay is timed no finer than its signals are sampled{}; \
         a node fed reports that slowly takes the inputs for stale between them (`replay` \
         says how much); log the sensors at the bus's 50 Hz (record every frame: candump -l)",
        slow.join("; "),
        if costs.is_empty() {
            String::new()
        } else {
            format!(": {}", costs.join("; and "))
        }
    );
    SlowSensors {
        note: Some(note),
        problem,
    }
}
