//! Host side of catmodel: log files, the plant simulator, replay, evaluation, identification.
//! Links the same `catmodel` core for everything the node does.
pub mod closed_loop;
pub mod csv2can;
pub mod dbc;
pub mod decode;
pub mod evaluate;
pub mod identify;
pub mod logcsv;
pub mod outputs;
pub mod planner_refusals;
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
use catmodel::can::codec::{
    decode_input, decode_planner, InputMessage, LocalOrigin, PlannerMessage,
};
use catmodel::geodesy::LocalFrame;
use evaluate::{BaselineInputs, Evaluation, Prediction, Truth};

/// The simulator's test site and the default origin of its truth files: the University of
/// Arizona area in Tucson, where the CAT Vehicle drove, degrees.
pub const SIM_ORIGIN_DEG: (f64, f64) = (32.2319, -110.9501);

/// [`SIM_ORIGIN_DEG`] in the node's units (`NodeConfig::origin_e7`, degrees x 1e7).
pub fn sim_origin_e7() -> (i32, i32) {
    (
        (SIM_ORIGIN_DEG.0 * 1e7).round() as i32,
        (SIM_ORIGIN_DEG.1 * 1e7).round() as i32,
    )
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

/// The largest heading a predictions or truth file may hold, rad (either way round, radians).
const MAX_HEADING_RAD: f64 = 6.3;
/// The longest horizon a predictions file may hold, s (the node predicts 2 s ahead).
const MAX_HORIZON_S: f64 = 60.0;

/// Reads a predictions CSV (`t,step,horizon_s,x,y,heading,speed,mode`).
pub fn read_predictions(path: &Path) -> Result<Vec<Prediction>> {
    let mut out = Vec::new();
    for_each_prediction(path, |p| out.push(p))?;
    Ok(out)
}

/// Reads a predictions CSV one line at a time, giving each row to `emit` as it is read (a drive's
/// rows are never held together: [`evaluate::Scorer`]); refused, naming the file and line, as
/// [`read_predictions`] refuses it, at the first bad row (the rows before it have been given).
pub fn for_each_prediction(path: &Path, mut emit: impl FnMut(Prediction)) -> Result<()> {
    use std::io::BufRead;
    let reading = || format!("reading {}", path.display());
    let file = std::fs::File::open(path).with_context(reading)?;
    let mut reader = std::io::BufReader::with_capacity(1 << 16, file);
    let mut text = String::new();
    let split = |l: &str| -> Vec<String> { l.split(',').map(|s| s.trim().to_string()).collect() };
    let next_line = |reader: &mut std::io::BufReader<std::fs::File>, text: &mut String| {
        text.clear();
        let n = reader.read_line(text).with_context(reading)?;
        if text.ends_with('\n') {
            text.pop();
            if text.ends_with('\r') {
                text.pop();
            }
        }
        anyhow::Ok(n > 0)
    };
    if !next_line(&mut reader, &mut text)? {
        bail!("{}:1: empty file, a header row is required", path.display());
    }
    let header = split(&text);
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
    let mut prev_t: Option<f64> = None;
    let mut line = 1;
    while next_line(&mut reader, &mut text)? {
        line += 1;
        if text.trim().is_empty() {
            continue;
        }
        let row = split(&text);
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
        // What no node's output can be (a corrupt cell, another file): refused here, where
        // the line is known, rather than squared into an `inf` in the report.
        for (name, v, bound) in [
            ("t", p.t, logcsv::LOG_RANGES[0].max),
            ("x", p.x, logcsv::MAX_TRUTH_POSITION_M),
            ("y", p.y, logcsv::MAX_TRUTH_POSITION_M),
            ("heading", p.heading, MAX_HEADING_RAD),
            ("horizon_s", p.horizon_s, MAX_HORIZON_S),
        ] {
            if v.abs() > bound {
                bail!(
                    "{}:{line}: column `{name}`: {} is outside -{bound}..{bound} (no node \
                     predicts this: a corrupt cell?)",
                    path.display(),
                    logcsv::Readable(v),
                    bound = logcsv::Readable(bound),
                );
            }
        }
        if p.horizon_s < 0.0 {
            bail!(
                "{}:{line}: column `horizon_s`: {} is negative",
                path.display(),
                p.horizon_s
            );
        }
        if let Some(prev_t) = prev_t {
            if p.t < prev_t {
                bail!(
                    "{}:{line}: column `t`: time goes backwards ({} s after {} s)",
                    path.display(),
                    p.t,
                    prev_t
                );
            }
        }
        prev_t = Some(p.t);
        emit(p);
    }
    Ok(())
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
    // Only the messages read below are kept: the rest of a busy bus is counted, not held.
    let frames = replay::read_candump_selected_reporting(path, None, |f| {
        matches!(decode_planner(f), Ok(PlannerMessage::LocalOrigin(..)))
            || matches!(
                decode_input(f, car.gnss_source),
                Ok(InputMessage::Steering(..)
                    | InputMessage::Speed(..)
                    | InputMessage::GnssPosition(_))
            )
    })?
    .frames;
    let frame = LocalFrame::new(
        (origin_deg.0 * 1e7).round() as i32,
        (origin_deg.1 * 1e7).round() as i32,
    )
    .map_err(|e| anyhow::anyhow!("origin {origin_deg:?}: {e:?}"))?;
    let mut inputs = BaselineInputs::default();
    // LOCAL_ORIGIN's latitude page (with its counter), waiting for the longitude page.
    let mut origin_lat: Option<(i32, u8)> = None;
    for f in frames {
        let t = f.t_us as f64 * 1e-6;
        if let Ok(PlannerMessage::LocalOrigin(page, counter)) = decode_planner(&f.frame) {
            match page {
                LocalOrigin::Latitude { lat_e7 } => origin_lat = Some((lat_e7, counter)),
                LocalOrigin::Longitude { lon_e7 } => {
                    if let Some((lat_e7, c)) = origin_lat.take() {
                        if (c + 1) & 0x0F == counter {
                            if let Ok(enu) = frame.to_local(lat_e7, lon_e7) {
                                inputs.local_origins.push((
                                    t,
                                    f64::from(enu.east_m),
                                    f64::from(enu.north_m),
                                ));
                            }
                        }
                    }
                }
            }
            continue;
        }
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

/// Inputs whose GNSS fixes lie further than this from the truth (the median), m, are not the
/// truth's drive or not in its frame: ten times the node's GNSS gate, beyond any receiver's
/// error. A black-box probe's `--inputs` of another drive scored a baseline 227 m off with
/// exit 0.
pub const INPUTS_FAR_M: f64 = 100.0;

/// Predictions that cover less than this share of the time the truth and the inputs share get
/// a warning ([`EvaluationData::coverage_warning`]).
pub const COVERED_SHARE: f64 = 0.9;
/// ... and miss more than this much of it, s.
pub const COVER_SLACK_S: f64 = 5.0;
/// The truth's speed above which the car moves, m/s (the node has no position before).
const MOVING_MPS: f64 = 0.5;

/// The truth file's samples, refused when it holds none: an empty file (0 bytes) or a header
/// alone. Read first, before the inputs, so that a truth with nothing to score against is what
/// `evaluate` names (a black-box probe's empty `X.truth.csv` was "missing header row", its
/// header alone "opening X.can.log: No such file" when the candump beside it was missing, and
/// an empty `X.csv` "cannot guess the candump of this truth file").
pub fn read_truth(path: &Path) -> Result<Truth> {
    // The CSV reader calls an empty text a missing header, which sends the user looking for a
    // header in a file that holds nothing at all.
    if std::fs::metadata(path).is_ok_and(|m| m.is_file() && m.len() == 0) {
        bail!(
            "{}: empty file (0 bytes): the truth has no sample to score the predictions against",
            path.display()
        );
    }
    let rows = logcsv::read_truth(path).map_err(|e| anyhow::anyhow!("{e}"))?;
    if rows.is_empty() {
        bail!(
            "{}: a header row and no sample: the truth has no sample to score the predictions \
             against",
            path.display()
        );
    }
    let truth = Truth::new(rows);
    if let Some((median, steps)) = truth
        .track_disagreement()
        .filter(|(m, _)| *m > evaluate::TRACK_DISAGREEMENT_RAD)
    {
        bail!(
            "{}: the truth's heading is {median:.2} rad from the direction its own x, y move \
             (the median over {steps} steps of {} m): a truth has x east and y north of the \
             origin, m, and the heading clockwise from north, rad, as the simulator writes it \
             (docs/logs.md); a heading counter-clockwise from east (ROS, ENU) or x and y \
             swapped (NED) would be scored as if the car drove elsewhere",
            path.display(),
            evaluate::TRACK_STEP_M
        );
    }
    Ok(truth)
}

/// Everything `catmodel evaluate` reads: truth and the baseline's bus inputs, and the
/// predictions, scored as they are read ([`evaluate::Scorer`]) and kept only as far as the
/// checks and the figures need them.
pub struct EvaluationData {
    /// What is kept of the node's predictions.
    pub predictions: evaluate::KeptPredictions,
    /// The scores, before [`Self::evaluate`]'s checks.
    scores: Evaluation,
    /// Ground truth.
    pub truth: Truth,
    /// Raw GNSS, speed and steering from the candump.
    pub inputs: BaselineInputs,
    /// The car.
    pub car: Car,
    /// The files read: predictions, truth, inputs (for the errors).
    pub paths: [PathBuf; 3],
    /// The truth frame's origin, degrees.
    pub origin_deg: (f64, f64),
}

impl EvaluationData {
    /// Reads the truth and the inputs, then the predictions, scoring them row by row;
    /// `origin_deg` is the origin of the truth frame.
    pub fn read(
        predictions: &Path,
        truth: &Path,
        inputs: &Path,
        origin_deg: (f64, f64),
        car: Car,
    ) -> Result<Self> {
        let truth_rows = read_truth(truth)?;
        let bus = baseline_inputs(inputs, origin_deg, &car)?;
        let mut scorer =
            evaluate::Scorer::new(&truth_rows, &bus, &car.vehicle, car.antenna_ahead_m);
        for_each_prediction(predictions, |p| scorer.add(&p))?;
        let (scores, kept) = scorer.finish();
        Ok(Self {
            predictions: kept,
            scores,
            truth: truth_rows,
            inputs: bus,
            car,
            paths: [
                predictions.to_path_buf(),
                truth.to_path_buf(),
                inputs.to_path_buf(),
            ],
            origin_deg,
        })
    }

    /// Scores the predictions and the baseline (the car's geometry for the baseline). Refused,
    /// with what to do, when the scores would mislead: the files do not overlap in time, the
    /// node had no position, the inputs hold no fix in the truth's time, the predictions are
    /// not in the truth's frame ([`Self::check_frame`]); and a report with a figure that is not
    /// a finite number is never returned.
    pub fn evaluate(&self) -> Result<Evaluation> {
        let [pred_path, truth_path, inputs_path] = &self.paths;
        let span = |t: &mut dyn Iterator<Item = f64>| {
            t.fold(None, |r: Option<(f64, f64)>, t| {
                Some(r.map_or((t, t), |(a, b)| (a.min(t), b.max(t))))
            })
        };
        let truth_span = span(&mut self.truth.samples().iter().map(|s| s.t));
        let Some((t0, t1)) = truth_span else {
            bail!("{}: no truth row (a header alone)", truth_path.display());
        };
        if let Some((p0, p1)) = self.predictions.span {
            if p1 < t0 || p0 > t1 {
                bail!(
                    "{} (t = {p0} .. {p1} s) and the truth {} (t = {t0} .. {t1} s) do not \
                     overlap in time: nothing to score. The two are on different clocks (an \
                     epoch time against time from the start?): shift one onto the other's \
                     clock (the log's `t` before csv2can, or the truth's `t`)",
                    pred_path.display(),
                    truth_path.display()
                );
            }
        }
        let e = self.scores.clone();
        if e.ticks == 0 && !self.predictions.current.is_empty() {
            // The node had positions; the truth had none to score them on: its samples are
            // further apart than [`evaluate::TRUTH_GAP_S`] (a 1 Hz reference receiver), and
            // nothing is scored within a gap.
            let mut steps: Vec<f64> = self
                .truth
                .samples()
                .windows(2)
                .map(|w| w[1].t - w[0].t)
                .collect();
            steps.sort_by(f64::total_cmp);
            if let Some(&median) = steps.get(steps.len() / 2) {
                if median > evaluate::TRUTH_GAP_S {
                    bail!(
                        "{}: no prediction to score: the truth's samples are {median:.3} s apart \
                         (median), more than the {} s across which a truth is interpolated, so \
                         every prediction falls in a gap of it (the node had positions at {} \
                         ticks): a truth sampled at {:.0} Hz or faster (the reference \
                         receiver's rate)",
                        truth_path.display(),
                        evaluate::TRUTH_GAP_S,
                        self.predictions.current.len(),
                        (1.0 / evaluate::TRUTH_GAP_S).ceil()
                    );
                }
            }
        }
        if e.ticks == 0 {
            bail!(
                "{}: no prediction to score: the node had no valid position at any tick \
                 (replay warns why: a receiver slower than the model file's gnss_rate_hz \
                 times out between its fixes; GNSS missing or refused)",
                pred_path.display()
            );
        }
        match span(&mut self.inputs.gnss.iter().map(|g| g.0)) {
            None => bail!(
                "{}: no GNSS fix from source address {} (the raw GNSS error and the baseline \
                 are measured on them): is it the candump the predictions came from?",
                inputs_path.display(),
                self.car.gnss_source
            ),
            Some((g0, g1)) if g1 < t0 || g0 > t1 => bail!(
                "the inputs {} (GNSS fixes at t = {g0} .. {g1} s) and the truth {} (t = {t0} .. \
                 {t1} s) do not overlap in time: the raw GNSS error and the baseline cannot be \
                 measured. Is it the candump the predictions came from, on the truth's clock?",
                inputs_path.display(),
                truth_path.display()
            ),
            Some((g0, g1)) => {
                if let Some((p0, p1)) = self
                    .predictions
                    .span
                    .filter(|(p0, p1)| g1 < *p0 || g0 > *p1)
                {
                    bail!(
                        "the inputs {} (GNSS fixes at t = {g0} .. {g1} s) and the predictions \
                         {} (t = {p0} .. {p1} s) do not overlap in time: the baseline has no \
                         input at the predictions' ticks. Is it the candump the predictions \
                         came from?",
                        inputs_path.display(),
                        pred_path.display()
                    );
                }
            }
        }
        if let Some((median_m, fixes)) = self.fixes_from_truth_m() {
            if median_m > INPUTS_FAR_M {
                bail!(
                    "the inputs {}: their GNSS fixes lie {median_m:.0} m from the truth {} at \
                     their times (the median over {fixes} fixes; a receiver's error is metres): \
                     they are not the drive of the truth (another drive's candump?) or not in \
                     its frame (evaluate's --origin, the truth frame's origin): the raw GNSS \
                     error and the baseline cannot be measured on them",
                    inputs_path.display(),
                    truth_path.display()
                );
            }
        }
        self.check_frame()?;
        if let Some((what, v)) = e.non_finite() {
            bail!(
                "{} against {}: the evaluation's {what} is {v}, not a finite number: refused \
                 rather than printed (an input value beyond what the readers check: please \
                 report it with the files)",
                pred_path.display(),
                truth_path.display()
            );
        }
        Ok(e)
    }

    /// The median distance of the inputs' GNSS fixes from the truth at their times, m, and the
    /// number of fixes within the truth; `None` without such a fix.
    fn fixes_from_truth_m(&self) -> Option<(f64, usize)> {
        let mut d: Vec<f64> = self
            .inputs
            .gnss
            .iter()
            .filter_map(|&(t, x, y)| {
                self.truth
                    .at(t)
                    .map(|(tx, ty, _, _)| (x - tx).hypot(y - ty))
            })
            .collect();
        if d.is_empty() {
            return None;
        }
        let n = d.len();
        let mid = n / 2;
        let (_, m, _) = d.select_nth_unstable_by(mid, f64::total_cmp);
        Some((*m, n))
    }

    /// A warning when the predictions leave more than 1 - [`COVERED_SHARE`] and
    /// [`COVER_SLACK_S`] of the drive the truth and the inputs' fixes share without a
    /// prediction (from when the car moves): the raw GNSS figures are over all of it, the
    /// node's over the predictions' (a black-box probe's first 30 s of a 5-minute drive put
    /// raw GNSS at 0.784 x a floor measured over those 30 s, without a word). It gives raw
    /// GNSS at the rear axle over the predictions' span, and its ratio to the floor.
    pub fn coverage_warning(&self, e: &Evaluation) -> Option<String> {
        let (p0, p1) = self.predictions.span?;
        let samples = self.truth.samples();
        let (t0, t1) = (samples.first()?.t, samples.last()?.t);
        let (g0, g1) = self
            .inputs
            .gnss
            .iter()
            .fold(None, |r: Option<(f64, f64)>, g| {
                Some(r.map_or((g.0, g.0), |(a, b)| (a.min(g.0), b.max(g.0))))
            })?;
        let (s0, s1) = (t0.max(g0), t1.min(g1));
        // The node has no position before the car moves: the drive starts there.
        let m0 = samples
            .iter()
            .find(|r| r.t >= s0 && r.t <= s1 && r.speed > MOVING_MPS)
            .map_or(s0, |r| r.t);
        let drive = s1 - m0;
        let uncovered = (p0 - m0).max(0.0) + (s1 - p1).max(0.0);
        if drive.is_nan()
            || drive <= 0.0
            || uncovered <= COVER_SLACK_S
            || uncovered <= (1.0 - COVERED_SHARE) * drive
        {
            return None;
        }
        let ahead = self.car.antenna_ahead_m;
        let mut sq = Vec::new();
        for &(t, x, y) in &self.inputs.gnss {
            if t < p0 || t > p1 {
                continue;
            }
            if let Some((tx, ty, th, _)) = self.truth.at(t) {
                let (ax, ay) = (x - ahead * th.sin(), y - ahead * th.cos());
                sq.push((ax - tx).powi(2) + (ay - ty).powi(2));
            }
        }
        let within = if sq.is_empty() {
            "no fix lies within it".to_string()
        } else {
            let rms = (sq.iter().sum::<f64>() / sq.len() as f64).sqrt();
            let floor = e.bias_floor.pos_rms_m;
            let ratio = if floor > 0.0 {
                format!(" = {:.3} x the floor", rms / floor)
            } else {
                String::new()
            };
            format!(
                "over it raw GNSS at the rear axle is {rms:.3} m RMS ({} fixes){ratio}",
                sq.len()
            )
        };
        Some(format!(
            "{}: the predictions cover t = {p0} .. {p1} s of the drive the truth and the \
             inputs' fixes share, t = {s0} .. {s1} s (the car moving from t = {m0} s): {:.1} s \
             of its {:.1} s ({:.0} %) have no prediction. The node's figures and the floor are \
             over the predictions' span, the raw GNSS lines over all of it; {within}",
            self.paths[0].display(),
            uncovered.min(drive),
            drive,
            100.0 * uncovered.min(drive) / drive
        ))
    }

    /// Refuses predictions that are not in the truth's frame. `replay` without `--origin`
    /// puts the node's origin at its first fix (the contract), and `evaluate` reads them in
    /// the truth's (the simulator's test site by default): the two frames differ by the first
    /// fix's error, 1-2 m, and the filtered position scored 1.2-1.8 x the bias floor where the
    /// same run in the truth's frame scores 1.01-1.05 x, without a word. The filtered position
    /// follows the fixes whatever their bias, so its mean offset from them tells the frame
    /// ([`evaluate::frame_offset_check`]): near 0 in the truth's frame, near minus the node's
    /// origin in the node's. The candidates: the first fix, and the planner's LOCAL_ORIGIN if
    /// the inputs carry one.
    pub fn check_frame(&self) -> Result<()> {
        let [pred_path, _, inputs_path] = &self.paths;
        let first_fix = self.inputs.gnss.first().map(|g| ("the first GNSS fix", g));
        let planner = self
            .inputs
            .local_origins
            .first()
            .map(|o| ("the planner's LOCAL_ORIGIN", o));
        for (what, &(_, east, north)) in first_fix.into_iter().chain(planner) {
            let Some(c) = evaluate::frame_offset_check(
                &self.predictions.current,
                &self.truth,
                &self.inputs.gnss,
                self.car.antenna_ahead_m,
                (east, north),
            ) else {
                continue;
            };
            if !c.in_candidate_frame() {
                continue;
            }
            let (lat, lon) = self.origin_deg;
            let advice = if what == "the first GNSS fix" {
                format!(
                    "`catmodel replay` without `--origin` puts the node's origin at its first \
                     fix. Re-run it in the truth's frame: `catmodel replay {} --origin \
                     {lat},{lon} --out {}` (the truth frame's origin; evaluate's `--origin` if \
                     the truth has another)",
                    inputs_path.display(),
                    pred_path.display()
                )
            } else {
                "the planner's map origin became the node's frame: evaluate against a truth in \
                 that frame (`--origin` its LAT,LON)"
                    .to_string()
            };
            bail!(
                "{}: the predictions are not in the truth's frame (origin {lat},{lon}): the \
                 node's filtered position sits ({:+.2}, {:+.2}) m east/north of the raw fixes on \
                 average over {} ticks, where a frame with its origin at {what}, ({:+.2}, \
                 {:+.2}) m from the truth's origin, puts it ({:.2} m off that, {:.2} m off the \
                 truth's frame). Scored as they are, they would add that offset to every error. \
                 {advice}",
                pred_path.display(),
                c.offset_m.0,
                c.offset_m.1,
                c.ticks,
                c.candidate_m.0,
                c.candidate_m.1,
                c.residual_candidate_m,
                c.residual_truth_m,
            );
        }
        Ok(())
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
    EvaluationData::read(predictions, truth, inputs, origin_deg, car)?.evaluate()
}

/// The rate of a receiver's fixes over a whole log or session: the median interval between
/// consecutive fixes. The node names none: it keeps the latest interval off the declared period
/// ([`catmodel::node::Node::gnss_off_rate_interval_us`]), one interval with the receive
/// times' jitter in it (8 ms, "132.7 Hz", for a 100 Hz receiver whose median interval is
/// 10.0 ms; 95.5 Hz on a longer drive of the same receiver: review finding 04). The median
/// over every fix is the receiver's period whatever the jitter and a few gaps.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReceiverRate {
    /// The median interval between consecutive fixes, s (the mean when the median is 0:
    /// fixes stamped in batches share their timestamps).
    pub interval_s: f64,
    /// The fixes it was measured over.
    pub fixes: usize,
}

impl ReceiverRate {
    /// The rate of fixes received at `t_us` (ascending), `None` with fewer than two fixes or
    /// none apart in time.
    pub fn measure(t_us: &[u64]) -> Option<Self> {
        let mut intervals: Vec<u64> = t_us.windows(2).map(|w| w[1].saturating_sub(w[0])).collect();
        intervals.sort_unstable();
        let median = *intervals.get(intervals.len() / 2)?;
        let interval_us = if median > 0 {
            median as f64
        } else {
            (t_us[t_us.len() - 1] - t_us[0]) as f64 / intervals.len() as f64
        };
        (interval_us > 0.0).then_some(Self {
            interval_s: interval_us * 1e-6,
            fixes: t_us.len(),
        })
    }

    /// Fixes per second.
    pub fn hz(&self) -> f64 {
        1.0 / self.interval_s
    }
}

/// Why the node did not use the GNSS fixes, when the receiver ran at another rate than the
/// model file declares (`counters.gnss_rate_mismatch` fixes not used): the message names the
/// receiver's rate as `measured` over the whole log ([`ReceiverRate`]) and the `gnss_rate_hz`
/// to declare, rounded to 0.1 Hz as `catmodel identify` writes it. A rate outside the model
/// file's range ([`model_file::GNSS_RATE_RANGE_HZ`]) is never advised: the reader refuses it
/// (132.7 Hz was, review finding 04); the message says to set the receiver's rate instead.
pub fn gnss_rate_note(
    counters: &catmodel::node::Counters,
    measured: Option<ReceiverRate>,
    declared_hz: f64,
) -> Option<String> {
    if counters.gnss_rate_mismatch == 0 {
        return None;
    }
    let declared = (declared_hz * 10.0).round() / 10.0;
    let lead = format!(
        "{} GNSS fixes not used: the model file declares gnss_rate_hz = {declared} (the GNSS \
         lowpass and heading filter are designed for that rate)",
        counters.gnss_rate_mismatch
    );
    let Some(rate) = measured else {
        return Some(format!(
            "{lead}, and the receiver's fixes came at another rate; set [vehicle] gnss_rate_hz \
             to the receiver's rate (`catmodel identify` writes it from the logs)"
        ));
    };
    let hz = rate.hz();
    let came = format!(
        "the receiver's fixes came at {hz:.1} Hz (the median interval between its {} fixes: \
         {:.2} ms)",
        rate.fixes,
        rate.interval_s * 1e3
    );
    if counters.time_errors > 0 && ((hz * 10.0).round() / 10.0 - declared).abs() < 0.05 {
        // The receiver runs at the declared rate: the fixes the rate check judged were the
        // ones left after the node refused those stamped after their TICK (a black-box
        // probe's fixes 1.5 and 6 ms late: every second one refused, the rest 20 ms apart,
        // and the note told it to declare the 100 Hz it declared). The timestamps are wrong.
        return Some(format!(
            "{came}, the rate the model file declares (gnss_rate_hz = {declared}), but {} GNSS \
             fixes were not used by the node's rate check: {} frames were stamped after the \
             TICK that delivered them, which the node refuses (`time_errors`), and the fixes \
             left came at intervals off the period. Stamp every frame at or before the TICK \
             that delivers it (the sender's clock runs ahead of the TICKs); the model file's \
             rate is right",
            counters.gnss_rate_mismatch, counters.time_errors
        ));
    }
    let (lo, hi) = model_file::GNSS_RATE_RANGE_HZ;
    let advice = if hz > hi {
        format!(
            "that is above the {hi} Hz a model file may declare (the rates the node's lowpass \
             and gap logic are designed for: {lo}..{hi} Hz): set the receiver to send at {hi} Hz \
             or less, and declare that rate"
        )
    } else if hz < lo {
        format!(
            "that is below the {lo} Hz a model file may declare (the rates the node's lowpass \
             and gap logic are designed for: {lo}..{hi} Hz): set the receiver to send at {lo} Hz \
             or more, and declare that rate"
        )
    } else {
        format!(
            "set [vehicle] gnss_rate_hz = {} (`catmodel identify` writes it from the logs)",
            ((hz * 10.0).round() / 10.0).clamp(lo, hi)
        )
    };
    Some(format!("{came}, and {lead}: {advice}"))
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
            (
                "0.02,0,0.00,1e300,2,0.1,3,kinematic\n",
                ":2: column `x`: 1e300 is outside -1e7..1e7",
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

    /// `evaluate` scores the predictions as it reads them, keeping only what the checks and
    /// the figures need (outside review, finding 08): the same evaluation as the whole list's
    /// on the bundled smoke drive.
    #[test]
    fn streamed_evaluation_equals_the_whole_lists() {
        let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data");
        let can = data.join("smoke.can.log");
        let mut config = node_config(None).unwrap();
        config.origin_e7 = Some(sim_origin_e7());
        let frames = replay::read_candump_reporting(&can, None).unwrap().frames;
        let pred = write(
            "smoke.pred.csv",
            &replay::replay(&frames, config).predictions_csv,
        );
        let car = Car::from_model(&model_file::load(&model_file::paper_path()).unwrap());
        let truth = data.join("smoke.truth.csv");
        let streamed = EvaluationData::read(&pred, &truth, &can, SIM_ORIGIN_DEG, car).unwrap();
        let list = read_predictions(&pred).unwrap();
        let whole = evaluate::evaluate(
            &list,
            &streamed.truth,
            &streamed.inputs,
            &car.vehicle,
            car.antenna_ahead_m,
        );
        assert_eq!(streamed.evaluate().unwrap(), whole);
        assert!(whole.ticks > 500, "{}", whole.ticks);
        assert_eq!(
            streamed.predictions.current,
            evaluate::current_positions(&list)
        );
        let (h1, rows) = streamed.predictions.path_horizon().unwrap();
        assert_eq!(h1, 1.0);
        assert_eq!(
            rows.len(),
            list.iter().filter(|p| p.horizon_s == 1.0).count()
        );
    }

    /// The rate a replay names (review finding 04): the median interval over every fix, whatever
    /// one interval's jitter, and never a `gnss_rate_hz` the model-file reader refuses.
    #[test]
    fn the_receiver_rate_is_the_median_and_only_a_readable_rate_is_advised() {
        // A 100 Hz receiver with one fix received 2 ms late (intervals of 12 and 8 ms beside
        // it, the node's latest off-period interval 8 ms: "125 Hz"): the median is 10 ms.
        let t: Vec<u64> = (0..100u64)
            .map(|k| k * 10_000 + if k == 40 { 2_000 } else { 0 })
            .collect();
        let rate = ReceiverRate::measure(&t).unwrap();
        assert_eq!(rate.interval_s, 0.010);
        assert_eq!(rate.hz(), 100.0);
        // Stamped in batches (every fix of a batch on one timestamp): the mean interval.
        let batched = [0, 0, 0, 50_000, 50_000, 50_000, 100_000];
        assert!((ReceiverRate::measure(&batched).unwrap().interval_s - 0.1 / 6.0).abs() < 1e-12);
        assert_eq!(ReceiverRate::measure(&[5]), None);
        assert_eq!(ReceiverRate::measure(&[5, 5]), None);

        let counters = catmodel::node::Counters {
            gnss_rate_mismatch: 7,
            ..Default::default()
        };
        let note = gnss_rate_note(&counters, Some(rate), 10.0).unwrap();
        assert!(
            note.contains("came at 100.0 Hz (the median interval between its 100 fixes: 10.00 ms)")
                && note.contains("declares gnss_rate_hz = 10 ")
                && note.ends_with("set [vehicle] gnss_rate_hz = 100 (`catmodel identify` writes it from the logs)"),
            "{note}"
        );
        // 200 Hz and 0.5 Hz: outside the reader's 1..100 Hz, so not advised.
        for (interval_s, bound) in [(0.005, "above the 100 Hz"), (2.0, "below the 1 Hz")] {
            let rate = ReceiverRate {
                interval_s,
                fixes: 50,
            };
            let note = gnss_rate_note(&counters, Some(rate), 10.0).unwrap();
            assert!(
                note.contains(bound) && !note.contains("set [vehicle] gnss_rate_hz ="),
                "{note}"
            );
        }
        let quiet = catmodel::node::Counters::default();
        assert_eq!(gnss_rate_note(&quiet, Some(rate), 10.0), None);
    }

    /// A black-box probe's fixes stamped 1.5 or 6 ms after the TICK that delivered them
    /// (`scen3.py future_gnss_1s`): the node refused those (`time_errors` 100), the fixes left
    /// came 20 ms apart and the rate check did not use 50 of them, and the note told the user
    /// to set gnss_rate_hz = 100, which the file declared. A receiver measured at the declared
    /// rate with frames stamped after their TICK is now told of its timestamps.
    #[test]
    fn fixes_at_the_declared_rate_refused_for_their_stamps_are_named_for_the_stamps() {
        let t: Vec<u64> = (0..4000u64).map(|k| k * 10_000).collect();
        let rate = ReceiverRate::measure(&t).unwrap();
        let counters = catmodel::node::Counters {
            gnss_rate_mismatch: 50,
            time_errors: 100,
            ..Default::default()
        };
        let note = gnss_rate_note(&counters, Some(rate), 100.0).unwrap();
        assert!(
            note.contains("came at 100.0 Hz")
                && note.contains("100 frames were stamped after the TICK that delivered them")
                && note.contains("50 GNSS fixes were not used")
                && note.contains("Stamp every frame at or before the TICK")
                && !note.contains("set [vehicle] gnss_rate_hz ="),
            "{note}"
        );
        // Without frames stamped late, a receiver at another rate is told its rate, as before.
        let other = catmodel::node::Counters {
            time_errors: 0,
            ..counters
        };
        let note = gnss_rate_note(&other, Some(rate), 10.0).unwrap();
        assert!(
            note.ends_with(
                "set [vehicle] gnss_rate_hz = 100 (`catmodel identify` writes it from the logs)"
            ),
            "{note}"
        );
    }
}
