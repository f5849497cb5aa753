//! Step 3: least-squares ARX estimation, the paper's eq 6 `Theta = (M^T M)^{-1} M^T Y`, with
//! order and delay selection.
//!
//! `y[k] + a_1 y[k-1] + ... + a_na y[k-na] = sum_j (b_j0 u_j[k-nk_j] + ... + b_j(nb-1) u_j[k-nk_j-nb+1]) + e[k]`.
//! The regression uses only samples inside each experiment (no row spans two logs). The
//! solve is column-scaled least squares ([`super::oe::lstsq`], nalgebra).
use anyhow::{bail, Result};

use super::oe::{lstsq, Data};

/// An ARX model.
#[derive(Debug, Clone, PartialEq)]
pub struct Arx {
    /// `[1, a_1, ..., a_na]`.
    pub a: Vec<f64>,
    /// Per input, `[b_0, ..., b_(nb-1)]`.
    pub b: Vec<Vec<f64>>,
    /// Per input delay, samples.
    pub nk: Vec<usize>,
    /// Mean squared equation error (one-step prediction error) on the estimation data.
    pub loss: f64,
    /// Rows used.
    pub rows: usize,
}

fn max_lag(na: usize, nb: &[usize], nk: &[usize]) -> usize {
    nb.iter()
        .zip(nk)
        .map(|(b, k)| b + k)
        .chain(std::iter::once(na))
        .max()
        .unwrap_or(0)
}

/// Least-squares ARX (eq 6) for the given orders and delays.
pub fn estimate(data: &[Data], na: usize, nb: &[usize], nk: &[usize]) -> Result<Arx> {
    let m = nb.len();
    if nk.len() != m {
        bail!("ARX: nb and nk differ in length");
    }
    let lag = max_lag(na, nb, nk);
    let ncols = na + nb.iter().sum::<usize>();
    let mut cols = vec![Vec::new(); ncols];
    let mut y = Vec::new();
    for d in data {
        if d.inputs.len() != m {
            bail!("ARX: {} inputs expected", m);
        }
        let n = d.output.len();
        for k in lag..n {
            let mut c = 0;
            for i in 1..=na {
                cols[c].push(-d.output[k - i]);
                c += 1;
            }
            for (j, u) in d.inputs.iter().enumerate() {
                for i in 0..nb[j] {
                    cols[c].push(u[k - nk[j] - i]);
                    c += 1;
                }
            }
            y.push(d.output[k]);
        }
    }
    if y.len() <= ncols {
        bail!(
            "ARX: {} rows for {} parameters: too little data",
            y.len(),
            ncols
        );
    }
    let theta = lstsq(&cols, &y)?;
    let mut loss = 0.0;
    for (r, yk) in y.iter().enumerate() {
        let pred: f64 = cols.iter().zip(&theta).map(|(c, t)| c[r] * t).sum();
        loss += (yk - pred) * (yk - pred);
    }
    let mut a = vec![1.0];
    a.extend_from_slice(&theta[..na]);
    let mut b = Vec::new();
    let mut at = na;
    for nbj in nb {
        b.push(theta[at..at + nbj].to_vec());
        at += nbj;
    }
    Ok(Arx {
        a,
        b,
        nk: nk.to_vec(),
        loss: loss / y.len() as f64,
        rows: y.len(),
    })
}

impl Arx {
    /// Pure simulation (not one-step prediction): past outputs are the model's own, started
    /// from the measured output for the first `max lag` samples.
    pub fn simulate(&self, inputs: &[&[f64]], y_measured: &[f64]) -> Vec<f64> {
        let na = self.a.len() - 1;
        let nb: Vec<usize> = self.b.iter().map(Vec::len).collect();
        let lag = max_lag(na, &nb, &self.nk);
        let n = y_measured.len();
        let mut ys = Vec::with_capacity(n);
        for k in 0..n {
            if k < lag {
                ys.push(y_measured[k]);
                continue;
            }
            let mut v = 0.0;
            for i in 1..=na {
                v -= self.a[i] * ys[k - i];
            }
            for (j, u) in inputs.iter().enumerate() {
                for (i, bi) in self.b[j].iter().enumerate() {
                    v += bi * u[k - self.nk[j] - i];
                }
            }
            ys.push(v);
        }
        ys
    }

    /// Number of parameters.
    pub fn parameters(&self) -> usize {
        self.a.len() - 1 + self.b.iter().map(Vec::len).sum::<usize>()
    }
}

/// SISO order and delay selection: the delay `nk` in `0..=max_nk` minimising the equation
/// error at `na = nb = 2`, then `na, nb` in `1..=3` by Akaike's criterion
/// `N ln(loss) + 2 p` at that delay.
pub fn select_siso(data: &[Data], max_nk: usize) -> Result<Arx> {
    let mut best: Option<Arx> = None;
    for nk in 0..=max_nk {
        let m = estimate(data, 2, &[2], &[nk])?;
        if best.as_ref().is_none_or(|b| m.loss < b.loss) {
            best = Some(m);
        }
    }
    let Some(at_delay) = best else {
        bail!("ARX: no delay candidate");
    };
    let nk = at_delay.nk[0];
    let mut chosen: Option<(f64, Arx)> = None;
    for na in 1..=3 {
        for nb in 1..=3 {
            let m = estimate(data, na, &[nb], &[nk])?;
            let aic = m.rows as f64 * m.loss.max(1e-300).ln() + 2.0 * m.parameters() as f64;
            if chosen.as_ref().is_none_or(|(b, _)| aic < *b) {
                chosen = Some((aic, m));
            }
        }
    }
    chosen
        .map(|(_, m)| m)
        .ok_or_else(|| anyhow::anyhow!("ARX: no order candidate"))
}
