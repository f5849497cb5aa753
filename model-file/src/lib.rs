//! The model file: the one place where a car is described, and the one reader of it.
//!
//! A commented TOML file (format `catmodel-model-2`, `models/paper.toml` is the published one)
//! holding the vehicle (geometry, body, GNSS antenna and receiver rate, limits), the optional
//! dynamic single-track parameters, the bus inputs' timeouts, the hybrid switching thresholds,
//! and every identified model as continuous-time transfer functions with input delays and the
//! fit figures they were validated with.
//!
//! The host CLI (`replay --model`, `identify --base`, `compare`, `discretize`) and the
//! firmware's build script read a file with [`load`] and turn it into the node's configuration
//! with [`ModelFile::node_config`]; so a file is accepted or refused, with the same message, by
//! both. A file loads only if the node can run it: every check the node's fixed-size blocks
//! need (orders, delays, the sample time, the receiver rate) is made here, at load time, and the
//! f64 discretization and filter design happen here too (the firmware gets f32 words, see
//! [`bake`]).
//!
//! Errors name the file and the key: `speed.blocks[0].delay_s: ...`. Writing ([`to_toml`])
//! produces the same commented layout, so a file written by `catmodel identify` reads like the
//! published one and loads back equal.
//!
//! Layout (stable keys; `models/paper.toml` carries the comments and the sources):
//! - top level: `format = "catmodel-model-2"`, `name`, `description`, `sample_time_s` (must be
//!   the node's 0.02 s);
//! - `[vehicle]`: `wheelbase_m`, `track_m`, `max_steer_deg`, `understeer_s2_per_m2`,
//!   `antenna_ahead_m`, `antenna_left_m` (default 0), `gnss_rate_hz` (1..100), `width_m`,
//!   `length_m`, `rear_overhang_m`, `max_speed_mps`, `max_steer_rate_pct_per_s`,
//!   `steer_lag_s` (optional);
//! - `[dynamics]` (optional; without it the node stays on the kinematic model): `mass_kg`,
//!   `yaw_inertia_kg_m2`, `cg_to_front_m`, `cg_to_rear_m` (summing to the wheelbase),
//!   `cornering_front_n_per_rad`, `cornering_rear_n_per_rad`;
//! - `[inputs]`: `steer_timeout_s`, `speed_timeout_s`, `pedal_timeout_s`,
//!   `gnss_source_address`, `gnss_gate_m`, `gnss_lost_s`;
//! - `[control]`: `controller` (`"mpc"` or `"pure-pursuit"`), `position_uncertainty_m`,
//!   `mpc_lateral_weight_per_m2` (optional);
//! - `[hybrid]`: `enter_dynamic_speed_mps`, `enter_dynamic_lat_accel_mps2`,
//!   `exit_dynamic_speed_mps`, `exit_dynamic_lat_accel_mps2`, `min_dwell_ticks`;
//! - `[speed]` (eq 5: `input_vel` -> `vel`) and `[dx_dt]` (eq 7: `v_m`, `x`, `y`, `phi` ->
//!   dx/dt), each with `equation`, `output`, `output_unit`, `[[X.blocks]]` (`input`,
//!   `input_unit`, `num`, `den` in descending powers of s, `delay_s`) matched to the node's
//!   inputs by name, in any order, and an optional `[X.fit]`;
//! - optional `[lateral]`: yaw rate from the kinematic yaw rate with an estimated steering gain
//!   and understeer term (`steer_gain`, `understeer_s2_per_m2`, one block, optional fit).
//!
//! A model no car has is refused too, naming the block: a pole in the right half-plane, on the
//! imaginary axis or decaying slower than [`MIN_POLE_DECAY_RATE_PER_S`] (the bound `catmodel
//! identify` fits under); a steady-state gain outside what the block's units allow
//! ([`SPEED_DC_GAIN_RANGE`], [`LATERAL_DC_GAIN_RANGE`], [`DX_DT_POSITION_DC_GAIN_MAX_PER_S`], and
//! for dx/dt from `v_m` +-2, from `phi` +-2 `max_speed_mps` per radian of lock); a `steer_gain`
//! outside [`STEER_GAIN_RANGE`] or giving a lock of [`MAX_LOCK_DEG`] or more.
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use catmodel::can::freshness::FreshnessConfig;
use catmodel::control::mpc::MpcConfig;
use catmodel::model::block::{MisoBlock, SsBlock};
use catmodel::model::dynamic::{DynamicParams, MIN_SPEED_MPS};
use catmodel::model::hybrid::HybridConfig;
use catmodel::model::predictor::DEFAULT_HORIZON;
use catmodel::model::tf::{ModelError, TransferFunction};
use catmodel::model::zoh::{self, DiscreteStateSpace};
use catmodel::node::drive::{mpc_tuning, Controller};
use catmodel::node::estimator::EstimatorConfig;
use catmodel::node::{NodeConfig, DXDT_DELAY_CAP, VELOCITY_DELAY_CAP};
use catmodel::vehicle::{Body, VehicleParams};
use serde::Deserialize;

pub mod bake;

/// Value of the `format` key this version reads and writes.
pub const FORMAT: &str = "catmodel-model-2";
/// Input names of the speed model (eq 5), in the node's order.
pub const SPEED_INPUTS: [&str; 1] = ["input_vel"];
/// Input names of the dx/dt model (eq 7), in the order of the node's `MisoBlock`.
pub const DX_DT_INPUTS: [&str; 4] = ["v_m", "x", "y", "phi"];
/// Input name of the lateral model: the kinematic yaw rate `v tan(g delta / (1 + K v^2)) / L`.
pub const LATERAL_INPUTS: [&str; 1] = ["yaw_rate_kinematic"];
/// Highest order of a block the node runs (its state-space blocks have 2 states; lower orders
/// are embedded exactly).
pub const NODE_MAX_ORDER: usize = 2;
/// GNSS receiver rates the node's lowpass and gap logic are designed for, Hz.
pub const GNSS_RATE_RANGE_HZ: (f64, f64) = (1.0, 100.0);

/// A model file that failed to load, with where and why.
#[derive(Debug, Clone, PartialEq)]
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
    /// The blocks, in the node's input order (whatever their order in the file).
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
    /// Measured-to-nominal steering angle ratio (1 = the nominal angle at 100 %).
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
    /// Sample time the delays are whole multiples of, s (the node's 0.02 s).
    pub sample_time_s: f64,
    /// The car (f64 as written; [`VehicleSection::params`]).
    pub vehicle: VehicleSection,
    /// The dynamic single-track model's parameters, if the car has them.
    pub dynamics: Option<DynamicsSection>,
    /// The bus inputs' timeouts and the GNSS receiver's address and gates.
    pub inputs: InputsSection,
    /// The controller that follows the planner's path.
    pub control: ControlSection,
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
    // Checked before the rest is read (`FormatOnly`), so that an old file gets a migration
    // message; kept here so that `deny_unknown_fields` knows the key.
    #[allow(dead_code)]
    format: String,
    name: String,
    #[serde(default)]
    description: String,
    sample_time_s: f64,
    vehicle: VehicleSection,
    dynamics: Option<DynamicsSection>,
    inputs: InputsSection,
    control: ControlSection,
    hybrid: HybridSection,
    speed: RawModel,
    dx_dt: RawModel,
    lateral: Option<RawLateral>,
}

/// Only the `format` key, read first so that an old file gets a migration message rather than
/// a list of missing keys.
#[derive(Deserialize)]
struct FormatOnly {
    format: Option<String>,
}

/// `[vehicle]`, as written in the file: everything the node needs to know about the car.
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
    /// GNSS antenna ahead of the rear axle, m.
    pub antenna_ahead_m: f64,
    /// GNSS antenna left of the centre line, m.
    #[serde(default)]
    pub antenna_left_m: f64,
    /// The GNSS receiver's fix rate, Hz.
    pub gnss_rate_hz: f64,
    /// Body width, m.
    pub width_m: f64,
    /// Body length, m.
    pub length_m: f64,
    /// Rear bumper behind the rear axle, m.
    pub rear_overhang_m: f64,
    /// Upper limit of plausible speeds, m/s (measured speeds are clamped to it).
    pub max_speed_mps: f64,
    /// Fastest steering change of the car's actuator, % per second.
    pub max_steer_rate_pct_per_s: f64,
    /// How far the steering trails a ramp command, s: the actuator's first-order lag plus the
    /// drive-by-wire's delay (`catmodel identify-steering` measures it). The MPC's steering
    /// command leads its plan by it (absent: 0.05 s is assumed, the CAT Vehicle's simulated
    /// actuator). A lag the node does not know costs the lane change at low speed
    /// (docs/controller.md, "A slow steering actuator").
    #[serde(default)]
    pub steer_lag_s: Option<f64>,
}

impl VehicleSection {
    /// The core's f32 steering geometry.
    pub fn params(&self) -> VehicleParams {
        VehicleParams {
            wheelbase_m: self.wheelbase_m as f32,
            track_m: self.track_m as f32,
            max_steer_rad: self.max_steer_deg.to_radians() as f32,
            understeer_s2_per_m2: self.understeer_s2_per_m2 as f32,
        }
    }

    /// The core's f32 body.
    pub fn body(&self) -> Body {
        Body {
            width_m: self.width_m as f32,
            length_m: self.length_m as f32,
            rear_overhang_m: self.rear_overhang_m as f32,
        }
    }

    /// Nominal centre-tyre angle from steering percent, rad (paper II-C), f64.
    pub fn steer_pct_to_rad(&self, pct: f64) -> f64 {
        pct.clamp(-100.0, 100.0) / 100.0 * self.max_steer_deg.to_radians()
    }
}

/// `[dynamics]`: the linear-tyre single-track model (see `catmodel::model::dynamic`).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DynamicsSection {
    /// Mass, kg.
    pub mass_kg: f64,
    /// Yaw moment of inertia, kg m^2.
    pub yaw_inertia_kg_m2: f64,
    /// Centre of gravity to the front axle, m.
    pub cg_to_front_m: f64,
    /// Centre of gravity to the rear axle, m.
    pub cg_to_rear_m: f64,
    /// Front axle cornering stiffness, N/rad.
    pub cornering_front_n_per_rad: f64,
    /// Rear axle cornering stiffness, N/rad.
    pub cornering_rear_n_per_rad: f64,
}

impl DynamicsSection {
    /// The core's f32 parameters.
    pub fn params(&self) -> DynamicParams {
        DynamicParams {
            mass_kg: self.mass_kg as f32,
            yaw_inertia_kg_m2: self.yaw_inertia_kg_m2 as f32,
            cg_to_front_m: self.cg_to_front_m as f32,
            cg_to_rear_m: self.cg_to_rear_m as f32,
            cornering_front_n_per_rad: self.cornering_front_n_per_rad as f32,
            cornering_rear_n_per_rad: self.cornering_rear_n_per_rad as f32,
            min_speed_mps: MIN_SPEED_MPS,
        }
    }
}

/// `[inputs]`: how the node treats its bus inputs.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InputsSection {
    /// STEERING_REPORT older than this is stale, s.
    pub steer_timeout_s: f64,
    /// SPEED_REPORT older than this is stale, s.
    pub speed_timeout_s: f64,
    /// PEDAL_REPORT older than this is stale, s.
    pub pedal_timeout_s: f64,
    /// NMEA 2000 source address of the GNSS receiver (0..251).
    pub gnss_source_address: u8,
    /// A fix farther than this from where the node expects the antenna is rejected, m: the
    /// most the node's gate allows; it learns a tighter one from the receiver's own fixes
    /// (5.1 times their median distance from there, at least 1 m: `node::gnss::GATE_MEDIANS`).
    pub gnss_gate_m: f64,
    /// GNSS silent this long: the position is no longer trusted, s.
    pub gnss_lost_s: f64,
}

impl InputsSection {
    /// GNSS is stale after 2.5 fix periods, and never sooner than 0.2 s (a short dropout of a
    /// fast receiver is dead-reckoned without a flag), s.
    pub fn gnss_timeout_s(gnss_rate_hz: f64) -> f64 {
        (2.5 / gnss_rate_hz).max(0.2)
    }

    /// Gate rejections in a row after which the fixes win: `gnss_lost_s` of fixes (at least
    /// 3), the longest outage dead reckoning bridges. Fixes the gate rejects are an outage to
    /// the estimate, and it treats them as one: a multipath burst shorter than that is bridged
    /// (a review's 30 m burst of 1 to 2 s was adopted after 1 s at every rate, 30 m off, and
    /// the true fixes rejected in turn when they came back, docs/findings.md); fixes that stay
    /// elsewhere for longer win, as the fixes after an outage do.
    pub fn gnss_reacquire_fixes(gnss_rate_hz: f64, gnss_lost_s: f64) -> u16 {
        (gnss_rate_hz * gnss_lost_s).round().clamp(3.0, 60_000.0) as u16
    }
}

/// `[control]`: the controller that follows the planner's path.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControlSection {
    /// `"mpc"` (model-predictive control over the identified models) or `"pure-pursuit"`
    /// (the reference controller).
    pub controller: ControllerName,
    /// Bound on the error of the node's position estimate with this car's receiver (2 sigma),
    /// m: the controller inflates obstacles by it.
    pub position_uncertainty_m: f64,
    /// The MPC's weight on the lateral offset from the planner's path, per m^2, for every path
    /// (absent: the built-in tuning's, 10, tuned on the CAT Vehicle, and 1 on a path that asks
    /// for most of the car's lock: `MpcTuning::line_rule`, docs/controller.md).
    #[serde(default)]
    pub mpc_lateral_weight_per_m2: Option<f64>,
}

/// The controller's name in the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ControllerName {
    /// Model-predictive control.
    Mpc,
    /// Pure pursuit + PI.
    PurePursuit,
}

impl ControllerName {
    /// As written in the file.
    pub fn as_str(self) -> &'static str {
        match self {
            ControllerName::Mpc => "mpc",
            ControllerName::PurePursuit => "pure-pursuit",
        }
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
        ModelError::DelayTooLong {
            delay_samples,
            capacity,
        } => format!(
            "delay of {delay_samples} samples is beyond the {capacity} samples the node's delay line holds"
        ),
        ModelError::NoEquilibrium => {
            "the model has a pole at s = 0 (no finite DC gain): the node cannot start it at the measured speed".into()
        }
        ModelError::NumericalFailure => {
            "the discretization is not finite (coefficients too large)".into()
        }
        other => format!("{other:?}"),
    }
}

fn err(path: &Path, message: String) -> ModelFileError {
    ModelFileError {
        path: path.to_path_buf(),
        message,
    }
}

/// Checks of single values, each naming its key.
struct Checker<'a> {
    path: &'a Path,
}

impl Checker<'_> {
    fn positive(&self, key: &str, v: f64) -> Result<(), ModelFileError> {
        if v.is_finite() && v > 0.0 {
            Ok(())
        } else {
            Err(err(
                self.path,
                format!("{key} = {v}: must be a finite number > 0"),
            ))
        }
    }

    fn non_negative(&self, key: &str, v: f64) -> Result<(), ModelFileError> {
        if v.is_finite() && v >= 0.0 {
            Ok(())
        } else {
            Err(err(
                self.path,
                format!("{key} = {v}: must be a finite number >= 0"),
            ))
        }
    }

    fn finite(&self, key: &str, v: f64) -> Result<(), ModelFileError> {
        if v.is_finite() {
            Ok(())
        } else {
            Err(err(self.path, format!("{key} = {v}: must be finite")))
        }
    }

    fn within(&self, key: &str, v: f64, lo: f64, hi: f64, why: &str) -> Result<(), ModelFileError> {
        if v.is_finite() && (lo..=hi).contains(&v) {
            Ok(())
        } else {
            Err(err(
                self.path,
                format!("{key} = {v}: must be within {lo}..{hi} ({why})"),
            ))
        }
    }
}

/// The blocks of a model, matched to the node's inputs by name.
fn convert_model(
    path: &Path,
    key: &str,
    raw: RawModel,
    inputs: &[&str],
    ts: f64,
    vehicle: &VehicleSection,
) -> Result<Model, ModelFileError> {
    let mut slots: Vec<Option<Block>> = vec![None; inputs.len()];
    for (i, b) in raw.blocks.into_iter().enumerate() {
        let bkey = format!("{key}.blocks[{i}]");
        let Some(slot) = inputs.iter().position(|want| *want == b.input) else {
            return Err(err(
                path,
                format!(
                    "{bkey}.input = {:?}: not an input of this model (its inputs: {})",
                    b.input,
                    inputs.join(", ")
                ),
            ));
        };
        let tf = TransferFunction::new(&b.num, &b.den, b.delay_s)
            .map_err(|e| err(path, format!("{bkey}: {}", describe_model_error(&e))))?;
        zoh::delay_samples(b.delay_s, ts).map_err(|e| {
            err(
                path,
                format!("{bkey}.delay_s: {}", describe_model_error(&e)),
            )
        })?;
        if tf.order() > NODE_MAX_ORDER {
            return Err(err(
                path,
                format!(
                    "{bkey}: order {} is above the {NODE_MAX_ORDER} the node runs",
                    tf.order()
                ),
            ));
        }
        let Some(target) = slots.get_mut(slot) else {
            continue;
        };
        if target.is_some() {
            return Err(err(
                path,
                format!(
                    "{bkey}.input = {:?}: a second block for this input",
                    b.input
                ),
            ));
        }
        // Stability, then the steady-state gain its units allow (both named by input).
        let nkey = format!("{key}.blocks[{}]", b.input);
        if let Some(why) = pole_problem(tf.denominator()) {
            return Err(err(path, format!("{nkey}: {why}")));
        }
        if let (Some((lo, hi, what)), Ok(gain)) =
            (dc_gain_bounds(key, &b.input, vehicle), tf.dc_gain())
        {
            if !(lo..=hi).contains(&gain) {
                return Err(err(
                    path,
                    format!(
                        "{nkey}: DC gain {} is outside {}..{} ({what})",
                        sig(gain),
                        sig(lo),
                        sig(hi)
                    ),
                ));
            }
        }
        *target = Some(Block {
            input: b.input,
            input_unit: b.input_unit,
            tf,
        });
    }
    let mut blocks = Vec::with_capacity(inputs.len());
    for (slot, want) in slots.into_iter().zip(inputs) {
        match slot {
            Some(b) => blocks.push(b),
            None => {
                return Err(err(
                    path,
                    format!(
                        "{key}.blocks: no block for input {want:?} (its inputs: {})",
                        inputs.join(", ")
                    ),
                ))
            }
        }
    }
    Ok(Model {
        equation: raw.equation,
        output: raw.output,
        output_unit: raw.output_unit,
        blocks,
        fit: raw.fit,
    })
}

/// Parses and validates a model file's text; `path` only names it in errors. A file that parses
/// is one the node runs ([`ModelFile::node_config`] succeeds).
pub fn parse(text: &str, path: &Path) -> Result<ModelFile, ModelFileError> {
    // Recorders and editors add a byte-order mark; TOML does not allow one.
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let format: FormatOnly = toml::from_str(text).map_err(|e| {
        err(
            path,
            format!("not a valid model file: {}", toml_message(text, &e)),
        )
    })?;
    match format.format.as_deref() {
        Some(FORMAT) => {}
        Some("catmodel-model-1") => {
            return Err(err(
                path,
                format!(
                    "format = \"catmodel-model-1\": written by an older catmodel; this one reads {FORMAT:?}, \
                     which describes the whole car: add to [vehicle] antenna_ahead_m, gnss_rate_hz, width_m, \
                     length_m, rear_overhang_m, max_speed_mps, max_steer_rate_pct_per_s, add an [inputs] table, \
                     optionally [dynamics], and set format = {FORMAT:?} (models/paper.toml shows every key)"
                ),
            ))
        }
        Some(other) => {
            return Err(err(
                path,
                format!("format = {other:?}: this catmodel reads {FORMAT:?}"),
            ))
        }
        None => return Err(err(path, format!("missing key `format` (expected {FORMAT:?})"))),
    }
    let raw: RawFile = toml::from_str(text).map_err(|e| err(path, toml_message(text, &e)))?;
    let check = Checker { path };
    let ts = raw.sample_time_s;
    let node_ts = catmodel::SAMPLE_PERIOD_S_F64;
    if !(ts.is_finite() && (ts - node_ts).abs() <= 1e-12) {
        return Err(err(
            path,
            format!(
                "sample_time_s = {ts}: the node runs every {node_ts} s; models must be identified and discretized at that period"
            ),
        ));
    }
    let v = &raw.vehicle;
    check.positive("vehicle.wheelbase_m", v.wheelbase_m)?;
    check.positive("vehicle.track_m", v.track_m)?;
    check.positive("vehicle.max_steer_deg", v.max_steer_deg)?;
    if v.max_steer_deg >= 90.0 {
        return Err(err(
            path,
            format!(
                "vehicle.max_steer_deg = {}: must be below 90",
                v.max_steer_deg
            ),
        ));
    }
    check.non_negative("vehicle.understeer_s2_per_m2", v.understeer_s2_per_m2)?;
    check.finite("vehicle.antenna_ahead_m", v.antenna_ahead_m)?;
    check.finite("vehicle.antenna_left_m", v.antenna_left_m)?;
    check.within(
        "vehicle.gnss_rate_hz",
        v.gnss_rate_hz,
        GNSS_RATE_RANGE_HZ.0,
        GNSS_RATE_RANGE_HZ.1,
        "the receiver rates the node's lowpass and gap logic are designed for",
    )?;
    check.positive("vehicle.width_m", v.width_m)?;
    check.positive("vehicle.length_m", v.length_m)?;
    check.non_negative("vehicle.rear_overhang_m", v.rear_overhang_m)?;
    if v.rear_overhang_m + v.wheelbase_m > v.length_m {
        return Err(err(
            path,
            format!(
                "vehicle.length_m = {}: shorter than rear_overhang_m + wheelbase_m = {}",
                v.length_m,
                v.rear_overhang_m + v.wheelbase_m
            ),
        ));
    }
    check.positive("vehicle.max_speed_mps", v.max_speed_mps)?;
    check.positive(
        "vehicle.max_steer_rate_pct_per_s",
        v.max_steer_rate_pct_per_s,
    )?;
    if let Some(lag) = v.steer_lag_s {
        if !(lag.is_finite() && (STEER_LAG_RANGE_S.0..=STEER_LAG_RANGE_S.1).contains(&lag)) {
            return Err(err(
                path,
                format!(
                    "vehicle.steer_lag_s = {lag}: must be within {}..{} s (how far the steering trails a ramp command)",
                    STEER_LAG_RANGE_S.0, STEER_LAG_RANGE_S.1
                ),
            ));
        }
    }
    if let Some(d) = &raw.dynamics {
        check.positive("dynamics.mass_kg", d.mass_kg)?;
        check.positive("dynamics.yaw_inertia_kg_m2", d.yaw_inertia_kg_m2)?;
        check.positive("dynamics.cg_to_front_m", d.cg_to_front_m)?;
        check.positive("dynamics.cg_to_rear_m", d.cg_to_rear_m)?;
        check.positive(
            "dynamics.cornering_front_n_per_rad",
            d.cornering_front_n_per_rad,
        )?;
        check.positive(
            "dynamics.cornering_rear_n_per_rad",
            d.cornering_rear_n_per_rad,
        )?;
        let l = d.cg_to_front_m + d.cg_to_rear_m;
        if (l - v.wheelbase_m).abs() > 0.01 {
            return Err(err(
                path,
                format!(
                    "dynamics: cg_to_front_m + cg_to_rear_m = {l} m differs from vehicle.wheelbase_m = {} m by more than 1 cm",
                    v.wheelbase_m
                ),
            ));
        }
    }
    let i = &raw.inputs;
    check.positive("inputs.steer_timeout_s", i.steer_timeout_s)?;
    check.positive("inputs.speed_timeout_s", i.speed_timeout_s)?;
    check.positive("inputs.pedal_timeout_s", i.pedal_timeout_s)?;
    if i.gnss_source_address > 251 {
        return Err(err(
            path,
            format!(
                "inputs.gnss_source_address = {}: NMEA 2000 source addresses are 0..251",
                i.gnss_source_address
            ),
        ));
    }
    check.positive("inputs.gnss_gate_m", i.gnss_gate_m)?;
    let gnss_timeout_s = InputsSection::gnss_timeout_s(v.gnss_rate_hz);
    if !(i.gnss_lost_s.is_finite() && i.gnss_lost_s > gnss_timeout_s) {
        return Err(err(
            path,
            format!(
                "inputs.gnss_lost_s = {}: must be longer than the GNSS timeout ({gnss_timeout_s} s at {} Hz)",
                i.gnss_lost_s, v.gnss_rate_hz
            ),
        ));
    }
    for (key, val) in [
        ("inputs.steer_timeout_s", i.steer_timeout_s),
        ("inputs.speed_timeout_s", i.speed_timeout_s),
        ("inputs.pedal_timeout_s", i.pedal_timeout_s),
        ("inputs.gnss_lost_s", i.gnss_lost_s),
    ] {
        if val > 60.0 {
            return Err(err(
                path,
                format!("{key} = {val}: above 60 s, an input that old is not a measurement"),
            ));
        }
    }
    let c = &raw.control;
    if !(c.position_uncertainty_m.is_finite() && (0.0..=20.0).contains(&c.position_uncertainty_m)) {
        return Err(err(
            path,
            format!(
                "control.position_uncertainty_m = {}: must be within 0..20 m",
                c.position_uncertainty_m
            ),
        ));
    }
    if let Some(w) = c.mpc_lateral_weight_per_m2 {
        if !(w.is_finite()
            && (MPC_LATERAL_WEIGHT_RANGE.0..=MPC_LATERAL_WEIGHT_RANGE.1).contains(&w))
        {
            return Err(err(
                path,
                format!(
                    "control.mpc_lateral_weight_per_m2 = {w}: must be within {}..{} (the heading weight is 10, the steering's 1)",
                    MPC_LATERAL_WEIGHT_RANGE.0, MPC_LATERAL_WEIGHT_RANGE.1
                ),
            ));
        }
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
        check.positive(key, val)?;
    }
    if h.exit_dynamic_speed_mps > h.enter_dynamic_speed_mps
        || h.exit_dynamic_lat_accel_mps2 > h.enter_dynamic_lat_accel_mps2
    {
        return Err(err(
            path,
            "hybrid: exit thresholds must not exceed enter thresholds (hysteresis)".into(),
        ));
    }
    let speed = convert_model(path, "speed", raw.speed, &SPEED_INPUTS, ts, &raw.vehicle)?;
    let dx_dt = convert_model(path, "dx_dt", raw.dx_dt, &DX_DT_INPUTS, ts, &raw.vehicle)?;
    let lateral = match raw.lateral {
        None => None,
        Some(l) => {
            if let Some(why) = steer_gain_problem(raw.vehicle.max_steer_deg, l.steer_gain) {
                return Err(err(path, why));
            }
            check.non_negative("lateral.understeer_s2_per_m2", l.understeer_s2_per_m2)?;
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
                &raw.vehicle,
            )?;
            Some(Lateral {
                steer_gain: l.steer_gain,
                understeer_s2_per_m2: l.understeer_s2_per_m2,
                model,
            })
        }
    };
    let file = ModelFile {
        name: raw.name,
        description: raw.description,
        sample_time_s: ts,
        vehicle: raw.vehicle,
        dynamics: raw.dynamics,
        inputs: raw.inputs,
        control: raw.control,
        hybrid: raw.hybrid,
        speed,
        dx_dt,
        lateral,
    };
    file.build_node_config(path)?;
    Ok(file)
}

/// The `toml` crate's message on one line, with the line and column it points at (the crate's
/// own rendering spans several lines, with a caret drawing).
fn toml_message(text: &str, e: &toml::de::Error) -> String {
    let what = e.message().trim().replace('\n', ", ");
    match e.span().map(|s| s.start) {
        Some(at) => {
            let before = text.get(..at).unwrap_or(text);
            let line = before.matches('\n').count() + 1;
            let column = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
            format!("line {line}, column {column}: {what}")
        }
        None => what,
    }
}

/// An f64 ZOH discretization with `n < N` states embedded in `N` exactly: the extra states
/// start at zero and stay there (zero rows and columns).
fn embed<const N: usize, const CAP: usize>(
    dss: &DiscreteStateSpace,
) -> Result<SsBlock<N, CAP>, ModelError> {
    let mut padded = *dss;
    if padded.n < N {
        padded.n = N;
    }
    SsBlock::from_discrete(&padded)
}

impl ModelFile {
    /// The node's configuration for this car: the models discretized (ZOH, f64) and rounded to
    /// f32, the GNSS lowpass designed for the receiver's rate, the timeouts. The firmware build
    /// bakes exactly this ([`bake`]); `replay --model` runs exactly this.
    pub fn node_config(&self) -> NodeConfig {
        // Note: `parse` built it once already, so this cannot fail for a loaded file.
        self.build_node_config(Path::new("<model>"))
            .unwrap_or_else(|e| unreachable!("a loaded model file builds: {e}"))
    }

    fn build_node_config(&self, path: &Path) -> Result<NodeConfig, ModelFileError> {
        let ts = self.sample_time_s;
        let block_err =
            |key: &str, e: ModelError| err(path, format!("{key}: {}", describe_model_error(&e)));
        let velocity_tf = self
            .speed
            .blocks
            .first()
            .map(|b| b.tf)
            .ok_or_else(|| err(path, "speed.blocks: empty".into()))?;
        let velocity: SsBlock<2, VELOCITY_DELAY_CAP> = zoh::discretize(&velocity_tf, ts)
            .and_then(|d| embed(&d))
            .map_err(|e| block_err("speed.blocks[input_vel]", e))?;
        velocity
            .dc_gain()
            .filter(|g| *g != 0.0)
            .ok_or_else(|| block_err("speed.blocks[input_vel]", ModelError::NoEquilibrium))?;
        let mut dxdt_blocks = [SsBlock::<2, DXDT_DELAY_CAP>::zeroed(); 4];
        for (slot, b) in dxdt_blocks.iter_mut().zip(&self.dx_dt.blocks) {
            *slot = zoh::discretize(&b.tf, ts)
                .and_then(|d| embed(&d))
                .map_err(|e| block_err(&format!("dx_dt.blocks[{}]", b.input), e))?;
        }
        let dxdt = MisoBlock::from_blocks(dxdt_blocks);
        let v = &self.vehicle;
        let mut vehicle = v.params();
        if let Some(lateral) = &self.lateral {
            vehicle.max_steer_rad = (v.max_steer_deg.to_radians() * lateral.steer_gain) as f32;
            vehicle.understeer_s2_per_m2 = lateral.understeer_s2_per_m2 as f32;
        }
        let estimator = EstimatorConfig::design(
            v.gnss_rate_hz,
            v.antenna_ahead_m as f32,
            v.antenna_left_m as f32,
        )
        .map_err(|e| {
            err(
                path,
                format!(
                    "vehicle.gnss_rate_hz = {}: no GNSS lowpass for this rate ({e:?})",
                    v.gnss_rate_hz
                ),
            )
        })?;
        let micros = |s: f64| (s * 1e6).round() as u64;
        let i = &self.inputs;
        let mut horizon = DEFAULT_HORIZON;
        horizon.max_speed_mps = v.max_speed_mps as f32;
        Ok(NodeConfig {
            vehicle,
            body: v.body(),
            dynamics: self.dynamics.map(|d| d.params()),
            hybrid: self.hybrid.config(),
            horizon,
            estimator,
            velocity,
            dxdt,
            gnss_source: i.gnss_source_address,
            origin_e7: None,
            freshness: FreshnessConfig {
                timeout_us: [
                    micros(i.steer_timeout_s),
                    micros(i.speed_timeout_s),
                    micros(i.pedal_timeout_s),
                    micros(InputsSection::gnss_timeout_s(v.gnss_rate_hz)),
                ],
            },
            gnss_lost_us: micros(i.gnss_lost_s),
            gnss_gate_m: i.gnss_gate_m as f32,
            gnss_reacquire_fixes: InputsSection::gnss_reacquire_fixes(
                v.gnss_rate_hz,
                i.gnss_lost_s,
            ),
            max_speed_mps: v.max_speed_mps as f32,
            max_steer_rate_pct_per_s: v.max_steer_rate_pct_per_s as f32,
            steer_lag_s: v.steer_lag_s.map(|lag| lag as f32),
            controller: match self.control.controller {
                ControllerName::Mpc => Controller::Mpc,
                ControllerName::PurePursuit => Controller::PurePursuit,
            },
            position_uncertainty_m: self.control.position_uncertainty_m as f32,
            mpc_lateral_weight_per_m2: self.control.mpc_lateral_weight_per_m2.map(|w| w as f32),
        })
        .and_then(|config| {
            // The controller must be buildable for this car, or the node could not drive it.
            if config.controller == Controller::Mpc {
                MpcConfig::for_node(&config, mpc_tuning(&config)).map_err(|e| {
                    err(
                        path,
                        format!(
                            "control: the model-predictive controller cannot run this car: {e:?}"
                        ),
                    )
                })?;
            }
            Ok(config)
        })
    }
}

/// Accepted range of `[vehicle] steer_lag_s`, s: the MPC's lead (the lag plus a tick) stays
/// within `catmodel::control::mpc::MAX_STEER_LEAD_S`.
pub const STEER_LAG_RANGE_S: (f64, f64) = (0.0, 0.25);

/// Accepted range of `[control] mpc_lateral_weight_per_m2`.
pub const MPC_LATERAL_WEIGHT_RANGE: (f64, f64) = (0.1, 100.0);

/// Slowest pole a model may have, 1/s: every pole's real part must be below
/// `-MIN_POLE_DECAY_RATE_PER_S` (a time constant under 10 s). `catmodel identify` fits under the
/// same bound (`identify::oe::MIN_DECAY_RATE_PER_S` is this constant): a slower pole cannot be
/// told from a drift in one-minute experiments, and is an integrator in all but name (the node
/// starts its blocks at equilibrium, which such a block hardly has). Poles in the right
/// half-plane or on the imaginary axis are refused for the same reason, more so.
pub const MIN_POLE_DECAY_RATE_PER_S: f64 = 0.1;

/// Accepted steady-state gain of the speed block (eq 5), m/s per commanded m/s: the car's
/// internal controller settles near the speed it is asked for (every file here: 0.99..1.02); a
/// car that settles at half or twice the commanded speed has no speed controller the node can
/// model.
pub const SPEED_DC_GAIN_RANGE: (f64, f64) = (0.5, 2.0);

/// Accepted steady-state gain of the lateral block, rad/s of yaw rate per rad/s of kinematic yaw
/// rate: the steering gain and the understeer term already carry the steady state (every
/// identified file: 0.99..1.01).
pub const LATERAL_DC_GAIN_RANGE: (f64, f64) = (0.5, 2.0);

/// Largest |steady-state gain| of the dx/dt blocks of the positions `x` and `y`, m/s per m
/// (1/s). dx/dt does not depend on where the car is, and the position blocks only soak up what
/// the other inputs miss: the paper's `x` block has 0.108, identified files below 0.002. At
/// 1 1/s a car 60 m further east would be predicted 60 m/s faster, a car's top speed.
pub const DX_DT_POSITION_DC_GAIN_MAX_PER_S: f64 = 1.0;

/// Accepted range of `[lateral] steer_gain` (the measured centre-tyre angle over the nominal
/// one): `catmodel identify` refuses an estimate outside it as implausible.
pub const STEER_GAIN_RANGE: (f64, f64) = (0.1, 10.0);

/// The lock a steering gain gives, `max_steer_deg * steer_gain`, must stay below this, degrees:
/// the same bound as `vehicle.max_steer_deg` (a wheel at 90 degrees rolls sideways, and eq 2's
/// `tan` has no value there).
pub const MAX_LOCK_DEG: f64 = 90.0;

/// A number with 4 significant digits, for messages (`0.25`, `-5e-7`, `1.329e30`).
fn sig(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    if !v.is_finite() {
        return format!("{v}");
    }
    let mag = v.abs().log10().floor();
    if (-3.0..5.0).contains(&mag) {
        let decimals = (3.0 - mag).max(0.0) as usize;
        let s = format!("{v:.decimals$}");
        let s = if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        };
        s
    } else {
        let s = format!("{v:.3e}");
        // 1.330e30 -> 1.33e30
        match s.split_once('e') {
            Some((m, e)) if m.contains('.') => {
                format!("{}e{e}", m.trim_end_matches('0').trim_end_matches('.'))
            }
            _ => s,
        }
    }
}

/// The poles of `den(s)` (descending powers of `s`, `den[0] != 0`) as `(re, im)`, for the orders
/// the node runs (0 to 2); `None` above. Real roots by the cancellation-free quadratic formula.
pub fn poles(den: &[f64]) -> Option<Vec<(f64, f64)>> {
    let a0 = *den.first()?;
    match den {
        [_] => Some(Vec::new()),
        [_, a1] => Some(vec![(-a1 / a0, 0.0)]),
        [_, a1, a2] => {
            let (b, c) = (a1 / a0, a2 / a0);
            let disc = b * b - 4.0 * c;
            if disc < 0.0 {
                let im = (-disc).sqrt() / 2.0;
                Some(vec![(-b / 2.0, im), (-b / 2.0, -im)])
            } else {
                let q = -(b + b.signum() * disc.sqrt()) / 2.0;
                let r2 = if q == 0.0 { 0.0 } else { c / q };
                Some(vec![(q, 0.0), (r2, 0.0)])
            }
        }
        _ => None,
    }
}

/// Why a block's denominator is refused, if it is: a pole in the right half-plane, on the
/// imaginary axis, or decaying slower than [`MIN_POLE_DECAY_RATE_PER_S`]; the message names the
/// slowest pole. Orders above 2 are not looked at (refused before, by order).
pub fn pole_problem(den: &[f64]) -> Option<String> {
    let poles = poles(den)?;
    let &(re, im) = poles.iter().max_by(|a, b| a.0.total_cmp(&b.0))?;
    let at = if im == 0.0 {
        sig(re)
    } else {
        format!("{} +/- {}j", sig(re), sig(im.abs()))
    };
    if re == 0.0 && im == 0.0 {
        Some(describe_model_error(&ModelError::NoEquilibrium))
    } else if re > 0.0 {
        Some(format!(
            "pole at s = {at} in the right half-plane: the model is unstable (its output grows without bound)"
        ))
    } else if re == 0.0 {
        Some(format!(
            "pole at s = {at} on the imaginary axis: the model oscillates for ever"
        ))
    } else if -re < MIN_POLE_DECAY_RATE_PER_S * (1.0 - 1e-9) {
        // The tolerance: `identify` fits on the bound (its constraint is strict, the pole sits
        // on it to rounding).
        Some(format!(
            "pole at s = {at} decays slower than {MIN_POLE_DECAY_RATE_PER_S} 1/s (time constant {} s, above 10 s): \
             an integrator in all but name, which `catmodel identify` never fits",
            sig(-1.0 / re)
        ))
    } else {
        None
    }
}

/// The steady-state gain a block may have, from its units: `(low, high, what)`.
fn dc_gain_bounds(key: &str, input: &str, v: &VehicleSection) -> Option<(f64, f64, String)> {
    match (key, input) {
        ("speed", _) => Some((
            SPEED_DC_GAIN_RANGE.0,
            SPEED_DC_GAIN_RANGE.1,
            "m/s per commanded m/s: the car's speed controller settles near the commanded speed".into(),
        )),
        ("lateral", _) => Some((
            LATERAL_DC_GAIN_RANGE.0,
            LATERAL_DC_GAIN_RANGE.1,
            "yaw rate per kinematic yaw rate: the steering gain and understeer carry the steady state".into(),
        )),
        ("dx_dt", "v_m") => Some((
            -2.0,
            2.0,
            "m/s per m/s: dx/dt stays within +-max_speed_mps, so from standstill to max_speed_mps \
             the block cannot move it by more than 2 max_speed_mps"
                .into(),
        )),
        ("dx_dt", "phi") => {
            let m = 2.0 * v.max_speed_mps / v.max_steer_deg.to_radians();
            Some((
                -m,
                m,
                format!(
                    "m/s per rad: dx/dt stays within +-max_speed_mps, so from straight ahead to the \
                     {} deg lock the block cannot move it by more than 2 max_speed_mps",
                    v.max_steer_deg
                ),
            ))
        }
        ("dx_dt", "x" | "y") => Some((
            -DX_DT_POSITION_DC_GAIN_MAX_PER_S,
            DX_DT_POSITION_DC_GAIN_MAX_PER_S,
            "m/s per m: dx/dt does not depend on where the car is; at 1 a car 60 m further \
             east would be predicted 60 m/s faster"
                .into(),
        )),
        _ => None,
    }
}

/// Why a steering gain is refused, if it is: outside [`STEER_GAIN_RANGE`], or a lock
/// (`max_steer_deg * steer_gain`) of [`MAX_LOCK_DEG`] or more. `catmodel identify` applies it to
/// its estimate.
pub fn steer_gain_problem(max_steer_deg: f64, steer_gain: f64) -> Option<String> {
    let lock = max_steer_deg * steer_gain;
    let (lo, hi) = STEER_GAIN_RANGE;
    if steer_gain.is_finite() && (lo..=hi).contains(&steer_gain) && lock < MAX_LOCK_DEG {
        None
    } else {
        Some(format!(
            "lateral.steer_gain = {steer_gain}: the lock would be max_steer_deg {max_steer_deg} x {} = {} deg; \
             the gain (measured over nominal steering angle) must be within {lo}..{hi} and the lock below {MAX_LOCK_DEG} deg",
            sig(steer_gain),
            sig(lock)
        ))
    }
}

/// Reads and validates a model file.
pub fn load(path: &Path) -> Result<ModelFile, ModelFileError> {
    let text = std::fs::read_to_string(path).map_err(|e| err(path, format!("reading: {e}")))?;
    parse(&text, path)
}

/// The published model file (`models/paper.toml` of this repository), loaded.
pub fn paper() -> ModelFile {
    // Note: the repository's own file; a test loads it, so this cannot fail in a build of it.
    load(&paper_path()).unwrap_or_else(|e| panic!("models/paper.toml: {e}"))
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
    let rows = [
        ("wheelbase_m", v.wheelbase_m, "L"),
        ("track_m", v.track_m, "T (tread), eq 3-4"),
        (
            "max_steer_deg",
            v.max_steer_deg,
            "centre-tyre angle at 100 % steering",
        ),
        (
            "understeer_s2_per_m2",
            v.understeer_s2_per_m2,
            "K of eq 2: R = L / tan(delta / (1 + K v^2))",
        ),
        (
            "antenna_ahead_m",
            v.antenna_ahead_m,
            "GNSS antenna ahead of the rear axle",
        ),
        (
            "antenna_left_m",
            v.antenna_left_m,
            "GNSS antenna left of the centre line",
        ),
        (
            "gnss_rate_hz",
            v.gnss_rate_hz,
            "the receiver's fix rate (1..100)",
        ),
        ("width_m", v.width_m, "body width"),
        ("length_m", v.length_m, "body length"),
        (
            "rear_overhang_m",
            v.rear_overhang_m,
            "rear bumper behind the rear axle",
        ),
        (
            "max_speed_mps",
            v.max_speed_mps,
            "speeds are clamped to [0, this]",
        ),
        (
            "max_steer_rate_pct_per_s",
            v.max_steer_rate_pct_per_s,
            "fastest steering change of the actuator",
        ),
    ];
    for (key, value, comment) in rows {
        let _ = writeln!(o, "{key} = {}  # {comment}", num(value));
    }
    if let Some(lag) = v.steer_lag_s {
        let _ = writeln!(
            o,
            "steer_lag_s = {}  # how far the steering trails a ramp command (identify-steering): the MPC's command leads its plan by it",
            num(lag)
        );
    }
    if let Some(d) = &f.dynamics {
        let _ = writeln!(o, "\n[dynamics]");
        let _ = writeln!(
            o,
            "# linear-tyre single-track model of the dynamic (high-speed) mode"
        );
        let rows = [
            ("mass_kg", d.mass_kg),
            ("yaw_inertia_kg_m2", d.yaw_inertia_kg_m2),
            ("cg_to_front_m", d.cg_to_front_m),
            ("cg_to_rear_m", d.cg_to_rear_m),
            ("cornering_front_n_per_rad", d.cornering_front_n_per_rad),
            ("cornering_rear_n_per_rad", d.cornering_rear_n_per_rad),
        ];
        for (key, value) in rows {
            let _ = writeln!(o, "{key} = {}", num(value));
        }
    }
    let i = &f.inputs;
    let _ = writeln!(o, "\n[inputs]");
    let _ = writeln!(
        o,
        "# an input older than its timeout is stale; GNSS's follows gnss_rate_hz"
    );
    let rows = [
        ("steer_timeout_s", i.steer_timeout_s),
        ("speed_timeout_s", i.speed_timeout_s),
        ("pedal_timeout_s", i.pedal_timeout_s),
    ];
    for (key, value) in rows {
        let _ = writeln!(o, "{key} = {}", num(value));
    }
    let _ = writeln!(o, "gnss_source_address = {}", i.gnss_source_address);
    let _ = writeln!(o, "gnss_gate_m = {}", num(i.gnss_gate_m));
    let _ = writeln!(o, "gnss_lost_s = {}", num(i.gnss_lost_s));
    let c = &f.control;
    let _ = writeln!(o, "\n[control]");
    let _ = writeln!(
        o,
        "# the controller that follows the planner's path: \"mpc\" or \"pure-pursuit\""
    );
    let _ = writeln!(o, "controller = {}", quoted(c.controller.as_str()));
    let _ = writeln!(
        o,
        "position_uncertainty_m = {}  # the position estimate's error bound (2 sigma): obstacles are inflated by it",
        num(c.position_uncertainty_m)
    );
    if let Some(w) = c.mpc_lateral_weight_per_m2 {
        let _ = writeln!(
            o,
            "mpc_lateral_weight_per_m2 = {}  # the MPC's weight on the offset from the planner's line (built-in: 10)",
            num(w)
        );
    }
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

/// Path of the published model file in this repository (tests, and the CLI's default).
pub fn paper_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("models")
        .join("paper.toml")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: (f64, f64), b: (f64, f64)) -> bool {
        (a.0 - b.0).abs() < 1e-12 && (a.1 - b.1).abs() < 1e-12
    }

    #[test]
    fn poles_of_dens_with_known_roots() {
        // (s + 1)(s + 2) = s^2 + 3 s + 2; scaled by 2 (den[0] need not be 1).
        let p = poles(&[2.0, 6.0, 4.0]).unwrap();
        assert!(
            close(p[0], (-2.0, 0.0)) && close(p[1], (-1.0, 0.0)),
            "{p:?}"
        );
        // (s + 1)^2 + 4 = s^2 + 2 s + 5: -1 +/- 2j.
        let p = poles(&[1.0, 2.0, 5.0]).unwrap();
        assert!(
            close(p[0], (-1.0, 2.0)) && close(p[1], (-1.0, -2.0)),
            "{p:?}"
        );
        // 4 s + 1: -0.25.
        assert_eq!(poles(&[4.0, 1.0]).unwrap(), vec![(-0.25, 0.0)]);
        // A constant: no pole; order 3: not the node's.
        assert_eq!(poles(&[3.0]).unwrap(), vec![]);
        assert_eq!(poles(&[1.0, 1.0, 1.0, 1.0]), None);
    }

    #[test]
    fn stability_check_by_hand() {
        // Stable and fast enough: (s + 1)(s + 2), the paper's eq 5 (-0.8145 +/- 0.298j).
        assert_eq!(pole_problem(&[1.0, 3.0, 2.0]), None);
        assert_eq!(pole_problem(&[1.0, 1.629, 0.7522]), None);
        // (s - 0.25)^2 + 0.55 / 4 = s^2 - 0.5 s + 0.2: 0.25 +/- 0.3708j, right half-plane.
        let why = pole_problem(&[1.0, -0.5, 0.2]).unwrap();
        assert!(
            why.starts_with("pole at s = 0.25 +/- 0.3708j in the right half-plane"),
            "{why}"
        );
        // (s - 1)^2: a double pole at 1.
        let why = pole_problem(&[1.0, -2.0, 1.0]).unwrap();
        assert!(
            why.starts_with("pole at s = 1 in the right half-plane"),
            "{why}"
        );
        // (s + 3)(s - 2) = s^2 + s - 6: one stable, one unstable pole; the unstable one named.
        let why = pole_problem(&[1.0, 1.0, -6.0]).unwrap();
        assert!(why.starts_with("pole at s = 2 in"), "{why}");
        // s^2 + 4: +/- 2j, on the axis.
        let why = pole_problem(&[1.0, 0.0, 4.0]).unwrap();
        assert!(
            why.starts_with("pole at s = 0 +/- 2j on the imaginary axis"),
            "{why}"
        );
        // s (s + 1.629): the integrator keeps its message.
        let why = pole_problem(&[1.0, 1.629, 0.0]).unwrap();
        assert!(why.starts_with("the model has a pole at s = 0"), "{why}");
        // (s + 0.05)(s + 1) = s^2 + 1.05 s + 0.05: 20 s time constant, too slow.
        let why = pole_problem(&[1.0, 1.05, 0.05]).unwrap();
        assert!(
            why.starts_with("pole at s = -0.05 decays slower than 0.1 1/s (time constant 20 s"),
            "{why}"
        );
        // s^2 + 1e-6 s + 1e-12: -5e-7 +/- 8.66e-7j (the review's near-integrator).
        let why = pole_problem(&[1.0, 1e-6, 1e-12]).unwrap();
        assert!(
            why.starts_with("pole at s = -5e-7 +/- 8.66e-7j decays"),
            "{why}"
        );
        // On the bound (s + 0.1)(s + 1) = s^2 + 1.1 s + 0.1 and a pair at -0.1 +/- 0.48j,
        // as `identify` leaves them: accepted.
        assert_eq!(pole_problem(&[1.0, 1.1, 0.1]), None);
        assert_eq!(pole_problem(&[1.0, 0.2, 0.2400]), None);
        // Just inside the bound: refused.
        assert!(pole_problem(&[1.0, 0.1999, 0.24]).is_some());
    }

    #[test]
    fn steering_gain_bounds_by_hand() {
        assert_eq!(steer_gain_problem(35.5, 1.0), None);
        assert_eq!(steer_gain_problem(35.5, 2.5), None); // 88.75 deg
        let why = steer_gain_problem(38.0, 50.98).unwrap();
        assert!(why.contains("= 1937 deg"), "{why}");
        assert!(steer_gain_problem(35.5, 2.6).is_some()); // 92.3 deg
        assert!(steer_gain_problem(35.5, 0.05).is_some());
        assert!(steer_gain_problem(35.5, f64::NAN).is_some());
    }

    #[test]
    fn numbers_in_messages() {
        assert_eq!(sig(0.25), "0.25");
        assert_eq!(sig(0.370809), "0.3708");
        assert_eq!(sig(1937.383), "1937");
        assert_eq!(sig(-5e-7), "-5e-7");
        assert_eq!(sig(1.3294e30), "1.329e30");
        assert_eq!(sig(20.0), "20");
        assert_eq!(sig(-96.84), "-96.84");
    }
}
