//! Host side of catmodel: log files, the plant simulator, replay, evaluation, identification.
//! Links the same `catmodel` core for everything the node does.
pub mod closed_loop;
pub mod csv2can;
pub mod dbc;
pub mod decode;
pub mod evaluate;
pub mod identify;
pub mod logcsv;
pub mod plot;
pub mod progress;
pub mod replay;
pub mod sil;
pub mod sim;

/// The model file reader (crate `catmodel-model-file`): the same one the firmware build uses.
pub use catmodel_model_file as model_file;

/// The node as the host runs it: its drive stage (about 23 KiB) on the heap.
pub type HostNode = catmodel::node::Node<Box<catmodel::node::drive::Drive>>;

/// A node for the car of `config`, with a fresh drive stage on the heap.
pub fn new_node(config: catmodel::node::NodeConfig) -> HostNode {
    catmodel::node::Node::new(config, Box::new(catmodel::node::drive::Drive::new()))
}

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use catmodel::can::codec::{decode_input, InputMessage};
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
    let mut out: Vec<Prediction> = Vec::with_capacity(rows.len());
    for (line, row) in rows {
        if row.len() != header.len() {
            bail!(
                "{}:{line}: {} fields, the header has {}",
                path.display(),
                row.len(),
                header.len()
            );
        }
        let f = |i: usize| cell_f64(path, line, &header, &row, cols[i]);
        let mode = row.get(cols[7]).cloned().unwrap_or_default();
        if mode != "kinematic" && mode != "dynamic" {
            bail!(
                "{}:{line}: column `mode`: {mode:?} is neither `kinematic` nor `dynamic`",
                path.display()
            );
        }
        let p = Prediction {
            t: f(0)?,
            step: f(1)? as u64,
            horizon_s: f(2)?,
            x: f(3)?,
            y: f(4)?,
            heading: f(5)?,
            speed: f(6)?,
            mode,
        };
        if p.horizon_s < 0.0 {
            bail!(
                "{}:{line}: column `horizon_s`: {} is negative",
                path.display(),
                p.horizon_s
            );
        }
        if let Some(prev) = out.last() {
            if p.t < prev.t {
                bail!(
                    "{}:{line}: column `t`: time goes backwards ({} s after {} s)",
                    path.display(),
                    p.t,
                    prev.t
                );
            }
        }
        out.push(p);
    }
    Ok(out)
}

/// What the evaluation needs to know about the car (from its model file): the kinematic
/// baseline's geometry and where the GNSS antenna sits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Car {
    /// Steering geometry (eq 2-4).
    pub vehicle: catmodel::vehicle::VehicleParams,
    /// GNSS antenna ahead of the rear axle, m.
    pub antenna_ahead_m: f64,
    /// NMEA 2000 source address of the GNSS receiver.
    pub gnss_source: u8,
}

impl Car {
    /// The car a model file describes.
    pub fn from_model(file: &model_file::ModelFile) -> Self {
        Self {
            vehicle: file.vehicle.params(),
            antenna_ahead_m: file.vehicle.antenna_ahead_m,
            gnss_source: file.inputs.gnss_source_address,
        }
    }
}

/// The baseline's inputs from a candump of the node's input frames, GNSS in local metres
/// around `origin_deg`. Frames the node would reject are skipped here too.
pub fn baseline_inputs(path: &Path, origin_deg: (f64, f64), car: &Car) -> Result<BaselineInputs> {
    let frames = replay::read_candump_reporting(path, None)?.frames;
    let frame = LocalFrame::new(
        (origin_deg.0 * 1e7).round() as i32,
        (origin_deg.1 * 1e7).round() as i32,
    )
    .map_err(|e| anyhow::anyhow!("origin {origin_deg:?}: {e:?}"))?;
    let mut inputs = BaselineInputs::default();
    for f in frames {
        let t = f.t_us as f64 * 1e-6;
        match decode_input(&f.frame, car.gnss_source) {
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

/// Everything `catmodel evaluate` reads: predictions, truth and the baseline's bus inputs.
pub struct EvaluationData {
    /// The node's predictions.
    pub predictions: Vec<Prediction>,
    /// Ground truth.
    pub truth: Truth,
    /// Raw GNSS, speed and steering from the candump.
    pub inputs: BaselineInputs,
    /// The car.
    pub car: Car,
}

impl EvaluationData {
    /// Reads the three files; `origin_deg` is the origin of the truth frame.
    pub fn read(
        predictions: &Path,
        truth: &Path,
        inputs: &Path,
        origin_deg: (f64, f64),
        car: Car,
    ) -> Result<Self> {
        Ok(Self {
            predictions: read_predictions(predictions)?,
            truth: Truth::new(logcsv::read_truth(truth).map_err(|e| anyhow::anyhow!("{e}"))?),
            inputs: baseline_inputs(inputs, origin_deg, &car)?,
            car,
        })
    }

    /// Scores the predictions and the baseline (the car's geometry for the baseline).
    pub fn evaluate(&self) -> Evaluation {
        evaluate::evaluate(
            &self.predictions,
            &self.truth,
            &self.inputs,
            &self.car.vehicle,
            self.car.antenna_ahead_m,
        )
    }

    /// Writes the figures of [`evaluate::write_plots`] into `dir`.
    pub fn write_plots(&self, dir: &Path, evaluation: &Evaluation) -> Result<Vec<PathBuf>> {
        evaluate::write_plots(
            dir,
            &self.predictions,
            &self.truth,
            &self.inputs,
            &self.car.vehicle,
            self.car.antenna_ahead_m,
            evaluation,
        )
    }
}

/// `catmodel evaluate` on files, for the car of `models/paper.toml`.
pub fn evaluate_files(
    predictions: &Path,
    truth: &Path,
    inputs: &Path,
    origin_deg: (f64, f64),
) -> Result<Evaluation> {
    let car = Car::from_model(&model_file::load(&model_file::paper_path())?);
    Ok(EvaluationData::read(predictions, truth, inputs, origin_deg, car)?.evaluate())
}

/// Why the node did not use the GNSS fixes, when the receiver ran at another rate than the
/// model file declares (`counters.gnss_rate_mismatch` fixes not used; `interval_us`: the
/// interval the node measured between them, off the declared period): the message names the
/// rate to declare.
pub fn gnss_rate_note(
    counters: &catmodel::node::Counters,
    interval_us: Option<u32>,
    declared_hz: f64,
) -> Option<String> {
    if counters.gnss_rate_mismatch == 0 {
        return None;
    }
    let measured = interval_us
        .filter(|us| *us > 0)
        .map_or("another rate".to_string(), |us| {
            let s = f64::from(us) * 1e-6;
            format!("{:.1} Hz (every {:.0} ms)", 1.0 / s, s * 1e3)
        });
    Some(format!(
        "{} GNSS fixes not used: the receiver's fixes came at {measured}, the model file declares \
         gnss_rate_hz = {} (the GNSS lowpass and heading filter are designed for that \
         rate); set [vehicle] gnss_rate_hz to the receiver's rate (`catmodel identify` writes it \
         from the logs)",
        counters.gnss_rate_mismatch,
        (declared_hz * 10.0).round() / 10.0
    ))
}

/// What the node's steering check ([`catmodel::node::steering`]) found, when it used a steering
/// gain other than the model file's (at the end of a run, or for `used_ticks` of it): the
/// gain, its standard deviation, and what to change in the model file.
pub fn steering_note(
    check: &catmodel::node::steering::SteeringCheck,
    used_ticks: Option<u64>,
) -> Option<String> {
    let used = used_ticks.map_or(String::new(), |n| {
        format!(
            " for {:.1} s",
            n as f64 * f64::from(catmodel::SAMPLE_PERIOD_S)
        )
    });
    if !check.mismatch() && used_ticks.unwrap_or(0) == 0 {
        return None;
    }
    let (gain, _) = check.fit();
    let std = check
        .gain_std()
        .map_or(String::new(), |s| format!(" +- {s:.3}"));
    let fit = format!(
        "the car turned {gain:.3}{std} times the yaw rate the model file's steering gives \
         (fitted over the drive's turns against the GNSS course)"
    );
    let advice = "Scale the model file's steering by it ([lateral] steer_gain, or [vehicle] \
                  max_steer_deg in a file without [lateral]), or identify the car's model file \
                  from its drives (`catmodel identify`)";
    Some(if check.mismatch() {
        format!("{fit}: the node used that gain{used} (NODE_STATUS steering_mismatch). {advice}")
    } else {
        format!(
            "the node used a steering gain other than the model file's{used} (NODE_STATUS \
             steering_mismatch) and dropped it again; at the end {fit}"
        )
    })
}

/// The node configuration for a model file (`None`: the published `models/paper.toml`, exactly
/// as the firmware's default): the very configuration the firmware build bakes from that file.
pub fn node_config(model: Option<&Path>) -> Result<catmodel::node::NodeConfig> {
    let path = model.map_or_else(model_file::paper_path, Path::to_path_buf);
    Ok(model_file::load(&path)?.node_config())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(name: &str, text: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("catmodel-host-lib-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    const HEADER: &str = "t,step,horizon_s,x,y,heading,speed,mode\n";

    #[test]
    fn predictions_reader_accepts_replay_output_and_names_bad_lines() {
        let good = write(
            "good.csv",
            &format!("{HEADER}0.02,0,0.00,1.5,2,0.1,3,kinematic\n0.02,0,0.20,2,2,0.1,3,kinematic\n0.04,1,0.00,1.6,2,0.1,3,dynamic\n"),
        );
        let p = read_predictions(&good).unwrap();
        assert_eq!(p.len(), 3);
        assert_eq!((p[1].horizon_s, p[1].x, p[2].step), (0.2, 2.0, 1));
        assert_eq!(p[2].mode, "dynamic");

        let cases = [
            (
                "0.04,0,0.00,1,2,0.1,3,kinematic\n0.02,1,0.00,1,2,0.1,3,kinematic\n",
                ":3: column `t`: time goes backwards",
            ),
            ("0.02,0,0.00,1,2,0.1,3,fast\n", ":2: column `mode`"),
            (
                "0.02,0,-0.20,1,2,0.1,3,kinematic\n",
                ":2: column `horizon_s`: -0.2 is negative",
            ),
            (
                "0.02,0,0.00,x,2,0.1,3,kinematic\n",
                ":2: column `x`: \"x\" is not a number",
            ),
            ("0.02,0,0.00,1,2,0.1,3\n", ":2: 7 fields, the header has 8"),
            (
                "0.02,0,0.00,1,2,inf,3,kinematic\n",
                ":2: column `heading`: \"inf\" is not finite",
            ),
        ];
        for (i, (rows, want)) in cases.iter().enumerate() {
            let path = write(&format!("bad{i}.csv"), &format!("{HEADER}{rows}"));
            let err = format!("{:#}", read_predictions(&path).unwrap_err());
            assert!(err.contains(want), "case {i}: {err}");
            assert!(err.starts_with(&path.display().to_string()), "{err}");
        }
        let no_col = write("nocol.csv", "t,step\n0,0\n");
        let err = format!("{:#}", read_predictions(&no_col).unwrap_err());
        assert!(err.contains(":1: missing column `horizon_s`"), "{err}");
    }
}
