//! Drives made to load the node: the dedicated inputs of the stage measurement
//! ([`stage_corpus`]: each stage of the tick on its most expensive path) and of the adversarial
//! search ([`targeted`], [`random`], [`mutate`]), written as candump files.
//!
//! A drive is a car following eq 8 (with eq 2's understeer) along speed and steering profiles,
//! reported the way `catmodel.dbc` says (steering, speed and pedal reports, GNSS position and
//! COG/SOG from the configured receiver), with the load and the faults of docs/faults.md laid
//! on top: frames bunched into one tick, GNSS at rates above the receiver's, dropouts and
//! jumps beyond the gate, floods of corrupt input frames (CRC, DLC, range, stuck counters,
//! unavailable fixes, foreign GNSS sources) and of identifiers the acceptance filter refuses.
//! Everything is deterministic in the spec (its seed included).
use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result};
use catmodel::can::codec::{
    Direction, GnssCogSog, GnssPosition, LocalOrigin, Obstacle, ObstacleCircle, PathHeader,
    PathLimits, PathPoint, PedalReport, SpeedReport, SteeringReport,
};
use catmodel::can::spec::MAX_PATH_POINTS;
use catmodel::can::{candump, CanFrame, CanId, TimedFrame};
use catmodel::control::mpc::MAX_OBSTACLES;
use catmodel::geodesy::{Enu, LocalFrame};
use catmodel::node::estimator::TRACK_LEN;
use catmodel::node::stage::GAP_FILL_PER_TICK;
use catmodel::node::NodeConfig;
use catmodel::node::{PLANNER_FRAMES_PER_TICK, SHORT_PATH_POINTS};

/// A value over time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Profile {
    /// Constant.
    Const(f64),
    /// `mean + amp sin(2 pi t / period_s)`.
    Sine { mean: f64, amp: f64, period_s: f64 },
    /// `lo` for the first half of each period, `hi` for the second.
    Square { lo: f64, hi: f64, period_s: f64 },
    /// From `from` to `to` over `seconds`, then `to`.
    Ramp { from: f64, to: f64, seconds: f64 },
}

impl Profile {
    fn at(&self, t_s: f64) -> f64 {
        match *self {
            Profile::Const(v) => v,
            Profile::Sine {
                mean,
                amp,
                period_s,
            } => mean + amp * (std::f64::consts::TAU * t_s / period_s.max(1e-3)).sin(),
            Profile::Square { lo, hi, period_s } => {
                if (t_s / period_s.max(1e-3)).fract() < 0.5 {
                    lo
                } else {
                    hi
                }
            }
            Profile::Ramp { from, to, seconds } => {
                from + (to - from) * (t_s / seconds.max(1e-3)).clamp(0.0, 1.0)
            }
        }
    }
}

/// A window that repeats: `len_s` long, every `every_s`, the first at `first_s`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Periodic {
    /// Start of the first window, s.
    pub first_s: f64,
    /// Period, s.
    pub every_s: f64,
    /// Length of each window, s.
    pub len_s: f64,
}

impl Periodic {
    /// The window `t_s` lies in, as its start.
    fn window(&self, t_s: f64) -> Option<f64> {
        if t_s < self.first_s {
            return None;
        }
        let k = ((t_s - self.first_s) / self.every_s.max(1e-3)).floor();
        let start = self.first_s + k * self.every_s;
        (t_s < start + self.len_s).then_some(start)
    }
}

/// Everything a drive is made of.
#[derive(Clone, Debug, PartialEq)]
pub struct Spec {
    /// File name (without `.log`).
    pub name: String,
    /// Seed of the noise and of the fault choices.
    pub seed: u64,
    /// Length, s.
    pub seconds: f64,
    /// Local frame origin (the first fix is near it), degrees.
    pub origin_deg: (f64, f64),
    /// Speed, m/s (reported as it is: the node clamps it).
    pub speed: Profile,
    /// Steering, % (clamped to the DBC's +-100).
    pub steer: Profile,
    /// GNSS position fixes per second (0: none).
    pub gnss_hz: f64,
    /// COG/SOG frames per second (0: none).
    pub cog_hz: f64,
    /// White noise on each fix, m.
    pub gnss_noise_m: f64,
    /// White noise on each course over ground, rad (a receiver that differences its fixes).
    pub cog_noise_rad: f64,
    /// GNSS silent in these windows.
    pub gnss_dropout: Option<Periodic>,
    /// Each dropout window a gap of exactly its length between two fixes, the second at a
    /// tick's time (the first tick at or after the window's end) and the first that long
    /// before it, off the receiver's slots: a fix as late as a receiver's clock and the bus
    /// can make it, so that a gap as long as the car's `gnss_lost_s` allows, and a tick more,
    /// is taken before the position is given up.
    pub gnss_gap_exact: bool,
    /// Fixes moved by `gnss_jump_m` east in these windows.
    pub gnss_jump: Option<Periodic>,
    /// The jump, m.
    pub gnss_jump_m: f64,
    /// With this above 0, the fixes in the jump windows are where the antenna was this long
    /// before, s, in place of `gnss_jump_m` east: a jump back along the car's own track, onto
    /// the path the planner sent.
    pub gnss_jump_back_s: f64,
    /// Every frame inside a window is stamped at the window's end: all of them are due in one
    /// tick.
    pub burst: Option<Periodic>,
    /// Extra input frames per tick that the node rejects (bad CRC, DLC, range, stuck counter,
    /// unavailable fix, foreign GNSS source).
    pub corrupt_per_tick: u32,
    /// Frames per tick that are not node inputs (the acceptance filter refuses them).
    pub unknown_per_tick: u32,
    /// Points of the path a planner sends over and over (0: no planner): LOCAL_ORIGIN at the
    /// drive's origin first, then the path (the car's own track from a metre behind where it
    /// is when the path's first frame goes out, straight on beyond the drive's end, 1 m
    /// between points, 5 m/s, 3 m corridors: valid, so every completion activates it, and the
    /// car is on it, so the controller plans) paced at the node's rule for a conforming
    /// planner (`PLANNER_FRAMES_PER_TICK`).
    pub path_points: usize,
    /// How far apart the planner's points are, m.
    pub path_spacing_m: f64,
    /// The planner sends one path (and its obstacles), not one after another: the car keeps
    /// its projection on it for the whole drive (a new path places it afresh).
    pub path_once: bool,
    /// Obstacles the planner sends after each path (at most the node's slots): circles of
    /// 0.3 m 2 m to the right of the path's last points, inside its corridor (a search of the
    /// path from its start comes nearer at every segment), or, with `obstacles_at_centre`, all
    /// at the centre of the circle through the path's first, middle and last points (on a
    /// path that runs round them, every segment is as near).
    pub obstacles: usize,
    /// See [`Spec::obstacles`].
    pub obstacles_at_centre: bool,
    /// Above 0 (in place of the placements of [`Spec::obstacles`]): every obstacle this far
    /// to the right of the path's last point and 2 m beyond it, m. Far enough (some hundreds
    /// of metres for a path of some tens), every segment is about as near as the nearest
    /// point, and each is nearer than the one before (on a straight path along a grid line,
    /// [`Spec::heading_rad`] 0, the bus's 0.02 m resolution cannot break that order): a
    /// search for an obstacle's nearest segment that prunes by distance prunes nothing and
    /// finds a new best at every segment. The node's search tests every segment in full
    /// wherever the obstacle is; this drive keeps it so.
    pub obstacles_far_m: f64,
    /// The car's heading at the drive's start, rad clockwise from north.
    pub heading_rad: f64,
    /// Above 0, with `path_once`: after the path, the planner sends every obstacle slot again
    /// each tick, its circle moving across the path, to the left, at this speed (the node
    /// measures each slot's motion from its frames: the slots' fits close in the same ticks),
    /// m/s.
    pub obstacles_moving_mps: f64,
    /// The corridors widen by this much from point to point, m: wider than the tie
    /// (`control::path::NARROWEST_TIE_M`) over the front half of a body, the search for the
    /// corridor's binding point reads its way back from the front to near the axle.
    pub corridor_widening_m: f64,
    /// The path's points this far to the right of the car's track, m: beyond its corridor by
    /// more than a body width, the car has lost its path (`Tracking::has_lost_path`) along it,
    /// and stops on the lane hold (`node::drive`).
    pub path_offset_m: f64,
}

impl Spec {
    /// A plain drive: 10 s at 5 m/s, gentle steering, GNSS and COG at 100 Hz, no faults.
    pub fn plain(name: &str) -> Self {
        Self {
            name: name.to_string(),
            seed: 1,
            seconds: 10.0,
            origin_deg: (32.2319, -110.9501),
            speed: Profile::Const(5.0),
            steer: Profile::Sine {
                mean: 0.0,
                amp: 30.0,
                period_s: 4.0,
            },
            gnss_hz: 100.0,
            cog_hz: 100.0,
            gnss_noise_m: 0.3,
            cog_noise_rad: 0.0,
            gnss_dropout: None,
            gnss_gap_exact: false,
            gnss_jump: None,
            gnss_jump_m: 0.0,
            gnss_jump_back_s: 0.0,
            burst: None,
            corrupt_per_tick: 0,
            unknown_per_tick: 0,
            path_points: 0,
            path_spacing_m: 1.0,
            path_once: false,
            obstacles: 0,
            obstacles_at_centre: false,
            obstacles_far_m: 0.0,
            heading_rad: 0.3,
            obstacles_moving_mps: 0.0,
            corridor_widening_m: 0.0,
            path_offset_m: 0.0,
        }
    }
}

/// The planner's frames of `spec` (see [`Spec::path_points`]).
fn planner_frames(spec: &Spec, truth: &Truth, origin_e7: (i32, i32)) -> Vec<TimedFrame> {
    let mut out = Vec::new();
    if spec.path_points < 2 {
        return out;
    }
    let points = spec.path_points.min(MAX_PATH_POINTS);
    let mut counters = [0u8; 5];
    let mut next = |slot: usize| {
        let c = counters[slot];
        counters[slot] = (c + 1) & 0x0F;
        c
    };
    let mut frames: Vec<CanFrame> = vec![
        LocalOrigin::Latitude {
            lat_e7: origin_e7.0,
        }
        .encode(next(4)),
        LocalOrigin::Longitude {
            lon_e7: origin_e7.1,
        }
        .encode(next(4)),
    ];
    let obstacles = spec.obstacles.min(MAX_OBSTACLES);
    let per_path = 2 * points + 1 + obstacles;
    // The last path's obstacles: slot, centre, and the heading of the path where they are.
    let mut circles: Vec<(usize, f64, f64, f64)> = Vec::new();
    let ticks = (spec.seconds / 0.02) as usize;
    let paths = match spec.path_once {
        true => 1,
        false => ticks * PLANNER_FRAMES_PER_TICK / per_path + 1,
    };
    for k in 0..paths {
        let path_id = (k % 16) as u8;
        let track = offset_right(
            &truth.track_ahead(
                frame_time_s(frames.len()) - 0.2,
                points,
                spec.path_spacing_m,
            ),
            spec.path_offset_m,
        );
        frames.push(
            PathHeader {
                path_id,
                count: points as u16,
            }
            .encode(next(0)),
        );
        for (i, &(east, north)) in track.iter().enumerate() {
            let index = i as u8;
            frames.push(
                PathPoint {
                    path_id,
                    index,
                    east_m: east as f32,
                    north_m: north as f32,
                }
                .encode(next(1)),
            );
            frames.push(
                PathLimits {
                    path_id,
                    index,
                    speed_mps: 5.0,
                    left_m: (3.0 + spec.corridor_widening_m * f64::from(index)) as f32,
                    right_m: (3.0 + spec.corridor_widening_m * f64::from(index)) as f32,
                }
                .encode(next(2)),
            );
        }
        let centre = circumcentre(&track);
        circles.clear();
        for slot in 0..obstacles {
            let i = points.saturating_sub(2 + slot);
            let (Some(&(e0, n0)), Some(&(e1, n1))) = (track.get(i), track.get(i + 1)) else {
                continue;
            };
            let heading = (e1 - e0).atan2(n1 - n0);
            let (east, north) = match centre {
                _ if spec.obstacles_far_m > 0.0 => {
                    let (e, n) = track[points - 1];
                    let (far, beyond) = (spec.obstacles_far_m, 2.0);
                    (
                        e + beyond * heading.sin() + far * heading.cos(),
                        n + beyond * heading.cos() - far * heading.sin(),
                    )
                }
                Some(c) if spec.obstacles_at_centre => c,
                _ => (e0 + 2.0 * heading.cos(), n0 - 2.0 * heading.sin()),
            };
            frames.push(
                Obstacle {
                    obstacle_id: slot as u8,
                    circle: Some(ObstacleCircle {
                        east_m: east as f32,
                        north_m: north as f32,
                        radius_m: 0.3,
                    }),
                }
                .encode(next(3)),
            );
            circles.push((slot, east, north, heading));
        }
    }
    if spec.path_once && spec.obstacles_moving_mps > 0.0 && !circles.is_empty() {
        let start_s = frame_time_s(frames.len());
        while frame_time_s(frames.len()) < spec.seconds {
            let moved_m = spec.obstacles_moving_mps * (frame_time_s(frames.len()) - start_s);
            for &(slot, east, north, heading) in &circles {
                frames.push(
                    Obstacle {
                        obstacle_id: slot as u8,
                        circle: Some(ObstacleCircle {
                            east_m: (east - moved_m * heading.cos()) as f32,
                            north_m: (north + moved_m * heading.sin()) as f32,
                            radius_m: 0.3,
                        }),
                    }
                    .encode(next(3)),
                );
            }
        }
    }
    for (i, frame) in frames.into_iter().enumerate() {
        let t_s = frame_time_s(i);
        if t_s >= spec.seconds {
            break;
        }
        out.push(TimedFrame {
            t_us: us(t_s),
            frame,
        });
    }
    out
}

/// The centre of the circle through the first, middle and last of `points` (`None` if they
/// are in a line).
fn circumcentre(points: &[(f64, f64)]) -> Option<(f64, f64)> {
    let (&a, &b, &c) = (
        points.first()?,
        points.get(points.len() / 2)?,
        points.last()?,
    );
    let d = 2.0 * (a.0 * (b.1 - c.1) + b.0 * (c.1 - a.1) + c.0 * (a.1 - b.1));
    if d.abs() < 1e-9 {
        return None;
    }
    let sq = |p: (f64, f64)| p.0 * p.0 + p.1 * p.1;
    let x = (sq(a) * (b.1 - c.1) + sq(b) * (c.1 - a.1) + sq(c) * (a.1 - b.1)) / d;
    let y = (sq(a) * (c.0 - b.0) + sq(b) * (a.0 - c.0) + sq(c) * (b.0 - a.0)) / d;
    Some((x, y))
}

/// When the planner's `i`-th frame goes out, s into the drive: PLANNER_FRAMES_PER_TICK per
/// 20 ms, 0.5 ms apart, from the first tick on.
fn frame_time_s(i: usize) -> f64 {
    let tick = (i / PLANNER_FRAMES_PER_TICK) as f64;
    let slot = (i % PLANNER_FRAMES_PER_TICK) as f64;
    0.0015 + tick * 0.02 + slot * 0.0005
}

/// splitmix64: small, fast and good enough to choose faults and noise reproducibly.
#[derive(Clone, Debug)]
pub struct Rng(u64);

impl Rng {
    /// A generator from `seed`.
    pub fn new(seed: u64) -> Self {
        Self(seed ^ 0x9E37_79B9_7F4A_7C15)
    }
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }
    /// Uniform integer in [0, n).
    pub fn below(&mut self, n: u64) -> u64 {
        self.next_u64() % n.max(1)
    }
    /// Standard normal (Box-Muller).
    pub fn normal(&mut self) -> f64 {
        let u = self.uniform().max(1e-300);
        let v = self.uniform();
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
}

/// The drive's first frame time, us: an epoch-like time, as a recorder writes it.
const START_US: u64 = 1_700_000_000_000_000;
/// Truth integration step, s.
const TRUTH_DT_S: f64 = 0.001;
/// Rate of the drive-by-wire reports (catmodel.dbc: 50 Hz).
const REPORT_HZ: f64 = 50.0;
/// Tick period, s.
const TICK_S: f64 = catmodel::SAMPLE_PERIOD_S_F64;

/// The car along the drive: rear axle and heading every [`TRUTH_DT_S`].
struct Truth {
    /// (east, north, heading rad clockwise from north, speed).
    samples: Vec<(f64, f64, f64, f64)>,
}

impl Truth {
    fn new(spec: &Spec, car: &NodeConfig) -> Self {
        let n = (spec.seconds / TRUTH_DT_S).ceil() as usize + 1;
        let mut samples = Vec::with_capacity(n);
        let (mut x, mut y, mut h) = (0.0f64, 0.0f64, spec.heading_rad);
        for i in 0..n {
            let t = i as f64 * TRUTH_DT_S;
            let v = spec.speed.at(t).max(0.0).min(f64::from(car.max_speed_mps));
            samples.push((x, y, h, v));
            let steer = spec.steer.at(t).clamp(-100.0, 100.0) as f32;
            let center = car.vehicle.steer_pct_to_center_rad(steer);
            let curvature = f64::from(car.vehicle.curvature_per_m(center, v as f32));
            let ds = v * TRUTH_DT_S;
            x += ds * (h + 0.5 * ds * curvature).sin();
            y += ds * (h + 0.5 * ds * curvature).cos();
            h += ds * curvature;
        }
        Self { samples }
    }

    /// `points` points `spacing_m` apart along the rear axle's track from where it is at
    /// `t_s` (clamped to the drive), straight on along the last heading beyond the drive's end.
    fn track_ahead(&self, t_s: f64, points: usize, spacing_m: f64) -> Vec<(f64, f64)> {
        let first = ((t_s / TRUTH_DT_S).round().max(0.0) as usize).min(self.samples.len() - 1);
        let (x0, y0, _, _) = self.samples[first];
        let mut out = vec![(x0, y0)];
        let (mut last_x, mut last_y) = (x0, y0);
        for &(x, y, _, _) in &self.samples[first..] {
            if out.len() == points {
                break;
            }
            if (x - last_x).hypot(y - last_y) >= spacing_m {
                out.push((x, y));
                (last_x, last_y) = (x, y);
            }
        }
        let (_, _, h, _) = self.samples[self.samples.len() - 1];
        while out.len() < points {
            (last_x, last_y) = (last_x + spacing_m * h.sin(), last_y + spacing_m * h.cos());
            out.push((last_x, last_y));
        }
        out
    }

    fn at(&self, t_s: f64) -> (f64, f64, f64, f64) {
        let i = ((t_s / TRUTH_DT_S).round().max(0.0) as usize).min(self.samples.len() - 1);
        self.samples[i]
    }
}

/// `track`'s points moved `offset_m` to the right of its direction there (each point along
/// its next segment's, the last along the one before).
fn offset_right(track: &[(f64, f64)], offset_m: f64) -> Vec<(f64, f64)> {
    if offset_m == 0.0 || track.len() < 2 {
        return track.to_vec();
    }
    (0..track.len())
        .map(|i| {
            let (a, b) = match i + 1 < track.len() {
                true => (track[i], track[i + 1]),
                false => (track[i - 1], track[i]),
            };
            let heading = (b.0 - a.0).atan2(b.1 - a.1);
            let (e, n) = track[i];
            (e + offset_m * heading.cos(), n - offset_m * heading.sin())
        })
        .collect()
}

/// Every time `k / hz + phase_s` within the drive.
fn ticks_of(hz: f64, phase_s: f64, seconds: f64) -> impl Iterator<Item = f64> {
    let n = if hz > 0.0 {
        (seconds * hz).floor() as u64
    } else {
        0
    };
    (0..n).map(move |k| k as f64 / hz + phase_s)
}

fn us(t_s: f64) -> u64 {
    START_US + (t_s * 1e6).round() as u64
}

/// The GNSS fixes' times of `spec`: the receiver's slots outside the dropout windows, or with
/// [`Spec::gnss_gap_exact`] each window's exact gap.
fn fix_times(spec: &Spec) -> Vec<f64> {
    let slots = ticks_of(spec.gnss_hz, 0.0033, spec.seconds);
    let Some(w) = spec.gnss_dropout else {
        return slots.collect();
    };
    if !spec.gnss_gap_exact {
        return slots.filter(|&t| w.window(t).is_none()).collect();
    }
    // Each window [s, s + len] as the gap (t_b - len, t_b), t_b the first tick at or after its
    // end (frame times are whole microseconds: the tick's own).
    let mut gaps = Vec::new();
    let mut start = w.first_s;
    while start + w.len_s < spec.seconds {
        let t_b = ((start + w.len_s) / TICK_S - 1e-9).ceil() * TICK_S;
        gaps.push((t_b - w.len_s, t_b));
        start += w.every_s.max(1e-3);
    }
    let mut times: Vec<f64> = slots
        .filter(|&t| !gaps.iter().any(|&(a, b)| t >= a - 1e-6 && t <= b + 1e-6))
        .collect();
    for (a, b) in gaps {
        times.extend([a, b]);
    }
    times.sort_by(f64::total_cmp);
    times
}

/// The drive's frames, in time order.
pub fn generate(spec: &Spec, car: &NodeConfig) -> Vec<TimedFrame> {
    let truth = Truth::new(spec, car);
    let mut rng = Rng::new(spec.seed);
    let origin_e7 = (
        (spec.origin_deg.0 * 1e7).round() as i32,
        (spec.origin_deg.1 * 1e7).round() as i32,
    );
    let frame = LocalFrame::new(origin_e7.0, origin_e7.1).ok();
    let source = car.gnss_source;
    let (ahead, left) = (
        f64::from(car.estimator.antenna_ahead_m),
        f64::from(car.estimator.antenna_left_m),
    );
    let mut out: Vec<TimedFrame> = planner_frames(spec, &truth, origin_e7);
    let mut push = |t_s: f64, frame: CanFrame| {
        out.push(TimedFrame {
            t_us: us(t_s),
            frame,
        })
    };

    // Drive-by-wire reports, 50 Hz, each with its own rolling counter.
    for (k, t) in ticks_of(REPORT_HZ, 0.0011, spec.seconds).enumerate() {
        let (_, _, _, v) = truth.at(t);
        let counter = (k % 16) as u8;
        let steer = spec.steer.at(t).clamp(-100.0, 100.0) as f32;
        // The command leads the speed by the car's speed-loop delay (eq 5: 0.42 s).
        let (_, _, _, v_cmd) = truth.at(t + 0.42);
        push(
            t,
            SteeringReport {
                steer_pct: Some(steer),
            }
            .encode(counter),
        );
        push(
            t + 0.0002,
            SpeedReport {
                speed_mps: Some(spec.speed.at(t).clamp(0.0, 655.0) as f32),
                speed_cmd_mps: Some(v_cmd.max(v * 0.0) as f32),
                direction: Direction::NotReported,
            }
            .encode(counter),
        );
        push(
            t + 0.0004,
            PedalReport {
                accel_pct: Some(20.0),
                brake_pct: Some(0.0),
            }
            .encode(counter),
        );
    }
    // GNSS: the antenna where the car's file puts it, in the node's local frame.
    if let Some(local) = frame {
        for t in fix_times(spec) {
            let jumped = spec.gnss_jump.and_then(|w| w.window(t)).is_some();
            let (x, y, h, _) = match jumped && spec.gnss_jump_back_s > 0.0 {
                true => truth.at(t - spec.gnss_jump_back_s),
                false => truth.at(t),
            };
            let jump = match jumped && spec.gnss_jump_back_s <= 0.0 {
                true => spec.gnss_jump_m,
                false => 0.0,
            };
            // Ahead along the heading (clockwise from north), left across it.
            let east =
                x + ahead * h.sin() - left * h.cos() + spec.gnss_noise_m * rng.normal() + jump;
            let north = y + ahead * h.cos() + left * h.sin() + spec.gnss_noise_m * rng.normal();
            let (lat, lon) = local.from_local(Enu {
                east_m: east as f32,
                north_m: north as f32,
            });
            push(
                t,
                GnssPosition {
                    lat_e7: (lat * 1e7).round() as i32,
                    lon_e7: (lon * 1e7).round() as i32,
                }
                .encode(source),
            );
        }
    }
    for (k, t) in ticks_of(spec.cog_hz, 0.0057, spec.seconds).enumerate() {
        let (_, _, h, v) = truth.at(t);
        // (Drawn only when asked for: the other drives' random streams stay as they were.)
        let h = if spec.cog_noise_rad > 0.0 {
            h + spec.cog_noise_rad * rng.normal()
        } else {
            h
        };
        push(
            t,
            GnssCogSog {
                sid: k as u8,
                cog_reference: 0,
                // The field's top (raw 62 832 x 1e-4 rad, catmodel.dbc), just below 2 pi.
                cog_rad: Some(h.rem_euclid(std::f64::consts::TAU).min(62_831.0 * 1e-4) as f32),
                sog_mps: Some(v.min(655.0) as f32),
            }
            .encode(source),
        );
    }
    // Load: frames the node rejects, and frames the acceptance filter refuses.
    let ticks = (spec.seconds / TICK_S).floor() as u64;
    for tick in 0..ticks {
        let t0 = tick as f64 * TICK_S;
        for _ in 0..spec.corrupt_per_tick {
            let t = t0 + rng.range(0.0, TICK_S);
            let frame = corrupt_frame(&mut rng, source);
            push(t, frame);
        }
        for _ in 0..spec.unknown_per_tick {
            let t = t0 + rng.range(0.0, TICK_S);
            push(t, unknown_frame(&mut rng));
        }
    }
    // Bursts: everything in a window arrives at its end, in one tick.
    if let Some(burst) = spec.burst {
        for f in out.iter_mut() {
            let t = (f.t_us - START_US) as f64 * 1e-6;
            if let Some(start) = burst.window(t) {
                f.t_us = us(start + burst.len_s);
            }
        }
    }
    out.sort_by_key(|f| f.t_us);
    out
}

/// An input frame the node rejects, of a random kind.
fn corrupt_frame(rng: &mut Rng, source: u8) -> CanFrame {
    let counter = rng.below(16) as u8;
    let good = match rng.below(3) {
        0 => SteeringReport {
            steer_pct: Some(rng.range(-100.0, 100.0) as f32),
        }
        .encode(counter),
        1 => SpeedReport {
            speed_mps: Some(rng.range(0.0, 60.0) as f32),
            speed_cmd_mps: Some(rng.range(0.0, 60.0) as f32),
            direction: Direction::NotReported,
        }
        .encode(counter),
        _ => PedalReport {
            accel_pct: Some(50.0),
            brake_pct: Some(0.0),
        }
        .encode(counter),
    };
    match rng.below(6) {
        // CRC error.
        0 => {
            let mut f = good;
            f.data[7] ^= 0x5A;
            f
        }
        // Wrong DLC.
        1 => CanFrame::new(good.id, &good.data[..7]).unwrap_or(good),
        // Out of range (steering raw beyond +-100 %), with a valid CRC.
        2 => {
            let mut f = SteeringReport {
                steer_pct: Some(0.0),
            }
            .encode(counter);
            f.data[0] = 0x50;
            f.data[1] = 0x46; // 18000 x 0.01 % = 180 %
            f.data[7] = catmodel::can::crc::frame_crc(f.id, &f.data);
            f
        }
        // A fix "not available".
        3 => GnssPosition {
            lat_e7: i32::MAX,
            lon_e7: i32::MAX,
        }
        .encode(source),
        // A fix from another receiver (passes the filter, the node counts it unknown).
        4 => GnssPosition {
            lat_e7: 322_319_000,
            lon_e7: -1_109_501_000,
        }
        .encode(source.wrapping_add(1)),
        // A COG/SOG frame with its fields unavailable.
        _ => GnssCogSog {
            sid: 0,
            cog_reference: 0,
            cog_rad: None,
            sog_mps: None,
        }
        .encode(source),
    }
}

/// A frame whose identifier is not a node input.
fn unknown_frame(rng: &mut Rng) -> CanFrame {
    let id = loop {
        let id = if rng.below(2) == 0 {
            CanId::Standard(rng.below(0x800) as u16)
        } else {
            CanId::Extended(rng.below(0x2000_0000) as u32)
        };
        if !catmodel::can::spec::is_node_input(id) {
            break id;
        }
    };
    let mut data = [0u8; 8];
    for b in &mut data {
        *b = rng.below(256) as u8;
    }
    CanFrame::new(id, &data).unwrap_or(CanFrame {
        id,
        len: 0,
        data: [0; 8],
    })
}

/// Writes `frames` as a candump file.
pub fn write_candump(path: &Path, frames: &[TimedFrame]) -> Result<()> {
    let mut text = String::with_capacity(frames.len() * 48);
    for f in frames {
        candump::format_line(f, "can0", &mut text).map_err(|_| anyhow::anyhow!("format"))?;
        let _ = writeln!(text);
    }
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

/// How long the node's heading takes to settle on the receiver's course, s (its time
/// constants at the file's course gain per tick; 0 without a gain).
fn heading_settle_s(car: &NodeConfig) -> f64 {
    let gain = f64::from(car.estimator.course_gain);
    match gain > 0.0 {
        true => f64::from(catmodel::node::smoothing::HEADING_SETTLE_TIME_CONSTANTS) / gain * TICK_S,
        false => 0.0,
    }
}

/// The shortest gap in the fixes that the node restarts its filters after, s: one more missing
/// fix than a tick fills (`src/node/gnss.rs`: a gap rounds to whole periods, so
/// `GAP_FILL_PER_TICK + 1.5` of them).
pub fn restart_gap_s(car: &NodeConfig) -> f64 {
    (f64::from(GAP_FILL_PER_TICK) + 1.5) / car.estimator.declared_gnss_rate_hz()
}

/// How much faster than its declared rate a receiver the bursts' drive sends at: under
/// `catmodel::node::gnss::CROWDED_TENTHS` / 10 (a faster one's fixes are not used), over the
/// rate that brings the tick's cap of fixes now and then.
pub const TAKEN_FASTER: f64 = 1.3;

/// The dedicated drives of the stage measurement: together they take every stage of the tick
/// through its most expensive path (docs/firmware.md, "Worst-case tick"). Each runs on a
/// fresh node.
pub fn stage_corpus(car: &NodeConfig) -> Vec<Spec> {
    let top = f64::from(car.max_speed_mps) + 5.0;
    let enter = f64::from(car.hybrid.enter_dynamic_speed_mps);
    let exit = f64::from(car.hybrid.exit_dynamic_speed_mps);
    let dwell_s = f64::from(car.hybrid.min_dwell_ticks) * TICK_S;
    // The car's receiver as its model file declares it: the node does not use fixes at another
    // rate (`gnss_rate_mismatch`), so every drive but the bursts' sends them at this one, and
    // the gaps are counted in its fixes. The published car's 100 Hz gives the figures in
    // docs/firmware.md; a 5 Hz car's gaps are longer in seconds, not in fixes.
    let gnss_hz = car.estimator.declared_gnss_rate_hz();
    let period_s = 1.0 / gnss_hz;
    let lost_s = car.gnss_lost_us as f64 * 1e-6;
    let reacquire_s = f64::from(car.gnss_reacquire_fixes) * period_s;
    let plain = |name: &str| Spec {
        gnss_hz,
        cog_hz: gnss_hz,
        ..Spec::plain(name)
    };
    // Long enough for a dozen gaps of each kind at the slowest receiver (1 Hz).
    let gaps_s = (16.0_f64).max(40.0 * period_s);
    // A restart's dearest run writes a track entry per missing fix up to the track's length:
    // the long gaps miss more fixes than that where the receiver is fast enough for it before
    // the position is lost, else as many as it can, and always more than a tick fills.
    let track_s = (TRACK_LEN as f64 + 1.5) * period_s;
    let long_gap_s = track_s.min(lost_s - 1.5 * period_s).max(restart_gap_s(car));
    let lost_gap_s = (2.6_f64).max(lost_s + 6.0 * period_s);
    // The exact gaps: as long as the track holds or the position lasts (a tick after
    // `gnss_lost_s` at most: the tick before the fix still finds it within), at least a
    // restart's; a few of them, apart by the filters' memory and the heading's settling.
    let exact_gap_s = (track_s.min(lost_s + TICK_S - 2e-6)).max(restart_gap_s(car) + 2e-6);
    let slow = (2.0_f64).max(f64::from(car.estimator.course_min_speed_mps) + 0.5);
    let memory_s = (car.estimator.fir.len() + car.estimator.ma.len() + 2) as f64 * period_s;
    let exact_first_s = 2.0 + memory_s + heading_settle_s(car);
    let exact_every_s = exact_gap_s + memory_s + 2.0;
    // As many missing fixes as a tick fills, or as the position lasts (a 1 Hz receiver lost
    // after 2.5 s: one; the GNSS timeout, 2.5 periods at least, leaves one always).
    let fill_gap_s = (f64::from(GAP_FILL_PER_TICK + 1) * period_s).min(lost_s + TICK_S - 2e-6);
    let fill_every_s = fill_gap_s + memory_s + 1.0;
    let far_every_s = (5.0_f64).max(2.0 * reacquire_s + 30.0 * period_s);
    vec![
        // Running, both modes: frames bunched into single ticks (every tick at the cap for a
        // while), GNSS and COG as fast above the declared rate as the node still takes a
        // receiver (`gnss::CROWDED_TENTHS`: 1.4 times is not; the published car's 100 Hz
        // brings 2.6 fixes a tick, the cap of three often).
        Spec {
            burst: Some(Periodic {
                first_s: 3.0,
                every_s: 0.5,
                len_s: 0.1,
            }),
            gnss_hz: TAKEN_FASTER * gnss_hz,
            cog_hz: TAKEN_FASTER * gnss_hz,
            ..Spec::plain("stages-bursts")
        },
        // Courses over ground that scatter (a receiver that differences its fixes): the
        // estimate judges each against the heading, then corrects the heading on the track's
        // chords in the same tick (`estimator::CogCorrection::Scattered`).
        Spec {
            cog_noise_rad: 0.5,
            ..plain("stages-cog-scattered")
        },
        // Top speed, full lock, steering flipping: the dynamic model, turns of more than
        // 0.5 rad per 0.2 s segment, headings wrapping, predictions saturating.
        Spec {
            seconds: 12.0,
            speed: Profile::Ramp {
                from: 8.0,
                to: top,
                seconds: 4.0,
            },
            steer: Profile::Square {
                lo: -100.0,
                hi: 100.0,
                period_s: 1.3,
            },
            ..plain("stages-top-speed-full-lock")
        },
        // The hybrid switch flipping as often as its dwell allows, both ways.
        Spec {
            speed: Profile::Square {
                lo: (exit - 1.0).max(0.5),
                hi: enter + 1.0,
                period_s: 2.0 * dwell_s + 2.0 * TICK_S,
            },
            steer: Profile::Square {
                lo: -100.0,
                hi: 100.0,
                period_s: 0.7,
            },
            ..plain("stages-hybrid-flips")
        },
        // GNSS gaps of every length: filled fix by fix, restarts on the track, outages past
        // "lost"; and jumps beyond the gate long enough to be followed.
        Spec {
            seconds: gaps_s,
            speed: Profile::Const(12.0),
            gnss_dropout: Some(Periodic {
                first_s: 2.0,
                every_s: (0.37_f64).max(5.3 * period_s),
                len_s: 1.3 * period_s,
            }),
            gnss_jump: Some(Periodic {
                first_s: 6.0,
                every_s: (5.0_f64).max(2.0 * reacquire_s + 10.0 * period_s),
                len_s: (1.3_f64).max(reacquire_s + 4.0 * period_s),
            }),
            gnss_jump_m: 40.0,
            ..plain("stages-gnss-gaps-short")
        },
        Spec {
            seconds: gaps_s,
            speed: Profile::Const(12.0),
            gnss_dropout: Some(Periodic {
                first_s: 2.0,
                every_s: (1.1_f64).max(long_gap_s + 5.0 * period_s),
                len_s: long_gap_s,
            }),
            ..plain("stages-gnss-gaps-long")
        },
        // The longest gap a restart can follow for this car, the fix after it taken in the
        // tick before the position is given up (`gnss_lost_s` and a tick at most, for a
        // receiver whose slots leave no such gap), driven slowly and straight so that dead
        // reckoning lands within the tightest gate a file sets, after the filters are warm
        // and the heading has settled.
        Spec {
            seconds: exact_first_s + 3.0 * exact_every_s,
            speed: Profile::Const(slow),
            steer: Profile::Const(0.0),
            gnss_dropout: Some(Periodic {
                first_s: exact_first_s,
                every_s: exact_every_s,
                len_s: exact_gap_s,
            }),
            gnss_gap_exact: true,
            ..plain("stages-gnss-gaps-exact")
        },
        // The same with gaps a tick fills, as many fixes as it fills.
        Spec {
            seconds: exact_first_s + 3.0 * fill_every_s,
            speed: Profile::Const(slow),
            steer: Profile::Const(0.0),
            gnss_dropout: Some(Periodic {
                first_s: exact_first_s,
                every_s: fill_every_s,
                len_s: fill_gap_s,
            }),
            gnss_gap_exact: true,
            ..plain("stages-gnss-gaps-exact-fill")
        },
        Spec {
            seconds: (14.0_f64).max(3.0 + 1.8 * (lost_gap_s + 3.4)),
            gnss_dropout: Some(Periodic {
                first_s: 3.0,
                every_s: lost_gap_s + 3.4,
                len_s: lost_gap_s,
            }),
            ..plain("stages-gnss-lost")
        },
        // Floods: every tick at the cap with frames the node must decode and reject, and
        // frames the acceptance filter refuses.
        Spec {
            corrupt_per_tick: 14,
            unknown_per_tick: 40,
            ..plain("stages-floods")
        },
        // Standstill, then off: the slow branches of the models and the roll-out.
        Spec {
            speed: Profile::Square {
                lo: 0.0,
                hi: 2.0,
                period_s: 3.0,
            },
            steer: Profile::Const(100.0),
            ..plain("stages-standstill")
        },
        // The local frame at other latitudes (its f64 set-up takes other paths).
        Spec {
            seconds: 2.0,
            origin_deg: (0.0001, 0.0001),
            ..plain("stages-origin-equator")
        },
        Spec {
            seconds: 2.0,
            origin_deg: (79.9, 179.9),
            ..plain("stages-origin-north")
        },
        Spec {
            seconds: 2.0,
            origin_deg: (-45.0, -179.99),
            ..plain("stages-origin-south")
        },
        // The car leaving the node's own frame: fixes 25 km away (beyond the frame's validity
        // radius) long enough for the frame to move to them, and back, at the dearest of the
        // latitudes above (the frame built again at each move).
        Spec {
            seconds: 2.0 + 2.0 * far_every_s,
            origin_deg: (79.9, 179.9),
            gnss_jump: Some(Periodic {
                first_s: 2.0,
                every_s: far_every_s,
                len_s: reacquire_s + 10.0 * period_s,
            }),
            gnss_jump_m: 25_000.0,
            ..plain("stages-frame-moves")
        },
        // The planner's paths completing: the longest path the bus carries (validation and
        // load over 256 points), and short ones completing every few ticks.
        // (Longer for a slow receiver: the controller plans, and a long path's tick coasts on
        // the previous plan, only once the lowpass has a position.)
        Spec {
            seconds: (9.0_f64).max(5.0 + 40.0 * period_s),
            path_points: MAX_PATH_POINTS,
            ..plain("stages-path-long")
        },
        Spec {
            seconds: (9.0_f64).max(5.0 + 40.0 * period_s),
            path_points: MAX_PATH_POINTS,
            path_spacing_m: 0.08,
            obstacles: MAX_OBSTACLES,
            corridor_widening_m: 0.002,
            ..plain("stages-path-dense")
        },
        // The same on a path that runs round its obstacles: the car at full lock.
        Spec {
            seconds: (9.0_f64).max(5.0 + 40.0 * period_s),
            speed: Profile::Const(4.0),
            steer: Profile::Const(100.0),
            path_points: MAX_PATH_POINTS,
            path_spacing_m: 0.08,
            obstacles: MAX_OBSTACLES,
            obstacles_at_centre: true,
            corridor_widening_m: 0.002,
            ..plain("stages-path-round")
        },
        // The same on a wide arc (40 m radius) round its obstacles: the search for an
        // obstacle's nearest segment finds every segment about as near (within the bus's
        // 0.02 m resolution of a point, which on the lock's small circle set the segments
        // apart by more than the search's pruning lets through), so it prunes none: its
        // dearest run, which the full-lock circle reached only for a car whose lock is wide.
        Spec {
            seconds: (9.0_f64).max(5.0 + 40.0 * period_s),
            speed: Profile::Const(4.0),
            steer: Profile::Const(steer_for_curvature_pct(car, 1.0 / ARC_RADIUS_M, 4.0)),
            path_points: MAX_PATH_POINTS,
            path_spacing_m: 0.08,
            obstacles: MAX_OBSTACLES,
            obstacles_at_centre: true,
            corridor_widening_m: 0.002,
            ..plain("stages-path-arc")
        },
        // The same on a straight path due north, the obstacles 600 m to its right and beyond
        // its end: each segment a little nearer than the one before, and all about as near
        // (`Spec::obstacles_far_m`), for every car: the dearest geometry for a search that
        // prunes by distance (the pruning search the node had cost 12 752 instructions
        // more here than on any other drive for the published car).
        Spec {
            seconds: (9.0_f64).max(5.0 + 40.0 * period_s),
            speed: Profile::Const(4.0),
            steer: Profile::Const(0.0),
            heading_rad: 0.0,
            path_points: MAX_PATH_POINTS,
            path_spacing_m: 0.08,
            obstacles: MAX_OBSTACLES,
            obstacles_far_m: FAR_OBSTACLE_M,
            corridor_widening_m: 0.002,
            ..plain("stages-path-far")
        },
        // The densest path the node accepts (`control::path::MIN_SEGMENT_M`: PATH_POINT's
        // 0.02 m grid allows (0.04, 0.04) m steps, 0.057 m, where a planner's own spacing is
        // 0.08 m), driven slowly enough that the plan's horizon and the body stay on it: every
        // search the reference makes in metres holds the most points it can (drive_reference
        // 127 304 instructions for the published car against 123 847 on the drives above,
        // before the body's ends' searches started from the station before).
        Spec {
            seconds: (9.0_f64).max(5.0 + 40.0 * period_s),
            speed: Profile::Const(1.5),
            steer: Profile::Const(0.0),
            heading_rad: core::f64::consts::FRAC_PI_4,
            path_points: MAX_PATH_POINTS,
            path_spacing_m: DENSEST_SPACING_M,
            obstacles: MAX_OBSTACLES,
            corridor_widening_m: 0.002,
            ..plain("stages-path-densest")
        },
        // Obstacles sent every tick as they move: the planner frames whose handling fits a
        // slot's motion (docs/bus.md, "Obstacles that move"), every slot's fit closing in the
        // same tick.
        Spec {
            seconds: (6.0_f64).max(5.0 + 40.0 * period_s),
            path_points: MAX_PATH_POINTS,
            path_once: true,
            obstacles: MAX_OBSTACLES,
            obstacles_moving_mps: 1.5,
            ..plain("stages-obstacles-moving")
        },
        Spec {
            seconds: (4.0_f64).max(1.0 + 40.0 * period_s),
            path_points: SHORT_PATH_POINTS,
            ..plain("stages-path-short")
        },
        path_jump(car, plain("stages-path-jump")),
        // A path beside the car, its corridor a body width and more away: the car has lost it
        // along it from the first plan on and brakes on the lane hold at the station it would
        // have reached (`node::drive`), a path sample and the hold's steering in every tick.
        Spec {
            seconds: (6.0_f64).max(5.0 + 40.0 * period_s),
            steer: Profile::Const(0.0),
            path_points: MAX_PATH_POINTS,
            path_once: true,
            path_offset_m: 3.0 + 2.0 * f64::from(car.body.width_m) + 1.0,
            ..plain("stages-path-lost")
        },
    ]
}

/// How far `stages-path-far`'s obstacles are to the right of its path, m: a path of 256
/// points 0.08 m apart (20.4 m) is 2 m to 22.4 m from them along it, and the squared distance
/// of its first point, 600^2 + 22.4^2, is 0.14 % above its last's, 600^2 + 2^2 (the node's
/// search once pruned by 0.3 %).
const FAR_OBSTACLE_M: f64 = 600.0;

/// `stages-path-densest`'s spacing, m: the bus's grid steps (0.04, 0.04) m along a diagonal,
/// the least spacing above `control::path::MIN_SEGMENT_M` a decoded path can have.
const DENSEST_SPACING_M: f64 = 0.04 * core::f64::consts::SQRT_2;

/// The radius of `stages-path-arc`'s path, m.
const ARC_RADIUS_M: f64 = 40.0;

/// The steering, percent (at most the lock), at which `car`'s model drives `curvature_per_m`
/// at `speed_mps`: bisection over the model's own conversion (monotonic in the percent).
fn steer_for_curvature_pct(car: &NodeConfig, curvature_per_m: f64, speed_mps: f64) -> f64 {
    let curvature = |pct: f64| {
        let center = car.vehicle.steer_pct_to_center_rad(pct as f32);
        f64::from(car.vehicle.curvature_per_m(center, speed_mps as f32))
    };
    let (mut lo, mut hi) = (0.0, 100.0);
    if curvature(hi) <= curvature_per_m {
        return hi;
    }
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if curvature(mid) < curvature_per_m {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// A position that jumps back along a dense path, onto a part of it farther than
/// `PROJECTION_RESEARCH_M` from the window its projection searches, and stays there long enough
/// for the fixes to win: the tick that finds the car there searches the whole path after its
/// window and moves the last plan on instead of solving (`drive_coast`). One path of 256 points,
/// sent once (a new path places the car afresh), as dense as the car's timeline lets it be
/// (0.08 m for a 100 Hz receiver; longer for a slow one, whose heading settles, gate yields and
/// lowpass fills more slowly): the path is sent and completes, the heading settles while the
/// controller has the path, a few plans, the jump, the gate's `gnss_reacquire_fixes`, the
/// filters' restart, then the tick; the car still on the path then, and the jump long enough
/// that the new position is well clear of the old window (`xtask::drives::tests`).
fn path_jump(car: &NodeConfig, plain: Spec) -> Spec {
    use catmodel::control::path::{PROJECTION_BEHIND_M, PROJECTION_RESEARCH_M};
    let period_s = 1.0 / plain.gnss_hz;
    let speed = (2.0_f64).max(f64::from(car.estimator.course_min_speed_mps) + 0.5);
    let obstacles = MAX_OBSTACLES;
    let sent_s = frame_time_s(2 + 2 * MAX_PATH_POINTS + 1 + obstacles);
    let settle_s = heading_settle_s(car);
    // The filters' memory in fixes, with two to spare: a position after a restart within it.
    let fill_s = (car.estimator.fir.len() + car.estimator.ma.len() + 2) as f64 * period_s;
    let planning_s = sent_s.max(fill_s) + settle_s + 1.0;
    let yield_s = f64::from(car.gnss_reacquire_fixes) * period_s;
    // The new position this far behind the old one at least: past the window's back by the
    // research distance, and past the configured gate (the widest it opens), 1.5 m to spare
    // either way, however long the filters took to fill.
    let behind_m = f64::from(PROJECTION_BEHIND_M + PROJECTION_RESEARCH_M)
        .max(f64::from(car.gnss_gate_m))
        + 1.5;
    let back_s = behind_m / speed + fill_s + 0.5;
    // After a few plans, and late enough that the new position is on the path (past its
    // first metre).
    let jump_s = (planning_s + 0.5).max(back_s + 1.0 / speed - yield_s - fill_s - 0.5);
    let found_s = jump_s + yield_s + fill_s + 0.5;
    let length_m = speed * (found_s + 1.0);
    Spec {
        seconds: found_s + 1.5,
        speed: Profile::Const(speed),
        steer: Profile::Const(0.0),
        gnss_jump: Some(Periodic {
            first_s: jump_s,
            every_s: 1e6,
            len_s: 1e6,
        }),
        gnss_jump_back_s: back_s,
        path_points: MAX_PATH_POINTS,
        path_spacing_m: (0.08_f64).max(length_m / (MAX_PATH_POINTS - 1) as f64),
        path_once: true,
        obstacles,
        ..plain
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use catmodel::node::drive::Drive;
    use catmodel::node::{due_ticks, Node, PlatformStats, Stage, StageProbe, Tick, TxFrames};

    /// The stages each tick ran.
    #[derive(Default)]
    struct Laps {
        ticks: Vec<Vec<Stage>>,
        this_tick: Vec<Stage>,
    }

    impl StageProbe for Laps {
        fn lap(&mut self, stage: Stage) {
            self.this_tick.push(stage);
        }
    }

    /// The stages of every tick of `spec`'s drive through a node of `car`.
    fn laps(spec: &Spec, car: &NodeConfig) -> Vec<Vec<Stage>> {
        let frames = generate(spec, car);
        let mut node = Node::new(car.clone(), Box::new(Drive::new()));
        let mut laps = Laps::default();
        for (now_us, due) in due_ticks(&frames) {
            let tick = Tick {
                now_us,
                platform: PlatformStats::default(),
            };
            let mut tx = TxFrames::new();
            let _ = node.step_probed(&tick, &frames[due], &mut tx, &mut laps);
            laps.ticks.push(core::mem::take(&mut laps.this_tick));
        }
        laps.ticks
    }

    /// The published car, a 5 Hz receiver that bridges 30 s and the van.
    const THREE_CARS: [&str; 3] = [
        "models/paper.toml",
        "models/stress/dearest-found.toml",
        "models/van.toml",
    ];

    /// `car`'s stage drive `name`.
    fn corpus_spec(car: &NodeConfig, name: &str) -> Spec {
        stage_corpus(car)
            .into_iter()
            .find(|s| s.name == name)
            .unwrap()
    }

    fn car(file: &str) -> NodeConfig {
        let path = crate::root().join(file);
        catmodel_model_file::load(&path).unwrap().node_config()
    }

    /// The lost drive reaches what it is made for: the car loses its path along it and stops
    /// on the lane hold (`node::drive`, a path sample each tick), for the published car, the
    /// dearest file found and the van.
    #[test]
    fn the_lost_drive_loses_the_path_along_it_for_every_car() {
        use catmodel::can::codec::{ControlCommand, FallbackCause};
        for file in THREE_CARS {
            let car = car(file);
            let spec = corpus_spec(&car, "stages-path-lost");
            let frames = generate(&spec, &car);
            let mut node = Node::new(car.clone(), Box::new(Drive::new()));
            let mut lost = 0;
            for (now_us, due) in due_ticks(&frames) {
                let tick = Tick {
                    now_us,
                    platform: PlatformStats::default(),
                };
                let mut tx = TxFrames::new();
                let _ = node.step(&tick, &frames[due], &mut tx);
                let id = catmodel::can::spec::CONTROL_COMMAND.id;
                for f in tx.iter().filter(|f| f.id == id) {
                    if let Ok((c, _)) = ControlCommand::decode(f) {
                        lost += usize::from(c.fallback == FallbackCause::LostPath);
                    }
                }
            }
            assert!(lost >= 50, "{file}: {lost} ticks lost");
        }
    }

    /// The jump drive reaches what it is made for, for the published car, a 5 Hz receiver that
    /// bridges 30 s (`models/stress/dearest-found.toml`) and the van: a tick that searched the
    /// whole path after its window (`drive_coast` without a path completing) follows ticks
    /// that planned, does not solve itself, and the controller plans again after it.
    #[test]
    fn the_jump_drive_leaves_the_window_on_the_path_for_every_car() {
        for file in THREE_CARS {
            let car = car(file);
            let spec = corpus_spec(&car, "stages-path-jump");
            let ticks = laps(&spec, &car);
            let has = |t: &Vec<Stage>, s: Stage| t.contains(&s);
            let jumps: Vec<usize> = (0..ticks.len())
                .filter(|&k| {
                    has(&ticks[k], Stage::DriveCoast) && !has(&ticks[k], Stage::PathComplete)
                })
                .collect();
            assert!(!jumps.is_empty(), "{file}: no tick left the window");
            for &k in &jumps {
                assert!(!has(&ticks[k], Stage::MpcSolve), "{file}: tick {k} solved");
            }
            let k = jumps[0];
            assert!(
                ticks[..k].iter().any(|t| has(t, Stage::MpcSolve)),
                "{file}: nothing planned before the jump"
            );
            assert!(
                ticks[k + 1..].iter().any(|t| has(t, Stage::MpcSolve)),
                "{file}: nothing planned after the jump"
            );
        }
    }

    /// The stage drives reach, on the host, every stage the bound counts for the car (the
    /// measurement in QEMU refuses a row no drive ran, `bound::measure`), without the
    /// closed-loop sessions the measurement adds: the published car, the second car, the van
    /// (5 Hz), the dearest file found, and a 25 m truck with its antenna at a front corner,
    /// whose controller rows no drive reached before the jump drive.
    #[test]
    fn the_stage_drives_reach_every_stage_for_every_car() {
        for file in [
            "models/paper.toml",
            "models/hatchback.toml",
            "models/van.toml",
            "models/stress/dearest-found.toml",
            "models/stress/truck-corner-antenna.toml",
        ] {
            if let Some(key) = a_stage_no_drive_reaches(&car(file)) {
                panic!("{file}: no stage drive ran {key}");
            }
        }
    }

    /// The first stage the bound counts that no stage drive of `car` runs, if any.
    fn a_stage_no_drive_reaches(car: &NodeConfig) -> Option<&'static str> {
        let unreachable = crate::bound::unreachable(car);
        let mut seen: Vec<Stage> = Vec::new();
        for spec in stage_corpus(car) {
            for stage in laps(&spec, car).into_iter().flatten() {
                if !seen.contains(&stage) {
                    seen.push(stage);
                }
            }
        }
        catmodel::node::TICK_STAGES
            .iter()
            .find(|row| !unreachable.contains(&row.key) && !seen.contains(&row.stage))
            .map(|row| row.key)
    }

    /// The same for model files no one measured: drawn at random over the reader's ranges
    /// ([`crate::cars`]; `CARS=N CARS_SEED=S` for another draw). A file whose drives miss a
    /// stage is one `CATMODEL_MODEL=FILE cargo qemu` cannot bound.
    #[test]
    fn the_stage_drives_reach_every_stage_for_random_cars() {
        let count: usize = std::env::var("CARS").map_or(40, |v| v.parse().unwrap());
        let seed: u64 = std::env::var("CARS_SEED").map_or(1, |v| v.parse().unwrap());
        let mut rng = Rng::new(seed);
        let root = crate::root();
        let mut missed = Vec::new();
        for k in 0..count {
            let (file, text, _) = crate::cars::draw(&mut rng, &root).unwrap();
            if let Some(key) = a_stage_no_drive_reaches(&file.node_config()) {
                missed.push(format!(
                    "car {k} (seed {seed}): no stage drive ran {key}\n{text}"
                ));
            }
        }
        assert!(
            missed.is_empty(),
            "{} of {count}:\n{}",
            missed.len(),
            missed.join("\n")
        );
    }
}
