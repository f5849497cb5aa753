//! `identify --report`: every figure is written with its numbered title, the log it shows
//! ("Validation log: NAME" or "Training log: NAME"), every series and marker in the legend, and
//! the legend below the data.
use std::path::{Path, PathBuf};

use catmodel_host::identify::preprocess::Experiment;
use catmodel_host::identify::{self, IdentifyOptions};
use catmodel_host::model_file;
use catmodel_host_tests::sim_experiment;

fn report(name: &str, validation: Vec<Experiment>) -> PathBuf {
    let training = vec![
        sim_experiment("straight-5", 1),
        sim_experiment("straight-10", 1),
    ];
    let base = model_file::load(&model_file::paper_path()).unwrap();
    let id = identify::identify(training, validation, &base, &IdentifyOptions::default()).unwrap();
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    identify::report::write_report(&dir, &id).unwrap();
    dir
}

/// The texts of an SVG's `<text>` elements with their y coordinates.
fn texts(svg: &str) -> Vec<(String, f64)> {
    svg.split("<text")
        .skip(1)
        .map(|t| {
            let y = t
                .split(" y=\"")
                .nth(1)
                .and_then(|s| s.split('"').next())
                .and_then(|s| s.parse().ok())
                .unwrap_or(f64::NAN);
            let body = t.split('>').nth(1).unwrap_or("").split("</text").next();
            (body.unwrap_or("").trim().to_string(), y)
        })
        .collect()
}

fn y_of(texts: &[(String, f64)], text: &str) -> f64 {
    texts
        .iter()
        .find(|(t, _)| t == text)
        .unwrap_or_else(|| panic!("no text {text:?} in {texts:?}"))
        .1
}

#[test]
fn figures_have_numbered_titles_their_log_and_full_legends_below_the_data() {
    let dir = report("report_validation", vec![sim_experiment("turn-left", 1)]);
    let figures = [
        ("fig4_speed.svg", "Fig 4: speed, measured and simulated"),
        ("fig5_speed_error.svg", "Fig 5: absolute speed error"),
        (
            "fig6_dx.svg",
            "Fig 6: dx/dt (east velocity), measured and simulated",
        ),
        ("fig7_dx_error.svg", "Fig 7: absolute dx/dt error"),
        (
            "residual_acf.svg",
            "Autocorrelation of the speed simulation error",
        ),
    ];
    for (file, title) in figures {
        let svg = std::fs::read_to_string(dir.join(file)).unwrap();
        let t = texts(&svg);
        y_of(&t, title);
        y_of(&t, "Validation log: turn-left-1");
        // Every legend entry lies below the x axis description (t or lag).
        let axis_y = t
            .iter()
            .find(|(s, _)| s == "t (s)" || s == "lag (s)")
            .unwrap()
            .1;
        for label in [
            "kinematic",
            "transfer function (eq 5 form)",
            "measured (GNSS)",
        ] {
            if let Some((_, y)) = t.iter().find(|(s, _)| s == label) {
                assert!(
                    *y > axis_y,
                    "{file}: legend {label:?} at {y}, axis at {axis_y}"
                );
            }
        }
    }

    // Fig 2: both markers drawn and named in the legend (2 markers + 2 legend samples).
    let svg = std::fs::read_to_string(dir.join("fig2_step.svg")).unwrap();
    let t = texts(&svg);
    y_of(&t, "Fig 2: delay and settling of a speed step");
    assert!(
        t.iter()
            .any(|(s, _)| s.starts_with("Training log: straight-")),
        "{t:?}"
    );
    let axis_y = y_of(&t, "t (s)");
    for label in [
        "commanded",
        "measured",
        "1: delay (the speed has moved 5 % of the step)",
        "2: settled (stays within 5 % of its final value)",
    ] {
        assert!(y_of(&t, label) > axis_y, "{label}");
    }
    assert_eq!(svg.matches("<circle").count(), 4);
}

#[test]
fn without_validation_logs_the_figures_name_the_training_log() {
    let dir = report("report_training", Vec::new());
    let svg = std::fs::read_to_string(dir.join("fig4_speed.svg")).unwrap();
    assert!(
        texts(&svg)
            .iter()
            .any(|(s, _)| s == "Training log: straight-5-1"),
        "{svg}"
    );
}
