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

use anyhow::{anyhow, Result};
use plotters::prelude::*;

use super::{delay, validate, Identification};

type Series<'a> = (&'a str, Vec<(f64, f64)>, RGBColor);

fn plot(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
    points: &[(f64, f64)],
) -> Result<()> {
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for (_, pts, _) in series {
        for &(x, y) in pts {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
    }
    if !(x0.is_finite() && y0.is_finite()) {
        return Ok(());
    }
    if x1 <= x0 {
        x1 = x0 + 1.0;
    }
    let pad = ((y1 - y0) * 0.05).max(1e-6);
    let (y0, y1) = (y0 - pad, y1 + pad);
    let root = SVGBackend::new(path, (900, 450)).into_drawing_area();
    let e = |e: DrawingAreaErrorKind<std::io::Error>| anyhow!("plot {}: {e:?}", path.display());
    root.fill(&WHITE).map_err(e)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(y_label)
        .draw()
        .map_err(e)?;
    for (name, pts, color) in series {
        let c = *color;
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), c.stroke_width(1)))
            .map_err(e)?
            .label(*name)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
    }
    if !points.is_empty() {
        chart
            .draw_series(points.iter().map(|&p| Circle::new(p, 5, RED.filled())))
            .map_err(e)?;
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(e)?;
    root.present().map_err(e)?;
    Ok(())
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
    std::fs::create_dir_all(dir)?;
    let (sets, sims, label) = if id.validation.is_empty() {
        (&id.training, &id.training_sims, "training")
    } else {
        (&id.validation, &id.validation_sims, "validation")
    };
    if let (Some(e), Some(s)) = (sets.first(), sims.first()) {
        let name = &e.name;
        plot(
            &dir.join("fig4_speed.svg"),
            &format!("Speed, {label} log {name} (Fig 4)"),
            "t [s]",
            "speed [m/s]",
            &[
                ("measured", xy(&e.t, &e.vel), BLACK),
                ("transfer function", xy(&e.t, &s.vel_model), BLUE),
                ("kinematic", xy(&e.t, &s.vel_kinematic), RED),
            ],
            &[],
        )?;
        plot(
            &dir.join("fig5_speed_error.svg"),
            &format!("|speed error|, {name} (Fig 5)"),
            "t [s]",
            "|error| [m/s]",
            &[
                (
                    "transfer function",
                    abs_err(&e.t, &e.vel, &s.vel_model),
                    BLUE,
                ),
                ("kinematic", abs_err(&e.t, &e.vel, &s.vel_kinematic), RED),
            ],
            &[],
        )?;
        plot(
            &dir.join("fig6_dx.svg"),
            &format!("dx/dt, {label} log {name} (Fig 6)"),
            "t [s]",
            "dx/dt [m/s]",
            &[
                ("measured (GNSS)", xy(&e.t, &e.dx), BLACK),
                ("transfer function", xy(&e.t, &s.dx_model), BLUE),
                ("kinematic", xy(&e.t, &s.dx_kinematic), RED),
            ],
            &[],
        )?;
        plot(
            &dir.join("fig7_dx_error.svg"),
            &format!("|dx/dt error|, {name} (Fig 7)"),
            "t [s]",
            "|error| [m/s]",
            &[
                ("transfer function", abs_err(&e.t, &e.dx, &s.dx_model), BLUE),
                ("kinematic", abs_err(&e.t, &e.dx, &s.dx_kinematic), RED),
            ],
            &[],
        )?;
        let resid: Vec<f64> = e.vel.iter().zip(&s.vel_model).map(|(a, b)| a - b).collect();
        let acf = autocorrelation(&resid, 250);
        let lags: Vec<(f64, f64)> = acf
            .iter()
            .enumerate()
            .map(|(k, r)| (k as f64 * e.ts_s, *r))
            .collect();
        plot(
            &dir.join("residual_acf.svg"),
            &format!("Autocorrelation of the speed simulation error, {name}"),
            "lag [s]",
            "r",
            &[("residual ACF", lags, BLUE)],
            &[],
        )?;
    }
    // Fig 2: the first step with both markers, on its experiment.
    if let Some(step) = id
        .steps
        .iter()
        .find(|s| s.delay_s.is_some() && s.settling_s.is_some())
    {
        if let Some(e) = id
            .training
            .iter()
            .chain(&id.validation)
            .find(|e| e.name == step.experiment)
        {
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
            let dots = [
                at(step.t_step_s + step.delay_s.unwrap_or(0.0)),
                at(step.t_step_s + step.settling_s.unwrap_or(0.0)),
            ];
            plot(
                &dir.join("fig2_step.svg"),
                &format!("Delay and settling, {} (Fig 2)", e.name),
                "t [s]",
                "speed [m/s]",
                &[
                    ("commanded", keep(&e.input_vel), RED),
                    ("measured", keep(&e.vel), BLACK),
                ],
                &dots,
            )?;
        }
    }

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
    let _ = writeln!(
        o,
        "## Models\n\n```\n{}```\n",
        super::summary(id)
            .lines()
            .take_while(|l| !l.is_empty())
            .map(|l| format!("{l}\n"))
            .collect::<String>()
    );
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
    let _ = writeln!(o, "## The paper's tables\n");
    o.push_str(&validate::format_tables(
        "### Training",
        &id.training_scores,
    ));
    if let Some(v) = vs {
        o.push('\n');
        o.push_str(&validate::format_tables("### Validation", v));
    }
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
    let _ = writeln!(o, "## Correlation of the 17 candidate regressors\n\n| candidate | r with dx/dt | | candidate | r with speed |\n|---|---|---|---|---|");
    for (a, b) in id.correlation_dx.iter().zip(&id.correlation_vel) {
        let _ = writeln!(o, "| {} | {:.3} | | {} | {:.3} |", a.name, a.r, b.name, b.r);
    }
    let _ = writeln!(o, "\n## Notes\n");
    for n in &id.notes {
        let _ = writeln!(o, "- {n}");
    }
    let _ = writeln!(o, "\n## Figures\n\n![Fig 2](fig2_step.svg)\n![Fig 4](fig4_speed.svg)\n![Fig 5](fig5_speed_error.svg)\n![Fig 6](fig6_dx.svg)\n![Fig 7](fig7_dx_error.svg)\n![residual ACF](residual_acf.svg)");
    let path = dir.join("summary.md");
    std::fs::write(&path, o)?;
    Ok(path)
}
