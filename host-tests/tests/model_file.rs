//! The model file: `models/paper.toml` holds exactly the paper's published models and the CAT
//! Vehicle's published figures; writing and reading back is lossless; the committed corpus of
//! bad files (`models/bad/`, made by `models/bad/generate.py`) is refused with the message each
//! file names, and the good ones (`models/good/`) give the published node exactly.
use std::path::{Path, PathBuf};

use catmodel::model::paper;
use catmodel::vehicle::VehicleParams;
use catmodel_host::model_file::{self, parse, to_toml, ModelFile};

fn paper_text() -> String {
    std::fs::read_to_string(model_file::paper_path()).expect("models/paper.toml")
}

#[test]
fn paper_file_holds_the_published_numbers() {
    let f = model_file::load(&model_file::paper_path()).expect("loads");
    assert_eq!(f.sample_time_s, paper::PAPER_TS_S);
    assert_eq!(f.speed.tfs(), vec![paper::EQ5_INTERNAL_CONTROLLER]);
    assert_eq!(f.dx_dt.tfs(), paper::EQ7_DX_DT.to_vec());
    // The CAT Vehicle: L and T from the CAT Vehicle ROS package, 35.5 deg and K = 0.0015 from
    // the paper (II-C, eq 2).
    let cat = VehicleParams {
        wheelbase_m: 2.62,
        track_m: 1.55,
        max_steer_rad: 35.5 * std::f32::consts::PI / 180.0,
        understeer_s2_per_m2: 0.0015,
    };
    assert_eq!(f.vehicle.params(), cat);
    assert_eq!(f.vehicle.gnss_rate_hz, 100.0, "paper II-B: every 0.01 s");
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
    // The dynamic model's understeer equals eq 2's K (the pair of stiffnesses was chosen so).
    let k = f.dynamics.unwrap().params().understeer_s2_per_m2();
    assert!((k - 0.0015).abs() < 2e-5, "{k}");
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

fn corpus(dir: &str) -> Vec<PathBuf> {
    let dir = model_file::paper_path().parent().unwrap().join(dir);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    files
}

/// The text a bad file's first line says its error must contain.
pub fn expected_message(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap();
    let first = text.lines().next().unwrap_or_default();
    first
        .strip_prefix("# expect: ")
        .unwrap_or_else(|| panic!("{}: no `# expect:` line", path.display()))
        .to_owned()
}

/// Every car's model file of the repository (the published one, those `catmodel identify`
/// wrote for the van and the hatchback, and the truck of docs/findings-data) loads: the
/// reader's stability, gain and physical bounds refuse none of them, though identified poles
/// sit on the 0.1 1/s bound `identify` fits under.
#[test]
fn every_car_model_of_the_repository_loads() {
    let mut files = corpus(".");
    assert!(files.len() >= 3, "{files:?}");
    files.push(repo("docs/findings-data/truck-4hz.model.toml"));
    for path in files {
        if let Err(e) = model_file::load(&path) {
            panic!("{e}");
        }
    }
}

fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(path)
}

/// Every car the repository describes reaches the node through the reader and is accepted by
/// its physical ranges: the owners' car files (`identify --vehicle`: the published file with
/// the car's `[vehicle]`, `[dynamics]`, `[inputs]`, `[control]`) and the simulator's plants
/// (`closed_loop::model_file_for`, as `closed-loop` and `sil` describe a plant to the node),
/// from the city car to the van, the pickup, the roadster and the 4 Hz truck: every file of
/// `host/vehicles/` (`*.car.toml` a car file, the rest plants), so that none added escapes,
/// and the ones kept beside tests and findings.
#[test]
fn every_car_file_and_plant_of_the_repository_is_accepted() {
    use catmodel_host::sim::config::VehicleConfig;
    let base = model_file::paper();
    let mut car_files = vec!["docs/findings-data/truck-4hz.car.toml".to_string()];
    let mut plants = vec![
        "host/tests/data/long-heavy-5hz.toml".to_string(),
        "host/tests/data/long-slow-steering-20hz.toml".to_string(),
        "docs/findings-data/truck-4hz.toml".to_string(),
    ];
    let listed = std::fs::read_dir(repo("host/vehicles")).expect("host/vehicles");
    for entry in listed {
        let name = entry.expect("a directory entry").file_name();
        let name = name.to_string_lossy();
        if name.ends_with(".car.toml") {
            car_files.push(format!("host/vehicles/{name}"));
        } else if name.ends_with(".toml") {
            plants.push(format!("host/vehicles/{name}"));
        }
    }
    assert!(
        car_files.len() >= 4 && plants.len() >= 10,
        "{car_files:?} {plants:?}"
    );
    for path in &car_files {
        if let Err(e) = catmodel_host::identify::car::apply(&base, &repo(path)) {
            panic!("{path}: {e}");
        }
    }
    for path in &plants {
        let plant = VehicleConfig::load(&repo(path)).unwrap_or_else(|e| panic!("{path}: {e}"));
        if let Err(e) = catmodel_host::closed_loop::model_file_for(&plant) {
            panic!("{path}: {e}");
        }
    }
}

/// Unstable, near-integrating and absurd-gain models, each a one-line change of the published
/// file, are refused naming the block and the pole or the gain (the review's cases; the
/// corpus holds them as files, `models/bad/`).
#[test]
fn unstable_slow_and_absurd_models_are_refused() {
    let text = paper_text();
    let cases = [
        (
            "den = [1.0, 1.629, 0.7522]",
            "den = [1.0, -0.5, 0.2]",
            "speed.blocks[input_vel]: pole at s = 0.25 +/- 0.3708j in the right half-plane",
        ),
        (
            "den = [1.0, 1.629, 0.7522]",
            "den = [1.0, 1e-6, 1e-12]",
            "speed.blocks[input_vel]: pole at s = -5e-7 +/- 8.66e-7j decays slower than 0.1 1/s",
        ),
        (
            "den = [1.0, 1.629, 0.7522]",
            "den = [1.0, 0.15, 0.005]",
            "speed.blocks[input_vel]: pole at s = -0.05 decays slower than 0.1 1/s (time constant 20 s",
        ),
        (
            "num = [0.03679, -0.1981, 0.7647]",
            "num = [0.0, 1e30, 1e30]",
            "speed.blocks[input_vel]: DC gain 1.329e30 is outside 0.5..2",
        ),
        (
            "num = [0.03679, -0.1981, 0.7647]",
            "num = [0.03679, -0.1981, -0.7647]",
            "speed.blocks[input_vel]: DC gain -1.017 is outside 0.5..2",
        ),
        (
            "den = [1.0, 6.211, 26.79]",
            "den = [1.0, -2.0, 1.0]",
            "dx_dt.blocks[v_m]: pole at s = 1 in the right half-plane",
        ),
        (
            "den = [1.0, 37.03, 111.7]",
            "den = [1.0, 37.03, -111.7]",
            "dx_dt.blocks[x]: pole at s = 2.804 in the right half-plane",
        ),
        (
            "num = [-4.122, 49.61, -4.098]",
            "num = [-4.122, 49.61, -80.0]",
            "dx_dt.blocks[v_m]: DC gain -2.986 is outside -2..2",
        ),
    ];
    for (old, new, needle) in cases {
        assert!(text.contains(old), "{old}");
        expect_error(&text.replacen(old, new, 1), needle);
    }
}

#[test]
fn every_bad_file_of_the_corpus_is_refused_with_its_message() {
    let files = corpus("bad");
    assert!(files.len() >= 20, "{} bad files", files.len());
    for path in files {
        let expect = expected_message(&path);
        match model_file::load(&path) {
            Ok(_) => panic!("{}: accepted", path.display()),
            Err(e) => {
                assert_eq!(e.path, path);
                assert!(
                    e.message.contains(&expect),
                    "{}: {:?} does not contain {expect:?}",
                    path.display(),
                    e.message
                );
                assert!(!e.message.contains('\n'), "one line: {:?}", e.message);
            }
        }
    }
}

#[test]
fn every_good_file_of_the_corpus_is_the_published_node() {
    let paper = model_file::paper().node_config();
    let files = corpus("good");
    assert!(!files.is_empty());
    for path in files {
        let f = model_file::load(&path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(f.node_config(), paper, "{}", path.display());
    }
}

#[test]
fn lower_orders_are_embedded_exactly() {
    // A first-order speed model with a delay runs in the node's 2-state block: its step
    // response is the first-order one (2/(s + 1), 0.1 s delay).
    let t = paper_text()
        .replace("num = [0.03679, -0.1981, 0.7647]", "num = [2.0]")
        .replace("den = [1.0, 1.629, 0.7522]", "den = [1.0, 1.0]")
        .replace("delay_s = 0.42", "delay_s = 0.1");
    let f = parse(&t, Path::new("first-order.toml")).unwrap();
    let cfg = f.node_config();
    let mut st = cfg.velocity.zero_state();
    let ts = 0.02f64;
    for k in 0..200 {
        let y = cfg.velocity.step(&mut st, 1.0);
        // y[k] for a unit step delayed 5 samples: 2 (1 - e^{-(k - 5) ts}) from k = 6 on.
        let expect = if k <= 5 {
            0.0
        } else {
            2.0 * (1.0 - (-((k - 5) as f64) * ts).exp())
        };
        assert!(
            (f64::from(y) - expect).abs() < 1e-5,
            "k {k}: {y} vs {expect}"
        );
    }
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
fn errors_name_the_file_and_the_key() {
    let t = paper_text();
    expect_error(
        &t.replace("delay_s = 0.42", "delay_s = -0.4"),
        "speed.blocks[0]: negative delay",
    );
    expect_error(
        &t.replace("antenna_left_m = 0.0", "antenna_left_m = inf"),
        "vehicle.antenna_left_m = inf: must be within -1.403..1.403 m (on the car",
    );
    expect_error(
        &t.replace("gnss_lost_s = 2.0", "gnss_lost_s = 0.1"),
        "inputs.gnss_lost_s = 0.1: must be longer than the GNSS timeout",
    );
}

/// `[control] mpc_lateral_weight_per_m2`: a file that sets it runs the MPC with that weight on
/// every path (the rest of the tuning the built-in one, its rule for paths that need the lock
/// off); it survives writing, reading and the firmware's image; a file without it runs the
/// built-in tuning.
/// `file` written by the writer reads back equal, and its node configuration comes back equal
/// from the firmware's image.
fn written_and_imaged_alike(file: &ModelFile) {
    let again = parse(&to_toml(file), Path::new("<written>")).unwrap();
    assert_eq!(&again, file);
    let config = file.node_config();
    let mut words = vec![0u32; catmodel::node::CONFIG_IMAGE_MAX_WORDS];
    let n = config.to_image(&mut words);
    let back = catmodel::node::NodeConfig::from_image(&words[..n]).unwrap();
    assert_eq!(back, config);
}

#[test]
fn a_car_sets_its_lateral_weight_in_its_model_file() {
    use catmodel::control::mpc::DEFAULT_TUNING;
    use catmodel::node::drive::mpc_tuning;
    let text = paper_text().replace(
        "position_uncertainty_m = 2.0",
        "position_uncertainty_m = 2.0\nmpc_lateral_weight_per_m2 = 2.5",
    );
    let file = parse(&text, Path::new("weighted.toml")).unwrap();
    assert_eq!(file.control.mpc_lateral_weight_per_m2, Some(2.5));
    let config = file.node_config();
    assert_eq!(config.mpc_lateral_weight_per_m2, Some(2.5));
    let tuning = mpc_tuning(&config);
    let mut expected = DEFAULT_TUNING;
    expected.weights.lateral_per_m2 = 2.5;
    expected.line_rule = None;
    assert_eq!(tuning, expected);
    written_and_imaged_alike(&file);
    let paper = model_file::paper().node_config();
    assert_eq!(paper.mpc_lateral_weight_per_m2, None);
    assert_eq!(mpc_tuning(&paper), DEFAULT_TUNING);
}

#[test]
fn a_car_declares_its_steering_lag_in_its_model_file() {
    use catmodel::control::mpc::{MpcConfig, DEFAULT_TUNING, MAX_STEER_LEAD_S};
    use catmodel::node::drive::mpc_tuning;
    let with_lag = |lag: &str| {
        paper_text().replace(
            "\n\n[dynamics]",
            &format!("\nsteer_lag_s = {lag}\n\n[dynamics]"),
        )
    };
    let file = parse(&with_lag("0.09"), Path::new("slow.toml")).unwrap();
    assert_eq!(file.vehicle.steer_lag_s, Some(0.09));
    let config = file.node_config();
    assert_eq!(config.steer_lag_s, Some(0.09));
    // The command leads the plan by the lag and the tick it takes to reach the actuator.
    let tuning = mpc_tuning(&config);
    assert!(
        (tuning.steer_lead_s - 0.11).abs() < 1e-6,
        "{}",
        tuning.steer_lead_s
    );
    let mut expected = DEFAULT_TUNING;
    expected.steer_lead_s = tuning.steer_lead_s;
    assert_eq!(tuning, expected);
    // Written and read back, through the firmware image too.
    written_and_imaged_alike(&file);
    // The longest lag the reader takes gives a lead the controller takes.
    let longest = parse(&with_lag("0.25"), Path::new("slowest.toml"))
        .unwrap()
        .node_config();
    assert!(mpc_tuning(&longest).steer_lead_s <= MAX_STEER_LEAD_S);
    assert!(MpcConfig::for_node(&longest, mpc_tuning(&longest)).is_ok());
    for bad in ["-0.01", "0.26", "nan"] {
        let e = parse(&with_lag(bad), Path::new("bad.toml")).unwrap_err();
        assert!(e.to_string().contains("vehicle.steer_lag_s"), "{bad}: {e}");
    }
    // Without the key: the built-in lead, the published car's.
    let paper = model_file::paper().node_config();
    assert_eq!(paper.steer_lag_s, None);
    assert_eq!(mpc_tuning(&paper).steer_lead_s, DEFAULT_TUNING.steer_lead_s);
}

/// Without a lateral weight in its file, a car whose steering changes its curvature more slowly
/// than the CAT Vehicle's (rate over wheelbase) gets the built-in weight times the square of
/// its share, 1 at least (hand-derived); the CAT Vehicle, the hatchback (faster) and a file
/// that sets its own weight keep theirs.
#[test]
fn a_slower_steering_gets_a_lighter_weight_on_the_line() {
    use catmodel::control::mpc::DEFAULT_TUNING;
    use catmodel::node::drive::mpc_tuning;
    let at_rate = |rate: &str| {
        parse(
            &paper_text().replace(
                "max_steer_rate_pct_per_s = 60.0",
                &format!("max_steer_rate_pct_per_s = {rate}"),
            ),
            Path::new("rate.toml"),
        )
        .unwrap()
        .node_config()
    };
    let weight = |rate: &str| mpc_tuning(&at_rate(rate)).weights.lateral_per_m2;
    assert_eq!(weight("60.0"), DEFAULT_TUNING.weights.lateral_per_m2);
    assert_eq!(weight("90.0"), DEFAULT_TUNING.weights.lateral_per_m2);
    // Half the rate: a quarter of 10.
    assert!((weight("30.0") - 2.5).abs() < 1e-4, "{}", weight("30.0"));
    // A fifth: 0.4, held at 1.
    assert_eq!(weight("12.0"), 1.0);
    // The line rule stays.
    assert_eq!(
        mpc_tuning(&at_rate("30.0")).line_rule,
        DEFAULT_TUNING.line_rule
    );
    let hatchback =
        model_file::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/hatchback.toml"))
            .unwrap()
            .node_config();
    assert_eq!(mpc_tuning(&hatchback).weights, DEFAULT_TUNING.weights);
    // A weight in the file wins.
    let text = paper_text()
        .replace(
            "max_steer_rate_pct_per_s = 60.0",
            "max_steer_rate_pct_per_s = 30.0",
        )
        .replace(
            "position_uncertainty_m = 2.0",
            "position_uncertainty_m = 2.0\nmpc_lateral_weight_per_m2 = 7.0",
        );
    let own = parse(&text, Path::new("own.toml")).unwrap().node_config();
    assert_eq!(mpc_tuning(&own).weights.lateral_per_m2, 7.0);
}
