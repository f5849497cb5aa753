//! A planned path in fixed-capacity storage, and its geometry: the rear axle's projection onto
//! it (station, lateral and heading error), and the reference (pose, curvature, target speed,
//! corridor) at any station, which is what a controller tracks.
//!
//! The path is a polyline of up to [`MAX_PATH_POINTS`] points in the node's local frame (east,
//! north, m), each with a target speed and a corridor (how far the body may stray to the left
//! and to the right). Conventions, as everywhere in catmodel: heading clockwise from north,
//! curvature and lateral offsets positive to the right.
//!
//! The reference is continuous where a polyline is not, and insensitive to the bus's 0.02 m
//! quantisation of the points: the reference heading at point `i` is the direction of the chord
//! from point `i - k` to point `i + k`, with `k` the fewest points that span twice
//! [`REFERENCE_BASELINE_M`], and the curvature there the change of that heading between those
//! two points divided by the distance between them; between points both are linear in station. With the heading of single segments, a
//! dense path (a planner's 0.5 m spacing) carries up to 0.04 rad of heading and 0.08 1/m of
//! curvature noise from the quantisation alone (a 6 deg steering feedforward at 10 m/s), which
//! a tracking controller follows. Rounded to 0.02 m, a point lies at most 0.014 m off across
//! the path, so a chord of at least 2 m turns by at most 0.014 rad, and the curvature, a
//! heading difference over at least 2 m, is off by at most 0.014 1/m
//! (host-tests `reference_is_insensitive_to_the_bus_quantisation`). On
//! points of a circle of radius R, `c` metres apart (chords), the chord's direction is the
//! tangent's at the middle point and the curvature `2 asin(c / 2R) / c`, within a relative
//! `c^2 / 24 R^2` of `1 / R` (0.13 % at c = 1 m on the car's tightest circle, R = 5.6 m),
//! except within two baselines of the path's ends, where the chord is one-sided. Elsewhere the
//! curvature is the mean over about 4 m of path, which rounds a curvature step (a clothoid's
//! start) over that length.
//!
//! The target speed at a station is the points' target speeds, linear between points, and no
//! more than lets the car slow to every later point's target, and to a stop at the path's end,
//! at the path's braking deceleration ([`Path::set_braking`]: the controller's): a planner's
//! speed is a limit to meet *at* its point, and a controller that looks only as far ahead as its
//! horizon meets a drop beyond it too late (a 20 -> 5 m/s step 300 m down a straight was
//! entered at 13 m/s, and a path's end at 20 m/s passed by 17 m on a car that brakes at
//! 3.5 m/s^2; docs/findings.md). The envelope is taken once, when the path is loaded: per point,
//! the most speed squared that still meets every later target, `R_i = min(v_i^2, R_{i+1} +
//! 2 a (s_{i+1} - s_i))` with `R = 0` at the last point (relative to the point, so that no
//! cancellation of kilometres of station enters it); between points `sqrt(R_{i+1} + 2 a
//! (s_{i+1} - s))`.
//!
//! A car's tyres give it a lateral acceleration of at most about its friction coefficient times
//! g, and a planner's speeds may ask for more: the loop's 20 m arcs at 14 m/s ask 9.8 m/s^2,
//! past the CAT Vehicle's grip, and every car of the closed-loop rig spun off them
//! (docs/controller.md, "A turn faster than the tyres"). With a lateral limit `a`
//! ([`Path::set_lateral_limit`], the model file's `[control] max_lateral_accel_mps2`), each
//! point's own limit is also the speed at which its turns ask no more than `a`: over each
//! window of [`TURN_WINDOWS_M`] ahead of the point and behind it, the path turns by `phi`
//! over `L` metres, and a car that cuts that turn from the corridor's outer edge to its inner
//! and out again (the room `w` is the corridor's width less the body's, the least of the
//! window's ends and the point) drives it on a radius of `L / phi + w / (1 - cos(phi / 2))`
//! (the racing line's through a corner of constant radius); the limit is `a` times that
//! radius. Each whole turn (a run of one sign of curvature, over its core) is one window too:
//! the racing line drives it at one radius, and a window inside a longer turn credits that
//! part of it with the whole room's cut ([`Path::set_lateral_limit`]'s `whole_turn_limits`).
//! The windows measure a sustained turn, not the path's line: the lane change's
//! quintic transitions swing the heading back within metres, and the corridor lets the car
//! cut them (at 16 m/s there they ask less than the CAT Vehicle's limit).
//!
//! Never allocates, never panics; every loop runs at most [`MAX_PATH_POINTS`] times.
use core::ptr::addr_of_mut;

use crate::in_place::fill;
use crate::math;
use crate::model::kinematic::Pose;

/// Most points of a path: the bus carries an 8-bit point index (docs/bus.md).
pub const MAX_PATH_POINTS: usize = crate::can::spec::MAX_PATH_POINTS;
/// Half the chord the reference heading at a point is measured over, m (see the module doc).
pub const REFERENCE_BASELINE_M: f32 = 1.0;
/// Consecutive points at least this far apart, m, as the node decodes them (PATH_POINT's
/// coordinates are multiples of 0.02 m): the heading of a shorter segment is dominated by the
/// 0.02 m quantisation of the bus (0.02 m over 0.05 m is 0.4 rad). A limit on the decoded
/// points, not relaxed by the rounding: the reference chord's bound (2 m / this = 40 points)
/// and the projection's windows rest on it. A planner spaces its points
/// [`MIN_PLANNED_SPACING_M`] apart before encoding them.
pub const MIN_SEGMENT_M: f32 = 0.05;
/// Least spacing of a planner's points before PATH_POINT rounds them, m, that keeps them
/// [`MIN_SEGMENT_M`] apart once decoded at any heading: each coordinate moves by up to half
/// the 0.02 m step, so a segment by up to 0.02 m per axis, 0.0283 m in length (along a
/// diagonal); 0.05 + 0.0283, rounded up to the bus's step. At exactly 0.05 m a straight path
/// decodes to segments of 0.04 and 0.06 m and is refused (docs/findings.md).
pub const MIN_PLANNED_SPACING_M: f32 = 0.08;
/// Consecutive points at most this far apart, m: a longer gap is a lost or corrupt point, not a
/// plan (a planner samples curves far more densely).
pub const MAX_SEGMENT_M: f32 = 50.0;
/// Largest heading change at one point, rad (60 deg): a sharper corner is not a path a car can
/// follow (and reverses are not planned).
pub const MAX_TURN_RAD: f32 = core::f32::consts::FRAC_PI_3;
/// How far ahead of the previous station a projection looks for the nearest segment, m: one
/// 20 ms tick at 40 m/s is 0.8 m, and the node propagates at most 0.1 s at a time (4 m).
pub const PROJECTION_AHEAD_M: f32 = 10.0;
/// How far behind the previous station a projection looks, m (noise moves the estimate back).
pub const PROJECTION_BEHIND_M: f32 = 3.0;
/// A windowed projection farther than this from the path falls back to a search of the whole
/// path, m (the car was moved, or the path changed under it).
pub const PROJECTION_RESEARCH_M: f32 = 5.0;
/// How much nearer than the path's first [`PROJECTION_AHEAD_M`] the rest of the path must be
/// for a car without a projection to be placed on it, m (see `Path::acquire`): the CAT
/// Vehicle's receiver error, 1.2 m RMS horizontal (paper, II-A), so that a car at the start of
/// a closed loop is at its start whatever its first fix.
pub const ACQUIRE_TIE_M: f32 = 1.2;
/// Relative margin by which a segment's corner must be nearer (in squared distance) than a
/// foot on another segment to be taken (see `Path::nearest_in`): five times what the rounding
/// of 0.3 m segments' headings 1 km from the origin can make of a tie.
const VERTEX_TIE: f32 = 2e-3;
/// The braking deceleration of a path's speed envelope until a controller sets its own
/// ([`Path::set_braking`]), m/s^2: the model-predictive controller's (`SpeedTuning::decel_mps2`).
pub const DEFAULT_BRAKING_MPS2: f32 = 3.0;

/// Lengths of path over which [`Path::set_lateral_limit`]'s envelope measures a turn, m, ahead
/// of each point and behind it: a turn is cut through the corridor over its own length, which
/// one of these spans within a factor of two (from a bend of a few metres to a long arc).
pub const TURN_WINDOWS_M: [f32; 6] = [4.0, 8.0, 16.0, 32.0, 64.0, 128.0];

/// The speed squared at which a car drives a turn of `turn_rad` (either sign) over `length_m`
/// of path at the lateral acceleration `accel_mps2`, cut from the corridor's outer edge to its
/// inner and out again with the room `room_m` (none if negative): `accel` times
/// `length / turn + room / (1 - cos(turn / 2))`, the cut growing no further past half a turn
/// ([`Path::set_lateral_limit`]); infinite for no turn or no length. `1 - cos(x)` by its series
/// to `x^8` (on `[0, pi/2]` within 3e-5 of it, relative): + - * / only.
fn cut_turn_m2ps2(accel_mps2: f32, turn_rad: f32, length_m: f32, room_m: f32) -> f32 {
    let turn = if turn_rad < 0.0 { -turn_rad } else { turn_rad };
    let x = math::min(turn, core::f32::consts::PI) * 0.5;
    let x2 = x * x;
    let g = x2 * (0.5 - x2 * (1.0 / 24.0 - x2 * (1.0 / 720.0 - x2 * (1.0 / 40320.0))));
    if !(g > 0.0 && length_m > 0.0) {
        // No turn (or one too small for f32 to square), or no length.
        return f32::INFINITY;
    }
    accel_mps2 * (length_m / turn + math::max(room_m, 0.0) / g)
}

/// Least curvature of a whole turn's points ([`Path::set_lateral_limit`]), 1/m (either sign): a
/// radius of 1 km; straighter points end a turn. A run of the reference curvature's noise on a
/// straight is a turn of next to nothing, whose limit is far above any speed.
pub const TURN_RUN_CURVATURE_PER_M: f32 = 1e-3;

/// A path of at most this many points is not held to [`Path::set_lateral_limit`]'s limit: its
/// completion shares a tick with a solve (`catmodel::node::stage::SHORT_PATH_POINTS`, which is
/// not more than this), and the windows' cost there measured up to 7 600 instructions a path
/// on a random model file's drives, three paths to a tick. Its targets and the stop at its end
/// still hold (a planner describes a turn with more points than five).
pub const TURN_FEW_POINTS: usize = 5;

/// The lateral acceleration a path's speed envelope holds its turns to
/// ([`Path::set_lateral_limit`]).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LateralLimit {
    /// The car's lateral acceleration at most, m/s^2.
    pub accel_mps2: f32,
    /// The body's width, m: the corridor's room to cut a turn is its width less this.
    pub width_m: f32,
}

/// One point of a path as the planner sends it: PATH_POINT and PATH_LIMITS of one index.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Waypoint {
    /// Rear-axle position east of the local origin, m.
    pub east_m: f32,
    /// North of the local origin, m.
    pub north_m: f32,
    /// Target speed there, m/s.
    pub speed_mps: f32,
    /// How far the body may stray left of the point, m.
    pub left_m: f32,
    /// How far the body may stray right of the point, m.
    pub right_m: f32,
}

impl Waypoint {
    /// All zero: the contents of a point buffer before it is filled.
    pub const ZERO: Self = Self {
        east_m: 0.0,
        north_m: 0.0,
        speed_mps: 0.0,
        left_m: 0.0,
        right_m: 0.0,
    };
}

/// Why a set of waypoints is not a path.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PathError {
    /// Fewer than 2 or more than [`MAX_PATH_POINTS`] points.
    PointCount,
    /// A value is not finite, or a speed or corridor is negative (index of the point).
    BadValue(u16),
    /// Segment `index` -> `index + 1` is shorter than [`MIN_SEGMENT_M`] or longer than
    /// [`MAX_SEGMENT_M`].
    SegmentLength(u16),
    /// The heading changes by more than [`MAX_TURN_RAD`] at point `index`.
    Turn(u16),
    /// The corridor at point `index` (`left_m + right_m`) is narrower than the car's body
    /// ([`PathCar::body_width_m`], less [`CORRIDOR_TOLERANCE_M`]): no body fits in it.
    Corridor(u16),
}

/// What [`Path::validate_for`] checks a path against: the car that is to drive it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PathCar {
    /// The body's overall width, m (0: no corridor check).
    pub body_width_m: f32,
}

/// A corridor this much narrower than the body is still taken, m: PATH_LIMITS carries each
/// side to 0.01 m, so a corridor planned exactly the body's width decodes up to 0.01 m under it.
pub const CORRIDOR_TOLERANCE_M: f32 = 0.01;

/// The reference at one station.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PathSample {
    /// Station (distance along the path from its first point), m; before the path clamped to
    /// its start, beyond its end on the last segment's extension.
    pub station_m: f32,
    /// Reference position east, m.
    pub east_m: f32,
    /// Reference position north, m.
    pub north_m: f32,
    /// Reference heading, clockwise from north, rad, in [-pi, pi).
    pub heading_rad: f32,
    /// Curvature, 1/m, positive = turning right.
    pub curvature_per_m: f32,
    /// Target speed, m/s: the points' (linear between them), within the path's speed envelope
    /// (see the module doc); 0 beyond the last point: the path ends there.
    pub speed_mps: f32,
    /// Corridor to the left, m.
    pub left_m: f32,
    /// Corridor to the right, m.
    pub right_m: f32,
}

/// Corridor widths this close are one width in [`Path::narrowest_corridor`], m.
pub const NARROWEST_TIE_M: f32 = 0.01;

/// Points per block of the corridor's block minima ([`Path::narrowest_corridor`]): a search
/// over any stretch of the path reads at most two partial blocks point by point and the
/// blocks between whole, so its cost does not grow with the body's length or the points'
/// density beyond `2 * CORRIDOR_BLOCK + MAX_PATH_POINTS / CORRIDOR_BLOCK` reads.
const CORRIDOR_BLOCK: usize = 8;
/// Blocks of [`CORRIDOR_BLOCK`] points a path of [`MAX_PATH_POINTS`] has.
const CORRIDOR_BLOCKS: usize = MAX_PATH_POINTS.div_ceil(CORRIDOR_BLOCK);
/// Words of one bit per point ([`Path::in_held_turn`]).
const HELD_WORDS: usize = MAX_PATH_POINTS.div_ceil(32);

/// Where the corridor binds a body's side ([`Path::narrowest_corridor`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Narrowest {
    /// The narrowest corridor to the left, m.
    pub left_m: f32,
    /// Where it is, station, m.
    pub left_station_m: f32,
    /// The narrowest corridor to the right, m.
    pub right_m: f32,
    /// Where it is, station, m.
    pub right_station_m: f32,
}

/// [`Path::narrowest_corridor_located`]'s answer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NarrowestLocated {
    /// Where the corridor binds.
    pub narrowest: Narrowest,
    /// The segment `narrowest.left_station_m` is on (the first or last for a station beyond
    /// the path's ends).
    pub left_segment: usize,
    /// The segment `narrowest.right_station_m` is on.
    pub right_segment: usize,
    /// The segment the stretch's far end (`to_m`) is on.
    pub to_segment: usize,
}

/// A nearest point found by `Path::nearest_split`: its projection, its squared distance and
/// whether it is a segment's end point rather than a foot on it.
type Nearest = (Projection, f32, bool);

/// The nearest segment so far of a search (`Path::scan_segments`).
#[derive(Clone, Copy)]
struct Best {
    /// The segment (`usize::MAX`: none yet).
    segment: usize,
    /// Squared distance to it, m^2 (`+inf`: none yet).
    d2: f32,
    /// What the search minimises ([`Best::key`]).
    key: f32,
    /// Whether the foot is clamped to one of its end points.
    clamped: bool,
    /// Along the segment from its start, m.
    along: f32,
    /// To the right of its line, m.
    lateral: f32,
}

impl Best {
    /// None yet: any finite distance beats it.
    const NONE: Self = Self {
        segment: usize::MAX,
        d2: f32::INFINITY,
        key: f32::INFINITY,
        clamped: true,
        along: 0.0,
        lateral: 0.0,
    };

    /// The squared distance, a corner's [`VERTEX_TIE`] farther. Near a point of a nearly
    /// straight stretch, the foot on the next segment and the corner of the previous one are
    /// equally near but for the rounding of the two segments' headings (1 km from the origin
    /// f32 points are 6e-5 m apart: 2e-4 rad for a 0.3 m segment, which moves a squared
    /// distance by up to 4e-4 of itself): the foot, the true nearest point there, wins such a
    /// tie.
    fn key(d2: f32, clamped: bool) -> f32 {
        if clamped {
            d2 * (1.0 + VERTEX_TIE)
        } else {
            d2
        }
    }
}

/// A point against a segment ([`foot`]).
#[derive(Clone, Copy)]
struct Foot {
    /// How far along the segment the point's foot is, m.
    along: f32,
    /// How far right of the segment's line the point is, m.
    lateral: f32,
    /// How far the foot lies beyond the segment's ends, m (0 on it).
    off: f32,
    /// The squared distance to the segment, m^2.
    d2: f32,
}

/// Point `(east, north)` against the segment from `a` along `(sin, cos)` of its heading,
/// `length` long.
#[inline(always)]
fn foot(
    a: &Waypoint,
    (sin_h, cos_h): (f32, f32),
    length: f32,
    (east_m, north_m): (f32, f32),
) -> Foot {
    let (px, py) = (east_m - a.east_m, north_m - a.north_m);
    // Along the segment (unit vector (sin h, cos h)) and to its right ((cos h, -sin h)).
    let along = px * sin_h + py * cos_h;
    let lateral = px * cos_h - py * sin_h;
    let off = along - math::clamp(along, 0.0, length);
    Foot {
        along,
        lateral,
        off,
        d2: off * off + lateral * lateral,
    }
}

/// Whether the foot `along` segment `i` (of a path whose last is `last`) is clamped to one of
/// its end points. The end segments extend beyond the path's ends for the station and offset,
/// but the distance is to the segment itself, the end point: the extension is a ray without
/// end, and a path whose end points back at its start (a loop) must not take a car at the
/// start for one far beyond the end. The foot is clamped to an end point, then, everywhere but
/// there.
#[inline(always)]
fn clamped(along: f32, length: f32, i: usize, last: usize) -> bool {
    (along < 0.0 && i != 0) || (along > length && i != last)
}

/// Where a point is relative to the path.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Projection {
    /// The segment the point projects onto (index of its first point).
    pub segment: usize,
    /// Station of the foot of the perpendicular, m: below 0 before the first point, above the
    /// length beyond the last (the end segments extend straight).
    pub station_m: f32,
    /// Signed distance from the path, m, positive = the point is to the right of the path.
    pub lateral_m: f32,
}

/// A car's pose relative to the path: what a tracking controller needs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tracking {
    /// Where the rear axle projects.
    pub projection: Projection,
    /// Car heading minus reference heading, rad, in [-pi, pi), positive = turned right of it.
    pub heading_error_rad: f32,
    /// The reference at the projection's station.
    pub reference: PathSample,
    /// The car had a projection, was farther than [`PROJECTION_RESEARCH_M`] from every point
    /// of its window, and the rest of the path, searched after the window, has a nearer point:
    /// the car is on another part of the path (its position jumped, or was reset elsewhere
    /// after a long gap). False for a car placed on the path afresh (`Path::acquire`) and for
    /// one whose nearest point is still in its window (past the path's end, or beside it).
    pub left_window: bool,
    /// How far the rear axle projects past the path's last point, m (0 or less: not past it).
    pub past_end_m: f32,
}

/// A car turned further than this from the path's direction is driving against it, rad.
pub const LOST_HEADING_RAD: f32 = core::f32::consts::FRAC_PI_2;

impl Tracking {
    /// How far the rear axle is outside the corridor at its projection, m (0 inside).
    pub fn outside_corridor_m(&self) -> f32 {
        let lateral = self.projection.lateral_m;
        math::max(
            math::max(
                lateral - self.reference.right_m,
                -lateral - self.reference.left_m,
            ),
            0.0,
        )
    }

    /// Whether the car has lost the path, for a body `body_width_m` wide: its rear axle more
    /// than a body width outside the corridor (the body, however it is turned, cannot reach
    /// back into it without a new plan: the planner's to make), or more than a body width past
    /// the path's last point (the corridor ends there; the stop at the end overshoots by a
    /// metre or so, docs/controller.md), or the car turned more than [`LOST_HEADING_RAD`] from
    /// the path (driving against it). A controller falls back (status 3, braking) rather than
    /// steer back on its own: a car beside its corridor, beyond its end or facing the wrong
    /// way has left what the planner checked. (A black-box probe's path that lay behind the
    /// car, on its line, was reported "tracking" while the car stopped 46 m past its end.) A
    /// non-finite input counts as lost.
    pub fn has_lost_path(&self, body_width_m: f32) -> bool {
        let outside = self.outside_corridor_m();
        let heading = self.heading_error_rad;
        !(outside <= body_width_m
            && self.past_end_m <= body_width_m
            && heading.abs() <= LOST_HEADING_RAD)
    }
}

/// A path: up to [`MAX_PATH_POINTS`] waypoints with their stations, segment headings and the
/// reference heading and curvature at each point. 9 f32 per point: 9 KiB at 256 points.
#[derive(Clone, Debug)]
pub struct Path {
    len: usize,
    points: [Waypoint; MAX_PATH_POINTS],
    /// Distance along the path from point 0 to point `i`, m.
    station_m: [f32; MAX_PATH_POINTS],
    /// Sine and cosine of the heading of segment `i` (point `i` to `i + 1`), computed once at
    /// load (every projection and sample uses them: a search of the whole path would otherwise
    /// take a sine and cosine per segment); the last entry repeats the last segment's.
    direction: [(f32, f32); MAX_PATH_POINTS],
    /// Reference heading at point `i` (see the module doc), rad.
    reference_heading_rad: [f32; MAX_PATH_POINTS],
    /// Reference curvature at point `i`, 1/m, positive turning right.
    curvature_per_m: [f32; MAX_PATH_POINTS],
    /// The largest of `curvature_per_m`'s magnitudes, 1/m: taken once at load, not per query.
    max_curvature_per_m: f32,
    /// Deceleration of the speed envelope, m/s^2 ([`Path::set_braking`]).
    braking_mps2: f32,
    /// The lateral acceleration the speed envelope holds the path's turns to, m/s^2, and the
    /// body's width, m ([`Path::set_lateral_limit`]); `None`: no such limit.
    lateral_limit: Option<LateralLimit>,
    /// The speed envelope at point `i`: the most speed squared that still meets every later
    /// point's target and stops at the end at `braking_mps2`, m^2/s^2 (see the module doc).
    reach_m2ps2: [f32; MAX_PATH_POINTS],
    /// Bit `i % 32` of word `i / 32`: point `i`'s own limit is a turn's, below its target
    /// ([`Path::in_held_turn`]).
    held: [u32; HELD_WORDS],
    /// Bit `i % 32` of word `i / 32`: point `i` is a stop, a target of 0 after one with a
    /// speed ([`Path::stop_ahead_m`]), marked at load.
    stops: [u32; HELD_WORDS],
    /// The narrowest corridor `(left, right)` over each block of [`CORRIDOR_BLOCK`] points,
    /// m, taken at load.
    corridor_block_min_m: [(f32, f32); CORRIDOR_BLOCKS],
}

impl Default for Path {
    fn default() -> Self {
        Self::new()
    }
}

impl Path {
    /// An empty path (no points: every query returns `None`).
    pub const fn new() -> Self {
        Self {
            len: 0,
            points: [Waypoint::ZERO; MAX_PATH_POINTS],
            station_m: [0.0; MAX_PATH_POINTS],
            direction: [(0.0, 1.0); MAX_PATH_POINTS],
            reference_heading_rad: [0.0; MAX_PATH_POINTS],
            curvature_per_m: [0.0; MAX_PATH_POINTS],
            max_curvature_per_m: 0.0,
            braking_mps2: DEFAULT_BRAKING_MPS2,
            lateral_limit: None,
            reach_m2ps2: [0.0; MAX_PATH_POINTS],
            held: [0; HELD_WORDS],
            stops: [0; HELD_WORDS],
            corridor_block_min_m: [(0.0, 0.0); CORRIDOR_BLOCKS],
        }
    }

    /// Writes [`Path::new`] into `slot` in place (`crate::in_place`).
    ///
    /// # Safety
    ///
    /// `slot` must be valid for writes of a `Path` and aligned for it.
    pub(crate) unsafe fn init_in_place(slot: *mut Self) {
        // SAFETY: every field of the `Path` the caller vouches for, once each.
        unsafe {
            addr_of_mut!((*slot).len).write(0);
            fill(addr_of_mut!((*slot).points), Waypoint::ZERO);
            fill(addr_of_mut!((*slot).station_m), 0.0);
            fill(addr_of_mut!((*slot).direction), (0.0, 1.0));
            fill(addr_of_mut!((*slot).reference_heading_rad), 0.0);
            fill(addr_of_mut!((*slot).curvature_per_m), 0.0);
            addr_of_mut!((*slot).max_curvature_per_m).write(0.0);
            addr_of_mut!((*slot).braking_mps2).write(DEFAULT_BRAKING_MPS2);
            addr_of_mut!((*slot).lateral_limit).write(None);
            fill(addr_of_mut!((*slot).reach_m2ps2), 0.0);
            fill(addr_of_mut!((*slot).held), 0);
            fill(addr_of_mut!((*slot).stops), 0);
            fill(addr_of_mut!((*slot).corridor_block_min_m), (0.0, 0.0));
        }
    }

    /// Sets the deceleration of the speed envelope (see the module doc), m/s^2: the one at
    /// which the controller brakes for a lower target ahead. Kept for every later path; the
    /// path loaded now (if any) is enveloped again. Not finite and positive: refused, `false`.
    pub fn set_braking(&mut self, decel_mps2: f32) -> bool {
        if !(decel_mps2.is_finite() && decel_mps2 > 0.0) {
            return false;
        }
        self.braking_mps2 = decel_mps2;
        self.speed_envelope();
        true
    }

    /// The deceleration of the speed envelope, m/s^2.
    pub const fn braking_mps2(&self) -> f32 {
        self.braking_mps2
    }

    /// Whether segment `segment` is in a turn that [`Path::set_lateral_limit`]'s limit holds
    /// the speed in: the own limit of either of its points is a turn's, below the point's
    /// target. A controller does not speed up there: a car at its lateral limit has no grip
    /// left to accelerate with (its tyres' friction circle), and the limit of the turn's last
    /// point is the one it may leave the turn at. `false` without a limit or past the end.
    pub fn in_held_turn(&self, segment: usize) -> bool {
        let bit = |k: usize| {
            k < self.len
                && self
                    .held
                    .get(k / 32)
                    .is_some_and(|word| word & (1 << (k % 32)) != 0)
        };
        bit(segment) || bit(segment.saturating_add(1))
    }

    /// Sets the lateral acceleration to which the speed envelope holds the path's turns (see
    /// the module doc), m/s^2, for a body `width_m` wide; `None` lifts the limit. Kept for every
    /// later path; the path loaded now (if any) is enveloped again. A limit or width that is
    /// not finite and positive is refused, `false`, and the limit stays as it was.
    pub fn set_lateral_limit(&mut self, limit: Option<LateralLimit>) -> bool {
        if let Some(l) = limit {
            let ok = |v: f32| v.is_finite() && v > 0.0;
            if !(ok(l.accel_mps2) && ok(l.width_m)) {
                return false;
            }
        }
        self.lateral_limit = limit;
        self.speed_envelope();
        true
    }

    /// The lateral acceleration limit of the speed envelope ([`Path::set_lateral_limit`]).
    pub const fn lateral_limit(&self) -> Option<LateralLimit> {
        self.lateral_limit
    }

    /// Checks `waypoints` without changing anything: the rules a path must follow.
    pub fn validate(waypoints: &[Waypoint]) -> Result<(), PathError> {
        if waypoints.len() < 2 || waypoints.len() > MAX_PATH_POINTS {
            return Err(PathError::PointCount);
        }
        for (i, w) in waypoints.iter().enumerate() {
            let finite = [w.east_m, w.north_m, w.speed_mps, w.left_m, w.right_m]
                .iter()
                .all(|v| v.is_finite());
            if !finite || w.speed_mps < 0.0 || w.left_m < 0.0 || w.right_m < 0.0 {
                return Err(PathError::BadValue(i as u16));
            }
        }
        // Lengths and turns without square roots or arc tangents (the tick a path completes
        // also loads it): squared lengths against the squared limits, and a turn beyond
        // MAX_TURN_RAD as `dot < cos(MAX_TURN_RAD) |a| |b|`, i.e. a non-positive dot or
        // `dot^2 < cos^2 |a|^2 |b|^2`.
        let cos_max_turn = math::sin_cos_inlined(MAX_TURN_RAD).1;
        let mut previous: Option<(f32, f32, f32)> = None;
        for (i, w) in waypoints.iter().enumerate() {
            let Some(next) = waypoints.get(i + 1) else {
                break;
            };
            let (dx, dy) = (next.east_m - w.east_m, next.north_m - w.north_m);
            let length2 = dx * dx + dy * dy;
            if !(MIN_SEGMENT_M * MIN_SEGMENT_M..=MAX_SEGMENT_M * MAX_SEGMENT_M).contains(&length2) {
                return Err(PathError::SegmentLength(i as u16));
            }
            if let Some((px, py, p2)) = previous {
                let dot = px * dx + py * dy;
                if dot <= 0.0 || dot * dot < cos_max_turn * cos_max_turn * p2 * length2 {
                    return Err(PathError::Turn(i as u16));
                }
            }
            previous = Some((dx, dy, length2));
        }
        Ok(())
    }

    /// [`Path::validate`], then what the car that is to drive the path needs of it: a corridor
    /// its body fits in at every point.
    ///
    /// A turn tighter than the car's lock is not refused here: whether a car at its lock can
    /// drive it depends on how far the corridor lets it swing wide before and after, which
    /// no per-point rule bounds without refusing turns it can drive. Such a path is driven
    /// until the car leaves its corridor, and the car then stops (`lost_path`, docs/bus.md).
    pub fn validate_for(waypoints: &[Waypoint], car: &PathCar) -> Result<(), PathError> {
        Self::validate(waypoints)?;
        for (i, w) in waypoints.iter().enumerate() {
            if w.left_m + w.right_m + CORRIDOR_TOLERANCE_M < car.body_width_m {
                return Err(PathError::Corridor(i as u16));
            }
        }
        Ok(())
    }

    /// Replaces this path by `waypoints` if they pass [`Path::validate`]; on an error the path
    /// is left as it was.
    pub fn load(&mut self, waypoints: &[Waypoint]) -> Result<(), PathError> {
        Self::validate(waypoints)?;
        self.load_valid(waypoints);
        Ok(())
    }

    /// Replaces this path by `waypoints` if they pass [`Path::validate_for`] `car`; on an
    /// error the path is left as it was.
    pub fn load_for(&mut self, waypoints: &[Waypoint], car: &PathCar) -> Result<(), PathError> {
        Self::validate_for(waypoints, car)?;
        self.load_valid(waypoints);
        Ok(())
    }

    /// Loads waypoints that passed [`Path::validate`].
    #[inline(never)]
    fn load_valid(&mut self, waypoints: &[Waypoint]) {
        let n = waypoints.len();
        let mut station = 0.0;
        for i in 0..n {
            let (Some(w), Some(s), Some(d), Some(p)) = (
                waypoints.get(i),
                self.station_m.get_mut(i),
                self.direction.get_mut(i),
                self.points.get_mut(i),
            ) else {
                break;
            };
            *p = *w;
            *s = station;
            if let Some(next) = waypoints.get(i + 1) {
                let (dx, dy) = (next.east_m - w.east_m, next.north_m - w.north_m);
                *d = math::sin_cos_inlined(math::atan2(dx, dy));
                station += math::sqrt(dx * dx + dy * dy);
            }
        }
        // The last point has no segment of its own: it keeps the last segment's heading.
        let last = self.direction.get(n - 2).copied().unwrap_or((0.0, 1.0));
        if let Some(d) = self.direction.get_mut(n - 1) {
            *d = last;
        }
        self.len = n;
        self.reference_geometry();
        self.speed_envelope();
        self.corridor_blocks();
        self.mark_stops();
    }

    /// The stops' bits (see [`Path::stop_ahead_m`]): a tick's search for the next one reads
    /// a word per 32 points rather than every point's target.
    fn mark_stops(&mut self) {
        self.stops = [0; HELD_WORDS];
        let targets = self.points.get(..self.len).unwrap_or(&[]);
        for (k, pair) in targets.windows(2).enumerate() {
            if let ([before, p], Some(word)) = (pair, self.stops.get_mut((k + 1) / 32)) {
                if p.speed_mps <= 0.0 && before.speed_mps > 0.0 {
                    *word |= 1 << ((k + 1) % 32);
                }
            }
        }
    }

    /// The first stop at point `from` or after it ([`Path::mark_stops`]).
    fn next_stop(&self, from: usize) -> Option<usize> {
        let mut w = from / 32;
        let mut word = self.stops.get(w)? & (u32::MAX << (from % 32));
        while word == 0 {
            w += 1;
            word = *self.stops.get(w)?;
        }
        Some(w * 32 + word.trailing_zeros() as usize)
    }

    /// The corridor's block minima (see [`Path::narrowest_corridor`]).
    fn corridor_blocks(&mut self) {
        let blocks = self.len.div_ceil(CORRIDOR_BLOCK);
        for (b, min) in self
            .corridor_block_min_m
            .iter_mut()
            .enumerate()
            .take(blocks)
        {
            let from = b * CORRIDOR_BLOCK;
            let block = self
                .points
                .get(from..(from + CORRIDOR_BLOCK).min(self.len))
                .unwrap_or(&[]);
            *min = block.iter().fold((f32::INFINITY, f32::INFINITY), |m, w| {
                (math::min(m.0, w.left_m), math::min(m.1, w.right_m))
            });
        }
    }

    /// The speed envelope of every point, from the end back (see the module doc).
    #[inline(never)]
    fn speed_envelope(&mut self) {
        // Each point's own limit: its target's square, and its turns' where a lateral limit is
        // set; then the braking from every later point's.
        for (r, p) in self
            .reach_m2ps2
            .iter_mut()
            .zip(self.points.iter())
            .take(self.len)
        {
            *r = p.speed_mps * p.speed_mps;
        }
        self.held = [0; HELD_WORDS];
        if let Some(limit) = self.lateral_limit {
            self.turn_limits(limit);
            self.whole_turn_limits(limit);
        }
        let two_a = 2.0 * self.braking_mps2;
        let mut later: Option<(f32, f32)> = None;
        for i in (0..self.len).rev() {
            let (Some(&s), Some(r)) = (self.station_m.get(i), self.reach_m2ps2.get_mut(i)) else {
                continue;
            };
            *r = match later {
                // The end is a stop.
                None => 0.0,
                Some((s_next, r_next)) => math::min(*r, r_next + two_a * (s_next - s)),
            };
            later = Some((s, *r));
        }
    }

    /// Lowers the own limits in `reach_m2ps2` of both ends of every window of [`TURN_WINDOWS_M`]
    /// that starts at a point to the speed squared at which the window's turn, cut through the
    /// corridor's room, asks `limit`'s lateral acceleration (see the module doc), at an end
    /// that turns with the window (its curvature at least half the window's mean): each point
    /// is the start of a window of each length, and the end of those that reach it. The heading
    /// is unwrapped along the path once; each window's end is a pointer that only moves on:
    /// O(points x windows), no transcendental call, the same work for any path of as many
    /// points (no shortcut for a path the limit cannot bind: the tick's bound counts it once).
    #[inline(never)]
    fn turn_limits(&mut self, limit: LateralLimit) {
        let n = self.len;
        if n <= TURN_FEW_POINTS {
            return;
        }
        // The heading unwrapped from the first point's, step by step: at point i, and per
        // window at its end (no array to clear).
        let mut theta_i = 0.0f32;
        let mut ends = [(0usize, 0.0f32); TURN_WINDOWS_M.len()];
        for i in 0..n {
            let Some((s_i, room_i)) = self.turn_room(i, limit.width_m) else {
                break;
            };
            if i > 0 {
                theta_i += self.heading_step(i - 1);
            }
            for (&window_m, (j, theta_j)) in TURN_WINDOWS_M.iter().zip(ends.iter_mut()) {
                if *j < i {
                    (*j, *theta_j) = (i, theta_i);
                }
                while self
                    .turn_room(*j + 1, limit.width_m)
                    .is_some_and(|(s, _)| s - s_i <= window_m)
                {
                    *theta_j += self.heading_step(*j);
                    *j += 1;
                }
                {
                    if let Some((s_j, room_j)) = self.turn_room(*j, limit.width_m) {
                        let (turn, length) = (*theta_j - theta_i, s_j - s_i);
                        let cap = cut_turn_m2ps2(
                            limit.accel_mps2,
                            turn,
                            length,
                            math::min(room_i, room_j),
                        );
                        // An end that turns with the window (at half its mean curvature or
                        // more) drives it: not a straight before or after it, which the
                        // braking reaches, or leaves.
                        let mean = if turn < 0.0 { -turn } else { turn };
                        for k in [i, *j] {
                            let (Some(&c), Some(r)) =
                                (self.curvature_per_m.get(k), self.reach_m2ps2.get_mut(k))
                            else {
                                continue;
                            };
                            let c = if c < 0.0 { -c } else { c };
                            if 2.0 * c * length >= mean && cap < *r {
                                *r = cap;
                                if let Some(word) = self.held.get_mut(k / 32) {
                                    *word |= 1 << (k % 32);
                                }
                            }
                        }
                    }
                }
                // Every longer window ends at the path's end too (its end catches up when a
                // later point needs it).
                if *j + 1 >= n {
                    break;
                }
            }
        }
    }

    /// The reference heading's step from point `k` to `k + 1`, rad (0 past the end).
    fn heading_step(&self, k: usize) -> f32 {
        match (
            self.reference_heading_rad.get(k),
            self.reference_heading_rad.get(k + 1),
        ) {
            (Some(&a), Some(&b)) => math::wrap_pi(b - a),
            _ => 0.0,
        }
    }

    /// Point `k`'s station, m, and the room a body `width_m` wide has there to cut a turn, m
    /// (the corridor's width less the body's); `None` past the path's end.
    fn turn_room(&self, k: usize, width_m: f32) -> Option<(f32, f32)> {
        let p = self.points.get(..self.len)?.get(k)?;
        Some((*self.station_m.get(k)?, p.left_m + p.right_m - width_m))
    }

    /// Lowers the own limits in `reach_m2ps2` of the points of each whole turn to the speed
    /// squared at which the turn, cut through the corridor's least room along it, asks
    /// `limit`'s lateral acceleration (see the module doc). A whole turn is a run of points
    /// whose curvature keeps one sign beyond [`TURN_RUN_CURVATURE_PER_M`], measured over its
    /// core, the points curving at least half as much as its tightest (the reference's
    /// smoothing spreads a turn's curvature a metre or two onto the straights around it): the
    /// racing line drives the turn at one radius, which no window of [`TURN_WINDOWS_M`]
    /// measures unless its length is the turn's (a window inside it credits that part with
    /// the whole room's cut). One pass and a second over each run when it ends, O(points).
    #[inline(never)]
    fn whole_turn_limits(&mut self, limit: LateralLimit) {
        let n = self.len;
        if n <= TURN_FEW_POINTS {
            return;
        }
        // The open run: its first point, sign and tightest curvature.
        let mut run: Option<(usize, f32, f32)> = None;
        for k in 0..=n {
            let c = match self.turn_room(k, limit.width_m) {
                Some(_) => self.curvature_per_m.get(k).copied().unwrap_or(0.0),
                None => 0.0,
            };
            let sign = if c > TURN_RUN_CURVATURE_PER_M {
                1.0
            } else if c < -TURN_RUN_CURVATURE_PER_M {
                -1.0
            } else {
                0.0
            };
            if let Some((first, run_sign, most)) = run {
                if sign == run_sign {
                    run = Some((first, run_sign, math::max(most, libm::fabsf(c))));
                    continue;
                }
                self.hold_whole_turn(limit, first, k, most);
                run = None;
            }
            if sign != 0.0 {
                run = Some((k, sign, libm::fabsf(c)));
            }
        }
    }

    /// [`Path::whole_turn_limits`] for the run of points `first..end` whose tightest
    /// curvature is `most`: its core's turn over the core's length, cut through the core's
    /// least room, lowers the core's own limits.
    fn hold_whole_turn(&mut self, limit: LateralLimit, first: usize, end: usize, most: f32) {
        // The core's first point and heading there, its last and heading there, its least
        // room; the heading unwrapped from the run's first point.
        let mut core: Option<(usize, f32, usize, f32, f32)> = None;
        let mut theta = 0.0f32;
        for m in first..end {
            if m > first {
                theta += self.heading_step(m - 1);
            }
            let c = libm::fabsf(self.curvature_per_m.get(m).copied().unwrap_or(0.0));
            let Some((_, room)) = self.turn_room(m, limit.width_m) else {
                break;
            };
            if c >= 0.5 * most {
                core = Some(match core {
                    None => (m, theta, m, theta, room),
                    Some((a, theta_a, _, _, least)) => {
                        (a, theta_a, m, theta, math::min(least, room))
                    }
                });
            }
        }
        let Some((a, theta_a, b, theta_b, room)) = core else {
            return;
        };
        let (Some((s_a, _)), Some((s_b, _))) = (
            self.turn_room(a, limit.width_m),
            self.turn_room(b, limit.width_m),
        ) else {
            return;
        };
        let cap = cut_turn_m2ps2(limit.accel_mps2, theta_b - theta_a, s_b - s_a, room);
        for m in a..=b {
            if let Some(r) = self.reach_m2ps2.get_mut(m) {
                if cap < *r {
                    *r = cap;
                    if let Some(word) = self.held.get_mut(m / 32) {
                        *word |= 1 << (m % 32);
                    }
                }
            }
        }
    }

    /// The chord around point `i`: the points `k` before and `k` after it (clamped to the
    /// path's ends) with `k` the fewest that span at least twice [`REFERENCE_BASELINE_M`]; as
    /// many points on both sides, so that on evenly spaced points the chord is parallel to the
    /// tangent at `i`. `k` starts from the previous point's less one: each call moves it by
    /// little, and all calls along the path take O(points) steps.
    fn chord_around(&self, i: usize, k: &mut usize) -> (usize, usize) {
        let last = self.len.saturating_sub(1);
        *k = k.saturating_sub(1).max(1);
        loop {
            let (lo, hi) = (i.saturating_sub(*k), (i + *k).min(last));
            let span = self.station_m.get(hi).copied().unwrap_or(0.0)
                - self.station_m.get(lo).copied().unwrap_or(0.0);
            if span >= 2.0 * REFERENCE_BASELINE_M || (lo == 0 && hi == last) {
                return (lo, hi);
            }
            *k += 1;
        }
    }

    /// The reference heading and curvature at every point (see the module doc).
    fn reference_geometry(&mut self) {
        let n = self.len;
        // Each point's chord half-width in points, kept for the curvature pass (at most
        // 2 m / MIN_SEGMENT_M = 40).
        let mut chord_points = [0u8; MAX_PATH_POINTS];
        let mut k = 1;
        for (i, kept) in chord_points.iter_mut().enumerate().take(n) {
            let (lo, hi) = self.chord_around(i, &mut k);
            *kept = k.min(u8::MAX as usize) as u8;
            let (Some(a), Some(b)) = (self.points.get(lo), self.points.get(hi)) else {
                break;
            };
            let heading = math::atan2(b.east_m - a.east_m, b.north_m - a.north_m);
            if let Some(h) = self.reference_heading_rad.get_mut(i) {
                *h = heading;
            }
        }
        let last = n.saturating_sub(1);
        let mut max_curvature = 0.0f32;
        for (i, &k) in chord_points.iter().enumerate().take(n) {
            let (lo, hi) = (i.saturating_sub(k as usize), (i + k as usize).min(last));
            let (Some(&h_lo), Some(&h_hi), Some(&s_lo), Some(&s_hi)) = (
                self.reference_heading_rad.get(lo),
                self.reference_heading_rad.get(hi),
                self.station_m.get(lo),
                self.station_m.get(hi),
            ) else {
                break;
            };
            let span = s_hi - s_lo;
            let curvature = if span > 0.0 {
                math::wrap_pi(h_hi - h_lo) / span
            } else {
                0.0
            };
            if let Some(k) = self.curvature_per_m.get_mut(i) {
                *k = curvature;
            }
            let magnitude = if curvature < 0.0 {
                -curvature
            } else {
                curvature
            };
            if magnitude > max_curvature {
                max_curvature = magnitude;
            }
        }
        self.max_curvature_per_m = max_curvature;
    }

    /// Forgets every point.
    pub fn clear(&mut self) {
        self.len = 0;
        self.max_curvature_per_m = 0.0;
    }

    /// Number of points (0 = no path).
    pub const fn len(&self) -> usize {
        self.len
    }

    /// Whether the path has no points.
    pub const fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The waypoints.
    pub fn points(&self) -> &[Waypoint] {
        self.points.get(..self.len).unwrap_or(&[])
    }

    /// Station of point `i`, m.
    pub fn station_of(&self, i: usize) -> Option<f32> {
        self.station_m.get(..self.len)?.get(i).copied()
    }

    /// The largest reference curvature of any point, 1/m, without its sign (0 for an empty
    /// path): how tight the path is at its tightest. Taken when the path is loaded.
    pub const fn max_curvature_per_m(&self) -> f32 {
        self.max_curvature_per_m
    }

    /// Distance from `station_m` to where the path next asks for a stop, m: the first point
    /// with a target speed of 0 after one with a speed (a stop line), from the start of the
    /// segment `station_m` is on (negative past such a point on that segment), else the
    /// path's end (negative beyond it). `hint` is a segment index to start the search from
    /// (the projection's). A planner that stops the car short of its path's end (a stop line,
    /// a blocked lane) sets the targets from there on to 0, and a controller brakes for that
    /// point as for the end; a path that starts at 0 (a launch) has no stop there.
    pub fn stop_ahead_m(&self, station_m: f32, hint: usize) -> f32 {
        let end = self.length_m();
        if self.len < 2 || !station_m.is_finite() {
            return end - station_m;
        }
        let first = self.segment_at(math::clamp(station_m, 0.0, end), hint);
        self.next_stop(first)
            .and_then(|k| self.station_of(k))
            .map_or(end - station_m, |s| s - station_m)
    }

    /// The point ahead of `station_m` (from the segment it is on, searched from `hint`) whose
    /// target is below `share` of that segment's first point's and below `below_mps` but not
    /// 0 (a stop is [`Path::stop_ahead_m`]'s), and which
    /// leaves the least room to slow to it: the least of its distance ahead plus
    /// `coasted_s` times its target (a car that coasts to a speed `w` needs its coast-out
    /// less `w` times that, `crate::control::mpc::longitudinal::SlowAhead`); as (distance
    /// ahead, m; target, m/s). `None` without such a point or a path.
    pub fn slow_ahead(
        &self,
        station_m: f32,
        hint: usize,
        coasted_s: f32,
        (below_mps, share): (f32, f32),
    ) -> Option<(f32, f32)> {
        if self.len < 2 || !station_m.is_finite() {
            return None;
        }
        let first = self.segment_at(math::clamp(station_m, 0.0, self.length_m()), hint);
        let below = math::min(share * self.points.get(first)?.speed_mps, below_mps);
        let ahead = self.points.get(first + 1..self.len)?;
        let stations = self.station_m.get(first + 1..self.len)?;
        // Every point but a new least does the same work, a candidate or not (the tick's
        // bound needs no drive that makes every point one; a new least at every point, targets
        // that fall all along, costs two moves a point more).
        let (mut least_room, mut least) = (f32::INFINITY, 0usize);
        for (k, (p, &s)) in ahead.iter().zip(stations).enumerate() {
            let v = p.speed_mps;
            let room = if v < below && v > 0.0 {
                s + coasted_s * v
            } else {
                f32::INFINITY
            };
            if room < least_room {
                (least_room, least) = (room, k);
            }
        }
        let (p, s) = (ahead.get(least)?, stations.get(least)?);
        (least_room < f32::INFINITY).then_some((s - station_m, p.speed_mps))
    }

    /// Length along the path, m.
    pub fn length_m(&self) -> f32 {
        self.station_of(self.len.saturating_sub(1)).unwrap_or(0.0)
    }

    /// Segment `i`: its start point, heading's `(sin, cos)` and length.
    fn segment(&self, i: usize) -> Option<(Waypoint, (f32, f32), f32)> {
        if i + 1 >= self.len {
            return None;
        }
        let a = *self.points.get(i)?;
        let d = *self.direction.get(i)?;
        let length = self.station_m.get(i + 1)? - self.station_m.get(i)?;
        Some((a, d, length))
    }

    /// The nearest point of the path to `(east, north)` among segments `range`, its squared
    /// distance and whether it is a segment's end point rather than a foot on it.
    fn nearest_in(
        &self,
        range: core::ops::Range<usize>,
        east_m: f32,
        north_m: f32,
    ) -> Option<(Projection, f32, bool)> {
        let end = range.end;
        self.nearest_split(range, end, east_m, north_m).1
    }

    /// [`Path::nearest_in`] over segments `range` in one pass, and the same over the part of
    /// it before segment `split`: `(before split, whole range)`.
    fn nearest_split(
        &self,
        range: core::ops::Range<usize>,
        split: usize,
        east_m: f32,
        north_m: f32,
    ) -> (Option<Nearest>, Option<Nearest>) {
        let segments = self.len.saturating_sub(1);
        let (first, end) = (range.start, range.end.min(segments));
        if first >= end {
            return (None, None);
        }
        let split = split.clamp(first, end);
        let before_split = self.scan_segments(first..split, east_m, north_m, Best::NONE);
        let best = self.scan_segments(split..end, east_m, north_m, before_split);
        (self.nearest_of(&before_split), self.nearest_of(&best))
    }

    /// [`Path::nearest_split`]'s search over segments `range` (within the path), from `best`
    /// on; the best after them ([`Path::scan_segments_each`] for one point). Not inlined: one
    /// copy for its five calls (the image's flash).
    #[inline(never)]
    fn scan_segments(
        &self,
        range: core::ops::Range<usize>,
        east_m: f32,
        north_m: f32,
        best: Best,
    ) -> Best {
        let [best] = self.scan_segments_each(range, [(east_m, north_m)], [best]);
        best
    }

    /// The projections onto the path of `points` (east, north; each finite), each as
    /// [`Path::project`] finds it without a previous projection (`None` without a path), in one
    /// pass over the segments: each segment's data read once for all of them.
    pub fn project_each<const N: usize>(&self, points: [(f32, f32); N]) -> [Option<Projection>; N] {
        let segments = self.len.saturating_sub(1);
        let best = self.scan_segments_each(0..segments, points, [Best::NONE; N]);
        best.map(|b| self.nearest_of(&b).map(|(p, _, _)| p))
    }

    /// The search over segments `range` (within the path) for each of `points`, from its
    /// `best` on; the best of each after them: the least key ([`Best::key`]), the first segment
    /// of equal ones. Every segment is tested in full for every point, with no branch on the
    /// data: the search costs the same wherever the points are (the tick's bound needs no drive
    /// to find its dearest geometry, docs/firmware.md "Where the obstacles' search prunes
    /// nothing").
    fn scan_segments_each<const N: usize>(
        &self,
        range: core::ops::Range<usize>,
        points_m: [(f32, f32); N],
        best: [Best; N],
    ) -> [Best; N] {
        let mut best = best;
        let first = range.start;
        // The segments' start points, directions, and the stations at both ends.
        let (Some(points), Some(directions), Some(starts), Some(ends)) = (
            self.points.get(range.clone()),
            self.direction.get(range.clone()),
            self.station_m.get(range.clone()),
            self.station_m.get(first + 1..range.end + 1),
        ) else {
            return best;
        };
        let last = self.len.saturating_sub(2);
        // The least key so far and its segment (of the range; `usize::MAX`: the best passed
        // in). In the loop a foot off its segment is a corner, a key `VERTEX_TIE` farther,
        // on every segment: no more than the key `clamped` gives, which the path's two end
        // segments (a foot beyond the path's end is not a corner) are given after it.
        let mut least = best.map(|b| b.key);
        let mut winner = [usize::MAX; N];
        let segments = points.iter().zip(directions).zip(starts.iter().zip(ends));
        for (k, ((a, &direction), (&s_a, &s_b))) in segments.enumerate() {
            let length = s_b - s_a;
            for ((l, w), &point) in least.iter_mut().zip(winner.iter_mut()).zip(&points_m) {
                let f = foot(a, direction, length, point);
                let key = if f.off != 0.0 {
                    f.d2 * (1.0 + VERTEX_TIE)
                } else {
                    f.d2
                };
                if key < *l {
                    *l = key;
                    *w = k;
                }
            }
        }
        // The end segments' own keys, in the order the loop met them: the first segment before
        // every later one of an equal key (not before the best passed in), the last after
        // every earlier one.
        for end in [0, last] {
            let Some(k) = end.checked_sub(first).filter(|&k| k < points.len()) else {
                continue;
            };
            let (Some(a), Some(&direction), Some(&s_a), Some(&s_b)) =
                (points.get(k), directions.get(k), starts.get(k), ends.get(k))
            else {
                continue;
            };
            let length = s_b - s_a;
            for ((l, w), &point) in least.iter_mut().zip(winner.iter_mut()).zip(&points_m) {
                let f = foot(a, direction, length, point);
                let key = Best::key(f.d2, clamped(f.along, length, end, last));
                let wins = if end == first {
                    key < *l || (key == *l && *w != usize::MAX)
                } else {
                    key < *l || *w == k
                };
                if wins {
                    *l = key;
                    *w = k;
                }
            }
        }
        for ((b, &w), &point) in best.iter_mut().zip(&winner).zip(&points_m) {
            let (Some(a), Some(&direction), Some(&s_a), Some(&s_b)) =
                (points.get(w), directions.get(w), starts.get(w), ends.get(w))
            else {
                continue;
            };
            let length = s_b - s_a;
            let f = foot(a, direction, length, point);
            let clamped = clamped(f.along, length, first + w, last);
            *b = Best {
                segment: first + w,
                d2: f.d2,
                key: Best::key(f.d2, clamped),
                clamped,
                along: f.along,
                lateral: f.lateral,
            };
        }
        best
    }

    /// The projection `best` found (`None` if it found none).
    fn nearest_of(&self, best: &Best) -> Option<Nearest> {
        let Best {
            segment: i,
            d2,
            clamped,
            along,
            lateral,
            ..
        } = *best;
        let (Some(&s_a), Some(&s_b)) = (
            self.station_m.get(i),
            i.checked_add(1).and_then(|j| self.station_m.get(j)),
        ) else {
            return None;
        };
        let length = s_b - s_a;
        let t = if !clamped {
            along
        } else if along < 0.0 {
            0.0
        } else {
            length
        };
        // At a corner the nearest point is the corner itself: the offset is the distance to
        // it, with the side of the segment's line.
        let lateral_m = if clamped {
            math::sqrt(d2).copysign(lateral)
        } else {
            lateral
        };
        Some((
            Projection {
                segment: i,
                station_m: s_a + t,
                lateral_m,
            },
            d2,
            clamped,
        ))
    }

    /// The projection of `(east, north)` onto the path. With `previous` (last tick's
    /// projection) only segments from [`PROJECTION_BEHIND_M`] behind to [`PROJECTION_AHEAD_M`]
    /// ahead of it are searched, so that a path that passes near itself (a loop) is followed in
    /// order; the whole path is searched without it, or when the windowed result is farther
    /// than [`PROJECTION_RESEARCH_M`] (the rest of the path, after the window). `None` without
    /// a path or for non-finite input.
    pub fn project(
        &self,
        east_m: f32,
        north_m: f32,
        previous: Option<&Projection>,
    ) -> Option<Projection> {
        self.project_windowed(east_m, north_m, previous)
            .map(|(p, _)| p)
    }

    /// [`Path::project`], and whether the point left `previous`'s window
    /// ([`Tracking::left_window`]; true for a `previous` of another path).
    fn project_windowed(
        &self,
        east_m: f32,
        north_m: f32,
        previous: Option<&Projection>,
    ) -> Option<(Projection, bool)> {
        if self.len < 2 || !east_m.is_finite() || !north_m.is_finite() {
            return None;
        }
        let segments = self.len - 1;
        let Some(prev) = previous.filter(|p| p.segment < segments) else {
            return self
                .nearest_in(0..segments, east_m, north_m)
                .map(|(p, _, _)| (p, previous.is_some()));
        };
        let window = self.window(prev);
        let in_window = self.scan_segments(window.clone(), east_m, north_m, Best::NONE);
        if let Some((p, d2, _)) = self.nearest_of(&in_window) {
            if d2 <= PROJECTION_RESEARCH_M * PROJECTION_RESEARCH_M {
                return Some((p, false));
            }
        }
        // The rest of the path, from the window's best on: with the window, one pass over the
        // path, no dearer than placing a car on it afresh.
        let before = self.scan_segments(0..window.start, east_m, north_m, in_window);
        let best = self.scan_segments(window.end..segments, east_m, north_m, before);
        let left = best.segment != in_window.segment;
        self.nearest_of(&best).map(|(p, _, _)| (p, left))
    }

    /// The segments from [`PROJECTION_BEHIND_M`] behind to [`PROJECTION_AHEAD_M`] ahead of
    /// `prev`.
    fn window(&self, prev: &Projection) -> core::ops::Range<usize> {
        let segments = self.len.saturating_sub(1);
        let (behind, ahead) = (
            prev.station_m - PROJECTION_BEHIND_M,
            prev.station_m + PROJECTION_AHEAD_M,
        );
        // The last segment that starts at or before `behind` (or the first), no later than
        // `prev`'s; the first point at or beyond `ahead` (or the last), after `prev`'s segment.
        let lo = prev.segment.min(self.segment_at(behind, prev.segment));
        let j = self.segment_at(ahead, prev.segment);
        let first_at_or_beyond = if self.station_of(j).is_some_and(|s| s < ahead) {
            j + 1
        } else {
            j
        };
        let hi = first_at_or_beyond.max(prev.segment + 1).min(segments);
        lo..hi
    }

    /// The projection of a car that has none yet (a new path, or a reset): the car is about to
    /// start the path, so a foot on its first [`PROJECTION_AHEAD_M`] is taken unless the rest
    /// of the path is nearer by more than [`ACQUIRE_TIE_M`]. A closed loop's end, or a figure
    /// of eight's crossing, lies at its start: there the nearest point of the whole path is a
    /// matter of the receiver's noise (a fix 0.5 m behind the start of a loop is on its last
    /// segment), and the car would take itself for one at the end of the path. A point of the
    /// first stretch that is a corner (the stretch's far end, for a car farther on) is not
    /// taken: the whole path's nearest point is.
    fn acquire(&self, east_m: f32, north_m: f32) -> Option<Projection> {
        if self.len < 2 || !east_m.is_finite() || !north_m.is_finite() {
            return None;
        }
        let start = Projection {
            segment: 0,
            station_m: 0.0,
            lateral_m: 0.0,
        };
        // The first stretch's window starts at segment 0: one pass over the whole path finds
        // both.
        let window = self.window(&start);
        let (near_start, nearest) =
            self.nearest_split(0..self.len.saturating_sub(1), window.end, east_m, north_m);
        let ((near_start, d2_start, corner), (nearest, d2, _)) = (near_start?, nearest?);
        if !corner && math::sqrt(d2_start) <= math::sqrt(d2) + ACQUIRE_TIE_M {
            Some(near_start)
        } else {
            Some(nearest)
        }
    }

    /// Index of the segment whose span holds `station_m`: the last segment that starts at or
    /// before it (the first one before the path). Searched from `hint` in steps that double
    /// (forward or backward), then halved: a station near the hint costs a step or two, and
    /// any station at most `2 log2(MAX_PATH_POINTS)` whatever the points' density.
    fn segment_at(&self, station_m: f32, hint: usize) -> usize {
        let last_segment = self.len.saturating_sub(2);
        let at_or_before = |i: usize| self.station_of(i).is_some_and(|s| s <= station_m);
        let i = hint.min(last_segment);
        // `lo` starts at or before the station (or is segment 0); `hi` is past it (or past
        // the last segment).
        let (mut lo, mut hi) = if at_or_before(i) {
            let (mut lo, mut step) = (i, 1);
            loop {
                let next = lo + step;
                if next > last_segment {
                    break (lo, last_segment + 1);
                }
                if !at_or_before(next) {
                    break (lo, next);
                }
                lo = next;
                step *= 2;
            }
        } else {
            let (mut hi, mut step) = (i, 1);
            loop {
                let Some(next) = hi.checked_sub(step) else {
                    break (0, hi);
                };
                if at_or_before(next) {
                    break (next, hi);
                }
                hi = next;
                step *= 2;
            }
        };
        while hi - lo > 1 {
            let mid = lo + (hi - lo) / 2;
            if at_or_before(mid) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        lo
    }

    /// Segment `segment`'s direction as (sin, cos) of its heading (clockwise from north);
    /// `None` past the path's last segment.
    pub fn segment_direction(&self, segment: usize) -> Option<(f32, f32)> {
        self.direction
            .get(segment..self.len.saturating_sub(1))?
            .first()
            .copied()
    }

    /// The segment that holds `station_m` (clamped to the path), searched from segment `hint`:
    /// the same whatever the hint, and cheaper from a nearby one. A caller sampling stations in
    /// ascending order passes each one's segment on as the next one's hint, so that its searches
    /// together walk the path once (`node::drive`'s reference over the horizon).
    pub fn segment_hint(&self, station_m: f32, hint: usize) -> usize {
        if !station_m.is_finite() {
            return hint;
        }
        self.segment_at(math::clamp(station_m, 0.0, self.length_m()), hint)
    }

    /// The reference at `station_m` (clamped to the path: before its start the first point's
    /// values, beyond its end the last point extended straight ahead at speed 0). `hint` is a
    /// segment index to start searching from (e.g. the projection's); `None` without a path.
    pub fn sample(&self, station_m: f32, hint: usize) -> Option<PathSample> {
        self.sample_with(station_m, hint, true)
    }

    /// [`Path::sample`] for its geometry and corridor only: its `speed_mps` is the points'
    /// targets, linear between them, without the speed envelope (whose square root a tick
    /// that samples the corridor at many stations need not take).
    pub fn sample_geometry(&self, station_m: f32, hint: usize) -> Option<PathSample> {
        self.sample_with(station_m, hint, false)
    }

    fn sample_with(&self, station_m: f32, hint: usize, envelope: bool) -> Option<PathSample> {
        if self.len < 2 || !station_m.is_finite() {
            return None;
        }
        let length = self.length_m();
        let s = math::clamp(station_m, 0.0, length);
        let i = self.segment_at(s, hint);
        let (a, (sin_h, cos_h), seg_len) = self.segment(i)?;
        let b = *self.points.get(i + 1)?;
        let s_a = *self.station_m.get(i)?;
        let t = s - s_a;
        let f = if seg_len > 0.0 { t / seg_len } else { 0.0 };
        let lerp = |x: f32, y: f32| x + (y - x) * f;
        // Beyond the end, the last segment extends straight: position moves on, speed is 0.
        let beyond = (station_m - length).max(0.0);
        let (heading_rad, curvature_per_m) = self.heading_and_curvature(i, t, seg_len);
        let target = lerp(a.speed_mps, b.speed_mps);
        let speed_mps = if beyond > 0.0 {
            0.0
        } else if envelope {
            // The square root only where the envelope binds.
            let r_b = self.reach_m2ps2.get(i + 1).copied().unwrap_or(0.0);
            let reach = math::max(r_b + 2.0 * self.braking_mps2 * (seg_len - t), 0.0);
            if target * target <= reach {
                target
            } else {
                math::sqrt(reach)
            }
        } else {
            target
        };
        Some(PathSample {
            station_m: s + beyond,
            east_m: a.east_m + (t + beyond) * sin_h,
            north_m: a.north_m + (t + beyond) * cos_h,
            heading_rad,
            curvature_per_m: if beyond > 0.0 { 0.0 } else { curvature_per_m },
            speed_mps,
            left_m: lerp(a.left_m, b.left_m),
            right_m: lerp(a.right_m, b.right_m),
        })
    }

    /// Reference heading and curvature `t` metres into segment `i` of length `seg_len`: linear
    /// between the segment's points (see the module doc).
    fn heading_and_curvature(&self, i: usize, t: f32, seg_len: f32) -> (f32, f32) {
        let f = if seg_len > 0.0 {
            math::clamp(t / seg_len, 0.0, 1.0)
        } else {
            0.0
        };
        let (Some(&h0), Some(&h1), Some(&k0), Some(&k1)) = (
            self.reference_heading_rad.get(i),
            self.reference_heading_rad.get(i + 1),
            self.curvature_per_m.get(i),
            self.curvature_per_m.get(i + 1),
        ) else {
            let (sin_h, cos_h) = self.direction.get(i).copied().unwrap_or((0.0, 1.0));
            return (math::atan2(sin_h, cos_h), 0.0);
        };
        (
            math::wrap_pi(h0 + math::wrap_pi(h1 - h0) * f),
            k0 + (k1 - k0) * f,
        )
    }

    /// Where the corridor binds a straight side of a body that spans the stations from `from_m`
    /// (the rear axle) to `to_m` (one end of the body; either order; beyond the path's ends the
    /// corridor is its end point's, at the station asked for): per side, the narrowest
    /// corridor there and the station where it is. The corridor is linear
    /// between points, so its minimum is at an end or at a point in between; where it is equally
    /// narrow over a stretch (within [`NARROWEST_TIE_M`]), the station farthest from `from_m`
    /// is taken: in a lane that goes on past the body's end that is the end's corner, in a lane
    /// that ends beyond the axle (the front half in a lane it is leaving) the lane's last point,
    /// in a lane that starts behind it (the rear half in a lane it is entering) its first point,
    /// where the body's side meets it; in a lane that starts ahead of the axle, or ends behind
    /// it, the end's corner (the side's other end of the stretch is not reported).
    /// `None` without a path. What a controller needs to keep a body's side, between the axle
    /// and a corner, inside.
    pub fn narrowest_corridor(&self, from_m: f32, to_m: f32, hint: usize) -> Option<Narrowest> {
        self.narrowest_corridor_located(from_m, to_m, (hint, hint))
            .map(|located| located.narrowest)
    }

    /// [`Path::narrowest_corridor`], with the segments its two stations are on (hints that
    /// make sampling the path there one step) and the segment `to_m` is on; `hints` are where
    /// the searches for `from_m`'s and `to_m`'s segments start (the result is the same from
    /// any, [`Path::segment_at`]; a near one makes it a step or two).
    pub fn narrowest_corridor_located(
        &self,
        from_m: f32,
        to_m: f32,
        hints: (usize, usize),
    ) -> Option<NarrowestLocated> {
        if self.len < 2 || !(from_m.is_finite() && to_m.is_finite()) {
            return None;
        }
        // The ends' stations as asked (the path extends beyond its ends, `sample`), the
        // points strictly between them on the path.
        let (lo, hi) = if from_m <= to_m {
            (from_m, to_m)
        } else {
            (to_m, from_m)
        };
        let length = self.length_m();
        let (a, b) = (math::clamp(lo, 0.0, length), math::clamp(hi, 0.0, length));
        let (hint_a, hint_b) = if from_m <= to_m {
            hints
        } else {
            (hints.1, hints.0)
        };
        let (seg_a, seg_b) = (self.segment_at(a, hint_a), self.segment_at(b, hint_b));
        let start = self.widths_in(seg_a, a)?;
        let end = self.widths_in(seg_b, b)?;
        let first = seg_a + 1;
        let last = if self.station_of(seg_b).is_some_and(|s| s < b) {
            seg_b
        } else {
            seg_b.saturating_sub(1)
        };
        let inner = (first <= last && a < b).then_some((first, last));
        let inner_min = inner.map_or((f32::INFINITY, f32::INFINITY), |(i, j)| {
            self.corridor_min(i, j)
        });
        // The farthest station from `from_m` goes first, so that the first within the tie of
        // the minimum is the one taken.
        let ahead = from_m <= to_m;
        let (far, near) = if ahead {
            ((hi, seg_b), (lo, seg_a))
        } else {
            ((lo, seg_a), (hi, seg_b))
        };
        // Per side: the narrowest width, the tie around it, and whether the far end is within
        // it (then it binds there); else the farthest point between the ends within it, else
        // the near end.
        let widths = (
            math::min(math::min(start.0, end.0), inner_min.0),
            math::min(math::min(start.1, end.1), inner_min.1),
        );
        let within = (widths.0 + NARROWEST_TIE_M, widths.1 + NARROWEST_TIE_M);
        let far_widths = if ahead { end } else { start };
        let far_fits = (far_widths.0 <= within.0, far_widths.1 <= within.1);
        // A side searched between the ends only if the far end does not bind it and a point
        // there may (`-inf`: not searched).
        let search = |far_fits: bool, inner_min: f32, within: f32| {
            if far_fits || inner_min > within {
                f32::NEG_INFINITY
            } else {
                within
            }
        };
        let found = inner.map_or((None, None), |(i, j)| {
            self.farthest_within(
                i,
                j,
                (
                    search(far_fits.0, inner_min.0, within.0),
                    search(far_fits.1, inner_min.1, within.1),
                ),
                ahead,
            )
        });
        let at = |far_fits: bool, found: Option<usize>| {
            if far_fits {
                far
            } else {
                // A point between the ends starts its own segment.
                found
                    .and_then(|k| self.station_of(k).map(|s| (s, k)))
                    .unwrap_or(near)
            }
        };
        let (left_m, (left_station_m, left_segment)) = (widths.0, at(far_fits.0, found.0));
        let (right_m, (right_station_m, right_segment)) = (widths.1, at(far_fits.1, found.1));
        Some(NarrowestLocated {
            narrowest: Narrowest {
                left_m,
                left_station_m,
                right_m,
                right_station_m,
            },
            left_segment,
            right_segment,
            to_segment: if ahead { seg_b } else { seg_a },
        })
    }

    /// The corridor `(left, right)` at station `station_m` (on the path) of segment `i`, m:
    /// linear between its points, as [`Path::sample`] has it.
    fn widths_in(&self, i: usize, station_m: f32) -> Option<(f32, f32)> {
        let (Some(a), Some(b), Some(&s_a), Some(&s_b)) = (
            self.points.get(i),
            self.points.get(i + 1),
            self.station_m.get(i),
            self.station_m.get(i + 1),
        ) else {
            return None;
        };
        let seg_len = s_b - s_a;
        let f = if seg_len > 0.0 {
            (station_m - s_a) / seg_len
        } else {
            0.0
        };
        let lerp = |x: f32, y: f32| x + (y - x) * f;
        Some((lerp(a.left_m, b.left_m), lerp(a.right_m, b.right_m)))
    }

    /// The narrowest corridor `(left, right)` over points `i..=j` (`i <= j < len`), m: the
    /// blocks wholly inside from their minima, the rest point by point.
    fn corridor_min(&self, i: usize, j: usize) -> (f32, f32) {
        let both = |m: (f32, f32), w: (f32, f32)| (math::min(m.0, w.0), math::min(m.1, w.1));
        let none = (f32::INFINITY, f32::INFINITY);
        let points = |from: usize, to: usize| {
            self.points
                .get(from..to)
                .unwrap_or(&[])
                .iter()
                .fold(none, |m, w| both(m, (w.left_m, w.right_m)))
        };
        let (first_block, last_block) = (i.div_ceil(CORRIDOR_BLOCK), (j + 1) / CORRIDOR_BLOCK);
        if first_block >= last_block {
            return points(i, j + 1);
        }
        let blocks = self
            .corridor_block_min_m
            .get(first_block..last_block)
            .unwrap_or(&[])
            .iter()
            .fold(none, |m, &b| both(m, b));
        let head = points(i, first_block * CORRIDOR_BLOCK);
        let tail = points(last_block * CORRIDOR_BLOCK, j + 1);
        both(both(head, blocks), tail)
    }

    /// The points of `i..=j` (`i <= j < len`) farthest along (`ahead`) or farthest back whose
    /// corridor is at most `within_m` `(left, right)`, both sides in one pass (a side whose
    /// bound is `-inf` is not searched): the block minima are scanned in a tight loop for the
    /// next block that may hold a side still unfound, and such a block is read point by point
    /// from its far end only while a side it may hold is unfound.
    fn farthest_within(
        &self,
        i: usize,
        j: usize,
        within_m: (f32, f32),
        ahead: bool,
    ) -> (Option<usize>, Option<usize>) {
        let (mut left, mut right) = (None, None);
        // A side's bound while it is unfound, `-inf` once found (no width is below it).
        let mut bound = within_m;
        let (first_block, last_block) = (i / CORRIDOR_BLOCK, j / CORRIDOR_BLOCK);
        let Some(minima) = self.corridor_block_min_m.get(first_block..=last_block) else {
            return (left, right);
        };
        // The blocks not yet scanned are `minima[..rest]` (ahead) or `minima[rest..]`.
        let mut rest = if ahead { minima.len() } else { 0 };
        while bound.0 > f32::NEG_INFINITY || bound.1 > f32::NEG_INFINITY {
            let may = |&(l, r): &(f32, f32)| l <= bound.0 || r <= bound.1;
            let found = if ahead {
                minima.get(..rest).and_then(|m| m.iter().rposition(may))
            } else {
                minima
                    .get(rest..)
                    .and_then(|m| m.iter().position(may))
                    .map(|n| rest + n)
            };
            let Some(n) = found else {
                break;
            };
            rest = if ahead { n } else { n + 1 };
            // A partial block's minimum may be outside the stretch: its points decide.
            let b = first_block + n;
            let from = (b * CORRIDOR_BLOCK).max(i);
            let to = ((b + 1) * CORRIDOR_BLOCK - 1).min(j);
            let Some(points) = self.points.get(from..=to) else {
                break;
            };
            let mut read = |k: usize, w: &Waypoint| {
                if w.left_m <= bound.0 {
                    left = Some(from + k);
                    bound.0 = f32::NEG_INFINITY;
                }
                if w.right_m <= bound.1 {
                    right = Some(from + k);
                    bound.1 = f32::NEG_INFINITY;
                }
                // Both found: the rest of the block is not read.
                bound.0 == f32::NEG_INFINITY && bound.1 == f32::NEG_INFINITY
            };
            let mut indexed = points.iter().enumerate();
            if ahead {
                indexed.rev().any(|(k, w)| read(k, w));
            } else {
                indexed.any(|(k, w)| read(k, w));
            }
        }
        (left, right)
    }

    /// The car's pose relative to the path (projection of the rear axle, heading error, the
    /// reference there); `previous` as in [`Path::project`]. Without `previous` the car is
    /// taken to be starting the path (see `Path::acquire`); `None` without a path or for a
    /// non-finite pose.
    pub fn track(&self, pose: &Pose, previous: Option<&Projection>) -> Option<Tracking> {
        let (projection, left_window) = match previous {
            Some(_) => self.project_windowed(pose.x_m, pose.y_m, previous)?,
            None => (self.acquire(pose.x_m, pose.y_m)?, false),
        };
        let reference = self.sample(projection.station_m, projection.segment)?;
        Some(Tracking {
            projection,
            heading_error_rad: math::wrap_pi(pose.heading_rad - reference.heading_rad),
            reference,
            left_window,
            past_end_m: projection.station_m - self.length_m(),
        })
    }

    /// The reference at each of `stations_m` (ascending for the cheapest search), into `out`;
    /// returns how many were written (the shorter of the two slices, 0 without a path).
    pub fn sample_stations(
        &self,
        stations_m: &[f32],
        hint: usize,
        out: &mut [PathSample],
    ) -> usize {
        let mut hint = hint;
        let mut written = 0;
        for (s, o) in stations_m.iter().zip(out.iter_mut()) {
            let Some(sample) = self.sample(*s, hint) else {
                break;
            };
            hint = self.segment_at(sample.station_m.min(self.length_m()), hint);
            *o = sample;
            written += 1;
        }
        written
    }
}
