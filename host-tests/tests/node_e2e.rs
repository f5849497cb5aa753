//! The node end to end on hand-built bus traffic whose answer is known by hand: a car driving
//! due east at a constant 10 m/s, straight, with exact GNSS at 100 Hz and reports at 50 Hz.
use catmodel::can::codec::{
    GnssPosition, Prediction, SpeedReport, StateMotion, StatePosition, SteeringReport,
};
use catmodel::can::spec::N2K_DEFAULT_SOURCE;
use catmodel::can::{CanFrame, TimedFrame};
use catmodel::geodesy::{Enu, LocalFrame};
use catmodel::node::{Node, NodeConfig, PlatformStats, Tick, TxFrames};

const ORIGIN: (i32, i32) = (322_319_000, -1_109_501_000);

/// Frames of `seconds` of driving east at `v` m/s from the origin, starting at t = 1 s.
fn drive_east(v: f32, seconds: f32) -> Vec<TimedFrame> {
    let frame = LocalFrame::new(ORIGIN.0, ORIGIN.1).unwrap();
    let mut out = Vec::new();
    let n = (seconds * 100.0) as u64;
    for i in 0..n {
        let t_us = 1_000_000 + i * 10_000 + 3_000;
        let east = v * (i as f32 * 0.01);
        let (lat, lon) = frame.from_local(Enu {
            east_m: east,
            north_m: 0.0,
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
                    steer_pct: Some(0.0),
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
    out
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
    let frames = drive_east(v, 20.0);
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
    // The last fix is at most 10 ms old: the compensated position is where the car is now.
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
