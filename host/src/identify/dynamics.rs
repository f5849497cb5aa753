//! `[dynamics]` from drives: the single-track model's cornering stiffnesses `C_f`, `C_r`, by a
//! simulation-error fit of the course rate at speed.
//!
//! The car file gives what a scale and a tape measure give (mass, yaw inertia, the centre of
//! gravity: `[dynamics]`'s other keys); the tyres are what only a drive shows. The model is the
//! node's own (`catmodel::model::dynamic`, the same trapezoidal step), driven by the measured
//! speed and the centre-tyre angle (with the steering gain the lateral fit found). Its output
//! is what the log measures: the course over ground at the antenna, `psi + beta_antenna` with
//! `beta_antenna = (v_y + d r) / v_x` (`d` the antenna ahead of the centre of gravity), through
//! the same central difference as the log's yaw rate ([`Experiment::as_measured_yaw`]).
//! Residuals count only where the car was above [`MIN_FIT_SPEED_MPS`] over the whole window.
//!
//! The fit is Levenberg-Marquardt on `(ln C_f, ln C_r)` from three starts (the car file's
//! values times 0.5, 1 and 2), with a numerical Jacobian, each residual weighted by the speed
//! (see `Weight::Speed`); then again with each drive weighted by its own noise, so that drives
//! of a noisier receiver beside them do not hide what a steadier one measured. Whether the
//! drives determine the
//! stiffnesses is decided from the fit itself: the standard error of each (from the Jacobian,
//! with the residuals' correlation over the measurement's window taken into account) must be
//! below [`MAX_RELATIVE_STD_ERROR`] of the value, and the drives must have cornered at speed
//! ([`MIN_CORNERING_SAMPLES`]). The paper's drives (turns at 2.5 m/s) do not: at that speed the
//! car follows its wheels and the tyres' slip is not measurable.
use catmodel::metrics;
use catmodel::model::dynamic::LateralState;

use super::preprocess::Experiment;
use super::stats;
use crate::model_file::{self, DynamicsSection, VehicleSection};

/// Samples count in the fit only where the car was faster than this, m/s (over the whole
/// window of the yaw rate's central difference).
pub const MIN_FIT_SPEED_MPS: f64 = 5.0;
/// Below this speed the model is held at its kinematic steady state, m/s.
const MIN_MODEL_SPEED_MPS: f64 = 3.0;
/// Cornering at speed the drives must hold, samples (5 s at 20 ms) with a lateral acceleration
/// above [`CORNERING_MPS2`] and a speed above [`MIN_FIT_SPEED_MPS`].
pub const MIN_CORNERING_SAMPLES: usize = 250;
/// Lateral acceleration that counts as cornering, m/s^2.
pub const CORNERING_MPS2: f64 = 1.0;
/// Largest standard error of a stiffness, relative to its value, for it to be written.
pub const MAX_RELATIVE_STD_ERROR: f64 = 0.05;

/// The fit.
#[derive(Debug, Clone, PartialEq)]
pub struct DynamicsFit {
    /// The car file's `[dynamics]` with the identified stiffnesses.
    pub section: DynamicsSection,
    /// Standard error of `C_f` and `C_r`, relative to their values.
    pub relative_std_error: (f64, f64),
    /// Samples in the fit.
    pub samples: usize,
    /// Of which cornering (see [`MIN_CORNERING_SAMPLES`]).
    pub cornering_samples: usize,
    /// Fit % of the course rate at speed with the identified stiffnesses.
    pub fit_percent: f64,
    /// ... with the car file's stiffnesses.
    pub prior_fit_percent: f64,
    /// ... with the kinematic model (eq 8, with the steering gain given).
    pub kinematic_fit_percent: f64,
}

/// The course rate at the antenna that experiment `e`'s yaw rate column would show for the
/// single-track model `dynamics` driven by its speed and steering.
fn simulate(
    e: &Experiment,
    vehicle: &VehicleSection,
    dynamics: &DynamicsSection,
    steer_gain: f64,
) -> Vec<f64> {
    let params = dynamics.params();
    let ahead_of_cg = vehicle.antenna_ahead_m - dynamics.cg_to_rear_m;
    let mut state = LateralState::default();
    let mut rate = Vec::with_capacity(e.len());
    let mut beta_prev = 0.0;
    for k in 0..e.len() {
        let v = e.vel[k];
        let delta = (steer_gain * e.delta_rad[k]) as f32;
        if v < MIN_MODEL_SPEED_MPS {
            state = params.steady_state(v as f32, delta);
        } else {
            params.step(&mut state, v as f32, delta, e.ts_s as f32);
        }
        let (vy, r) = (f64::from(state.vy_mps), f64::from(state.yaw_rate_rps));
        let beta = (vy + ahead_of_cg * r) / v.max(MIN_MODEL_SPEED_MPS);
        let beta_rate = if k == 0 {
            0.0
        } else {
            (beta - beta_prev) / e.ts_s
        };
        beta_prev = beta;
        rate.push(r + beta_rate);
    }
    e.as_measured_yaw(&rate)
}

/// The kinematic model's course rate at the antenna (eq 8: the rear axle does not slide).
fn kinematic(e: &Experiment, vehicle: &VehicleSection, steer_gain: f64) -> Vec<f64> {
    let l = vehicle.wheelbase_m;
    let rate: Vec<f64> = (0..e.len())
        .map(|k| e.vel[k] * (steer_gain * e.delta_rad[k]).tan() / l)
        .collect();
    e.as_measured_yaw(&rate)
}

/// The samples that count: above [`MIN_FIT_SPEED_MPS`] over the central difference's window.
fn mask(e: &Experiment) -> Vec<bool> {
    let hw = e.yaw_half_width;
    (0..e.len())
        .map(|k| {
            k >= hw
                && k + hw < e.len()
                && !e.in_gnss_gap(k)
                && e.vel[k - hw..=k + hw]
                    .iter()
                    .all(|&v| v > MIN_FIT_SPEED_MPS)
        })
        .collect()
}

/// How the residuals are scaled.
#[derive(Clone, Copy, PartialEq)]
enum Weight<'a> {
    /// As measured (for fit %).
    None,
    /// Times the speed, and times each experiment's weight (one per experiment): the course's
    /// error from the receiver's position noise falls as one over the speed, and so does its
    /// rate's; weighting each residual by the inverse of its error is the least-squares
    /// estimate of least variance (measured: the standard errors with the CAT Vehicle's
    /// standard receiver fall from 15 % and 21 % to 10 % and 14 %). The experiments' weights
    /// are one over their own noise ([`stats::inverse_noise_weights`]): logs of another
    /// receiver count for what they measure.
    Speed(&'a [f64]),
}

/// Residuals (measured minus model) over the masked samples of every experiment.
fn residuals(
    training: &[Experiment],
    masks: &[Vec<bool>],
    weight: Weight,
    model: impl Fn(&Experiment) -> Vec<f64>,
) -> Vec<f64> {
    let mut out = Vec::new();
    for (i, (e, m)) in training.iter().zip(masks).enumerate() {
        let y = model(e);
        for k in 0..e.len() {
            if m[k] {
                let w = match weight {
                    Weight::None => 1.0,
                    Weight::Speed(per_log) => e.vel[k] * per_log.get(i).copied().unwrap_or(1.0),
                };
                out.push((e.yaw_rate[k] - y[k]) * w);
            }
        }
    }
    out
}

fn sse(r: &[f64]) -> f64 {
    r.iter().map(|x| x * x).sum()
}

/// Fit % ([`metrics::fit_percent`], as everywhere in the report) of the model whose residuals
/// against `measured` are `r`; NaN for a constant `measured` (cornering rules that out).
fn fit_percent(r: &[f64], measured: &[f64]) -> f64 {
    let model: Vec<f64> = measured.iter().zip(r).map(|(y, e)| y - e).collect();
    metrics::fit_percent(measured, &model).unwrap_or(f64::NAN)
}

/// Identifies `C_f` and `C_r` (see the module doc); `Err` says why the drives do not determine
/// them (the car file's `[dynamics]` is then kept as it is).
pub fn identify_dynamics(
    training: &[Experiment],
    vehicle: &VehicleSection,
    prior: &DynamicsSection,
    steer_gain: f64,
) -> std::result::Result<DynamicsFit, String> {
    let masks: Vec<Vec<bool>> = training.iter().map(mask).collect();
    let samples: usize = masks.iter().map(|m| m.iter().filter(|&&b| b).count()).sum();
    let cornering_samples: usize = training
        .iter()
        .zip(&masks)
        .map(|(e, m)| {
            (0..e.len())
                .filter(|&k| m[k] && (e.vel[k] * e.yaw_rate[k]).abs() > CORNERING_MPS2)
                .count()
        })
        .sum();
    if cornering_samples < MIN_CORNERING_SAMPLES {
        return Err(format!(
            "the drives corner at more than {CORNERING_MPS2} m/s^2 above {MIN_FIT_SPEED_MPS} m/s for {cornering_samples} samples ({MIN_CORNERING_SAMPLES} needed: drive step steers at speed, e.g. `simulate-drive --scenario steps-at-speed`)"
        ));
    }
    let with = |theta: [f64; 2]| DynamicsSection {
        cornering_front_n_per_rad: theta[0].exp(),
        cornering_rear_n_per_rad: theta[1].exp(),
        ..*prior
    };
    let res_weighted = |theta: [f64; 2], weight: Weight| {
        let d = with(theta);
        residuals(training, &masks, weight, |e| {
            simulate(e, vehicle, &d, steer_gain)
        })
    };
    let measured: Vec<f64> = training
        .iter()
        .zip(&masks)
        .flat_map(|(e, m)| (0..e.len()).filter(|&k| m[k]).map(|k| e.yaw_rate[k]))
        .collect();
    let start = [
        prior.cornering_front_n_per_rad.ln(),
        prior.cornering_rear_n_per_rad.ln(),
    ];
    // Every experiment weighted alike first; then each by its own noise about that fit, and
    // the fit again from there.
    let alike = vec![1.0; training.len()];
    let mut first: Option<([f64; 2], f64)> = None;
    for scale in [1.0f64, 0.5, 2.0] {
        let theta0 = [start[0] + scale.ln(), start[1] + scale.ln()];
        let (theta, cost, _) =
            levenberg_marquardt(theta0, &|t| res_weighted(t, Weight::Speed(&alike)));
        if first.as_ref().is_none_or(|b| cost < b.1) {
            first = Some((theta, cost));
        }
    }
    let Some((first, _)) = first else {
        return Err("no fit".into());
    };
    let first_residuals = res_weighted(first, Weight::Speed(&alike));
    let mut per_log = Vec::with_capacity(training.len());
    let mut rest = &first_residuals[..];
    for m in &masks {
        let (log, after) = rest.split_at(m.iter().filter(|&&b| b).count().min(rest.len()));
        per_log.push(log);
        rest = after;
    }
    let log_weights = stats::inverse_noise_weights(&per_log);
    let (theta, cost, jtj) =
        levenberg_marquardt(first, &|t| res_weighted(t, Weight::Speed(&log_weights)));
    // Standard errors: s^2 (J'J)^-1 in ln C, i.e. relative. The residuals are correlated (the
    // course rate is a central difference over 2 hw + 1 samples of lowpassed positions, and
    // the receiver's bias wanders): counting 2 hw + 1 samples as one independent error is on
    // the safe side. Measured over ten pairs of `steps-at-speed` runs with the CAT Vehicle's
    // standard receiver: the estimates scatter by 5.1 % (C_f) and 7.2 % (C_r) where this says
    // 10-12 % and 14-17 %; the residuals' own autocorrelation (summed over twice the window)
    // said 1-5 %, too little, and is not used.
    let hw = training.first().map_or(1, |e| e.yaw_half_width);
    let correlated = (2 * hw + 1) as f64;
    let dof = (samples as f64 - 2.0).max(1.0);
    let s2 = cost / dof * correlated;
    let det = jtj[0][0] * jtj[1][1] - jtj[0][1] * jtj[1][0];
    if det.is_nan() || det <= 0.0 {
        return Err("the course rate does not depend on the stiffnesses on these drives".into());
    }
    let rel = ((s2 * jtj[1][1] / det).sqrt(), (s2 * jtj[0][0] / det).sqrt());
    let section = with(theta);
    if !(theta[0].is_finite() && theta[1].is_finite()) {
        return Err("the fit diverged".into());
    }
    let fit = DynamicsFit {
        section,
        relative_std_error: rel,
        samples,
        cornering_samples,
        fit_percent: fit_percent(&res_weighted(theta, Weight::None), &measured),
        prior_fit_percent: fit_percent(&res_weighted(start, Weight::None), &measured),
        kinematic_fit_percent: fit_percent(
            &residuals(training, &masks, Weight::None, |e| {
                kinematic(e, vehicle, steer_gain)
            }),
            &measured,
        ),
    };
    // Stiffnesses the model file's reader refuses (an oversteering pair unstable below the car's
    // top speed, a stiffness no tyre has for its load) are not written.
    if let Some(why) = model_file::dynamics_problem(vehicle, &section) {
        return Err(format!(
            "the fit, C_f {:.0} N/rad and C_r {:.0} N/rad, is refused by the model file's reader: {why}",
            section.cornering_front_n_per_rad, section.cornering_rear_n_per_rad
        ));
    }
    if rel.0 > MAX_RELATIVE_STD_ERROR || rel.1 > MAX_RELATIVE_STD_ERROR {
        // The standard error falls as one over the square root of the data.
        let more = (rel.0.max(rel.1) / MAX_RELATIVE_STD_ERROR).powi(2).ceil();
        return Err(format!(
            "C_f {:.0} N/rad, C_r {:.0} N/rad with standard errors of {:.0} % and {:.0} % (at most {:.0} %): the drives do not determine them; drive step steers at speed (at most {more:.0} times as much as these drives' {cornering_samples} cornering samples: the error is overstated about twice, on the safe side; or a receiver with a steadier course)",
            section.cornering_front_n_per_rad,
            section.cornering_rear_n_per_rad,
            100.0 * rel.0,
            100.0 * rel.1,
            100.0 * MAX_RELATIVE_STD_ERROR
        ));
    }
    Ok(fit)
}

/// Levenberg-Marquardt on two parameters with a central-difference Jacobian: the parameters,
/// the sum of squared residuals and `J'J` at the end.
fn levenberg_marquardt(
    mut theta: [f64; 2],
    res: &impl Fn([f64; 2]) -> Vec<f64>,
) -> ([f64; 2], f64, [[f64; 2]; 2]) {
    const H: f64 = 1e-3;
    let mut r = res(theta);
    let mut cost = sse(&r);
    let mut lambda = 1e-3;
    let mut jtj = [[0.0; 2]; 2];
    for _ in 0..40 {
        let mut columns = [Vec::new(), Vec::new()];
        for (i, column) in columns.iter_mut().enumerate() {
            let (mut up, mut down) = (theta, theta);
            up[i] += H;
            down[i] -= H;
            let (ru, rd) = (res(up), res(down));
            // d(residual)/d(theta): residual = measured - model.
            *column = ru
                .iter()
                .zip(&rd)
                .map(|(a, b)| (a - b) / (2.0 * H))
                .collect();
        }
        let mut jtr = [0.0; 2];
        for a in 0..2 {
            for b in 0..2 {
                jtj[a][b] = columns[a].iter().zip(&columns[b]).map(|(x, y)| x * y).sum();
            }
            jtr[a] = columns[a].iter().zip(&r).map(|(x, y)| x * y).sum();
        }
        let mut improved = false;
        while lambda < 1e10 {
            let m = [
                [jtj[0][0] * (1.0 + lambda), jtj[0][1]],
                [jtj[1][0], jtj[1][1] * (1.0 + lambda)],
            ];
            let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
            if det.abs() < f64::MIN_POSITIVE {
                break;
            }
            // Gauss-Newton on r(theta + step) ~ r + J step: step = -(J'J)^-1 J'r.
            let step = [
                -(jtr[0] * m[1][1] - jtr[1] * m[0][1]) / det,
                -(m[0][0] * jtr[1] - m[1][0] * jtr[0]) / det,
            ];
            let candidate = [
                theta[0] + step[0].clamp(-1.0, 1.0),
                theta[1] + step[1].clamp(-1.0, 1.0),
            ];
            let rc = res(candidate);
            let c = sse(&rc);
            if c < cost {
                let small = step[0].abs() < 1e-6 && step[1].abs() < 1e-6;
                theta = candidate;
                r = rc;
                cost = c;
                lambda = (lambda / 10.0).max(1e-9);
                improved = !small;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    (theta, cost, jtj)
}
