//! Step 2: delay and settling time of the speed response to commanded-speed steps (paper
//! Fig 2: "when the car starts moving (dot 1) and when the car reaches an equilibrium point
//! (dot 2)"), per step and as means.
//!
//! A step is a change of the commanded speed by at least [`MIN_STEP_MPS`]; its time is where
//! the (filtered) command has made half of the change. Delay: until the measured speed has
//! moved by 5 % of the step. Settling: until the speed stays within 5 % of the step (at least
//! 0.1 m/s) of its final value, the mean of the last second before the next step.
use serde::Serialize;

/// Smallest commanded-speed change treated as a step, m/s.
pub const MIN_STEP_MPS: f64 = 0.5;

/// One step of the commanded speed and the response's markers.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StepResponse {
    /// Experiment name.
    pub experiment: String,
    /// Time of the step, s.
    pub t_step_s: f64,
    /// Command before and after, m/s.
    pub from_mps: f64,
    /// Command after, m/s.
    pub to_mps: f64,
    /// Delay until the speed moves (dot 1), s.
    pub delay_s: Option<f64>,
    /// Time until the speed stays near its final value (dot 2), s.
    pub settling_s: Option<f64>,
}

/// Finds the steps of `u` and measures the response `y` (both on the grid `t`).
pub fn step_responses(name: &str, t: &[f64], u: &[f64], y: &[f64]) -> Vec<StepResponse> {
    let n = u.len().min(y.len()).min(t.len());
    // Plateaus: runs where the command moves less than 1 mm/s per sample.
    let mut plateaus: Vec<(usize, usize)> = Vec::new();
    let mut start = 0;
    for k in 1..=n {
        let moving = k < n && (u[k] - u[k - 1]).abs() > 1e-3;
        if moving || k == n {
            if k - start >= 25 {
                plateaus.push((start, k - 1));
            }
            start = k;
        }
    }
    let mut out = Vec::new();
    for w in plateaus.windows(2) {
        let (_, end_a) = w[0];
        let (start_b, end_b) = w[1];
        let from = u[end_a];
        let to = u[start_b];
        let delta = to - from;
        if delta.abs() < MIN_STEP_MPS {
            continue;
        }
        let Some(ks) = (end_a..=start_b).find(|&k| (u[k] - from).abs() >= 0.5 * delta.abs()) else {
            continue;
        };
        let y0 = y[ks];
        let delay = (ks..=end_b)
            .find(|&k| (y[k] - y0) * delta.signum() >= 0.05 * delta.abs())
            .map(|k| t[k] - t[ks]);
        let tail = ((1.0 / (t[1] - t[0])).round() as usize).max(1);
        let settling = if end_b >= ks + tail {
            let final_v: f64 = y[end_b + 1 - tail..=end_b].iter().sum::<f64>() / tail as f64;
            let band = (0.05 * delta.abs()).max(0.1);
            let last_out = (ks..=end_b).rev().find(|&k| (y[k] - final_v).abs() > band);
            match last_out {
                Some(k) if k < end_b - tail / 2 => Some(t[k + 1] - t[ks]),
                Some(_) => None,
                None => Some(0.0),
            }
        } else {
            None
        };
        out.push(StepResponse {
            experiment: name.to_string(),
            t_step_s: t[ks],
            from_mps: from,
            to_mps: to,
            delay_s: delay,
            settling_s: settling,
        });
    }
    out
}

/// Mean of the present values.
pub fn mean_of(v: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    let (s, c) = v.flatten().fold((0.0, 0usize), |(s, c), x| (s + x, c + 1));
    (c > 0).then(|| s / c as f64)
}
