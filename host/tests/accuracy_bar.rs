//! The host loop's accuracy bar, through the built `catmodel` binary exactly as a user runs it:
//! simulate-drive -> replay -> evaluate --json. Ground truth is only read by `evaluate`.
//!
//! Measured on the 5-minute validation drive with seed 0 (the drive the node's defaults were
//! chosen on) and, so that the bar is not a property of that one drive, on drives nothing was
//! tuned on: the validation drive with other seeds (other GNSS errors, commands and clocks) and
//! the held-out `suburb` scenario (faster, lane changes, a roundabout, a stop).
//!
//! On every drive:
//! - the filtered current position (horizon 0) is within 10 % of the GNSS bias floor (the slow
//!   GNSS error no filter of GNSS alone can remove, `evaluate`'s `bias_floor`), and closer to
//!   truth than raw GNSS even after the best possible lever-arm correction (raw fixes moved to
//!   the rear axle along the *true* heading);
//! - 1 s ahead, the node beats the kinematic-only baseline fed with raw GNSS, measured speed and
//!   steering; and the part of its error above the floor (`sqrt(rms^2 - floor^2)`: what a
//!   predictor controls, the bias aside) is at most half the baseline's.
//!
//! On the tuning drive also the original bar: 1 s ahead at least a quarter below the baseline
//! (on drives with a larger bias the bias dominates both errors and that ratio says little).
//!
//! And a second car, end to end (`host/vehicles/vw-polo.toml`: another wheelbase, antenna
//! position, tyres, speed-loop delay, and a 10 Hz receiver): its experiments simulated, its
//! models identified with `identify --vehicle` (every fit above the floor), replayed with that
//! model file on drives identification did not see, and the goals for a 10 Hz receiver: within
//! 20 % of the bias floor and below raw GNSS.
use std::path::{Path, PathBuf};
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_catmodel");

fn ok(args: &[&str]) {
    let out = Command::new(BIN).args(args).output().unwrap();
    assert!(
        out.status.success(),
        "catmodel {args:?}:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// What `evaluate --json` says about one drive.
struct Scores {
    /// Filtered position (horizon 0), RMS, m.
    node0: f64,
    /// Node and baseline 1 s ahead, RMS, m.
    node1: f64,
    base1: f64,
    /// Raw GNSS at the rear axle with the true heading, RMS, m.
    raw_axle: f64,
    /// The bias floor, RMS, m, and the filtered position's ratio to it.
    floor: f64,
    floor_ratio: f64,
    /// Ticks scored and the drive's length in ticks.
    ticks: u64,
    drive_ticks: f64,
}

/// A car: the simulator's vehicle file and the model file the node runs (`None`: the CAT
/// Vehicle and the published models).
#[derive(Clone, Copy)]
struct Car<'a> {
    name: &'a str,
    vehicle: Option<&'a Path>,
    model: Option<&'a Path>,
}

const CAT: Car<'static> = Car {
    name: "cat",
    vehicle: None,
    model: None,
};

fn tmp(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// `simulate-drive` of `scenario` with `seed` on `car` into `dir`.
fn simulate(car: Car<'_>, scenario: &str, seed: u64, dir: &Path) {
    let seed_text = seed.to_string();
    let mut args = vec![
        "simulate-drive",
        "--scenario",
        scenario,
        "--seed",
        &seed_text,
        "--out",
        dir.to_str().unwrap(),
    ];
    if let Some(v) = car.vehicle {
        args.extend(["--vehicle", v.to_str().unwrap()]);
    }
    ok(&args);
}

fn scores(car: Car<'_>, scenario: &str, seed: u64) -> Scores {
    let dir = tmp(&format!("accuracy_{}_{scenario}_{seed}", car.name));
    let d = dir.to_str().unwrap();
    simulate(car, scenario, seed, &dir);
    let pred = dir.join("pred.csv");
    let json = dir.join("eval.json");
    let model: Vec<&str> = car
        .model
        .map(|m| vec!["--model", m.to_str().unwrap()])
        .unwrap_or_default();
    let replay = [
        "replay",
        &format!("{d}/{scenario}.can.log"),
        "--origin",
        "32.2319,-110.9501",
        "--out",
        pred.to_str().unwrap(),
    ];
    ok(&[&replay[..], &model].concat());
    let truth = format!("{d}/{scenario}.truth.csv");
    let evaluate = [
        "evaluate",
        pred.to_str().unwrap(),
        "--truth",
        &truth,
        "--json",
        json.to_str().unwrap(),
    ];
    ok(&[&evaluate[..], &model].concat());
    let e: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let rms = |v: &serde_json::Value| v["pos_rms_m"].as_f64().unwrap();
    let horizon = |h: f64| {
        e["horizons"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| (r["horizon_s"].as_f64().unwrap() - h).abs() < 1e-9)
            .unwrap_or_else(|| panic!("no horizon {h}"))
            .clone()
    };
    let truth_rows = std::fs::read_to_string(&truth).unwrap().lines().count() - 1;
    let s = Scores {
        node0: rms(&horizon(0.0)["node"]),
        node1: rms(&horizon(1.0)["node"]),
        base1: rms(&horizon(1.0)["baseline"]),
        raw_axle: rms(&e["raw_gnss_at_axle"]),
        floor: rms(&e["bias_floor"]),
        floor_ratio: e["bias_floor"]["filtered_ratio"].as_f64().unwrap(),
        ticks: e["ticks"].as_u64().unwrap(),
        // Truth rows every 10 ms.
        drive_ticks: truth_rows as f64 / 2.0,
    };
    eprintln!(
        "{} {scenario} seed {seed}: horizon 0: node {:.3} m = {:.3} x the bias floor {:.3} m, raw at axle {:.3} m; 1 s: node {:.3} m, baseline {:.3} m",
        car.name, s.node0, s.floor_ratio, s.floor, s.raw_axle, s.node1, s.base1
    );
    s
}

/// Error above the bias floor: `sqrt(rms^2 - floor^2)`, 0 if below.
fn above_floor(rms: f64, floor: f64) -> f64 {
    (rms * rms - floor * floor).max(0.0).sqrt()
}

/// The bar of one drive: the filtered position within `floor_share` of the bias floor, and the
/// 1 s predictions' error above the floor at most `above_floor_share` of the baseline's.
fn check_every_drive_bar(name: &str, s: &Scores, floor_share: f64, above_floor_share: f64) {
    assert!(
        s.floor_ratio <= floor_share,
        "{name}: filtered {} m is {} x the floor",
        s.node0,
        s.floor_ratio
    );
    assert!(
        s.node0 < s.raw_axle,
        "{name}: filtered {} vs raw at the axle {}",
        s.node0,
        s.raw_axle
    );
    assert!(
        s.node1 < s.base1,
        "{name}: 1 s: node {} vs baseline {}",
        s.node1,
        s.base1
    );
    let (node, base) = (above_floor(s.node1, s.floor), above_floor(s.base1, s.floor));
    assert!(
        node <= above_floor_share * base,
        "{name}: 1 s above the floor: node {node} vs baseline {base}"
    );
    // Most ticks are scored (the node reports from its first heading on).
    assert!(
        s.ticks as f64 > 0.95 * s.drive_ticks,
        "{name}: {} of {} ticks",
        s.ticks,
        s.drive_ticks
    );
}

#[test]
fn validation_drive_meets_the_accuracy_bar() {
    let s = scores(CAT, "validation", 0);
    check_every_drive_bar("validation seed 0", &s, 1.10, 0.5);
    assert!(
        s.node1 < 0.75 * s.base1,
        "1 s: node {} vs baseline {}",
        s.node1,
        s.base1
    );
}

#[test]
fn drives_nothing_was_tuned_on_meet_the_accuracy_bar() {
    for (scenario, seed) in [
        ("validation", 9),
        ("suburb", 7),
        ("suburb", 11),
        ("suburb", 16),
    ] {
        let s = scores(CAT, scenario, seed);
        check_every_drive_bar(&format!("{scenario} seed {seed}"), &s, 1.10, 0.5);
    }
}

fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(path)
}

/// The paper-sized training set (README, "Identify, compare, discretize") and the validation
/// drive with seed 3, of the second car.
#[test]
fn a_second_car_end_to_end() {
    let vehicle = repo("host/vehicles/vw-polo.toml");
    let polo = Car {
        name: "vw-polo",
        vehicle: Some(&vehicle),
        model: None,
    };
    let dir = tmp("second_car_identify");
    let mut training = Vec::new();
    for (scenario, seed) in catmodel_host::sim::scenario::PAPER_SIZED_TRAINING {
        let sub = dir.join(format!("seed{seed}"));
        simulate(polo, scenario, seed, &sub);
        training.push(sub.join(format!("{scenario}.csv")));
    }
    simulate(polo, "validation", 3, &dir);
    let model = dir.join("vw-polo.toml");
    let car_file = repo("host/vehicles/vw-polo.car.toml");
    let mut args: Vec<&str> = vec!["identify"];
    args.extend(training.iter().map(|p| p.to_str().unwrap()));
    let validation = dir.join("validation.csv");
    args.extend([
        "--validate",
        validation.to_str().unwrap(),
        "--vehicle",
        car_file.to_str().unwrap(),
        "--out",
        model.to_str().unwrap(),
    ]);
    // Every fit above the floor, or nothing is written.
    ok(&args);
    let file = catmodel_host::model_file::load(&model).unwrap();
    assert_eq!(file.vehicle.gnss_rate_hz, 10.0);
    assert_eq!(file.vehicle.antenna_ahead_m, 0.6);
    assert_eq!(file.vehicle.wheelbase_m, 2.564);
    assert_eq!(file.dynamics.map(|d| d.mass_kg), Some(1200.0));
    assert!(file.lateral.is_some(), "the lateral model is identified");

    let polo = Car {
        model: Some(&model),
        ..polo
    };
    // Drives identification did not see. A 10 Hz course steers the heading less well than a
    // 100 Hz one: the 1 s bar above the floor is 0.6 of the baseline's (0.5 at 100 Hz).
    for (scenario, seed) in [("validation", 0), ("validation", 9), ("suburb", 7)] {
        let s = scores(polo, scenario, seed);
        check_every_drive_bar(&format!("vw-polo {scenario} seed {seed}"), &s, 1.20, 0.6);
    }
}
