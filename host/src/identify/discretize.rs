//! `catmodel discretize`: every single-input block of a model file as discrete state space
//! (ZOH, f64, the core's [`catmodel::model::zoh`]), JSON (README, "CLI"):
//! `{"ts": 0.02, "models": [{"name", "input", "output", "A", "B", "C", "D", "delay_samples"}]}`
//! with matrices as arrays of rows (`A` n x n, `B` n x 1, `C` 1 x n, `D` 1 x 1).
use anyhow::{anyhow, Result};
use catmodel::model::zoh;
use serde::Serialize;

use crate::model_file::{describe_model_error, Model, ModelFile};

/// One discretized block.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DiscreteBlock {
    /// `model.input`, e.g. `speed.input_vel`, `dx_dt.phi`.
    pub name: String,
    /// Input name and unit, e.g. `input_vel [m/s]`.
    pub input: String,
    /// Output name and unit.
    pub output: String,
    /// State matrix, rows.
    #[serde(rename = "A")]
    pub a: Vec<Vec<f64>>,
    /// Input matrix, rows (n x 1).
    #[serde(rename = "B")]
    pub b: Vec<Vec<f64>>,
    /// Output matrix (1 x n).
    #[serde(rename = "C")]
    pub c: Vec<Vec<f64>>,
    /// Feedthrough (1 x 1).
    #[serde(rename = "D")]
    pub d: Vec<Vec<f64>>,
    /// Input delay, samples.
    pub delay_samples: usize,
}

/// The `discretize` document.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Discretized {
    /// Sample time, s.
    pub ts: f64,
    /// Every block of every model, in file order (speed, dx_dt, lateral).
    pub models: Vec<DiscreteBlock>,
}

/// One transfer function, ZOH-discretized at `ts` (any order up to the core's
/// `MAX_ORDER`), named `name`.
pub fn discretize_tf(
    name: String,
    input: String,
    output: String,
    tf: &catmodel::model::tf::TransferFunction,
    ts: f64,
) -> Result<DiscreteBlock> {
    let dss =
        zoh::discretize(tf, ts).map_err(|e| anyhow!("{name}: {}", describe_model_error(&e)))?;
    let n = dss.n;
    Ok(DiscreteBlock {
        name,
        input,
        output,
        a: (0..n).map(|i| dss.ad[i][..n].to_vec()).collect(),
        b: (0..n).map(|i| vec![dss.bd[i]]).collect(),
        c: vec![dss.cd[..n].to_vec()],
        d: vec![vec![dss.dd]],
        delay_samples: dss.delay_samples,
    })
}

fn blocks(key: &str, m: &Model, ts: f64, out: &mut Vec<DiscreteBlock>) -> Result<()> {
    for b in &m.blocks {
        out.push(discretize_tf(
            format!("{key}.{}", b.input),
            format!("{} [{}]", b.input, b.input_unit),
            format!("{} [{}]", m.output, m.output_unit),
            &b.tf,
            ts,
        )?);
    }
    Ok(())
}

/// Discretizes every block of `file` at `ts_s` (default: the file's sample time).
pub fn discretize_file(file: &ModelFile, ts_s: Option<f64>) -> Result<Discretized> {
    let ts = ts_s.unwrap_or(file.sample_time_s);
    let mut models = Vec::new();
    blocks("speed", &file.speed, ts, &mut models)?;
    blocks("dx_dt", &file.dx_dt, ts, &mut models)?;
    if let Some(l) = &file.lateral {
        blocks("lateral", &l.model, ts, &mut models)?;
    }
    Ok(Discretized { ts, models })
}
