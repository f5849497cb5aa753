//! The node end to end on hand-built bus traffic whose answer is known by hand: a car driving
//! due east at a constant speed, straight or on a circle, with exact GNSS at 100 Hz from an
//! antenna 1.478 m ahead of the rear axle and reports at 50 Hz. The node reports the rear axle.
use catmodel::can::codec::{Prediction, StateMotion, StatePosition};
use catmodel_host_tests::bus::{self, drive, frames, rear_axle, run, run_with, TickOut};

/// Frames of a drive and its path curvature.
fn drive_frames(v: f32, steer_pct: f32, seconds: f32) -> (Vec<catmodel::can::TimedFrame>, f64) {
    (
        frames(&drive(v, steer_pct, seconds)),
        bus::curvature(v, steer_pct),
    )
}

#[test]
fn straight_drive_is_tracked_and_predicted() {
    let v = 10.0;
    let (frames, _) = drive_frames(v, 0.0, 20.0);
    let ticks = run(&frames);
    let TickOut {
        now_us: now,
        tx,
        counters,
        ..
    } = ticks.last().unwrap();
    assert_eq!(
        counters.crc_errors + counters.counter_errors + counters.range_errors,
        0,
        "{counters:?}"
    );
    let t_s = (*now as f32 - 1_003_000.0) * 1e-6;
    let mut pos = None;
    let mut motion = None;
    let mut preds = Vec::new();
    for f in tx {
        if let Ok((p, _)) = StatePosition::decode(f) {
            pos = Some(p);
        }
        if let Ok((m, _)) = StateMotion::decode(f) {
            motion = Some(m);
        }
        if let Ok((p, _)) = Prediction::decode(f) {
            preds.push(p);
        }
    }
    let pos = pos.expect("STATE_POSITION sent");
    assert!(pos.position_valid);
    // The last fix is at most 10 ms old: the compensated position is where the car (its rear
    // axle, 1.478 m behind the antenna) is now.
    let east = pos.east_m.unwrap();
    assert!(
        (east - v * t_s).abs() < 0.15,
        "east {east} vs truth {}",
        v * t_s
    );
    assert!(pos.north_m.unwrap().abs() < 0.05);
    let m = motion.unwrap();
    assert!(
        (m.heading_rad.unwrap() - std::f32::consts::FRAC_PI_2).abs() < 0.01,
        "{m:?}"
    );
    assert_eq!(preds.len(), 10);
    for p in preds {
        let h = p.point.horizon_us() as f32 * 1e-6;
        assert!((p.dx_m.unwrap() - v * h).abs() < 0.05, "{p:?}");
        assert!(p.dy_m.unwrap().abs() < 0.05, "{p:?}");
        assert!((p.speed_mps.unwrap() - v).abs() < 0.05, "{p:?}");
    }
}

/// Decoded position and heading of the node's last tick.
fn last_state(ticks: &[TickOut]) -> (u64, f32, f32, f32) {
    let TickOut {
        now_us: now, tx, ..
    } = ticks.last().unwrap();
    let mut pos = None;
    let mut heading = None;
    for f in tx {
        if let Ok((p, _)) = StatePosition::decode(f) {
            pos = Some(p);
        }
        if let Ok((m, _)) = StateMotion::decode(f) {
            heading = m.heading_rad;
        }
    }
    let pos = pos.expect("STATE_POSITION sent");
    assert!(pos.position_valid);
    (
        *now,
        pos.east_m.unwrap(),
        pos.north_m.unwrap(),
        heading.unwrap(),
    )
}

#[test]
fn circle_is_tracked_at_the_rear_axle_with_the_true_heading() {
    // 5 m/s at 30 % right steering: a ~14 m radius circle, kinematic mode (a_y ~1.8 m/s^2).
    // In the turn the antenna's course leads the heading by atan(1.478 * curvature) ~ 0.1 rad
    // and the antenna is 1.478 m off the rear axle: both must be taken out. The truth is eq 8's
    // (no tyre slip), so the node is the published car without its `[dynamics]`, whose rear
    // axle would slide 0.015 rad here (the sliding case: the estimator's unit tests).
    let v = 5.0;
    let (frames, curvature) = drive_frames(v, 30.0, 25.0);
    assert!(curvature > 0.05, "{curvature}");
    let kinematic = catmodel::node::NodeConfig {
        dynamics: None,
        ..bus::config()
    };
    let ticks = run_with(kinematic, &frames, |_| {
        catmodel::node::PlatformStats::default()
    });
    let (now, east, north, heading) = last_state(&ticks);
    let t_s = (now as f64 - 1_003_000.0) * 1e-6;
    let (te, tn, th) = rear_axle(f64::from(v), curvature, t_s);
    let heading_err = (f64::from(heading) - th + std::f64::consts::PI)
        .rem_euclid(std::f64::consts::TAU)
        - std::f64::consts::PI;
    assert!(heading_err.abs() < 0.01, "heading {heading} vs {th}");
    let pos_err = ((f64::from(east) - te).powi(2) + (f64::from(north) - tn).powi(2)).sqrt();
    assert!(
        pos_err < 0.05,
        "({east}, {north}) vs ({te}, {tn}): {pos_err} m"
    );
}

#[test]
fn the_default_build_bakes_the_published_model_file_bit_for_bit() {
    // The firmware's build script bakes models/paper.toml unless CATMODEL_MODEL names another
    // file; what it baked must be exactly what the host reader makes of the same file.
    if std::env::var_os("CATMODEL_MODEL").is_some() {
        return;
    }
    assert_eq!(catmodel_firmware::baked::MODEL_PATH, "models/paper.toml");
    let baked = catmodel_firmware::baked::node_config().unwrap();
    let host = catmodel_model_file::paper().node_config();
    assert_eq!(baked, host);
    // Bit for bit, not only `==` (which equates 0.0 and -0.0).
    let mut host_words = vec![0u32; catmodel::node::CONFIG_IMAGE_MAX_WORDS];
    let n = host.to_image(&mut host_words);
    assert_eq!(
        &host_words[..n],
        &catmodel_firmware::baked::CONFIG_IMAGE[..]
    );
}

#[test]
fn a_configuration_image_round_trips_and_refuses_corruption() {
    let config = catmodel_model_file::paper().node_config();
    let mut words = vec![0u32; catmodel::node::CONFIG_IMAGE_MAX_WORDS];
    let n = config.to_image(&mut words);
    assert!(n <= catmodel::node::CONFIG_IMAGE_MAX_WORDS);
    let back = catmodel::node::NodeConfig::from_image(&words[..n]).unwrap();
    assert_eq!(back, config);
    // Every single word turned into NaN is either refused or (for integer words) changes the
    // configuration: nothing passes silently as the same car.
    let mut refused = 0;
    for k in 2..n {
        let mut bad = words[..n].to_vec();
        bad[k] = f32::NAN.to_bits();
        match catmodel::node::NodeConfig::from_image(&bad) {
            Err(_) => refused += 1,
            Ok(other) => assert_ne!(other, config, "word {k}"),
        }
    }
    assert!(refused > n / 2, "{refused} of {n} corrupt words refused");
    assert!(catmodel::node::NodeConfig::from_image(&words[..n - 1]).is_err());
}
