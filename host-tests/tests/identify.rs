//! `catmodel identify`: recovery of the published model from its own noise-free simulation,
//! the accuracy and run-time bars on the built-in simulator, the cornering stiffnesses from
//! step steers at speed on two cars, and clear errors on bad input.
use std::path::Path;
use std::time::Instant;

use catmodel::model::paper;
use catmodel_host::identify::preprocess::{preprocess_rows, Experiment, PreprocessOptions};
use catmodel_host::identify::{self, simulate, validate, IdentifyOptions};
use catmodel_host::logcsv::LogRow;
use catmodel_host::model_file;
use catmodel_host::sim::config::VehicleConfig;
use catmodel_host::sim::scenario::PAPER_SIZED_TRAINING;
use catmodel_host_tests::{sim_experiment, sim_experiment_of};

fn experiment(name: &str, input_vel: Vec<f64>, vel: Vec<f64>) -> Experiment {
    let n = input_vel.len();
    let z = vec![0.0; n];
    Experiment {
        name: name.into(),
        t: (0..n).map(|k| k as f64 * 0.02).collect(),
        ts_s: 0.02,
        vel,
        input_vel,
        steer_pct: z.clone(),
        delta_rad: z.clone(),
        accel_pct: z.clone(),
        brake_pct: z.clone(),
        x: z.clone(),
        y: z.clone(),
        dx: z.clone(),
        dy: z.clone(),
        heading: z.clone(),
        yaw_rate: z,
        origin_deg: (0.0, 0.0),
        yaw_half_width: 48,
        log_notes: Vec::new(),
        log_warnings: Vec::new(),
        gnss_rate_hz: 100.0,
        speed_scale: None,
        speed_disagreement: None,
        gnss_gap: Vec::new(),
        track_from: 0,
        speed_skip: Vec::new(),
        report_intervals: Default::default(),
        command_unit: None,
    }
}

/// Piecewise-constant commands, `(duration_s, speed)`, on the 20 ms grid.
fn steps(segments: &[(f64, f64)]) -> Vec<f64> {
    segments
        .iter()
        .flat_map(|&(d, v)| std::iter::repeat_n(v, (d / 0.02).round() as usize))
        .collect()
}

/// Three logs of speed steps, their speed simulated noise-free from the published eq 5.
fn eq5_training() -> Vec<Experiment> {
    let commands = [
        steps(&[(2.0, 0.0), (30.0, 2.5), (20.0, 5.0), (8.0, 0.0)]),
        steps(&[(2.0, 0.0), (25.0, 7.5), (15.0, 3.0), (18.0, 6.0)]),
        steps(&[
            (2.0, 0.0),
            (10.0, 10.0),
            (10.0, 4.0),
            (10.0, 8.0),
            (28.0, 0.0),
        ]),
    ];
    commands
        .iter()
        .enumerate()
        .map(|(i, u)| {
            let y = simulate::simulate(&paper::EQ5_INTERNAL_CONTROLLER, 0.02, u).unwrap();
            experiment(&format!("eq5-{i}"), u.clone(), y)
        })
        .collect()
}

/// Noise-free data simulated from eq 5: identify recovers every coefficient within 1 % and
/// the delay exactly (21 samples = 0.42 s).
#[test]
fn recovers_the_published_speed_model() {
    let training = eq5_training();
    let id = identify::identify_speed(&training, &[], &IdentifyOptions::default()).unwrap();
    let tf = id.tf;
    assert_eq!(tf.delay_s(), paper::EQ5_DELAY_S, "delay");
    let num = tf.numerator();
    let den = tf.denominator();
    let check = |got: f64, want: f64, what: &str| {
        assert!(
            ((got - want) / want).abs() < 0.01,
            "{what}: {got} vs published {want} (rtol 1 %)"
        );
    };
    for i in 0..3 {
        check(num[i] / den[0], paper::EQ5_NUM[i], &format!("num[{i}]"));
        check(den[i] / den[0], paper::EQ5_DEN[i], &format!("den[{i}]"));
    }
}

/// A training log whose `input_vel` reads 0 for 5 s while the car cruises on (a driver's
/// takeover, the speed control disengaged: the car did not follow the command): found by
/// `preprocess::command_not_followed` and the log fitted in the stretches around it, each
/// simulated from its own start, the published model is recovered as from the clean logs
/// (delay 0.42 s, coefficients within 1 %); taken as it is, the fit's delay
/// is wrong (a black-box probe: 0.30 s for 0.88, with right-half-plane zeros, and no word).
/// The clean logs' own steps, 10 m/s down to 0 among them, are not taken for one.
#[test]
fn a_command_the_car_did_not_follow_is_left_out_of_the_speed_fit() {
    use catmodel_host::identify::preprocess::command_not_followed;
    let mut training = eq5_training();
    for e in &training {
        let (_, found) = command_not_followed(&e.t, &e.vel, &e.input_vel);
        assert!(found.is_empty(), "{}: {found:?}", e.name);
    }
    // The takeover: 5 s of the second log's 7.5 m/s stretch, from 12 s.
    let e = &mut training[1];
    for k in 600..850 {
        e.input_vel[k] = 0.0;
    }
    let (skip, found) = command_not_followed(&e.t, &e.vel, &e.input_vel);
    assert_eq!(found.len(), 1, "{found:?}");
    assert!((found[0].from_s - 12.0).abs() < 0.05 && (found[0].to_s - 16.98).abs() < 0.05);
    let opts = IdentifyOptions::default();
    let taken = identify::identify_speed(&training, &[], &opts).unwrap().tf;
    assert_ne!(taken.delay_s(), paper::EQ5_DELAY_S, "the takeover taken in");
    training[1].speed_skip = skip;
    let tf = identify::identify_speed(&training, &[], &opts).unwrap().tf;
    assert_eq!(tf.delay_s(), paper::EQ5_DELAY_S, "delay");
    let (num, den) = (tf.numerator(), tf.denominator());
    for i in 0..3 {
        let (got, want) = (num[i] / den[0], paper::EQ5_NUM[i]);
        assert!(
            ((got - want) / want).abs() < 0.01,
            "num[{i}] {got} vs {want}"
        );
        let (got, want) = (den[i] / den[0], paper::EQ5_DEN[i]);
        assert!(
            ((got - want) / want).abs() < 0.01,
            "den[{i}] {got} vs {want}"
        );
    }
}

/// A truck-like speed loop's launches are no command the car did not follow (a black-box
/// probe's car with 0.6 s of command delay, a 1.2 s actuator lag and 0.8 m/s^2 at most: the
/// command 2.3 m/s above the speed for about 4 s at the start of six of the paper-sized set's
/// logs was named as not followed and left out of the speed fit): the speed closes on the
/// command at the stretch's end. A command in km/h or mph is named as its unit by the speed
/// it settles to, before any fit, and not as a command not followed (the probe's km/h set had
/// every log named so before the unit's refusal). The simulator's drives in m/s, on the CAT
/// Vehicle and the truck-like car, name no unit.
#[test]
fn a_slow_launch_is_followed_and_a_command_in_km_h_is_named_as_its_unit() {
    let base = model_file::load(&model_file::paper_path()).unwrap();
    let cat = VehicleConfig::load(&vehicles_dir().join("cat-vehicle.toml")).unwrap();
    let mut truck = cat.clone();
    truck.speed_controller.command_delay_s = 0.6;
    truck.speed_controller.actuator_lag_s = 1.2;
    truck.speed_controller.max_accel_mps2 = 0.8;
    let launches = [
        ("straight-2.5", 1),
        ("straight-2.5", 2),
        ("turn-left", 1),
        ("turn-right", 1),
        ("circle-left", 1),
        ("circle-right", 1),
    ];
    for (scenario, seed) in launches {
        for plant in [&cat, &truck] {
            let e = sim_experiment_of(scenario, seed, plant, &base.vehicle);
            assert!(
                e.speed_skip.is_empty() && e.command_unit.is_none(),
                "{}: {:?} {:?}",
                e.name,
                e.log_notes,
                e.command_unit
            );
        }
    }
    for (scenario, seed) in [("straight-5", 1), ("straight-10", 2), ("circle-left", 1)] {
        let rows = simulated(scenario, seed);
        for (factor, unit) in [(3.6, "km/h"), (2.237, "mph")] {
            let mut rows = rows.clone();
            for r in &mut rows {
                r.input_vel = r.input_vel.map(|v| v * factor);
            }
            let e = preprocess_rows(
                scenario,
                &rows,
                &base.vehicle,
                &PreprocessOptions::default(),
            )
            .unwrap();
            let why = e.command_unit.as_deref().unwrap_or_default();
            assert!(
                why.contains(&format!("`input_vel` looks like {unit}")),
                "{scenario} {unit}: {why:?}"
            );
            assert!(
                e.speed_skip.is_empty()
                    && !e.log_notes.iter().any(|n| n.contains("did not follow")),
                "{scenario} {unit}: {:?}",
                e.log_notes
            );
        }
    }
}

/// `model` written as a model file reads back equal.
fn assert_round_trips(model: &model_file::ModelFile) {
    let text = model_file::to_toml(model);
    assert_eq!(&model_file::parse(&text, Path::new("<id>")).unwrap(), model);
}

/// The paper-sized training set on the CAT Vehicle.
fn paper_sized_set() -> Vec<Experiment> {
    PAPER_SIZED_TRAINING
        .iter()
        .map(|&(n, seed)| sim_experiment(n, seed))
        .collect()
}

/// The paper-sized set with its bus sensors (`vel`, `input_vel`, `steer`, the pedals) each
/// kept at every `nth` sample, as a telemetry logger that samples the bus slower than its
/// 50 Hz writes them; the fixes as they are.
fn paper_sized_set_with_sensors_every(nth: usize) -> Vec<Experiment> {
    let base = model_file::load(&model_file::paper_path()).expect("models/paper.toml");
    PAPER_SIZED_TRAINING
        .iter()
        .map(|&(scenario, seed)| {
            let mut rows = simulated(scenario, seed);
            let mut seen = [0usize; 5];
            for r in &mut rows {
                let cells = [
                    &mut r.vel,
                    &mut r.input_vel,
                    &mut r.steer,
                    &mut r.accel,
                    &mut r.brake,
                ];
                for (cell, seen) in cells.into_iter().zip(&mut seen) {
                    if cell.is_some() {
                        *seen += 1;
                        if *seen % nth != 0 {
                            *cell = None;
                        }
                    }
                }
            }
            let name = format!("{scenario}-{seed}");
            preprocess_rows(&name, &rows, &base.vehicle, &PreprocessOptions::default())
                .unwrap_or_else(|e| panic!("preprocessing {name}: {e:#}"))
        })
        .collect()
}

/// Speed and steering logged at 1 Hz (a black-box probe: the paper-sized set so logged fitted a
/// speed delay of 0.68 s for the 0.88 s of the same drives at 50 Hz, without a note) are named
/// in `replay`'s and `csv2can`'s words, with what their interval costs the delays: +-0.50 s,
/// within which the truth lies. At 0.5 Hz the fitted delay (0.14 s) is inside its +-1.00 s:
/// the figure means nothing and `identify` refuses it (`--force` writes it). At 50 Hz nothing
/// is said.
#[test]
fn sensors_logged_slower_than_the_bus_are_named_with_what_they_cost_the_delay() {
    let base = model_file::load(&model_file::paper_path()).unwrap();
    let run = |nth: usize| {
        identify::identify(
            paper_sized_set_with_sensors_every(nth),
            Vec::new(),
            &base,
            &IdentifyOptions::default(),
        )
        .unwrap()
    };
    let slow_note = |id: &identify::Identification| {
        id.notes
            .iter()
            .find(|n| n.contains("further apart than the node's timeouts"))
            .cloned()
    };
    let id = run(1);
    assert_eq!(slow_note(&id), None);
    assert_eq!(id.slow_sensor_problem, None);
    let id = run(50);
    let delay = id.speed.tf.delay_s();
    let note = slow_note(&id).expect("named");
    assert!(
        note.contains("SPEED_REPORT every 1.000 s (median), longer than its 0.100 s timeout")
            && note.contains("STEERING_REPORT every 1.000 s")
            && note.contains(&format!(
                "the speed model's delay, {delay:.2} s, is known to +-0.50 s at best"
            )),
        "{note}"
    );
    // The truth within what the note says.
    assert!((delay - 0.88).abs() <= 0.5, "{delay}");
    assert_eq!(id.slow_sensor_problem, None);
    let id = run(100);
    let why = id.slow_sensor_problem.expect("refused");
    assert!(
        why.contains("logged every 2.000 s (median)") && why.contains("means nothing"),
        "{why}"
    );
}

/// Trained on the four straight-line experiments of the simulator, the speed model reaches at
/// least 87 % fit (pure simulation) on the 5-minute validation drive; the paper-sized set
/// (11 one-minute experiments + validation) is identified in under 5 s.
#[test]
fn simulator_bars() {
    let base = model_file::load(&model_file::paper_path()).unwrap();
    let straight: Vec<Experiment> = ["straight-2.5", "straight-5", "straight-7.5", "straight-10"]
        .iter()
        .map(|n| sim_experiment(n, 1))
        .collect();
    let validation = vec![sim_experiment("validation", 3)];
    let id = identify::identify(
        straight,
        validation.clone(),
        &base,
        &IdentifyOptions::default(),
    )
    .unwrap();
    let v = id.validation_scores.unwrap();
    let fit = v.vel_model.fit_percent.unwrap();
    println!(
        "straight-line training: validation speed fit {fit:.2} % (kinematic {:.2} %), ARX {:.2} %",
        v.vel_kinematic.fit_percent.unwrap(),
        id.speed.arx_validation.unwrap().fit_percent.unwrap()
    );
    assert!(fit >= 87.0, "validation speed fit {fit:.2} % < 87 %");
    assert!(fit > v.vel_kinematic.fit_percent.unwrap());
    assert_eq!(id.model.speed.fit.validation_fit_percent, Some(fit));
    // The written file loads back equal.
    assert_round_trips(&id.model);

    let set = paper_sized_set();
    assert_eq!(set.len(), 11);
    let started = Instant::now();
    let id = identify::identify(set, validation, &base, &IdentifyOptions::default()).unwrap();
    let secs = started.elapsed().as_secs_f64();
    println!(
        "paper-sized set identified in {secs:.2} s\n{}",
        identify::summary(&id)
    );
    // Its run time is measured by the criterion bench `identify/paper_set` (README), not here:
    // a wall-clock bound in a test fails on a loaded machine and proves nothing.
    let lateral = id
        .model
        .lateral
        .as_ref()
        .expect("turns and circles excite the lateral model");
    // The simulator's steering is the nominal 35.5 deg at 100 %, its understeer ~0.0015.
    assert!(
        (lateral.steer_gain - 1.0).abs() < 0.05,
        "{}",
        lateral.steer_gain
    );
}

fn row(t: f64, vel: Option<f64>, cmd: Option<f64>, steer: Option<f64>, gnss: bool) -> LogRow {
    LogRow {
        t,
        vel,
        input_vel: cmd,
        steer,
        lat: gnss.then_some(32.2319 + t * 1e-6),
        lon: gnss.then_some(-110.9501),
        ..LogRow::default()
    }
}

#[test]
fn bad_input_gets_a_clear_error() {
    let v = model_file::load(&model_file::paper_path()).unwrap().vehicle;
    let o = PreprocessOptions::default();
    let rows = |secs: f64, steer: bool, cmd: &dyn Fn(f64) -> f64| -> Vec<LogRow> {
        (0..(secs / 0.02) as usize)
            .map(|k| {
                let t = k as f64 * 0.02;
                row(t, Some(1.0), Some(cmd(t)), steer.then_some(0.0), true)
            })
            .collect()
    };
    let e = preprocess_rows("nosteer", &rows(30.0, false, &|_| 1.0), &v, &o).unwrap_err();
    assert!(format!("{e:#}").contains("steer"), "{e:#}");
    let e = preprocess_rows("short", &rows(5.0, true, &|_| 1.0), &v, &o).unwrap_err();
    assert!(format!("{e:#}").contains("too short"), "{e:#}");
    let constant = preprocess_rows("const", &rows(30.0, true, &|_| 1.0), &v, &o).unwrap();
    let e = identify::identify_speed(&[constant], &[], &IdentifyOptions::default()).unwrap_err();
    assert!(format!("{e:#}").contains("constant"), "{e:#}");
    // A real file without the needed column: the error names the file.
    let dir = std::env::temp_dir().join("catmodel-identify-test");
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("no-gnss.csv");
    std::fs::write(&path, "t,vel,input_vel,steer\n0,0,0,0\n0.02,0,1,0\n").unwrap();
    let e = identify::preprocess::load_experiment(&path, &v, &o).unwrap_err();
    let msg = format!("{e:#}");
    assert!(
        msg.contains("no-gnss.csv") && msg.contains("missing"),
        "{msg}"
    );
    // All columns present, but GNSS never reported.
    std::fs::write(
        &path,
        "t,vel,input_vel,accel,steer,brake,lat,lon\n0,0,0,,0,,,\n0.02,0,1,,0,,,\n",
    )
    .unwrap();
    let msg = format!(
        "{:#}",
        identify::preprocess::load_experiment(&path, &v, &o).unwrap_err()
    );
    assert!(
        msg.contains("no-gnss.csv") && msg.contains("lat/lon"),
        "{msg}"
    );
}

/// The largest |a - b| over the pairs, 0 for none.
fn largest_difference(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

/// One corrupt sample that is still in range (a speed of 70 m/s in a drive at 5 m/s, a fix
/// moved 1 km) is named and left out, instead of moving the identified model without a word
/// (it halved the speed delay); a step in the command is no outlier; a clean drive has none.
#[test]
fn an_impossible_sample_is_named_and_left_out() {
    let v = model_file::load(&model_file::paper_path()).unwrap().vehicle;
    let o = PreprocessOptions::default();
    let drive = || -> Vec<LogRow> {
        (0..3000)
            .map(|k| {
                let t = k as f64 * 0.02;
                // A command step at 20 s, the speed following it smoothly.
                let cmd = if t < 20.0 { 3.0 } else { 8.0 };
                let vel = if t < 20.0 {
                    3.0
                } else {
                    8.0 - 5.0 * (-(t - 20.0)).exp()
                };
                row(t, Some(vel), Some(cmd), Some(10.0 * (t * 0.2).sin()), true)
            })
            .collect()
    };
    let clean = preprocess_rows("clean", &drive(), &v, &o).unwrap();
    assert!(clean.log_notes.is_empty(), "{:?}", clean.log_notes);
    let mut bad = drive();
    bad[1000].vel = Some(70.0);
    bad[2000].lat = Some(bad[2000].lat.unwrap() + 0.009); // 1 km north
    let e = preprocess_rows("bad", &bad, &v, &o).unwrap();
    assert_eq!(e.log_notes.len(), 2, "{:?}", e.log_notes);
    assert!(
        e.log_notes[0]
            .starts_with("bad: column `vel`: the sample at t = 20 s (70 m/s) is impossible"),
        "{}",
        e.log_notes[0]
    );
    assert!(
        e.log_notes[1].contains("column `lat/lon`: the sample at t = 40 s")
            && e.log_notes[1].contains("left out"),
        "{}",
        e.log_notes[1]
    );
    // What is left is the clean drive but for the interpolation over one sample.
    let worst = largest_difference;
    assert!(
        worst(&e.vel, &clean.vel) < 0.05,
        "{}",
        worst(&e.vel, &clean.vel)
    );
    assert!(worst(&e.y, &clean.y) < 0.01, "{}", worst(&e.y, &clean.y));
}

/// The first and the last sample of a sensor are judged too, against the samples on their one
/// side: a first or last `vel` of 70 m/s in a drive at 3-8 m/s, and a first or last fix at
/// longitude -11 in a drive at -110.95 (as a line cut short writes it), are named and left
/// out. Before, the ends were skipped: one such speed took a speed fit from 58.5 % to -0.8 %,
/// and a first fix that far moved the local origin 6300 km.
#[test]
fn an_impossible_first_or_last_sample_is_named_and_left_out() {
    let v = model_file::load(&model_file::paper_path()).unwrap().vehicle;
    let o = PreprocessOptions::default();
    let drive = || -> Vec<LogRow> {
        (0..3000)
            .map(|k| {
                let t = k as f64 * 0.02;
                let vel = 3.0 + 5.0 * (t / 60.0);
                row(t, Some(vel), Some(vel), Some(10.0 * (t * 0.2).sin()), true)
            })
            .collect()
    };
    let clean = preprocess_rows("clean", &drive(), &v, &o).unwrap();
    assert!(clean.log_notes.is_empty(), "{:?}", clean.log_notes);
    let worst = largest_difference;
    let last = drive().len() - 1;
    for (what, end) in [("first", 0), ("last", last)] {
        let mut bad = drive();
        bad[end].vel = Some(70.0);
        bad[end].lon = Some(-11.0);
        let e = preprocess_rows("bad", &bad, &v, &o).unwrap();
        let side = if end == 0 { "after" } else { "before" };
        assert_eq!(e.log_notes.len(), 2, "{what}: {:?}", e.log_notes);
        assert!(
            e.log_notes[0].starts_with(&format!(
                "bad: column `vel`: the sample at t = {} s (70 m/s) is impossible beside the \
                 samples {side} it",
                bad[end].t
            )) && e.log_notes[0].ends_with("left out"),
            "{what}: {}",
            e.log_notes[0]
        );
        assert!(
            e.log_notes[1].starts_with(&format!(
                "bad: column `lat/lon`: the sample at t = {} s",
                bad[end].t
            )) && e.log_notes[1].ends_with("left out"),
            "{what}: {}",
            e.log_notes[1]
        );
        // The origin is a fix of the drive's, not the far one; the grid starts or ends one
        // sample in, and the rest is the clean drive's.
        let (lat, lon) = e.origin_deg;
        assert!(
            (lat - clean.origin_deg.0).abs() < 1e-6 && (lon - clean.origin_deg.1).abs() < 1e-9,
            "{what}: origin {lat}, {lon}"
        );
        let n = e.t.len();
        assert!(n + 1 >= clean.t.len() && n <= clean.t.len(), "{what}: {n}");
        let skip = usize::from(end == 0 && n < clean.t.len());
        let c = |x: &[f64]| x[skip..skip + n].to_vec();
        assert!(worst(&e.vel, &c(&clean.vel)) < 0.05, "{what}: vel");
        assert!(worst(&e.x, &c(&clean.x)) < 0.01, "{what}: x");
        assert!(worst(&e.y, &c(&clean.y)) < 0.01, "{what}: y");
    }
}

/// A pause in a needed sensor is refused, naming the column and the times, instead of being
/// filled with straight lines (a one-hour pause improved the fit's MSE 65 times); a GNSS
/// outage of a few seconds is interpolated; a slow receiver's own period is not a pause.
#[test]
fn a_pause_in_a_sensor_is_refused_and_a_short_outage_is_not() {
    let v = model_file::load(&model_file::paper_path()).unwrap().vehicle;
    let o = PreprocessOptions::default();
    // 60 s at 50 Hz; GNSS silent over `outage` (s).
    let drive = |outage: (f64, f64), gnss_every: usize| -> Vec<LogRow> {
        (0..3000)
            .map(|k| {
                let t = k as f64 * 0.02;
                let fix = k % gnss_every == 0 && !(outage.0..outage.1).contains(&t);
                row(t, Some(1.0 + (t * 0.3).sin()), Some(1.0), Some(0.0), fix)
            })
            .collect()
    };
    let ok = preprocess_rows("tunnel", &drive((20.0, 24.0), 1), &v, &o).unwrap();
    assert!((ok.gnss_rate_hz - 50.0).abs() < 0.01, "{}", ok.gnss_rate_hz);
    // 1 Hz fixes: 1 s between fixes is the receiver's period.
    let slow = preprocess_rows("1hz", &drive((0.0, 0.0), 50), &v, &o).unwrap();
    assert!(
        (slow.gnss_rate_hz - 1.0).abs() < 0.01,
        "{}",
        slow.gnss_rate_hz
    );
    let e = preprocess_rows("pause", &drive((20.0, 30.0), 1), &v, &o).unwrap_err();
    let msg = format!("{e:#}");
    assert!(
        msg.contains("column `lat/lon` has no sample for 10.0 s (t = 19.98 to 30)"),
        "{msg}"
    );
    // The same pause in every sensor (the recorder paused): the first needed column names it.
    let mut rows = drive((0.0, 0.0), 1);
    for r in rows.iter_mut().filter(|r| r.t >= 30.0) {
        r.t += 3600.0;
    }
    let e = preprocess_rows("hour", &rows, &v, &o).unwrap_err();
    assert!(
        format!("{e:#}").contains("column `vel` has no sample for 3600.0 s"),
        "{e:#}"
    );
}

/// Two drives joined in one log (review finding 02: time continuous, the second drive 2 km
/// east, a fix 2 km from the one 20 ms before): refused as the pause rule refuses a pause, with
/// the file, the line of the first fix after the step, the times and the advice to split the
/// log there. Before, identify trained across it (dx/dt MSE 519 (m/s)^2 instead of 0.05) with
/// exit 0. A burst of three bad fixes (which the outlier check keeps: the median of three
/// neighbours is bad too) is no discontinuity, and neither is a slow receiver's period.
#[test]
fn a_gnss_step_no_car_can_make_is_refused_as_a_discontinuity() {
    let v = model_file::load(&model_file::paper_path()).unwrap().vehicle;
    let o = PreprocessOptions::default();
    // 60 s at 50 Hz, a fix every `gnss_every` rows; from t = 30 s the fixes `shift` deg east.
    let drive = |shift: f64, gnss_every: usize| -> Vec<LogRow> {
        (0..3000)
            .map(|k| {
                let t = k as f64 * 0.02;
                let mut r = row(t, Some(5.0), Some(5.0), Some(0.0), k % gnss_every == 0);
                if t >= 30.0 {
                    r.lon = r.lon.map(|lon| lon + shift);
                }
                r
            })
            .collect()
    };
    // 0.0213 deg of longitude at 32.2319 deg north: pi/180 a cos(lat) / sqrt(1 - e^2 sin^2(lat))
    // = 94 253 m/deg (WGS-84), 2008 m.
    let e = preprocess_rows("joined", &drive(0.0213, 1), &v, &o).unwrap_err();
    let msg = format!("{e:#}");
    assert!(
        msg.contains("the GNSS fix jumps 2008 m in 0.02 s (t = 29.98 to 30), and stays there")
            && msg.contains("split the log at this line"),
        "{msg}"
    );
    // A 1 Hz receiver: its side medians span 3 fixes each (5 s, 500 m at most): still refused.
    let msg = format!(
        "{:#}",
        preprocess_rows("joined-1hz", &drive(0.0213, 50), &v, &o).unwrap_err()
    );
    assert!(msg.contains("(t = 29 to 30)"), "{msg}");
    // The joined drive as a file: the line of the first fix after the step (the header is
    // line 1, t = 0 line 2, t = 30 s, row 1500, line 1502).
    let dir = std::env::temp_dir().join(format!("catmodel-gnss-step-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("joined.csv");
    let cell = |x: Option<f64>| x.map_or(String::new(), |x| format!("{x}"));
    let mut text = String::from("t,vel,input_vel,accel,steer,brake,lat,lon\n");
    for r in drive(0.0213, 1) {
        text += &format!(
            "{},{},{},,{},,{},{}\n",
            r.t,
            cell(r.vel),
            cell(r.input_vel),
            cell(r.steer),
            cell(r.lat),
            cell(r.lon)
        );
    }
    std::fs::write(&path, text).unwrap();
    let msg = format!(
        "{:#}",
        identify::preprocess::load_experiment(&path, &v, &o).unwrap_err()
    );
    assert!(
        msg.starts_with(&format!(
            "{}:1502: the GNSS fix jumps 2008 m",
            path.display()
        )),
        "{msg}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
    // Not a discontinuity: the same drive unshifted; three fixes 1 km north in a row (kept by
    // the outlier check, they move neither side's median over 1 s); a 20 m step that stays
    // (two drives joined at one site: within the receiver's error at worst).
    assert!(preprocess_rows("one", &drive(0.0, 1), &v, &o).is_ok());
    let mut burst = drive(0.0, 1);
    for r in &mut burst[1000..1003] {
        r.lat = r.lat.map(|lat| lat + 0.009);
    }
    assert!(preprocess_rows("burst", &burst, &v, &o).is_ok());
    assert!(preprocess_rows("20m", &drive(20.0 / 94_253.0, 1), &v, &o).is_ok());
}

/// What a steering gain no car has is named (review finding 01), against the gains worked out
/// by hand for the CAT Vehicle's 35.5 deg lock: the road wheels' degrees read as percent give
/// 100 / 35.5 = 2.817, the steering wheel's degrees at a 16:1 ratio 100 / (35.5 x 16) = 0.176
/// (a lock of 6.25 deg), a `steer` of the other sign minus the car's gain. Gains a car has
/// (1, 0.8 and 1.25 off its file) are none of these.
#[test]
fn a_steering_gain_no_car_has_names_its_likely_cause() {
    let cause = |g: f64, se: f64| identify::steer_gain_cause(g, se, 35.5);
    for g in [0.987, 0.8, 1.25, 2.0] {
        assert_eq!(cause(g, 0.01), None, "{g}");
    }
    let sign = cause(-0.987, 0.012).unwrap();
    assert!(
        sign.starts_with("`steer` turns the car the other way than the schema's sign convention (positive = right)")
            && sign.ends_with("negate the column"),
        "{sign}"
    );
    let wheel = cause(2.78, 0.03).unwrap();
    assert!(
        wheel.contains("road wheels' angle in degrees")
            && wheel.contains("100 / 35.5 = 2.82")
            && wheel.contains("multiply it by 100 / 35.5"),
        "{wheel}"
    );
    // The other sign and degrees at once: both named.
    let both = cause(-2.78, 0.03).unwrap();
    assert!(
        both.contains("negate the column") && both.contains("road wheels' angle in degrees"),
        "{both}"
    );
    let steering_wheel = cause(100.0 / (35.5 * 16.0), 0.002).unwrap();
    assert!(
        steering_wheel.contains("steering wheel's angle in degrees (with a steering ratio of 16:1")
            && steering_wheel.contains("6.2 deg"),
        "{steering_wheel}"
    );
    // A fraction of the lock (-1..1) gives 100; the road wheels' radians 100 / 0.6196 = 161.4.
    let fraction = cause(98.9, 1.2).unwrap();
    assert!(
        fraction.contains("a fraction of full lock") && fraction.ends_with("multiply it by 100"),
        "{fraction}"
    );
    let radians = cause(159.6, 1.9).unwrap();
    assert!(
        radians.contains("road wheels' angle in radians")
            && radians.contains("100 / 0.62 = 161")
            && radians.ends_with("multiply it by 161"),
        "{radians}"
    );
    // Near zero, within its error of 0: not the sign; no car steers so.
    let none = cause(-0.02, 0.05).unwrap();
    assert!(
        none.starts_with("no car steers so") && !none.contains("negate"),
        "{none}"
    );
}

/// A plant with a survey-grade (RTK) receiver: 1 cm white noise and bias per axis (NovAtel OEM7
/// data sheet, RTK: 1 cm + 1 ppm RMS horizontal), as the closed-loop rig's `--receiver rtk`.
fn with_rtk(mut plant: VehicleConfig) -> VehicleConfig {
    plant.sensors.gnss.white_noise_m = 0.01;
    plant.sensors.gnss.bias_sigma_m = 0.01;
    plant
}

fn vehicles_dir() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../host/vehicles")
}

/// `[dynamics]`' cornering stiffnesses from two runs of `steps-at-speed` (step steers right and
/// left at 8, 12 and 16 m/s, a slalom at 12 m/s) with an RTK receiver, on the CAT Vehicle and
/// the Polo (whose defaults nothing was tuned on), the fit starting from the car file's front
/// stiffness halved and rear doubled: within 8 % of the plant's tyres, which are the magic
/// formula's slope at zero slip (at the drives' 2.5 m/s^2 their secant is about 3 % lower), and
/// determined to 4 %. With the standard receiver, or with the paper's drives (turns at
/// 2.5 m/s), the stiffnesses are not determined, and `identify` says so instead of writing them.
#[test]
fn cornering_stiffnesses_from_step_steers_at_speed() {
    let base = model_file::load(&model_file::paper_path()).unwrap();
    let polo_car = identify::car::apply(&base, &vehicles_dir().join("vw-polo.car.toml"))
        .unwrap()
        .file;
    let polo_plant = VehicleConfig::load(&vehicles_dir().join("vw-polo.toml")).unwrap();
    for (name, plant, car) in [
        ("CAT Vehicle", VehicleConfig::default(), &base),
        ("Polo", polo_plant, &polo_car),
    ] {
        let truth = (
            plant.tyre_front.cornering_stiffness_n_per_rad,
            plant.tyre_rear.cornering_stiffness_n_per_rad,
        );
        let prior = car.dynamics.expect("the car file's [dynamics]");
        let skewed = model_file::DynamicsSection {
            cornering_front_n_per_rad: 0.5 * prior.cornering_front_n_per_rad,
            cornering_rear_n_per_rad: 2.0 * prior.cornering_rear_n_per_rad,
            ..prior
        };
        let rtk = with_rtk(plant.clone());
        let drives: Vec<Experiment> = [1, 2]
            .iter()
            .map(|&s| sim_experiment_of("steps-at-speed", s, &rtk, &car.vehicle))
            .collect();
        let fit = identify::dynamics::identify_dynamics(&drives, &car.vehicle, &skewed, 1.0)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let (cf, cr) = (
            fit.section.cornering_front_n_per_rad,
            fit.section.cornering_rear_n_per_rad,
        );
        println!(
            "{name}: C_f {cf:.0} (plant {:.0}, +-{:.1} %), C_r {cr:.0} (plant {:.0}, +-{:.1} %), course rate fit {:.1} % (kinematic {:.1} %), {} samples",
            truth.0,
            100.0 * fit.relative_std_error.0,
            truth.1,
            100.0 * fit.relative_std_error.1,
            fit.fit_percent,
            fit.kinematic_fit_percent,
            fit.samples
        );
        assert!(
            (cf / truth.0 - 1.0).abs() < 0.08,
            "{name}: C_f {cf} vs {}",
            truth.0
        );
        assert!(
            (cr / truth.1 - 1.0).abs() < 0.08,
            "{name}: C_r {cr} vs {}",
            truth.1
        );
        assert!(fit.relative_std_error.0 < 0.04 && fit.relative_std_error.1 < 0.04);
        assert!(
            fit.fit_percent > fit.kinematic_fit_percent + 10.0,
            "{fit:?}"
        );
        // The lateral model's understeer from the same drives, steady samples only: the
        // plant's K = m (b / C_f - a / C_r) / L^2 (the transients of the steps read as
        // understeer 2.5 times the plant's when every sample counted).
        let lateral =
            identify::identify_lateral(&drives, &car.vehicle, &IdentifyOptions::default())
                .unwrap()
                .unwrap();
        // Determined by these drives (RTK, steps at speed), its standard error small.
        assert!(
            matches!(
                lateral.understeer,
                identify::Understeer::Estimated { relative_std_error } if relative_std_error < 0.1
            ),
            "{name}: {:?}",
            lateral.understeer
        );
        let (gain, k) = (lateral.steer_gain, lateral.understeer_s2_per_m2);
        let plant_k = plant.understeer_s2_per_m2();
        println!("{name}: steering gain {gain:.4}, understeer {k:.5} (plant {plant_k:.5})");
        assert!(
            (k / plant_k - 1.0).abs() < 0.15,
            "{name}: K {k} vs {plant_k}"
        );
        assert!((gain - 1.0).abs() < 0.03, "{name}: steering gain {gain}");
        // The other keys are the car file's.
        assert_eq!(fit.section.mass_kg, prior.mass_kg);
        assert_eq!(fit.section.cg_to_front_m, prior.cg_to_front_m);

        // The same drives with the car's standard receiver: not determined.
        let drives: Vec<Experiment> = [1, 2]
            .iter()
            .map(|&s| sim_experiment_of("steps-at-speed", s, &plant, &car.vehicle))
            .collect();
        let why = identify::dynamics::identify_dynamics(&drives, &car.vehicle, &prior, 1.0)
            .expect_err("a standard receiver's course does not determine the stiffnesses");
        assert!(why.contains("standard errors"), "{name}: {why}");
    }
    // Through the whole pipeline: the written model file carries the identified pair (the
    // steering gain from the same drives), and reads back equal.
    let mut skewed_base = base.clone();
    if let Some(d) = skewed_base.dynamics.as_mut() {
        d.cornering_front_n_per_rad *= 0.5;
        d.cornering_rear_n_per_rad *= 2.0;
    }
    let rtk = with_rtk(VehicleConfig::default());
    let drives: Vec<Experiment> = [1, 2]
        .iter()
        .map(|&s| sim_experiment_of("steps-at-speed", s, &rtk, &base.vehicle))
        .collect();
    let id = identify::identify(
        drives,
        Vec::new(),
        &skewed_base,
        &IdentifyOptions::default(),
    )
    .unwrap();
    let fit = id.dynamics.as_ref().expect("[dynamics] identified");
    assert_eq!(id.model.dynamics, Some(fit.section));
    let written = id.model.dynamics.unwrap();
    assert!((written.cornering_front_n_per_rad / 80_000.0 - 1.0).abs() < 0.08);
    assert!((written.cornering_rear_n_per_rad / 91_000.0 - 1.0).abs() < 0.08);
    assert!(id
        .notes
        .iter()
        .any(|n| n.contains("cornering stiffnesses identified")));
    assert_round_trips(&id.model);

    // The paper's drives: no cornering at speed.
    let set = paper_sized_set();
    let prior = base.dynamics.unwrap();
    let why = identify::dynamics::identify_dynamics(&set, &base.vehicle, &prior, 1.0).unwrap_err();
    assert!(why.contains("step steers at speed"), "{why}");
}

/// A speed loop that answers later than the node's delay line holds (1.28 s): a plant whose
/// speed controller acts 1.4 s after the command, behind a 0.3 s lag. The model found runs on
/// the node (its delay within the line, the file written loads), and a note says that the
/// delay is at the limit, with the ARX search's; the CAT Vehicle's drives (0.88 s) get none.
#[test]
fn a_speed_loop_slower_than_the_node_takes_is_named() {
    let base = model_file::load(&model_file::paper_path()).unwrap();
    let mut slow = VehicleConfig::default();
    slow.speed_controller.command_delay_s = 1.4;
    let straights = |plant: &VehicleConfig| -> Vec<Experiment> {
        ["straight-2.5", "straight-5", "straight-7.5", "straight-10"]
            .iter()
            .map(|n| sim_experiment_of(n, 1, plant, &base.vehicle))
            .collect()
    };
    let at_limit = |id: &identify::Identification| {
        id.notes
            .iter()
            .find(|n| n.contains("the longest the node runs"))
            .cloned()
    };
    let id = identify::identify(
        straights(&slow),
        Vec::new(),
        &base,
        &IdentifyOptions::default(),
    )
    .unwrap();
    let note = at_limit(&id).expect("a note on the delay");
    println!("{note}");
    assert!(note.contains("64 samples"), "{note}");
    let delay_s = id.speed.tf.delay_s();
    assert!(delay_s <= 1.28 + 1e-9, "{delay_s}");
    assert_round_trips(&id.model);
    let id = identify::identify(
        straights(&VehicleConfig::default()),
        Vec::new(),
        &base,
        &IdentifyOptions::default(),
    )
    .unwrap();
    assert_eq!(at_limit(&id), None);
}

/// Drives of two receivers in one set: the paper-sized set with the car's standard receiver
/// (turns at 2.5 m/s, straights to 10 m/s) beside two runs of `steps-at-speed` with a
/// survey-grade one, on the CAT Vehicle (100 Hz) and on a car of 5 Hz. Each drive counts for
/// its own noise (`identify::stats::inverse_noise_weights`), so the set determines the
/// stiffnesses and the understeer as the step steers alone do: their standard errors at most
/// 1.2 times the step steers' alone (where those hold enough steady turning for an
/// understeer), and the values as close to the plant's. Counted alike,
/// the standard receiver's noise set every drive's error: on the 5 Hz car the stiffnesses'
/// standard errors were 14 % and 21 % (2.4 % and 3.8 % from the step steers alone) and the
/// understeer's 145 %, none of them written.
#[test]
fn drives_of_a_noisier_receiver_beside_do_not_hide_what_a_steadier_one_measured() {
    let base = model_file::load(&model_file::paper_path()).unwrap();
    let mut slow = VehicleConfig::default();
    slow.sensors.gnss.period_s = 0.2;
    let mut slow_car = base.clone();
    slow_car.vehicle.gnss_rate_hz = 5.0;
    for (name, plant, car) in [
        ("CAT Vehicle", VehicleConfig::default(), &base),
        ("the CAT Vehicle at 5 Hz", slow, &slow_car),
    ] {
        let rtk = with_rtk(plant.clone());
        let steps: Vec<Experiment> = [1, 2]
            .iter()
            .map(|&s| sim_experiment_of("steps-at-speed", s, &rtk, &car.vehicle))
            .collect();
        let mut mixed: Vec<Experiment> = PAPER_SIZED_TRAINING
            .iter()
            .map(|&(n, seed)| sim_experiment_of(n, seed, &plant, &car.vehicle))
            .collect();
        mixed.extend(steps.iter().cloned());
        let prior = car.dynamics.expect("the car file's [dynamics]");
        let fit = |drives: &[Experiment]| {
            identify::dynamics::identify_dynamics(drives, &car.vehicle, &prior, 1.0)
                .unwrap_or_else(|e| panic!("{name}: {e}"))
        };
        let (alone, both) = (fit(&steps), fit(&mixed));
        // The step steers alone may hold too few steady samples for a lateral fit (at 5 Hz).
        let lateral = |drives: &[Experiment]| {
            identify::identify_lateral(drives, &car.vehicle, &IdentifyOptions::default())
                .unwrap()
                .ok()
        };
        let (lateral_alone, lateral_both) = (lateral(&steps), lateral(&mixed));
        let lateral_both = lateral_both.expect("a lateral fit from the set");
        println!(
            "{name}: C_f, C_r +-{:.1} %, {:.1} % alone, +-{:.1} %, {:.1} % in the set; understeer {:?} alone, {:?} in the set",
            100.0 * alone.relative_std_error.0,
            100.0 * alone.relative_std_error.1,
            100.0 * both.relative_std_error.0,
            100.0 * both.relative_std_error.1,
            lateral_alone.map(|l| l.understeer),
            lateral_both.understeer
        );
        assert!(both.relative_std_error.0 < 1.2 * alone.relative_std_error.0);
        assert!(both.relative_std_error.1 < 1.2 * alone.relative_std_error.1);
        let truth = (
            plant.tyre_front.cornering_stiffness_n_per_rad,
            plant.tyre_rear.cornering_stiffness_n_per_rad,
        );
        let (cf, cr) = (
            both.section.cornering_front_n_per_rad,
            both.section.cornering_rear_n_per_rad,
        );
        assert!((cf / truth.0 - 1.0).abs() < 0.08, "{name}: C_f {cf}");
        assert!((cr / truth.1 - 1.0).abs() < 0.08, "{name}: C_r {cr}");
        let se = |u: &identify::Understeer| match u {
            identify::Understeer::Estimated { relative_std_error } => *relative_std_error,
            other => panic!("{name}: {other:?}"),
        };
        if let Some(alone) = lateral_alone {
            assert!(se(&lateral_both.understeer) < 1.2 * se(&alone.understeer));
        }
        let (k, plant_k) = (
            lateral_both.understeer_s2_per_m2,
            plant.understeer_s2_per_m2(),
        );
        assert!(
            (k / plant_k - 1.0).abs() < 0.15,
            "{name}: K {k} vs {plant_k}"
        );
    }
}

/// The understeer from drives with a standard receiver (the CAT Vehicle's 100 Hz, 1.2 m): the
/// steady turns' yaw rate, read off the course, does not determine it (a review's 4 Hz car gave
/// 0.0017 to 0.0057 over three seeds for the plant's 0.00215, and the node used it): the car
/// file's is kept, the estimate and its standard error said.
#[test]
fn an_understeer_the_drives_do_not_determine_is_the_car_files() {
    let base = model_file::load(&model_file::paper_path()).unwrap();
    let plant = VehicleConfig::default();
    let drives: Vec<Experiment> = [1, 2]
        .iter()
        .map(|&s| sim_experiment_of("steps-at-speed", s, &plant, &base.vehicle))
        .collect();
    let lateral = identify::identify_lateral(&drives, &base.vehicle, &IdentifyOptions::default())
        .unwrap()
        .unwrap();
    println!("{:?}", lateral.understeer);
    assert!(
        matches!(
            lateral.understeer,
            identify::Understeer::Undetermined { relative_std_error, .. }
                if relative_std_error > identify::MAX_UNDERSTEER_RELATIVE_STD_ERROR
        ),
        "{:?}",
        lateral.understeer
    );
    assert_eq!(
        lateral.understeer_s2_per_m2,
        base.vehicle.understeer_s2_per_m2
    );
}

/// The wheel speed's unit against the GNSS track (review finding 04: a training set in km/h,
/// inside the schema's range in town, was identified with exit 0 and a steering gain of 0.34
/// instead of 0.99). The simulator's drives in m/s pass at every receiver rate (1 to 100 Hz,
/// the CAT Vehicle's standard receiver and RTK, the Polo's 10 Hz and the van's 5 Hz, with
/// faults too); the same drives in km/h and mph are named as such.
#[test]
fn the_wheel_speed_unit_is_checked_against_the_gnss_track() {
    use catmodel_host::identify::units::SpeedScale;
    use catmodel_host::sim::{self, SimOptions};
    let vehicle = model_file::load(&model_file::paper_path()).unwrap().vehicle;
    let at_rate = |hz: f64| {
        let mut p = VehicleConfig::default();
        p.sensors.gnss.period_s = 1.0 / hz;
        (format!("CAT Vehicle at {hz} Hz"), p)
    };
    let mut plants = vec![
        ("CAT Vehicle".to_string(), VehicleConfig::default()),
        (
            "CAT Vehicle RTK".to_string(),
            with_rtk(VehicleConfig::default()),
        ),
        (
            "Polo (10 Hz)".to_string(),
            VehicleConfig::load(&vehicles_dir().join("vw-polo.toml")).unwrap(),
        ),
        (
            "van (5 Hz)".to_string(),
            VehicleConfig::load(&vehicles_dir().join("van.toml")).unwrap(),
        ),
    ];
    plants.extend([1.0, 2.0, 20.0, 50.0].map(at_rate));
    let scale_of = |plant: &VehicleConfig, scenario: &str, faults: bool, unit: f64| {
        let base = sim::scenario::Scenario::builtin(scenario).unwrap();
        let options = SimOptions {
            seed: 4,
            faults,
            ..SimOptions::default()
        };
        let mut rows = sim::simulate(&base, plant, &options).log;
        for r in &mut rows {
            r.vel = r.vel.map(|v| v * unit);
            r.input_vel = r.input_vel.map(|v| v * unit);
        }
        let e = preprocess_rows(scenario, &rows, &vehicle, &PreprocessOptions::default())
            .unwrap_or_else(|e| panic!("{scenario}: {e:#}"));
        e.speed_scale
    };
    let mut worst: f64 = 1.0;
    for (name, plant) in &plants {
        for scenario in [
            "straight-2.5",
            "straight-10",
            "turn-left",
            "circle-right",
            "suburb",
        ] {
            for faults in [false, true] {
                let what = format!("{name}, {scenario}, faults {faults}");
                let s: SpeedScale = scale_of(plant, scenario, faults, 1.0)
                    .unwrap_or_else(|| panic!("{what}: not judged"));
                assert_eq!(s.problem(), None, "{what}: {s:?}");
                println!("{what}: {:.3} over {} stretches", s.ratio, s.stretches);
                if (s.ratio - 1.0).abs() > (worst - 1.0).abs() {
                    worst = s.ratio;
                }
                if faults {
                    continue;
                }
                for (unit, label) in [(3.6, "km/h"), (2.236_936, "mph")] {
                    let s = scale_of(plant, scenario, faults, unit).unwrap();
                    let problem = s.problem().unwrap_or_else(|| panic!("{what}: {s:?}"));
                    assert!(
                        problem.contains(&format!("looks like {label}")),
                        "{what}, {label}: {problem}"
                    );
                }
            }
        }
    }
    println!("wheel over track distance, m/s drives: farthest from 1 {worst:.3}");
}

/// The wheel speed is moved to the antenna before its unit is judged (third probe, finding
/// 01): a 12 m bus with its antenna 6.5 m ahead of the rear axle ran its full-lock circles in
/// m/s at 0.68 times the speed along the GNSS track, and `identify` refused them as a unit
/// mistake. With the car file's antenna (ahead of the axle, or behind it and far to one side,
/// at the ends of the documented ranges), every drive in m/s is within a few per cent of 1,
/// and the same drives in km/h and mph are still named as such. With the antenna declared on
/// the axle (the check as it was), the bus's circles are refused.
#[test]
fn the_wheel_speed_is_moved_to_the_antenna_before_its_unit_is_judged() {
    use catmodel_host::closed_loop::model_file_for;
    use catmodel_host::sim::{self, SimOptions};
    let bus = VehicleConfig::load(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("../host/tests/data/bus-12m-20hz.toml"),
    )
    .unwrap();
    let with_antenna = |ahead: f64, left: f64| {
        let mut p = bus.clone();
        p.sensors.gnss.antenna_ahead_of_rear_axle_m = ahead;
        p.sensors.gnss.antenna_left_of_centre_line_m = left;
        p
    };
    // The documented ranges: -rear_overhang_m - 0.5 .. length_m - rear_overhang_m + 0.5 =
    // -3.5 .. 9.5 m ahead, width_m / 2 + 0.5 = 1.775 m to either side.
    let plants = [
        ("bus, antenna 6.5 m ahead", bus.clone(), true),
        (
            "bus, antenna 3.45 m behind, 1.75 m left",
            with_antenna(-3.45, 1.75),
            true,
        ),
        (
            "bus, antenna 9.45 m ahead, 1.75 m right",
            with_antenna(9.45, -1.75),
            true,
        ),
        (
            "bus, antenna on the rear axle",
            with_antenna(0.0, 0.0),
            false,
        ),
    ];
    let mut worst: f64 = 1.0;
    for (name, plant, lever) in &plants {
        let car = model_file_for(plant).unwrap().vehicle;
        assert_eq!(
            (car.antenna_ahead_m, car.antenna_left_m),
            (
                plant.sensors.gnss.antenna_ahead_of_rear_axle_m,
                plant.sensors.gnss.antenna_left_of_centre_line_m
            )
        );
        let mut on_axle = car;
        on_axle.antenna_ahead_m = 0.0;
        on_axle.antenna_left_m = 0.0;
        let mut refused_before = 0;
        for scenario in ["circle-left", "circle-right", "turn-left", "straight-10"] {
            let base = sim::scenario::Scenario::builtin(scenario).unwrap();
            let options = SimOptions {
                seed: 1,
                ..SimOptions::default()
            };
            let log = sim::simulate(&base, plant, &options).log;
            let scale = |vehicle: &model_file::VehicleSection, unit: f64| {
                let mut rows = log.clone();
                for r in &mut rows {
                    r.vel = r.vel.map(|v| v * unit);
                    r.input_vel = r.input_vel.map(|v| v * unit);
                }
                preprocess_rows(scenario, &rows, vehicle, &PreprocessOptions::default())
                    .unwrap_or_else(|e| panic!("{name}, {scenario}: {e:#}"))
                    .speed_scale
                    .unwrap_or_else(|| panic!("{name}, {scenario}: not judged"))
            };
            let what = format!("{name}, {scenario}");
            let before = scale(&on_axle, 1.0);
            let after = scale(&car, 1.0);
            println!(
                "{what}: wheel over track {:.3} (the rear axle's speed), {:.3} (moved to the \
                 antenna), over {} stretches",
                before.ratio, after.ratio, after.stretches
            );
            assert_eq!(after.problem(), None, "{what}: {after:?}");
            assert!((after.ratio - 1.0).abs() < 0.05, "{what}: {after:?}");
            if (after.ratio - 1.0).abs() > (worst - 1.0).abs() {
                worst = after.ratio;
            }
            if *lever {
                assert_eq!(
                    after.antenna_m,
                    Some((car.antenna_ahead_m, car.antenna_left_m))
                );
            } else {
                // No lever arm: the check as it was, to the last bit.
                assert_eq!(after, before, "{what}");
            }
            refused_before += usize::from(before.problem().is_some());
            for (unit, label) in [(3.6, "km/h"), (2.236_936, "mph")] {
                let s = scale(&car, unit);
                println!("{what}, {label}: {:.3}", s.ratio);
                let problem = s
                    .problem()
                    .unwrap_or_else(|| panic!("{what}, {label}: {s:?}"));
                assert!(
                    problem.contains(&format!("looks like {label}")),
                    "{what}, {label}: {problem}"
                );
                assert!(
                    (s.ratio / after.ratio / unit - 1.0).abs() < 0.02,
                    "{what}, {label}: {s:?} against {after:?}"
                );
            }
        }
        if name.contains("6.5 m ahead") {
            assert!(
                refused_before >= 2,
                "{name}: the circles were refused before"
            );
        }
    }
    println!("moved to the antenna, m/s drives: farthest from 1 {worst:.3}");
}

/// A steering sensor that clips (black-box probe: `steer` held at +-50 % while the wheels
/// turned to full lock gave the circles a steering gain of 1.97 and the turns 0.99, pooled into
/// 1.93 and written with exit 0: the node would have predicted twice the yaw rate). The logs'
/// gains disagree, and the clip is named with its level, on two cars and three receivers;
/// unclipped, one car's logs agree within a few per cent (at most 4.3 % measured on seven cars'
/// paper-sized sets), far inside `STEER_GAIN_SPREAD`.
#[test]
fn a_steering_sensor_that_clips_is_named() {
    for (name, plant, vehicle) in &four_plants("CAT Vehicle at 10 Hz", 0.1) {
        let set = |clip: f64| {
            let turns = ["turn-left", "turn-right", "circle-left", "circle-right"];
            steer_altered(name, plant, vehicle, &turns, |s| s.clamp(-clip, clip))
        };
        assert_eq!(
            identify::steering_problem(&set(100.0), vehicle),
            None,
            "{name}"
        );
        // At 10 Hz the turns' gains scatter by 0.2: a clip at 70 % (41 % apart) is within 3.5
        // standard errors of their difference, not told from the noise.
        let clips: &[f64] = if name.contains("10 Hz") {
            &[50.0]
        } else {
            &[50.0, 70.0]
        };
        for &clip in clips {
            let why = identify::steering_problem(&set(clip), vehicle)
                .unwrap_or_else(|| panic!("{name}, clipped at {clip} %: not named"));
            println!("{name}, clipped at {clip} %: {why}");
            assert!(why.contains("steering gains"), "{name}: {why}");
            assert!(
                why.contains(&format!("a steering sensor that clips at {clip:.1} %")),
                "{name}: {why}"
            );
        }
    }
}

/// A `steer` written as a fraction of the lock (-1..1) or as the road wheels' angle in radians
/// (black-box probe: `identify` exited 0 and wrote a model without `[lateral]`, its note
/// blaming the drives for too few turns; `compare` said nothing): every turn reads under the
/// 0.01 rad the steady turns need, so the turns are the GNSS course's, and the gain (about 100,
/// or 100 / max_steer_rad) is named with the likely unit, on two cars. In percent, or on
/// straight drives alone (a course that turns only by its noise at 2.5 m/s: a gain of 5 +- 23),
/// nothing is named.
#[test]
fn a_steering_as_a_fraction_or_in_radians_is_named() {
    let plants = four_plants("unused", 1.0);
    for (name, plant, vehicle) in [&plants[0], &plants[3]] {
        let lock_rad = vehicle.max_steer_deg.to_radians();
        let set = |scenarios: &[&str], scale: f64| {
            steer_altered(name, plant, vehicle, scenarios, |s| s * scale)
        };
        let turns = ["straight-5", "turn-left", "circle-left"];
        let straight = ["straight-2.5", "straight-10"];
        for (unit, scale) in [
            ("percent", 1.0),
            ("fraction", 0.01),
            ("radians", 0.01 * lock_rad),
        ] {
            let why = identify::steering_problem(&set(&straight, scale), vehicle);
            assert_eq!(why, None, "{name}, straight drives, {unit}");
            let why = identify::steering_problem(&set(&turns, scale), vehicle);
            println!("{name}, {unit}: {why:?}");
            match unit {
                "percent" => assert_eq!(why, None, "{name}"),
                "fraction" => {
                    let why = why.unwrap_or_else(|| panic!("{name}, {unit}: not named"));
                    assert!(why.contains("a fraction of full lock"), "{name}: {why}");
                }
                _ => {
                    let why = why.unwrap_or_else(|| panic!("{name}, {unit}: not named"));
                    assert!(
                        why.contains("road wheels' angle in radians"),
                        "{name}: {why}"
                    );
                }
            }
        }
    }
}

/// The steering's zero against the GNSS course (black-box probe: a `steer` 5 % off its zero,
/// clamped at the lock as a sensor is, gave a steering gain of 0.932 and a yaw-rate fit of
/// 65.9 % instead of 80.5 %, with exit 0 and no note). Drives whose zero is right are not
/// refused on two cars at receiver rates from 1 to 100 Hz, RTK and with faults; the same drives
/// with a zero 1.5 % or 3 % off, either way, are named with the offset to within 0.2 % and two
/// of its standard errors, and the fix that takes it out; 0.3 % off is within what is taken as
/// the car's.
#[test]
fn a_steering_zero_that_is_off_is_named_with_its_offset() {
    use catmodel_host::sim::{self, SimOptions};
    let paper = model_file::load(&model_file::paper_path()).unwrap().vehicle;
    let hatchback_file = vehicles_dir().join("../../models/hatchback.toml");
    let hatchback = model_file::load(&hatchback_file).unwrap().vehicle;
    let at_rate = |hz: f64| {
        let mut p = VehicleConfig::default();
        p.sensors.gnss.period_s = 1.0 / hz;
        (format!("CAT Vehicle at {hz} Hz"), p, paper)
    };
    let mut plants = vec![
        ("CAT Vehicle".to_string(), VehicleConfig::default(), paper),
        (
            "CAT Vehicle RTK".to_string(),
            with_rtk(VehicleConfig::default()),
            paper,
        ),
        (
            "hatchback".to_string(),
            VehicleConfig::load(&vehicles_dir().join("hatchback.toml")).unwrap(),
            hatchback,
        ),
    ];
    plants.extend([1.0, 5.0, 10.0].map(at_rate));
    let drive = |plant: &VehicleConfig, scenario: &str, seed: u64, faults: bool, offset: f64| {
        let base = sim::scenario::Scenario::builtin(scenario).unwrap();
        let options = SimOptions {
            seed,
            faults,
            ..SimOptions::default()
        };
        let mut rows = sim::simulate(&base, plant, &options).log;
        for r in &mut rows {
            r.steer = r.steer.map(|s| (s + offset).clamp(-100.0, 100.0));
        }
        rows
    };
    for (name, plant, vehicle) in &plants {
        for (scenario, seed, faults) in [("validation", 4, false), ("suburb", 4, true)] {
            let what = format!("{name}, {scenario}, faults {faults}");
            let experiment = |offset: f64| {
                let rows = drive(plant, scenario, seed, faults, offset);
                preprocess_rows(scenario, &rows, vehicle, &PreprocessOptions::default())
                    .unwrap_or_else(|e| panic!("{what}: {e:#}"))
            };
            let problem = |offset: f64| {
                identify::steering_problem(std::slice::from_ref(&experiment(offset)), vehicle)
            };
            assert_eq!(problem(0.0), None, "{what}");
            assert_eq!(problem(0.3), None, "{what}, 0.3 % off");
            for offset in [1.5, -3.0] {
                let Some(why) = problem(offset) else {
                    // A drive whose course is too noisy to tell 1.5 % says nothing; one that
                    // tells nothing at 3 % is a defect.
                    assert!(offset.abs() < 3.0, "{what}, {offset} % off: not named");
                    println!("{what}, {offset} % off: too noisy to tell");
                    continue;
                };
                let number_after = |marker: &str| -> f64 {
                    why.split(marker)
                        .nth(1)
                        .and_then(|r| r.split(' ').next())
                        .and_then(|z| z.parse().ok())
                        .unwrap_or_else(|| panic!("{what}: {why}"))
                };
                let (zero, se) = (number_after("`steer` = "), number_after(" % +- "));
                assert!(
                    (zero - offset).abs() < 0.2 + 2.0 * se,
                    "{what}, {offset} % off: {why}"
                );
                let fix = if offset > 0.0 {
                    format!("subtract {zero:.2} from every `steer`")
                } else {
                    format!("add {:.2} to every `steer`", -zero)
                };
                assert!(
                    why.starts_with("the steering's zero is off") && why.contains(&fix),
                    "{what}: {why}"
                );
                println!("{what}, {offset} % off: {zero:+.2} % +- {se}");
            }
        }
    }
}

/// A wheel speed without its sign (black-box probe: a `vel` that is the speed's magnitude while
/// the car reversed gave a speed delay of 0.20 s instead of 0.84, exit 0). Eq 5-like
/// responses (0.42 s delay, 1.2 s lag) to reverse commands: signed, as the schema has it,
/// nothing is said; the same as a magnitude is named with the stretch. A reverse asked for while
/// the car still rolls forward at 10 m/s (it brakes first) is not taken for one, nor a reverse
/// too short to have been taken.
#[test]
fn a_wheel_speed_without_its_sign_in_reverse_is_named() {
    use catmodel_host::identify::units::unsigned_reverse;
    let respond = |command: &[f64], v0: f64| -> Vec<f64> {
        let (delay, tau) = (21, 1.2);
        let mut v = v0;
        (0..command.len())
            .map(|k| {
                let u = if k >= delay { command[k - delay] } else { v0 };
                v += (u - v) * 0.02 / tau;
                v
            })
            .collect()
    };
    let check = |what: &str, command: Vec<f64>, v0: f64, named: bool| {
        let vel = respond(&command, v0);
        let signed = experiment(what, command.clone(), vel.clone());
        assert_eq!(unsigned_reverse(&signed), None, "{what}: signed");
        let magnitude = experiment(what, command, vel.iter().map(|v| v.abs()).collect());
        let why = unsigned_reverse(&magnitude);
        assert_eq!(why.is_some(), named, "{what}: {why:?}");
        why
    };
    let why = check(
        "park and reverse",
        steps(&[(10.0, 3.0), (5.0, 0.0), (8.0, -2.0), (5.0, 0.0)]),
        0.0,
        true,
    )
    .unwrap();
    assert!(
        why.starts_with(
            "`vel` stays positive while `input_vel` asks for reverse (t = 15.0 to 23.0 s"
        ) && why.contains("`input_vel` -2.00 m/s")
            && why.contains("1 such stretch(es)")
            && why.contains("negative in reverse"),
        "{why}"
    );
    // Reverse asked for at 10 m/s: the signed speed crosses 0 after 3.3 s.
    check(
        "reverse from speed",
        steps(&[(10.0, 10.0), (12.0, -1.0), (5.0, 0.0)]),
        10.0,
        true,
    );
    // Asked for briefly at 20 m/s: the car is still braking when the command ends (1.9 m/s
    // 3 s on, 0.2 m/s at the end): no reverse to judge.
    check(
        "reverse from 20 m/s, briefly",
        steps(&[(10.0, 20.0), (4.5, -0.5), (5.0, 0.0)]),
        20.0,
        false,
    );
    check(
        "a short reverse",
        steps(&[(5.0, 0.0), (3.2, -1.0), (5.0, 0.0)]),
        0.0,
        false,
    );
}

/// A lateral fit below the floor because the GNSS course is poor is said to be the course's
/// (black-box probe: a 5 Hz receiver with 0.5 m of white noise per axis, the car at a crawl
/// in places, was blamed on "one sample far outside the rest: a corrupt value there?", and 2 s
/// multipath bursts on "too little excitation" with the steering spanning 160 %). The
/// kinematic model, with nothing fitted, fits the course's yaw rate as poorly: that is the
/// cause named. The same drive from the standard receiver passes the floor.
#[test]
fn a_lateral_fit_spoilt_by_the_course_names_the_course() {
    use catmodel_host::identify::floor::{check, Which};
    let base = model_file::load(&model_file::paper_path()).unwrap();
    let mut cheap = VehicleConfig::default();
    cheap.sensors.gnss.period_s = 0.2;
    // 1 m: with the differences' window at the log's own 5 Hz (since they no longer follow
    // the base file's 100 Hz) 0.5 m passes the floor.
    cheap.sensors.gnss.white_noise_m = 1.0;
    let lateral = |plant: &VehicleConfig| {
        let drive = sim_experiment_of("validation", 1, plant, &base.vehicle);
        let id = identify::identify(vec![drive], Vec::new(), &base, &IdentifyOptions::default())
            .unwrap();
        check(&id).into_iter().find(|v| v.model == Which::Lateral)
    };
    assert_eq!(lateral(&VehicleConfig::default()), None);
    let v = lateral(&cheap).expect("below the floor");
    assert!(
        v.cause
            .starts_with("the yaw rate from the GNSS course is what fits poorly, not the model")
            && v.cause.contains("the steering spans")
            && v.suspect.is_none(),
        "{v}"
    );
}

/// Fixes that reach the log late (black-box probe: 0.3 s, timestamped at their arrival, moved
/// the lateral model's time constant from 0.04 to 0.14 s without a word) are timed against the
/// wheel speed and named. The simulator's drives with the fixes moved 0.1 and 0.3 s late give
/// those latencies to within 0.03 s and two standard errors; as recorded, on the CAT Vehicle
/// and the hatchback, their latency is within 0.05 s of 0 and nothing is said. 1.5 s late (a
/// receiver's clock behind the logger's) was beyond the 1 s searched before, and unnamed.
#[test]
fn fixes_that_reach_the_log_late_are_timed_and_named() {
    use catmodel_host::identify::units::gnss_latency;
    use catmodel_host::sim::{self, SimOptions};
    let paper = model_file::load(&model_file::paper_path()).unwrap();
    let hatchback_file = vehicles_dir().join("../../models/hatchback.toml");
    let hatchback = model_file::load(&hatchback_file).unwrap().vehicle;
    let plants = [
        ("CAT Vehicle", VehicleConfig::default(), paper.vehicle),
        (
            "hatchback",
            VehicleConfig::load(&vehicles_dir().join("hatchback.toml")).unwrap(),
            hatchback,
        ),
    ];
    for (name, plant, vehicle) in &plants {
        let base = sim::scenario::Scenario::builtin("validation").unwrap();
        let options = SimOptions {
            seed: 2,
            ..SimOptions::default()
        };
        let rows = sim::simulate(&base, plant, &options).log;
        let fixes: Vec<usize> = (0..rows.len()).filter(|&i| rows[i].lat.is_some()).collect();
        let period = (rows[fixes[1]].t - rows[fixes[0]].t).max(1e-3);
        for late_s in [0.0, 0.1, 0.3, 1.5] {
            // Each fix's row takes the fix `late_s` before it.
            let behind = (late_s / period).round() as usize;
            let mut late = rows.clone();
            for (j, &i) in fixes.iter().enumerate() {
                let earlier = j.checked_sub(behind).map(|e| &rows[fixes[e]]);
                late[i].lat = earlier.and_then(|r| r.lat);
                late[i].lon = earlier.and_then(|r| r.lon);
            }
            let what = format!("{name}, fixes {late_s} s late");
            let e = preprocess_rows("validation", &late, vehicle, &PreprocessOptions::default())
                .unwrap_or_else(|e| panic!("{what}: {e:#}"));
            let (lag, se) = gnss_latency(&e).unwrap_or_else(|| panic!("{what}: not timed"));
            println!("{what}: {lag:.3} +- {se:.3} s");
            // Within 0.03 s and two standard errors, and a tenth of the latency (the fit reads
            // 7-12 % short: 0.265 for 0.3 s, 1.39 for 1.5 s on the CAT Vehicle).
            assert!(
                (lag - late_s).abs() < 0.03 + 2.0 * se + 0.1 * late_s,
                "{what}: {lag} +- {se}"
            );
            if late_s == 0.0 {
                assert!(lag.abs() < 0.05, "{what}: {lag} +- {se}");
            }
            let base_file = if *name == "hatchback" {
                model_file::load(&hatchback_file).unwrap()
            } else {
                paper.clone()
            };
            let id =
                identify::identify(vec![e], Vec::new(), &base_file, &IdentifyOptions::default())
                    .unwrap();
            let named = id.notes.iter().find(|n| n.contains("the GNSS fixes are"));
            assert_eq!(named.is_some(), late_s > 0.2, "{what}: {named:?}");
            if let Some(note) = named {
                assert!(
                    note.starts_with(&format!(
                        "validation: the GNSS fixes are {}.",
                        late_s as u32
                    )) && note.contains("late behind the wheel speed"),
                    "{what}: {note}"
                );
            }
        }
    }
}

/// The CAT Vehicle's `scenario` (seed `seed`) with its fixes stamped `late_s` later (on their
/// own rows, as a recorder that stamps them with another clock writes them), preprocessed.
fn with_fixes_late(scenario: &str, seed: u64, late_s: f64) -> Experiment {
    let base = model_file::load(&model_file::paper_path()).unwrap();
    let rows = simulated(scenario, seed);
    let mut moved: Vec<LogRow> = Vec::new();
    for r in rows {
        if let (Some(lat), Some(lon)) = (r.lat, r.lon) {
            moved.push(LogRow {
                lat: Some(lat),
                lon: Some(lon),
                ..LogRow::empty(r.t + late_s)
            });
        }
        let rest = LogRow {
            lat: None,
            lon: None,
            ..r
        };
        if rest != LogRow::empty(r.t) {
            moved.push(rest);
        }
    }
    moved.sort_by(|a, b| a.t.total_cmp(&b.t));
    let name = format!("{scenario}-{seed}");
    preprocess_rows(&name, &moved, &base.vehicle, &PreprocessOptions::default())
        .unwrap_or_else(|e| panic!("{name}: {e:#}"))
}

/// GNSS fixes stamped seconds off the other sensors (a black-box probe: 3 s and 18 s late, GPS
/// time logged as UTC, were refused as "a wheel speed that sticks ... or fixes of another
/// receiver"; up to 2.5 s the latency is named) are named as another clock, with the offset,
/// and moved onto the sensors' clock: within 0.1 s of the truth (0.06 s at most measured), 3
/// and 18 s late and 7 s early, on straights, turns, circles and the 5-minute drive; nothing
/// said of the wheel speed; the model identified from logs 18 s late has the speed delay and
/// the lateral fit of the logs as recorded. As recorded, nothing is named.
#[test]
fn fixes_on_another_clock_are_named_and_moved_onto_the_sensors() {
    let drives = [
        ("straight-5", 1),
        ("straight-10", 2),
        ("turn-left", 1),
        ("circle-left", 1),
        ("validation", 3),
    ];
    let clock_note = |e: &Experiment| {
        e.log_notes
            .iter()
            .find(|n| n.contains("another clock"))
            .cloned()
    };
    let offset_in = |note: &str, side: &str| -> f64 {
        let at = note.find("the GNSS fixes run ").expect("offset") + 19;
        let rest = &note[at..];
        assert!(
            rest.contains(&format!(" s {side} the other sensors")),
            "{note}"
        );
        rest.split(' ').next().unwrap().parse().unwrap()
    };
    let mut late = Vec::new();
    let mut on_time = Vec::new();
    for (scenario, seed) in drives {
        for (late_s, side) in [(3.0, "behind"), (18.0, "behind"), (-7.0, "ahead of")] {
            let e = with_fixes_late(scenario, seed, late_s);
            let note = clock_note(&e).unwrap_or_else(|| panic!("{}: {:?}", e.name, e.log_notes));
            let found = offset_in(&note, side);
            println!("{} {late_s} s: found {found} s {side}", e.name);
            assert!((found - late_s.abs()).abs() <= 0.1, "{}: {note}", e.name);
            assert_eq!(e.speed_disagreement, None, "{}", e.name);
            if late_s == 18.0 {
                late.push(e);
            }
        }
        let e = with_fixes_late(scenario, seed, 0.0);
        assert_eq!(clock_note(&e), None, "{}", e.name);
        on_time.push(e);
    }
    let base = model_file::load(&model_file::paper_path()).unwrap();
    let opts = IdentifyOptions::default();
    let [late_val, on_time_val] = [&mut late, &mut on_time].map(|set| set.split_off(4));
    let yaw_fit = |id: &identify::Identification| {
        id.validation_scores
            .as_ref()
            .and_then(|v| v.yaw_model)
            .and_then(|s| s.fit_percent)
            .expect("a lateral validation fit")
    };
    let moved = identify::identify(late, late_val, &base, &opts).unwrap();
    let recorded = identify::identify(on_time, on_time_val, &base, &opts).unwrap();
    println!(
        "speed delay {} s (as recorded {} s); lateral validation fit {:.2} % ({:.2} %)",
        moved.speed.tf.delay_s(),
        recorded.speed.tf.delay_s(),
        yaw_fit(&moved),
        yaw_fit(&recorded)
    );
    assert_eq!(moved.speed.tf.delay_s(), recorded.speed.tf.delay_s());
    assert!(
        (yaw_fit(&moved) - yaw_fit(&recorded)).abs() < 1.0,
        "{} against {}",
        yaw_fit(&moved),
        yaw_fit(&recorded)
    );
}

/// `lat`/`lon` written with too few decimals of a degree (a black-box probe: 4 decimals, 11 m
/// steps, drew dozens of multipath and impossible-sample notes and a refusal for a steering
/// gain of -0.763, the resolution never named; 5 decimals, 1.1 m, wrote a file whose dx/dt
/// model validated 17 points below the same drive's written in full). Refused with 4 decimals,
/// named in a note with 5, nothing said with 6 or the simulator's full precision.
#[test]
fn fixes_written_with_too_few_decimals_are_named() {
    use catmodel_host::sim::{self, SimOptions};
    let base = model_file::load(&model_file::paper_path()).unwrap();
    let scenario = sim::scenario::Scenario::builtin("validation").unwrap();
    let options = SimOptions {
        seed: 2,
        ..SimOptions::default()
    };
    let rows = sim::simulate(&scenario, &VehicleConfig::default(), &options).log;
    let written = |decimals: i32| -> Vec<_> {
        let scale = 10f64.powi(decimals);
        rows.iter()
            .cloned()
            .map(|mut r| {
                r.lat = r.lat.map(|v| (v * scale).round() / scale);
                r.lon = r.lon.map(|v| (v * scale).round() / scale);
                r
            })
            .collect()
    };
    let preprocess = |rows: &[_]| {
        preprocess_rows(
            "validation",
            rows,
            &base.vehicle,
            &PreprocessOptions::default(),
        )
    };
    let err = preprocess(&written(4)).expect_err("4 decimals");
    let err = format!("{err:#}");
    assert!(
        err.contains("written with 4 decimals") && err.contains("step by 11.1 m"),
        "{err}"
    );
    let five = preprocess(&written(5)).unwrap();
    assert!(
        five.log_notes
            .iter()
            .any(|n| n.contains("written with 5 decimals") && n.contains("1.1 m")),
        "{:?}",
        five.log_notes
    );
    for rows in [written(6), rows.clone()] {
        let e = preprocess(&rows).unwrap();
        assert!(
            !e.log_notes.iter().any(|n| n.contains("decimals")),
            "{:?}",
            e.log_notes
        );
    }
}

/// Fixes lost one or two at a time are no outage (black-box probe: a 100 Hz receiver losing
/// 10 % of its fixes at random had 53 s of every minute left out of the track's fits as
/// "outage", and 288 of the validation drive's 301 s, where a straight line across 20-30 ms is
/// the track). The validation drive at 100 Hz and at 50 Hz with 10 % of its fixes dropped
/// (independent losses, a fixed pseudo-random pattern): no outage note, under 1 % of it left
/// out (94 % at 100 Hz before), and the same model scores within half a point of its score on
/// the whole drive; a gap of 0.5 s still is one. (A slower receiver's gaps of two or three
/// periods were outages before and are: at 10 Hz, 0.3 s.)
#[test]
fn fixes_lost_one_at_a_time_are_no_outage() {
    use catmodel_host::sim::{self, SimOptions};
    let base = model_file::load(&model_file::paper_path()).unwrap();
    let mut fifty_hz = VehicleConfig::default();
    fifty_hz.sensors.gnss.period_s = 0.02;
    for (name, plant) in [("100 Hz", VehicleConfig::default()), ("50 Hz", fifty_hz)] {
        let scenario = sim::scenario::Scenario::builtin("validation").unwrap();
        let options = SimOptions {
            seed: 2,
            ..SimOptions::default()
        };
        let rows = sim::simulate(&scenario, &plant, &options).log;
        // xorshift64: independent losses, two or three in a row as often as chance has them.
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let lossy: Vec<_> = rows
            .iter()
            .cloned()
            .map(|mut r| {
                if r.lat.is_some() {
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    if state % 1000 < 100 {
                        r.lat = None;
                        r.lon = None;
                    }
                }
                r
            })
            .collect();
        let experiment = |rows: &[_]| {
            preprocess_rows(
                "validation",
                rows,
                &base.vehicle,
                &PreprocessOptions::default(),
            )
            .unwrap()
        };
        let (whole, lossy) = (experiment(&rows), experiment(&lossy));
        let left_out = (0..lossy.len()).filter(|k| lossy.in_gnss_gap(*k)).count();
        let share = left_out as f64 / lossy.len() as f64;
        let fit = |on: &Experiment| {
            let id = identify::identify(
                vec![whole.clone()],
                vec![on.clone()],
                &base,
                &IdentifyOptions::default(),
            )
            .unwrap();
            id.validation_scores
                .unwrap()
                .yaw_model
                .unwrap()
                .fit_percent
                .unwrap()
        };
        let (on_whole, on_lossy) = (fit(&whole), fit(&lossy));
        println!(
            "{name}, 10 % of the fixes lost: {:.1} % left out, yaw fit {on_lossy:.2} % against \
             {on_whole:.2} % on the whole drive",
            100.0 * share
        );
        assert!(
            !lossy.log_notes.iter().any(|n| n.contains("GNSS outage")),
            "{name}: {:?}",
            lossy.log_notes
        );
        assert!(share < 0.01, "{name}: {:.1} % left out", 100.0 * share);
        assert!(
            (on_lossy - on_whole).abs() < 0.5,
            "{name}: {on_lossy} against {on_whole}"
        );
        // Half a second without a fix is still an outage.
        let paused: Vec<_> = rows
            .iter()
            .cloned()
            .map(|mut r| {
                if (100.0..100.5).contains(&r.t) {
                    r.lat = None;
                    r.lon = None;
                }
                r
            })
            .collect();
        assert!(
            experiment(&paused)
                .log_notes
                .iter()
                .any(|n| n.contains("GNSS outage")),
            "{name}: a 0.5 s gap"
        );
    }
}

/// GNSS outages are left out of the fits and scores that use the track (black-box probe: eight
/// outages of 2-4 s in the turns took the steering gain 4 % low, 0.945, and the yaw-rate fit
/// to 63.7 %, where the same model scores 80.5 % on the drive without them: the track was
/// interpolated in a straight line across the turns). The simulator's validation drive with
/// its fixes cut for 3 s in each of its eight sharpest turns: the model identified from it has
/// a steering gain within 2 % of the uncut drive's model, and scores within 2 points of it on
/// the uncut drive; on the cut drive the two models score within 2 points of each other (its
/// score there, on the turns left, is its own); the outage is named in a note.
#[test]
fn gnss_outages_are_left_out_of_the_track_fits() {
    let base = model_file::load(&model_file::paper_path()).unwrap();
    let plant = VehicleConfig::default();
    let clean = sim_experiment_of("validation", 2, &plant, &base.vehicle);
    // The eight sharpest turns, 10 s apart at least.
    let mut order: Vec<usize> = (0..clean.len()).collect();
    order.sort_by(|a, b| {
        clean.yaw_rate[*b]
            .abs()
            .total_cmp(&clean.yaw_rate[*a].abs())
    });
    let mut turns: Vec<f64> = Vec::new();
    for k in order {
        let t = clean.t[k];
        if turns.iter().all(|u| (u - t).abs() > 10.0) {
            turns.push(t);
        }
        if turns.len() == 8 {
            break;
        }
    }
    let rows = {
        use catmodel_host::sim::{self, SimOptions};
        let scenario = sim::scenario::Scenario::builtin("validation").unwrap();
        let options = SimOptions {
            seed: 2,
            ..SimOptions::default()
        };
        let mut rows = sim::simulate(&scenario, &plant, &options).log;
        for r in &mut rows {
            if turns.iter().any(|t| (r.t - t).abs() < 1.5) {
                r.lat = None;
                r.lon = None;
            }
        }
        rows
    };
    let cut = preprocess_rows(
        "validation",
        &rows,
        &base.vehicle,
        &PreprocessOptions::default(),
    )
    .unwrap();
    assert!(
        cut.log_notes
            .iter()
            .any(|n| n.starts_with("validation: 24.")
                && n.contains(" s of GNSS outage")
                && n.contains("left out")),
        "{:?}",
        cut.log_notes
    );
    // (steering gain, yaw-rate fit on the uncut drive, on the cut drive)
    let lateral = |training: &Experiment| {
        let score = |on: &Experiment| {
            let id = identify::identify(
                vec![training.clone()],
                vec![on.clone()],
                &base,
                &IdentifyOptions::default(),
            )
            .unwrap();
            let gain = id.model.lateral.as_ref().expect("identified").steer_gain;
            (
                gain,
                id.validation_scores
                    .unwrap()
                    .yaw_model
                    .unwrap()
                    .fit_percent
                    .unwrap(),
            )
        };
        let (gain, on_clean) = score(&clean);
        (gain, on_clean, score(&cut).1)
    };
    let (gain0, clean0, cut0) = lateral(&clean);
    let (gain, on_clean, on_cut) = lateral(&cut);
    println!(
        "from the uncut drive: gain {gain0:.4}, yaw fit {clean0:.2} % uncut, {cut0:.2} % cut; \
         from the cut drive: gain {gain:.4}, {on_clean:.2} % uncut, {on_cut:.2} % cut"
    );
    assert!((gain / gain0 - 1.0).abs() < 0.02, "{gain} vs {gain0}");
    assert!((on_clean - clean0).abs() < 2.0, "{on_clean} vs {clean0}");
    assert!((on_cut - cut0).abs() < 2.0, "{on_cut} vs {cut0}");
    assert!((on_cut - clean0).abs() < 5.0, "{on_cut} vs {clean0}");
}

/// A log that stands much of its time says so (black-box probe: 300 s of standstill in a
/// 5-minute drive halved the validation MSE and raised the fit 2.8 points for the same model,
/// without a word): the simulator's `standstill` drive is noted with its share, the validation
/// drive (stops at junctions) is not.
#[test]
fn a_log_that_mostly_stands_says_so() {
    let stands = |scenario: &str| {
        sim_experiment(scenario, 1)
            .log_notes
            .into_iter()
            .find(|n| n.contains("the car stands"))
    };
    assert_eq!(stands("validation"), None);
    let note = stands("standstill").expect("noted");
    assert!(
        note.starts_with("standstill-1: the car stands ") && note.contains("read better than"),
        "{note}"
    );
}

/// Two logs of one file name from two folders (`a/drive.csv`, `b/drive.csv`) are told apart
/// by their paths in every note (each was named `drive` before, and the notes of one read as
/// the other's); a file name of its own stays short.
#[test]
fn logs_of_one_file_name_are_named_by_their_paths() {
    use catmodel_host::identify::preprocess::log_names;
    use std::path::PathBuf;
    let names = log_names(&[
        Path::new("a/drive.csv"),
        Path::new("b/drive.csv"),
        Path::new("b/turn.csv"),
        Path::new("plain"),
    ]);
    assert_eq!(names, ["a/drive", "b/drive", "turn", "plain"]);

    let dir = std::env::temp_dir().join(format!("catmodel-log-names-{}", std::process::id()));
    let out = catmodel_host::sim::run_named("standstill", None, &Default::default()).unwrap();
    let paths: Vec<PathBuf> = ["a", "b"]
        .iter()
        .map(|sub| {
            std::fs::create_dir_all(dir.join(sub)).unwrap();
            let path = dir.join(sub).join("drive.csv");
            catmodel_host::logcsv::write_log(&path, &out.log).unwrap();
            path
        })
        .collect();
    let base = model_file::load(&model_file::paper_path()).unwrap();
    let set = identify::load_all(&paths, &base.vehicle, &PreprocessOptions::default()).unwrap();
    for (e, path) in set.iter().zip(&paths) {
        let name = path.display().to_string().replace(".csv", "");
        assert_eq!(e.name, name);
        let note = e.log_notes.iter().find(|n| n.contains("the car stands"));
        assert!(
            note.is_some_and(|n| n.starts_with(&format!("{name}: "))),
            "{note:?}"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// Bursts of fixes that step off the track and back (multipath; black-box probe: one or two
/// bursts of 3-8 m for 2 s took the yaw-rate validation fit from 80.5 % to 68.1 %, five got a
/// correct lateral model refused, and neither the lone outlier's rule nor the step's saw them)
/// are found against the wheel speed, named and left out: the simulator's validation drive
/// with two such bursts (one in a turn) gives the same lateral model as without them (yaw-rate
/// fits within 1 point, steering gain within 1 %). No burst is found in the drives as recorded
/// on two cars at receiver rates from 1 to 100 Hz, RTK and with faults.
#[test]
fn bursts_of_fixes_off_the_track_are_found_and_left_out() {
    use catmodel_host::sim::{self, SimOptions};
    let base = model_file::load(&model_file::paper_path()).unwrap();
    let simulate = |plant: &VehicleConfig, scenario: &str, seed: u64, faults: bool| {
        let scenario = sim::scenario::Scenario::builtin(scenario).unwrap();
        let options = SimOptions {
            seed,
            faults,
            ..SimOptions::default()
        };
        sim::simulate(&scenario, plant, &options).log
    };
    let bursts_in = |e: &Experiment| {
        e.log_notes
            .iter()
            .find(|n| n.contains("burst(s) of fixes"))
            .cloned()
    };
    // None in clean drives.
    let hatchback_file = vehicles_dir().join("../../models/hatchback.toml");
    let hatchback = model_file::load(&hatchback_file).unwrap().vehicle;
    let mut plants = vec![
        ("CAT Vehicle", VehicleConfig::default(), base.vehicle),
        (
            "CAT Vehicle RTK",
            with_rtk(VehicleConfig::default()),
            base.vehicle,
        ),
        (
            "hatchback",
            VehicleConfig::load(&vehicles_dir().join("hatchback.toml")).unwrap(),
            hatchback,
        ),
    ];
    for hz in [1.0, 5.0, 10.0] {
        let mut p = VehicleConfig::default();
        p.sensors.gnss.period_s = 1.0 / hz;
        plants.push(("CAT Vehicle, slower receiver", p, base.vehicle));
    }
    for (name, plant, vehicle) in &plants {
        for (scenario, faults) in [
            ("validation", false),
            ("suburb", true),
            ("turn-left", false),
        ] {
            let rows = simulate(plant, scenario, 4, faults);
            let e =
                preprocess_rows(scenario, &rows, vehicle, &PreprocessOptions::default()).unwrap();
            assert_eq!(bursts_in(&e), None, "{name}, {scenario}, faults {faults}");
        }
    }
    // Two bursts in the validation drive: 3 m at their ends, 8 m in their middle, each in one
    // direction (3 + 5 sin(pi u), u over the burst's 2 s).
    let clean_rows = simulate(&VehicleConfig::default(), "validation", 2, false);
    let mut rows = clean_rows.clone();
    let bursts = [(70.0, 0.7), (150.0, 2.5)];
    for r in &mut rows {
        for &(start, direction) in &bursts {
            let u = (r.t - start) / 2.0;
            if (0.0..1.0).contains(&u) {
                let m = 3.0 + 5.0 * (std::f64::consts::PI * u).sin();
                if let (Some(lat), Some(lon)) = (r.lat, r.lon) {
                    r.lat = Some(lat + m * f64::cos(direction) / 111_320.0);
                    r.lon =
                        Some(lon + m * f64::sin(direction) / (111_320.0 * lat.to_radians().cos()));
                }
            }
        }
    }
    let opts = PreprocessOptions::default();
    let clean = preprocess_rows("validation", &clean_rows, &base.vehicle, &opts).unwrap();
    let burst = preprocess_rows("validation", &rows, &base.vehicle, &opts).unwrap();
    let note = bursts_in(&burst).expect("found");
    assert!(
        note.starts_with("validation: 2 burst(s) of fixes"),
        "{note}"
    );
    let validation = sim_experiment_of("validation", 3, &VehicleConfig::default(), &base.vehicle);
    let lateral = |e: Experiment| {
        let id = identify::identify(
            vec![e],
            vec![validation.clone()],
            &base,
            &IdentifyOptions::default(),
        )
        .unwrap();
        let gain = id.model.lateral.as_ref().expect("identified").steer_gain;
        let fit = |s: Option<validate::Score>| s.unwrap().fit_percent.unwrap();
        (
            gain,
            fit(id.training_scores.yaw_model),
            fit(id.validation_scores.unwrap().yaw_model),
        )
    };
    let (gain0, training0, validation0) = lateral(clean);
    let (gain, training, validation_fit) = lateral(burst);
    println!(
        "without the bursts: gain {gain0:.4}, yaw fit {training0:.2} / {validation0:.2} %; \
         with them: {gain:.4}, {training:.2} / {validation_fit:.2} %"
    );
    assert!((gain / gain0 - 1.0).abs() < 0.01, "{gain} vs {gain0}");
    assert!(
        (training - training0).abs() < 1.0,
        "{training} vs {training0}"
    );
    assert!(
        (validation_fit - validation0).abs() < 1.0,
        "{validation_fit} vs {validation0}"
    );
}

/// `simulate-drive` names a drive in which the car slid beyond its tyres' grip (a black-box
/// probe's 220 kg kart spun in the built-in validation drive, sideslip 1.29 rad, and
/// `identify` blamed the validation fit on another car or a fault). The CAT Vehicle and the
/// hatchback drive the built-in scenarios inside their grip on three seeds: no warning; the
/// city car (`host/vehicles/city-car.toml`) spins into the validation drive's tight turn at
/// 112 s on seed 3 (the rear axle's sideslip to 0.9 rad at 3 m/s): named, with the time.
#[test]
fn a_simulated_drive_beyond_the_grip_is_named() {
    use catmodel_host::sim::{self, SimOptions};
    let load = |name: &str| VehicleConfig::load(&vehicles_dir().join(name)).unwrap();
    for (name, cfg) in [
        ("CAT Vehicle", VehicleConfig::default()),
        ("hatchback", load("hatchback.toml")),
    ] {
        for scenario in ["validation", "circle-left", "steps-at-speed", "suburb"] {
            for seed in 1..=3 {
                let options = SimOptions {
                    seed,
                    ..SimOptions::default()
                };
                let out = sim::run_named_on(scenario, &cfg, &options).unwrap();
                assert_eq!(
                    sim::slide_warning(scenario, &out.truth, &cfg),
                    None,
                    "{name}, {scenario}, seed {seed}"
                );
            }
        }
    }
    let city = load("city-car.toml");
    let options = SimOptions {
        seed: 3,
        ..SimOptions::default()
    };
    let out = sim::run_named_on("validation", &city, &options).unwrap();
    let warning = sim::slide_warning("validation", &out.truth, &city).expect("named");
    assert!(
        warning.starts_with("validation: the car slid beyond its tyres' grip")
            && warning.contains("from t = 112."),
        "{warning}"
    );
}

/// The built-in `scenarios` simulated on `plant` (seed 1), each log's `steer` passed through
/// `alter`, preprocessed for `vehicle`.
fn steer_altered(
    name: &str,
    plant: &VehicleConfig,
    vehicle: &model_file::VehicleSection,
    scenarios: &[&str],
    alter: impl Fn(f64) -> f64,
) -> Vec<Experiment> {
    use catmodel_host::sim::{self, SimOptions};
    scenarios
        .iter()
        .map(|scenario| {
            let base = sim::scenario::Scenario::builtin(scenario).unwrap();
            let options = SimOptions {
                seed: 1,
                ..SimOptions::default()
            };
            let mut rows = sim::simulate(&base, plant, &options).log;
            for r in &mut rows {
                r.steer = r.steer.map(&alter);
            }
            preprocess_rows(scenario, &rows, vehicle, &PreprocessOptions::default())
                .unwrap_or_else(|e| panic!("{name}, {scenario}: {e:#}"))
        })
        .collect()
}

/// Four plants with the model file's vehicle section each is identified with: the CAT
/// Vehicle with its receiver, with RTK, and with a receiver every `slow_period_s` (named
/// `slow_name`), and the hatchback.
fn four_plants(
    slow_name: &'static str,
    slow_period_s: f64,
) -> [(&'static str, VehicleConfig, model_file::VehicleSection); 4] {
    let paper = model_file::load(&model_file::paper_path()).unwrap().vehicle;
    let hatchback_file = vehicles_dir().join("../../models/hatchback.toml");
    let hatchback = model_file::load(&hatchback_file).unwrap().vehicle;
    let mut slow = VehicleConfig::default();
    slow.sensors.gnss.period_s = slow_period_s;
    [
        ("CAT Vehicle", VehicleConfig::default(), paper),
        ("CAT Vehicle RTK", with_rtk(VehicleConfig::default()), paper),
        (slow_name, slow, paper),
        (
            "hatchback",
            VehicleConfig::load(&vehicles_dir().join("hatchback.toml")).unwrap(),
            hatchback,
        ),
    ]
}

/// An edit of a log row with a fix, given the fix of the row before (as edited).
type FixEdit = dyn Fn(&mut LogRow, Option<(f64, f64)>);

/// A wheel speed that sticks (black-box probe: a `vel` stuck for 20 s passed without a word;
/// stuck through a stop, the speed model's fit fell from 82 % to 63 % and the lateral fit was
/// refused for the receiver's course, which was right). Stuck at its cruising value from 4 s
/// before the stop, the span is named, from when the car slowed to the log's end;
/// dropped to zero while the car cruises, named the other way; untouched, nothing is named.
/// Fixes off the track for 3 s are no disagreement, and fixes held are named as the fixes'.
/// On three receivers (100 Hz, RTK, 1 Hz) and a second car.
#[test]
fn a_wheel_speed_that_sticks_is_named() {
    use catmodel_host::sim::{self, SimOptions};
    for (name, plant, vehicle) in &four_plants("CAT Vehicle at 1 Hz", 1.0) {
        let base = sim::scenario::Scenario::builtin("straight-10").unwrap();
        let options = SimOptions {
            seed: 4,
            ..SimOptions::default()
        };
        let rows = sim::simulate(&base, plant, &options).log;
        let judged = |edit: &dyn Fn(f64, f64) -> f64| {
            let mut rows = rows.clone();
            for r in &mut rows {
                r.vel = r.vel.map(|v| edit(r.t, v));
            }
            preprocess_rows("straight-10", &rows, vehicle, &PreprocessOptions::default())
                .unwrap_or_else(|e| panic!("{name}: {e:#}"))
                .speed_disagreement
        };
        assert_eq!(judged(&|_, v| v), None, "{name}: untouched");
        // Stuck from 4 s before the command to stop (the car cruises at 10 m/s until then).
        let stop = rows
            .iter()
            .find(|r| r.t > 30.0 && r.input_vel == Some(0.0))
            .map(|r| r.t)
            .unwrap();
        let from = stop - 4.0;
        let held = rows
            .iter()
            .find(|r| r.t >= from && r.vel.is_some())
            .and_then(|r| r.vel)
            .unwrap();
        let stuck = judged(&|t, v| if t >= from { held } else { v })
            .unwrap_or_else(|| panic!("{name}: a wheel speed stuck through the stop not named"));
        println!("{name}: stop at {stop:.1} s, stuck: {}", stuck.problem());
        assert!(stuck.wheel_m > stuck.track_m + 20.0, "{name}: {stuck:?}");
        assert!(
            (stop..=stop + 5.0).contains(&stuck.from_s) && stuck.to_s >= stop + 6.0,
            "{name}: {stuck:?}"
        );
        assert!(
            stuck.problem().contains("sticks at its last value"),
            "{name}"
        );
        // Zero from 20 to 30 s while the car cruises.
        let zero = judged(&|t, v| if (20.0..30.0).contains(&t) { 0.0 } else { v })
            .unwrap_or_else(|| panic!("{name}: a wheel speed at zero while moving not named"));
        println!("{name}: zero: {}", zero.problem());
        assert!(zero.track_m > zero.wheel_m + 40.0, "{name}: {zero:?}");
        assert!(zero.from_s >= 17.0 && zero.to_s <= 33.0, "{name}: {zero:?}");
        assert!(zero.problem().contains("drops to zero"), "{name}");
        assert!(!zero.car_stood, "{name}: the commands ask the car to move");
        // The receiver's, not the wheel speed's: once the car stands (15 s more of it), 3 s
        // without fixes, then fixes 18 m off converging back over 8 s (the ninth probe's
        // receiver after an outage).
        let mut parked = base.clone();
        parked.segments.last_mut().unwrap().duration_s += 15.0;
        let mut parked = sim::simulate(&parked, plant, &options).log;
        for r in &mut parked {
            if (58.0..61.0).contains(&r.t) {
                (r.lat, r.lon) = (None, None);
            } else if (61.0..69.0).contains(&r.t) {
                // 15 m east and 10 m north at first (18 m), none at the end.
                let off = (69.0 - r.t) / 8.0;
                let m_per_deg = 111_320.0 * sim::geo::ORIGIN_LAT_DEG.to_radians().cos();
                r.lon = r.lon.map(|lon| lon + 15.0 * off / m_per_deg);
                r.lat = r.lat.map(|lat| lat + 10.0 * off / 111_320.0);
            }
        }
        let converging = preprocess_rows("parked", &parked, vehicle, &PreprocessOptions::default())
            .unwrap_or_else(|e| panic!("{name}: {e:#}"))
            .speed_disagreement;
        println!("{name}: converging: {converging:?}");
        if name.contains("1 Hz") {
            assert!(converging.is_none_or(|d| d.car_stood), "{name}");
        } else {
            let d = converging.unwrap_or_else(|| panic!("{name}: the receiver's motion"));
            assert!(d.car_stood && d.track_m > 10.0, "{name}: {d:?}");
            assert!(
                d.problem().contains("re-converging after an outage"),
                "{name}"
            );
        }
        // Speed steps: stuck at 8 m/s from 22 to 40 s while the car speeds up to 12 m/s at
        // 28 s (less than half: the windows alone do not tell it), named as held; a healthy
        // wheel speed of 5 km/h steps holds its values too, and is not.
        let steps = sim::scenario::Scenario::builtin("steps-at-speed").unwrap();
        let steps = sim::simulate(&steps, plant, &options).log;
        let judged_steps = |edit: &dyn Fn(f64, f64) -> f64| {
            let mut rows = steps.clone();
            for r in &mut rows {
                r.vel = r.vel.map(|v| edit(r.t, v));
            }
            preprocess_rows(
                "steps-at-speed",
                &rows,
                vehicle,
                &PreprocessOptions::default(),
            )
            .unwrap_or_else(|e| panic!("{name}: {e:#}"))
            .speed_disagreement
        };
        let at_22 = steps
            .iter()
            .find(|r| r.t >= 22.0 && r.vel.is_some())
            .and_then(|r| r.vel)
            .unwrap();
        let held = judged_steps(&|t, v| if (22.0..40.0).contains(&t) { at_22 } else { v })
            .unwrap_or_else(|| panic!("{name}: a wheel speed held from 8 to 12 m/s not named"));
        println!("{name}: held: {}", held.problem());
        let (value, slowest, fastest) = held.held.unwrap_or_else(|| panic!("{held:?}"));
        assert_eq!(value, at_22, "{name}");
        assert!(slowest < 9.0 && fastest > 11.0, "{name}: {held:?}");
        assert!(
            (22.0..=28.0).contains(&held.from_s) && (34.0..=40.0).contains(&held.to_s),
            "{name}: {held:?}"
        );
        assert!(
            held.problem().contains("sticks at its last value"),
            "{name}"
        );
        let step = 5.0 / 3.6;
        assert_eq!(
            judged_steps(&|_, v| (v / step).round() * step),
            None,
            "{name}: 5 km/h steps"
        );
        // The fixes, not the wheel speed: 15 m off the track for 3 s and back (multipath,
        // which the log's reader leaves in below 3 Hz) is no disagreement; the last fix
        // repeated for 10 s while the car cruises (a recorder through an outage) is named as
        // the fixes' at 1 Hz.
        let fixes = |edit: &FixEdit| {
            let mut rows = rows.clone();
            let mut last = None;
            for r in &mut rows {
                if r.lat.is_some() && r.lon.is_some() {
                    edit(r, last);
                    last = r.lat.zip(r.lon);
                }
            }
            preprocess_rows("straight-10", &rows, vehicle, &PreprocessOptions::default())
                .unwrap_or_else(|e| panic!("{name}: {e:#}"))
                .speed_disagreement
        };
        let off = fixes(&|r, _| {
            if (20.0..23.0).contains(&r.t) {
                r.lat = r.lat.map(|lat| lat + 15.0 / 111_000.0);
            }
        });
        assert_eq!(off, None, "{name}: a burst off the track");
        let held = fixes(&|r, before| {
            if (40.0..50.0).contains(&r.t) {
                if let Some((lat, lon)) = before {
                    (r.lat, r.lon) = (Some(lat), Some(lon));
                }
            }
        });
        // A fast receiver's held fixes may leave the track in a burst, which the log's reader
        // takes out (a gap, nothing to compare); a slow one's reach the check.
        if name.contains("1 Hz") {
            let held = held.unwrap_or_else(|| panic!("{name}: fixes held for 10 s not named"));
            assert!(held.repeated_fixes, "{name}: {held:?}");
            assert!(held.problem().contains("holds its last fix"), "{name}");
        } else {
            assert!(held.is_none_or(|d| d.repeated_fixes), "{name}: {held:?}");
        }
    }
}

/// The built-in scenario `scenario`'s log with sensor seed `seed`.
fn simulated(scenario: &str, seed: u64) -> Vec<LogRow> {
    let options = catmodel_host::sim::SimOptions {
        seed,
        ..Default::default()
    };
    catmodel_host::sim::run_named(scenario, None, &options)
        .unwrap_or_else(|e| panic!("simulating {scenario}: {e}"))
        .log
}

/// A logger that writes every column every 10 ms and repeats (samples and holds) a 10 Hz
/// receiver's last fix (black-box probe): the median interval between rows with a fix read
/// 100 Hz, `identify` wrote `gnss_rate_hz = 100` without a note, the node built from that
/// file refused 2836 of the validation drive's 2856 fixes, and `csv2can` sent every repeat as
/// a fix. Now the repeats are named and left out, the rate is the fixes that change (10 Hz),
/// the track is the unheld log's, and `csv2can` sends each fix once. A track written with 5 or
/// 6 decimals, whose fixes repeat while the car crosses a cell, is not taken for held fixes.
#[test]
fn fixes_a_logger_holds_are_no_fixes() {
    use catmodel_host::sim::{self, SimOptions};
    let base = model_file::load(&model_file::paper_path()).unwrap();
    let scenario = sim::scenario::Scenario::builtin("validation").unwrap();
    let options = SimOptions {
        seed: 2,
        ..SimOptions::default()
    };
    let mut ten_hz = VehicleConfig::default();
    ten_hz.sensors.gnss.period_s = 0.1;
    let rows = sim::simulate(&scenario, &ten_hz, &options).log;
    // The logger: every 10 ms, the last value of every column.
    let mut held: Vec<LogRow> = Vec::new();
    let mut last = LogRow::default();
    let mut next = rows.iter().peekable();
    let mut k = 0;
    while let Some(t) = Some(rows[0].t + 0.01 * k as f64).filter(|t| *t <= rows[rows.len() - 1].t) {
        while let Some(r) = next.next_if(|r| r.t <= t + 1e-9) {
            last = LogRow {
                t,
                vel: r.vel.or(last.vel),
                input_vel: r.input_vel.or(last.input_vel),
                accel: r.accel.or(last.accel),
                steer: r.steer.or(last.steer),
                brake: r.brake.or(last.brake),
                lat: r.lat.or(last.lat),
                lon: r.lon.or(last.lon),
            };
        }
        if last.vel.is_some()
            && last.input_vel.is_some()
            && last.steer.is_some()
            && last.lat.is_some()
        {
            held.push(LogRow { t, ..last });
        }
        k += 1;
    }
    let preprocess = |rows: &[LogRow]| {
        preprocess_rows(
            "validation",
            rows,
            &base.vehicle,
            &PreprocessOptions::default(),
        )
        .unwrap_or_else(|e| panic!("{e:#}"))
    };
    let (unheld, e) = (preprocess(&rows), preprocess(&held));
    assert!(
        (e.gnss_rate_hz - 10.0).abs() < 0.2,
        "measured {} Hz",
        e.gnss_rate_hz
    );
    assert!(
        e.log_notes
            .iter()
            .any(|n| n.contains("repeat the fix before them exactly")
                && n.contains("10.0 Hz")
                && n.contains("left out")),
        "{:?}",
        e.log_notes
    );
    // The track: the unheld log's, but for the logger's 0-10 ms of latency.
    let rms = |a: &[f64], b: &[f64]| {
        let n = a.len().min(b.len());
        (a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / n as f64).sqrt()
    };
    let off = (unheld.t[0] - e.t[0]).abs();
    assert!(off < 0.03, "the grids start {off} s apart");
    let dx = rms(&unheld.dx, &e.dx);
    assert!(dx < 0.05, "dx/dt {dx} m/s RMS from the unheld log's");
    // csv2can: each fix once.
    let gnss_frames = |rows: &[LogRow]| {
        let encoded = catmodel_host::csv2can::encode_log(rows).unwrap();
        let n = encoded
            .frames
            .iter()
            .filter(|f| f.frame.id == catmodel::can::spec::GNSS_POSITION_RAPID.id)
            .count();
        (n, encoded.note())
    };
    let (sent, note) = gnss_frames(&held);
    let fixes = rows.iter().filter(|r| r.lat.is_some()).count();
    assert!(
        sent.abs_diff(fixes) <= 2,
        "{sent} fixes sent of the receiver's {fixes}"
    );
    assert!(note.is_some_and(|n| n.contains("not sent as GNSS frames")));
    assert_eq!(gnss_frames(&rows), (fixes, None));
    // Few decimals repeat fixes at 100 Hz: the resolution's, not a logger's.
    let rows100 = sim::simulate(&scenario, &VehicleConfig::default(), &options).log;
    for decimals in [5, 6] {
        let scale = 10f64.powi(decimals);
        let coarse: Vec<LogRow> = rows100
            .iter()
            .map(|r| LogRow {
                lat: r.lat.map(|v| (v * scale).round() / scale),
                lon: r.lon.map(|v| (v * scale).round() / scale),
                ..*r
            })
            .collect();
        let e = preprocess(&coarse);
        assert!(
            !e.log_notes.iter().any(|n| n.contains("repeat the fix")),
            "{decimals} decimals: {:?}",
            e.log_notes
        );
        assert!(
            e.gnss_rate_hz > 90.0,
            "{decimals} decimals: {}",
            e.gnss_rate_hz
        );
    }
}

/// A receiver that starts 20 s after the bus sensors (a cold start; black-box probe): the grid
/// started at the first fix, so those 20 s of speed data were cut from the speed model without
/// a word (the probe's set: 29 speed steps -> 21, the speed delay 0.88 s -> 0.68 s). Now the
/// grid spans the bus sensors, the speed model uses it all, the track's samples before the
/// first fix are left out like an outage's, and a note says so; a receiver on time changes
/// nothing.
#[test]
fn a_receiver_that_starts_late_does_not_cut_the_speed_data() {
    use catmodel_host::sim::{self, SimOptions};
    let base = model_file::load(&model_file::paper_path()).unwrap();
    let scenario = sim::scenario::Scenario::builtin("validation").unwrap();
    let options = SimOptions {
        seed: 2,
        ..SimOptions::default()
    };
    let rows = sim::simulate(&scenario, &VehicleConfig::default(), &options).log;
    let late: Vec<LogRow> = rows
        .iter()
        .map(|r| match r.t < 20.0 {
            true => LogRow {
                lat: None,
                lon: None,
                ..*r
            },
            false => *r,
        })
        .collect();
    let preprocess = |rows: &[LogRow]| {
        preprocess_rows(
            "validation",
            rows,
            &base.vehicle,
            &PreprocessOptions::default(),
        )
        .unwrap_or_else(|e| panic!("{e:#}"))
    };
    let (full, e) = (preprocess(&rows), preprocess(&late));
    assert_eq!(full.track_from, 0);
    assert!(
        !full.log_notes.iter().any(|n| n.contains("without a fix")),
        "{:?}",
        full.log_notes
    );
    // The bus sensors' span: the full log's (which starts at its first fix, a few
    // milliseconds after them) and no shorter.
    assert!(e.t[0] <= full.t[0], "the grid starts at {} s", e.t[0]);
    assert!(e.t.len() >= full.t.len());
    assert!((e.t[e.t.len() - 1] - full.t[full.t.len() - 1]).abs() < 0.03);
    assert!((e.t[e.track_from] - 20.0).abs() < 0.03);
    assert!(e.gnss_gap[..e.track_from].iter().all(|g| *g));
    assert!(!e.gnss_gap[e.track_from + 500]);
    assert!(
        e.log_notes
            .iter()
            .any(|n| n.contains("the 20.0 s without a fix are used by the speed model")),
        "{:?}",
        e.log_notes
    );
}

/// The measured signals are the log's, whatever model file reads it (black-box probe):
/// the differences' windows followed the file's `gnss_rate_hz`, so `compare` on one 100 Hz
/// log scored the same models' yaw rate 19.4 %, 36.6 % and 46.0 % with files declaring 100,
/// 20 and 5 Hz, and identify's validation figures (taken with its base file's 100 Hz) were
/// not what `compare` gave with the file it wrote at the logs' 5 Hz (yaw rate 62.0 % against
/// 79.7 %). Now the windows follow the log's own receiver: the same signals under every file.
#[test]
fn the_measured_signals_do_not_depend_on_the_files_receiver_rate() {
    let base = model_file::load(&model_file::paper_path()).unwrap();
    let log = simulated("turn-left", 1);
    let at = |hz: f64| {
        let mut v = base.vehicle;
        v.gnss_rate_hz = hz;
        preprocess_rows("turn-left", &log, &v, &PreprocessOptions::default()).unwrap()
    };
    let reference = at(100.0);
    for hz in [20.0, 5.0, 1.0] {
        let e = at(hz);
        assert_eq!(e.yaw_half_width, reference.yaw_half_width, "{hz} Hz");
        assert_eq!(e.dx, reference.dx, "{hz} Hz");
        assert_eq!(e.yaw_rate, reference.yaw_rate, "{hz} Hz");
    }
}

/// The first 12 s of a steady turn (black-box probe): the lateral fit is below the floor (a
/// held steering excites nothing), and the cause named was "one sample stands far outside the
/// rest: `steer` ... near t = 0.80 s (-24.902 after filtering); a corrupt value there?", a
/// normal sample 0.4 % off a steering held within 0.1 %. A suspect now stands out by more than
/// a sensor's noise and a driver's small correction (5 % of the steering, 1 m/s, 0.05 rad/s).
#[test]
fn a_held_steering_is_no_corrupt_sample() {
    use catmodel_host::identify::floor::check;
    let base = model_file::load(&model_file::paper_path()).unwrap();
    let log = simulated("turn-left", 1);
    let t0 = log[0].t;
    let rows: Vec<LogRow> = log.iter().copied().filter(|r| r.t - t0 <= 12.0).collect();
    let e = preprocess_rows(
        "turn12",
        &rows,
        &base.vehicle,
        &PreprocessOptions::default(),
    )
    .unwrap_or_else(|e| panic!("{e:#}"));
    let id = identify::identify(vec![e], Vec::new(), &base, &IdentifyOptions::default()).unwrap();
    for v in check(&id) {
        assert!(
            v.suspect.is_none() && !v.cause.contains("a corrupt value there?"),
            "{:?}: {v}",
            v.model
        );
    }
}

/// A receiver converging after a cold start (its fixes 60 m off at the start, closing over
/// 20 s; a black-box probe) was refused as "a wheel speed that sticks at its last value ...,
/// or fixes of another receiver". A disagreement that starts at the log's first fixes now
/// names the cold start first, and what to cut.
#[test]
fn a_receiver_converging_after_a_cold_start_is_named() {
    let base = model_file::load(&model_file::paper_path()).unwrap();
    let log = simulated("straight-5", 1);
    let rows: Vec<LogRow> = log
        .iter()
        .map(|r| {
            let k = ((20.0 - r.t) / 20.0 * 60.0).max(0.0);
            LogRow {
                lat: r.lat.map(|v| v + k / 111_000.0),
                lon: r.lon.map(|v| v + k / 94_000.0),
                ..*r
            }
        })
        .collect();
    let e = preprocess_rows("cold", &rows, &base.vehicle, &PreprocessOptions::default())
        .unwrap_or_else(|e| panic!("{e:#}"));
    let problem = e
        .speed_disagreement
        .expect("the track disagrees with the wheel speed")
        .problem();
    assert!(
        problem.contains("a receiver still converging after a cold start"),
        "{problem}"
    );
}
