//! The plant simulator: determinism, physics against independent relations, sensor statistics.
use catmodel_host::logcsv::{self, LogRow, TruthRow};
use catmodel_host::sim::config::VehicleConfig;
use catmodel_host::sim::scenario::{Scenario, Segment, SteerProfile, SCENARIO_NAMES};
use catmodel_host::sim::{self, geo, SimOptions};
use catmodel_host_tests::{assert_allclose, isclose, load_reference};

fn run(name: &str, seed: u64) -> sim::SimOutput {
    sim::run_named(
        name,
        None,
        &SimOptions {
            seed,
            ..Default::default()
        },
    )
    .expect("built-in scenario")
}

/// The second car's vehicle file.
fn polo() -> VehicleConfig {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../host/vehicles/vw-polo.toml");
    VehicleConfig::load(&path).expect("vehicle file loads")
}

/// A built-in scenario on the car `cfg`.
fn run_on(cfg: &VehicleConfig, name: &str, seed: u64) -> sim::SimOutput {
    sim::simulate(
        &Scenario::builtin(name).expect("built-in scenario"),
        cfg,
        &SimOptions {
            seed,
            ..Default::default()
        },
    )
}

fn exact(segments: Vec<Segment>) -> Scenario {
    Scenario {
        name: "test".into(),
        initial_heading_rad: 0.4,
        segments,
    }
}

fn hold(duration_s: f64, speed_mps: f64, steer_pct: f64) -> Segment {
    Segment {
        duration_s,
        speed_mps,
        steer: SteerProfile::Hold(steer_pct),
    }
}

fn log_bytes(rows: &[LogRow]) -> Vec<u8> {
    let mut b = Vec::new();
    logcsv::write_log_to(&mut b, rows).expect("writable");
    b
}

fn truth_bytes(rows: &[TruthRow]) -> Vec<u8> {
    let mut b = Vec::new();
    logcsv::write_truth_to(&mut b, rows).expect("writable");
    b
}

/// The TORC steady-state relation (CAT Vehicle ROS package `jmscslgroup/catvehicle`,
/// `distanceEstimatorSteeringBased.cpp`, "from TORC"), rear-axle radius: R = L / tan(delta / (1 + K v^2)).
fn torc_radius_m(steer_pct: f64, speed_mps: f64) -> f64 {
    let delta = steer_pct / 100.0 * 35.5_f64.to_radians();
    2.62 / (delta / (1.0 + 0.0015 * speed_mps * speed_mps)).tan()
}

#[test]
fn vehicle_file_is_the_default_and_matches_the_understeer_term() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../host/vehicles/cat-vehicle.toml");
    let file = VehicleConfig::load(&path).expect("vehicle file loads");
    assert_eq!(file, VehicleConfig::default());
    // K = m (b/Cf - a/Cr) / L^2 from the stiffnesses vs the published 0.0015 s^2/m^2 (rtol 1 %).
    assert!(
        isclose(file.understeer_s2_per_m2(), 0.0015, 0.01, 0.0),
        "{}",
        file.understeer_s2_per_m2()
    );
    let mut bad = VehicleConfig::default();
    bad.chassis.cg_to_front_m = 1.5;
    assert!(bad.validate().is_err());
    assert!(VehicleConfig::from_toml_str("[chassis]\nwheelbase_m = 2.6\n").is_err());
}

/// The second car differs from the CAT Vehicle where the issue asks: wheelbase, antenna
/// position, receiver rate (10 Hz), speed-loop delay and tyres; and its own understeer term
/// follows from its tyres as the comment in the file says.
#[test]
fn second_vehicle_file_is_another_car() {
    let (cat, p) = (VehicleConfig::default(), polo());
    assert_ne!(p.chassis.wheelbase_m, cat.chassis.wheelbase_m);
    assert_ne!(
        p.sensors.gnss.antenna_ahead_of_rear_axle_m,
        cat.sensors.gnss.antenna_ahead_of_rear_axle_m
    );
    assert_eq!(p.sensors.gnss.period_s, 0.1);
    assert_ne!(
        p.speed_controller.command_delay_s,
        cat.speed_controller.command_delay_s
    );
    assert_ne!(p.tyre_front, cat.tyre_front);
    assert_ne!(p.tyre_rear, cat.tyre_rear);
    assert!(
        isclose(p.understeer_s2_per_m2(), 0.00195, 0.01, 0.0),
        "{}",
        p.understeer_s2_per_m2()
    );
    // Receivers from 1 to 100 Hz, nothing else.
    for (period_s, ok) in [(0.01, true), (1.0, true), (0.009, false), (1.5, false)] {
        let mut c = p.clone();
        c.sensors.gnss.period_s = period_s;
        assert_eq!(c.validate().is_ok(), ok, "period {period_s} s");
    }
}

#[test]
fn same_seed_same_bytes_different_seed_different() {
    let a = run("smoke", 7);
    let b = run("smoke", 7);
    let c = run("smoke", 8);
    assert_eq!(log_bytes(&a.log), log_bytes(&b.log));
    assert_eq!(truth_bytes(&a.truth), truth_bytes(&b.truth));
    assert_ne!(log_bytes(&a.log), log_bytes(&c.log));
    assert_ne!(truth_bytes(&a.truth), truth_bytes(&c.truth));
    // Pinned digest of one run: catches platform-dependent maths (std transcendental functions
    // would differ in the last bits between C libraries) as well as unintended changes.
    let digest = |bytes: &[u8]| {
        bytes.iter().fold(0xcbf2_9ce4_8422_2325_u64, |h, &x| {
            (h ^ x as u64).wrapping_mul(0x0100_0000_01b3)
        })
    };
    let got = digest(&log_bytes(&a.log));
    assert_eq!(
        got, 0x32dd_2465_fe3f_3388,
        "smoke seed 7 log digest {got:#018x}: update this golden value only for an intended change of the simulator"
    );
}

#[test]
fn steady_state_radius_follows_the_understeer_relation_at_two_speeds() {
    let cfg = VehicleConfig::default();
    // (steer %, speed m/s): lateral acceleration about 1.2 and 2.0 m/s^2, in the tyres' linear range.
    for (steer_pct, speed_mps) in [(20.0, 5.0), (-10.0, 10.0)] {
        let scenario = exact(vec![hold(40.0, speed_mps, steer_pct)]);
        let out = sim::simulate(
            &scenario,
            &cfg,
            &SimOptions {
                vary_commands: false,
                ..Default::default()
            },
        );
        let tail: Vec<&TruthRow> = out.truth.iter().filter(|r| r.t >= 30.0).collect();
        let n = tail.len() as f64;
        let speed = tail.iter().map(|r| r.speed).sum::<f64>() / n;
        let yaw_rate = tail.iter().map(|r| r.yaw_rate).sum::<f64>() / n;
        assert!(
            yaw_rate.signum() == steer_pct.signum(),
            "positive steering turns right (clockwise)"
        );
        let radius = speed / yaw_rate.abs();
        let expected = torc_radius_m(steer_pct.abs(), speed);
        println!("steer {steer_pct} % at {speed:.3} m/s: R {radius:.3} m, TORC {expected:.3} m");
        // rtol 0.5 %: the TORC relation is the linear-tyre, small-angle steady state; the plant has
        // magic-formula tyres (about 1.5 % stiffness loss at 2 m/s^2, which moves R by ~0.2 %)
        // and exact trigonometry. Measured: 0.07 % and 0.06 %.
        assert!(
            isclose(radius, expected, 0.005, 0.0),
            "steer {steer_pct} % at {speed} m/s: R {radius} m, TORC {expected} m"
        );
        // ... and the understeer matters here: the kinematic radius is clearly different.
        let kinematic = torc_radius_m(steer_pct.abs(), 0.0);
        assert!(
            !isclose(radius, kinematic, 0.02, 0.0),
            "R {radius} vs kinematic {kinematic}"
        );
    }
}

#[test]
fn tightest_circle_is_near_the_published_geometry() {
    let out = run("circle-right", 0);
    let tail: Vec<&TruthRow> = out
        .truth
        .iter()
        .filter(|r| (30.0..50.0).contains(&r.t))
        .collect();
    let n = tail.len() as f64;
    let radius = tail.iter().map(|r| r.speed / r.yaw_rate).sum::<f64>() / n;
    println!("tightest circle (rear axle): {radius:.3} m");
    // Rear-axle radius at 100 % = 35.5 deg: L / tan(35.5 deg) = 3.68 m kinematically; the
    // manufacturer's 5.58 m minimum turning radius is the outer front corner, so the rear axle
    // must be well inside it. Bounds: 3.6..4.3 m.
    assert!((3.6..4.3).contains(&radius), "circle radius {radius} m");
}

#[test]
fn speed_response_shows_delay_limits_and_reaches_the_command() {
    let cfg = VehicleConfig::default();
    let scenario = exact(vec![
        hold(2.0, 0.0, 0.0),
        hold(28.0, 7.5, 0.0),
        hold(10.0, 0.0, 0.0),
    ]);
    let out = sim::simulate(
        &scenario,
        &cfg,
        &SimOptions {
            vary_commands: false,
            ..Default::default()
        },
    );
    let speed_at = |t: f64| {
        out.truth
            .iter()
            .find(|r| r.t >= t - 1e-9)
            .map(|r| r.speed)
            .expect("in range")
    };
    // Transport delay 0.4 s: not a millimetre per second before 2.4 s, moving by 3.0 s.
    assert_eq!(speed_at(2.39), 0.0);
    assert!(speed_at(3.0) > 0.05, "moving by 3 s: {}", speed_at(3.0));
    // Acceleration within the limits (+2.0 / -3.5 m/s^2; 2 % slack for the 0.1 s difference).
    let mut max_accel: f64 = 0.0;
    let mut max_decel: f64 = 0.0;
    for w in out.truth.windows(11) {
        let a = (w[10].speed - w[0].speed) / (w[10].t - w[0].t);
        max_accel = max_accel.max(a);
        max_decel = max_decel.min(a);
    }
    assert!(
        max_accel <= 2.0 * 1.02 && max_accel > 1.5,
        "max accel {max_accel}"
    );
    assert!(
        (-3.5 * 1.02..-2.0).contains(&max_decel),
        "max decel {max_decel}"
    );
    // Minimum rise time at 2 m/s^2 is 3.75 s after the delay; within 2 % of 7.5 m/s by t = 12 s
    // and settled (1 %) over the last 10 s of the cruise.
    assert!(
        (speed_at(12.0) - 7.5).abs() < 0.15,
        "speed at 12 s: {}",
        speed_at(12.0)
    );
    assert!(speed_at(5.5) < 7.0, "cannot beat the acceleration limit");
    for t in [20.0, 25.0, 29.9] {
        assert!(
            (speed_at(t) - 7.5).abs() < 0.075,
            "speed at {t} s: {}",
            speed_at(t)
        );
    }
    // Stops and stays stopped, never reverses.
    let stopped: Vec<&TruthRow> = out.truth.iter().filter(|r| r.t >= 37.0).collect();
    assert!(stopped.iter().all(|r| r.speed == 0.0));
    assert!(stopped
        .windows(2)
        .all(|w| w[0].x == w[1].x && w[0].y == w[1].y));
    assert!(out.truth.iter().all(|r| r.speed >= 0.0));
    // The log shows the same: command steps at 2 s, measured speed still 0 at 2.4 s.
    let first_cmd = out
        .log
        .iter()
        .find(|r| r.input_vel.is_some_and(|v| v > 0.0))
        .expect("command");
    assert!((2.0..2.03).contains(&first_cmd.t), "{}", first_cmd.t);
    assert!(out
        .log
        .iter()
        .filter(|r| r.t < 2.4)
        .all(|r| r.vel.is_none_or(|v| v == 0.0)));
    // Accelerator pressed while accelerating, brake while stopping.
    assert!(out
        .log
        .iter()
        .any(|r| r.t > 3.0 && r.t < 5.0 && r.accel.is_some_and(|a| a > 90.0)));
    assert!(out
        .log
        .iter()
        .any(|r| r.t > 30.5 && r.t < 33.0 && r.brake.is_some_and(|b| b > 50.0)));
}

/// GNSS error statistics of `cfg`'s receiver over 30 parked 20 s runs: the horizontal RMS in
/// `rms_range_m`, the white part equal to the file's value (rtol 10 %).
fn check_gnss_error_statistics(cfg: &VehicleConfig, rms_range_m: std::ops::Range<f64>) {
    let g = &cfg.sensors.gnss;
    // Metres per degree at the origin (WGS-84 meridian and normal radii).
    let (m_per_deg_lat, m_per_deg_lon) = {
        let (a, f): (f64, f64) = (6_378_137.0, 1.0 / 298.257_223_563);
        let e2 = f * (2.0 - f);
        let s = geo::ORIGIN_LAT_DEG.to_radians().sin();
        let w = (1.0 - e2 * s * s).sqrt();
        let meridian = a * (1.0 - e2) / (w * w * w);
        (
            meridian.to_radians(),
            (a / w * geo::ORIGIN_LAT_DEG.to_radians().cos()).to_radians(),
        )
    };
    let mut sum_sq = 0.0;
    let mut n = 0usize;
    let mut diff_sq = 0.0;
    let mut n_diff = 0usize;
    for seed in 0..30 {
        let out = run_on(cfg, "standstill", seed);
        let truth = out.truth[0];
        let ahead = g.antenna_ahead_of_rear_axle_m;
        let (lat0, lon0) = geo::enu_to_lat_lon(
            geo::ORIGIN_LAT_DEG,
            geo::ORIGIN_LON_DEG,
            truth.x + ahead * truth.heading.sin(),
            truth.y + ahead * truth.heading.cos(),
        );
        let errors: Vec<(f64, f64)> = out
            .log
            .iter()
            .filter_map(|r| {
                Some((
                    (r.lon? - lon0) * m_per_deg_lon,
                    (r.lat? - lat0) * m_per_deg_lat,
                ))
            })
            .collect();
        let expected_fixes = out.scenario.duration_s() / g.period_s;
        assert!(
            (errors.len() as f64 - expected_fixes).abs() <= 2.0,
            "{} Hz: {} fixes",
            1.0 / g.period_s,
            errors.len()
        );
        for (e, nn) in &errors {
            sum_sq += e * e + nn * nn;
            n += 1;
        }
        for w in errors.windows(2) {
            diff_sq += (w[1].0 - w[0].0).powi(2) + (w[1].1 - w[0].1).powi(2);
            n_diff += 2;
        }
    }
    let horizontal_rms = (sum_sq / n as f64).sqrt();
    println!("GNSS horizontal RMS {horizontal_rms:.3} m over {n} fixes");
    assert!(
        rms_range_m.contains(&horizontal_rms),
        "horizontal RMS {horizontal_rms} m"
    );
    // The white part: fix-to-fix differences have variance 2 sigma_w^2 per axis (the bias moves
    // by < 1 cm in 10 ms, < 6 cm in 100 ms on the second car). rtol 10 % (6 000 differences or
    // more).
    let white = (diff_sq / n_diff as f64 / 2.0).sqrt();
    println!("GNSS white noise {white:.3} m per axis");
    assert!(
        isclose(white, g.white_noise_m, 0.1, 0.0),
        "white noise {white} m"
    );
}

#[test]
fn gnss_error_statistics() {
    // NovAtel's 1.2 m (paper II-A). 30 runs of 20 s see about 60 independent bias values (60 s
    // correlation), so the estimate scatters by about 10 %: accept 0.9..1.5 m.
    check_gnss_error_statistics(&VehicleConfig::default(), 0.9..1.5);
    // The second car's receiver at 10 Hz: sqrt(2 (0.4^2 + 1.2^2)) = 1.79 m; its 100 s bias
    // correlation leaves about 40 independent values: accept +-25 %.
    check_gnss_error_statistics(&polo(), 1.34..2.24);
}

#[test]
fn reports_run_on_their_own_clocks() {
    let mut one_hz = polo();
    one_hz.sensors.gnss.period_s = 1.0;
    for cfg in [VehicleConfig::default(), polo(), one_hz] {
        check_clocks(&cfg);
    }
}

fn check_clocks(cfg: &VehicleConfig) {
    let out = run_on(cfg, "smoke", 3);
    let times = |f: &dyn Fn(&LogRow) -> bool| {
        out.log
            .iter()
            .filter(|r| f(r))
            .map(|r| r.t)
            .collect::<Vec<_>>()
    };
    for (what, t, period) in [
        ("speed", times(&|r| r.vel.is_some()), 0.02),
        ("steer", times(&|r| r.steer.is_some()), 0.02),
        ("pedals", times(&|r| r.accel.is_some()), 0.02),
        (
            "gnss",
            times(&|r| r.lat.is_some()),
            cfg.sensors.gnss.period_s,
        ),
    ] {
        let mut dt: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
        dt.sort_by(f64::total_cmp);
        let median = dt[dt.len() / 2];
        assert!(
            isclose(median, period, 0.1, 0.0),
            "{what}: median interval {median}"
        );
        // Jitter of a few ms, never a reordering.
        assert!(
            dt[0] > 0.0 && dt[0] < period && dt[dt.len() - 1] > period,
            "{what}: {} .. {}",
            dt[0],
            dt[dt.len() - 1]
        );
    }
    // Rows are not on a common grid: most rows carry one report only.
    let single = out
        .log
        .iter()
        .filter(|r| {
            [
                r.vel.is_some(),
                r.steer.is_some(),
                r.accel.is_some(),
                r.lat.is_some(),
            ]
            .iter()
            .filter(|&&x| x)
            .count()
                == 1
        })
        .count();
    assert!(single * 10 > out.log.len() * 9);
}

#[test]
fn no_nan_anywhere_and_faults_remove_and_corrupt_fixes() {
    for name in SCENARIO_NAMES {
        let out = run(name, 11);
        assert!(
            out.truth
                .iter()
                .all(|r| [r.t, r.x, r.y, r.heading, r.yaw_rate, r.speed]
                    .iter()
                    .all(|v| v.is_finite())),
            "{name}"
        );
        assert!(
            out.log.iter().all(|r| r.t.is_finite()
                && [r.vel, r.input_vel, r.accel, r.steer, r.brake, r.lat, r.lon]
                    .iter()
                    .flatten()
                    .all(|v| v.is_finite())),
            "{name}"
        );
        assert!(
            out.log.windows(2).all(|w| w[1].t > w[0].t),
            "{name}: time increasing"
        );
        assert!(out
            .truth
            .iter()
            .all(|r| r.heading > -std::f64::consts::PI && r.heading <= std::f64::consts::PI));
    }
    let clean = run("validation", 5);
    let faulty = sim::run_named(
        "validation",
        None,
        &SimOptions {
            seed: 5,
            faults: true,
            ..Default::default()
        },
    )
    .expect("runs");
    assert!(faulty.log.iter().all(|r| [
        r.vel,
        r.input_vel,
        r.accel,
        r.steer,
        r.brake,
        r.lat,
        r.lon
    ]
    .iter()
    .flatten()
    .all(|v| v.is_finite())));
    let fixes = |o: &sim::SimOutput| o.log.iter().filter(|r| r.lat.is_some()).count();
    let speeds = |o: &sim::SimOutput| o.log.iter().filter(|r| r.vel.is_some()).count();
    assert!(fixes(&faulty) < fixes(&clean), "outages remove fixes");
    assert!(speeds(&faulty) < speeds(&clean), "lost bus reports");
    assert_eq!(clean.truth, faulty.truth, "faults touch the sensors only");
}

#[test]
fn enu_to_lat_lon_matches_pymap3d() {
    let reference = load_reference("sim_geodesy.json");
    let cases = reference["cases"].as_array().expect("cases");
    let (mut got, mut want) = (Vec::new(), Vec::new());
    for c in cases {
        let f = |k: &str| c[k].as_f64().expect("number");
        let (lat, lon) = geo::enu_to_lat_lon(
            geo::ORIGIN_LAT_DEG,
            geo::ORIGIN_LON_DEG,
            f("east_m"),
            f("north_m"),
        );
        got.extend([lat, lon]);
        want.extend([f("lat_deg"), f("lon_deg")]);
    }
    // atol 1e-10 deg = 0.01 mm.
    assert_allclose(&got, &want, 0.0, 1e-10, "lat/lon");
}

#[test]
fn simulated_files_round_trip_through_the_readers() {
    let out = run("smoke", 2);
    for r in out.log.iter().skip(300).take(8) {
        println!("{r:?}");
    }
    let dir = std::env::temp_dir().join(format!("catmodel-sim-test-{}", std::process::id()));
    let (log_path, truth_path) = sim::write_outputs(&dir, "smoke", &out).expect("writes");
    assert_eq!(logcsv::read_log(&log_path).expect("reads").rows, out.log);
    assert_eq!(logcsv::read_truth(&truth_path).expect("reads"), out.truth);
    std::fs::remove_dir_all(&dir).expect("cleanup");
    assert!(matches!(
        sim::run_named("nope", None, &SimOptions::default()),
        Err(sim::SimError::UnknownScenario(_))
    ));
}

#[test]
fn validation_drive_is_five_minutes_and_fast() {
    let start = std::time::Instant::now();
    let out = run("validation", 0);
    let elapsed = start.elapsed().as_secs_f64();
    println!(
        "validation drive: {:.1} s simulated in {:.3} s, {} log rows",
        out.scenario.duration_s(),
        elapsed,
        out.log.len()
    );
    assert!((285.0..315.0).contains(&out.scenario.duration_s()));
    // Mixed: both turn directions, stops, 0..10 m/s.
    assert!(
        out.truth.iter().any(|r| r.yaw_rate > 0.2) && out.truth.iter().any(|r| r.yaw_rate < -0.2)
    );
    assert!(out.truth.iter().any(|r| r.speed > 9.5));
    assert!(out
        .truth
        .iter()
        .filter(|r| r.t > 10.0)
        .any(|r| r.speed == 0.0));
    if !cfg!(debug_assertions) {
        assert!(elapsed < 1.0, "release build: {elapsed} s");
    }
}
