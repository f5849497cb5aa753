//! `identify --report DIR`: `summary.md` (the paper's tables for the user's data, the step
//! delays and settling times, the correlation ranking, ARX vs output-error vs kinematic) and
//! SVG figures (plotters, SVG backend only):
//! - `fig2_step.svg`: one speed step with the delay (dot 1) and settling (dot 2) markers;
//! - `fig4_speed.svg`, `fig5_speed_error.svg`: measured vs model vs kinematic speed and the
//!   absolute errors, on the first validation log (else the first training log);
//! - `fig6_dx.svg`, `fig7_dx_error.svg`: the same for dx/dt;
//! - `residual_acf.svg`: autocorrelation of the speed model's simulation error.
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

use super::preprocess::Experiment;
use super::validate::Simulated;
use super::{delay, validate, Identification};
use crate::plot::{Figure, Style, PALETTE};

/// Colours of the report's series: measured black, the identified model blue, the kinematic
/// model red, the command orange; Fig 2's markers green (delay) and purple (settling).
const MEASURED_C: (u8, u8, u8) = PALETTE[0];
const MODEL_C: (u8, u8, u8) = PALETTE[1];
const KINEMATIC_C: (u8, u8, u8) = PALETTE[2];
const DELAY_C: (u8, u8, u8) = PALETTE[3];
const COMMAND_C: (u8, u8, u8) = PALETTE[4];
const SETTLING_C: (u8, u8, u8) = PALETTE[5];
/// Time series of 20 ms samples are dense: thin lines.
const TRACE: Style = Style::Line { width_px: 1 };

/// A named series of a report figure: label, points, colour.
type Curve<'a> = (&'a str, Vec<(f64, f64)>, (u8, u8, u8));

/// A report figure: `title` (with its figure number), `subtitle` (which log), line series, and
/// labelled marker series; 900 x 500 with the legend below the data.
fn plot(
    path: &Path,
    title: &str,
    subtitle: &str,
    (x_label, y_label): (&str, &str),
    lines: Vec<Curve<'_>>,
    markers: Vec<Curve<'_>>,
) -> Result<()> {
    let mut figure = Figure::new(title, x_label, y_label)
        .subtitle(subtitle)
        .size(900, 500);
    for (label, points, color) in lines {
        figure = figure.series(label, points, TRACE).color(color);
    }
    for (label, points, color) in markers {
        figure = figure
            .series(label, points, Style::Points { radius_px: 5 })
            .color(color);
    }
    figure.write_svg(path)
}

fn xy(t: &[f64], y: &[f64]) -> Vec<(f64, f64)> {
    t.iter().copied().zip(y.iter().copied()).collect()
}

fn abs_err(t: &[f64], a: &[f64], b: &[f64]) -> Vec<(f64, f64)> {
    t.iter()
        .zip(a.iter().zip(b))
        .map(|(t, (a, b))| (*t, (a - b).abs()))
        .collect()
}

/// Normalised autocorrelation of `e` at lags 0..=max_lag.
pub fn autocorrelation(e: &[f64], max_lag: usize) -> Vec<f64> {
    let n = e.len();
    let m = e.iter().sum::<f64>() / n.max(1) as f64;
    let c0: f64 = e.iter().map(|v| (v - m) * (v - m)).sum();
    (0..=max_lag.min(n.saturating_sub(1)))
        .map(|k| {
            let ck: f64 = (0..n - k).map(|i| (e[i] - m) * (e[i + k] - m)).sum();
            if c0 > 0.0 {
                ck / c0
            } else {
                0.0
            }
        })
        .collect()
}

fn opt(v: Option<f64>, d: usize) -> String {
    v.map_or("-".into(), |x| format!("{x:.d$}"))
}

/// Writes the report into `dir`; returns the summary's path.
pub fn write_report(dir: &Path, id: &Identification) -> Result<PathBuf> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    if let Some((e, s, log)) = figure_log(id) {
        write_signal_figures(dir, e, s, &log)?;
        write_residual_acf(dir, e, s, &log)?;
    }
    if let Some((step, e, which)) = step_to_plot(id) {
        write_step_figure(dir, step, e, which)?;
    }
    let summary = [
        header(id),
        models_section(id),
        speed_table(id),
        paper_tables(id),
        steps_table(id),
        correlation_table(id),
        notes_section(id),
        figures_section(),
    ]
    .concat();
    let path = dir.join("summary.md");
    std::fs::write(&path, summary)?;
    Ok(path)
}

/// The log that Fig 4 to 7 and the residual ACF show, its simulation and the figures'
/// subtitle: the first validation log, else the first training log.
fn figure_log(id: &Identification) -> Option<(&Experiment, &Simulated, String)> {
    let (sets, sims, label) = if id.validation.is_empty() {
        (&id.training, &id.training_sims, "Training")
    } else {
        (&id.validation, &id.validation_sims, "Validation")
    };
    let (e, s) = (sets.first()?, sims.first()?);
    Some((e, s, format!("{label} log: {}", e.name)))
}

/// One signal's two figures: the signal measured and simulated, then the absolute errors.
struct SignalFigures<'a> {
    /// The signal's file and the errors' file.
    files: (&'a str, &'a str),
    /// Their figure numbers.
    numbers: (u32, u32),
    /// What the signal is; its first word names it on the axes.
    quantity: &'a str,
    /// The measured signal's label.
    measured_label: &'a str,
    /// The measured signal, m/s.
    measured: &'a [f64],
    /// The identified model's label.
    model_label: &'a str,
    /// Its simulation, m/s.
    model: &'a [f64],
    /// The kinematic model's simulation, m/s.
    kinematic: &'a [f64],
}

/// Fig 4 / 5 (speed) and Fig 6 / 7 (dx/dt) on log `e` and its simulation `s`.
fn write_signal_figures(dir: &Path, e: &Experiment, s: &Simulated, log: &str) -> Result<()> {
    let speed = SignalFigures {
        files: ("fig4_speed.svg", "fig5_speed_error.svg"),
        numbers: (4, 5),
        quantity: "speed",
        measured_label: "measured",
        measured: &e.vel,
        model_label: "transfer function (eq 5 form)",
        model: &s.vel_model,
        kinematic: &s.vel_kinematic,
    };
    let dx = SignalFigures {
        files: ("fig6_dx.svg", "fig7_dx_error.svg"),
        numbers: (6, 7),
        quantity: "dx/dt (east velocity)",
        measured_label: "measured (GNSS)",
        measured: &e.dx,
        model_label: "transfer function (eq 7 form)",
        model: &s.dx_model,
        kinematic: &s.dx_kinematic,
    };
    for figures in [speed, dx] {
        write_signal_and_error(dir, &e.t, log, figures)?;
    }
    Ok(())
}

/// The signal's figure, then its absolute errors' figure, over the times `t`.
fn write_signal_and_error(dir: &Path, t: &[f64], log: &str, f: SignalFigures) -> Result<()> {
    let short = f.quantity.split(' ').next().unwrap_or(f.quantity);
    plot(
        &dir.join(f.files.0),
        &format!(
            "Fig {}: {}, measured and simulated",
            f.numbers.0, f.quantity
        ),
        log,
        ("t (s)", &format!("{short} (m/s)")),
        vec![
            (f.measured_label, xy(t, f.measured), MEASURED_C),
            (f.model_label, xy(t, f.model), MODEL_C),
            ("kinematic", xy(t, f.kinematic), KINEMATIC_C),
        ],
        Vec::new(),
    )?;
    plot(
        &dir.join(f.files.1),
        &format!("Fig {}: absolute {short} error", f.numbers.1),
        log,
        ("t (s)", "|error| (m/s)"),
        vec![
            (f.model_label, abs_err(t, f.measured, f.model), MODEL_C),
            (
                "kinematic",
                abs_err(t, f.measured, f.kinematic),
                KINEMATIC_C,
            ),
        ],
        Vec::new(),
    )
}

/// The autocorrelation of the speed model's simulation error on log `e`, up to 250 samples.
fn write_residual_acf(dir: &Path, e: &Experiment, s: &Simulated, log: &str) -> Result<()> {
    let resid: Vec<f64> = e.vel.iter().zip(&s.vel_model).map(|(a, b)| a - b).collect();
    let acf = autocorrelation(&resid, 250);
    let lags: Vec<(f64, f64)> = acf
        .iter()
        .enumerate()
        .map(|(k, r)| (k as f64 * e.ts_s, *r))
        .collect();
    plot(
        &dir.join("residual_acf.svg"),
        "Autocorrelation of the speed simulation error",
        log,
        ("lag (s)", "autocorrelation"),
        vec![("speed error, transfer function (eq 5 form)", lags, MODEL_C)],
        Vec::new(),
    )
}

/// Fig 2's step: the first with both markers, its experiment, and whether that is a
/// "Training" or a "Validation" log.
fn step_to_plot(id: &Identification) -> Option<(&delay::StepResponse, &Experiment, &'static str)> {
    let step = id
        .steps
        .iter()
        .find(|s| s.delay_s.is_some() && s.settling_s.is_some())?;
    let in_training = id.training.iter().any(|e| e.name == step.experiment);
    let e = id
        .training
        .iter()
        .chain(&id.validation)
        .find(|e| e.name == step.experiment)?;
    let which = if in_training {
        "Training"
    } else {
        "Validation"
    };
    Some((step, e, which))
}

/// Fig 2: `step` on its experiment `e` (a `which` log), commanded and measured speed, with the
/// delay and settling markers.
fn write_step_figure(
    dir: &Path,
    step: &delay::StepResponse,
    e: &Experiment,
    which: &str,
) -> Result<()> {
    let t0 = step.t_step_s - 2.0;
    let t1 = step.t_step_s + step.settling_s.unwrap_or(10.0) + 5.0;
    let keep = |v: &[f64]| -> Vec<(f64, f64)> {
        e.t.iter()
            .zip(v)
            .filter(|(t, _)| **t >= t0 && **t <= t1)
            .map(|(t, y)| (*t, *y))
            .collect()
    };
    let at = |t: f64| -> (f64, f64) {
        let k = ((t - e.t[0]) / e.ts_s).round().max(0.0) as usize;
        (t, e.vel[k.min(e.len() - 1)])
    };
    plot(
        &dir.join("fig2_step.svg"),
        "Fig 2: delay and settling of a speed step",
        &format!(
            "{which} log: {}, step at t = {:.2} s",
            e.name, step.t_step_s
        ),
        ("t (s)", "speed (m/s)"),
        vec![
            ("commanded", keep(&e.input_vel), COMMAND_C),
            ("measured", keep(&e.vel), MEASURED_C),
        ],
        vec![
            (
                "1: delay (the speed has moved 5 % of the step)",
                vec![at(step.t_step_s + step.delay_s.unwrap_or(0.0))],
                DELAY_C,
            ),
            (
                "2: settled (stays within 5 % of its final value)",
                vec![at(step.t_step_s + step.settling_s.unwrap_or(0.0))],
                SETTLING_C,
            ),
        ],
    )
}

/// The summary's title, its logs and the identification's time.
fn header(id: &Identification) -> String {
    let mut o = String::new();
    let _ = writeln!(o, "# catmodel identify report\n");
    let _ = writeln!(
        o,
        "Training logs: {}",
        id.training
            .iter()
            .map(|e| e.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    );
    let _ = writeln!(
        o,
        "\nValidation logs: {}\n",
        id.validation
            .iter()
            .map(|e| e.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    );
    let _ = writeln!(o, "Identified in {:.2} s. Fit % is MATLAB `compare`'s (pure simulation from the inputs), over the concatenated logs.\n", id.seconds);
    o
}

/// The models as the console summary lists them (its first paragraph).
fn models_section(id: &Identification) -> String {
    format!(
        "## Models\n\n```\n{}```\n\n",
        super::summary(id)
            .lines()
            .take_while(|l| !l.is_empty())
            .map(|l| format!("{l}\n"))
            .collect::<String>()
    )
}

/// The speed's ARX, transfer function and kinematic model side by side, training and
/// validation.
fn speed_table(id: &Identification) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "## Speed: ARX (eq 6) vs transfer function (eq 5 form) vs kinematic (eq 8)\n"
    );
    let _ = writeln!(o, "| model | training fit % | training MSE | validation fit % | validation MSE |\n|---|---|---|---|---|");
    let vs = id.validation_scores.as_ref();
    let _ = writeln!(
        o,
        "| ARX na {} nb {} nk {} | {} | {} | {} | {} |",
        id.speed.arx.a.len() - 1,
        id.speed.arx.b[0].len(),
        id.speed.arx.nk[0],
        opt(id.speed.arx_training.fit_percent, 2),
        opt(id.speed.arx_training.mse, 4),
        opt(id.speed.arx_validation.and_then(|s| s.fit_percent), 2),
        opt(id.speed.arx_validation.and_then(|s| s.mse), 4)
    );
    let t = &id.training_scores;
    let _ = writeln!(
        o,
        "| transfer function | {} | {} | {} | {} |",
        opt(t.vel_model.fit_percent, 2),
        opt(t.vel_model.mse, 4),
        opt(vs.and_then(|v| v.vel_model.fit_percent), 2),
        opt(vs.and_then(|v| v.vel_model.mse), 4)
    );
    let _ = writeln!(
        o,
        "| kinematic | {} | {} | {} | {} |\n",
        opt(t.vel_kinematic.fit_percent, 2),
        opt(t.vel_kinematic.mse, 4),
        opt(vs.and_then(|v| v.vel_kinematic.fit_percent), 2),
        opt(vs.and_then(|v| v.vel_kinematic.mse), 4)
    );
    o
}

/// The paper's tables ([`validate::format_tables`]) for the training logs, then the
/// validation logs.
fn paper_tables(id: &Identification) -> String {
    let mut o = String::new();
    let _ = writeln!(o, "## The paper's tables\n");
    o.push_str(&validate::format_tables(
        "### Training",
        &id.training_scores,
    ));
    if let Some(v) = id.validation_scores.as_ref() {
        o.push('\n');
        o.push_str(&validate::format_tables("### Validation", v));
    }
    o
}

/// Every speed step's delay and settling (Fig 2), and their means beside the paper's.
fn steps_table(id: &Identification) -> String {
    let mut o = String::new();
    let _ = writeln!(o, "\n## Speed steps: delay and settling (Fig 2)\n");
    let _ = writeln!(o, "| log | t [s] | from [m/s] | to [m/s] | delay [s] | settling [s] |\n|---|---|---|---|---|---|");
    for s in &id.steps {
        let _ = writeln!(
            o,
            "| {} | {:.2} | {:.2} | {:.2} | {} | {} |",
            s.experiment,
            s.t_step_s,
            s.from_mps,
            s.to_mps,
            opt(s.delay_s, 3),
            opt(s.settling_s, 2)
        );
    }
    let _ = writeln!(
        o,
        "\nMean delay {} s, mean settling {} s (paper: 0.7387 s, 30.11 s).\n",
        opt(delay::mean_of(id.steps.iter().map(|s| s.delay_s)), 3),
        opt(delay::mean_of(id.steps.iter().map(|s| s.settling_s)), 2)
    );
    o
}

/// The candidate regressors ranked by correlation with dx/dt and with the speed, side by side.
fn correlation_table(id: &Identification) -> String {
    let mut o = String::new();
    let _ = writeln!(o, "## Correlation of the 17 candidate regressors\n\n| candidate | r with dx/dt | | candidate | r with speed |\n|---|---|---|---|---|");
    for (a, b) in id.correlation_dx.iter().zip(&id.correlation_vel) {
        let _ = writeln!(o, "| {} | {:.3} | | {} | {:.3} |", a.name, a.r, b.name, b.r);
    }
    o
}

/// The identification's notes, one item each.
fn notes_section(id: &Identification) -> String {
    let mut o = String::new();
    let _ = writeln!(o, "\n## Notes\n");
    for n in &id.notes {
        let _ = writeln!(o, "- {n}");
    }
    o
}

/// The figures, embedded.
fn figures_section() -> String {
    "\n## Figures\n\n![Fig 2](fig2_step.svg)\n![Fig 4](fig4_speed.svg)\n![Fig 5](fig5_speed_error.svg)\n![Fig 6](fig6_dx.svg)\n![Fig 7](fig7_dx_error.svg)\n![residual ACF](residual_acf.svg)\n".into()
}
