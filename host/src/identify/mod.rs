//! `catmodel identify`: driving logs -> validated models -> a model file. The paper's pipeline
//! (II-C, II-D, II-E), each step a documented function:
//! 1. [`preprocess`]: uniform 20 ms grid (eq 1), zero-phase FIR lowpass + moving average,
//!    GNSS to local metres, steering percent to angles (eq 2-4);
//! 2. [`delay`]: delay and settling time of the speed response per step (Fig 2);
//! 3. [`correlation`]: ranking of 17 candidate regressors; [`arx`]: least-squares ARX (eq 6)
//!    with order and delay selection;
//! 4. [`oe`]: continuous-time transfer functions with input delay by simulation-error
//!    minimisation (separable least squares + Levenberg-Marquardt from the ARX poles), for
//!    the internal controller (eq 5), the dx/dt MISO model (eq 7) and the lateral model;
//! 5. [`validate`]: fit % (pure simulation, MATLAB `compare`) and MSE on training and
//!    validation data, each beside the kinematic model; written into the model file;
//! 6. [`floor`]: every fit checked against the floor before the file may be written.
pub mod arx;
pub mod car;
pub mod correlation;
pub mod delay;
pub mod discretize;
pub mod dynamics;
pub mod floor;
pub mod gnss_clock;
pub mod oe;
pub mod preprocess;
pub mod receiver;
pub mod report;
pub mod sensor_rates;
pub mod simulate;
pub mod stats;
pub mod steering;
pub mod units;
pub mod validate;

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use catmodel::model::tf::TransferFunction;

use crate::model_file::{self, Block, Fit, Lateral, Model, ModelFile, VehicleSection};
use arx::Arx;
use oe::{BlockSpec, Data};
use preprocess::{Experiment, PreprocessOptions};
use validate::{Score, Scores, Simulated};

/// How to identify.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IdentifyOptions {
    /// Preprocessing.
    pub preprocess: PreprocessOptions,
    /// Largest input delay searched for the speed model, samples: the node's capacity
    /// ([`catmodel::node::VELOCITY_DELAY_CAP`], 64 = 1.28 s at 20 ms), so that every model
    /// found runs on the node.
    pub max_delay_samples: usize,
    /// Denominator order of the speed model (the paper's eq 5: 2).
    pub speed_order: usize,
    /// Levenberg-Marquardt iterations, final fits.
    pub max_iter: usize,
}

impl Default for IdentifyOptions {
    fn default() -> Self {
        Self {
            preprocess: PreprocessOptions::default(),
            max_delay_samples: catmodel::node::VELOCITY_DELAY_CAP,
            speed_order: 2,
            max_iter: 100,
        }
    }
}

/// The speed model's identification details.
#[derive(Debug, Clone, PartialEq)]
pub struct SpeedIdentification {
    /// The selected ARX model (eq 6).
    pub arx: Arx,
    /// ARX pure-simulation scores, training and validation.
    pub arx_training: Score,
    /// ARX on validation data.
    pub arx_validation: Option<Score>,
    /// Output-error cost per scanned delay (samples, sum of squared errors).
    pub delay_scan: Vec<(usize, f64)>,
    /// The continuous-time model.
    pub tf: TransferFunction,
}

/// Everything `identify` measured.
#[derive(Debug, Clone)]
pub struct Identification {
    /// The model file to write.
    pub model: ModelFile,
    /// Training experiments (preprocessed).
    pub training: Vec<Experiment>,
    /// Validation experiments.
    pub validation: Vec<Experiment>,
    /// Simulations of the identified models on training data.
    pub training_sims: Vec<Simulated>,
    /// ... on validation data.
    pub validation_sims: Vec<Simulated>,
    /// Step responses of the speed (Fig 2), every experiment.
    pub steps: Vec<delay::StepResponse>,
    /// Correlation ranking for dx/dt.
    pub correlation_dx: Vec<correlation::Ranked>,
    /// Correlation ranking for the speed.
    pub correlation_vel: Vec<correlation::Ranked>,
    /// Speed model details.
    pub speed: SpeedIdentification,
    /// Scores on training data.
    pub training_scores: Scores,
    /// Scores on validation data.
    pub validation_scores: Option<Scores>,
    /// Whether the dx/dt model was re-identified (else the file keeps the base file's).
    pub dx_dt_identified: bool,
    /// The cornering stiffnesses, when the drives determine them (else the file keeps the car
    /// file's `[dynamics]`, and a note says why).
    pub dynamics: Option<dynamics::DynamicsFit>,
    /// Why the training logs' steering cannot be the schema's ([`steering_problem`]):
    /// `catmodel identify` refuses to write the file unless `--force`, which writes it without
    /// `[lateral]`.
    pub steering_problem: Option<String>,
    /// Why the speed model's delay means nothing: a speed logged too slowly to time it
    /// ([`sensor_rates::SlowSensors::problem`]); `catmodel identify` refuses to write the file
    /// unless `--force`.
    pub slow_sensor_problem: Option<String>,
    /// Things the user should know (skipped models, weak excitation, transfer caveats).
    pub notes: Vec<String>,
    /// Wall time of the identification (without reading files), s.
    pub seconds: f64,
}

/// Weight of one experiment in the speed fit: `1 / var(y)` (each experiment's fit % counts
/// alike, so that a few large, rate-limited steps do not dominate the small ones; measured on
/// the simulator: validation fit 86.5 % unweighted, 90 % weighted).
fn experiment_weight(y: &[f64]) -> f64 {
    let n = y.len().max(1) as f64;
    let m = y.iter().sum::<f64>() / n;
    let v = y.iter().map(|a| (a - m) * (a - m)).sum::<f64>() / n;
    if v > 1e-12 {
        1.0 / v
    } else {
        1.0
    }
}

fn span(v: impl Iterator<Item = f64>) -> f64 {
    let (lo, hi) = v.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), x| {
        (l.min(x), h.max(x))
    });
    hi - lo
}

/// Default initial denominators for a 2nd-order search besides the ARX poles.
const DEFAULT_DENS_2: [[f64; 2]; 3] = [[2.0, 1.0], [1.0, 0.25], [4.0, 4.0]];

fn initial_dens(arx: Option<&Arx>, order: usize, ts: f64) -> Vec<Vec<f64>> {
    let mut out = Vec::new();
    if let Some(d) = arx.and_then(|a| oe::continuous_den_from_discrete(&a.a, ts)) {
        if d.len() == order {
            out.push(d);
        } else if d.len() == 1 && order == 2 {
            // One ARX pole: add a faster one.
            out.push(vec![d[0] + 5.0, d[0] * 5.0]);
        }
    }
    match order {
        1 => out.extend([vec![1.0], vec![5.0]]),
        2 => out.extend(DEFAULT_DENS_2.iter().map(|d| d.to_vec())),
        _ => out.extend([vec![3.0, 3.0, 1.0], vec![6.0, 12.0, 8.0]]),
    }
    out
}

/// SISO output-error fit with the delay chosen by scanning `candidates` (quick fits), then a
/// full fit from every initial denominator at the best delays. Returns the best fit and the
/// scan (delay, cost).
pub fn fit_siso_with_delay_scan(
    data: &[Data],
    order: usize,
    proper: bool,
    candidates: &[usize],
    inits: &[Vec<f64>],
    ts: f64,
    max_iter: usize,
) -> Result<(oe::OeFit, Vec<(usize, f64)>)> {
    let quick = |d: usize| -> f64 {
        let spec = [BlockSpec {
            order,
            proper,
            delay_samples: d,
        }];
        inits
            .iter()
            .take(1)
            .filter_map(|init| oe::fit(data, &spec, std::slice::from_ref(init), ts, 8).ok())
            .map(|f| f.cost)
            .fold(f64::INFINITY, f64::min)
    };
    // Coarse scan every third candidate, then every candidate within 2 of the best two.
    let mut scan: Vec<(usize, f64)> = candidates
        .iter()
        .step_by(3)
        .map(|&d| (d, quick(d)))
        .collect();
    let mut sorted = scan.clone();
    sorted.sort_by(|a, b| a.1.total_cmp(&b.1));
    for &(centre, _) in sorted.iter().take(2) {
        for &d in candidates {
            if d.abs_diff(centre) <= 2 && !scan.iter().any(|(x, _)| *x == d) {
                scan.push((d, quick(d)));
            }
        }
    }
    scan.sort_by_key(|x| x.0);
    let mut order_by_cost: Vec<(usize, f64)> = scan.clone();
    order_by_cost.sort_by(|a, b| a.1.total_cmp(&b.1));
    let mut best: Option<oe::OeFit> = None;
    for &(d, _) in order_by_cost.iter().take(2) {
        let spec = [BlockSpec {
            order,
            proper,
            delay_samples: d,
        }];
        for init in inits.iter().take(2) {
            if let Ok(f) = oe::fit(data, &spec, std::slice::from_ref(init), ts, max_iter) {
                if best.as_ref().is_none_or(|b| f.cost < b.cost) {
                    best = Some(f);
                }
            }
        }
    }
    let best = best.context("no delay candidate gave a stable model")?;
    Ok((best, scan))
}

impl SpeedIdentification {
    /// The note for a speed model whose input delay is the longest the search and the node
    /// take ([`IdentifyOptions::max_delay_samples`]), the ARX model's or the transfer
    /// function's: the car's speed loop answers that late or later, and a later answer is
    /// stood in for by the numerator's zeros (black-box probe: a car whose loop answered after
    /// 1.4 s, with a 0.3 s lag, was identified with no word of it; the ARX search had stopped
    /// at its 1.2 s). `None` below the limit.
    pub fn delay_at_the_limit(&self, opts: &IdentifyOptions) -> Option<String> {
        let ts = opts.preprocess.ts_s;
        let limit = opts.max_delay_samples;
        let tf_samples = (self.tf.delay_s() / ts).round() as usize;
        let arx_samples = self.arx.nk.first().copied().unwrap_or(0);
        (tf_samples >= limit || arx_samples >= limit).then(|| {
            format!(
                "speed model: the ARX model's delay is {arx_samples} samples and the transfer \
                 function's {:.2} s, against the longest the node runs, {limit} samples of \
                 {:.0} ms ({:.2} s): the car's speed loop answers that late or later, and a \
                 later answer is approximated by the numerator's zeros; check the step \
                 responses' delays (`--report`)",
                self.tf.delay_s(),
                1e3 * ts,
                limit as f64 * ts
            )
        })
    }
}

/// The transfer function's delay is "far below" the step responses' mean delay when it is
/// less than this share of it (and [`DELAY_SHORT_BY_S`] shorter): the paper-sized set's 0.88 s
/// against its steps' 0.79 s is not.
const DELAY_FAR_BELOW_SHARE: f64 = 0.5;

/// ... and shorter by at least this, s: a fraction of a small delay is within a sample or two.
const DELAY_SHORT_BY_S: f64 = 0.3;

/// A note when the fitted transfer function answers a step otherwise than the step
/// responses measured: a zero in the right half-plane (an inverse response: the speed first
/// moves against the command), or a delay far below the steps' mean delay `steps_delay_s`
/// ([`DELAY_FAR_BELOW_SHARE`]). A black-box probe's truck-like speed loop (0.6 s delay, 1.2 s
/// lag) was fitted with a 0.16 s delay and a zero at +1.84 1/s, training fit 63 %, where the
/// steps said a mean delay of 1.811 s, without a note: the 2nd-order delayed form
/// approximates a slower loop's late answer with the zero.
pub fn speed_step_mismatch_note(
    tf: &TransferFunction,
    steps_delay_s: Option<f64>,
) -> Option<String> {
    let delay = tf.delay_s();
    let num = tf.numerator();
    let lead = num.iter().position(|c| *c != 0.0).unwrap_or(num.len());
    let rhp: Vec<(f64, f64)> = model_file::poles(&num[lead..])
        .unwrap_or_default()
        .into_iter()
        .filter(|z| z.0 > 0.0)
        .collect();
    let far_below = steps_delay_s
        .filter(|&d| delay < DELAY_FAR_BELOW_SHARE * d && d - delay >= DELAY_SHORT_BY_S);
    if rhp.is_empty() && far_below.is_none() {
        return None;
    }
    let mut found = Vec::new();
    if let Some(&(re, im)) = rhp.iter().max_by(|a, b| a.0.total_cmp(&b.0)) {
        let at = if im == 0.0 {
            format!("+{re:.2}")
        } else {
            format!("+{re:.2} +- {:.2}j", im.abs())
        };
        found.push(format!(
            "a zero at s = {at} 1/s in the right half-plane (an inverse response: the speed \
                 first moves against a step of the command)"
        ));
    }
    found.push(match steps_delay_s {
        Some(d) if far_below.is_some() => {
            format!("a delay of {delay:.2} s, far below the step responses' mean delay of {d:.3} s")
        }
        Some(d) => format!("a delay of {delay:.2} s (the step responses' mean delay: {d:.3} s)"),
        None => format!("a delay of {delay:.2} s (no step response measured)"),
    });
    Some(format!(
        "speed model: the transfer function has {}: a speed loop slower than the \
             2nd-order delayed form describes (a long actuator lag after the delay) is fitted \
             with an early answer and a zero; the model's step response is not the car's: \
             check the step responses (`--report`) and the fits before using it",
        found.join(" and ")
    ))
}

/// The ranges of a log of `len` samples outside `skip`'s flagged samples (an empty `skip`:
/// the whole log).
fn driven_stretches(
    skip: &[bool],
    len: usize,
) -> impl Iterator<Item = std::ops::Range<usize>> + '_ {
    let mut k = 0;
    std::iter::from_fn(move || {
        while k < len && skip.get(k).copied().unwrap_or(false) {
            k += 1;
        }
        if k >= len {
            return None;
        }
        let start = k;
        while k < len && !skip.get(k).copied().unwrap_or(false) {
            k += 1;
        }
        Some(start..k)
    })
}

/// Identifies the speed model (eq 5 form) from `input_vel` -> `vel`.
pub fn identify_speed(
    training: &[Experiment],
    validation: &[Experiment],
    opts: &IdentifyOptions,
) -> Result<SpeedIdentification> {
    let ts = opts.preprocess.ts_s;
    if span(training.iter().flat_map(|e| e.input_vel.iter().copied())) < 0.1 {
        bail!("input_vel (commanded speed) is constant over every training log: nothing excites the speed model; use logs with speed steps");
    }
    // Each log in the stretches where its command drove the car ([`Experiment::speed_skip`]),
    // each simulated from its own start: a simulation run through a stretch the car did not
    // follow starts the next one from a state the car was never in.
    let pieces: Vec<(&Experiment, std::ops::Range<usize>)> = training
        .iter()
        .flat_map(|e| driven_stretches(&e.speed_skip, e.len()).map(move |r| (e, r)))
        .collect();
    let inputs: Vec<[&[f64]; 1]> = pieces
        .iter()
        .map(|(e, r)| [&e.input_vel[r.clone()]])
        .collect();
    let data: Vec<Data> = pieces
        .iter()
        .zip(&inputs)
        .map(|((e, r), u)| Data {
            inputs: u,
            output: &e.vel[r.clone()],
            weight: experiment_weight(&e.vel),
            skip: &[],
        })
        .collect();
    let arx = arx::select_siso(&data, opts.max_delay_samples)?;
    let arx_sim = |set: &[Experiment]| -> Score {
        let (mut y, mut yh) = (Vec::new(), Vec::new());
        for e in set {
            let sim = arx.simulate(&[&e.input_vel], &e.vel);
            let driven = |k: &usize| !e.speed_skip.get(*k).copied().unwrap_or(false);
            y.extend((0..e.vel.len()).filter(driven).map(|k| e.vel[k]));
            yh.extend((0..sim.len()).filter(driven).map(|k| sim[k]));
        }
        validate::score(&y, &yh)
    };
    let arx_training = arx_sim(training);
    let arx_validation = (!validation.is_empty()).then(|| arx_sim(validation));
    let nk = arx.nk[0];
    let lo = nk.saturating_sub(20);
    let hi = (nk + 20).min(opts.max_delay_samples);
    let candidates: Vec<usize> = (lo..=hi).collect();
    let inits = initial_dens(Some(&arx), opts.speed_order, ts);
    let (fit, delay_scan) = fit_siso_with_delay_scan(
        &data,
        opts.speed_order,
        true,
        &candidates,
        &inits,
        ts,
        opts.max_iter,
    )?;
    Ok(SpeedIdentification {
        arx,
        arx_training,
        arx_validation,
        delay_scan,
        tf: fit.tfs[0],
    })
}

/// Speed-up factors of the published eq 7 poles used as extra starts of the dx/dt fit
/// (`s -> s / k`: denominator `s^2 + k a_1 s + k^2 a_2`).
pub const DX_DT_START_TIME_SCALES: [f64; 3] = [1.0, 2.0, 4.0];

/// Identifies the eq 7 MISO dx/dt model (inputs `[v_m, x, y, phi]`, proper 2nd-order blocks,
/// no delay), started from the common poles of a MISO ARX model, or `None` with the reason
/// when an input is not excited.
pub fn identify_dx_dt(
    training: &[Experiment],
    opts: &IdentifyOptions,
) -> Result<std::result::Result<Vec<TransferFunction>, String>> {
    let ts = opts.preprocess.ts_s;
    let names = model_file::DX_DT_INPUTS;
    // From the first fix ([`Experiment::track_from`]): before it the fixes are held, and a
    // simulation through it would start the track's blocks from inputs the car never had.
    let from = |e: &Experiment| e.track_from.min(e.len());
    let inputs: Vec<[&[f64]; 4]> = training
        .iter()
        .map(|e| {
            let k = from(e);
            [&e.vel[k..], &e.x[k..], &e.y[k..], &e.delta_rad[k..]]
        })
        .collect();
    for (j, name) in names.iter().enumerate() {
        if span(inputs.iter().flat_map(|u| u[j].iter().copied())) < 1e-3 {
            return Ok(Err(format!(
                "input `{name}` is constant over the training logs (drive turns or circles to excite it)"
            )));
        }
    }
    let data: Vec<Data> = training
        .iter()
        .zip(&inputs)
        .map(|(e, u)| Data {
            inputs: u,
            output: &e.dx[from(e)..],
            weight: 1.0,
            skip: e.gnss_gap.get(from(e)..).unwrap_or_default(),
        })
        .collect();
    let arx = arx::estimate(&data, 2, &[3; 4], &[0; 4]).ok();
    let specs = [BlockSpec {
        order: 2,
        proper: true,
        delay_samples: 0,
    }; 4];
    // Starts: the common ARX poles (when they map to s) and the published eq 7 poles at their
    // own time scale and 2x, 4x faster. The cost surface has several nearly equal minima (the
    // steering and y blocks are weakly determined: one minute of training data each) and a
    // single start lands in whichever basin its path leads to (measured on the paper-sized set:
    // the eq 7 start alone ends 0.2 % above the best training cost with 86.8 % validation fit,
    // the 2x start at the best cost with 90.5 %). Each start is run to convergence and the
    // lowest training cost wins.
    let mut starts: Vec<Vec<Vec<f64>>> = Vec::new();
    if let Some(d) = arx
        .as_ref()
        .and_then(|a| oe::continuous_den_from_discrete(&a.a, ts))
        .filter(|d| d.len() == 2)
    {
        starts.push(vec![d; 4]);
    }
    let eq7: Vec<Vec<f64>> = catmodel::model::paper::EQ7_DX_DT
        .iter()
        .map(|tf| tf.to_monic().denominator()[1..].to_vec())
        .collect();
    for k in DX_DT_START_TIME_SCALES {
        starts.push(eq7.iter().map(|d| vec![d[0] * k, d[1] * k * k]).collect());
    }
    let mut best: Option<oe::OeFit> = None;
    for s in &starts {
        if let Ok(f) = oe::fit(&data, &specs, s, ts, opts.max_iter.min(40)) {
            if best.as_ref().is_none_or(|b| f.cost < b.cost) {
                best = Some(f);
            }
        }
    }
    Ok(best
        .map(|b| b.tfs)
        .ok_or_else(|| "no stable fit found".to_string()))
}

/// One steady-turn sample: speed, m/s; nominal centre angle, rad; yaw rate from the course,
/// rad/s.
type SteadyTurn = (f64, f64, f64);

/// Steady-turn samples `(speed, nominal centre angle, yaw rate)` of one experiment: speed above
/// 2 m/s, |angle| above 0.01 rad, steering and speed steady for [`LATERAL_STEADY_S`] and over
/// the yaw rate's window ahead. A step steer at speed yaws up over a second; fitted as if
/// steady, its transient reads as understeer (0.0038 s^2/m^2 instead of the plant's 0.0015
/// with `steps-at-speed` in the set).
fn steady_turns(e: &Experiment) -> Vec<SteadyTurn> {
    steady_samples(e, STEADY_TURN_MIN_SPEED_MPS, 0.01)
}

/// The speed above which [`steady_turns`] count, m/s.
const STEADY_TURN_MIN_SPEED_MPS: f64 = 2.0;

/// As [`steady_turns`], faster than `min_speed_mps` and with |angle| above `min_angle_rad`
/// (0: straight driving too).
fn steady_samples(e: &Experiment, min_speed_mps: f64, min_angle_rad: f64) -> Vec<SteadyTurn> {
    let mut pts = Vec::new();
    let behind = (LATERAL_STEADY_S / e.ts_s).round() as usize;
    for k in behind..e.len().saturating_sub(e.yaw_half_width) {
        let (v, d) = (e.vel[k], e.delta_rad[k]);
        if v <= min_speed_mps || d.abs() < min_angle_rad || e.in_gnss_gap(k) {
            continue;
        }
        let window = k - behind..=k + e.yaw_half_width;
        let steady = e.delta_rad[window.clone()]
            .iter()
            .all(|x| (x - d).abs() <= 0.05 * d.abs() + 0.002)
            && e.vel[window].iter().all(|x| (x - v).abs() <= 0.3);
        if steady {
            pts.push((v, d, e.yaw_rate[k]));
        }
    }
    pts
}

/// Steady-turn samples needed to estimate the steering gain (5 s of turning at 50 Hz).
pub const MIN_STEADY_TURN_SAMPLES: usize = 250;

/// The steering gain `g` of `r = v tan(g delta / (1 + K v^2)) / L` with the car file's K, by
/// Gauss-Newton from 1, and its standard error (the yaw rate's central difference over
/// `2 hw + 1` samples counted as one independent error, as the understeer's).
fn steer_gain_alone(pts: &[SteadyTurn], vehicle: &VehicleSection, hw: usize) -> (f64, f64) {
    steer_gain_from(pts, vehicle, hw, 1.0)
}

/// [`steer_gain_alone`] from the gain `start`.
fn steer_gain_from(
    pts: &[SteadyTurn],
    vehicle: &VehicleSection,
    hw: usize,
    start: f64,
) -> (f64, f64) {
    let (l, k) = (vehicle.wheelbase_m, vehicle.understeer_s2_per_m2);
    let mut g = start;
    let (mut jtj, mut cost) = (0.0, 0.0);
    for _ in 0..50 {
        let mut jtr = 0.0;
        (jtj, cost) = (0.0, 0.0);
        for &(v, d, r) in pts {
            let arg = g * d / (1.0 + k * v * v);
            let res = r - v * arg.tan() / l;
            let j = v / l / arg.cos().powi(2) * d / (1.0 + k * v * v);
            jtj += j * j;
            jtr += j * res;
            cost += res * res;
        }
        if jtj.is_nan() || jtj <= 0.0 {
            break;
        }
        let dg = jtr / jtj;
        g += dg;
        if dg.abs() < 1e-10 {
            break;
        }
    }
    let s2 = cost / (pts.len() as f64 - 1.0).max(1.0) * (2 * hw + 1) as f64;
    (g, (s2 / jtj).sqrt())
}

/// The small-angle steering gain of `pts` (`r = v g delta / ((1 + K v^2) L)` by least
/// squares), a start for [`steer_gain_from`] far from 1; 1 when the steering is all zero.
fn small_angle_gain(pts: &[SteadyTurn], vehicle: &VehicleSection) -> f64 {
    let (l, k) = (vehicle.wheelbase_m, vehicle.understeer_s2_per_m2);
    let (mut ar, mut aa) = (0.0, 0.0);
    for &(v, d, r) in pts {
        let a = v * d / ((1.0 + k * v * v) * l);
        ar += a * r;
        aa += a * a;
    }
    if aa > 0.0 && (ar / aa).is_finite() {
        ar / aa
    } else {
        1.0
    }
}

/// The course's curvature (yaw rate over speed) above which a steady sample is a turn when the
/// steering is too small to say so ([`course_turns`]), 1/m: a circle of 50 m, which takes a
/// centre-tyre angle of 0.05 rad on a car of 2.5 m, five times [`steady_turns`]' least.
const COURSE_TURN_CURVATURE: f64 = 0.02;

/// The steady samples of `e` where the GNSS course turns ([`COURSE_TURN_CURVATURE`]), whatever
/// the steering says: a `steer` written as a fraction of the lock (-1..1) or in radians reads
/// as under 0.01 rad on every turn, and [`steady_turns`] found none (a black-box probe's such
/// training set was identified with exit 0, without `[lateral]`, its drives blamed).
fn course_turns(e: &Experiment) -> Vec<SteadyTurn> {
    steady_samples(e, STEADY_TURN_MIN_SPEED_MPS, 0.0)
        .into_iter()
        .filter(|&(v, _, r)| (r / v).abs() > COURSE_TURN_CURVATURE)
        .collect()
}

/// A gain from the course's turns ([`course_turns`]) is judged when it is this many standard
/// errors from 1.
const COURSE_GAIN_SIGMAS: f64 = 5.0;

/// A steering gain this many standard errors below 0 turns the car the other way.
pub const STEER_SIGN_SIGMAS: f64 = 3.0;

/// The smallest lock a car has, deg: the model file's floor on `max_steer_deg` ("below 10 no
/// turn tighter than a 30 m circle"). A gain that leaves the car file's lock below it describes
/// no car.
pub const MIN_LOCK_DEG: f64 = 10.0;

/// A gain within this fraction of what a unit gives names that unit (the antenna's wider arc
/// on a circle reads 1-10 % low, as in [`units`]).
const STEER_UNIT_TOLERANCE: f64 = 0.15;

/// The steering gain of a `steer` written as a fraction of the lock (-1..1) read as percent.
pub const STEER_FRACTION_GAIN: f64 = 100.0;

/// Overall steering ratios (steering wheel to road wheels) of road vehicles: about 12:1 on a
/// sports car, 14-18:1 on most cars, to 20-25:1 on vans, trucks and buses.
pub const STEERING_RATIO_RANGE: std::ops::RangeInclusive<f64> = 10.0..=25.0;

/// What a steering gain that no car has most likely means, or `None` for one a car can have.
/// `steer` is percent of the lock (`max_steer_deg`), so
/// - the road wheels' angle in degrees read as percent gives `100 / max_steer_deg` (2.82 on
///   the CAT Vehicle's 35.5 deg): the lock it implies is 100 deg, more than any wheel turns;
/// - the steering wheel's angle in degrees gives `100 / (max_steer_deg R)` for a steering
///   ratio R ([`STEERING_RATIO_RANGE`]): a lock of `100 / R` deg, 4-10 deg;
/// - a fraction of the lock (-1..1) gives [`STEER_FRACTION_GAIN`];
/// - the road wheels' angle in radians gives `100 / max_steer_rad` (161 on 35.5 deg);
/// - a `steer` of the other sign (positive = left) gives minus the car's gain.
pub fn steer_gain_cause(g: f64, std_error: f64, max_steer_deg: f64) -> Option<String> {
    let near = |x: f64| (g.abs() / x - 1.0).abs() < STEER_UNIT_TOLERANCE;
    let wheel_deg = 100.0 / max_steer_deg;
    let wheel_rad = 100.0 / max_steer_deg.to_radians();
    let lock = g.abs() * max_steer_deg;
    let ratio = 100.0 / lock;
    let fraction = near(STEER_FRACTION_GAIN).then(|| {
        "`steer` looks like a fraction of full lock (-1..1: a fraction read as percent gives a \
         gain of 100): the schema's `steer` is percent of full lock: multiply it by 100"
            .to_string()
    });
    let radians = near(wheel_rad).then(|| {
        format!(
            "`steer` looks like the road wheels' angle in radians (radians read as percent of \
             the car file's {max_steer_deg} deg lock, {} rad, give a gain of 100 / {} = {}): \
             the schema's `steer` is percent of full lock: multiply it by {}",
            sig3(max_steer_deg.to_radians()),
            sig3(max_steer_deg.to_radians()),
            sig3(wheel_rad),
            sig3(wheel_rad)
        )
    });
    let unit = if fraction.is_some() || radians.is_some() {
        Some(
            [fraction, radians]
                .into_iter()
                .flatten()
                .collect::<Vec<_>>()
                .join("; or "),
        )
    } else if near(wheel_deg) {
        Some(format!(
            "`steer` looks like the road wheels' angle in degrees (degrees read as percent of \
             the car file's {max_steer_deg} deg lock give a gain of 100 / {max_steer_deg} = {}): \
             the schema's `steer` is percent of full lock: multiply it by 100 / {max_steer_deg}",
            sig3(wheel_deg)
        ))
    } else if lock < MIN_LOCK_DEG && STEERING_RATIO_RANGE.contains(&ratio) {
        Some(format!(
            "`steer` looks like the steering wheel's angle in degrees (with a steering ratio of \
             {ratio:.0}:1, degrees at the steering wheel read as percent of the car file's \
             {max_steer_deg} deg lock give this gain; the lock it implies, {lock:.1} deg, no car \
             has): the schema's `steer` is percent of full lock at the road wheels: divide it by \
             the steering ratio and multiply by 100 / {max_steer_deg}"
        ))
    } else {
        None
    };
    if g < 0.0 && -g > STEER_SIGN_SIGMAS * std_error {
        let sign = "`steer` turns the car the other way than the schema's sign convention \
                    (positive = right): the yaw rate from the GNSS course has the opposite sign \
                    to the steering; negate the column";
        return Some(match unit {
            Some(u) => format!("{sign}; and {u}"),
            None => sign.into(),
        });
    }
    if unit.is_some() {
        return unit;
    }
    let problem = model_file::steer_gain_problem(max_steer_deg, g);
    if problem.is_none() && lock >= MIN_LOCK_DEG {
        return None;
    }
    Some(format!(
        "no car steers so ({}): check `steer`'s unit (percent of full lock), its sign (positive \
         = right), that it is this car's, and the car file's max_steer_deg ({max_steer_deg})",
        problem.unwrap_or_else(|| format!(
            "the lock would be max_steer_deg {max_steer_deg} x {} = {lock:.1} deg, below the \
             {MIN_LOCK_DEG} deg of any car",
            sig3(g)
        ))
    ))
}

/// Three decimals, without a sign on a zero (`-0.000`) and in exponent form below them (a
/// gain of -9.4e-38 from a frozen receiver's course read `-0.000`).
fn dec3(x: f64) -> String {
    if x != 0.0 && x.abs() < 5e-4 {
        format!("{x:.1e}")
    } else {
        format!("{:.3}", x + 0.0)
    }
}

/// Three significant figures.
fn sig3(x: f64) -> String {
    format!("{}", format!("{x:.2e}").parse::<f64>().unwrap_or(x))
}

/// Why the steering of `logs` cannot be the schema's (review finding 01: a `steer` of the other
/// sign gave a gain of -0.987, a `steer` in wheel degrees 2.78; `identify` said so in a note,
/// left `[lateral]` out, wrote the file and exited 0): the gain over their steady turns with
/// the car file's understeer, its standard error, each log's own gain where it has
/// [`MIN_STEADY_TURN_SAMPLES`] / 5, and the likely cause ([`steer_gain_cause`]). `None` when
/// the gain is one a car has, or too few steady turns to tell.
/// When the steering reads too small for [`steady_turns`] to find enough (a fraction of the
/// lock, radians), the turns are the course's ([`course_turns`]) and the gain is fitted from
/// its small-angle estimate.
pub fn steering_gain_problem(logs: &[Experiment], vehicle: &VehicleSection) -> Option<String> {
    let turns = |find: fn(&Experiment) -> Vec<SteadyTurn>| -> Vec<(&str, Vec<SteadyTurn>, usize)> {
        logs.iter()
            .map(|e| (e.name.as_str(), find(e), e.yaw_half_width))
            .collect()
    };
    let pooled = |per_log: &[(&str, Vec<SteadyTurn>, usize)]| -> Vec<SteadyTurn> {
        per_log.iter().flat_map(|p| p.1.clone()).collect()
    };
    let mut per_log = turns(steady_turns);
    let mut all = pooled(&per_log);
    let (mut start, mut by_course) = (1.0, false);
    if all.len() < MIN_STEADY_TURN_SAMPLES {
        by_course = true;
        per_log = turns(course_turns);
        all = pooled(&per_log);
        if all.len() < MIN_STEADY_TURN_SAMPLES {
            return None;
        }
        start = small_angle_gain(&all, vehicle);
    }
    let hw = logs.first().map_or(1, |e| e.yaw_half_width);
    let (g, se) = steer_gain_from(&all, vehicle, hw, start);
    // The course's turns alone are the course's noise on a straight drive at walking pace (a
    // gain of 5.1 +- 23 on the simulator's straight-2.5): only a gain that they determine far
    // from 1 is judged.
    if by_course && !(se.is_finite() && (g - 1.0).abs() > COURSE_GAIN_SIGMAS * se) {
        return None;
    }
    let cause = steer_gain_cause(g, se, vehicle.max_steer_deg)?;
    let each: Vec<String> = per_log
        .iter()
        .filter(|p| p.1.len() >= MIN_STEADY_TURN_SAMPLES / 5)
        .map(|(name, pts, hw)| {
            format!(
                "{name} {}",
                dec3(steer_gain_from(pts, vehicle, *hw, start).0)
            )
        })
        .collect();
    Some(format!(
        "the steering gain (the centre-tyre angle the GNSS course shows over the nominal one \
         from `steer`) is {} +- {} over {} samples of steady turning (per log: {}): \
         {cause}",
        dec3(g),
        dec3(se),
        all.len(),
        if each.is_empty() {
            "none has enough alone".into()
        } else {
            each.join(", ")
        }
    ))
}

/// Two logs' steering gains this far apart (the larger over the smaller) are not one car's
/// steering: a sensor that clips (a probe's `steer` held at +-50 % while the wheels turned to
/// full lock read 1.97 on its circles against 0.99 on its turns, pooled into 1.93 and
/// written), logs of two cars, a sensor changed between them. Within one car's logs they
/// agree to a few per cent (the tyres' slip at full lock against a gentle turn).
pub const STEER_GAIN_SPREAD: f64 = 1.25;
/// ... and this many standard errors of their difference apart.
pub const STEER_GAIN_SPREAD_SIGMAS: f64 = 3.5;

/// Why the logs' steering gains cannot be one car's ([`STEER_GAIN_SPREAD`]), naming each
/// log's and, where the largest log's `steer` is held at its largest magnitude below the
/// lock through its steady turns, the clip. `None` when they agree, or fewer than two logs
/// have [`MIN_STEADY_TURN_SAMPLES`] / 5 steady turns.
pub fn steering_gain_spread_problem(
    logs: &[Experiment],
    vehicle: &VehicleSection,
) -> Option<String> {
    let per_log: Vec<(&Experiment, Vec<SteadyTurn>, f64, f64)> = logs
        .iter()
        .map(|e| (e, steady_turns(e)))
        .filter(|(_, pts)| pts.len() >= MIN_STEADY_TURN_SAMPLES / 5)
        .map(|(e, pts)| {
            let (g, se) = steer_gain_alone(&pts, vehicle, e.yaw_half_width);
            (e, pts, g, se)
        })
        .filter(|p| p.2.is_finite() && p.2 > 0.0 && p.3.is_finite())
        .collect();
    let by_gain =
        |a: &&(&Experiment, Vec<SteadyTurn>, f64, f64),
         b: &&(&Experiment, Vec<SteadyTurn>, f64, f64)| a.2.total_cmp(&b.2);
    let lo = per_log.iter().min_by(by_gain)?;
    let hi = per_log.iter().max_by(by_gain)?;
    if hi.2 / lo.2 < STEER_GAIN_SPREAD || hi.2 - lo.2 < STEER_GAIN_SPREAD_SIGMAS * hi.3.hypot(lo.3)
    {
        return None;
    }
    let each: Vec<String> = per_log
        .iter()
        .map(|(e, _, g, se)| format!("{} {g:.3} +- {se:.3}", e.name))
        .collect();
    // The largest log's steady turns at its largest |steer|: a clip holds the sensor there.
    let largest = hi.0.steer_pct.iter().fold(0.0f64, |m, s| m.max(s.abs()));
    let largest_rad = hi.0.delta_rad.iter().fold(0.0f64, |m, d| m.max(d.abs()));
    let at_largest =
        hi.1.iter()
            .filter(|p| p.1.abs() > largest_rad * (1.0 - 1e-6))
            .count();
    let cause = if largest < 95.0 && at_largest * 2 >= hi.1.len() {
        format!(
            "`steer` in {} is held at its largest, {largest:.1} % of the lock, through {} of \
             its {} samples of steady turning, while the GNSS course turns the car {:.2} \
             times as far as the others' logs say: a steering sensor that clips at \
             {largest:.1} %, whose turns beyond it read as {largest:.1} % (the node reads the \
             same sensor on the bus): fix the sensor's range, or leave the logs that turn \
             beyond it out",
            hi.0.name,
            at_largest,
            hi.1.len(),
            hi.2 / lo.2
        )
    } else {
        "check that the logs are of one car, with one steering sensor, calibrated alike".into()
    };
    Some(format!(
        "the logs' steering gains (the centre-tyre angle the GNSS course shows over the nominal \
         one from `steer`) disagree, {} against {} ({:.0} % apart; one car's steering turns it \
         alike in every log) (per log: {}): {cause}",
        hi.0.name,
        lo.0.name,
        (hi.2 / lo.2 - 1.0) * 100.0,
        each.join(", ")
    ))
}

/// A steering whose zero is this far off, % of the lock, is refused (when it is also
/// [`STEER_ZERO_SIGMAS`] standard errors from 0): at 10 m/s on the CAT Vehicle, 0.5 % of its
/// 35.5 deg lock is a yaw rate of 0.012 rad/s with the wheel straight, 0.24 m sideways over the
/// node's 2 s prediction.
pub const STEER_ZERO_MAX_PCT: f64 = 0.5;
/// See [`STEER_ZERO_MAX_PCT`].
pub const STEER_ZERO_SIGMAS: f64 = 3.0;
/// Steady samples at speed needed to judge the steering's zero (4 s at 50 Hz).
pub const MIN_STEER_ZERO_SAMPLES: usize = 200;
/// Only samples faster than this judge the zero, m/s: the course's yaw rate is noisier
/// the slower the car (its angle `atan(r L / v)`).
const STEER_ZERO_MIN_SPEED_MPS: f64 = 4.0;

/// The steering's zero: the `steer` at which the GNSS course runs straight, % of the lock, its
/// standard error, and the samples. A line `a = g delta + c` through the steady samples at
/// speed, straight driving included, with `a = atan(r L / v) (1 + K v^2)` the centre angle the
/// course shows (the car file's understeer K); the zero is `-c / g`. With too little turning
/// to fit `g` (angles spanning less than 0.02 rad), `g` is 1. `None` with fewer than
/// [`MIN_STEER_ZERO_SAMPLES`].
pub fn steer_zero(
    pts: &[SteadyTurn],
    vehicle: &VehicleSection,
    hw: usize,
) -> Option<(f64, f64, usize)> {
    let (l, k) = (vehicle.wheelbase_m, vehicle.understeer_s2_per_m2);
    let xy: Vec<(f64, f64)> = pts
        .iter()
        .filter(|p| p.0 > STEER_ZERO_MIN_SPEED_MPS)
        .map(|&(v, d, r)| (d, (r * l / v).atan() * (1.0 + k * v * v)))
        .filter(|(d, a)| d.is_finite() && a.is_finite())
        .collect();
    let n = xy.len();
    if n < MIN_STEER_ZERO_SAMPLES {
        return None;
    }
    let nf = n as f64;
    let mx = xy.iter().map(|p| p.0).sum::<f64>() / nf;
    let my = xy.iter().map(|p| p.1).sum::<f64>() / nf;
    let sxx: f64 = xy.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let (lo, hi) = xy
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.0), hi.max(p.0))
        });
    // Each yaw rate is a central difference over 2 hw + 1 samples: one independent error.
    let window = (2 * hw + 1) as f64;
    let (g, zero_rad, var) = if hi - lo >= 0.02 && sxx > 0.0 {
        let g = xy.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum::<f64>() / sxx;
        let c = my - g * mx;
        let rss: f64 = xy.iter().map(|p| (p.1 - c - g * p.0).powi(2)).sum();
        let s2 = rss / (nf - 2.0) * window;
        // var(-c / g) to first order, c and g correlated through the mean angle.
        let var_c = s2 * (1.0 / nf + mx * mx / sxx);
        let var_g = s2 / sxx;
        let cov = -mx * s2 / sxx;
        let z = -c / g;
        let var = (var_c + z * z * var_g + 2.0 * z * cov) / (g * g);
        (g, z, var)
    } else {
        let z = xy.iter().map(|p| p.0 - p.1).sum::<f64>() / nf;
        let rss: f64 = xy.iter().map(|p| (p.0 - p.1 - z).powi(2)).sum();
        (1.0, z, rss / (nf - 1.0) * window / nf)
    };
    if !(g.is_finite() && g > 0.0 && zero_rad.is_finite() && var.is_finite()) {
        return None;
    }
    let per_pct = vehicle.max_steer_deg.to_radians() / 100.0;
    Some((zero_rad / per_pct, var.sqrt() / per_pct, n))
}

/// Why the steering's zero of `logs` cannot be the car's: `steer` is
/// [`STEER_ZERO_MAX_PCT`] or more off where the GNSS course runs straight (black-box probe:
/// a sensor 5 % off its zero gave a steering gain of 0.932 and a yaw-rate fit of 65.9 % instead
/// of 80.5 %, with exit 0 and no note; the node, reading the same sensor, predicts a car that
/// drives straight on a circle). `None` when the zero is within it, or too few steady samples
/// at speed to tell.
pub fn steering_zero_problem(logs: &[Experiment], vehicle: &VehicleSection) -> Option<String> {
    let hw = logs.first().map_or(1, |e| e.yaw_half_width);
    let per_log: Vec<(&str, Vec<SteadyTurn>)> = logs
        .iter()
        .map(|e| {
            (
                e.name.as_str(),
                steady_samples(e, STEER_ZERO_MIN_SPEED_MPS, 0.0),
            )
        })
        .collect();
    let all: Vec<SteadyTurn> = per_log.iter().flat_map(|p| p.1.clone()).collect();
    let (zero, se, n) = steer_zero(&all, vehicle, hw)?;
    if zero.abs() < STEER_ZERO_MAX_PCT || zero.abs() < STEER_ZERO_SIGMAS * se {
        return None;
    }
    let each: Vec<String> = per_log
        .iter()
        .filter_map(|(name, pts)| {
            steer_zero(pts, vehicle, hw).map(|(z, _, _)| format!("{name} {z:+.2} %"))
        })
        .collect();
    let (side, fix) = if zero > 0.0 {
        ("left", format!("subtract {zero:.2} from"))
    } else {
        ("right", format!("add {:.2} to", -zero))
    };
    Some(format!(
        "the steering's zero is off: the GNSS course runs straight at `steer` = {zero:+.2} % \
         +- {se:.2} over {n} samples of steady driving faster than {STEER_ZERO_MIN_SPEED_MPS} \
         m/s (per log: {}), so a `steer` of 0 turns the car {side} (at most \
         {STEER_ZERO_MAX_PCT} % is taken as the car's): the node reads the same `steer` on the \
         bus, so recalibrate the steering sensor's zero; to identify from these logs, {fix} \
         every `steer` (positive = right)",
        if each.is_empty() {
            "none has enough alone".into()
        } else {
            each.join(", ")
        }
    ))
}

/// Why the steering of `logs` cannot be the car's as the schema has it: a gain no car has
/// ([`steering_gain_problem`]: the other sign, another unit), gains that differ from log to
/// log ([`steering_gain_spread_problem`]: a sensor that clips) or a zero that is off
/// ([`steering_zero_problem`]).
pub fn steering_problem(logs: &[Experiment], vehicle: &VehicleSection) -> Option<String> {
    steering_gain_problem(logs, vehicle)
        .or_else(|| steering_gain_spread_problem(logs, vehicle))
        .or_else(|| steering_zero_problem(logs, vehicle))
}

/// Steering gain and understeer term from `r = v tan(g delta / (1 + K v^2)) / L` by
/// Gauss-Newton on the samples faster than 2 m/s with |delta| > 0.01 rad; then the dynamic
/// part, a first-order lag with delay, by output error. `Err(reason)` when the data do not
/// excite it.
pub fn identify_lateral(
    training: &[Experiment],
    vehicle: &VehicleSection,
    opts: &IdentifyOptions,
) -> Result<std::result::Result<LateralFit, String>> {
    // The steering gain and understeer are a steady-state relation: only steady turns count
    // ([`steady_turns`]).
    let turns = SteadyTurns {
        per_log: training.iter().map(steady_turns).collect(),
        vehicle,
    };
    if let Some(why) = turns.too_few() {
        return Ok(Err(why));
    }
    let estimate_k = turns.speed_span_mps() > 2.0;
    let log_weights = turns.log_weights(training, estimate_k);
    let weighted = turns.gauss_newton(estimate_k, &log_weights);
    let understeer = if estimate_k {
        let hw = training.first().map_or(1, |e| e.yaw_half_width);
        understeer_verdict(&weighted, turns.samples(), hw)
    } else {
        Understeer::SpeedSpan
    };
    // An understeer the drives do not determine is the car file's: the gain is fitted again
    // with it.
    let (g, k) = match understeer {
        Understeer::Undetermined { .. } => turns.gauss_newton(false, &log_weights).gain_and_k(),
        _ => weighted.gain_and_k(),
    };
    if let Some(why) = steady_state_problem(vehicle, g, k) {
        return Ok(Err(why));
    }
    let tf = yaw_rate_lag(training, vehicle, (g, k), opts)?;
    Ok(Ok(LateralFit {
        steer_gain: g,
        understeer_s2_per_m2: k,
        understeer,
        tf,
    }))
}

/// The steady turns of each training log and the car they are fitted for, in
/// [`identify_lateral`].
struct SteadyTurns<'a> {
    /// Each log's samples ([`steady_turns`]), in the logs' order.
    per_log: Vec<Vec<SteadyTurn>>,
    /// Its wheelbase, and the understeer each fit starts from (and keeps when K is not
    /// estimated).
    vehicle: &'a VehicleSection,
}

/// The result of [`SteadyTurns::gauss_newton`]: the estimates, with J'J and the weighted
/// residuals' sum of squares at the end, for K's standard error.
struct GaussNewton {
    /// Steering gain g.
    steer_gain: f64,
    /// Understeer K, s^2/m^2.
    understeer_s2_per_m2: f64,
    /// J'J of the last iteration (K's row and column zero when K is the car file's).
    jtj: [[f64; 2]; 2],
    /// The weighted residuals' sum of squares, (rad/s)^2.
    cost: f64,
}

impl GaussNewton {
    fn gain_and_k(&self) -> (f64, f64) {
        (self.steer_gain, self.understeer_s2_per_m2)
    }
}

impl SteadyTurns<'_> {
    /// Samples over all logs.
    fn samples(&self) -> usize {
        self.per_log.iter().map(Vec::len).sum()
    }

    /// Why the logs hold too few samples ([`MIN_STEADY_TURN_SAMPLES`]) to fit on; `None` when
    /// they hold enough.
    fn too_few(&self) -> Option<String> {
        let n = self.samples();
        (n < MIN_STEADY_TURN_SAMPLES).then(|| {
            format!(
                "only {n} samples of steady steering above 0.01 rad at more than 2 m/s (at least {MIN_STEADY_TURN_SAMPLES} needed: drive turns or circles)"
            )
        })
    }

    /// The samples' speed span over all logs, m/s: K is estimated only when it is above 2 m/s.
    fn speed_span_mps(&self) -> f64 {
        span(self.per_log.iter().flatten().map(|p| p.0))
    }

    /// The measured yaw rate less the steady-state model's with gain `g` and understeer `k`,
    /// rad/s.
    fn residual_rad_per_s(&self, g: f64, k: f64, (v, d, r): SteadyTurn) -> f64 {
        r - v * (g * d / (1.0 + k * v * v)).tan() / self.vehicle.wheelbase_m
    }

    /// Each log's weight in the final fit: the inverse of its noise about a first fit with
    /// every log alike.
    fn log_weights(&self, training: &[Experiment], estimate_k: bool) -> Vec<f64> {
        // Every log alike first; then each weighted by its own noise about that fit (logs of a
        // standard receiver beside a survey-grade one's: `stats::inverse_noise_weights`),
        // measured over all its steady driving, straight too: a log of step steers holds a few
        // seconds of steady turning, and the straights between them at the same speeds.
        let (g1, k1) = self
            .gauss_newton(estimate_k, &vec![1.0; self.per_log.len()])
            .gain_and_k();
        let first_residuals: Vec<Vec<f64>> = training
            .iter()
            .map(|e| {
                steady_samples(e, STEADY_TURN_MIN_SPEED_MPS, 0.0)
                    .into_iter()
                    .map(|p| self.residual_rad_per_s(g1, k1, p))
                    .collect()
            })
            .collect();
        stats::inverse_noise_weights(
            &first_residuals
                .iter()
                .map(Vec::as_slice)
                .collect::<Vec<_>>(),
        )
    }

    /// Gauss-Newton on (g, K), or on g alone with K the car file's, each log's samples
    /// weighted by `log_weights`.
    fn gauss_newton(&self, estimate_k: bool, log_weights: &[f64]) -> GaussNewton {
        let l = self.vehicle.wheelbase_m;
        let (mut g, mut k) = (1.0, self.vehicle.understeer_s2_per_m2);
        let mut jtj = [[0.0; 2]; 2];
        let mut cost = 0.0;
        for _ in 0..30 {
            let mut jtr = [0.0; 2];
            (jtj, cost) = ([[0.0; 2]; 2], 0.0);
            let weighted = self
                .per_log
                .iter()
                .zip(log_weights)
                .flat_map(|(log, &w)| log.iter().map(move |&p| (p, w)));
            for ((v, d, r), w) in weighted {
                let den = 1.0 + k * v * v;
                let arg = g * d / den;
                let sec2 = 1.0 / arg.cos().powi(2);
                let res = w * self.residual_rad_per_s(g, k, (v, d, r));
                let jg = w * v / l * sec2 * d / den;
                let jk = -w * v / l * sec2 * g * d * v * v / (den * den);
                let j = [jg, if estimate_k { jk } else { 0.0 }];
                for a in 0..2 {
                    for b in 0..2 {
                        jtj[a][b] += j[a] * j[b];
                    }
                    jtr[a] += j[a] * res;
                }
                cost += res * res;
            }
            let mut solve = jtj;
            if !estimate_k {
                solve[1][1] = 1.0;
            }
            let det = solve[0][0] * solve[1][1] - solve[0][1] * solve[1][0];
            if det.abs() < 1e-300 {
                break;
            }
            let dg = (jtr[0] * solve[1][1] - jtr[1] * solve[0][1]) / det;
            let dk = (solve[0][0] * jtr[1] - solve[1][0] * jtr[0]) / det;
            g += dg;
            k = (k + dk).max(0.0);
            if dg.abs() < 1e-10 && dk.abs() < 1e-12 {
                break;
            }
        }
        GaussNewton {
            steer_gain: g,
            understeer_s2_per_m2: k,
            jtj,
            cost,
        }
    }
}

/// Whether the understeer K of `fit` (over `samples` steady turns, yaw rates over `2 hw + 1`
/// samples) is estimated: its standard error relative to K at most
/// [`MAX_UNDERSTEER_RELATIVE_STD_ERROR`]; else undetermined.
fn understeer_verdict(fit: &GaussNewton, samples: usize, hw: usize) -> Understeer {
    let (jtj, k) = (fit.jtj, fit.understeer_s2_per_m2);
    // K's standard error, s^2 (J'J)^-1, with the yaw rate's central difference over
    // 2 hw + 1 samples counted as one independent error (as the stiffnesses', dynamics.rs).
    let s2 = fit.cost / (samples as f64 - 2.0).max(1.0) * (2 * hw + 1) as f64;
    let det = jtj[0][0] * jtj[1][1] - jtj[0][1] * jtj[1][0];
    let se = if det > 0.0 {
        (s2 * jtj[0][0] / det).sqrt()
    } else {
        f64::INFINITY
    };
    let relative = se / k;
    if relative.is_finite() && relative <= MAX_UNDERSTEER_RELATIVE_STD_ERROR {
        Understeer::Estimated {
            relative_std_error: relative,
        }
    } else {
        Understeer::Undetermined {
            estimate: k,
            relative_std_error: relative,
        }
    }
}

/// Why the steering gain `g` or the understeer `k` cannot be written; `None` when both can.
fn steady_state_problem(vehicle: &VehicleSection, g: f64, k: f64) -> Option<String> {
    // The reader's bound (a gain within 0.1..10 and a lock below 90 degrees), so that the file
    // written loads.
    if let Some(why) = model_file::steer_gain_problem(vehicle.max_steer_deg, g) {
        return Some(format!("steering gain estimate {g} is implausible ({why})"));
    }
    model_file::range_problem("lateral.understeer_s2_per_m2", k)
        .map(|why| format!("understeer estimate {k} is implausible ({why})"))
}

/// The lateral model's dynamic part over whole experiments: the lag with delay from the
/// kinematic yaw rate with the fitted `(g, K)` to the measured one, by output error.
fn yaw_rate_lag(
    training: &[Experiment],
    vehicle: &VehicleSection,
    (g, k): (f64, f64),
    opts: &IdentifyOptions,
) -> Result<TransferFunction> {
    let r_kin: Vec<Vec<f64>> = training
        .iter()
        .map(|e| {
            e.as_measured_yaw(&validate::kinematic_yaw(
                vehicle,
                g,
                k,
                &e.vel,
                &e.delta_rad,
            ))
        })
        .collect();
    let inputs: Vec<[&[f64]; 1]> = r_kin.iter().map(|r| [&r[..]]).collect();
    let data: Vec<Data> = training
        .iter()
        .zip(&inputs)
        .map(|(e, u)| Data {
            inputs: u,
            output: &e.yaw_rate,
            weight: 1.0,
            // Where the track is interpolated across an outage the course is not measured.
            skip: &e.gnss_gap,
        })
        .collect();
    let ts = opts.preprocess.ts_s;
    let (fit, _) = fit_siso_with_delay_scan(
        &data,
        1,
        false,
        &(0..=10).collect::<Vec<_>>(),
        &initial_dens(None, 1, ts),
        ts,
        opts.max_iter,
    )?;
    lag_within_sample_rate(fit.tfs[0])
}

/// `tf` with its pole at most [`MAX_LATERAL_POLE_PER_S`].
fn lag_within_sample_rate(mut tf: TransferFunction) -> Result<TransferFunction> {
    let den = tf.to_monic();
    let a = den.denominator()[1];
    if a > MAX_LATERAL_POLE_PER_S {
        // No lag measurable at this sample rate: keep the DC gain, lag = 2 samples.
        let dc = tf.dc_gain().unwrap_or(1.0);
        tf = TransferFunction::new(
            &[dc * MAX_LATERAL_POLE_PER_S],
            &[1.0, MAX_LATERAL_POLE_PER_S],
            tf.delay_s(),
        )
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    }
    Ok(tf)
}

/// The lateral model's steady-state part and lag.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LateralFit {
    /// Steering gain g (true centre angle / nominal).
    pub steer_gain: f64,
    /// Understeer K, s^2/m^2.
    pub understeer_s2_per_m2: f64,
    /// Whether K was estimated, or why it is the car file's.
    pub understeer: Understeer,
    /// The lag G(s) from the kinematic yaw rate to the measured one.
    pub tf: TransferFunction,
}

/// Largest standard error of the understeer K, relative to its value, for it to be written
/// (else the car file's is kept). K weighs the steady yaw rate by `1 / (1 + K v^2)`: a quarter
/// of a typical 0.002 s^2/m^2 moves it by 5 % at 10 m/s. A review's 4 Hz receiver on a long car
/// gave 0.0017 to 0.0057 over three seeds for a plant's 0.00215 (RTK: 0.00225), unchecked,
/// and the node's lateral model used it in place of the car file's.
pub const MAX_UNDERSTEER_RELATIVE_STD_ERROR: f64 = 0.25;

/// How the lateral model's understeer was decided ([`LateralFit::understeer`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Understeer {
    /// Estimated, with this standard error relative to the value.
    Estimated {
        /// Standard error / value.
        relative_std_error: f64,
    },
    /// The car file's: the steady turns span less than 2 m/s of speed.
    SpeedSpan,
    /// The car file's: the estimate's standard error is above
    /// [`MAX_UNDERSTEER_RELATIVE_STD_ERROR`].
    Undetermined {
        /// What the drives gave.
        estimate: f64,
        /// Its standard error / value.
        relative_std_error: f64,
    },
}

/// How long steering and speed must have been steady for a sample to count in the lateral
/// model's steady-state fit, s (the yaw rate settles within a second of a step at 16 m/s).
pub const LATERAL_STEADY_S: f64 = 1.5;

/// Fastest lateral lag pole written, 1/s (time constant 2 samples of 20 ms): a faster fitted
/// pole means no lag is measurable, and is replaced by this one with the same DC gain.
pub const MAX_LATERAL_POLE_PER_S: f64 = 25.0;

fn fit_from(
    source: &str,
    train: &Score,
    kin_train: &Score,
    val: Option<(&Score, &Score)>,
    note: String,
) -> Fit {
    Fit {
        source: source.to_string(),
        training_fit_percent: train.fit_percent,
        training_mse: train.mse,
        kinematic_training_fit_percent: kin_train.fit_percent,
        kinematic_training_mse: kin_train.mse,
        validation_fit_percent: val.and_then(|v| v.0.fit_percent),
        validation_mse: val.and_then(|v| v.0.mse),
        kinematic_validation_fit_percent: val.and_then(|v| v.1.fit_percent),
        kinematic_validation_mse: val.and_then(|v| v.1.mse),
        note,
    }
}

/// Loads and preprocesses logs.
pub fn load_all(
    paths: &[PathBuf],
    vehicle: &VehicleSection,
    opts: &PreprocessOptions,
) -> Result<Vec<Experiment>> {
    let [set, _] = load_sets([paths, &[]], vehicle, opts, || {})?;
    Ok(set)
}

/// Loads and preprocesses two sets of logs (training and validation), named over both
/// ([`preprocess::log_names`]: a training and a validation log of one file name are told apart
/// by their paths); `each` is called after each log.
pub fn load_sets(
    sets: [&[PathBuf]; 2],
    vehicle: &VehicleSection,
    opts: &PreprocessOptions,
    mut each: impl FnMut(),
) -> Result<[Vec<Experiment>; 2]> {
    let all: Vec<&Path> = sets
        .iter()
        .flat_map(|s| s.iter().map(PathBuf::as_path))
        .collect();
    let mut names = preprocess::log_names(&all).into_iter();
    let mut read = |paths: &[PathBuf]| -> Result<Vec<Experiment>> {
        paths
            .iter()
            .zip(names.by_ref())
            .map(|(p, name)| {
                let e = preprocess::load_named(p, &name, vehicle, opts);
                each();
                e
            })
            .collect()
    };
    Ok([read(sets[0])?, read(sets[1])?])
}

/// How far the logs' GNSS rate may stray from the base file's before the identified file takes
/// the logs' (a receiver's nominal rate and its measured median interval agree far better).
const GNSS_RATE_TOLERANCE: f64 = 0.25;

/// The identified file describes the receiver that made the training logs: when their GNSS
/// rate (the median of the logs' [`Experiment::gnss_rate_hz`]) differs from the base file's by
/// more than [`GNSS_RATE_TOLERANCE`], the file takes the logs' rate (rounded to 0.1 Hz, within
/// the model file's 1..100 Hz), and the note says so. Without this, identify on 1 Hz logs wrote
/// the base's 100 Hz, and the node built from the file never accepted a position from that
/// receiver (replay: no prediction at all).
fn receiver_rate(model: &mut ModelFile, training: &[Experiment]) -> Option<String> {
    let mut rates: Vec<f64> = training
        .iter()
        .map(|e| e.gnss_rate_hz)
        .filter(|r| r.is_finite() && *r > 0.0)
        .collect();
    let measured = stats::median(&mut rates);
    if !measured.is_finite() {
        return None;
    }
    let base = model.vehicle.gnss_rate_hz;
    let (rate, lost) = set_receiver_rate(model, measured)?;
    let mut note = format!(
        "vehicle.gnss_rate_hz = {rate}: the training logs' GNSS fixes come at {measured:.2} Hz \
         (median interval), the base file said {base} Hz"
    );
    if let Some((was, lost_s)) = lost {
        note.push_str(&format!(
            "; inputs.gnss_lost_s = {lost_s} (twice the GNSS timeout at that rate; the base \
             file's {was} s is shorter than the timeout)"
        ));
    }
    Some(note)
}

/// The training logs whose GNSS rate is more than [`GNSS_RATE_TOLERANCE`] off the file's
/// `gnss_rate_hz` (after [`receiver_rate`]), named with their rates and what was written: a
/// receiver changed between sessions. A black-box probe's 8 logs from a 100 Hz receiver and 3
/// from a 10 Hz one wrote `gnss_rate_hz = 100` without a word; the file describes one
/// receiver, and a node built from it expects fixes at that rate.
fn mixed_receiver_rates(model: &ModelFile, training: &[Experiment]) -> Option<String> {
    let written = model.vehicle.gnss_rate_hz;
    let others: Vec<String> = training
        .iter()
        .filter(|e| {
            e.gnss_rate_hz.is_finite()
                && e.gnss_rate_hz > 0.0
                && (e.gnss_rate_hz / written - 1.0).abs() > GNSS_RATE_TOLERANCE
        })
        .map(|e| format!("{} at {:.1} Hz", e.name, e.gnss_rate_hz))
        .collect();
    if others.is_empty() {
        return None;
    }
    Some(format!(
        "{} of the {} training logs' GNSS fixes come at another rate than the \
         vehicle.gnss_rate_hz = {written} written (the logs' median): {}. Another receiver? The \
         file describes one, and a node built from it expects fixes at {written} Hz: identify \
         each receiver's logs apart, or set gnss_rate_hz to the receiver the car will carry",
        others.len(),
        training.len(),
        others.join(", ")
    ))
}

/// `model` made to describe a receiver at `measured_hz`, when that is more than
/// [`GNSS_RATE_TOLERANCE`] off its `gnss_rate_hz`: the rate (rounded to 0.1 Hz, within the model
/// file's 1..100 Hz) and, when the outage bridged by dead reckoning would not outlast the GNSS
/// timeout at that rate, `gnss_lost_s` (twice the timeout). Returns the rate and the change of
/// `gnss_lost_s` (was, now); `None` when the file's rate stands.
pub fn set_receiver_rate(
    model: &mut ModelFile,
    measured_hz: f64,
) -> Option<(f64, Option<(f64, f64)>)> {
    let base = model.vehicle.gnss_rate_hz;
    if !(measured_hz.is_finite() && measured_hz > 0.0)
        || (measured_hz / base - 1.0).abs() <= GNSS_RATE_TOLERANCE
    {
        return None;
    }
    let (lo, hi) = model_file::GNSS_RATE_RANGE_HZ;
    let rate = rate_to_declare_hz(measured_hz).clamp(lo, hi);
    model.vehicle.gnss_rate_hz = rate;
    let lost = model.inputs.outlast_gnss_timeout(rate);
    Some((rate, lost))
}

/// A receiver's rate as a model file declares it, from its measured rate (the logs' median
/// interval): rounded to 0.1 Hz, the receiver's nominal rate and its clock's error apart.
pub fn rate_to_declare_hz(measured_hz: f64) -> f64 {
    (measured_hz * 10.0).round() / 10.0
}

/// Why a log's receiver is too slow for what `identify` and `compare` measure on its track,
/// or `None`: its fixes come at a rate that, as a model file would declare it
/// ([`rate_to_declare_hz`]), is below the least a model file may declare
/// ([`model_file::GNSS_RATE_RANGE_HZ`], the rates the node's lowpass and gap logic are
/// designed for), and the checks that compare the track with the wheel speed are made for
/// those rates too. Between fixes two or more seconds apart the track cuts every turn short,
/// so a black-box probe's 0.5 Hz receiver was refused for "a wheel speed that sticks at its
/// last value" (`units::disagreement`: 43.6 m by the wheel speed, 6.8 m along the track, on
/// the 5-minute drive's turns; on the circles, 153.0 m and 18.6 m), noted "the wheel speed
/// `vel` is 0.62 s +- 0.13 late" on a straight drive, and blamed one `steer` sample, "a
/// corrupt value there?", for the lateral fit on the turns: the receiver is named instead,
/// with its rate.
pub fn slow_receiver(e: &Experiment) -> Option<String> {
    let (lo, hi) = model_file::GNSS_RATE_RANGE_HZ;
    let hz = e.gnss_rate_hz;
    (hz.is_finite() && hz > 0.0 && rate_to_declare_hz(hz) < lo).then(|| {
        format!(
            "the GNSS fixes come every {:.2} s ({hz:.2} Hz, the median interval): below the \
             {lo} Hz a model file may declare (the rates the node's lowpass and gap logic are \
             designed for: {lo}..{hi} Hz), and too far apart for the track to judge the wheel \
             speed by (between fixes that far apart the track cuts the turns short, and the \
             wheel speed reads as going further), to time the fixes against it, or to give \
             the course the lateral fit needs: set the receiver to send at {lo} Hz or more",
            1.0 / hz
        )
    })
}

/// The whole pipeline on preprocessed experiments. `base` provides the vehicle, the hybrid
/// thresholds and the models kept when the data cannot identify them (the published file).
pub fn identify(
    training: Vec<Experiment>,
    validation: Vec<Experiment>,
    base: &ModelFile,
    opts: &IdentifyOptions,
) -> Result<Identification> {
    let started = Instant::now();
    if training.is_empty() {
        bail!("no training logs");
    }
    let vehicle = base.vehicle;
    let steps = speed_steps(&training, &validation);
    let correlation_dx = correlation::rank(&training, &vehicle, |e| &e.dx);
    let correlation_vel = correlation::rank(&training, &vehicle, |e| &e.vel);
    let mut notes = gnss_latency_notes(&training, &validation);
    let speed = identify_speed(&training, &validation, opts)?;
    notes.extend(speed.delay_at_the_limit(opts));
    notes.extend(speed_step_mismatch_note(
        &speed.tf,
        delay::mean_of(steps.iter().map(|s| s.delay_s)),
    ));
    let dx_dt_tfs = dx_dt_or_kept(&training, opts, &mut notes)?;
    let (steering_problem, lateral) =
        lateral_unless_steering_problem(&training, &vehicle, opts, &mut notes)?;
    let identified_dynamics = cornering_stiffnesses(&training, base, lateral.as_ref(), &mut notes);
    let slow = sensor_rates::slow_sensors(
        &training,
        &base.node_config().freshness,
        speed.tf.delay_s(),
        lateral.as_ref().map(|l| l.tf.delay_s()),
    );
    notes.extend(slow.note);

    let fitted = Fitted {
        speed: speed.tf,
        dx_dt: dx_dt_tfs.as_deref(),
        lateral,
        dynamics: identified_dynamics.as_ref(),
    };
    let mut model = identified_model(base, &training, fitted, &mut notes);
    let training_sims = simulate_each(&model, &training)?;
    let validation_sims = simulate_each(&model, &validation)?;
    let training_scores = validate::scores(&training, &training_sims);
    let validation_scores =
        (!validation.is_empty()).then(|| validate::scores(&validation, &validation_sims));
    let vs = validation_scores.as_ref();
    notes.extend(lateral_below_kinematic(vs));
    write_fits(&mut model, &training_scores, vs, dx_dt_tfs.is_some());
    if dx_dt_tfs.is_some() {
        notes.push("dx/dt (eq 7) takes absolute positions x, y as inputs: it describes the places it was trained on, not the car; compare its validation fit with the training fit before trusting it elsewhere".into());
    }
    Ok(Identification {
        model,
        training,
        validation,
        training_sims,
        validation_sims,
        steps,
        correlation_dx,
        correlation_vel,
        speed,
        training_scores,
        validation_scores,
        dx_dt_identified: dx_dt_tfs.is_some(),
        dynamics: identified_dynamics,
        steering_problem,
        slow_sensor_problem: slow.problem,
        notes,
        seconds: started.elapsed().as_secs_f64(),
    })
}

/// The speed's step responses (Fig 2) in every log, training then validation.
fn speed_steps(training: &[Experiment], validation: &[Experiment]) -> Vec<delay::StepResponse> {
    training
        .iter()
        .chain(validation)
        .flat_map(|e| delay::step_responses(&e.name, &e.t, &e.input_vel, &e.vel))
        .collect()
}

/// A note for each log whose GNSS fixes come measurably late behind (or early ahead of) its
/// wheel speed ([`units::gnss_latency`]).
fn gnss_latency_notes(training: &[Experiment], validation: &[Experiment]) -> Vec<String> {
    let mut notes = Vec::new();
    // Fixes late behind the wheel speed: the lateral model's lag would take the latency in.
    for e in training.iter().chain(validation) {
        // A receiver too slow to time the fixes by is named as such ([`slow_receiver`]).
        if slow_receiver(e).is_some() {
            continue;
        }
        if let Some((lag, se)) = units::gnss_latency(e) {
            if lag.abs() > units::gnss_latency_named_above_s(e.gnss_rate_hz)
                && lag.abs() > units::GNSS_LATENCY_SIGMAS * se
            {
                let best_fit = "(the lag that best fits the speed along the track with `vel`)";
                notes.push(if lag > 0.0 {
                    format!(
                        "{}: the GNSS fixes are {lag:.2} s +- {se:.2} late behind the wheel \
                         speed {best_fit}: the yaw rate and dx/dt fitted from the track lag the \
                         steering by as much, which the lateral and dx/dt models cannot follow \
                         (their fits fall: a fit below the floor may be this, not another car), \
                         and the node, fed fixes as late, predicts from positions that old; log \
                         the fixes at their time of validity, or use a receiver with less \
                         latency",
                        e.name
                    )
                } else {
                    // Fixes ahead of the wheel: it is the wheel speed that comes late (the
                    // black-box probe's note said the fixes were "early" and blamed the
                    // receiver's latency).
                    format!(
                        "{}: the wheel speed `vel` is {:.2} s +- {se:.2} late behind the GNSS \
                         track {best_fit}: a wheel speed logged late, or filtered on its way to \
                         the log; the speed models' delays take it in; log `vel` at its time \
                         of measurement",
                        e.name, -lag
                    )
                });
            }
        }
    }
    notes
}

/// The dx/dt model's blocks ([`identify_dx_dt`]), or `None` with a note when the logs do not
/// excite it (the file then keeps the base file's).
fn dx_dt_or_kept(
    training: &[Experiment],
    opts: &IdentifyOptions,
    notes: &mut Vec<String>,
) -> Result<Option<Vec<TransferFunction>>> {
    Ok(match identify_dx_dt(training, opts)? {
        Ok(tfs) => Some(tfs),
        Err(why) => {
            notes.push(format!(
                "dx/dt (eq 7) not re-identified: {why}; the model file keeps the input model's dx_dt"
            ));
            None
        }
    })
}

/// The training logs' steering problem ([`steering_problem`]) and the lateral model
/// ([`identify_lateral`]), which is fitted only when there is none; a note says why the
/// model is missing.
fn lateral_unless_steering_problem(
    training: &[Experiment],
    vehicle: &VehicleSection,
    opts: &IdentifyOptions,
    notes: &mut Vec<String>,
) -> Result<(Option<String>, Option<LateralFit>)> {
    // A steering no car has (the other sign, degrees) is the log's, not the car's: named as a
    // refusal, and the lateral model is not fitted to it.
    let steering_problem = steering_problem(training, vehicle);
    let fitted = match &steering_problem {
        Some(why) => Err(why.clone()),
        None => identify_lateral(training, vehicle, opts)?,
    };
    let lateral = match fitted {
        Ok(l) => Some(l),
        Err(why) => {
            notes.push(format!("lateral model not identified: {why}"));
            None
        }
    };
    Ok((steering_problem, lateral))
}

/// The cornering stiffnesses ([`dynamics::identify_dynamics`], with the lateral model's
/// steering gain), when the car file has a `[dynamics]` and the drives determine them; a note
/// either way.
fn cornering_stiffnesses(
    training: &[Experiment],
    base: &ModelFile,
    lateral: Option<&LateralFit>,
    notes: &mut Vec<String>,
) -> Option<dynamics::DynamicsFit> {
    let Some(prior) = &base.dynamics else {
        notes.push("[dynamics] not identified: the car file has none (its mass, yaw inertia and centre of gravity are needed; the cornering stiffnesses are then fitted)".into());
        return None;
    };
    let steer_gain = lateral.map_or(1.0, |l| l.steer_gain);
    match dynamics::identify_dynamics(training, &base.vehicle, prior, steer_gain) {
        Ok(fit) => {
            notes.push(format!(
                "[dynamics] cornering stiffnesses identified from {} samples at speed ({} cornering): C_f {:.0} N/rad (+-{:.1} %), C_r {:.0} N/rad (+-{:.1} %); course rate fit {:.1} % (the car file's stiffnesses {:.1} %, kinematic {:.1} %)",
                fit.samples,
                fit.cornering_samples,
                fit.section.cornering_front_n_per_rad,
                100.0 * fit.relative_std_error.0,
                fit.section.cornering_rear_n_per_rad,
                100.0 * fit.relative_std_error.1,
                fit.fit_percent,
                fit.prior_fit_percent,
                fit.kinematic_fit_percent
            ));
            Some(fit)
        }
        Err(why) => {
            notes.push(format!(
                "[dynamics] cornering stiffnesses not identified, the car file's kept: {why}"
            ));
            None
        }
    }
}

/// What the drives determined, for [`identified_model`].
struct Fitted<'a> {
    /// The speed model (eq 5 form).
    speed: TransferFunction,
    /// The dx/dt model's blocks; `None`: the base file's model is kept.
    dx_dt: Option<&'a [TransferFunction]>,
    /// The lateral model; `None`: the file has none.
    lateral: Option<LateralFit>,
    /// The cornering stiffnesses; `None`: the base file's `[dynamics]` is kept.
    dynamics: Option<&'a dynamics::DynamicsFit>,
}

/// The model file to write: the base file with the logs' receiver rate ([`receiver_rate`])
/// and the fitted models (their fits not yet scored), and notes on what it keeps.
fn identified_model(
    base: &ModelFile,
    training: &[Experiment],
    fitted: Fitted,
    notes: &mut Vec<String>,
) -> ModelFile {
    let mut model = base.clone();
    model.name = "identified".into();
    if let Some(note) = receiver_rate(&mut model, training) {
        notes.push(note);
    }
    notes.extend(mixed_receiver_rates(&model, training));
    if let Some(fit) = fitted.dynamics {
        model.dynamics = Some(fit.section);
    }
    let names: Vec<&str> = training.iter().map(|e| e.name.as_str()).collect();
    model.description = format!(
        "Identified by catmodel identify from {} log(s): {}",
        training.len(),
        names.join(", ")
    );
    model.speed = speed_model(fitted.speed);
    if let Some(tfs) = fitted.dx_dt {
        model.dx_dt = dx_dt_model(tfs);
    }
    if let Some(l) = fitted.lateral.as_ref() {
        notes.extend(understeer_note(l));
    }
    model.lateral = fitted.lateral.map(lateral_section);
    model
}

/// The speed model's section (eq 5 form), its fit not yet scored.
fn speed_model(tf: TransferFunction) -> Model {
    Model {
        equation: "eq 5 form (2nd order, input delay), simulation-error fit".into(),
        output: model_file::SPEED_SIGNALS.output.into(),
        output_unit: model_file::SPEED_SIGNALS.output_unit.into(),
        blocks: vec![Block {
            input: model_file::SPEED_INPUTS[0].into(),
            input_unit: model_file::SPEED_SIGNALS.input_units[0].into(),
            tf,
        }],
        fit: Fit::default(),
    }
}

/// The dx/dt model's section (eq 7 form, one block per input), its fit not yet scored.
fn dx_dt_model(tfs: &[TransferFunction]) -> Model {
    Model {
        equation: "eq 7 form (MISO, proper 2nd-order blocks), simulation-error fit".into(),
        output: model_file::DX_DT_SIGNALS.output.into(),
        output_unit: model_file::DX_DT_SIGNALS.output_unit.into(),
        blocks: tfs
            .iter()
            .zip(model_file::DX_DT_INPUTS)
            .zip(model_file::DX_DT_SIGNALS.input_units)
            .map(|((tf, i), u)| Block {
                input: i.into(),
                input_unit: (*u).into(),
                tf: *tf,
            })
            .collect(),
        fit: Fit::default(),
    }
}

/// Why the lateral model's understeer is the car file's, when it is ([`Understeer`]).
fn understeer_note(l: &LateralFit) -> Option<String> {
    match l.understeer {
        Understeer::Estimated { .. } => None,
        Understeer::SpeedSpan => Some(format!(
            "lateral model: the understeer is the car file's ({} s^2/m^2), not estimated: the steady turns span less than 2 m/s of speed (drive circles at two speeds, or steps-at-speed)",
            l.understeer_s2_per_m2
        )),
        Understeer::Undetermined {
            estimate,
            relative_std_error,
        } => Some(format!(
            "lateral model: the understeer is the car file's ({} s^2/m^2): the drives gave {estimate:.5} with a standard error of {:.0} % (at most {:.0} %): they do not determine it (drive circles at several speeds, or a receiver with a steadier course)",
            l.understeer_s2_per_m2,
            100.0 * relative_std_error,
            100.0 * MAX_UNDERSTEER_RELATIVE_STD_ERROR
        )),
    }
}

/// The lateral model's section, its fit not yet scored.
fn lateral_section(l: LateralFit) -> Lateral {
    Lateral {
        steer_gain: l.steer_gain,
        understeer_s2_per_m2: l.understeer_s2_per_m2,
        model: Model {
            equation: "yaw rate = G(s) v tan(g delta / (1 + K v^2)) / L, G first order".into(),
            output: model_file::LATERAL_SIGNALS.output.into(),
            output_unit: model_file::LATERAL_SIGNALS.output_unit.into(),
            blocks: vec![Block {
                input: model_file::LATERAL_INPUTS[0].into(),
                input_unit: model_file::LATERAL_SIGNALS.input_units[0].into(),
                tf: l.tf,
            }],
            fit: Fit::default(),
        },
    }
}

/// Every model of `model` simulated over each experiment of `set`.
fn simulate_each(model: &ModelFile, set: &[Experiment]) -> Result<Vec<Simulated>> {
    set.iter()
        .map(|e| validate::simulate_all(model, e))
        .collect()
}

/// The note for a lateral model that fits the validation drives' yaw rate worse than the
/// kinematic model with the nominal steering.
fn lateral_below_kinematic(validation: Option<&Scores>) -> Option<String> {
    // A lateral model that does worse than the kinematic model with the nominal steering on
    // the validation drive is worth a word (black-box probe: 80.5 % against 82.1 %, silently).
    let (m, k) = validation.and_then(|v| {
        v.yaw_model
            .and_then(|m| m.fit_percent)
            .zip(v.yaw_kinematic.fit_percent)
    })?;
    (m < k).then(|| {
        format!(
            "lateral model: on the validation drive it fits the yaw rate {m:.1} %, below the \
             kinematic model with the nominal steering ({k:.1} %): its steering gain and lag \
             do not carry over to that drive better than the car file's geometry does"
        )
    })
}

/// Each identified model's scores, training and validation, beside the kinematic model's,
/// into its `fit` section (the dx/dt model's only when it was identified, else the base
/// file's stays).
fn write_fits(
    model: &mut ModelFile,
    training: &Scores,
    validation: Option<&Scores>,
    dx_dt_identified: bool,
) {
    let source = "catmodel identify";
    let note = "fit % over the concatenated logs, each simulated from its inputs alone";
    model.speed.fit = fit_from(
        source,
        &training.vel_model,
        &training.vel_kinematic,
        validation.map(|v| (&v.vel_model, &v.vel_kinematic)),
        note.into(),
    );
    if dx_dt_identified {
        model.dx_dt.fit = fit_from(
            source,
            &training.dx_model,
            &training.dx_kinematic,
            validation.map(|v| (&v.dx_model, &v.dx_kinematic)),
            "x, y are metres from each log's first GNSS fix: the model depends on where the car drives".into(),
        );
    }
    if let (Some(l), Some(tr)) = (model.lateral.as_mut(), training.yaw_model.as_ref()) {
        let val = validation.and_then(|v| v.yaw_model.as_ref().map(|y| (y, &v.yaw_kinematic)));
        l.model.fit = fit_from(
            source,
            tr,
            &training.yaw_kinematic,
            val,
            "yaw rate from the GNSS course; kinematic = nominal steering".into(),
        );
    }
}

/// Plain-text summary for the terminal: delay/settling means, the speed model, the tables.
pub fn summary(id: &Identification) -> String {
    let mut o = String::new();
    let delay = delay::mean_of(id.steps.iter().map(|s| s.delay_s));
    let settle = delay::mean_of(id.steps.iter().map(|s| s.settling_s));
    o.push_str(&format!(
        "speed steps: {} ; mean delay {} s ; mean settling {} s\n",
        id.steps.len(),
        delay.map_or("-".into(), |d| format!("{d:.3}")),
        settle.map_or("-".into(), |d| format!("{d:.2}"))
    ));
    let a = &id.speed.arx;
    o.push_str(&format!(
        "ARX (eq 6): na {} nb {} nk {} ; pure-simulation fit training {} % validation {} %\n",
        a.a.len() - 1,
        a.b[0].len(),
        a.nk[0],
        fmt_opt(id.speed.arx_training.fit_percent),
        fmt_opt(id.speed.arx_validation.and_then(|s| s.fit_percent)),
    ));
    let tf = &id.speed.tf;
    o.push_str(&format!(
        "speed model: e^(-{} s) {:?} / {:?}\n",
        tf.delay_s(),
        tf.numerator(),
        tf.denominator()
    ));
    if let Some(l) = &id.model.lateral {
        o.push_str(&format!(
            "lateral: steer_gain {:.4}, understeer {:.5} s^2/m^2, G(s) = {:?} / {:?}\n",
            l.steer_gain,
            l.understeer_s2_per_m2,
            l.model.blocks[0].tf.numerator(),
            l.model.blocks[0].tf.denominator()
        ));
    }
    o.push('\n');
    o.push_str(&validate::format_tables("training", &id.training_scores));
    if let Some(v) = &id.validation_scores {
        o.push('\n');
        o.push_str(&validate::format_tables("validation", v));
    }
    for n in &id.notes {
        o.push_str(&format!("\nnote: {n}"));
    }
    o.push_str(&format!("\nidentified in {:.2} s\n", id.seconds));
    o
}

fn fmt_opt(v: Option<f64>) -> String {
    v.map_or("-".into(), |x| format!("{x:.2}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `scenario` (seed `seed`) driven by the VW Polo's plant with an RTK receiver (1 cm: a
    /// lag's scatter is the fixes' timing's, not their noise's) at `hz`, its fixes moved
    /// `late_s` late as a recorder that stamps them at their arrival does, preprocessed as
    /// `identify --vehicle vehicles/vw-polo.car.toml` does.
    fn polo_drive(scenario: &str, seed: u64, hz: f64, late_s: f64) -> Experiment {
        use crate::sim::{self, config::VehicleConfig, SimOptions};
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("vehicles");
        let mut plant = VehicleConfig::load(&dir.join("vw-polo.toml")).unwrap();
        crate::closed_loop::Receiver::Rtk.apply(&mut plant.sensors.gnss);
        plant.sensors.gnss.period_s = 1.0 / hz;
        let car = car::apply(&model_file::paper(), &dir.join("vw-polo.car.toml"))
            .unwrap()
            .file;
        let drive = sim::scenario::Scenario::builtin(scenario).unwrap();
        let options = SimOptions {
            seed,
            ..SimOptions::default()
        };
        let rows = sim::simulate(&drive, &plant, &options).log;
        let fixes: Vec<usize> = (0..rows.len()).filter(|&i| rows[i].lat.is_some()).collect();
        let behind = (late_s * hz).round() as usize;
        let mut late = rows.clone();
        for (j, &i) in fixes.iter().enumerate() {
            let earlier = j.checked_sub(behind).map(|e| &rows[fixes[e]]);
            late[i].lat = earlier.and_then(|r| r.lat);
            late[i].lon = earlier.and_then(|r| r.lon);
        }
        let name = format!("{scenario}-{seed} at {hz} Hz, {late_s} s late");
        preprocess::preprocess_rows(&name, &late, &car.vehicle, &Default::default())
            .unwrap_or_else(|e| panic!("{name}: {e:#}"))
    }

    /// Fixes without latency are not named late (or the wheel speed late) at any receiver
    /// rate: a lag is trusted only to half the interval between fixes
    /// ([`units::GNSS_LATENCY_RESOLUTION_PERIODS`]). A black-box probe's 1 Hz receiver read
    /// 0.12 s +- 0.02 late (`turn-left` seed 16 here: "the GNSS fixes are 0.12 s +- 0.02 late
    /// behind the wheel speed"); seed 14 read the wheel speed 0.14-0.16 s late. Fixes 0.3 s
    /// late from a 10 Hz receiver, twice the bound there, are still named.
    #[test]
    fn fixes_on_time_are_not_named_late_at_any_receiver_rate() {
        assert!((units::gnss_latency_named_above_s(1.0) - 0.6).abs() < 1e-12);
        assert!((units::gnss_latency_named_above_s(10.0) - 0.15).abs() < 1e-12);
        for hz in [1.0, 2.0, 5.0, 10.0] {
            for (scenario, seed) in [("turn-left", 16), ("turn-right", 16), ("turn-left", 14)] {
                let e = polo_drive(scenario, seed, hz, 0.0);
                let lag = units::gnss_latency(&e);
                let notes = gnss_latency_notes(std::slice::from_ref(&e), &[]);
                assert!(notes.is_empty(), "{}: {lag:?}: {notes:?}", e.name);
            }
        }
        let e = polo_drive("steps-at-speed", 0, 10.0, 0.3);
        let (lag, se) = units::gnss_latency(&e).expect("timed");
        assert!((lag - 0.3).abs() < 0.03 + 2.0 * se, "{lag} +- {se}");
        let notes = gnss_latency_notes(std::slice::from_ref(&e), &[]);
        assert!(
            notes.len() == 1 && notes[0].contains("the GNSS fixes are 0.3"),
            "{lag} +- {se}: {notes:?}"
        );
    }

    #[test]
    fn tiny_gains_are_not_printed_as_minus_zero_or_fifty_decimals() {
        assert_eq!(dec3(-9.404e-38), "-9.4e-38");
        assert_eq!(dec3(-0.0), "0.000");
        assert_eq!(dec3(0.0), "0.000");
        assert_eq!(dec3(0.98765), "0.988");
        let problem = model_file::steer_gain_problem(35.5, -9.404_e-38).unwrap();
        assert!(
            problem.starts_with("lateral.steer_gain = -9.404e-38: the lock"),
            "{problem}"
        );
    }

    #[test]
    fn the_file_takes_the_logs_receiver_rate_when_it_differs() {
        let base = model_file::paper();
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/smoke.csv");
        let log = preprocess::load_experiment(&path, &base.vehicle, &Default::default()).unwrap();
        // The bundled logs' receiver is the paper's 100 Hz: nothing to change.
        let mut model = base.clone();
        assert_eq!(receiver_rate(&mut model, std::slice::from_ref(&log)), None);
        assert_eq!(model, base);
        // Logs from a 1 Hz receiver (the median wins over one odd log).
        let at = |hz: f64| Experiment {
            gnss_rate_hz: hz,
            ..log.clone()
        };
        let note = receiver_rate(&mut model, &[at(1.02), at(0.98), at(50.0)]).unwrap();
        assert_eq!(model.vehicle.gnss_rate_hz, 1.0);
        // The outage bridged must outlast the 2.5 s timeout at 1 Hz: the file is readable.
        assert_eq!(model.inputs.gnss_lost_s, 5.0);
        assert!(
            note.contains("gnss_rate_hz = 1") && note.contains("gnss_lost_s = 5"),
            "{note}"
        );
        let dir = std::env::temp_dir().join(format!("catmodel-rate-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("m.toml");
        model_file::save(&file, &model).unwrap();
        assert_eq!(model_file::load(&file).unwrap().vehicle.gnss_rate_hz, 1.0);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A truck-like speed loop (0.6 s delay, 1.2 s lag; a black-box probe) was fitted with a
    /// short delay and a right-half-plane zero, training fit 63 %, while the step responses
    /// said a mean delay of 1.811 s, and nothing was noted. Now both are named; the
    /// paper-sized set's model (0.88 s, zeros at -190.8 and -0.24, steps 0.787 s) gets no note.
    #[test]
    fn a_speed_model_with_an_inverse_response_or_an_early_delay_is_noted() {
        let truck = TransferFunction::new(
            &[-0.245_449, 0.347_154, 0.093_322],
            &[1.0, 0.796_234, 0.096_811],
            0.36,
        )
        .unwrap();
        let note = speed_step_mismatch_note(&truck, Some(1.811)).expect("noted");
        assert!(
            note.contains("a zero at s = +1.65 1/s in the right half-plane")
                && note.contains(
                    "a delay of 0.36 s, far below the step responses' mean delay of 1.811 s"
                ),
            "{note}"
        );
        // An early delay alone, the zeros in the left half-plane.
        let early = TransferFunction::new(&[0.774, 0.183], &[1.0, 0.897, 0.1837], 0.16).unwrap();
        let note = speed_step_mismatch_note(&early, Some(1.811)).expect("noted");
        assert!(
            note.contains("far below") && !note.contains("zero at"),
            "{note}"
        );
        let paper = TransferFunction::new(
            &[0.004_048_6, 0.774_025, 0.183_073],
            &[1.0, 0.897_001, 0.183_652],
            0.88,
        )
        .unwrap();
        assert_eq!(speed_step_mismatch_note(&paper, Some(0.787)), None);
        assert_eq!(speed_step_mismatch_note(&paper, None), None);
    }

    /// Training logs from two receivers (a black-box probe: 8 logs at 100 Hz, 3 at 10 Hz) wrote
    /// `gnss_rate_hz = 100` without a note. Now the logs at another rate are named, with what
    /// was written; logs from one receiver (their clocks' spread) get no such note.
    #[test]
    fn logs_from_receivers_at_other_rates_are_named() {
        let base = model_file::paper();
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/smoke.csv");
        let log = preprocess::load_experiment(&path, &base.vehicle, &Default::default()).unwrap();
        let at = |name: &str, hz: f64| Experiment {
            name: name.into(),
            gnss_rate_hz: hz,
            ..log.clone()
        };
        let mut logs: Vec<Experiment> = (0..8).map(|k| at(&format!("a{k}"), 100.0)).collect();
        logs.extend((0..3).map(|k| at(&format!("b{k}"), 10.0)));
        let mut model = base.clone();
        assert_eq!(receiver_rate(&mut model, &logs), None);
        let note = mixed_receiver_rates(&model, &logs).expect("named");
        assert!(
            note.starts_with("3 of the 11 training logs'")
                && note.contains("gnss_rate_hz = 100 written")
                && note.contains("b0 at 10.0 Hz, b1 at 10.0 Hz, b2 at 10.0 Hz"),
            "{note}"
        );
        assert!(!note.contains("a0"), "{note}");
        let one = [at("a", 100.3), at("b", 99.8), at("c", 100.0)];
        assert_eq!(mixed_receiver_rates(&model, &one), None);
    }
}
