//! Pure simulation of continuous-time models over sampled inputs (f64, offline): ZOH
//! discretization by the core ([`catmodel::model::zoh`]), input delay as a shift by whole
//! samples, initial state at the equilibrium of the first input sample (a log that starts in
//! motion starts the model in steady state, as MATLAB `compare` with estimated initial
//! conditions would approximately do). This is what fit % "as MATLAB `compare`" simulates.
use anyhow::{anyhow, bail, Result};
use catmodel::model::tf::{TransferFunction, MAX_ORDER};
use catmodel::model::zoh::{self, DiscreteStateSpace};

use crate::model_file::describe_model_error;

/// ZOH discretization with a readable error.
pub fn discretize(tf: &TransferFunction, ts_s: f64) -> Result<DiscreteStateSpace> {
    zoh::discretize(tf, ts_s).map_err(|e| anyhow!("{}", describe_model_error(&e)))
}

/// Input `u` delayed by `d` samples, held at `u[0]` before the start.
pub fn delayed(u: &[f64], d: usize) -> impl Iterator<Item = f64> + '_ {
    let u0 = u.first().copied().unwrap_or(0.0);
    (0..u.len()).map(move |k| if k >= d { u[k - d] } else { u0 })
}

/// State trajectory `x[k]` (first `n` entries used) of `x[k+1] = Ad x[k] + Bd u[k - d]`,
/// started at the equilibrium for `u[0]` (zero if there is none, i.e. a pole at z = 1).
pub fn states(dss: &DiscreteStateSpace, u: &[f64]) -> Vec<[f64; MAX_ORDER]> {
    let n = dss.n;
    let u0 = u.first().copied().unwrap_or(0.0);
    let mut x = match dss.equilibrium_per_unit_input() {
        Ok(e) => e.map(|v| v * u0),
        Err(_) => [0.0; MAX_ORDER],
    };
    let mut out = Vec::with_capacity(u.len());
    for uk in delayed(u, dss.delay_samples) {
        out.push(x);
        let mut next = [0.0; MAX_ORDER];
        for ((slot, row), b) in next.iter_mut().zip(&dss.ad).zip(&dss.bd).take(n) {
            *slot = b * uk
                + row
                    .iter()
                    .zip(&x)
                    .take(n)
                    .map(|(a, xj)| a * xj)
                    .sum::<f64>();
        }
        x = next;
    }
    out
}

/// Output of one model over input `u` (same length).
pub fn simulate(tf: &TransferFunction, ts_s: f64, u: &[f64]) -> Result<Vec<f64>> {
    let dss = discretize(tf, ts_s)?;
    let xs = states(&dss, u);
    Ok(xs
        .iter()
        .zip(delayed(u, dss.delay_samples))
        .map(|(x, uk)| {
            dss.dd * uk
                + dss
                    .cd
                    .iter()
                    .zip(x)
                    .take(dss.n)
                    .map(|(c, xi)| c * xi)
                    .sum::<f64>()
        })
        .collect())
}

/// Output of a MISO model: the sum of each block's output over its input.
pub fn simulate_miso(tfs: &[TransferFunction], ts_s: f64, inputs: &[&[f64]]) -> Result<Vec<f64>> {
    if tfs.len() != inputs.len() {
        bail!("{} blocks but {} inputs", tfs.len(), inputs.len());
    }
    let n = inputs.first().map_or(0, |u| u.len());
    let mut y = vec![0.0; n];
    for (tf, u) in tfs.iter().zip(inputs) {
        if u.len() != n {
            bail!("inputs of different lengths");
        }
        for (a, b) in y.iter_mut().zip(simulate(tf, ts_s, u)?) {
            *a += b;
        }
    }
    Ok(y)
}
