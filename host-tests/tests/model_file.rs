//! The model file: `models/paper.toml` holds exactly the core's published models; writing and
//! reading back is lossless; bad files get errors that name the key.
use std::path::Path;

use catmodel::model::paper;
use catmodel::vehicle::CAT_VEHICLE;
use catmodel_host::model_file::{self, parse, to_toml};

fn paper_text() -> String {
    std::fs::read_to_string(model_file::paper_path()).expect("models/paper.toml")
}

#[test]
fn paper_file_equals_the_core_models() {
    let f = model_file::load(&model_file::paper_path()).expect("loads");
    assert_eq!(f.sample_time_s, paper::PAPER_TS_S);
    assert_eq!(f.speed.tfs(), vec![paper::EQ5_INTERNAL_CONTROLLER]);
    assert_eq!(f.dx_dt.tfs(), paper::EQ7_DX_DT.to_vec());
    assert_eq!(f.vehicle.params(), CAT_VEHICLE);
    assert_eq!(f.hybrid.config(), catmodel::model::hybrid::DEFAULT_HYBRID);
    assert_eq!(
        f.speed.fit.training_fit_percent,
        Some(paper::EQ5_FIT_TRAINING_PERCENT)
    );
    assert_eq!(
        f.speed.fit.validation_fit_percent,
        Some(paper::EQ5_FIT_TEST_PERCENT)
    );
    assert_eq!(
        f.speed.fit.validation_mse,
        Some(paper::SPEED_MSE_EQ5_M2_PER_S2)
    );
    assert_eq!(
        f.dx_dt.fit.training_fit_percent,
        Some(paper::EQ7_FIT_PERCENT)
    );
    assert_eq!(
        f.dx_dt.fit.validation_mse,
        Some(paper::DX_DT_MSE_EQ7_M2_PER_S2)
    );
    assert!(f.lateral.is_none());
}

#[test]
fn write_then_read_is_lossless() {
    let f = model_file::load(&model_file::paper_path()).unwrap();
    let text = to_toml(&f);
    let again = parse(&text, Path::new("<written>")).unwrap();
    assert_eq!(again, f);
    // And a second round trip is textually stable.
    assert_eq!(to_toml(&again), text);
}

fn expect_error(text: &str, needle: &str) {
    match parse(text, Path::new("bad.toml")) {
        Ok(_) => panic!("accepted a bad file (expected an error with {needle:?})"),
        Err(e) => {
            let msg = e.to_string();
            assert!(msg.starts_with("bad.toml: "), "{msg}");
            assert!(msg.contains(needle), "{msg:?} should contain {needle:?}");
        }
    }
}

#[test]
fn bad_files_name_the_key() {
    let t = paper_text();
    expect_error(
        &t.replace("delay_s = 0.42", "delay_s = 0.41"),
        "speed.blocks[0].delay_s",
    );
    expect_error(
        &t.replace("delay_s = 0.42", "delay_s = 0.43"),
        "whole number of samples",
    );
    expect_error(
        &t.replace("delay_s = 0.42", "delay_s = -0.4"),
        "negative delay",
    );
    expect_error(
        &t.replace("den = [1.0, 1.629, 0.7522]", "den = [0.0, 1.629, 0.7522]"),
        "speed.blocks[0]: leading denominator",
    );
    expect_error(
        &t.replace("den = [1.0, 1.629, 0.7522]", "den = [1.629, 0.7522]"),
        "improper",
    );
    expect_error(
        &t.replace("input = \"phi\"", "input = \"psi\""),
        "dx_dt.blocks[3].input",
    );
    expect_error(
        &t.replace("sample_time_s = 0.02", "sample_time_s = 0.0"),
        "sample_time_s",
    );
    expect_error(
        &t.replace("wheelbase_m = 2.62", "wheelbase_mm = 2620"),
        "wheelbase_mm",
    );
    expect_error(
        &t.replace("format = \"catmodel-model-1\"", "format = \"v0\""),
        "format",
    );
    expect_error(
        &t.replace(
            "exit_dynamic_speed_mps = 4.0",
            "exit_dynamic_speed_mps = 8.0",
        ),
        "hysteresis",
    );
    // Dropping a whole block.
    let cut = t.find("[[dx_dt.blocks]]\ninput = \"phi\"").unwrap();
    let end = t[cut..].find("[dx_dt.fit]").unwrap() + cut;
    expect_error(
        &format!("{}{}", &t[..cut], &t[end..]),
        "expected 4 block(s)",
    );
}
