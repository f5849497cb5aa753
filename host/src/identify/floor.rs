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
use super::validate::Score;
use super::Identification;
use crate::model_file::{Fit, ModelFile};

/// Lowest accepted fit %, training and validation, of every model `identify` writes (speed,
/// dx/dt when re-identified, lateral when identified).
pub const FIT_FLOOR_PERCENT: f64 = 50.0;

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
    /// The sample that looks corrupt, when that is the likely cause.
    pub suspect: Option<Suspect>,
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

/// A measured sample that stands far outside the rest of its signal: where a corrupt value
/// that passed the range checks sits.
#[derive(Debug, Clone, PartialEq)]
pub struct Suspect {
    /// The experiment (the log's file stem).
    pub log: String,
    /// The log column it comes from (`vel`, `input_vel`, `steer`), or the derived signal
    /// (`dx/dt from lat/lon`, `yaw rate from lat/lon`).
    pub column: &'static str,
    /// Time on the 20 ms grid, s.
    pub t: f64,
    /// The (filtered) value there.
    pub value: f64,
}

/// A sample counts as far outside when its distance from the signal's median exceeds this
/// many times the distance that 90 % of the samples stay within (step tests, standstills and
/// turns keep the ratio under about 2).
const OUTLIER_SPREAD_RATIO: f64 = 4.0;

/// A signal of an experiment.
type Signal = fn(&Experiment) -> &[f64];

/// The sample of a signal farthest from its median over `set`, if it stands out.
fn outlier(set: &[Experiment], column: &'static str, f: Signal) -> Option<Suspect> {
    let mut all: Vec<f64> = set.iter().flat_map(|e| f(e).iter().copied()).collect();
    let median = super::stats::median(&mut all);
    if !median.is_finite() {
        return None;
    }
    let mut dev: Vec<f64> = all.iter().map(|v| (v - median).abs()).collect();
    dev.sort_by(f64::total_cmp);
    let p90 = *dev.get(dev.len() * 9 / 10)?;
    let mut worst: Option<(f64, Suspect)> = None;
    for e in set {
        for (t, v) in e.t.iter().zip(f(e)) {
            let d = (v - median).abs();
            if worst.as_ref().is_none_or(|w| d > w.0) {
                let s = Suspect {
                    log: e.name.clone(),
                    column,
                    t: *t,
                    value: *v,
                };
                worst = Some((d, s));
            }
        }
    }
    let (d, s) = worst?;
    (d > OUTLIER_SPREAD_RATIO * p90 && d > least_outlier(column)).then_some(s)
}

/// The least distance from the median a corrupt sample of `column` stands out by, in its
/// unit: a sensor's noise and a driver's small correction stay within it. A signal that hardly
/// moves (a steady turn at -25 % held for 12 s: 90 % of the steering within 0.1 % of its median)
/// made a normal sample 0.4 % off "a corrupt value" (black-box probe).
fn least_outlier(column: &str) -> f64 {
    match column {
        "steer" => 5.0,
        "vel" | "input_vel" | "dx/dt from lat/lon" => 1.0,
        "yaw rate from lat/lon" => 0.05,
        _ => 0.0,
    }
}

/// The measured signals a model is fitted on, named by the column they come from.
fn signals(model: Which) -> [(&'static str, Signal); 2] {
    match model {
        Which::Speed => [("vel", |e| &e.vel), ("input_vel", |e| &e.input_vel)],
        Which::DxDt => [("vel", |e| &e.vel), ("dx/dt from lat/lon", |e| &e.dx)],
        Which::Lateral => [
            ("steer", |e| &e.steer_pct),
            ("yaw rate from lat/lon", |e| &e.yaw_rate),
        ],
    }
}

/// Steering that spans this much, %, is excitation enough for the lateral model (the paper's
/// turns and circles span 100 % and more; a drive along straight roads a few per cent).
const LATERAL_EXCITATION_PCT: f64 = 20.0;

/// A kinematic yaw rate that fits the logs within this many points of the lateral model, or
/// better, puts the fault in the measured yaw rate: the kinematic model (nominal steering) has
/// nothing fitted.
const KINEMATIC_AS_GOOD_POINTS: f64 = 3.0;

/// Why the lateral model's training fit is low when the fault is the course's: the kinematic
/// model, nothing fitted, fits the yaw rate from the GNSS course as poorly (`kinematic_fit`
/// against `model_fit`, %) while the steering spans enough to fit it (black-box probe: a
/// 5 Hz receiver's 0.5 m at a crawl and 2 s multipath bursts were blamed on a corrupt sample
/// that was not there, or on "too little excitation" with the steering spanning 160 %).
fn course_cause(set: &[Experiment], model_fit: f64, kinematic_fit: f64) -> Option<String> {
    let steering = span(set, |e| &e.steer_pct);
    if steering < LATERAL_EXCITATION_PCT || kinematic_fit < model_fit - KINEMATIC_AS_GOOD_POINTS {
        return None;
    }
    let worst = outlier(set, "yaw rate from lat/lon", |e| &e.yaw_rate)
        .map(|s| {
            format!(
                "; it departs most in {} near t = {:.2} s ({:.3} rad/s after filtering)",
                s.log, s.t, s.value
            )
        })
        .unwrap_or_default();
    Some(format!(
        "the yaw rate from the GNSS course is what fits poorly, not the model: the kinematic \
         model, with nothing fitted, scores {kinematic_fit:.1} % on it too, and the steering \
         spans {steering:.1} %{worst}. Most likely a receiver too noisy or too slow for the \
         course at the logs' speeds (fixes closer than their noise at a crawl), multipath or \
         fixes that jump in bursts: a receiver with a steadier course, or drives at speed"
    ))
}

/// Why the training fit is low, and the suspect sample if there is one. `fits`: the model's
/// and the kinematic model's training fit, % (the lateral model's only).
fn training_cause(
    model: Which,
    set: &[Experiment],
    fits: Option<(f64, f64)>,
) -> (String, Option<Suspect>) {
    // A corrupt steering sample spoils the kinematic model's fit as well: it comes first.
    let columns = signals(model);
    if let Some(s) = columns
        .iter()
        .take(usize::from(model == Which::Lateral))
        .find_map(|(column, f)| outlier(set, column, *f))
    {
        return (suspect_cause(&s), Some(s));
    }
    if let Some(cause) = fits.and_then(|(m, k)| course_cause(set, m, k)) {
        return (cause, None);
    }
    if let Some(s) = columns
        .into_iter()
        .find_map(|(column, f)| outlier(set, column, f))
    {
        return (suspect_cause(&s), Some(s));
    }
    let cause =     match model {
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
    };
    (cause, None)
}

/// A suspect sample, in words.
fn suspect_cause(s: &Suspect) -> String {
    format!(
        "one sample stands far outside the rest: `{}` in {} near t = {:.2} s ({:.3} after filtering); a corrupt value there?",
        s.column, s.log, s.t, s.value
    )
}

/// A validation set whose speed stays within this, m/s, does not move: a parked car, whose
/// speed, track and turns are constant (noise at most), gives nothing to score a model on.
const PARKED_MPS: f64 = 0.2;

/// Why the validation fit is low while training's is not.
fn validation_cause(model: Which, training: &[Experiment], validation: &[Experiment]) -> String {
    let top = max_abs(validation, |e| &e.vel);
    if top < PARKED_MPS {
        let what = match model {
            Which::Speed => "speed",
            Which::DxDt => "motion",
            Which::Lateral => "turn",
        };
        return format!(
            "the validation log does not move (its speed stays within {top:.2} m/s, a parked \
             car): there is no {what} to score the model on, which says nothing of the model; \
             validate with a drive (speed steps, turns)"
        );
    }
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
    let mut models: Vec<(Which, Score, Option<Score>, Option<Score>)> =
        vec![(Which::Speed, tr.vel_model, va.map(|v| v.vel_model), None)];
    if id.dx_dt_identified {
        models.push((Which::DxDt, tr.dx_model, va.map(|v| v.dx_model), None));
    }
    if let Some(yaw) = tr.yaw_model {
        models.push((
            Which::Lateral,
            yaw,
            va.and_then(|v| v.yaw_model),
            Some(tr.yaw_kinematic),
        ));
    }
    let mut out = Vec::new();
    for (model, train, val, kinematic) in models {
        if below(&train) {
            let fits = train.fit_percent.zip(kinematic.and_then(|k| k.fit_percent));
            let (cause, suspect) = training_cause(model, &id.training, fits);
            out.push(FloorViolation {
                model,
                data: "training",
                fit_percent: train.fit_percent,
                cause,
                suspect,
            });
        } else if let Some(val) = val.filter(below) {
            out.push(FloorViolation {
                model,
                data: "validation",
                fit_percent: val.fit_percent,
                cause: validation_cause(model, &id.training, &id.validation),
                suspect: None,
            });
        }
    }
    out
}

/// The log line behind a suspect: the row within 1 s of `suspect.t` whose raw cell is
/// farthest from that column's median over the log, with its value. `None` for the signals
/// derived from GNSS, or when the log has no such cell.
pub fn locate(suspect: &Suspect, log: &crate::logcsv::Log) -> Option<(usize, f64)> {
    let get: fn(&crate::logcsv::LogRow) -> Option<f64> = match suspect.column {
        "vel" => |r| r.vel,
        "input_vel" => |r| r.input_vel,
        "steer" => |r| r.steer,
        _ => return None,
    };
    let mut values: Vec<f64> = log.rows.iter().filter_map(get).collect();
    let median = super::stats::median(&mut values);
    if !median.is_finite() {
        return None;
    }
    log.rows
        .iter()
        .zip(&log.lines)
        .filter(|(r, _)| (r.t - suspect.t).abs() <= 1.0)
        .filter_map(|(r, line)| get(r).map(|v| (*line, v)))
        // The first of equals: where a run of corrupt values starts.
        .fold(None, |best: Option<(usize, f64)>, c| match best {
            Some(b) if (c.1 - median).abs() <= (b.1 - median).abs() => Some(b),
            _ => Some(c),
        })
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
        fit.note = format!("WARNING (--force): {v} -- {}", fit.note);
    }
}
