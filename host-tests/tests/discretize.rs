//! `catmodel discretize` against python-control: `control.c2d(ss(tf2ss(num, den)), ts, 'zoh')`
//! values committed in `reference/discretize_c2d.json` by `reference/gen_identify.py`.
//! Tolerance: rtol 1e-9, atol 1e-12 (scipy/python-control use a Padé expm, catmodel a
//! scaled Taylor series; both are accurate to ~1e-15 relative).

use catmodel::model::tf::TransferFunction;
use catmodel_host::identify::discretize::{discretize_file, discretize_tf, DiscreteBlock};
use catmodel_host::model_file;
use catmodel_host_tests::{assert_allclose, load_reference};

fn flat(m: &[Vec<f64>]) -> Vec<f64> {
    m.iter().flatten().copied().collect()
}

fn json_matrix(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .flat_map(|row| row.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()))
        .collect()
}

fn check(block: &DiscreteBlock, case: &serde_json::Value) {
    let what = format!("{} at ts {}", block.name, case["ts"]);
    for (key, mine) in [
        ("A", &block.a),
        ("B", &block.b),
        ("C", &block.c),
        ("D", &block.d),
    ] {
        assert_allclose(
            &flat(mine),
            &json_matrix(&case[key]),
            1e-9,
            1e-12,
            &format!("{what} {key}"),
        );
    }
    assert_eq!(
        block.delay_samples as u64,
        case["delay_samples"].as_u64().unwrap(),
        "{what}"
    );
    let n = block.a.len();
    assert!(block.a.iter().all(|r| r.len() == n) && block.b.len() == n && block.c[0].len() == n);
}

#[test]
fn paper_models_match_python_control() {
    let reference = load_reference("discretize_c2d.json");
    let file = model_file::load(&model_file::paper_path()).unwrap();
    let mut checked = 0;
    for case in reference["cases"].as_array().unwrap() {
        if case["group"] != "paper" {
            continue;
        }
        let ts = case["ts"].as_f64().unwrap();
        let d = discretize_file(&file, Some(ts)).unwrap();
        assert_eq!(d.ts, ts);
        assert_eq!(d.models.len(), 5, "one entry per single-input block");
        let name = case["name"].as_str().unwrap();
        let block = d.models.iter().find(|b| b.name == name).expect(name);
        check(block, case);
        checked += 1;
    }
    assert_eq!(checked, 10);
    // Default ts is the file's, and eq 5's 0.42 s is 21 samples.
    let d = discretize_file(&file, None).unwrap();
    assert_eq!(d.ts, 0.02);
    assert_eq!(d.models[0].delay_samples, 21);
    assert_eq!(d.models[0].input, "input_vel [m/s]");
    assert_eq!(d.models[0].output, "vel [m/s]");
}

#[test]
fn other_orders_match_python_control() {
    // First and third order: a model file for the node holds at most 2nd order, so these go
    // through the same discretization directly.
    let reference = load_reference("discretize_c2d.json");
    let mut checked = 0;
    for case in reference["cases"].as_array().unwrap() {
        if case["group"] != "extra" {
            continue;
        }
        let coeffs = |k: &str| -> Vec<f64> {
            case[k]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect()
        };
        let tf = TransferFunction::new(
            &coeffs("num"),
            &coeffs("den"),
            case["delay_s"].as_f64().unwrap(),
        )
        .unwrap();
        let ts = case["ts"].as_f64().unwrap();
        let block = discretize_tf("extra".into(), "u".into(), "y".into(), &tf, ts).unwrap();
        check(&block, case);
        checked += 1;
    }
    assert_eq!(checked, 6);
}

#[test]
fn fractional_delay_is_a_clear_error() {
    let file = model_file::load(&model_file::paper_path()).unwrap();
    let e = discretize_file(&file, Some(0.04)).unwrap_err().to_string();
    assert!(
        e.contains("speed.input_vel") && e.contains("not a whole number of samples"),
        "{e}"
    );
}
