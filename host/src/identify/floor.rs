//! The fit floors: `identify` refuses to write a model whose training or validation fit is
//! below [`FIT_FLOOR_PERCENT`], and says which fit failed and the likely cause; `--force`
//! writes it anyway with the warning in the file ([`mark_forced`]).
//!
//! Why a floor: a pure-simulation fit (MATLAB `compare`, [`catmodel::metrics::fit_percent`])
//! of 50 % means the model's error is half the output's own variation about its mean. The
//! published models reach 83 % (eq 5) and the simulator's re-identified ones 82-95 %; a model
//! below 50 % describes the logs worse than that by far, and what went wrong is nearly always
//! in the data: an impossible sample that passed the range checks, a drive without steps or
//! turns, or a validation drive outside what training covered. Writing such a model silently
//! would bake it into a firmware.
use super::preprocess::Experiment;
use super::validate::{Score, Simulated};
use super::Identification;
use crate::model_file::{Fit, ModelFile};

/// Lowest accepted fit %, training and validation, of every model `identify` writes (speed,
/// dx/dt when re-identified, lateral when identified).
pub const FIT_FLOOR_PERCENT: f64 = 50.0;

/// A residual this many times the RMS of the others is "a sample far outside the rest".
const OUTLIER_RATIO: f64 = 8.0;

/// A validation drive whose range exceeds training's by more than this share "leaves the
/// training range".
const RANGE_MARGIN: f64 = 0.1;

/// Which model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Which {
    /// `[speed]` (eq 5 form).
    Speed,
    /// `[dx_dt]` (eq 7 form).
    DxDt,
    /// `[lateral]`.
    Lateral,
}

impl Which {
    fn section(self) -> &'static str {
        match self {
            Which::Speed => "speed",
            Which::DxDt => "dx_dt",
            Which::Lateral => "lateral",
        }
    }
}

/// One fit below the floor.
#[derive(Debug, Clone, PartialEq)]
pub struct FloorViolation {
    /// The model.
    pub model: Which,
    /// `training` or `validation`.
    pub data: &'static str,
    /// The fit %, `None` when undefined (a constant output).
    pub fit_percent: Option<f64>,
    /// The likely cause, in words.
    pub cause: String,
}

impl std::fmt::Display for FloorViolation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.fit_percent {
            Some(p) => write!(
                f,
                "[{}] {} fit {p:.1} % < {FIT_FLOOR_PERCENT} %: {}",
                self.model.section(),
                self.data,
                self.cause
            ),
            None => write!(
                f,
                "[{}] {} fit undefined (the output never varies): {}",
                self.model.section(),
                self.data,
                self.cause
            ),
        }
    }
}

/// A series of every experiment: measured output, simulated output.
type Pick = fn(&Experiment, &Simulated) -> (Vec<f64>, Vec<f64>);

fn pick_speed(e: &Experiment, s: &Simulated) -> (Vec<f64>, Vec<f64>) {
    (e.vel.clone(), s.vel_model.clone())
}

fn pick_dx(e: &Experiment, s: &Simulated) -> (Vec<f64>, Vec<f64>) {
    (e.dx.clone(), s.dx_model.clone())
}

fn pick_yaw(e: &Experiment, s: &Simulated) -> (Vec<f64>, Vec<f64>) {
    (e.yaw_rate.clone(), s.yaw_model.clone().unwrap_or_default())
}

/// Largest `|f|` over a set of experiments.
fn max_abs(set: &[Experiment], f: fn(&Experiment) -> &[f64]) -> f64 {
    set.iter()
        .flat_map(|e| f(e).iter().copied())
        .fold(0.0, |m, v| m.max(v.abs()))
}

/// Span (max - min) over a set of experiments.
fn span(set: &[Experiment], f: fn(&Experiment) -> &[f64]) -> f64 {
    let (lo, hi) = set
        .iter()
        .flat_map(|e| f(e).iter().copied())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
            (l.min(v), h.max(v))
        });
    (hi - lo).max(0.0)
}

/// The sample with the largest residual, if it stands far out of the rest: (experiment, t,
/// measured, simulated).
fn outlier(set: &[Experiment], sims: &[Simulated], pick: Pick) -> Option<(String, f64, f64, f64)> {
    let mut worst: Option<(String, f64, f64, f64, f64)> = None;
    let (mut sum_sq, mut n) = (0.0, 0usize);
    for (e, s) in set.iter().zip(sims) {
        let (y, yh) = pick(e, s);
        for ((t, a), b) in e.t.iter().zip(&y).zip(&yh) {
            let r = (a - b).abs();
            sum_sq += r * r;
            n += 1;
            if worst.as_ref().is_none_or(|w| r > w.4) {
                worst = Some((e.name.clone(), *t, *a, *b, r));
            }
        }
    }
    let (name, t, y, yh, r) = worst?;
    let others = n.checked_sub(1).filter(|&m| m > 0)?;
    let rms_others = ((sum_sq - r * r).max(0.0) / others as f64).sqrt();
    (r > OUTLIER_RATIO * rms_others).then_some((name, t, y, yh))
}

/// Why the training fit is low.
fn training_cause(model: Which, set: &[Experiment], sims: &[Simulated], pick: Pick) -> String {
    if let Some((name, t, y, yh)) = outlier(set, sims, pick) {
        return format!(
            "one sample stands far outside the rest: {name} near t = {t:.2} s (measured {y:.3}, model {yh:.3}); look at the log's lines there for a corrupt value"
        );
    }
    match model {
        Which::Speed => format!(
            "too little excitation or a car the 2nd-order delayed form does not describe: the commanded speed spans {:.2} m/s over the training logs (drive speed steps up and down, as the paper's straight lines)",
            span(set, |e| &e.input_vel)
        ),
        Which::DxDt => format!(
            "too little excitation: the heading spans {:.2} rad and the speed {:.2} m/s over the training logs (drive turns and circles)",
            span(set, |e| &e.heading),
            span(set, |e| &e.vel)
        ),
        Which::Lateral => format!(
            "too little excitation: steering spans {:.1} % over the training logs (drive turns and circles at several speeds)",
            span(set, |e| &e.steer_pct)
        ),
    }
}

/// Why the validation fit is low while training's is not.
fn validation_cause(model: Which, training: &[Experiment], validation: &[Experiment]) -> String {
    let leaves = |what: &str, unit: &str, f: fn(&Experiment) -> &[f64]| {
        let (v, t) = (max_abs(validation, f), max_abs(training, f));
        (v > t * (1.0 + RANGE_MARGIN)).then(|| {
            format!(
                "the validation drive leaves the training range ({what} up to {v:.2} {unit}, trained up to {t:.2} {unit})"
            )
        })
    };
    let found = match model {
        Which::Speed => leaves("speeds", "m/s", |e| &e.vel),
        Which::DxDt => leaves("speeds", "m/s", |e| &e.vel)
            .or_else(|| leaves("east positions", "m", |e| &e.x))
            .or_else(|| leaves("north positions", "m", |e| &e.y)),
        Which::Lateral => leaves("speeds", "m/s", |e| &e.vel)
            .or_else(|| leaves("steering", "%", |e| &e.steer_pct)),
    };
    found.unwrap_or_else(|| match model {
        Which::DxDt => "the validation drive differs from training within its range: eq 7 takes absolute positions x, y, so another place or direction does not carry over (or another car)".into(),
        _ => "the validation drive differs from training within its range (another car, another speed-loop setting, or a validation log with a fault)".into(),
    })
}

fn below(score: &Score) -> bool {
    score.fit_percent.is_none_or(|p| p < FIT_FLOOR_PERCENT)
}

/// Every fit of `id` below the floor, with its likely cause; empty when the model is fine.
pub fn check(id: &Identification) -> Vec<FloorViolation> {
    let tr = &id.training_scores;
    let va = id.validation_scores.as_ref();
    let mut models: Vec<(Which, Score, Option<Score>, Pick)> = vec![(
        Which::Speed,
        tr.vel_model,
        va.map(|v| v.vel_model),
        pick_speed,
    )];
    if id.dx_dt_identified {
        models.push((Which::DxDt, tr.dx_model, va.map(|v| v.dx_model), pick_dx));
    }
    if let Some(yaw) = tr.yaw_model {
        models.push((Which::Lateral, yaw, va.and_then(|v| v.yaw_model), pick_yaw));
    }
    let mut out = Vec::new();
    for (model, train, val, pick) in models {
        if below(&train) {
            out.push(FloorViolation {
                model,
                data: "training",
                fit_percent: train.fit_percent,
                cause: training_cause(model, &id.training, &id.training_sims, pick),
            });
        } else if let Some(val) = val.filter(below) {
            out.push(FloorViolation {
                model,
                data: "validation",
                fit_percent: val.fit_percent,
                cause: validation_cause(model, &id.training, &id.validation),
            });
        }
    }
    out
}

/// Writes the violations into the model file written with `--force`: the description and the
/// fit note of each model concerned start with a warning, so that whoever bakes the file into a
/// firmware reads it.
pub fn mark_forced(model: &mut ModelFile, violations: &[FloorViolation]) {
    if violations.is_empty() {
        return;
    }
    model.description = format!(
        "WARNING: written with --force below the fit floor ({} fit(s) < {FIT_FLOOR_PERCENT} %). {}",
        violations.len(),
        model.description
    );
    for v in violations {
        let fit: &mut Fit = match v.model {
            Which::Speed => &mut model.speed.fit,
            Which::DxDt => &mut model.dx_dt.fit,
            Which::Lateral => match model.lateral.as_mut() {
                Some(l) => &mut l.model.fit,
                None => continue,
            },
        };
        fit.note = format!("WARNING (--force): {v}. {}", fit.note);
    }
}
