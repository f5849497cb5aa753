//! Scoring a closed-loop run on ground truth: the body against cones and obstacles (checked at
//! every 1 ms plant step, so that a graze between two 10 ms truth rows still counts), the rear
//! axle's lateral error from the planner's path, speeds and time.
//!
//! The body is a rectangle (`Body`: width, length, rear overhang) around the rear axle and
//! heading; a cone is hit when the rectangle touches its base circle (distance from the circle's
//! centre to the rectangle <= its radius).
use serde::Serialize;

use super::scenario::{Cone, Course};
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

/// Running scores, updated at every plant step.
#[derive(Debug, Clone)]
pub struct Scorer {
    body: Body,
    cones: Vec<Cone>,
    cone_clearance_m: Vec<f64>,
    obstacles: Vec<(f64, f64, f64)>,
    obstacle_clearance_m: f64,
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
        }
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

    /// The smallest clearance between body and obstacle, m (negative: a collision).
    pub fn obstacle_clearance_m(&self) -> Option<f64> {
        self.obstacle_clearance_m
            .is_finite()
            .then_some(self.obstacle_clearance_m)
    }
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
    /// Smallest body-cone clearance, m.
    pub min_cone_clearance_m: Option<f64>,
    /// Smallest body-obstacle clearance, m (negative: a collision).
    pub min_obstacle_clearance_m: Option<f64>,
    /// Whether the rear axle got past the scored range's end.
    pub completed: bool,
    /// RMS of the rear axle's lateral error from the path over the scored range, m (truth).
    pub lateral_rms_m: Option<f64>,
    /// Largest |lateral error| over the scored range, m.
    pub lateral_max_m: Option<f64>,
    /// Time the rear axle took across the scored range, s.
    pub scored_time_s: Option<f64>,
    /// Time the controller drove (from engagement to the end of the run), s.
    pub driven_time_s: f64,
    /// Simulated time, s.
    pub total_time_s: f64,
    /// Ticks by CONTROL_COMMAND status while engaged: no path, tracking, avoiding, fallback.
    pub status_ticks: [u64; 4],
    /// Whether the run is clean: no cone hit, no collision, completed.
    pub clean: bool,
}
