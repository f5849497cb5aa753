//! What the planner tells the node, assembled from its frames: the active path, the path being
//! received, the four obstacle slots and the map origin (docs/bus.md, "Sending a path").
//!
//! Rules: a PATH_HEADER starts assembling a path; its PATH_POINT and PATH_LIMITS frames arrive
//! each in index order; the path replaces the active one only when every point and limit is in
//! and the whole passes [`Path::validate_for`] the car ([`PlannerInputs::set_car`]). Everything else is a counted rejection, never a
//! panic: duplicates, gaps (a lost frame abandons the assembly), frames of a path not being
//! assembled, a header change mid-way (abandons the old assembly), stuck rolling counters, a
//! longitude page of LOCAL_ORIGIN that does not follow its latitude page.
//!
//! An obstacle slot that the planner keeps sending moves: its velocity is measured from its
//! circles ([`ObstacleMotion`]), since OBSTACLE carries none (docs/bus.md, "Obstacles that
//! move").
//!
//! No configuration; the state is [`PlannerInputs`]: the active [`Path`] (7 KiB) and the
//! assembly buffer (5 KiB) at 256 points. Never allocates; every call is O(1) except the one
//! that completes a path (one pass over its points to validate, one to load).
use core::ptr::addr_of_mut;

use crate::can::codec::{LocalOrigin, ObstacleCircle, PlannerMessage};
use crate::can::counter::CounterChecker;
use crate::can::spec::OBSTACLE_SLOTS;
use crate::in_place::fill;
use crate::math::{self, max, min};

use super::path::{LateralLimit, Path, PathCar, PathError, Waypoint, MAX_PATH_POINTS};

/// Rejection and event counters since start (saturating).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PlannerCounters {
    /// Paths that became active.
    pub paths_activated: u32,
    /// Assemblies abandoned: a lost frame, or a new header before completion.
    pub paths_abandoned: u32,
    /// Complete paths refused by [`Path::validate_for`] (the active path stays).
    pub paths_invalid: u32,
    /// PATH_POINT / PATH_LIMITS with an index already received (duplicates).
    pub duplicates: u32,
    /// PATH_POINT / PATH_LIMITS of a path id not being assembled (stray, or after an abandon).
    pub stray_frames: u32,
    /// Frames whose rolling counter did not change (a stuck sender), rejected.
    pub stuck_counters: u32,
    /// Counter jumps (frames of a planner message lost on the bus), counted.
    pub counter_jumps: u32,
    /// LOCAL_ORIGIN longitude pages that did not follow a latitude page.
    pub origin_mismatches: u32,
}

impl PlannerCounters {
    /// Frames and paths refused (NODE_STATUS `planner_rejects`): every count but the paths
    /// activated and the counter jumps (a jump is a lost frame, not a refusal: the path it
    /// breaks is counted abandoned).
    pub const fn rejects(&self) -> u32 {
        self.paths_abandoned
            .saturating_add(self.paths_invalid)
            .saturating_add(self.duplicates)
            .saturating_add(self.stray_frames)
            .saturating_add(self.stuck_counters)
            .saturating_add(self.origin_mismatches)
    }
}

fn bump(c: &mut u32) {
    *c = c.saturating_add(1);
}

/// What a received frame changed, for the caller to act on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PlannerEvent {
    /// Nothing the caller needs to act on (the frame was stored, or rejected and counted).
    None,
    /// Path `path_id` is complete and now the active path.
    PathActivated(u8),
    /// A complete path was refused; the previous path stays active.
    PathInvalid(u8, PathError),
    /// The planner set its map origin (1e-7 deg): the node's local frame.
    Origin {
        /// Latitude, 1e-7 deg.
        lat_e7: i32,
        /// Longitude, 1e-7 deg.
        lon_e7: i32,
    },
}

/// The span of frames of one obstacle slot that gives its velocity, us: a least-squares fit
/// of the centre's track over at least this long (25 frames at one a tick: a detector's
/// 0.1 m of noise on each circle is 0.14 m/s of it, the bus's 0.02 m resolution 0.03 m/s).
pub const OBSTACLE_VELOCITY_SPAN_US: u64 = 500_000;
/// A span of a standing object whose velocity is not yet a motion ([`OBSTACLE_MOTION_SIGMAS`])
/// goes on gathering frames up to this long, us, its fit tested at each: the velocity's standard error falls
/// with the span's length to the power 1.5, so a detector's 0.1 m of scatter hides a walk of
/// 0.58 m/s over 0.5 s and of 0.21 m/s over 1 s.
pub const OBSTACLE_VELOCITY_SPAN_MAX_US: u64 = 1_000_000;
/// A slot silent for longer starts its motion afresh, us.
pub const OBSTACLE_SILENT_US: u64 = 2_000_000;
/// Slower is taken as standing still, m/s: a standing object whose detection moves its circle
/// by centimetres from frame to frame does not move.
pub const OBSTACLE_STILL_MPS: f32 = 0.3;
/// A standing object's span shows a motion only if its velocity is this many times its own
/// standard error (from the fit's residuals) or more (a moving object goes on moving while it
/// is above [`OBSTACLE_STILL_MPS`]): a detector whose circles scatter by 0.1 m measures a standing
/// object at 0.14 m/s per axis over a span, past [`OBSTACLE_STILL_MPS`] in one span of twelve,
/// and each such span moved the object by its speed times the time to meet it. For a velocity
/// of zero the measured speed over its standard error has a Rayleigh law (above 5.5 once in
/// `exp(5.5^2 / 2)`, 3.6 million); a span tested at every frame from 0.5 to 1 s
/// ([`OBSTACLE_VELOCITY_SPAN_MAX_US`]) calls a standing object with 0.2 m of scatter moving in
/// none of 20 000 simulated spans at 5.5, 3 in 10 000 at 5.0 and 28 in 10 000 at 4.3 (the
/// simulation: `scripts/obstacle-motion-false-rate.py`).
pub const OBSTACLE_MOTION_SIGMAS: f32 = 5.5;
/// A moving object's span whose velocity is within this many of its standard errors of the
/// velocity held is the same motion: the velocity held becomes the mean of the two, so that a
/// walk's scatter does not take it below [`OBSTACLE_STILL_MPS`] for a span (a walk of 0.5 m/s
/// under 0.1 m of scatter did, about one span in sixteen, and the car took the pedestrian for
/// one standing and passed ahead of it: docs/findings.md). Farther, the span's is taken.
pub const OBSTACLE_SAME_SIGMAS: f32 = 3.0;
/// Faster than this between two frames (plus [`OBSTACLE_JUMP_M`]) is another object in the
/// slot, not a motion, m/s.
pub const OBSTACLE_MAX_MPS: f32 = 40.0;
/// See [`OBSTACLE_MAX_MPS`], m.
pub const OBSTACLE_JUMP_M: f32 = 0.5;

/// An obstacle's centre is the mean of its circles over about this long, s, each moved on by
/// the measured velocity to the latest's time (an exponential mean, the frames since the mean
/// started counted equally until there are this long of them): a detector's 0.1 m of scatter
/// on each circle is 0.014 m of it at one circle a tick.
pub const OBSTACLE_CENTRE_TIME_S: f32 = 0.5;
/// A circle farther from the mean centre than this many times the circles' scatter about the
/// last span's line (both axes) is not taken into it (before a span is measured, farther than
/// [`OBSTACLE_JUMP_M`]): one of a detector's outliers. The scatter over both axes is
/// `sqrt(2)` times the scatter per axis, so at 3 one circle in 8 000 (`exp(9)`) falls beyond
/// it.
pub const OBSTACLE_CENTRE_SIGMAS: f32 = 3.0;
/// The least such reach, m: a few times the bus's 0.02 m resolution.
pub const OBSTACLE_CENTRE_REACH_MIN_M: f32 = 0.05;
/// The most, m: a detector that scatters by 0.35 m per axis. Capped lower, at 0.5 m, a
/// scatter of 0.3 m put a quarter of the circles beyond reach and three in a row once a
/// second, each time restarting the mean at a circle 0.5 m off or more.
pub const OBSTACLE_CENTRE_REACH_MAX_M: f32 = 1.5;
/// So many circles in a row beyond reach of the mean centre: the object has moved, and the
/// mean starts afresh at the latest circle (an object that sets off, or turns, is lagged by its
/// reach and two frames of its motion at most).
pub const OBSTACLE_CENTRE_OUTLIERS: u8 = 3;

/// An obstacle slot's motion, measured from its circles: the slope of a least-squares line
/// through the centres of a span of frames at least [`OBSTACLE_VELOCITY_SPAN_US`] long (up to
/// [`OBSTACLE_VELOCITY_SPAN_MAX_US`] while it is no motion), held until the next span ends.
/// Zero (the obstacle stands) for a slot sent once, after a jump or [`OBSTACLE_SILENT_US`] of silence (until a span of frames after it), below
/// [`OBSTACLE_STILL_MPS`], and a standing one until its span's velocity is
/// [`OBSTACLE_MOTION_SIGMAS`] of its standard error.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ObstacleMotion {
    /// Velocity east, m/s.
    pub east_mps: f32,
    /// Velocity north, m/s.
    pub north_mps: f32,
    /// The span being measured: its first frame's centre and time (us), and the sums of the
    /// fit over its frames, in s and m from that first frame: count, t, t^2, east, north,
    /// t east, t north, east^2 + north^2.
    origin: (f32, f32),
    origin_us: u64,
    sums: [f32; 8],
    /// The latest frame's time, us.
    last_us: u64,
    /// The centre estimated ([`OBSTACLE_CENTRE_TIME_S`]) at the latest frame, m east and north.
    centre: (f32, f32),
    /// How far the centre may be from the latest circle, m ([`OBSTACLE_CENTRE_SIGMAS`]).
    reach_m: f32,
    /// Frames in the mean since it started, saturating.
    frames: u16,
    /// Circles beyond reach of the centre in a row.
    outliers: u8,
}

impl ObstacleMotion {
    /// Standing still, nothing measured.
    pub const STILL: Self = Self {
        east_mps: 0.0,
        north_mps: 0.0,
        origin: (0.0, 0.0),
        origin_us: 0,
        sums: [0.0; 8],
        last_us: 0,
        centre: (0.0, 0.0),
        reach_m: OBSTACLE_JUMP_M,
        frames: 0,
        outliers: 0,
    };

    /// Takes the slot's new circle `now` at `t_us`, `before` being what the slot held; returns
    /// what it holds now: the circle at the centre estimated from the circles so far, `None`
    /// for a cleared slot.
    #[inline(never)]
    fn observe(
        &mut self,
        before: Option<&ObstacleCircle>,
        now: Option<&ObstacleCircle>,
        t_us: u64,
    ) -> Option<ObstacleCircle> {
        // Microseconds since the last frame; a time that went back, or more than the silence,
        // as the silence and one more.
        let since_last = t_us
            .checked_sub(self.last_us)
            .filter(|d| *d <= OBSTACLE_SILENT_US)
            .map_or(OBSTACLE_SILENT_US as u32 + 1, |d| d as u32);
        // A frame after a silence or a cleared slot starts afresh; one farther from the last
        // than the object can have gone (a jump) starts the velocity afresh, and the centre too
        // if it is farther than any scatter the centre takes (another object in the slot);
        // nearer, it is one of the centre's outliers (a detector's scatter of 0.4 m puts one
        // circle in 200 more than 1.3 m from the centre, the jump a tick allows).
        let (fresh, jumped, far) = match (before, now) {
            (Some(b), Some(c)) if since_last <= OBSTACLE_SILENT_US as u32 => {
                let (de, dn) = (c.east_m - b.east_m, c.north_m - b.north_m);
                let d2 = de * de + dn * dn;
                let gate = OBSTACLE_MAX_MPS * since_last as f32 * 1e-6 + OBSTACLE_JUMP_M;
                let far = 2.0 * OBSTACLE_CENTRE_REACH_MAX_M;
                (false, d2 > gate * gate, d2 > far * far)
            }
            _ => (true, false, false),
        };
        if fresh || jumped {
            let centre = (self.centre, self.reach_m, self.frames, self.outliers);
            *self = Self::STILL;
            if !fresh {
                (self.centre, self.reach_m, self.frames, self.outliers) = centre;
            }
        }
        let c = now?;
        if self.sums[0] == 0.0 {
            self.origin = (c.east_m, c.north_m);
            self.origin_us = t_us;
        }
        self.last_us = t_us;
        // The centre: where the last one has gone at the measured velocity, then a running
        // mean of the circles about that. A circle beyond reach of it is not taken in, unless
        // [`OBSTACLE_CENTRE_OUTLIERS`] come in a row: then the object has moved otherwise, and
        // the mean starts afresh at the latest.
        let raw = (c.east_m, c.north_m);
        let dt = since_last as f32 * 1e-6;
        let went = (
            self.centre.0 + self.east_mps * dt,
            self.centre.1 + self.north_mps * dt,
        );
        let (de, dn) = (raw.0 - went.0, raw.1 - went.1);
        if de * de + dn * dn > self.reach_m * self.reach_m {
            self.outliers = self.outliers.saturating_add(1);
        } else {
            self.outliers = 0;
        }
        if fresh || far || self.outliers >= OBSTACLE_CENTRE_OUTLIERS {
            (self.centre, self.frames, self.outliers) = (raw, 1, 0);
        } else if self.outliers == 0 {
            self.frames = self.frames.saturating_add(1);
            let a = max(dt / OBSTACLE_CENTRE_TIME_S, 1.0 / f32::from(self.frames));
            self.centre = (went.0 + a * de, went.1 + a * dn);
        } else {
            self.centre = went;
        }
        let held = ObstacleCircle {
            east_m: self.centre.0,
            north_m: self.centre.1,
            ..*c
        };
        // Within a span: at most the silence per frame, and a span closes at its first frame
        // past OBSTACLE_VELOCITY_SPAN_US.
        let span_us = (t_us.saturating_sub(self.origin_us)).min(u64::from(u32::MAX)) as u32;
        let t = span_us as f32 * 1e-6;
        let (e, n) = (c.east_m - self.origin.0, c.north_m - self.origin.1);
        for (sum, term) in
            self.sums
                .iter_mut()
                .zip([1.0, t, t * t, e, n, t * e, t * n, e * e + n * n])
        {
            *sum += term;
        }
        if span_us < OBSTACLE_VELOCITY_SPAN_US as u32 {
            return Some(held);
        }
        let [k, st, stt, se, sn, ste, stn, sqq] = self.sums;
        let spread = k * stt - st * st;
        let (ve, vn) = ((k * ste - st * se) / spread, (k * stn - st * sn) / spread);
        // The residuals' sum of squares over both axes, k times over: k sum q^2 - (sum q)^2
        // less the fitted slope's share, spread v^2. The variance per axis of the residuals
        // is that / (2 k (k - 2)), and of each slope that times k / spread, so the test
        // v^2 >= c^2 var is v^2 spread (2 (k - 2)) >= c^2 rss.
        let speed2 = ve * ve + vn * vn;
        let rss = k * sqq - se * se - sn * sn - spread * speed2;
        let significant = speed2 * spread * (2.0 * (k - 2.0))
            >= OBSTACLE_MOTION_SIGMAS * OBSTACLE_MOTION_SIGMAS * rss;
        // Significance to set off; a moving object goes on moving above the still speed (so a
        // walk of 0.5 m/s under 0.1 m of scatter does not stop at every other span), and a
        // span that finds it below closes at once (it stopped).
        let was_moving = self.east_mps != 0.0 || self.north_mps != 0.0;
        // The scatter about the line, both axes: rss / (k (k - 2)); each slope's variance
        // that times k / spread.
        let scatter2 = max(rss, 0.0) / (k * (k - 2.0));
        let (de, dn) = (ve - self.east_mps, vn - self.north_mps);
        let same = was_moving
            && (de * de + dn * dn) * spread
                <= OBSTACLE_SAME_SIGMAS * OBSTACLE_SAME_SIGMAS * scatter2 * k;
        let (ve, vn) = if same {
            (0.5 * (ve + self.east_mps), 0.5 * (vn + self.north_mps))
        } else {
            (ve, vn)
        };
        let speed2 = ve * ve + vn * vn;
        let moving =
            speed2 >= OBSTACLE_STILL_MPS * OBSTACLE_STILL_MPS && (significant || was_moving);
        if !moving && !was_moving && span_us < OBSTACLE_VELOCITY_SPAN_MAX_US as u32 {
            return Some(held);
        }
        self.reach_m = min(
            max(
                OBSTACLE_CENTRE_SIGMAS * math::sqrt(scatter2),
                OBSTACLE_CENTRE_REACH_MIN_M,
            ),
            OBSTACLE_CENTRE_REACH_MAX_M,
        );
        (self.east_mps, self.north_mps) = if moving && spread > 0.0 {
            (ve, vn)
        } else {
            (0.0, 0.0)
        };
        // The next span starts with this frame.
        self.origin = (c.east_m, c.north_m);
        self.origin_us = t_us;
        self.sums = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        Some(held)
    }
}

/// A path being received. Always allocated (in place, in the node's static drive state), so
/// that starting or completing a path never moves its 5 KiB of waypoints through the stack.
#[derive(Clone, Debug)]
struct Assembly {
    /// A path is being received (the other fields mean nothing otherwise).
    active: bool,
    path_id: u8,
    count: usize,
    next_point: usize,
    next_limits: usize,
    waypoints: [Waypoint; MAX_PATH_POINTS],
}

/// Rolling-counter slots, one per planner message.
const MESSAGES: usize = PlannerMessage::KINDS;

/// The two halves of a waypoint, each arriving in index order.
#[derive(Clone, Copy)]
enum Stream {
    /// PATH_POINT: position.
    Points,
    /// PATH_LIMITS: target speed and corridor.
    Limits,
}

/// The node's view of the planner: active path, assembly, obstacles, origin pairing.
#[derive(Clone, Debug)]
pub struct PlannerInputs {
    path: Path,
    path_id: Option<u8>,
    assembly: Assembly,
    obstacles: [Option<ObstacleCircle>; OBSTACLE_SLOTS],
    /// Each slot's motion, measured from its circles.
    motion: [ObstacleMotion; OBSTACLE_SLOTS],
    /// Latitude page waiting for its longitude page: (lat_e7, counter).
    origin_latitude: Option<(i32, u8)>,
    counters: [CounterChecker; MESSAGES],
    stats: PlannerCounters,
    /// The car the paths are checked against ([`Path::validate_for`]); zero: geometry only.
    car: PathCar,
}

impl Default for PlannerInputs {
    fn default() -> Self {
        Self::new()
    }
}

impl PlannerInputs {
    /// Nothing received yet: no path, no obstacles.
    pub const fn new() -> Self {
        Self {
            path: Path::new(),
            path_id: None,
            assembly: Assembly {
                active: false,
                path_id: 0,
                count: 0,
                next_point: 0,
                next_limits: 0,
                waypoints: [Waypoint::ZERO; MAX_PATH_POINTS],
            },
            obstacles: [None; OBSTACLE_SLOTS],
            motion: [ObstacleMotion::STILL; OBSTACLE_SLOTS],
            origin_latitude: None,
            counters: [CounterChecker::new(); MESSAGES],
            stats: PlannerCounters {
                paths_activated: 0,
                paths_abandoned: 0,
                paths_invalid: 0,
                duplicates: 0,
                stray_frames: 0,
                stuck_counters: 0,
                counter_jumps: 0,
                origin_mismatches: 0,
            },
            car: PathCar { body_width_m: 0.0 },
        }
    }

    /// Writes [`PlannerInputs::new`] into `slot` in place (`crate::in_place`): the path and
    /// the assembly's waypoints are 15 KiB.
    ///
    /// # Safety
    ///
    /// `slot` must be valid for writes of a `PlannerInputs` and aligned for it.
    pub(crate) unsafe fn init_in_place(slot: *mut Self) {
        // SAFETY: every field of the `PlannerInputs` the caller vouches for (and of its
        // assembly), once each; the path by its own in-place constructor.
        unsafe {
            Path::init_in_place(addr_of_mut!((*slot).path));
            addr_of_mut!((*slot).path_id).write(None);
            let assembly = addr_of_mut!((*slot).assembly);
            addr_of_mut!((*assembly).active).write(false);
            addr_of_mut!((*assembly).path_id).write(0);
            addr_of_mut!((*assembly).count).write(0);
            addr_of_mut!((*assembly).next_point).write(0);
            addr_of_mut!((*assembly).next_limits).write(0);
            fill(addr_of_mut!((*assembly).waypoints), Waypoint::ZERO);
            addr_of_mut!((*slot).obstacles).write([None; OBSTACLE_SLOTS]);
            addr_of_mut!((*slot).motion).write([ObstacleMotion::STILL; OBSTACLE_SLOTS]);
            addr_of_mut!((*slot).origin_latitude).write(None);
            addr_of_mut!((*slot).counters).write([CounterChecker::new(); MESSAGES]);
            addr_of_mut!((*slot).stats).write(PlannerCounters::default());
            addr_of_mut!((*slot).car).write(PathCar::default());
        }
    }

    /// The active path, if one is complete.
    pub fn path(&self) -> Option<&Path> {
        (!self.path.is_empty()).then_some(&self.path)
    }

    /// The active path's id.
    pub const fn path_id(&self) -> Option<u8> {
        self.path_id
    }

    /// The id of the path being received, how many of its points and limits are in, and how
    /// many points its header announced.
    pub fn receiving(&self) -> Option<(u8, usize, usize, usize)> {
        let a = &self.assembly;
        a.active
            .then_some((a.path_id, a.next_point, a.next_limits, a.count))
    }

    /// The obstacle slots (`None` = cleared).
    pub const fn obstacles(&self) -> &[Option<ObstacleCircle>; OBSTACLE_SLOTS] {
        &self.obstacles
    }

    /// Each obstacle slot's motion ([`ObstacleMotion`]; standing still for a cleared slot).
    pub const fn obstacle_motion(&self) -> &[ObstacleMotion; OBSTACLE_SLOTS] {
        &self.motion
    }

    /// Counters since start.
    pub const fn counters(&self) -> &PlannerCounters {
        &self.stats
    }

    /// Forgets everything received (in place), counters included.
    pub fn reset(&mut self) {
        self.path.clear();
        self.path_id = None;
        self.assembly.active = false;
        self.obstacles = [None; OBSTACLE_SLOTS];
        self.motion = [ObstacleMotion::STILL; OBSTACLE_SLOTS];
        self.origin_latitude = None;
        self.counters = [CounterChecker::new(); MESSAGES];
        self.stats = PlannerCounters::default();
    }

    /// Sets the deceleration at which the active controller brakes for a lower target speed
    /// ahead: the paths' speed envelope ([`Path::set_braking`]); `false` if refused (not finite
    /// and positive).
    pub fn set_braking(&mut self, decel_mps2: f32) -> bool {
        self.path.set_braking(decel_mps2)
    }

    /// Sets the lateral acceleration to which the paths' speed envelope holds their turns
    /// ([`Path::set_lateral_limit`]); `false` if refused.
    pub fn set_lateral_limit(&mut self, limit: Option<LateralLimit>) -> bool {
        self.path.set_lateral_limit(limit)
    }

    /// Sets the car that every path completed from now on must fit ([`Path::validate_for`]:
    /// its body in the corridor).
    pub fn set_car(&mut self, car: PathCar) {
        self.car = car;
    }

    /// The car every completed path is checked against ([`PlannerInputs::set_car`]).
    pub const fn car(&self) -> &PathCar {
        &self.car
    }

    /// Forgets the active path (e.g. the local frame changed under it); the counters stay.
    pub fn drop_path(&mut self) {
        self.path.clear();
        self.path_id = None;
    }

    /// Applies one decoded planner message received at `t_us` (see the module doc for the
    /// rules).
    pub fn receive(&mut self, message: &PlannerMessage, t_us: u64) -> PlannerEvent {
        let (slot, counter) = message.counter();
        if let Some(checker) = self.counters.get_mut(slot) {
            let verdict = checker.check(counter);
            if !verdict.accepted() {
                bump(&mut self.stats.stuck_counters);
                return PlannerEvent::None;
            }
            if verdict.is_error() {
                bump(&mut self.stats.counter_jumps);
            }
        }
        match *message {
            PlannerMessage::PathHeader(h, _) => {
                if self.assembly.active {
                    bump(&mut self.stats.paths_abandoned);
                }
                self.start_assembly(h.path_id, usize::from(h.count));
                PlannerEvent::None
            }
            PlannerMessage::PathPoint(p, _) => {
                self.store(p.path_id, usize::from(p.index), Stream::Points, |w| {
                    w.east_m = p.east_m;
                    w.north_m = p.north_m;
                })
            }
            PlannerMessage::PathLimits(l, _) => {
                self.store(l.path_id, usize::from(l.index), Stream::Limits, |w| {
                    w.speed_mps = l.speed_mps;
                    w.left_m = l.left_m;
                    w.right_m = l.right_m;
                })
            }
            PlannerMessage::Obstacle(o, _) => {
                let id = usize::from(o.obstacle_id);
                if let (Some(slot), Some(motion)) =
                    (self.obstacles.get_mut(id), self.motion.get_mut(id))
                {
                    *slot = motion.observe(slot.as_ref(), o.circle.as_ref(), t_us);
                }
                PlannerEvent::None
            }
            PlannerMessage::LocalOrigin(page, c) => self.origin_page(page, c),
        }
    }

    fn start_assembly(&mut self, path_id: u8, count: usize) {
        let a = &mut self.assembly;
        a.active = true;
        a.path_id = path_id;
        a.count = count.min(MAX_PATH_POINTS);
        a.next_point = 0;
        a.next_limits = 0;
    }

    /// Stores one half of waypoint `index` (`fill` writes it) if it is the next one expected
    /// on its stream of the path being assembled; completes the path after its last half.
    fn store(
        &mut self,
        path_id: u8,
        index: usize,
        stream: Stream,
        fill: impl FnOnce(&mut Waypoint),
    ) -> PlannerEvent {
        let a = &mut self.assembly;
        if !a.active || a.path_id != path_id {
            bump(&mut self.stats.stray_frames);
            return PlannerEvent::None;
        }
        let expected = match stream {
            Stream::Points => &mut a.next_point,
            Stream::Limits => &mut a.next_limits,
        };
        if index < *expected {
            bump(&mut self.stats.duplicates);
            return PlannerEvent::None;
        }
        if index > *expected || index >= a.count {
            // A lost frame (or an index beyond the count): this path can never complete.
            a.active = false;
            bump(&mut self.stats.paths_abandoned);
            return PlannerEvent::None;
        }
        *expected += 1;
        if let Some(w) = a.waypoints.get_mut(index) {
            fill(w);
        }
        if a.next_point == a.count && a.next_limits == a.count {
            return self.complete();
        }
        PlannerEvent::None
    }

    fn complete(&mut self) -> PlannerEvent {
        let a = &mut self.assembly;
        if !a.active {
            return PlannerEvent::None;
        }
        a.active = false;
        let waypoints = a.waypoints.get(..a.count).unwrap_or(&[]);
        match self.path.load_for(waypoints, &self.car) {
            Ok(()) => {
                self.path_id = Some(a.path_id);
                bump(&mut self.stats.paths_activated);
                PlannerEvent::PathActivated(a.path_id)
            }
            Err(e) => {
                bump(&mut self.stats.paths_invalid);
                PlannerEvent::PathInvalid(a.path_id, e)
            }
        }
    }

    fn origin_page(&mut self, page: LocalOrigin, counter: u8) -> PlannerEvent {
        match page {
            LocalOrigin::Latitude { lat_e7 } => {
                self.origin_latitude = Some((lat_e7, counter));
                PlannerEvent::None
            }
            LocalOrigin::Longitude { lon_e7 } => match self.origin_latitude.take() {
                Some((lat_e7, c)) if (c + 1) & 0x0F == counter & 0x0F => {
                    PlannerEvent::Origin { lat_e7, lon_e7 }
                }
                _ => {
                    bump(&mut self.stats.origin_mismatches);
                    PlannerEvent::None
                }
            },
        }
    }
}
