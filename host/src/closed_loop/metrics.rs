//! Scoring a closed-loop run on ground truth: the body against cones and obstacles (checked at
//! every 1 ms plant step, so that a graze between two 10 ms truth rows still counts), the rear
//! axle's lateral error from the planner's path, speeds and time.
//!
//! The body is a rectangle (`Body`: width, length, rear overhang) around the rear axle and
//! heading; a cone is hit when the rectangle touches its base circle (distance from the circle's
//! centre to the rectangle <= its radius). Not touching a cone is not enough: the car must go
//! *through* the track, so every pair of cones is a gate, and the rear axle must cross each gate
//! between its two lane edges (a missed gate is scored by how far outside it the axle crossed).
use std::collections::BTreeMap;

use serde::Serialize;

use super::scenario::{self, Cone, Course, CourseFrame};
use crate::sim::config::Body;

/// Distance from `(east, north)` to the body whose rear axle is at `(x, y)` with `heading`
/// (clockwise from north), m; 0 inside.
pub fn distance_to_body(body: &Body, x: f64, y: f64, heading: f64, east: f64, north: f64) -> f64 {
    let (s, c) = heading.sin_cos();
    let (de, dn) = (east - x, north - y);
    // Along the heading (sin h, cos h) and to its right (cos h, -sin h).
    let u = de * s + dn * c;
    let v = de * c - dn * s;
    let (u_min, u_max) = (-body.rear_overhang_m, body.length_m - body.rear_overhang_m);
    let du = (u_min - u).max(u - u_max).max(0.0);
    let dv = (v.abs() - 0.5 * body.width_m).max(0.0);
    (du * du + dv * dv).sqrt()
}

/// The body's four corners (east, north), rear right first, counter-clockwise seen from above.
pub fn body_corners(body: &Body, x: f64, y: f64, heading: f64) -> [(f64, f64); 4] {
    let (s, c) = heading.sin_cos();
    let at = |u: f64, v: f64| (x + u * s + v * c, y + u * c - v * s);
    let (back, front, half) = (
        -body.rear_overhang_m,
        body.length_m - body.rear_overhang_m,
        0.5 * body.width_m,
    );
    [
        at(back, half),
        at(front, half),
        at(front, -half),
        at(back, -half),
    ]
}

/// A gate of the track: course `x` and the lane's edges there.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Gate {
    x_m: f64,
    y_right_m: f64,
    y_left_m: f64,
}

/// Running scores, updated at every plant step.
#[derive(Debug, Clone)]
pub struct Scorer {
    body: Body,
    cones: Vec<Cone>,
    cone_clearance_m: Vec<f64>,
    obstacles: Vec<(f64, f64, f64)>,
    obstacle_clearance_m: f64,
    frame: CourseFrame,
    gates: Vec<Gate>,
    /// How far outside each gate the rear axle crossed it (0 inside), m; `None` not yet.
    gate_miss_m: Vec<Option<f64>>,
    last_x_m: Option<f64>,
}

impl Scorer {
    /// Scores against `course`'s cones and obstacles.
    pub fn new(body: &Body, course: &Course) -> Self {
        Self {
            body: body.clone(),
            cones: course.cones.clone(),
            cone_clearance_m: vec![f64::INFINITY; course.cones.len()],
            obstacles: course
                .obstacles
                .iter()
                .map(|o| (o.east_m, o.north_m, o.radius_m))
                .collect(),
            obstacle_clearance_m: f64::INFINITY,
            frame: course.frame,
            gates: course
                .lanes
                .iter()
                .flat_map(|l| {
                    scenario::cone_stations(l).map(move |x_m| Gate {
                        x_m,
                        y_right_m: l.y_right_m,
                        y_left_m: l.y_left_m,
                    })
                })
                .collect(),
            gate_miss_m: course
                .lanes
                .iter()
                .flat_map(scenario::cone_stations)
                .map(|_| None)
                .collect(),
            last_x_m: None,
        }
    }

    /// The obstacles are now at these circles (east, north, radius), in the course's order:
    /// obstacles that move.
    pub fn move_obstacles(&mut self, circles: &[(f64, f64, f64)]) {
        self.obstacles.clear();
        self.obstacles.extend_from_slice(circles);
    }

    /// The body at rear axle `(x, y)`, `heading`.
    pub fn observe(&mut self, x: f64, y: f64, heading: f64) {
        let reach = self.body.length_m + self.body.width_m;
        for (cone, best) in self.cones.iter().zip(&mut self.cone_clearance_m) {
            // Far cones cannot be the nearest: skip the exact test.
            if (cone.east_m - x).abs() > reach || (cone.north_m - y).abs() > reach {
                continue;
            }
            let d = distance_to_body(&self.body, x, y, heading, cone.east_m, cone.north_m)
                - cone.radius_m;
            *best = best.min(d);
        }
        for &(e, n, r) in &self.obstacles {
            let d = distance_to_body(&self.body, x, y, heading, e, n) - r;
            self.obstacle_clearance_m = self.obstacle_clearance_m.min(d);
        }
        let (cx, cy) = self.frame.to_course(x, y);
        if let Some(prev) = self.last_x_m {
            for (gate, miss) in self.gates.iter().zip(&mut self.gate_miss_m) {
                if miss.is_none() && prev < gate.x_m && cx >= gate.x_m {
                    *miss = Some((gate.y_right_m - cy).max(cy - gate.y_left_m).max(0.0));
                }
            }
        }
        self.last_x_m = Some(cx);
    }

    /// How far outside each gate the rear axle crossed it, m (0: through the gate); a gate not
    /// reached is `None`.
    pub fn gate_misses_m(&self) -> &[Option<f64>] {
        &self.gate_miss_m
    }

    /// Gates the rear axle crossed outside the lane.
    pub fn gates_missed(&self) -> usize {
        self.gate_miss_m
            .iter()
            .filter(|m| m.is_some_and(|d| d > 0.0))
            .count()
    }

    /// Cones touched (clearance <= 0), and the smallest clearance to any cone, m.
    pub fn cones(&self) -> (usize, Option<f64>) {
        let hits = self.cone_clearance_m.iter().filter(|d| **d <= 0.0).count();
        let min = self
            .cone_clearance_m
            .iter()
            .copied()
            .filter(|d| d.is_finite())
            .reduce(f64::min);
        (hits, min)
    }

    /// The smallest clearance of the body to each cone so far, m (infinite: never near).
    pub fn cone_clearances_m(&self) -> &[f64] {
        &self.cone_clearance_m
    }

    /// The smallest clearance between body and obstacle, m (negative: a collision).
    pub fn obstacle_clearance_m(&self) -> Option<f64> {
        self.obstacle_clearance_m
            .is_finite()
            .then_some(self.obstacle_clearance_m)
    }
}

/// How far the side of a body `width_m` wide, its rear axle `lateral_m` right of the path
/// (negative: left), is outside the corridor `(left_m, right_m)` there, m (0: inside).
pub fn corridor_exit_m(lateral_m: f64, width_m: f64, (left_m, right_m): (f64, f64)) -> f64 {
    let half = width_m / 2.0;
    (lateral_m + half - right_m)
        .max(-lateral_m + half - left_m)
        .max(0.0)
}

/// The scores of a run (`metrics.json`).
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Metrics {
    /// Scenario name.
    pub scenario: String,
    /// Controller name.
    pub controller: String,
    /// Receiver: `rtk` or `standard`.
    pub receiver: String,
    /// Target speed, m/s.
    pub target_speed_mps: f64,
    /// Truth speed when the body's front reached the scored range's start, m/s.
    pub entry_speed_mps: Option<f64>,
    /// Cones the body touched.
    pub cone_hits: usize,
    /// Gates (pairs of cones) the rear axle crossed outside the lane.
    pub gates_missed: usize,
    /// Smallest body-cone clearance, m.
    pub min_cone_clearance_m: Option<f64>,
    /// Smallest body-obstacle clearance, m (negative: a collision).
    pub min_obstacle_clearance_m: Option<f64>,
    /// Whether the rear axle got past the scored range's end, with the controller driving
    /// (engaged before it got there).
    pub completed: bool,
    /// RMS of the rear axle's lateral error from the path over the scored range, m (truth).
    pub lateral_rms_m: Option<f64>,
    /// Largest |lateral error| over the scored range, m.
    pub lateral_max_m: Option<f64>,
    /// How far the body's side at the rear axle (truth) went outside the planner's corridor
    /// over the scored range, at most, m (0: never; `None`: nothing scored).
    pub corridor_exit_m: Option<f64>,
    /// Time the rear axle took across the scored range, s.
    pub scored_time_s: Option<f64>,
    /// Time the controller drove (from engagement to the end of the run), s.
    pub driven_time_s: f64,
    /// Simulated time, s.
    pub total_time_s: f64,
    /// Ticks by CONTROL_COMMAND status while engaged: no path, tracking, avoiding, fallback.
    pub status_ticks: [u64; 4],
    /// The fallback's ticks while engaged by CONTROL_COMMAND `fallback_reason` (the DBC's
    /// names: `lost_path`, `no_passage`, ...); only the reasons that occurred.
    pub fallback_ticks: BTreeMap<String, u64>,
    /// Whether the run is clean: no cone hit, no gate missed, no collision, completed, and,
    /// off the cone track (the obstacle, the loop), the body never wholly outside the corridor
    /// ([`Self::corridor_exit_m`] below the body's width: the car never left the road). A
    /// standard receiver's metre of bias puts the body's side over the corridor's edge on
    /// most runs (the node cannot know that bias); `corridor_exit_m` reports by how much.
    pub clean: bool,
}
