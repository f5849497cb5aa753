//! Step 5: validation, as MATLAB `compare` (pure simulation from the inputs only) and MSE,
//! each model beside the kinematic model (eq 8), the paper's two tables (II-E).
//!
//! Kinematic baseline, as the paper: eq 8 driven by the commanded speed and the measured
//! steering angle; its speed is the commanded speed, its dx/dt is `v sin(theta)` with `theta`
//! integrated from the measured course at the start (`theta' = v tan(delta_eff) / L`, eq 2).
use anyhow::Result;
use catmodel::metrics;
use serde::Serialize;

use super::preprocess::Experiment;
use super::simulate::{simulate, simulate_miso};
use crate::model_file::{Lateral, ModelFile, VehicleSection};

/// Fit % and MSE of one simulated signal (None where undefined, e.g. a constant output).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Default)]
pub struct Score {
    /// Fit %, MATLAB `compare`.
    pub fit_percent: Option<f64>,
    /// Mean square error, output unit squared.
    pub mse: Option<f64>,
}

/// Scores `yhat` against `y`.
pub fn score(y: &[f64], yhat: &[f64]) -> Score {
    Score {
        // Finite figures only (a sum of squares can overflow): the model file's reader refuses
        // a non-finite fit, and an undefined one is written as none.
        fit_percent: metrics::fit_percent(y, yhat).ok().filter(|f| f.is_finite()),
        mse: metrics::mse(y, yhat).ok().filter(|m| m.is_finite()),
    }
}

/// Every simulated series of one experiment.
#[derive(Debug, Clone, PartialEq)]
pub struct Simulated {
    /// Speed, identified model, m/s.
    pub vel_model: Vec<f64>,
    /// Speed, kinematic model (= commanded speed), m/s.
    pub vel_kinematic: Vec<f64>,
    /// dx/dt, identified MISO model, m/s.
    pub dx_model: Vec<f64>,
    /// dx/dt, kinematic model, m/s.
    pub dx_kinematic: Vec<f64>,
    /// Yaw rate, lateral model (if the file has one), rad/s.
    pub yaw_model: Option<Vec<f64>>,
    /// Yaw rate, kinematic with the nominal steering, rad/s.
    pub yaw_kinematic: Vec<f64>,
}

/// Scores of one experiment (or of a set, concatenated).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Default)]
pub struct Scores {
    /// Speed, identified model.
    pub vel_model: Score,
    /// Speed, kinematic.
    pub vel_kinematic: Score,
    /// dx/dt, identified model.
    pub dx_model: Score,
    /// dx/dt, kinematic.
    pub dx_kinematic: Score,
    /// Yaw rate, lateral model.
    pub yaw_model: Option<Score>,
    /// Yaw rate, kinematic (nominal steering).
    pub yaw_kinematic: Score,
}

/// Kinematic yaw rate `v tan(gain delta / (1 + K v^2)) / L`, rad/s, positive clockwise.
pub fn kinematic_yaw(
    v: &VehicleSection,
    gain: f64,
    k: f64,
    speed: &[f64],
    delta: &[f64],
) -> Vec<f64> {
    speed
        .iter()
        .zip(delta)
        .map(|(s, d)| s * (gain * d / (1.0 + k * s * s)).tan() / v.wheelbase_m)
        .collect()
}

/// dx/dt of the kinematic model (eq 8) with the commanded speed (see the module doc).
/// Integrated from the first sample the track covers ([`Experiment::track_from`]); 0 before.
pub fn kinematic_dx(e: &Experiment, v: &VehicleSection) -> Vec<f64> {
    let yaw = kinematic_yaw(v, 1.0, v.understeer_s2_per_m2, &e.input_vel, &e.delta_rad);
    let k0 = e.track_from;
    let mut theta = e.heading.get(k0).copied().unwrap_or(0.0);
    let mut out = vec![0.0; k0.min(e.input_vel.len())];
    for (s, r) in e.input_vel.iter().zip(&yaw).skip(k0) {
        out.push(s * theta.sin());
        theta += r * e.ts_s;
    }
    out
}

/// Simulates every model of `file` over `e`.
pub fn simulate_all(file: &ModelFile, e: &Experiment) -> Result<Simulated> {
    let ts = e.ts_s;
    let vel_model = simulate(&file.speed.blocks[0].tf, ts, &e.input_vel)?;
    // From the first sample the track covers: before it the fixes are held (a receiver that
    // started late), and the model's state would start from inputs the car never had.
    let k0 = e.track_from;
    let from = |v: &[f64]| v.get(k0..).unwrap_or_default().to_vec();
    let mut dx_model = vec![0.0; k0.min(e.len())];
    dx_model.extend(simulate_miso(
        &file.dx_dt.tfs(),
        ts,
        &[&from(&e.vel), &from(&e.x), &from(&e.y), &from(&e.delta_rad)],
    )?);
    let yaw_model = match &file.lateral {
        Some(l) => Some(lateral_yaw(l, &file.vehicle, e)?),
        None => None,
    };
    Ok(Simulated {
        vel_model,
        vel_kinematic: e.input_vel.clone(),
        dx_model,
        dx_kinematic: kinematic_dx(e, &file.vehicle),
        yaw_model,
        yaw_kinematic: e.as_measured_yaw(&kinematic_yaw(
            &file.vehicle,
            1.0,
            file.vehicle.understeer_s2_per_m2,
            &e.vel,
            &e.delta_rad,
        )),
    })
}

/// The lateral model's yaw rate over `e` (measured speed, measured steering), as `e.yaw_rate`
/// measures it ([`Experiment::as_measured_yaw`]).
pub fn lateral_yaw(l: &Lateral, v: &VehicleSection, e: &Experiment) -> Result<Vec<f64>> {
    let r_kin = kinematic_yaw(
        v,
        l.steer_gain,
        l.understeer_s2_per_m2,
        &e.vel,
        &e.delta_rad,
    );
    simulate(&l.model.blocks[0].tf, e.ts_s, &e.as_measured_yaw(&r_kin))
}

/// Scores of the simulated series over several experiments, concatenated.
pub fn scores(experiments: &[Experiment], sims: &[Simulated]) -> Scores {
    type Pick<'a> = &'a dyn Fn(&Experiment, &Simulated) -> (Vec<f64>, Vec<f64>);
    let cat = |f: Pick| {
        let mut y = Vec::new();
        let mut yh = Vec::new();
        for (e, s) in experiments.iter().zip(sims) {
            let (a, b) = f(e, s);
            y.extend(a);
            yh.extend(b);
        }
        score(&y, &yh)
    };
    let have_yaw = sims.iter().all(|s| s.yaw_model.is_some());
    // The GNSS-derived outputs are scored where the track was measured, not interpolated
    // across an outage ([`Experiment::gnss_gap`]).
    let fixed = |e: &Experiment, measured: &[f64], model: &[f64]| -> (Vec<f64>, Vec<f64>) {
        (0..measured.len().min(model.len()))
            .filter(|&k| !e.in_gnss_gap(k))
            .map(|k| (measured[k], model[k]))
            .unzip()
    };
    // The speed is scored where the command drove the car ([`Experiment::speed_skip`]).
    let driven = |e: &Experiment, model: &[f64]| -> (Vec<f64>, Vec<f64>) {
        (0..e.vel.len().min(model.len()))
            .filter(|&k| !e.speed_skip.get(k).copied().unwrap_or(false))
            .map(|k| (e.vel[k], model[k]))
            .unzip()
    };
    Scores {
        vel_model: cat(&|e, s| driven(e, &s.vel_model)),
        vel_kinematic: cat(&|e, s| driven(e, &s.vel_kinematic)),
        dx_model: cat(&|e, s| fixed(e, &e.dx, &s.dx_model)),
        dx_kinematic: cat(&|e, s| fixed(e, &e.dx, &s.dx_kinematic)),
        yaw_model: have_yaw.then(|| {
            cat(&|e, s| fixed(e, &e.yaw_rate, s.yaw_model.as_deref().unwrap_or_default()))
        }),
        yaw_kinematic: cat(&|e, s| fixed(e, &e.yaw_rate, &s.yaw_kinematic)),
    }
}

fn cell(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "-".into(), |x| format!("{x:.digits$}"))
}

/// The paper's tables (fit % and MSE, model beside kinematic) as Markdown.
pub fn format_tables(title: &str, s: &Scores) -> String {
    let mut o = format!("{title}\n\n| output | model | fit % | MSE |\n|---|---|---|---|\n");
    let mut row = |out: &str, model: &str, sc: &Score| {
        o.push_str(&format!(
            "| {out} | {model} | {} | {} |\n",
            cell(sc.fit_percent, 2),
            cell(sc.mse, 4)
        ));
    };
    row("speed [m/s]", "transfer function (eq 5 form)", &s.vel_model);
    row("speed [m/s]", "kinematic (eq 8)", &s.vel_kinematic);
    row("dx/dt [m/s]", "transfer function (eq 7 form)", &s.dx_model);
    row("dx/dt [m/s]", "kinematic (eq 8)", &s.dx_kinematic);
    if let Some(y) = &s.yaw_model {
        row("yaw rate [rad/s]", "lateral model", y);
    }
    row(
        "yaw rate [rad/s]",
        "kinematic (nominal steering)",
        &s.yaw_kinematic,
    );
    o
}

/// `compare --out` CSV: `t,vel,vel_model,vel_kinematic,dx,dx_model,dx_kinematic`.
pub fn compare_csv(e: &Experiment, s: &Simulated) -> String {
    let mut o = String::from("t,vel,vel_model,vel_kinematic,dx,dx_model,dx_kinematic\n");
    for k in 0..e.len() {
        o.push_str(&format!(
            "{:?},{:?},{:?},{:?},{:?},{:?},{:?}\n",
            e.t[k],
            e.vel[k],
            s.vel_model[k],
            s.vel_kinematic[k],
            e.dx[k],
            s.dx_model[k],
            s.dx_kinematic[k]
        ));
    }
    o
}
