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

use super::path::{Path, PathCar, PathError, Waypoint, MAX_PATH_POINTS};

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
/// A slot silent for longer starts its motion afresh, us.
pub const OBSTACLE_SILENT_US: u64 = 2_000_000;
/// Slower is taken as standing still, m/s: a standing object whose detection moves its circle
/// by centimetres from frame to frame does not move.
pub const OBSTACLE_STILL_MPS: f32 = 0.3;
/// Faster than this between two frames (plus [`OBSTACLE_JUMP_M`]) is another object in the
/// slot, not a motion, m/s.
pub const OBSTACLE_MAX_MPS: f32 = 40.0;
/// See [`OBSTACLE_MAX_MPS`], m.
pub const OBSTACLE_JUMP_M: f32 = 0.5;

/// An obstacle slot's motion, measured from its circles: the slope of a least-squares line
/// through the centres of a span of frames at least [`OBSTACLE_VELOCITY_SPAN_US`] long, held
/// until the next span ends. Zero (the obstacle stands) for a slot sent once, after a jump or
/// [`OBSTACLE_SILENT_US`] of silence (until a span of frames after it), and below
/// [`OBSTACLE_STILL_MPS`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ObstacleMotion {
    /// Velocity east, m/s.
    pub east_mps: f32,
    /// Velocity north, m/s.
    pub north_mps: f32,
    /// The span being measured: its first frame's centre and time (us), and the sums of the
    /// fit over its frames, in s and m from that first frame: count, t, t^2, east, north,
    /// t east, t north.
    origin: (f32, f32),
    origin_us: u64,
    sums: [f32; 7],
    /// The latest frame's time, us.
    last_us: u64,
}

impl ObstacleMotion {
    /// Standing still, nothing measured.
    pub const STILL: Self = Self {
        east_mps: 0.0,
        north_mps: 0.0,
        origin: (0.0, 0.0),
        origin_us: 0,
        sums: [0.0; 7],
        last_us: 0,
    };

    /// Takes the slot's new circle `now` at `t_us`, `before` being what the slot held.
    #[inline(never)]
    fn observe(
        &mut self,
        before: Option<&ObstacleCircle>,
        now: Option<&ObstacleCircle>,
        t_us: u64,
    ) {
        // Microseconds since the last frame; a time that went back, or more than the silence,
        // as the silence and one more.
        let since_last = t_us
            .checked_sub(self.last_us)
            .filter(|d| *d <= OBSTACLE_SILENT_US)
            .map_or(OBSTACLE_SILENT_US as u32 + 1, |d| d as u32);
        let continues = match (before, now) {
            (Some(b), Some(c)) => {
                let (de, dn) = (c.east_m - b.east_m, c.north_m - b.north_m);
                let reach = OBSTACLE_MAX_MPS * since_last as f32 * 1e-6 + OBSTACLE_JUMP_M;
                since_last <= OBSTACLE_SILENT_US as u32 && de * de + dn * dn <= reach * reach
            }
            _ => false,
        };
        if !continues {
            *self = Self::STILL;
        }
        let Some(c) = now else { return };
        if self.sums[0] == 0.0 {
            self.origin = (c.east_m, c.north_m);
            self.origin_us = t_us;
        }
        self.last_us = t_us;
        // Within a span: at most the silence per frame, and a span closes at its first frame
        // past OBSTACLE_VELOCITY_SPAN_US.
        let span_us = (t_us.saturating_sub(self.origin_us)).min(u64::from(u32::MAX)) as u32;
        let t = span_us as f32 * 1e-6;
        let (e, n) = (c.east_m - self.origin.0, c.north_m - self.origin.1);
        for (sum, term) in self
            .sums
            .iter_mut()
            .zip([1.0, t, t * t, e, n, t * e, t * n])
        {
            *sum += term;
        }
        if span_us < OBSTACLE_VELOCITY_SPAN_US as u32 {
            return;
        }
        let [k, st, stt, se, sn, ste, stn] = self.sums;
        let spread = k * stt - st * st;
        let (ve, vn) = ((k * ste - st * se) / spread, (k * stn - st * sn) / spread);
        let moving = ve * ve + vn * vn >= OBSTACLE_STILL_MPS * OBSTACLE_STILL_MPS;
        (self.east_mps, self.north_mps) = if moving && spread > 0.0 {
            (ve, vn)
        } else {
            (0.0, 0.0)
        };
        // The next span starts with this frame.
        self.origin = (c.east_m, c.north_m);
        self.origin_us = t_us;
        self.sums = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
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

    /// The id of the path being received, and how many of its points and limits are in.
    pub fn receiving(&self) -> Option<(u8, usize, usize)> {
        let a = &self.assembly;
        a.active.then_some((a.path_id, a.next_point, a.next_limits))
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
                    motion.observe(slot.as_ref(), o.circle.as_ref(), t_us);
                    *slot = o.circle;
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
