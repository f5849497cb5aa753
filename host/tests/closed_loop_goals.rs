//! The controller's goals on the closed-loop rig: the node (controller inside) on the bus with
//! the built-in plant, the planner's frames and the sensors' reports, exactly as
//! `catmodel closed-loop` runs it. These pin what the model-predictive controller reaches
//! (docs/controller.md, "Figures"); where that falls short of the goal, the test says
//! so and pins the measured figure, so that a regression fails and an improvement is a one-line
//! change.
//!
//! Release builds only (about 40 runs of the rig; CI runs
//! `cargo test --release -p catmodel-host --test closed_loop_goals`): the unoptimised build
//! ignores them.
use catmodel_host::closed_loop::driver::{Controller, NodeDriver};
use catmodel_host::closed_loop::limits::{clean_at, SEEDS};
use catmodel_host::closed_loop::metrics::Metrics;
use catmodel_host::closed_loop::scenario::{self, Kind};
use catmodel_host::closed_loop::{load_setup, run};
use catmodel_host::closed_loop::{Receiver, RunOptions};

/// The second car, which the defaults were not tuned on: the compact hatchback
/// (`host/vehicles/hatchback.toml`, its model file `models/hatchback.toml`).
fn hatchback() -> (std::path::PathBuf, std::path::PathBuf) {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    (
        root.join("vehicles/hatchback.toml"),
        root.join("../models/hatchback.toml"),
    )
}

fn drive(kind: Kind, controller: Controller, receiver: Receiver, speed: f64, seed: u64) -> Metrics {
    drive_car(None, kind, controller, receiver, speed, seed)
}

fn drive_car(
    car: Option<(std::path::PathBuf, std::path::PathBuf)>,
    kind: Kind,
    controller: Controller,
    receiver: Receiver,
    speed: f64,
    seed: u64,
) -> Metrics {
    let (vehicle, node) = match &car {
        Some((v, m)) => load_setup(Some(v), Some(m)).unwrap(),
        None => load_setup(None, None).unwrap(),
    };
    let course = scenario::course(kind, &vehicle.body, speed);
    let mut driver = NodeDriver::new(node, controller);
    let options = RunOptions {
        seed,
        receiver,
        max_time_s: 120.0,
        replan_s: None,
    };
    run(&vehicle, &course, &mut driver, "", &options).metrics
}

/// The double lane change: the MPC clean on every seed up to 13.5 m/s (its limit by
/// `catmodel dlc-limits --controllers pure-pursuit,mpc`: 13.88 m/s; pure pursuit's 13.13 m/s).
/// Goal: 2 m/s above pure pursuit and within 1 m/s of the optimiser's limit (16.94 m/s): not
/// reached (docs/controller.md, "What is left").
#[test]
#[cfg_attr(debug_assertions, ignore = "release only (see the module doc)")]
fn double_lane_change_mpc_clean_up_to_its_limit() {
    let (vehicle, node) = load_setup(None, None).unwrap();
    for speed in [5.0, 8.0, 10.0, 12.5, 13.5] {
        let (clean, _) = clean_at(&vehicle, &node, Controller::Mpc, Receiver::Rtk, speed);
        assert!(clean, "MPC not clean at {speed} m/s on seeds {SEEDS:?}");
    }
}

/// The obstacle on the path with the standard receiver (1.2 m horizontal RMS): passed with at
/// least 0.5 m between the body and the obstacle on every seed (measured: 2.10 m at least).
#[test]
#[cfg_attr(debug_assertions, ignore = "release only (see the module doc)")]
fn obstacle_passed_with_half_a_metre_standard_receiver() {
    for seed in SEEDS {
        let m = drive(
            Kind::Obstacle,
            Controller::Mpc,
            Receiver::Standard,
            Kind::Obstacle.default_speed_mps(),
            seed,
        );
        assert!(m.completed, "seed {seed}: not completed");
        let clearance = m.min_obstacle_clearance_m.unwrap();
        assert!(clearance >= 0.5, "seed {seed}: {clearance} m");
    }
}

/// Lateral RMS with the RTK receiver on the parking-lot loop: 0.012 m at its 4 m/s; at 10 m/s
/// 0.031 m (goal 0.10 m; 0.141 m before the dead reckoning knew the rear axle's slip, 0.043 m
/// before the heading came from two chords compared).
#[test]
#[cfg_attr(debug_assertions, ignore = "release only (see the module doc)")]
fn loop_lateral_rms_rtk() {
    let slow = drive(Kind::Loop, Controller::Mpc, Receiver::Rtk, 4.0, 0);
    let rms = slow.lateral_rms_m.unwrap();
    assert!(rms <= 0.03, "4 m/s: {rms} m");
    for seed in SEEDS {
        let fast = drive(Kind::Loop, Controller::Mpc, Receiver::Rtk, 10.0, seed);
        let rms = fast.lateral_rms_m.unwrap();
        assert!(
            fast.completed && rms <= 0.10,
            "10 m/s, seed {seed}: {rms} m"
        );
    }
}

/// The second car: the MPC clean at 13 m/s (`catmodel dlc-limits --controllers
/// pure-pursuit,mpc --vehicle host/vehicles/hatchback.toml --model models/hatchback.toml`:
/// MPC 13.5 m/s; pure pursuit with the CAT Vehicle's tuning 6.13 m/s, with a lookahead tuned
/// for this car 14.81 m/s: docs/controller.md); the obstacle passed with 0.5 m with the
/// standard receiver (measured 2.12 m); the loop at 10 m/s within the goal's 0.10 m lateral
/// RMS (measured 0.032 m).
#[test]
#[cfg_attr(debug_assertions, ignore = "release only (see the module doc)")]
fn second_car_goals() {
    let (v, m) = hatchback();
    let (vehicle, node) = load_setup(Some(&v), Some(&m)).unwrap();
    let (clean, _) = clean_at(&vehicle, &node, Controller::Mpc, Receiver::Rtk, 13.0);
    assert!(clean, "MPC not clean at 13 m/s");
    let car = Some((v, m));
    let obstacle = drive_car(
        car.clone(),
        Kind::Obstacle,
        Controller::Mpc,
        Receiver::Standard,
        Kind::Obstacle.default_speed_mps(),
        0,
    );
    assert!(obstacle.completed);
    assert!(
        obstacle.min_obstacle_clearance_m.unwrap() >= 0.5,
        "{obstacle:?}"
    );
    let fast = drive_car(car, Kind::Loop, Controller::Mpc, Receiver::Rtk, 10.0, 0);
    let rms = fast.lateral_rms_m.unwrap();
    assert!(fast.completed && rms <= 0.10, "10 m/s: {rms} m");
}
