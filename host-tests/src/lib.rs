//! Shared helpers of the integration tests: loading committed reference values and comparing
//! numbers with stated tolerances.
use std::path::PathBuf;

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
