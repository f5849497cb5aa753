//! The closed-loop scenarios: the course the car drives (the planner's path with its target
//! speed and corridor, obstacles, cones) and where the car starts.
//!
//! - `dlc`: the ISO 3888-2 severe lane change (obstacle avoidance) test track (ISO
//!   3888-2:2011, "Passenger cars - Test track for a severe lane-change manoeuvre - Part 2:
//!   Obstacle avoidance", section 4 and table 1, as the published excerpts give it): five
//!   sections of 12, 13.5, 11, 12.5 and 12 m (61 m in all); section 1 is `1.1 b + 0.25` m wide,
//!   section 3 `b + 1` m, its near edge 1 m to the left of section 1's far edge; section 5 is
//!   `1.3 b + 0.25` m wide, at most 3 m, on section 1's centreline; `b` is the vehicle's width.
//!   The track limits are tangent to the base circles of the cones (at least 0.5 m tall) that
//!   mark the sections' edges. Our cones: a base circle of [`CONE_RADIUS_M`], centres
//!   [`CONE_RADIUS_M`] outside the edges, at most [`CONE_SPACING_M`] apart along each edge of
//!   sections 1, 3 and 5.
//! - `obstacle`: a straight two-lane road with an obstacle in the car's lane; the corridor
//!   allows the adjacent lane to the left.
//! - `loop`: a parking-lot loop (two straights joined by half circles), one lap.
//!
//! Frame: east/north metres from the simulator's origin; the car starts at rest on the path's
//! first point, heading along it. The lateral coordinate `y` of a course is positive to the
//! left of its direction of travel (a lane change to the left is the standard's).
use super::planner::{ObstacleWalk, PlannedObstacle, PlannedPoint};
use crate::sim::config::Body;

/// Base circle radius of a cone, m: a 500 mm traffic cone's base is about 0.3 m across [I].
pub const CONE_RADIUS_M: f64 = 0.15;
/// Largest distance between neighbouring cones along a section edge, m.
pub const CONE_SPACING_M: f64 = 3.0;
/// The ISO 3888-2 section lengths, m (sections 1..5).
pub const DLC_SECTION_LENGTHS_M: [f64; 5] = [12.0, 13.5, 11.0, 12.5, 12.0];
/// Largest width of the exit lane (section 5), m (ISO 3888-2 table 1).
pub const DLC_EXIT_WIDTH_MAX_M: f64 = 3.0;
/// Deceleration the planner's speed profile uses to bring the car to rest at the path's end,
/// m/s^2.
pub const PLANNER_DECEL_MPS2: f64 = 2.0;
/// After the double lane change's last cones the planner holds the target speed this long
/// before its stop begins, s: longer than a controller looks ahead (the MPC's speed plan, 2 s)
/// plus the speed loop's delay, so that no controller brakes inside the track. The optimiser's
/// trials hold the speed command through it, and ISO 3888-2 is driven at the entry speed; with
/// a fixed 40 m exit the stop reached into the track from 14 m/s and the MPC slowed by up to
/// 3 m/s in the exit lane (docs/findings.md).
pub const DLC_HOLD_AFTER_S: f64 = 3.0;

/// Which course.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// ISO 3888-2 double lane change.
    DoubleLaneChange,
    /// An obstacle on a straight road.
    Obstacle,
    /// A parking-lot loop.
    Loop,
    /// A pedestrian crossing the road ahead of the car.
    Crossing,
}

/// Names accepted by `catmodel closed-loop --scenario`.
pub const SCENARIO_NAMES: [&str; 4] = ["dlc", "obstacle", "loop", "crossing"];

impl Kind {
    /// The scenario called `name`.
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "dlc" => Some(Kind::DoubleLaneChange),
            "obstacle" => Some(Kind::Obstacle),
            "loop" => Some(Kind::Loop),
            "crossing" => Some(Kind::Crossing),
            _ => None,
        }
    }

    /// Its name.
    pub fn name(self) -> &'static str {
        match self {
            Kind::DoubleLaneChange => "dlc",
            Kind::Obstacle => "obstacle",
            Kind::Loop => "loop",
            Kind::Crossing => "crossing",
        }
    }

    /// The target speed when none is given, m/s.
    pub fn default_speed_mps(self) -> f64 {
        match self {
            Kind::DoubleLaneChange => 10.0,
            Kind::Obstacle => 8.0,
            Kind::Loop => 4.0,
            Kind::Crossing => 8.0,
        }
    }
}

/// A cone of the track: its base circle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cone {
    /// Centre east, m.
    pub east_m: f64,
    /// Centre north, m.
    pub north_m: f64,
    /// Base radius, m.
    pub radius_m: f64,
}

/// One lane of the double lane change: `x` range along the course and `y` of its edges.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lane {
    /// Course coordinate where it starts, m.
    pub x_start_m: f64,
    /// Where it ends, m.
    pub x_end_m: f64,
    /// Right edge (y), m.
    pub y_right_m: f64,
    /// Left edge (y), m.
    pub y_left_m: f64,
}

/// Everything a closed-loop run needs to know about its course.
#[derive(Debug, Clone, PartialEq)]
pub struct Course {
    /// Which scenario.
    pub kind: Kind,
    /// The target speed, m/s.
    pub speed_mps: f64,
    /// The path the planner sends.
    pub path: Vec<PlannedPoint>,
    /// The obstacles the planner reports.
    pub obstacles: Vec<PlannedObstacle>,
    /// The cones on the ground (the double lane change).
    pub cones: Vec<Cone>,
    /// The lanes the cones mark (the double lane change).
    pub lanes: Vec<Lane>,
    /// The course's own frame: origin (east, north) and direction of travel (heading, rad):
    /// `x` along it, `y` to its left.
    pub frame: CourseFrame,
    /// Station range of the path that is scored (the track itself), m.
    pub scored_stations_m: (f64, f64),
}

/// A course's frame in the local frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CourseFrame {
    /// Origin east, m.
    pub east_m: f64,
    /// Origin north, m.
    pub north_m: f64,
    /// Direction of `x`, clockwise from north, rad.
    pub heading_rad: f64,
}

impl CourseFrame {
    /// `(x along, y to the left)` -> `(east, north)`.
    pub fn to_local(&self, x: f64, y: f64) -> (f64, f64) {
        let (s, c) = self.heading_rad.sin_cos();
        // Forward (sin h, cos h); left is (-cos h, sin h).
        (self.east_m + x * s - y * c, self.north_m + x * c + y * s)
    }

    /// `(east, north)` -> `(x along, y to the left)`.
    pub fn to_course(&self, east_m: f64, north_m: f64) -> (f64, f64) {
        let (s, c) = self.heading_rad.sin_cos();
        let (de, dn) = (east_m - self.east_m, north_m - self.north_m);
        (de * s + dn * c, -de * c + dn * s)
    }
}

/// The course's points in course coordinates, with target speed and corridor; converted to
/// planner points (local frame) by [`finish_path`].
struct CoursePoint {
    x: f64,
    y: f64,
    speed_mps: f64,
    y_left_edge: f64,
    y_right_edge: f64,
}

/// Converts course points to the planner's path: positions in the local frame, corridor as
/// distances from the point, and the target speed tapered so that the car can stop at the end.
fn finish_path(frame: &CourseFrame, points: &[CoursePoint]) -> Vec<PlannedPoint> {
    let mut out: Vec<PlannedPoint> = Vec::with_capacity(points.len());
    let mut stations = Vec::with_capacity(points.len());
    let mut s = 0.0;
    for (i, p) in points.iter().enumerate() {
        if i > 0 {
            let q = &points[i - 1];
            s += ((p.x - q.x).powi(2) + (p.y - q.y).powi(2)).sqrt();
        }
        stations.push(s);
    }
    let total = s;
    for (p, s) in points.iter().zip(stations) {
        let (east_m, north_m) = frame.to_local(p.x, p.y);
        let stop = (2.0 * PLANNER_DECEL_MPS2 * (total - s)).sqrt();
        out.push(PlannedPoint {
            east_m,
            north_m,
            speed_mps: p.speed_mps.min(stop),
            left_m: (p.y_left_edge - p.y).max(0.0),
            right_m: (p.y - p.y_right_edge).max(0.0),
        });
    }
    out
}

/// Quintic smoothstep `10 t^3 - 15 t^4 + 6 t^5` on [0, 1] (zero slope and curvature at both
/// ends), clamped outside.
fn smoothstep(t: f64) -> f64 {
    let t = t.clamp(0.0, 1.0);
    t * t * t * (10.0 + t * (-15.0 + 6.0 * t))
}

/// Course `x` of the cones along a lane's edges (both edges have cones at the same `x`).
pub fn cone_stations(lane: &Lane) -> impl Iterator<Item = f64> {
    stations(lane.x_start_m, lane.x_end_m, CONE_SPACING_M)
}

/// Course coordinates `x` from `from` to `to` (inclusive of `to`), at most `spacing` apart.
fn stations(from: f64, to: f64, spacing: f64) -> impl Iterator<Item = f64> {
    let n = ((to - from) / spacing).ceil().max(1.0) as usize;
    (0..=n).map(move |i| from + (to - from) * i as f64 / n as f64)
}

/// Distance to reach `speed` from rest with the launch and the car's speed loop (about
/// 1.2 m/s^2 on average, delay and lag included) plus 3 s to settle, m.
fn run_up_m(speed_mps: f64) -> f64 {
    (speed_mps * speed_mps / (2.0 * 1.2) + 3.0 * speed_mps + 20.0).max(30.0)
}

/// The ISO 3888-2 lanes for a vehicle `width_m` wide: sections 1, 3, 5.
pub fn dlc_lanes(width_m: f64) -> [Lane; 3] {
    let [l1, l2, l3, l4, l5] = DLC_SECTION_LENGTHS_M;
    let w1 = 1.1 * width_m + 0.25;
    let w3 = width_m + 1.0;
    let w5 = (1.3 * width_m + 0.25).min(DLC_EXIT_WIDTH_MAX_M);
    let y3_right = w1 / 2.0 + 1.0;
    let x3 = l1 + l2;
    let x5 = x3 + l3 + l4;
    [
        Lane {
            x_start_m: 0.0,
            x_end_m: l1,
            y_right_m: -w1 / 2.0,
            y_left_m: w1 / 2.0,
        },
        Lane {
            x_start_m: x3,
            x_end_m: x3 + l3,
            y_right_m: y3_right,
            y_left_m: y3_right + w3,
        },
        Lane {
            x_start_m: x5,
            x_end_m: x5 + l5,
            y_right_m: -w5 / 2.0,
            y_left_m: w5 / 2.0,
        },
    ]
}

/// The corridor's (left, right) edges at course `x` of the double lane change of `lanes`: the
/// lane whose cones are beside the point; across a gap, the envelope of the two lanes it joins.
pub fn dlc_edges(lanes: &[Lane; 3], x: f64) -> (f64, f64) {
    let [s1, s3, s5] = lanes;
    if x < s1.x_end_m {
        (s1.y_left_m, s1.y_right_m)
    } else if x < s3.x_start_m {
        (s3.y_left_m, s1.y_right_m)
    } else if x <= s3.x_end_m {
        (s3.y_left_m, s3.y_right_m)
    } else if x < s5.x_start_m {
        (s3.y_left_m, s5.y_right_m)
    } else {
        (s5.y_left_m, s5.y_right_m)
    }
}

/// Clearance the planner keeps between the body and every cone when the car follows its path
/// exactly, m: room for tracking error.
pub const DLC_PATH_MARGIN_M: f64 = 0.15;

/// One lateral transition of the planned path: a quintic from `(x0, y0)` to `(x1, y1)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transition {
    /// Start, course `x`, m.
    pub x0: f64,
    /// End, course `x`, m.
    pub x1: f64,
    /// `y` before, m.
    pub y0: f64,
    /// `y` after, m.
    pub y1: f64,
}

impl Transition {
    fn y(&self, x: f64) -> f64 {
        self.y0 + (self.y1 - self.y0) * smoothstep((x - self.x0) / (self.x1 - self.x0))
    }

    /// Largest |curvature| of the transition, 1/m: `|y''| / (1 + y'^2)^1.5`, sampled.
    fn max_curvature(&self) -> f64 {
        let a = self.y1 - self.y0;
        let d = self.x1 - self.x0;
        (0..=200)
            .map(|i| {
                let t = i as f64 / 200.0;
                let dy = a / d * 30.0 * t * t * (1.0 - t) * (1.0 - t);
                let ddy = a / (d * d) * 60.0 * t * (1.0 - t) * (1.0 - 2.0 * t);
                ddy.abs() / (1.0 + dy * dy).powf(1.5)
            })
            .fold(0.0, f64::max)
    }
}

/// The planner's double-lane-change path (course coordinates): two transitions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LaneChangeDesign {
    /// From section 1 into section 3.
    pub first: Transition,
    /// From section 3 into section 5.
    pub second: Transition,
}

impl LaneChangeDesign {
    /// The path's `y` at course `x`.
    pub fn y_at(&self, x: f64) -> f64 {
        if x <= self.second.x0 {
            self.first.y(x)
        } else {
            self.second.y(x)
        }
    }
}

/// The smallest clearance between the body, its rear axle on `y(x)` and heading along it, and
/// the cones of `lanes`, for rear-axle `x` in `[from, to]` (0.05 m steps), m.
fn path_clearance(body: &Body, lanes: &[Lane], y: impl Fn(f64) -> f64, from: f64, to: f64) -> f64 {
    let cones: Vec<(f64, f64)> = lanes
        .iter()
        .flat_map(|l| {
            cone_stations(l).flat_map(move |x| {
                [
                    (x, l.y_left_m + CONE_RADIUS_M),
                    (x, l.y_right_m - CONE_RADIUS_M),
                ]
            })
        })
        .collect();
    let mut worst = f64::INFINITY;
    let n = ((to - from) / 0.05).ceil() as usize;
    for i in 0..=n {
        let x = from + (to - from) * i as f64 / n as f64;
        let (ya, yb) = (y(x - 0.01), y(x + 0.01));
        // Course frame as a local frame heading "north" (x -> north, y -> west): the body
        // test is then the local one with heading = -atan(y').
        let heading = -((yb - ya) / 0.02).atan();
        for &(cx, cy) in &cones {
            if (cx - x).abs() > body.length_m + 1.0 {
                continue;
            }
            let d =
                super::metrics::distance_to_body(body, -y(x), x, heading, -cy, cx) - CONE_RADIUS_M;
            worst = worst.min(d);
        }
    }
    worst
}

/// The least-curvature transitions (by grid search over where each starts and ends, 0.5 m
/// steps) that keep the body [`DLC_PATH_MARGIN_M`] clear of every cone when followed exactly;
/// in each lane the path runs on the side nearer the next lane, the margin from its edge.
/// A planner's choice: the controllers track it and may use the corridor around it.
pub fn design_lane_change(body: &Body, lanes: &[Lane; 3]) -> LaneChangeDesign {
    let [s1, s3, s5] = *lanes;
    let half = 0.5 * body.width_m;
    let y1 = s1.y_left_m - half - DLC_PATH_MARGIN_M;
    let y3 = s3.y_right_m + half + DLC_PATH_MARGIN_M;
    let y5 = s5.y_left_m - half - DLC_PATH_MARGIN_M;
    let best = |x_lo: f64, x_hi: f64, y0: f64, y1: f64, lanes: &[Lane]| -> Transition {
        let mut best: Option<(f64, Transition)> = None;
        let n = ((x_hi - x_lo) / 0.5).round() as usize;
        for i in 0..=n {
            for j in i + 4..=n {
                let t = Transition {
                    x0: x_lo + 0.5 * i as f64,
                    x1: x_lo + 0.5 * j as f64,
                    y0,
                    y1,
                };
                let k = t.max_curvature();
                if best.as_ref().is_some_and(|(b, _)| *b <= k) {
                    continue;
                }
                let clear = path_clearance(
                    body,
                    lanes,
                    |x| t.y(x),
                    t.x0 - body.length_m,
                    t.x1 + body.length_m,
                );
                if clear >= DLC_PATH_MARGIN_M - 1e-9 {
                    best = Some((k, t));
                }
            }
        }
        // Note: the gap is long enough for the widest cars ISO 3888-2 covers; should no
        // candidate fit, the gap itself is the fallback.
        best.map(|(_, t)| t).unwrap_or(Transition {
            x0: x_lo,
            x1: x_hi,
            y0,
            y1,
        })
    };
    let first = best(s1.x_start_m, s3.x_end_m, y1, y3, &[s1, s3]);
    let second = best(s3.x_start_m, s5.x_end_m, y3, y5, &[s3, s5]);
    LaneChangeDesign { first, second }
}

/// The double lane change at `speed_mps` for a car with `body`, starting at the local origin
/// heading east.
pub fn double_lane_change(body: &Body, speed_mps: f64) -> Course {
    let lanes = dlc_lanes(body.width_m);
    let s5 = lanes[2];
    let design = design_lane_change(body, &lanes);
    let y_at = |x: f64| design.y_at(x);
    let edges = |x: f64| dlc_edges(&lanes, x);
    let run_up = run_up_m(speed_mps);
    let exit = (speed_mps * DLC_HOLD_AFTER_S + speed_mps * speed_mps / (2.0 * PLANNER_DECEL_MPS2))
        .max(40.0);
    let approach_spacing = (run_up / 80.0).max(1.0);
    let mut xs: Vec<f64> = stations(-run_up, 0.0, approach_spacing).collect();
    xs.pop();
    xs.extend(stations(0.0, s5.x_end_m, 0.5));
    xs.pop();
    xs.extend(stations(
        s5.x_end_m,
        s5.x_end_m + exit,
        (exit / 40.0).max(2.0),
    ));
    let points: Vec<CoursePoint> = xs
        .iter()
        .map(|&x| {
            let (left, right) = edges(x);
            CoursePoint {
                x,
                y: y_at(x),
                speed_mps,
                y_left_edge: left,
                y_right_edge: right,
            }
        })
        .collect();
    // The track starts `run_up` metres east of the local origin, where the car starts.
    let frame = CourseFrame {
        east_m: run_up,
        north_m: 0.0,
        heading_rad: std::f64::consts::FRAC_PI_2,
    };
    let mut cones = Vec::new();
    for lane in &lanes {
        for x in cone_stations(lane) {
            for y in [
                lane.y_left_m + CONE_RADIUS_M,
                lane.y_right_m - CONE_RADIUS_M,
            ] {
                let (east_m, north_m) = frame.to_local(x, y);
                cones.push(Cone {
                    east_m,
                    north_m,
                    radius_m: CONE_RADIUS_M,
                });
            }
        }
    }
    Course {
        kind: Kind::DoubleLaneChange,
        speed_mps,
        path: finish_path(&frame, &points),
        obstacles: Vec::new(),
        cones,
        lanes: lanes.to_vec(),
        frame,
        scored_stations_m: (run_up, run_up + s5.x_end_m),
    }
}

/// Obstacle radius, m, and where it stands after the run-up, m.
pub const OBSTACLE_RADIUS_M: f64 = 0.5;
/// Distance from the end of the run-up to the obstacle, m.
pub const OBSTACLE_AHEAD_M: f64 = 40.0;
/// Lane width of the obstacle road, m (a 3.5 m lane, the common main-road width).
pub const ROAD_LANE_WIDTH_M: f64 = 3.5;

/// A straight two-lane road; an obstacle on the car's lane centre; the corridor is both lanes.
pub fn obstacle(speed_mps: f64) -> Course {
    let run_up = run_up_m(speed_mps);
    let length = run_up + OBSTACLE_AHEAD_M + 60.0;
    let frame = CourseFrame {
        east_m: 0.0,
        north_m: 0.0,
        heading_rad: std::f64::consts::FRAC_PI_2,
    };
    let spacing = (length / 200.0).max(0.5);
    let points: Vec<CoursePoint> = stations(0.0, length, spacing)
        .map(|x| CoursePoint {
            x,
            y: 0.0,
            speed_mps,
            y_left_edge: 1.5 * ROAD_LANE_WIDTH_M,
            y_right_edge: -0.5 * ROAD_LANE_WIDTH_M,
        })
        .collect();
    let x_obstacle = run_up + OBSTACLE_AHEAD_M;
    let (east_m, north_m) = frame.to_local(x_obstacle, 0.0);
    Course {
        kind: Kind::Obstacle,
        speed_mps,
        path: finish_path(&frame, &points),
        obstacles: vec![PlannedObstacle {
            east_m,
            north_m,
            radius_m: OBSTACLE_RADIUS_M,
            walk: None,
        }],
        cones: Vec::new(),
        lanes: Vec::new(),
        frame,
        scored_stations_m: (x_obstacle - 30.0, x_obstacle + 30.0),
    }
}

/// The pedestrian of the crossing: radius, m; where it stands, m right of the car's lane
/// centre; its walking speed to the left, m/s; how near the car comes before it sets off, m.
pub const PEDESTRIAN_RADIUS_M: f64 = 0.4;
/// See [`PEDESTRIAN_RADIUS_M`].
pub const PEDESTRIAN_FROM_RIGHT_M: f64 = 6.0;
/// See [`PEDESTRIAN_RADIUS_M`].
pub const PEDESTRIAN_SPEED_MPS: f64 = 1.5;
/// See [`PEDESTRIAN_RADIUS_M`].
pub const PEDESTRIAN_STARTS_WITHIN_M: f64 = 35.0;

/// The obstacle's road (two lanes, the car in the right-hand one) with a pedestrian crossing it
/// from the right where the obstacle stood: it sets off as the car comes within 35 m and
/// walks to the left at 1.5 m/s, the planner sending its circle every tick.
pub fn crossing(speed_mps: f64) -> Course {
    let mut course = obstacle(speed_mps);
    course.kind = Kind::Crossing;
    let frame = course.frame;
    let x_crossing = run_up_m(speed_mps) + OBSTACLE_AHEAD_M;
    let (east_m, north_m) = frame.to_local(x_crossing, -PEDESTRIAN_FROM_RIGHT_M);
    let (left_e, left_n) = frame.to_local(x_crossing, 1.0);
    let (zero_e, zero_n) = frame.to_local(x_crossing, 0.0);
    course.obstacles = vec![PlannedObstacle {
        east_m,
        north_m,
        radius_m: PEDESTRIAN_RADIUS_M,
        walk: Some(ObstacleWalk {
            east_mps: (left_e - zero_e) * PEDESTRIAN_SPEED_MPS,
            north_mps: (left_n - zero_n) * PEDESTRIAN_SPEED_MPS,
            start_within_m: PEDESTRIAN_STARTS_WITHIN_M,
        }),
    }];
    course
}

/// Radius of the loop's half circles, m.
pub const LOOP_RADIUS_M: f64 = 20.0;
/// Length of the loop's straights, m.
pub const LOOP_STRAIGHT_M: f64 = 40.0;
/// Half width of the loop's lane, m.
pub const LOOP_HALF_LANE_M: f64 = 1.5;

/// One lap of a loop turning left: east along a straight, a half circle, west along the other
/// straight, a half circle back to the start; points 1 m apart.
pub fn parking_loop(speed_mps: f64) -> Course {
    let frame = CourseFrame {
        east_m: 0.0,
        north_m: 0.0,
        heading_rad: std::f64::consts::FRAC_PI_2,
    };
    let (r, l) = (LOOP_RADIUS_M, LOOP_STRAIGHT_M);
    let perimeter = 2.0 * l + 2.0 * std::f64::consts::PI * r;
    let n = perimeter.round() as usize;
    let at = |s: f64| -> (f64, f64) {
        // Course coordinates of arc length s (left turns: y grows).
        let half = std::f64::consts::PI * r;
        if s <= l {
            (s, 0.0)
        } else if s <= l + half {
            let a = (s - l) / r;
            (l + r * a.sin(), r - r * a.cos())
        } else if s <= 2.0 * l + half {
            (l - (s - l - half), 2.0 * r)
        } else {
            let a = (s - 2.0 * l - half) / r;
            (-r * a.sin(), r + r * a.cos())
        }
    };
    let points: Vec<CoursePoint> = (0..=n)
        .map(|i| {
            let (x, y) = at(perimeter * i as f64 / n as f64);
            CoursePoint {
                x,
                y,
                speed_mps,
                y_left_edge: y + LOOP_HALF_LANE_M,
                y_right_edge: y - LOOP_HALF_LANE_M,
            }
        })
        .collect();
    Course {
        kind: Kind::Loop,
        speed_mps,
        path: finish_path(&frame, &points),
        obstacles: Vec::new(),
        cones: Vec::new(),
        lanes: Vec::new(),
        frame,
        scored_stations_m: (10.0, perimeter - 10.0),
    }
}

/// The course of `kind` at `speed_mps` for a car with `body`.
pub fn course(kind: Kind, body: &Body, speed_mps: f64) -> Course {
    match kind {
        Kind::DoubleLaneChange => double_lane_change(body, speed_mps),
        Kind::Obstacle => obstacle(speed_mps),
        Kind::Loop => parking_loop(speed_mps),
        Kind::Crossing => crossing(speed_mps),
    }
}
