//! The node end to end on hand-built bus traffic whose answer is known by hand: a car driving
//! due east at a constant speed, straight or on a circle, with exact GNSS at 100 Hz from an
//! antenna 1.478 m ahead of the rear axle and reports at 50 Hz. The node reports the rear axle.
use catmodel::can::codec::{
    GnssPosition, Prediction, SpeedReport, StateMotion, StatePosition, SteeringReport,
};
use catmodel::can::spec::N2K_DEFAULT_SOURCE;
use catmodel::can::{CanFrame, TimedFrame};
use catmodel::geodesy::{Enu, LocalFrame};
use catmodel::node::{
    Node, NodeConfig, PlatformStats, Tick, TxFrames, CAT_VEHICLE_ANTENNA_AHEAD_M,
};
use catmodel::vehicle::CAT_VEHICLE;

const ORIGIN: (i32, i32) = (322_319_000, -1_109_501_000);

/// Rear axle `(east, north, heading)` at `t_s` of a drive that starts at the origin heading
/// east at `v` m/s on a path of constant `curvature` (1/m, positive = turning right).
fn rear_axle(v: f64, curvature: f64, t_s: f64) -> (f64, f64, f64) {
    let h0 = std::f64::consts::FRAC_PI_2;
    let w = v * curvature;
    if w == 0.0 {
        return (v * t_s, 0.0, h0);
    }
    let h = h0 + w * t_s;
    // x' = v sin(h), y' = v cos(h) (eq 8), integrated in closed form.
    (
        (v / w) * (h0.cos() - h.cos()),
        (v / w) * (h.sin() - h0.sin()),
        h,
    )
}

/// Frames of `seconds` of driving at `v` m/s with steering `steer_pct` from the origin,
/// starting at t = 1 s. Returns the frames and the path's curvature.
fn drive(v: f32, steer_pct: f32, seconds: f32) -> (Vec<TimedFrame>, f64) {
    let center = CAT_VEHICLE.steer_pct_to_center_rad(steer_pct);
    let curvature = f64::from(CAT_VEHICLE.curvature_per_m(center, v));
    let lever = f64::from(CAT_VEHICLE_ANTENNA_AHEAD_M);
    let frame = LocalFrame::new(ORIGIN.0, ORIGIN.1).unwrap();
    let mut out = Vec::new();
    let n = (seconds * 100.0) as u64;
    for i in 0..n {
        let t_us = 1_000_000 + i * 10_000 + 3_000;
        let (east, north, h) = rear_axle(f64::from(v), curvature, i as f64 * 0.01);
        let (lat, lon) = frame.from_local(Enu {
            east_m: (east + lever * h.sin()) as f32,
            north_m: (north + lever * h.cos()) as f32,
        });
        let fix = GnssPosition {
            lat_e7: (lat * 1e7).round() as i32,
            lon_e7: (lon * 1e7).round() as i32,
        };
        out.push(TimedFrame {
            t_us,
            frame: fix.encode(N2K_DEFAULT_SOURCE),
        });
        if i % 2 == 0 {
            let counter = ((i / 2) % 16) as u8;
            let push = |out: &mut Vec<TimedFrame>, f: CanFrame| {
                out.push(TimedFrame {
                    t_us: t_us + 1_000,
                    frame: f,
                })
            };
            push(
                &mut out,
                SteeringReport {
                    steer_pct: Some(steer_pct),
                }
                .encode(counter),
            );
            push(
                &mut out,
                SpeedReport {
                    speed_mps: Some(v),
                    speed_cmd_mps: Some(v),
                }
                .encode(counter),
            );
        }
    }
    (out, curvature)
}

fn run(frames: &[TimedFrame]) -> (Node, Vec<(u64, TxFrames)>) {
    let mut config = NodeConfig::paper().unwrap();
    config.origin_e7 = Some(ORIGIN);
    let mut node = Node::new(config);
    let mut out = Vec::new();
    let mut now = catmodel::node::first_tick_us(frames[0].t_us);
    let mut next = 0;
    while now <= frames.last().unwrap().t_us {
        let start = next;
        while next < frames.len() && frames[next].t_us <= now {
            next += 1;
        }
        let mut tx = TxFrames::new();
        node.step(
            &Tick {
                now_us: now,
                platform: PlatformStats::default(),
            },
            &frames[start..next],
            &mut tx,
        );
        out.push((now, tx));
        now += 20_000;
    }
    (node, out)
}

#[test]
fn straight_drive_is_tracked_and_predicted() {
    let v = 10.0;
    let (frames, _) = drive(v, 0.0, 20.0);
    let (node, ticks) = run(&frames);
    assert_eq!(
        node.counters().crc_errors + node.counters().counter_errors + node.counters().range_errors,
        0,
        "{:?}",
        node.counters()
    );
    let (now, tx) = ticks.last().unwrap();
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
fn last_state(ticks: &[(u64, TxFrames)]) -> (u64, f32, f32, f32) {
    let (now, tx) = ticks.last().unwrap();
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
    let (frames, curvature) = drive(v, 30.0, 25.0);
    assert!(curvature > 0.05, "{curvature}");
    let (_, ticks) = run(&frames);
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
