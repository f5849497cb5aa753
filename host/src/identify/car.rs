//! `identify --vehicle CAR.toml`: the car the logs come from, described by its owner, carried
//! into the model file that `identify` writes.
//!
//! A car file holds the model file's `[vehicle]` table (README, "Model file": geometry,
//! steering range, GNSS antenna position and receiver rate, body, limits), and optionally its
//! `[dynamics]` (the dynamic single-track model's mass, inertia, CG and cornering stiffnesses),
//! `[inputs]` (timeouts, the receiver's address and gates) and `[control]` (the controller, the
//! position estimate's error bound with this car's receiver) tables; nothing else. The
//! identified file takes `[vehicle]` from it, `[dynamics]` from it or none (another car's
//! masses and tyres would be wrong: without them the node stays on the kinematic model), and
//! `[inputs]` and `[control]` from it or from the base file. The result is
//! checked by the model file's own reader, so a car file is refused with the same message, key
//! by key, as a model file with the same table would be.
use std::path::Path;

use anyhow::{anyhow, Context, Result};
use serde::Deserialize;

use crate::model_file::{
    self, ControlSection, DynamicsSection, InputsSection, ModelFile, VehicleSection,
};

/// The tables a car file may hold.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CarFile {
    vehicle: VehicleSection,
    dynamics: Option<DynamicsSection>,
    inputs: Option<InputsSection>,
    control: Option<ControlSection>,
}

/// `base` with the car of the file at `path` (see the module doc); errors name the file.
pub fn apply(base: &ModelFile, path: &Path) -> Result<ModelFile> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
    let car: CarFile = toml::from_str(text).map_err(|e| {
        anyhow!(
            "{}: {} (a car file holds [vehicle] and optionally [dynamics], [inputs] and [control], with the model file's keys)",
            path.display(),
            e.message()
        )
    })?;
    let mut file = base.clone();
    file.vehicle = car.vehicle;
    file.dynamics = car.dynamics;
    if let Some(inputs) = car.inputs {
        file.inputs = inputs;
    }
    if let Some(control) = car.control {
        file.control = control;
    }
    // The model file's reader checks every key (ranges, the CG on the wheelbase, timeouts
    // against the receiver rate), on the file as it will be written.
    model_file::parse(&model_file::to_toml(&file), path).map_err(|e| anyhow!("{e}"))
}
