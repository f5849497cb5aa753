//! The node end to end on hand-built bus traffic whose answer is known by hand: a car driving
//! due east at a constant speed, straight or on a circle, with exact GNSS at 100 Hz from an
//! antenna 1.478 m ahead of the rear axle and reports at 50 Hz. The node reports the rear axle.
use catmodel::can::codec::{Prediction, StateMotion, StatePosition};
use catmodel_host_tests::bus::{self, drive, frames, rear_axle, run, TickOut};

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
    // and the antenna is 1.478 m off the rear axle: both must be taken out.
    let v = 5.0;
    let (frames, curvature) = drive_frames(v, 30.0, 25.0);
    assert!(curvature > 0.05, "{curvature}");
    let ticks = run(&frames);
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
fn the_default_build_bakes_the_published_models() {
    // build.rs bakes models/paper.toml unless CATMODEL_MODEL names another file.
    if std::env::var_os("CATMODEL_MODEL").is_some() {
        return;
    }
    let baked = catmodel::node::baked::baked_models().unwrap();
    assert_eq!(baked, catmodel::node::NodeModels::paper());
    assert_eq!(catmodel::node::baked::BAKED_MODEL_PATH, "models/paper.toml");
}
