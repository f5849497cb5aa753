//! Synthetic bus traffic with a known answer, and a runner that steps the node over it the way
//! replay and the firmware do (every 20 ms, the frames received since the previous tick).
//!
//! The car starts at the origin heading east at a constant speed and steering; its rear axle
//! follows eq 8 in closed form; GNSS (100 Hz) measures the antenna, 1.478 m ahead; steering and
//! speed reports come at 50 Hz with rolling counters.
use catmodel::can::codec::{
    Direction, GnssPosition, NodeStatus, Prediction, SpeedReport, StatePosition, SteeringReport,
};
use catmodel::can::spec::N2K_DEFAULT_SOURCE;
use catmodel::can::{CanFrame, CanId, TimedFrame};
use catmodel::geodesy::{Enu, LocalFrame};
use catmodel::node::{
    first_tick_us, Counters, NodeConfig, PlatformStats, Tick, TickEstimate, TxFrames,
};

/// Origin of the local frame, 1e-7 deg.
pub const ORIGIN: (i32, i32) = (322_319_000, -1_109_501_000);
/// Time of the first fix, us.
pub const START_US: u64 = 1_003_000;

/// Which input a frame is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// GNSS position, PGN 129025.
    Gnss,
    /// STEERING_REPORT.
    Steering,
    /// SPEED_REPORT.
    Speed,
}

/// One frame of the drive, labelled.
#[derive(Clone, Copy, Debug)]
pub struct Labelled {
    /// What it carries.
    pub kind: Kind,
    /// The frame and its time.
    pub frame: TimedFrame,
}

/// Rear axle `(east, north, heading)` at `t_s` on a path of constant `curvature` (1/m, positive
/// = turning right) at `v` m/s, starting at the origin heading east.
pub fn rear_axle(v: f64, curvature: f64, t_s: f64) -> (f64, f64, f64) {
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

/// Path curvature of the published car (`models/paper.toml`) at `steer_pct` and `v` (eq 2 with
/// understeer).
pub fn curvature(v: f32, steer_pct: f32) -> f64 {
    let vehicle = config().vehicle;
    let center = vehicle.steer_pct_to_center_rad(steer_pct);
    f64::from(vehicle.curvature_per_m(center, v))
}

/// `seconds` of driving at `v` m/s with steering `steer_pct`, first fix at [`START_US`].
pub fn drive(v: f32, steer_pct: f32, seconds: f32) -> Vec<Labelled> {
    let k = curvature(v, steer_pct);
    let lever = f64::from(config().estimator.antenna_ahead_m);
    let frame = LocalFrame::new(ORIGIN.0, ORIGIN.1).expect("origin");
    let mut out = Vec::new();
    let n = (seconds * 100.0) as u64;
    for i in 0..n {
        let t_us = START_US + i * 10_000;
        let (east, north, h) = rear_axle(f64::from(v), k, i as f64 * 0.01);
        out.push(fix_at(&frame, lever, (east, north, h), t_us));
        if i % 2 == 0 {
            let counter = ((i / 2) % 16) as u8;
            let steering = SteeringReport {
                steer_pct: Some(steer_pct),
            }
            .encode(counter);
            let speed = SpeedReport {
                speed_mps: Some(v),
                speed_cmd_mps: Some(v),
                direction: Direction::NotReported,
            }
            .encode(counter);
            for (kind, frame) in [(Kind::Steering, steering), (Kind::Speed, speed)] {
                out.push(Labelled {
                    kind,
                    frame: TimedFrame {
                        t_us: t_us + 1_000,
                        frame,
                    },
                });
            }
        }
    }
    out
}

/// One leg of a scripted drive ([`drive_legs`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Leg {
    /// How long, s.
    pub seconds: f64,
    /// Speed along the heading, m/s: negative = reversing.
    pub speed_mps: f32,
    /// Steering, % (positive right).
    pub steer_pct: f32,
}

/// The truth of a scripted drive: the rear axle every millisecond from [`START_US`].
#[derive(Clone, Debug, Default)]
pub struct Truth {
    /// `(east, north, heading)` of the rear axle, m and rad (heading clockwise from north,
    /// unwrapped), one per millisecond.
    pub rear_axle_ms: Vec<(f64, f64, f64)>,
}

impl Truth {
    /// The rear axle at `t_us` (on the drive's time base; clamped to the drive).
    pub fn at(&self, t_us: u64) -> (f64, f64, f64) {
        let ms = (t_us.saturating_sub(START_US) / 1_000) as usize;
        self.rear_axle_ms[ms.min(self.rear_axle_ms.len() - 1)]
    }
}

/// A drive of `legs` one after the other, starting at the origin heading east: the rear axle
/// follows eq 8 (integrated every millisecond, yaw rate = speed x curvature, so a reversing
/// car turns the other way for the same steering), GNSS at 100 Hz measures the antenna,
/// steering and speed reports at 50 Hz. SPEED_REPORT carries the speed's magnitude, and, with
/// `report_direction`, `direction` forward or reverse (else not reported, as every kit without
/// the signal).
pub fn drive_legs(legs: &[Leg], report_direction: bool) -> (Vec<Labelled>, Truth) {
    let lever = f64::from(config().estimator.antenna_ahead_m);
    let frame = LocalFrame::new(ORIGIN.0, ORIGIN.1).expect("origin");
    let total_ms: f64 = legs.iter().map(|l| l.seconds * 1_000.0).sum();
    let (mut east, mut north, mut h) = (0.0f64, 0.0f64, std::f64::consts::FRAC_PI_2);
    let mut truth = Truth::default();
    let mut out = Vec::new();
    let (mut leg_index, mut leg_end_ms) = (0usize, legs[0].seconds * 1_000.0);
    for ms in 0..total_ms.round() as u64 {
        while ms as f64 >= leg_end_ms && leg_index + 1 < legs.len() {
            leg_index += 1;
            leg_end_ms += legs[leg_index].seconds * 1_000.0;
        }
        let leg = legs[leg_index];
        truth.rear_axle_ms.push((east, north, h));
        let t_us = START_US + ms * 1_000;
        if ms % 10 == 0 {
            out.push(fix_at(&frame, lever, (east, north, h), t_us));
        }
        if ms % 20 == 1 {
            let counter = ((ms / 20) % 16) as u8;
            let steering = SteeringReport {
                steer_pct: Some(leg.steer_pct),
            }
            .encode(counter);
            let direction = match (report_direction, leg.speed_mps < 0.0) {
                (false, _) => Direction::NotReported,
                (true, false) => Direction::Forward,
                (true, true) => Direction::Reverse,
            };
            let speed = SpeedReport {
                speed_mps: Some(leg.speed_mps.abs()),
                speed_cmd_mps: Some(leg.speed_mps.abs()),
                direction,
            }
            .encode(counter);
            for (kind, frame) in [(Kind::Steering, steering), (Kind::Speed, speed)] {
                out.push(Labelled {
                    kind,
                    frame: TimedFrame { t_us, frame },
                });
            }
        }
        // One millisecond of eq 8, at the step's middle heading.
        let v = f64::from(leg.speed_mps);
        let yaw = v * curvature(leg.speed_mps.abs(), leg.steer_pct);
        let mid = h + 0.5 * yaw * 1e-3;
        east += v * mid.sin() * 1e-3;
        north += v * mid.cos() * 1e-3;
        h += yaw * 1e-3;
    }
    (out, truth)
}

/// What one tick produced.
#[derive(Clone, Debug)]
pub struct TickOut {
    /// Tick time, us.
    pub now_us: u64,
    /// Frames sent.
    pub tx: TxFrames,
    /// The estimate.
    pub estimate: TickEstimate,
    /// Counters after the tick.
    pub counters: Counters,
}

impl TickOut {
    /// Seconds since the first fix.
    pub fn t_s(&self) -> f64 {
        (self.now_us as f64 - START_US as f64) * 1e-6
    }

    /// The decoded STATE_POSITION.
    pub fn position(&self) -> StatePosition {
        self.tx
            .iter()
            .find_map(|f| StatePosition::decode(f).ok())
            .expect("STATE_POSITION sent every tick")
            .0
    }

    /// The decoded predictions.
    pub fn predictions(&self) -> Vec<Prediction> {
        self.tx
            .iter()
            .filter_map(|f| Prediction::decode(f).ok().map(|p| p.0))
            .collect()
    }

    /// The decoded NODE_STATUS page of this tick.
    pub fn status(&self) -> NodeStatus {
        self.tx
            .iter()
            .find_map(|f| NodeStatus::decode(f).ok())
            .expect("NODE_STATUS sent every tick")
            .0
    }

    /// Every frame sent passes its own decoder.
    pub fn assert_frames_valid(&self) {
        for f in &self.tx {
            let CanId::Standard(id) = f.id else {
                panic!("extended frame sent: {f:?}")
            };
            let ok = match id {
                0x300 => StatePosition::decode(f).is_ok(),
                0x301 => catmodel::can::codec::StateMotion::decode(f).is_ok(),
                0x320 => catmodel::can::codec::ControlCommand::decode(f).is_ok(),
                0x310..=0x319 => Prediction::decode(f).is_ok(),
                0x3F0 => NodeStatus::decode(f).is_ok(),
                _ => false,
            };
            assert!(ok, "invalid frame {f:?}");
        }
    }
}

/// The published configuration (`models/paper.toml`) with the test origin.
pub fn config() -> NodeConfig {
    let mut c = catmodel_model_file::paper().node_config();
    c.origin_e7 = Some(ORIGIN);
    c
}

/// Steps a node every 20 ms over `frames` (sorted by time), with `platform(tick index)` as the
/// platform's counters.
pub fn run_with(
    config: NodeConfig,
    frames: &[TimedFrame],
    platform: impl Fn(usize) -> PlatformStats,
) -> Vec<TickOut> {
    let mut node = catmodel_host::new_node(config);
    run_node(&mut node, frames, platform)
}

/// [`run`] on a node of the caller's, to look at its state afterwards.
pub fn run_on(node: &mut catmodel_host::HostNode, frames: &[TimedFrame]) -> Vec<TickOut> {
    run_node(node, frames, |_| PlatformStats::default())
}

fn run_node(
    node: &mut catmodel_host::HostNode,
    frames: &[TimedFrame],
    platform: impl Fn(usize) -> PlatformStats,
) -> Vec<TickOut> {
    let mut out = Vec::new();
    let (Some(first), Some(last)) = (frames.first(), frames.last()) else {
        return out;
    };
    let mut now = first_tick_us(first.t_us);
    let mut next = 0;
    while now <= last.t_us {
        let start = next;
        while next < frames.len() && frames[next].t_us <= now {
            next += 1;
        }
        let mut tx = TxFrames::new();
        let estimate = node.step(
            &Tick {
                now_us: now,
                platform: platform(out.len()),
            },
            &frames[start..next],
            &mut tx,
        );
        out.push(TickOut {
            now_us: now,
            tx,
            estimate,
            counters: *node.counters(),
        });
        now += 20_000;
    }
    out
}

/// [`run_with`] with the published configuration and no platform events.
pub fn run(frames: &[TimedFrame]) -> Vec<TickOut> {
    run_with(config(), frames, |_| PlatformStats::default())
}

/// The frames of a labelled drive.
pub fn frames(drive: &[Labelled]) -> Vec<TimedFrame> {
    drive.iter().map(|l| l.frame).collect()
}

/// Re-computes byte 7 (CRC-8/SAE-J1850 over ID and payload) after a payload edit.
pub fn reseal(mut frame: CanFrame) -> CanFrame {
    frame.data[7] = catmodel::can::crc::frame_crc(frame.id, &frame.data);
    frame
}

/// The receiver's fix at `t_us` of a car whose rear axle is at `(east, north)` with heading `h`
/// (rad, clockwise from north) in `frame`, its antenna `lever` metres ahead of the axle.
fn fix_at(
    frame: &LocalFrame,
    lever: f64,
    (east, north, h): (f64, f64, f64),
    t_us: u64,
) -> Labelled {
    let (lat, lon) = frame.from_local(Enu {
        east_m: (east + lever * h.sin()) as f32,
        north_m: (north + lever * h.cos()) as f32,
    });
    let fix = GnssPosition {
        lat_e7: (lat * 1e7).round() as i32,
        lon_e7: (lon * 1e7).round() as i32,
    };
    Labelled {
        kind: Kind::Gnss,
        frame: TimedFrame {
            t_us,
            frame: fix.encode(N2K_DEFAULT_SOURCE),
        },
    }
}
