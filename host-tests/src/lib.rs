//! Shared helpers of the integration tests: loading committed reference values, comparing
//! numbers with stated tolerances, simulated drives as identification experiments.
use std::path::PathBuf;

use catmodel_host::identify::preprocess::{preprocess_rows, Experiment, PreprocessOptions};
use catmodel_host::model_file;
use catmodel_host::sim::{self, SimOptions};

pub mod bus;
pub mod mpc_sim;

/// Path of a file under `host-tests/reference/`.
pub fn reference_path(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("reference")
        .join(name)
}

/// Parsed JSON of a committed reference file.
pub fn load_reference(name: &str) -> serde_json::Value {
    let path = reference_path(name);
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("reading {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("parsing {}: {e}", path.display()))
}

/// `|a - b| <= atol + rtol * |b|`, numpy's `isclose`.
pub fn isclose(a: f64, b: f64, rtol: f64, atol: f64) -> bool {
    (a - b).abs() <= atol + rtol * b.abs()
}

/// Asserts `isclose` element-wise, naming the first offending index.
#[track_caller]
pub fn assert_allclose(actual: &[f64], expected: &[f64], rtol: f64, atol: f64, what: &str) {
    assert_eq!(actual.len(), expected.len(), "{what}: length");
    for (i, (a, b)) in actual.iter().zip(expected).enumerate() {
        assert!(
            isclose(*a, *b, rtol, atol),
            "{what}[{i}]: {a} vs reference {b} (rtol {rtol}, atol {atol})"
        );
    }
}

/// One drive of the built-in simulator (`scenario`, `seed`) on the plant `plant`, preprocessed
/// as `identify` does for the car file's `vehicle`, named `SCENARIO-SEED`.
pub fn sim_experiment_of(
    scenario: &str,
    seed: u64,
    plant: &sim::config::VehicleConfig,
    vehicle: &model_file::VehicleSection,
) -> Experiment {
    let base = sim::scenario::Scenario::builtin(scenario)
        .unwrap_or_else(|| panic!("no built-in scenario {scenario}"));
    let out = sim::simulate(
        &base,
        plant,
        &SimOptions {
            seed,
            ..SimOptions::default()
        },
    );
    preprocess_rows(
        &format!("{scenario}-{seed}"),
        &out.log,
        vehicle,
        &PreprocessOptions::default(),
    )
    .unwrap_or_else(|e| panic!("preprocessing {scenario}: {e:#}"))
}

/// One drive of the built-in simulator (`scenario`, `seed`) on the CAT Vehicle, preprocessed
/// as `identify` does, named `SCENARIO-SEED`.
pub fn sim_experiment(scenario: &str, seed: u64) -> Experiment {
    let out = sim::run_named(
        scenario,
        None,
        &SimOptions {
            seed,
            ..SimOptions::default()
        },
    )
    .unwrap_or_else(|e| panic!("simulating {scenario}: {e}"));
    let base = model_file::load(&model_file::paper_path()).expect("models/paper.toml");
    preprocess_rows(
        &format!("{scenario}-{seed}"),
        &out.log,
        &base.vehicle,
        &PreprocessOptions::default(),
    )
    .unwrap_or_else(|e| panic!("preprocessing {scenario}: {e:#}"))
}
