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
//! `[control]` from it or from the base file, and `[inputs]` key by key: a car file may set
//! only the keys its car needs (its receiver's source address, say), the others are the base
//! file's. One is derived: a car whose receiver is so slow that the base file's `gnss_lost_s`
//! is not longer than its GNSS timeout (a 1 Hz receiver: 2.5 s against the bundled file's
//! 2 s) gets twice its timeout, with a note, unless its file sets the key. The result is
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
    /// Any of `[inputs]`' keys, over the base file's.
    inputs: Option<toml::Table>,
    control: Option<ControlSection>,
}

/// A car file applied: the model file, and what was derived for the car, in words.
pub struct Applied {
    pub file: ModelFile,
    pub notes: Vec<String>,
}

/// `base` with the car of the file at `path` (see the module doc); errors name the file.
pub fn apply(base: &ModelFile, path: &Path) -> Result<Applied> {
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
    let mut notes = Vec::new();
    let rate_hz = car.vehicle.gnss_rate_hz;
    file.vehicle = car.vehicle;
    file.dynamics = car.dynamics;
    let own = car.inputs.unwrap_or_default();
    let sets_lost = own.contains_key("gnss_lost_s");
    file.inputs =
        inputs_over(&base.inputs, own).map_err(|e| anyhow!("{}: [inputs]: {e}", path.display()))?;
    if sets_lost {
        // Its own value, checked against its own receiver by the reader below.
    } else if let Some((was, now)) = file.inputs.outlast_gnss_timeout(rate_hz) {
        notes.push(format!(
            "{}: inputs.gnss_lost_s = {now} s, twice the GNSS timeout of a {rate_hz} Hz \
             receiver ({} s): the base file's {was} s is not longer than the timeout; set \
             gnss_lost_s in the car file's [inputs] for another bound on the outages dead \
             reckoning bridges",
            path.display(),
            InputsSection::gnss_timeout_s(rate_hz)
        ));
    }
    if let Some(control) = car.control {
        file.control = control;
    }
    // The model file's reader checks every key (ranges, the CG on the wheelbase, timeouts
    // against the receiver rate), on the file as it will be written.
    let file = model_file::parse(&model_file::to_toml(&file), path).map_err(|e| anyhow!("{e}"))?;
    Ok(Applied { file, notes })
}

/// `base`'s `[inputs]` with the keys of `own` in place of its own (unknown keys refused by
/// the model file's table).
fn inputs_over(base: &InputsSection, own: toml::Table) -> Result<InputsSection, String> {
    let mut table = toml::Table::try_from(base).map_err(|e| e.to_string())?;
    table.extend(own);
    table
        .try_into()
        .map_err(|e: toml::de::Error| e.message().to_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The Polo's car file with its receiver at `rate_hz` and `inputs` as its `[inputs]`
    /// table (none if empty), written under the target's temporary directory.
    fn polo(name: &str, rate_hz: f64, inputs: &str) -> std::path::PathBuf {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("vehicles");
        let text = std::fs::read_to_string(dir.join("vw-polo.car.toml")).unwrap();
        let text = text.replace(
            "gnss_rate_hz = 10.0",
            &format!("gnss_rate_hz = {rate_hz:?}"),
        );
        assert!(text.contains(&format!("gnss_rate_hz = {rate_hz:?}")));
        let text = if inputs.is_empty() {
            text
        } else {
            format!("{text}\n[inputs]\n{inputs}\n")
        };
        let path =
            std::env::temp_dir().join(format!("catmodel-car-{}-{name}.toml", std::process::id()));
        std::fs::write(&path, text).unwrap();
        path
    }

    #[test]
    fn an_inputs_table_may_set_single_keys_over_the_base() {
        let base = model_file::paper();
        let got = apply(&base, &polo("address", 10.0, "gnss_source_address = 7")).unwrap();
        let want = InputsSection {
            gnss_source_address: 7,
            ..base.inputs
        };
        assert_eq!(got.file.inputs, want);
        assert!(got.notes.is_empty(), "{:?}", got.notes);
        // A key the table does not have is refused by name.
        let e = apply(&base, &polo("unknown", 10.0, "gnss_gate = 3.0"))
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("[inputs]") && e.contains("gnss_gate"), "{e}");
        // A value out of range is refused by the model file's reader, key by key.
        let e = apply(&base, &polo("range", 10.0, "gnss_source_address = 252"))
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("gnss_source_address"), "{e}");
    }

    #[test]
    fn a_slow_receivers_car_outlasts_its_gnss_timeout() {
        // The bundled file's 2 s is shorter than a 1 Hz receiver's 2.5 s timeout: the car
        // file was refused for a key it never set.
        let base = model_file::paper();
        assert_eq!(base.inputs.gnss_lost_s, 2.0);
        let got = apply(&base, &polo("1hz", 1.0, "")).unwrap();
        assert_eq!(got.file.inputs.gnss_lost_s, 5.0);
        assert_eq!(got.notes.len(), 1, "{:?}", got.notes);
        assert!(
            got.notes[0].contains(
                "inputs.gnss_lost_s = 5 s, twice the GNSS timeout of a 1 Hz receiver (2.5 s)"
            ),
            "{:?}",
            got.notes
        );
        // Its own value stands, and is checked against its receiver.
        let got = apply(&base, &polo("1hz-own", 1.0, "gnss_lost_s = 4.0")).unwrap();
        assert_eq!((got.file.inputs.gnss_lost_s, got.notes.len()), (4.0, 0));
        let e = apply(&base, &polo("1hz-short", 1.0, "gnss_lost_s = 2.0"))
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("must be longer than the GNSS timeout"), "{e}");
        // A 5 Hz car keeps the base file's.
        let got = apply(&base, &polo("5hz", 5.0, "")).unwrap();
        assert_eq!((got.file.inputs.gnss_lost_s, got.notes.len()), (2.0, 0));
    }
}
