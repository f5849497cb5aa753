//! The controller's goals on the closed-loop rig: the node (controller inside) on the bus with
//! the built-in plant, the planner's frames and the sensors' reports, exactly as
//! `catmodel closed-loop` runs it. These pin what the model-predictive controller reaches
//! (docs/controller.md, "Figures"); where that falls short of the goal, the test says
//! so and pins the measured figure, so that a regression fails and an improvement is a one-line
//! change.
//!
//! Release builds only (about 40 runs of the rig; CI runs every test in release,
//! `cargo test --workspace --release`): the unoptimised build
//! ignores them.
use catmodel::control::mpc::DEFAULT_TUNING;
use catmodel::node::NodeConfig;
use catmodel_host::closed_loop::driver::{Controller, NodeDriver};
use catmodel_host::closed_loop::limits::{clean_at, SEEDS};
use catmodel_host::closed_loop::metrics::Metrics;
use catmodel_host::closed_loop::scenario::{self, Kind};
use catmodel_host::closed_loop::{load_setup, run};
use catmodel_host::closed_loop::{Receiver, RunOptions, RunOutput};
use catmodel_host::sim::config::VehicleConfig;

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
    drive_with(&vehicle, &node, controller, receiver, kind, speed, seed).metrics
}

/// The double lane change: the MPC clean on every seed up to 14.25 m/s (its limit by
/// `catmodel dlc-limits --controllers pure-pursuit,mpc`: 14.38 m/s; pure pursuit's 13.06 m/s;
/// 14.56 and 13.13 when the planner's stop reached into the track).
/// Goal: 2 m/s above pure pursuit and within 1 m/s of the optimiser's limit (16.94 m/s): not
/// reached (docs/controller.md, "What is left").
#[test]
#[cfg_attr(debug_assertions, ignore = "release only (see the module doc)")]
fn double_lane_change_mpc_clean_up_to_its_limit() {
    let (vehicle, node) = load_setup(None, None).unwrap();
    for speed in [5.0, 8.0, 10.0, 12.5, 14.0, 14.25] {
        let (clean, _) = clean_at(&vehicle, &node, Controller::Mpc, Receiver::Rtk, speed);
        assert!(clean, "MPC not clean at {speed} m/s on seeds {SEEDS:?}");
    }
}

/// The lane change is driven at its speed, as the optimiser's trials are (speed command held):
/// the car's speed stays within 0.4 m/s of the target from the first cone to the last. With
/// the planner's stop 40 m after the track, the MPC braked into the exit lane from 14 m/s
/// (14.5 m/s target: 11.6 m/s at its slowest, seed 0) and its limit was not the optimiser's
/// manoeuvre.
#[test]
#[cfg_attr(debug_assertions, ignore = "release only (see the module doc)")]
fn double_lane_change_is_driven_at_its_speed() {
    let (vehicle, node) = load_setup(None, None).unwrap();
    let speed = 14.5;
    let course = scenario::course(Kind::DoubleLaneChange, &vehicle.body, speed);
    let (from, to) = course.scored_stations_m;
    let out = mpc_lane_change(&vehicle, &node, speed, 0);
    let scored: Vec<f64> = out
        .samples
        .iter()
        .filter(|s| s.station_m >= from && s.station_m <= to)
        .map(|s| s.truth.speed)
        .collect();
    assert!(scored.len() > 150, "{} samples in the track", scored.len());
    let slowest = scored.iter().copied().fold(f64::INFINITY, f64::min);
    assert!(
        slowest >= speed - 0.4,
        "{slowest} m/s in the track at {speed} m/s"
    );
}

/// The van (`host/vehicles/van.toml`: a 3.7 m wheelbase, 55 %/s steering, a 5 Hz receiver),
/// whose lane change path asks for 0.87 of its lock: the MPC weighs the path with its
/// `line_rule`'s lateral weight of 1, and the van passes its cones within 0.03 m at 5 to 9 m/s
/// on every seed (measured clean on every seed, by 0.00 to 0.06 m; with the speed bias
/// low-passed in the predictions too, 0.01 m into a cone at 7 m/s on one seed), clean at 5 m/s;
/// with the weight of 10 on every path it hits a cone at 6 to 9 m/s on every seed
/// (`mpc_rig_sweep`'s `norule=1`). The van passes by 0 to 0.02 m at every speed, so which seed
/// touches is chance at the centimetre, and the test allows 0.03 m (docs/controller.md, "A car
/// the line asks too much of").
#[test]
#[cfg_attr(debug_assertions, ignore = "release only (see the module doc)")]
fn the_van_through_the_lane_change() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let (vehicle, node) = load_setup(
        Some(&root.join("vehicles/van.toml")),
        Some(&root.join("../models/van.toml")),
    )
    .unwrap();
    assert_eq!(node.mpc_lateral_weight_per_m2, None);
    for speed in [5.0, 6.0, 7.0, 8.0, 9.0] {
        for seed in SEEDS {
            let m = mpc_lane_change(&vehicle, &node, speed, seed).metrics;
            let clearance = m.min_cone_clearance_m.unwrap();
            assert!(
                clearance >= -0.03 && (speed > 5.0 || m.clean),
                "the van's MPC at {speed} m/s, seed {seed}: {clearance:.3} m from a cone"
            );
        }
    }
}

/// A slow steering actuator: the CAT Vehicle with a 0.09 s lag instead of its 0.05 s, which its
/// model file declares (`[vehicle] steer_lag_s`): the MPC's command leads its plan by the lag
/// and a tick, and the lane change is clean at 6 and 8 m/s on every seed. With the built-in
/// lead (a 0.05 s lag's) seed 0 touched a cone at both (docs/controller.md, "A slow steering
/// actuator").
#[test]
#[cfg_attr(debug_assertions, ignore = "release only (see the module doc)")]
fn a_slow_steering_actuator_declared_in_the_model_file() {
    let (mut vehicle, _) = load_setup(None, None).unwrap();
    vehicle.steering.lag_s = 0.09;
    let paper = catmodel_host::model_file::paper_path();
    let text = std::fs::read_to_string(&paper)
        .unwrap()
        .replace("\n\n[dynamics]", "\nsteer_lag_s = 0.09\n\n[dynamics]");
    let node = catmodel_host::model_file::parse(&text, &paper)
        .unwrap()
        .node_config();
    assert_eq!(node.steer_lag_s, Some(0.09));
    for speed in [6.0, 8.0] {
        let (clean, _) = clean_at(&vehicle, &node, Controller::Mpc, Receiver::Rtk, speed);
        assert!(
            clean,
            "a 0.09 s steering lag: not clean at {speed} m/s on seeds {SEEDS:?}"
        );
    }
}

/// A car whose speed loop answers faster than its model file's speed model says (the CAT
/// Vehicle's plant with a 0.2 s command delay, a 0.1 s powertrain lag and twice the speed
/// loop's gains, driven with eq 5's 0.42 s delay and 1.2 s poles) holds the loop's 5 m/s: with
/// the speed bias low-passed over 1.5 s the speed stays within 0.45 m/s of it once settled
/// (measured 0.40; 0.27 before the commands' band narrowed on a car its model misses, which
/// settles its launch more slowly) and no command exceeds 6 m/s (5.03); with the bias as
/// measured each tick the plan chases its own corrections (0.83 m/s off, commands up to
/// 8.36 m/s). The CAT Vehicle's own plant: 0.20 m/s (0.17 before the band)
/// (docs/controller.md, "A speed loop the model does not describe").
#[test]
#[cfg_attr(debug_assertions, ignore = "release only (see the module doc)")]
fn a_speed_loop_faster_than_its_model_holds_the_paths_speed() {
    let (mut vehicle, node) = load_setup(None, None).unwrap();
    let sc = &mut vehicle.speed_controller;
    sc.command_delay_s = 0.2;
    sc.actuator_lag_s = 0.1;
    sc.kp_per_s *= 2.0;
    sc.ki_per_s2 *= 2.0;
    let (default_vehicle, _) = load_setup(None, None).unwrap();
    // (largest |speed - 5| once settled, largest command) over the loop, m/s.
    let swing_on = |vehicle: &VehicleConfig, bias_time_constant_s: f32| {
        let mut tuning = catmodel::node::drive::mpc_tuning(&node);
        tuning.speed.bias_time_constant_s = bias_time_constant_s;
        let out = drive_with(
            vehicle,
            &node,
            Controller::MpcTuned(tuning),
            Receiver::Rtk,
            Kind::Loop,
            5.0,
            0,
        );
        let engaged_at = out.samples.iter().find(|s| s.engaged).unwrap().t_s;
        // Settled: 5 s after engagement, up to the loop's last 15 m (its stop).
        let end = out.samples.iter().map(|s| s.station_m).fold(0.0, f64::max) - 15.0;
        let settled = out
            .samples
            .iter()
            .filter(|s| s.engaged && s.t_s > engaged_at + 5.0 && s.station_m < end);
        let speed_error = settled
            .clone()
            .map(|s| (s.truth.speed - 5.0).abs())
            .fold(0.0, f64::max);
        let command = settled
            .filter_map(|s| s.command.speed_cmd_mps)
            .fold(0.0f32, f32::max);
        (speed_error, command)
    };
    let tau = DEFAULT_TUNING.speed.bias_time_constant_s;
    let (error, command) = swing_on(&vehicle, tau);
    assert!(
        error <= 0.45 && command <= 6.0,
        "low-passed bias: speed off by up to {error:.2} m/s, commands up to {command:.2} m/s"
    );
    let (raw_error, raw_command) = swing_on(&vehicle, 0.0);
    assert!(
        raw_error > 0.6 || raw_command > 7.0,
        "the bias as measured holds the speed too ({raw_error:.2} m/s, commands up to \
         {raw_command:.2}): the car no longer shows what the lowpass is for"
    );
    // The car the model describes keeps its speed as well with the lowpass and the band.
    let (error, command) = swing_on(&default_vehicle, tau);
    assert!(
        error <= 0.25 && command <= 6.0,
        "the CAT Vehicle's own plant: {error:.2} m/s off, commands up to {command:.2} m/s"
    );
}

/// The obstacle on the path with the standard receiver (1.2 m horizontal RMS): passed with at
/// least 0.5 m between the body and the obstacle on each of ten seeds (measured: 0.84 m at
/// least, seed 3, whose receiver bias reaches 2.07 m to the side of the obstacle; with the
/// 1.6 m the model file declared before, 0.41 m: docs/controller.md, "The obstacle and the
/// receiver").
#[test]
#[cfg_attr(debug_assertions, ignore = "release only (see the module doc)")]
fn obstacle_passed_with_half_a_metre_standard_receiver() {
    obstacle_passed_on_ten_seeds(None);
}

/// The obstacle with the standard receiver, seeds 0-9: completed, the body 0.5 m from it.
fn obstacle_passed_on_ten_seeds(car: Option<(std::path::PathBuf, std::path::PathBuf)>) {
    for seed in 0..10 {
        let m = drive_car(
            car.clone(),
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

/// A pedestrian crossing the road from the right at 1.5 m/s, setting off as the car comes
/// within 35 m (`catmodel closed-loop --scenario crossing`), the planner sending its circle every
/// tick; the standard receiver, seeds 0-2, both cars. The node measures its motion and passes
/// behind it in its lane: 2.6 m of clearance at least, the lateral error under 0.9 m, no
/// fallback. With the circles taken as standing (the motion's still speed raised past any
/// walk; measured, not kept) both cars swerved 4.3 to 6.7 m into the other lane, fell back
/// (no passage, plans that entered the pedestrian) and passed it by 0.97 to 1.6 m.
#[test]
#[cfg_attr(debug_assertions, ignore = "release only (see the module doc)")]
fn a_pedestrian_crossing_is_passed_behind_in_the_lane() {
    for car in [None, Some(hatchback())] {
        for seed in SEEDS {
            let m = drive_car(
                car.clone(),
                Kind::Crossing,
                Controller::Mpc,
                Receiver::Standard,
                Kind::Crossing.default_speed_mps(),
                seed,
            );
            let which = format!("{car:?}, seed {seed}");
            assert!(m.completed, "{which}: not completed");
            let clearance = m.min_obstacle_clearance_m.unwrap();
            assert!(clearance >= 1.5, "{which}: {clearance} m");
            let lateral = m.lateral_max_m.unwrap();
            assert!(lateral <= 1.5, "{which}: {lateral} m off the path");
            assert!(
                m.fallback_ticks.is_empty(),
                "{which}: {:?}",
                m.fallback_ticks
            );
        }
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

/// The second car: the MPC clean at 12.5 and 14.25 m/s (`catmodel dlc-limits --controllers
/// pure-pursuit,mpc --vehicle host/vehicles/hatchback.toml --model models/hatchback.toml`:
/// MPC 14.44 m/s; 15.19 when the planner's stop reached into the track, 13.06 with the 1.5 s
/// horizon, 12.88 before the corridor gave way to a start
/// outside it, 13.5 m/s before the controllers waited for the heading to settle, which moved
/// the take-over by 0.2 s: the clearances are centimetres at every speed and which speeds pass
/// is chance at that scale, docs/controller.md); pure pursuit with the CAT Vehicle's tuning
/// 6.25 m/s, with a lookahead tuned for this car 14.81 m/s; the obstacle passed with 0.5 m with the
/// standard receiver on each of ten seeds (measured 0.70 m at least, seed 3; 0.29 m with the
/// 1.6 m its file declared before); the loop at 10 m/s within the goal's 0.10 m lateral RMS
/// (measured 0.031 m).
#[test]
#[cfg_attr(debug_assertions, ignore = "release only (see the module doc)")]
fn second_car_goals() {
    let (v, m) = hatchback();
    let (vehicle, node) = load_setup(Some(&v), Some(&m)).unwrap();
    for speed in [12.5, 14.25] {
        let (clean, _) = clean_at(&vehicle, &node, Controller::Mpc, Receiver::Rtk, speed);
        assert!(clean, "MPC not clean at {speed} m/s");
    }
    let car = Some((v, m));
    obstacle_passed_on_ten_seeds(car.clone());
    let fast = drive_car(car, Kind::Loop, Controller::Mpc, Receiver::Rtk, 10.0, 0);
    let rms = fast.lateral_rms_m.unwrap();
    assert!(fast.completed && rms <= 0.10, "10 m/s: {rms} m");
}

/// The second car with a receiver slower than its own: the same uncorrected noise (1.2 m RMS)
/// at `rate_hz` instead of 100 Hz, its vehicle and model files edited to say so (into `dir`).
fn hatchback_at(rate_hz: f64, dir: &std::path::Path) -> (VehicleConfig, NodeConfig) {
    let (v, m) = hatchback();
    std::fs::create_dir_all(dir).unwrap();
    let edit = |from: &std::path::Path, to: &str, changes: &[(&str, String)]| {
        let mut text = std::fs::read_to_string(from).unwrap();
        for (old, new) in changes {
            assert_eq!(text.matches(old).count(), 1, "{old} in {}", from.display());
            text = text.replace(old, new);
        }
        let to = dir.join(to);
        std::fs::write(&to, text).unwrap();
        to
    };
    let period = format!("period_s = {} # paper", 1.0 / rate_hz);
    let v = edit(
        &v,
        "vehicle.toml",
        &[("period_s = 0.01             # paper", period)],
    );
    // The node calls GNSS lost after gnss_lost_s without a fix: more than a 1 Hz period.
    let m = edit(
        &m,
        "model.toml",
        &[
            (
                "gnss_rate_hz = 100.0",
                format!("gnss_rate_hz = {rate_hz:.1}"),
            ),
            ("gnss_lost_s = 2.0", "gnss_lost_s = 5.0".to_string()),
        ],
    );
    let setup = load_setup(Some(&v), Some(&m)).unwrap();
    assert_eq!(setup.1.estimator.gnss_period_s, (1.0 / rate_hz) as f32);
    setup
}

fn drive_setup(
    vehicle: &VehicleConfig,
    node: &NodeConfig,
    kind: Kind,
    speed: f64,
    seed: u64,
) -> RunOutput {
    drive_with(
        vehicle,
        node,
        Controller::Mpc,
        Receiver::Standard,
        kind,
        speed,
        seed,
    )
}

/// `kind` at `speed` with `controller` and `receiver` on seed `seed`.
fn drive_with(
    vehicle: &VehicleConfig,
    node: &NodeConfig,
    controller: Controller,
    receiver: Receiver,
    kind: Kind,
    speed: f64,
    seed: u64,
) -> RunOutput {
    let course = scenario::course(kind, &vehicle.body, speed);
    let mut driver = NodeDriver::new(node.clone(), controller);
    let options = RunOptions::new(seed, receiver);
    run(vehicle, &course, &mut driver, "", &options)
}

/// The MPC through the double lane change, RTK receiver.
fn mpc_lane_change(vehicle: &VehicleConfig, node: &NodeConfig, speed: f64, seed: u64) -> RunOutput {
    drive_with(
        vehicle,
        node,
        Controller::Mpc,
        Receiver::Rtk,
        Kind::DoubleLaneChange,
        speed,
        seed,
    )
}

/// A long, heavy car with a slow, noisy receiver (`host/tests/data/long-heavy-5hz.toml`: a
/// random plant, 3.79 m wheelbase, 3.4 t, a 5 Hz receiver; described to the node as its
/// model file would) meets the obstacle, seed 0. With a 2 s horizon it swerved late: once beside
/// the obstacle its plans kept entering the inflated circle (status 3, the obstacle not
/// cleared, for 129 ticks) and it passed 1.81 m from it braking along the lane (before that
/// fallback it turned into the obstacle and stopped 1.15 m from it, docs/findings.md). Its
/// steering is slow for its wheelbase, and its horizon is 3 s now (the steering plan's later
/// stages longer, `mpc::StageClock`): it swerves in time and passes 2.40 m from it without a
/// fallback. (The fallback's lane hold: `mpc_closed_loop::an_obstacle_beside_a_slow_car_is_braked_for_along_the_lane`.)
#[test]
#[cfg_attr(debug_assertions, ignore = "release only (see the module doc)")]
fn a_long_heavy_car_swerves_in_time() {
    let car =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/long-heavy-5hz.toml");
    let (vehicle, node) = load_setup(Some(&car), None).unwrap();
    let m = obstacle(&vehicle, &node, 0);
    assert_eq!(m.status_ticks[3], 0, "the fallback was taken: {m:?}");
    assert!(m.completed, "{m:?}");
    let clearance = m.min_obstacle_clearance_m.unwrap_or(f64::NAN);
    assert!(clearance >= 2.0, "body {clearance:.2} m from the obstacle");
}

/// A short, light car (`tests/data/short-light-car.toml`: 1.87 m wheelbase, 2.7 m body,
/// 800 kg) at 4 and 6 m/s: its plans turned it 90 degrees in their horizon's last second to
/// "pass" the obstacle (the stages' stations advance along the path whatever the heading), put
/// the swerve off from tick to tick, and the car braked 0.11 m short of the obstacle (RTK, seed
/// 0, 4 m/s) or hit it (-0.31 m, standard receiver, seed 2; -0.27 m at 6 m/s, seed 1). With the
/// plan's heading error bounded while an obstacle is in the problem (`lateral::heading_row`)
/// it swerves in time and passes by 2.4-2.8 m (docs/findings.md).
#[test]
#[cfg_attr(debug_assertions, ignore = "release only (see the module doc)")]
fn a_short_light_car_swerves_early_round_the_obstacle() {
    let car =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/short-light-car.toml");
    let (vehicle, node) = load_setup(Some(&car), None).unwrap();
    for (receiver, speed, seed) in [
        (Receiver::Rtk, 4.0, 0),
        (Receiver::Standard, 4.0, 2),
        (Receiver::Standard, 6.0, 1),
    ] {
        let m = drive_with(
            &vehicle,
            &node,
            Controller::Mpc,
            receiver,
            Kind::Obstacle,
            speed,
            seed,
        )
        .metrics;
        let clearance = m.min_obstacle_clearance_m.unwrap_or(f64::NAN);
        assert!(
            m.completed && m.status_ticks[3] == 0 && clearance >= 1.0,
            "{receiver:?} {speed} m/s seed {seed}: {clearance:.2} m from the obstacle: {m:?}"
        );
    }
}

/// A long car with slow steering (`tests/data/long-slow-steering-20hz.toml`: 3.65 m wheelbase,
/// 71 %/s) whose plan the receiver's noise put into the inflated obstacle: the fallback braked
/// it to 2 m/s beside the obstacle, 3.4 m from its path. The return from there was asked of it
/// within 3 s: at a crawl that is 0.5 rad of heading, the plan steered to 90 % of the lock, the
/// car sped up with 0.6 rad and swung through the path and 3.1 m off the road, then back 4.3 m.
/// The return no faster than 0.2 rad of heading at the speed it has: 0.82 m over the road's
/// edge (docs/findings.md). Seed 9 held the fallback for 1.8 s, 3.4-3.9 m beside the path,
/// and its return left the road by 0.70 m. Its horizon is 2.4 s now (`mpc::StageClock`): its
/// plans clear the obstacle, it takes no fallback and leaves the road by 0.29 m (the
/// receiver's bias puts the estimate inside it).
#[test]
#[cfg_attr(debug_assertions, ignore = "release only (see the module doc)")]
fn a_long_car_with_slow_steering_passes_the_obstacle_without_a_swing() {
    let car = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/long-slow-steering-20hz.toml");
    let (vehicle, node) = load_setup(Some(&car), None).unwrap();
    let m = obstacle(&vehicle, &node, 9);
    assert_eq!(m.status_ticks[3], 0, "the fallback was taken: {m:?}");
    assert!(m.completed, "{m:?}");
    let exit = m.corridor_exit_m.unwrap_or(f64::NAN);
    assert!(exit < 0.5, "{exit:.2} m off the road: {m:?}");
}

/// The black-box review's pickup (`host/vehicles/pickup.toml`: 2.05 m wide, the CAT Vehicle's
/// 2.0 m position bound) has 2.15 m between the road's edge and the inflated obstacle: room for
/// its body, not for the body and the corner rows' 0.15 m margin. It took that passage, fought
/// the corridor beside the obstacle and passed it by 0.29 m on seed 3. It stops before it
/// now, no passage, on the seed that passed closest and on one that passed wide (docs/findings.md).
#[test]
#[cfg_attr(debug_assertions, ignore = "release only (see the module doc)")]
fn the_pickup_stops_before_an_obstacle_its_plan_cannot_pass() {
    let car = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("vehicles/pickup.toml");
    let (vehicle, node) = load_setup(Some(&car), None).unwrap();
    for seed in [0, 3] {
        let out = obstacle_run(&vehicle, &node, seed);
        let m = &out.metrics;
        assert!(!m.completed, "seed {seed}: passed: {m:?}");
        assert!(m.status_ticks[3] > 0, "seed {seed}: {m:?}");
        // And it says why on the bus: every fallback tick names the missing passage.
        assert_eq!(
            m.fallback_ticks
                .keys()
                .map(String::as_str)
                .collect::<Vec<_>>(),
            ["no_passage"],
            "seed {seed}: {m:?}"
        );
        let clearance = m.min_obstacle_clearance_m.unwrap_or(f64::NAN);
        assert!(
            clearance >= 1.0,
            "seed {seed}: stopped {clearance:.2} m from it"
        );
        // Stopped and kept stopped: the last second at rest, commanded 0.
        let end = out.samples.last().map_or(0.0, |s| s.t_s) - 1.0;
        assert!(out
            .samples
            .iter()
            .filter(|s| s.t_s >= end)
            .all(|s| s.truth.speed < 0.05 && s.command.speed_cmd_mps == Some(0.0)));
    }
}

/// The obstacle at its default speed on seed `seed` (the car's own receiver).
fn obstacle_run(vehicle: &VehicleConfig, node: &NodeConfig, seed: u64) -> RunOutput {
    drive_setup(
        vehicle,
        node,
        Kind::Obstacle,
        Kind::Obstacle.default_speed_mps(),
        seed,
    )
}

/// [`obstacle_run`]'s metrics.
fn obstacle(vehicle: &VehicleConfig, node: &NodeConfig, seed: u64) -> Metrics {
    obstacle_run(vehicle, node, seed).metrics
}

/// Steering activity while engaged: the mean |change of the steering command| per second, %/s.
fn steering_activity(out: &RunOutput) -> f64 {
    let steer: Vec<f64> = out
        .samples
        .iter()
        .filter(|s| s.engaged)
        .filter_map(|s| s.command.steer_cmd_pct.map(f64::from))
        .collect();
    steer.windows(2).map(|w| (w[1] - w[0]).abs()).sum::<f64>()
        / steer.len().saturating_sub(1).max(1) as f64
        / 0.02
}

/// The CAT Vehicle on the loop with the standard receiver (100 Hz, 0.3 m white noise and a
/// 0.8 m bias per axis). The lowpass's output moves by millimetres per fix, its noise shared
/// over its 0.3 s window, and the control pose measured the receiver's noise per fix: it took
/// it for a survey-grade one and the controllers steered at the noise left after the lowpass
/// (the steering command moved 29-40 %/s on average at 3 and 8 m/s on these seeds, against
/// 7-8 %/s with RTK at 10 m/s). The noise measured over the window
/// (`catmodel::node::smoothing`): 17-22 %/s, the lateral RMS the same (the bias's, 0.34-1.04
/// m); docs/findings.md.
#[test]
#[cfg_attr(debug_assertions, ignore = "release only (see the module doc)")]
fn a_fast_noisy_receiver_does_not_make_the_car_weave() {
    let (vehicle, node) = load_setup(None, None).unwrap();
    for speed in [3.0, 8.0] {
        for seed in 0..3 {
            let out = drive_setup(&vehicle, &node, Kind::Loop, speed, seed);
            assert!(out.metrics.clean, "{speed} m/s, seed {seed}");
            let rate = steering_activity(&out);
            println!("loop at {speed} m/s, seed {seed}: steering moves {rate:.1} %/s");
            assert!(
                rate < 26.0,
                "loop at {speed} m/s, seed {seed}: steering moves {rate:.0} %/s"
            );
        }
    }
}

/// A noisy receiver is smoothed by as much as the dead reckoning's drift allows: the drift over
/// the lowpass's window is the heading's error times the distance driven, and where the dead
/// reckoning drifts less than the heading filter's variance says, the drift measured over a
/// longer lag (`catmodel::node::smoothing`). With the drift allowed for at every speed as at
/// speed (0.05 m^2/s), the steering command moved, on the loop, seeds 0-2: the standard
/// receiver at 2 m/s 16-22 %/s, a receiver with white noise alone (0.3 m per axis, the bias
/// 0.01 m) at 3 m/s 27-35 %/s and at 8 m/s 24-31 %/s; with the drift from the distance 10-13,
/// 7-10 and 20-29 %/s; with the measured drift as well 10-13, 7-8 and 12-14 %/s
/// (docs/controller.md, "Slow receivers").
#[test]
#[cfg_attr(debug_assertions, ignore = "release only (see the module doc)")]
fn a_noisy_receiver_is_smoothed_most_where_the_car_moves_least() {
    let (vehicle, node) = load_setup(None, None).unwrap();
    let mut white = vehicle.clone();
    white.sensors.gnss.bias_sigma_m = 0.01;
    for (name, vehicle, speed) in [
        ("standard", &vehicle, 2.0),
        ("white noise", &white, 3.0),
        ("white noise", &white, 8.0),
    ] {
        for seed in 0..3 {
            let out = drive_setup(vehicle, &node, Kind::Loop, speed, seed);
            assert!(out.metrics.clean, "{name}, seed {seed}");
            let rate = steering_activity(&out);
            println!("{name} receiver, loop at {speed} m/s, seed {seed}: {rate:.1} %/s");
            assert!(
                rate < 16.0,
                "{name} receiver, loop at {speed} m/s, seed {seed}: steering moves {rate:.0} %/s"
            );
        }
    }
}

/// The hatchback at 5 Hz. Each fix moves the estimate by up to a metre (the filter's window
/// holds three fixes); the control pose spreads those jumps by the scatter it measures
/// (`catmodel::node::smoothing`). Without it the MPC steered at every jump: on the loop at
/// 10 m/s the steering command moved at 67-68 %/s on average (the same car at 100 Hz: 9 %/s),
/// on the obstacle seed 6 of these ten drove into it (-0.46 m) and seed 3 passed it by 0.33 m.
/// Measured with it: 29-33 %/s; every seed passes (the closest, seed 3, by 0.72 m;
/// docs/controller.md, "Slow receivers").
#[test]
#[cfg_attr(debug_assertions, ignore = "release only (see the module doc)")]
fn second_car_with_a_slow_noisy_receiver() {
    let dir = std::env::temp_dir().join(format!("catmodel-5hz-{}", std::process::id()));
    let (vehicle, node) = hatchback_at(5.0, &dir);
    for seed in 0..10 {
        let m = obstacle(&vehicle, &node, seed);
        assert!(m.clean, "obstacle, seed {seed}: {m:?}");
    }
    for seed in 0..3 {
        let out = drive_setup(&vehicle, &node, Kind::Loop, 10.0, seed);
        assert!(out.metrics.completed, "loop, seed {seed}");
        let rate = steering_activity(&out);
        assert!(
            rate < 45.0,
            "loop, seed {seed}: steering moves {rate:.0} %/s"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// The hatchback at 1 Hz (a low-cost receiver's default rate): the filter's window is one fix
/// and the first heading, from the first chord, was up to 0.4 rad out when the controller took
/// over (0.36 rad on these seeds); it steered at an error of its own making and lost the path
/// on seeds 6 and 8 of these ten. The controllers now wait for the heading to settle
/// (`HeadingSettle`: three time constants of its correction, 6 s at 1 Hz,
/// while the driver launches the car): the heading is within 0.1 rad of the truth when they
/// take over, and every seed passes the obstacle but seed 8, which leaves the road.
#[test]
#[cfg_attr(debug_assertions, ignore = "release only (see the module doc)")]
fn second_car_with_a_1_hz_receiver_waits_for_its_heading() {
    let dir = std::env::temp_dir().join(format!("catmodel-1hz-{}", std::process::id()));
    let (vehicle, node) = hatchback_at(1.0, &dir);
    let mut worst = 0.0f64;
    for seed in 0..10 {
        let out = obstacle_run(&vehicle, &node, seed);
        // Seed 8 left the road (lateral 6.7 m, the body 2.33 m outside the corridor) until
        // the controller returned to a corridor it starts outside of at a bounded lateral
        // acceleration (`lateral::relax_corridor`; docs/findings.md): the receiver's 2 m
        // bias put the estimate outside the corridor when the controller took over, and the
        // corridor's exact penalty swung the car into a limit cycle.
        assert!(
            out.metrics.clean,
            "obstacle, seed {seed}: {:?}",
            out.metrics
        );
        let first = out.samples.iter().find(|s| s.engaged).unwrap();
        let (_, _, heading) = first.estimate.unwrap();
        let error = (heading - first.truth.heading + std::f64::consts::PI)
            .rem_euclid(std::f64::consts::TAU)
            - std::f64::consts::PI;
        worst = worst.max(error.abs());
    }
    // Measured 0.085 rad at most over these seeds (the course's noise at 1 Hz); 0.36 rad
    // without the wait.
    assert!(worst < 0.1, "engaged with the heading {worst:.3} rad out");
    std::fs::remove_dir_all(&dir).ok();
}

/// A car held at a crawl with a 5 Hz receiver that sends no course of its own: the track's
/// chords over 0.6 s are 1.1 m long at 1.9 m/s, shorter than the 1.5 m the estimator corrects
/// the heading by, so the first heading (from a longer chord of the first fixes) is never
/// corrected there. The heading's settling counted the ticks at the course speed, and a
/// random SIL sweep's truck held at 1.9 m/s was handed to the controller with its heading
/// 0.53 rad off and driven 7 m out of its corridor (docs/findings.md). Only the ticks that
/// corrected the heading count now: at 1.9 m/s the car is never taken over (status 3,
/// `heading_settling`); launched at 3 m/s it is, with the heading within 0.1 rad.
#[test]
#[cfg_attr(debug_assertions, ignore = "release only (see the module doc)")]
fn a_heading_no_chord_corrects_is_not_settled_at_a_crawl() {
    use catmodel::can::codec::{ControlStatus, FallbackCause};
    let dir = std::env::temp_dir().join(format!("catmodel-crawl-{}", std::process::id()));
    let (vehicle, node) = hatchback_at(5.0, &dir);
    let course = scenario::course(Kind::Loop, &vehicle.body, 8.0);
    for (launch_mps, engages) in [(1.9, false), (3.0, true)] {
        let mut driver = NodeDriver::new(node.clone(), Controller::Mpc);
        let mut options = RunOptions::new(0, Receiver::Standard);
        options.max_time_s = 30.0;
        options.launch_mps = launch_mps;
        let out = run(&vehicle, &course, &mut driver, "", &options);
        let first = out.samples.iter().find(|s| s.engaged);
        assert_eq!(first.is_some(), engages, "launched at {launch_mps} m/s");
        match first {
            Some(first) => {
                let (_, _, heading) = first.estimate.unwrap();
                let error = (heading - first.truth.heading + std::f64::consts::PI)
                    .rem_euclid(std::f64::consts::TAU)
                    - std::f64::consts::PI;
                assert!(error.abs() < 0.1, "engaged {error:.3} rad out");
            }
            None => {
                // With a pose, every tick after the first seconds waits for the heading.
                let last = out.samples.last().unwrap();
                assert!(last.t_s > 29.0 && last.estimate.is_some(), "{:?}", last.t_s);
                assert_eq!(last.command.status, ControlStatus::Fallback);
                assert_eq!(last.command.fallback, FallbackCause::HeadingSettling);
            }
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// The tables of docs/controller.md, "Slow receivers", measured again: the hatchback with its
/// receiver's noise at 1 to 20 Hz (plant and model file), the obstacle on seeds 0-9 (0-14 at 1
/// and 5 Hz) and the loop at 10 m/s at 5 Hz. Prints; `cargo test --release -p catmodel-host
/// --test closed_loop_goals -- --ignored slow_receiver_tables --nocapture` (about 5 minutes).
#[test]
#[ignore = "measurement; prints the tables"]
fn slow_receiver_tables() {
    for rate in [1.0, 2.0, 5.0, 10.0, 20.0] {
        let dir =
            std::env::temp_dir().join(format!("catmodel-rates-{}-{rate}", std::process::id()));
        let (vehicle, node) = hatchback_at(rate, &dir);
        let seeds = if rate == 1.0 || rate == 5.0 { 15 } else { 10 };
        let clearances: Vec<f64> = (0..seeds)
            .map(|seed| {
                let m = obstacle(&vehicle, &node, seed);
                if m.clean {
                    m.min_obstacle_clearance_m.unwrap_or(f64::NAN)
                } else {
                    f64::NEG_INFINITY
                }
            })
            .collect();
        let passed = |n: usize| clearances.iter().take(n).filter(|c| c.is_finite()).count();
        let closest = clearances.iter().copied().fold(f64::INFINITY, f64::min);
        println!(
            "{rate} Hz obstacle: seeds 0-9 passed {}, seeds 0-{} passed {}, closest {closest:.2} m ({clearances:.2?})",
            passed(10),
            seeds - 1,
            passed(seeds as usize),
        );
        if rate == 5.0 {
            for seed in 0..3 {
                let out = drive_setup(&vehicle, &node, Kind::Loop, 10.0, seed);
                let activity = steering_activity(&out);
                println!(
                    "5 Hz loop at 10 m/s, seed {seed}: lateral RMS {:.2} m, steering activity {activity:.0} %/s",
                    out.metrics.lateral_rms_m.unwrap_or(f64::NAN)
                );
            }
        }
        std::fs::remove_dir_all(&dir).ok();
    }
}

/// Cars nothing was tuned on: plants drawn at random around the hatchback (seeded; wheelbase
/// 2.3-3.8 m, 0.9-3.5 t, width 1.6-2.1 m, steering 40-120 %/s at 28-40 deg with a lag of
/// 0.03-0.1 s, a speed loop's
/// delay of 0.2-0.8 s, receivers at 5-100 Hz with the antenna anywhere along the car; the
/// oversteering ones, which a model file refuses, are drawn again), each described to the node
/// as its model file would (`closed_loop::model_file_for`). Prints, per car, the double lane
/// change at 6 / 8 / 10 / 12 m/s (clean seeds of 0 and 1, RTK), the obstacle with the standard
/// receiver and the loop at 10 m/s with RTK, each in brackets again with the lateral weight at 1
/// on every path (docs/controller.md, "What is left").
/// `[PLANTS_SEED=N] [PLANTS_OUT=DIR] cargo test --release -p catmodel-host --test closed_loop_goals -- --ignored random_plants --nocapture`
#[test]
#[ignore = "measurement; prints the table"]
fn random_plants() {
    let (base, _) = hatchback();
    let base = VehicleConfig::load(&base).unwrap();
    // Another draw of ten: PLANTS_SEED=N (any u64; the table in the docs is the default's).
    let mut state = std::env::var("PLANTS_SEED")
        .ok()
        .and_then(|s| s.parse::<u64>().ok())
        .unwrap_or(0x2545_f491_4f6c_dd1d_u64);
    let mut uniform = |lo: f64, hi: f64| {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        lo + (hi - lo) * ((state >> 11) as f64 / (1u64 << 53) as f64)
    };
    let mut cars = Vec::new();
    while cars.len() < 10 {
        let mut v = base.clone();
        let c = &mut v.chassis;
        c.wheelbase_m = (uniform(2.3, 3.8) * 1e3).round() / 1e3;
        c.cg_to_front_m = (c.wheelbase_m * uniform(0.38, 0.52) * 1e3).round() / 1e3;
        c.cg_to_rear_m = c.wheelbase_m - c.cg_to_front_m;
        c.mass_kg = uniform(900.0, 3500.0);
        c.yaw_inertia_kg_m2 = c.mass_kg * c.cg_to_front_m * c.cg_to_rear_m * uniform(0.9, 1.1);
        c.cg_height_m = uniform(0.45, 1.0);
        c.max_steer_deg = uniform(28.0, 40.0);
        v.body.width_m = uniform(1.6, 2.1);
        c.track_m = v.body.width_m - 0.25;
        v.body.length_m = c.wheelbase_m + uniform(1.2, 2.4);
        v.body.rear_overhang_m = uniform(0.5, 1.2);
        v.tyre_front.cornering_stiffness_n_per_rad = c.mass_kg * uniform(40.0, 60.0);
        v.tyre_rear.cornering_stiffness_n_per_rad = c.mass_kg * uniform(45.0, 70.0);
        v.steering.rate_limit_pct_per_s = uniform(40.0, 120.0);
        v.steering.lag_s = uniform(0.03, 0.1);
        v.speed_controller.command_delay_s =
            [0.2, 0.3, 0.4, 0.5, 0.6, 0.8][uniform(0.0, 5.99) as usize];
        v.speed_controller.actuator_lag_s = uniform(0.2, 0.6);
        v.sensors.gnss.period_s = [0.01, 0.02, 0.05, 0.1, 0.2][uniform(0.0, 4.99) as usize];
        v.sensors.gnss.antenna_ahead_of_rear_axle_m = uniform(-0.5, v.chassis.wheelbase_m + 0.5);
        if v.validate().is_ok() && v.understeer_s2_per_m2() >= 0.0 {
            cars.push(v);
        }
    }
    let out = std::env::var("PLANTS_OUT")
        .ok()
        .map(std::path::PathBuf::from);
    for (i, v) in cars.iter().enumerate() {
        if let Some(dir) = &out {
            // Each car's plant file, for `catmodel closed-loop --vehicle DIR/car-N.toml`.
            std::fs::create_dir_all(dir).unwrap();
            let text = toml::to_string(v).unwrap();
            std::fs::write(dir.join(format!("car-{i}.toml")), text).unwrap();
        }
        let node = catmodel_host::closed_loop::model_file_for(v)
            .unwrap()
            .node_config();
        let run_with = |controller, kind, speed, seed, receiver| {
            drive_with(v, &node, controller, receiver, kind, speed, seed).metrics
        };
        let run_one =
            |kind, speed, seed, receiver| run_with(Controller::Mpc, kind, speed, seed, receiver);
        // The car's own tuning with the lateral weight at 1 on every path (docs/controller.md,
        // "What is left").
        let mut light = catmodel::node::drive::mpc_tuning(&node);
        light.weights.lateral_per_m2 = 1.0;
        light.line_rule = None;
        let mut line = format!(
            "car {i}: L {:.2} m, {:.0} kg, {:.2} m wide, {:.0} %/s, {:.0} Hz |",
            v.chassis.wheelbase_m,
            v.chassis.mass_kg,
            v.body.width_m,
            v.steering.rate_limit_pct_per_s,
            1.0 / v.sensors.gnss.period_s
        );
        for speed in [6.0, 8.0, 10.0, 12.0] {
            let clean = (0..2)
                .filter(|&s| run_one(Kind::DoubleLaneChange, speed, s, Receiver::Rtk).clean)
                .count();
            let light_clean = (0..2)
                .filter(|&s| {
                    run_with(
                        Controller::MpcTuned(light),
                        Kind::DoubleLaneChange,
                        speed,
                        s,
                        Receiver::Rtk,
                    )
                    .clean
                })
                .count();
            line += &format!(" dlc {speed}: {clean}/2 ({light_clean}/2)");
        }
        let o = run_one(
            Kind::Obstacle,
            Kind::Obstacle.default_speed_mps(),
            0,
            Receiver::Standard,
        );
        let l = run_one(Kind::Loop, 10.0, 0, Receiver::Rtk);
        let light_o = run_with(
            Controller::MpcTuned(light),
            Kind::Obstacle,
            Kind::Obstacle.default_speed_mps(),
            0,
            Receiver::Standard,
        );
        let light_l = run_with(
            Controller::MpcTuned(light),
            Kind::Loop,
            10.0,
            0,
            Receiver::Rtk,
        );
        let passed = |m: &catmodel_host::closed_loop::metrics::Metrics| {
            if m.clean {
                "passed"
            } else {
                "NOT passed"
            }
        };
        line += &format!(
            " | obstacle {} {:.2} m ({} {:.2} m) | loop {:.3} m ({:.3} m)",
            passed(&o),
            o.min_obstacle_clearance_m.unwrap_or(f64::NAN),
            passed(&light_o),
            light_o.min_obstacle_clearance_m.unwrap_or(f64::NAN),
            l.lateral_rms_m.unwrap_or(f64::NAN),
            light_l.lateral_rms_m.unwrap_or(f64::NAN)
        );
        println!("{line}");
    }
}

/// A planner that asks for more than the tyres give: the loop's 20 m arcs at 14 and 20 m/s ask
/// 9.8 and 20 m/s^2, past the CAT Vehicle's grip (friction 0.9). With the lateral limit its
/// model file declares (`[control] max_lateral_accel_mps2 = 5.9`) the speed envelope slows the
/// car for the arcs and it keeps its corridor (measured: 0.16-0.19 m of lateral RMS, 0.41 m at
/// most, completed); without it, the car spins off the first arc (5.5 m of lateral RMS, 10 m out
/// of its corridor, not completed). docs/controller.md, "A turn faster than the tyres".
#[test]
#[cfg_attr(debug_assertions, ignore = "release only (see the module doc)")]
fn a_loop_faster_than_the_tyres_is_slowed_to_their_limit() {
    let (vehicle, node) = load_setup(None, None).unwrap();
    assert_eq!(node.max_lateral_accel_mps2, Some(5.9));
    for speed in [14.0, 20.0] {
        let m = drive_with(
            &vehicle,
            &node,
            Controller::Mpc,
            Receiver::Rtk,
            Kind::Loop,
            speed,
            0,
        )
        .metrics;
        let (rms, exit) = (m.lateral_rms_m.unwrap(), m.corridor_exit_m.unwrap_or(0.0));
        assert!(
            m.completed && rms <= 0.25 && exit <= 0.0,
            "{speed} m/s: completed {}, lateral RMS {rms} m, out of the corridor by {exit} m",
            m.completed
        );
    }
    // The same car without the limit: the test can tell.
    let unlimited = NodeConfig {
        max_lateral_accel_mps2: None,
        ..node
    };
    let m = drive_with(
        &vehicle,
        &unlimited,
        Controller::Mpc,
        Receiver::Rtk,
        Kind::Loop,
        14.0,
        0,
    )
    .metrics;
    assert!(
        !m.completed || m.corridor_exit_m.unwrap_or(0.0) > 1.0,
        "without the limit at 14 m/s: completed {}, out of the corridor by {:?} m",
        m.completed,
        m.corridor_exit_m
    );
}
