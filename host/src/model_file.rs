//! The model file (DESIGN.md, "Model file"): a commented TOML file holding the vehicle
//! parameters, the sample time, every identified model as continuous-time transfer functions
//! with input delays, the fit figures they were validated with, and the hybrid switching
//! thresholds. `models/paper.toml` is the published one.
//!
//! Loading validates everything into the core's types ([`TransferFunction`], [`VehicleParams`],
//! [`HybridConfig`]); every problem is an error naming the file and the key
//! (`speed.blocks[0].den: ...`). Writing ([`to_toml`]) produces the same commented layout, so a
//! file written by `catmodel identify` reads like the published one and loads back equal.
//!
//! Layout (stable keys; see `models/paper.toml` for the comments):
//! - top level: `format = "catmodel-model-1"`, `name`, `description`, `sample_time_s`;
//! - `[vehicle]`: `wheelbase_m`, `track_m`, `max_steer_deg`, `understeer_s2_per_m2`;
//! - `[hybrid]`: `enter_dynamic_speed_mps`, `enter_dynamic_lat_accel_mps2`,
//!   `exit_dynamic_speed_mps`, `exit_dynamic_lat_accel_mps2`, `min_dwell_ticks`;
//! - `[speed]` (eq 5: `input_vel` -> `vel`) and `[dx_dt]` (eq 7: `[v_m, x, y, phi]` -> dx/dt),
//!   each with `equation`, `output`, `output_unit`, `[[X.blocks]]` (`input`, `input_unit`,
//!   `num`, `den` in descending powers of s, `delay_s`) and an optional `[X.fit]`;
//! - optional `[lateral]`: yaw rate from the kinematic yaw rate with an estimated steering gain
//!   and understeer term (`steer_gain`, `understeer_s2_per_m2`, one block, optional fit).
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use catmodel::model::hybrid::HybridConfig;
use catmodel::model::tf::{ModelError, TransferFunction};
use catmodel::model::zoh;
use catmodel::vehicle::VehicleParams;
use serde::Deserialize;

/// Value of the `format` key this version reads and writes.
pub const FORMAT: &str = "catmodel-model-1";
/// Input names of the speed model (eq 5), in order.
pub const SPEED_INPUTS: [&str; 1] = ["input_vel"];
/// Input names of the dx/dt model (eq 7), in the order of the node's `MisoBlock`.
pub const DX_DT_INPUTS: [&str; 4] = ["v_m", "x", "y", "phi"];
/// Input name of the lateral model: the kinematic yaw rate `v tan(g delta / (1 + K v^2)) / L`.
pub const LATERAL_INPUTS: [&str; 1] = ["yaw_rate_kinematic"];

/// A model file that failed to load, with where and why.
#[derive(Debug)]
pub struct ModelFileError {
    /// The file (or `<string>`).
    pub path: PathBuf,
    /// What is wrong, naming the key.
    pub message: String,
}

impl std::fmt::Display for ModelFileError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.path.display(), self.message)
    }
}

impl std::error::Error for ModelFileError {}

/// Fit figures a model was validated with (MATLAB `compare` fit %, pure simulation; MSE in the
/// output's unit squared). Every field is optional: the paper does not give all of them.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Fit {
    /// Where the figures come from (`paper`, or `catmodel identify` with its inputs).
    #[serde(default)]
    pub source: String,
    /// Fit % on the training data.
    pub training_fit_percent: Option<f64>,
    /// Fit % on the validation data.
    pub validation_fit_percent: Option<f64>,
    /// MSE on the training data.
    pub training_mse: Option<f64>,
    /// MSE on the validation data.
    pub validation_mse: Option<f64>,
    /// The kinematic model (eq 8) on the training data, fit %.
    pub kinematic_training_fit_percent: Option<f64>,
    /// The kinematic model (eq 8) on the validation data, fit %.
    pub kinematic_validation_fit_percent: Option<f64>,
    /// The kinematic model (eq 8) on the training data, MSE.
    pub kinematic_training_mse: Option<f64>,
    /// The kinematic model (eq 8) on the validation data, MSE.
    pub kinematic_validation_mse: Option<f64>,
    /// Free text: what exactly was measured.
    #[serde(default)]
    pub note: String,
}

/// One single-input block of a model: `h(s) = e^{-delay s} num(s)/den(s)` from `input`.
#[derive(Debug, Clone, PartialEq)]
pub struct Block {
    /// Input signal name (see [`SPEED_INPUTS`], [`DX_DT_INPUTS`], [`LATERAL_INPUTS`]).
    pub input: String,
    /// Input unit.
    pub input_unit: String,
    /// The validated transfer function.
    pub tf: TransferFunction,
}

/// A (MISO) model: output = sum of its blocks.
#[derive(Debug, Clone, PartialEq)]
pub struct Model {
    /// The paper's equation it reproduces, or a description.
    pub equation: String,
    /// Output signal name.
    pub output: String,
    /// Output unit.
    pub output_unit: String,
    /// The blocks, in input order.
    pub blocks: Vec<Block>,
    /// Fit figures.
    pub fit: Fit,
}

impl Model {
    /// The transfer functions, in input order.
    pub fn tfs(&self) -> Vec<TransferFunction> {
        self.blocks.iter().map(|b| b.tf).collect()
    }
}

/// The lateral model for the hybrid predictor: `r = G(s) r_kin`, with
/// `r_kin = v tan(steer_gain * delta / (1 + K v^2)) / L` and `delta` the nominal centre-tyre
/// angle from steering percent (`max_steer_deg / 100 * p`).
#[derive(Debug, Clone, PartialEq)]
pub struct Lateral {
    /// Measured-to-nominal steering angle ratio (1 = the nominal 35.5 deg at 100 %).
    pub steer_gain: f64,
    /// Understeer term K, s^2/m^2.
    pub understeer_s2_per_m2: f64,
    /// The dynamic part `G(s)` (one block, input [`LATERAL_INPUTS`]).
    pub model: Model,
}

/// A loaded, validated model file.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelFile {
    /// Short name.
    pub name: String,
    /// What it is and where it comes from.
    pub description: String,
    /// Sample time the delays are whole multiples of, s.
    pub sample_time_s: f64,
    /// Vehicle geometry and steering conversion (f64 as written; [`VehicleSection::params`]).
    pub vehicle: VehicleSection,
    /// Hybrid switching thresholds (f64 as written; [`HybridSection::config`]).
    pub hybrid: HybridSection,
    /// Eq 5: commanded speed -> speed.
    pub speed: Model,
    /// Eq 7: `[v_m, x, y, phi]` -> dx/dt.
    pub dx_dt: Model,
    /// Optional lateral model.
    pub lateral: Option<Lateral>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFile {
    format: String,
    name: String,
    #[serde(default)]
    description: String,
    sample_time_s: f64,
    vehicle: VehicleSection,
    hybrid: HybridSection,
    speed: RawModel,
    dx_dt: RawModel,
    lateral: Option<RawLateral>,
}

/// `[vehicle]`, as written in the file.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VehicleSection {
    /// Wheelbase L, m.
    pub wheelbase_m: f64,
    /// Track T, m.
    pub track_m: f64,
    /// Centre-tyre angle at 100 % steering, degrees.
    pub max_steer_deg: f64,
    /// Understeer term K of eq 2, s^2/m^2.
    pub understeer_s2_per_m2: f64,
}

impl VehicleSection {
    /// The core's f32 parameters.
    pub fn params(&self) -> VehicleParams {
        VehicleParams {
            wheelbase_m: self.wheelbase_m as f32,
            track_m: self.track_m as f32,
            max_steer_rad: self.max_steer_deg.to_radians() as f32,
            understeer_s2_per_m2: self.understeer_s2_per_m2 as f32,
        }
    }

    /// Nominal centre-tyre angle from steering percent, rad (paper II-C), f64.
    pub fn steer_pct_to_rad(&self, pct: f64) -> f64 {
        pct.clamp(-100.0, 100.0) / 100.0 * self.max_steer_deg.to_radians()
    }
}

/// `[hybrid]`, as written in the file.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HybridSection {
    /// Kinematic -> dynamic above this speed, m/s.
    pub enter_dynamic_speed_mps: f64,
    /// ... or this |lateral acceleration|, m/s^2.
    pub enter_dynamic_lat_accel_mps2: f64,
    /// Dynamic -> kinematic below this speed ...
    pub exit_dynamic_speed_mps: f64,
    /// ... and this |lateral acceleration|, m/s^2.
    pub exit_dynamic_lat_accel_mps2: f64,
    /// Minimum ticks in a mode.
    pub min_dwell_ticks: u16,
}

impl HybridSection {
    /// The core's f32 configuration.
    pub fn config(&self) -> HybridConfig {
        HybridConfig {
            enter_dynamic_speed_mps: self.enter_dynamic_speed_mps as f32,
            enter_dynamic_lat_accel_mps2: self.enter_dynamic_lat_accel_mps2 as f32,
            exit_dynamic_speed_mps: self.exit_dynamic_speed_mps as f32,
            exit_dynamic_lat_accel_mps2: self.exit_dynamic_lat_accel_mps2 as f32,
            min_dwell_ticks: self.min_dwell_ticks,
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawModel {
    #[serde(default)]
    equation: String,
    output: String,
    output_unit: String,
    blocks: Vec<RawBlock>,
    #[serde(default)]
    fit: Fit,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBlock {
    input: String,
    input_unit: String,
    num: Vec<f64>,
    den: Vec<f64>,
    delay_s: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLateral {
    steer_gain: f64,
    understeer_s2_per_m2: f64,
    #[serde(default)]
    equation: String,
    output: String,
    output_unit: String,
    blocks: Vec<RawBlock>,
    #[serde(default)]
    fit: Fit,
}

/// Why a transfer function was refused, in words.
pub fn describe_model_error(e: &ModelError) -> String {
    match e {
        ModelError::NotFinite => "a coefficient or the delay is not a finite number".into(),
        ModelError::EmptyPolynomial => "empty polynomial".into(),
        ModelError::ZeroLeadingDenominator => {
            "leading denominator coefficient is 0 (the order would be ill-defined)".into()
        }
        ModelError::Improper {
            numerator_degree,
            denominator_degree,
        } => format!(
            "improper: numerator degree {numerator_degree} > denominator degree {denominator_degree}"
        ),
        ModelError::OrderTooHigh { order, max } => {
            format!("order {order} is above the supported maximum {max}")
        }
        ModelError::NegativeDelay => "negative delay".into(),
        ModelError::InvalidSamplePeriod => "sample period must be > 0".into(),
        ModelError::FractionalDelay { delay_s, ts_s } => format!(
            "delay {delay_s} s is not a whole number of samples of {ts_s} s (fractional delays are not supported)"
        ),
        other => format!("{other:?}"),
    }
}

fn check_positive(path: &Path, key: &str, v: f64) -> Result<(), ModelFileError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(err(
            path,
            format!("{key} = {v}: must be a finite number > 0"),
        ))
    }
}

fn err(path: &Path, message: String) -> ModelFileError {
    ModelFileError {
        path: path.to_path_buf(),
        message,
    }
}

fn convert_model(
    path: &Path,
    key: &str,
    raw: RawModel,
    inputs: &[&str],
    ts: f64,
) -> Result<Model, ModelFileError> {
    if raw.blocks.len() != inputs.len() {
        return Err(err(
            path,
            format!(
                "{key}.blocks: expected {} block(s) with inputs {:?}, found {}",
                inputs.len(),
                inputs,
                raw.blocks.len()
            ),
        ));
    }
    let mut blocks = Vec::with_capacity(raw.blocks.len());
    for (i, (b, want)) in raw.blocks.into_iter().zip(inputs).enumerate() {
        let bkey = format!("{key}.blocks[{i}]");
        if b.input != *want {
            return Err(err(
                path,
                format!("{bkey}.input = {:?}: expected {want:?}", b.input),
            ));
        }
        let tf = TransferFunction::new(&b.num, &b.den, b.delay_s)
            .map_err(|e| err(path, format!("{bkey}: {}", describe_model_error(&e))))?;
        zoh::delay_samples(b.delay_s, ts).map_err(|e| {
            err(
                path,
                format!("{bkey}.delay_s: {}", describe_model_error(&e)),
            )
        })?;
        blocks.push(Block {
            input: b.input,
            input_unit: b.input_unit,
            tf,
        });
    }
    Ok(Model {
        equation: raw.equation,
        output: raw.output,
        output_unit: raw.output_unit,
        blocks,
        fit: raw.fit,
    })
}

/// Parses and validates a model file's text; `path` only names it in errors.
pub fn parse(text: &str, path: &Path) -> Result<ModelFile, ModelFileError> {
    let raw: RawFile = toml::from_str(text).map_err(|e| err(path, e.to_string()))?;
    if raw.format != FORMAT {
        return Err(err(
            path,
            format!("format = {:?}: this catmodel reads {FORMAT:?}", raw.format),
        ));
    }
    let ts = raw.sample_time_s;
    check_positive(path, "sample_time_s", ts)?;
    let v = &raw.vehicle;
    check_positive(path, "vehicle.wheelbase_m", v.wheelbase_m)?;
    check_positive(path, "vehicle.track_m", v.track_m)?;
    check_positive(path, "vehicle.max_steer_deg", v.max_steer_deg)?;
    if v.max_steer_deg >= 90.0 {
        return Err(err(
            path,
            format!(
                "vehicle.max_steer_deg = {}: must be below 90",
                v.max_steer_deg
            ),
        ));
    }
    if !(v.understeer_s2_per_m2.is_finite() && v.understeer_s2_per_m2 >= 0.0) {
        return Err(err(
            path,
            format!(
                "vehicle.understeer_s2_per_m2 = {}: must be finite and >= 0",
                v.understeer_s2_per_m2
            ),
        ));
    }
    let h = &raw.hybrid;
    for (key, val) in [
        ("hybrid.enter_dynamic_speed_mps", h.enter_dynamic_speed_mps),
        (
            "hybrid.enter_dynamic_lat_accel_mps2",
            h.enter_dynamic_lat_accel_mps2,
        ),
        ("hybrid.exit_dynamic_speed_mps", h.exit_dynamic_speed_mps),
        (
            "hybrid.exit_dynamic_lat_accel_mps2",
            h.exit_dynamic_lat_accel_mps2,
        ),
    ] {
        check_positive(path, key, val)?;
    }
    if h.exit_dynamic_speed_mps > h.enter_dynamic_speed_mps
        || h.exit_dynamic_lat_accel_mps2 > h.enter_dynamic_lat_accel_mps2
    {
        return Err(err(
            path,
            "hybrid: exit thresholds must not exceed enter thresholds (hysteresis)".into(),
        ));
    }
    let speed = convert_model(path, "speed", raw.speed, &SPEED_INPUTS, ts)?;
    let dx_dt = convert_model(path, "dx_dt", raw.dx_dt, &DX_DT_INPUTS, ts)?;
    let lateral = match raw.lateral {
        None => None,
        Some(l) => {
            check_positive(path, "lateral.steer_gain", l.steer_gain)?;
            if !(l.understeer_s2_per_m2.is_finite() && l.understeer_s2_per_m2 >= 0.0) {
                return Err(err(
                    path,
                    "lateral.understeer_s2_per_m2: must be finite and >= 0".into(),
                ));
            }
            let model = convert_model(
                path,
                "lateral",
                RawModel {
                    equation: l.equation,
                    output: l.output,
                    output_unit: l.output_unit,
                    blocks: l.blocks,
                    fit: l.fit,
                },
                &LATERAL_INPUTS,
                ts,
            )?;
            Some(Lateral {
                steer_gain: l.steer_gain,
                understeer_s2_per_m2: l.understeer_s2_per_m2,
                model,
            })
        }
    };
    Ok(ModelFile {
        name: raw.name,
        description: raw.description,
        sample_time_s: ts,
        vehicle: raw.vehicle,
        hybrid: raw.hybrid,
        speed,
        dx_dt,
        lateral,
    })
}

/// Reads and validates a model file.
pub fn load(path: &Path) -> Result<ModelFile, ModelFileError> {
    let text = std::fs::read_to_string(path).map_err(|e| err(path, format!("reading: {e}")))?;
    parse(&text, path)
}

/// Writes `file` as commented TOML (see [`to_toml`]).
pub fn save(path: &Path, file: &ModelFile) -> std::io::Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    std::fs::write(path, to_toml(file))
}

/// f64 in TOML: Rust's shortest round-trip form, always with a decimal point or exponent.
fn num(v: f64) -> String {
    let s = format!("{v:?}");
    if s.contains('.') || s.contains('e') || s.contains("inf") || s.contains("NaN") {
        s
    } else {
        format!("{s}.0")
    }
}

fn nums(v: &[f64]) -> String {
    let items: Vec<String> = v.iter().map(|x| num(*x)).collect();
    format!("[{}]", items.join(", "))
}

fn quoted(s: &str) -> String {
    // TOML basic strings: JSON escaping is a valid subset.
    serde_json::to_string(s).unwrap_or_else(|_| "\"\"".into())
}

fn write_fit(out: &mut String, key: &str, fit: &Fit) {
    let _ = writeln!(out, "\n[{key}.fit]");
    let _ = writeln!(
        out,
        "# fit % as MATLAB `compare` (pure simulation), MSE in the output unit squared"
    );
    let _ = writeln!(out, "source = {}", quoted(&fit.source));
    let fields = [
        ("training_fit_percent", fit.training_fit_percent),
        ("validation_fit_percent", fit.validation_fit_percent),
        ("training_mse", fit.training_mse),
        ("validation_mse", fit.validation_mse),
        (
            "kinematic_training_fit_percent",
            fit.kinematic_training_fit_percent,
        ),
        (
            "kinematic_validation_fit_percent",
            fit.kinematic_validation_fit_percent,
        ),
        ("kinematic_training_mse", fit.kinematic_training_mse),
        ("kinematic_validation_mse", fit.kinematic_validation_mse),
    ];
    for (name, value) in fields {
        if let Some(v) = value {
            let _ = writeln!(out, "{name} = {}", num(v));
        }
    }
    if !fit.note.is_empty() {
        let _ = writeln!(out, "note = {}", quoted(&fit.note));
    }
}

fn write_blocks(out: &mut String, key: &str, model: &Model) {
    for b in &model.blocks {
        let tf = &b.tf;
        let _ = writeln!(out, "\n[[{key}.blocks]]");
        let _ = writeln!(
            out,
            "# h(s) = e^(-delay_s s) num(s) / den(s), descending powers of s"
        );
        let _ = writeln!(out, "input = {}", quoted(&b.input));
        let _ = writeln!(out, "input_unit = {}", quoted(&b.input_unit));
        let _ = writeln!(out, "num = {}", nums(tf.numerator()));
        let _ = writeln!(out, "den = {}", nums(tf.denominator()));
        let _ = writeln!(out, "delay_s = {}", num(tf.delay_s()));
    }
}

fn write_model_head(out: &mut String, model: &Model) {
    let _ = writeln!(out, "equation = {}", quoted(&model.equation));
    let _ = writeln!(out, "output = {}", quoted(&model.output));
    let _ = writeln!(out, "output_unit = {}", quoted(&model.output_unit));
}

/// The model file as commented TOML, in the layout of `models/paper.toml`.
pub fn to_toml(f: &ModelFile) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "# catmodel model file (README, \"Model file\"). Stable keys; comments are ignored."
    );
    let _ = writeln!(o, "format = {}", quoted(FORMAT));
    let _ = writeln!(o, "name = {}", quoted(&f.name));
    let _ = writeln!(o, "description = {}", quoted(&f.description));
    let _ = writeln!(
        o,
        "# Sample time of the node and of every discretization, s; every delay_s is a whole multiple."
    );
    let _ = writeln!(o, "sample_time_s = {}", num(f.sample_time_s));
    let v = &f.vehicle;
    let _ = writeln!(o, "\n[vehicle]");
    let _ = writeln!(o, "wheelbase_m = {}       # L", num(v.wheelbase_m));
    let _ = writeln!(
        o,
        "track_m = {}           # T (tread), eq 3-4",
        num(v.track_m)
    );
    let _ = writeln!(
        o,
        "max_steer_deg = {}     # centre-tyre angle at 100 % steering",
        num(v.max_steer_deg)
    );
    let _ = writeln!(
        o,
        "understeer_s2_per_m2 = {}  # K of eq 2: R = L / tan(delta / (1 + K v^2))",
        num(v.understeer_s2_per_m2)
    );
    let h = &f.hybrid;
    let _ = writeln!(o, "\n[hybrid]");
    let _ = writeln!(
        o,
        "# kinematic -> dynamic above enter_*, back below both exit_*; each mode kept >= min_dwell_ticks x 20 ms"
    );
    let _ = writeln!(
        o,
        "enter_dynamic_speed_mps = {}",
        num(h.enter_dynamic_speed_mps)
    );
    let _ = writeln!(
        o,
        "enter_dynamic_lat_accel_mps2 = {}",
        num(h.enter_dynamic_lat_accel_mps2)
    );
    let _ = writeln!(
        o,
        "exit_dynamic_speed_mps = {}",
        num(h.exit_dynamic_speed_mps)
    );
    let _ = writeln!(
        o,
        "exit_dynamic_lat_accel_mps2 = {}",
        num(h.exit_dynamic_lat_accel_mps2)
    );
    let _ = writeln!(o, "min_dwell_ticks = {}", h.min_dwell_ticks);

    let _ = writeln!(
        o,
        "\n# Internal speed controller: commanded speed -> measured speed."
    );
    let _ = writeln!(o, "[speed]");
    write_model_head(&mut o, &f.speed);
    write_blocks(&mut o, "speed", &f.speed);
    write_fit(&mut o, "speed", &f.speed.fit);

    let _ = writeln!(
        o,
        "\n# Car dynamics, MISO: dx/dt (east) = h1 v_m + h2 x + h3 y + h4 phi, inputs in this order."
    );
    let _ = writeln!(o, "[dx_dt]");
    write_model_head(&mut o, &f.dx_dt);
    write_blocks(&mut o, "dx_dt", &f.dx_dt);
    write_fit(&mut o, "dx_dt", &f.dx_dt.fit);

    if let Some(l) = &f.lateral {
        let _ = writeln!(
            o,
            "\n# Lateral model for the hybrid predictor: yaw rate = G(s) r_kin,\n# r_kin = v tan(steer_gain delta / (1 + K v^2)) / L, delta = max_steer_deg / 100 * steer %."
        );
        let _ = writeln!(o, "[lateral]");
        let _ = writeln!(o, "steer_gain = {}", num(l.steer_gain));
        let _ = writeln!(o, "understeer_s2_per_m2 = {}", num(l.understeer_s2_per_m2));
        write_model_head(&mut o, &l.model);
        write_blocks(&mut o, "lateral", &l.model);
        write_fit(&mut o, "lateral", &l.model.fit);
    }
    o
}

/// Path of the published model file in this repository.
pub fn paper_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("models")
        .join("paper.toml")
}
