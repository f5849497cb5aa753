//! Host side of catmodel: log files, the plant simulator, replay, evaluation, identification.
//! Links the same `catmodel` core for everything the node does.
pub mod csv2can;
pub mod evaluate;
pub mod identify;
pub mod logcsv;
pub mod model_file;
pub mod replay;
pub mod sim;

use std::path::Path;

use anyhow::{bail, Context, Result};
use catmodel::can::codec::{decode_input, InputMessage};
use catmodel::can::spec::N2K_DEFAULT_SOURCE;
use catmodel::geodesy::LocalFrame;
use evaluate::{BaselineInputs, Evaluation, Prediction, Truth};

/// The simulator's test site and the default origin of its truth files: the University of
/// Arizona area in Tucson, where the CAT Vehicle drove, degrees.
pub const SIM_ORIGIN_DEG: (f64, f64) = (32.2319, -110.9501);

/// Rows of a CSV file with their line numbers.
type Rows = Vec<(usize, Vec<String>)>;

/// Splits a CSV file into its header and its non-empty rows.
fn csv_table(path: &Path) -> Result<(Vec<String>, Rows)> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut lines = text.lines().enumerate();
    let Some((_, header)) = lines.next() else {
        bail!("{}:1: empty file, a header row is required", path.display());
    };
    let header: Vec<String> = header.split(',').map(|s| s.trim().to_string()).collect();
    let rows = lines
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| (i + 1, l.split(',').map(|s| s.trim().to_string()).collect()))
        .collect();
    Ok((header, rows))
}

fn column(path: &Path, header: &[String], name: &str) -> Result<usize> {
    header
        .iter()
        .position(|h| h == name)
        .with_context(|| format!("{}:1: missing column `{name}`", path.display()))
}

fn cell_f64(
    path: &Path,
    line: usize,
    header: &[String],
    row: &[String],
    col: usize,
) -> Result<f64> {
    let name = header.get(col).map_or("?", String::as_str);
    let cell = row
        .get(col)
        .with_context(|| format!("{}:{line}: column `{name}`: missing cell", path.display()))?;
    let v: f64 = cell.parse().with_context(|| {
        format!(
            "{}:{line}: column `{name}`: {cell:?} is not a number",
            path.display()
        )
    })?;
    if !v.is_finite() {
        bail!(
            "{}:{line}: column `{name}`: {cell:?} is not finite",
            path.display()
        );
    }
    Ok(v)
}

/// Reads a predictions CSV (`t,step,horizon_s,x,y,heading,speed,mode`).
pub fn read_predictions(path: &Path) -> Result<Vec<Prediction>> {
    let (header, rows) = csv_table(path)?;
    let cols: Vec<usize> = [
        "t",
        "step",
        "horizon_s",
        "x",
        "y",
        "heading",
        "speed",
        "mode",
    ]
    .iter()
    .map(|n| column(path, &header, n))
    .collect::<Result<_>>()?;
    let mut out = Vec::with_capacity(rows.len());
    for (line, row) in rows {
        let f = |i: usize| cell_f64(path, line, &header, &row, cols[i]);
        out.push(Prediction {
            t: f(0)?,
            step: f(1)? as u64,
            horizon_s: f(2)?,
            x: f(3)?,
            y: f(4)?,
            heading: f(5)?,
            speed: f(6)?,
            mode: row.get(cols[7]).cloned().unwrap_or_default(),
        });
    }
    Ok(out)
}

/// The baseline's inputs from a candump of the node's input frames, GNSS in local metres
/// around `origin_deg`. Frames the node would reject are skipped here too.
pub fn baseline_inputs(path: &Path, origin_deg: (f64, f64)) -> Result<BaselineInputs> {
    let frames = replay::read_candump(path)?;
    let frame = LocalFrame::new(
        (origin_deg.0 * 1e7).round() as i32,
        (origin_deg.1 * 1e7).round() as i32,
    )
    .map_err(|e| anyhow::anyhow!("origin {origin_deg:?}: {e:?}"))?;
    let mut inputs = BaselineInputs::default();
    for f in frames {
        let t = f.t_us as f64 * 1e-6;
        match decode_input(&f.frame, N2K_DEFAULT_SOURCE) {
            Ok(InputMessage::Steering(m, _)) => {
                if let Some(p) = m.steer_pct {
                    inputs.steer.push((t, f64::from(p)));
                }
            }
            Ok(InputMessage::Speed(m, _)) => {
                if let Some(v) = m.speed_mps {
                    inputs.speed.push((t, f64::from(v)));
                }
            }
            Ok(InputMessage::GnssPosition(p)) => {
                if let Ok(enu) = frame.to_local(p.lat_e7, p.lon_e7) {
                    inputs
                        .gnss
                        .push((t, f64::from(enu.east_m), f64::from(enu.north_m)));
                }
            }
            _ => {}
        }
    }
    Ok(inputs)
}

/// `catmodel evaluate` on files.
pub fn evaluate_files(
    predictions: &Path,
    truth: &Path,
    inputs: &Path,
    origin_deg: (f64, f64),
) -> Result<Evaluation> {
    let preds = read_predictions(predictions)?;
    let truth = Truth::new(logcsv::read_truth(truth).map_err(|e| anyhow::anyhow!("{e}"))?);
    let inputs = baseline_inputs(inputs, origin_deg)?;
    Ok(evaluate::evaluate(
        &preds,
        &truth,
        &inputs,
        &catmodel::vehicle::CAT_VEHICLE,
    ))
}
