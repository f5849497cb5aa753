//! The simulated planner: turns a path (points with target speed and corridor), obstacles and
//! a map origin into the planner's bus frames (PATH_HEADER, PATH_POINT, PATH_LIMITS, OBSTACLE,
//! LOCAL_ORIGIN), each message with its own rolling counter, paced so that a path transfer
//! never floods the bus or the node's receive queue.
use catmodel::can::codec::{
    LocalOrigin, Obstacle, ObstacleCircle, PathHeader, PathLimits, PathPoint,
};
use catmodel::can::spec::{MAX_PATH_POINTS, OBSTACLE_SLOTS};
use catmodel::can::CanFrame;
use std::collections::VecDeque;

/// Planner frames sent per 20 ms tick at most: the node's rule for a conforming planner
/// ([`catmodel::node::PLANNER_FRAMES_PER_TICK`], 4: with the vehicle's inputs within the 12
/// frames a tick takes). A 256-point path (513 frames) takes 129 ticks.
pub const PATH_FRAMES_PER_TICK: usize = catmodel::node::PLANNER_FRAMES_PER_TICK;

/// One point of a planned path, as the planner knows it (f64, the local frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlannedPoint {
    /// Rear-axle position east of the local origin, m.
    pub east_m: f64,
    /// North of the local origin, m.
    pub north_m: f64,
    /// Target speed there, m/s.
    pub speed_mps: f64,
    /// Corridor: how far the body may stray left of the point, m.
    pub left_m: f64,
    /// How far the body may stray right of the point, m.
    pub right_m: f64,
}

/// An obstacle the planner reports, a circle in the local frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlannedObstacle {
    /// Centre east, m.
    pub east_m: f64,
    /// Centre north, m.
    pub north_m: f64,
    /// Radius, m.
    pub radius_m: f64,
    /// How it moves from there, if it does.
    pub walk: Option<ObstacleWalk>,
}

/// An obstacle that sets off across the car's way: from where the course puts it, at a
/// constant velocity, once the car's rear axle is within `start_within_m` of it along the
/// course. A course with one has the planner send every obstacle each tick where it is then
/// (a perception's rate), not queued behind the path ([`Planner::obstacle_frames`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObstacleWalk {
    /// Velocity east, m/s.
    pub east_mps: f64,
    /// Velocity north, m/s.
    pub north_mps: f64,
    /// How near the car comes along the course before it sets off, m.
    pub start_within_m: f64,
}

/// Why the planner refused a path.
#[derive(Debug, Clone, PartialEq)]
pub enum PlannerError {
    /// A path needs 2..=256 points.
    PointCount(usize),
    /// More obstacles than slots.
    TooManyObstacles(usize),
}

impl std::fmt::Display for PlannerError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PlannerError::PointCount(n) => {
                write!(f, "a path has 2..={MAX_PATH_POINTS} points, this one {n}")
            }
            PlannerError::TooManyObstacles(n) => {
                write!(f, "at most {OBSTACLE_SLOTS} obstacles, got {n}")
            }
        }
    }
}

impl std::error::Error for PlannerError {}

/// The planner's transmit side: a queue of frames, drained at [`PATH_FRAMES_PER_TICK`] per
/// tick, with one rolling counter per message.
#[derive(Debug, Default)]
pub struct Planner {
    queue: VecDeque<CanFrame>,
    next_path_id: u8,
    counters: [u8; 5],
}

/// Counter slots, one per planner message.
const HEADER: usize = 0;
const POINT: usize = 1;
const LIMITS: usize = 2;
const OBSTACLE: usize = 3;
const ORIGIN: usize = 4;

impl Planner {
    /// A planner with nothing queued.
    pub fn new() -> Self {
        Self::default()
    }

    fn counter(&mut self, slot: usize) -> u8 {
        let c = self.counters[slot];
        self.counters[slot] = (c + 1) & 0x0F;
        c
    }

    /// Queues the map origin (latitude page, then longitude page with the next counter).
    pub fn send_origin(&mut self, lat_deg: f64, lon_deg: f64) {
        let lat_e7 = (lat_deg * 1e7).round() as i32;
        let lon_e7 = (lon_deg * 1e7).round() as i32;
        let c = self.counter(ORIGIN);
        self.queue
            .push_back(LocalOrigin::Latitude { lat_e7 }.encode(c));
        let c = self.counter(ORIGIN);
        self.queue
            .push_back(LocalOrigin::Longitude { lon_e7 }.encode(c));
    }

    /// Queues a whole path under the next path id (header, then each point's PATH_POINT and
    /// PATH_LIMITS in index order); returns the id.
    pub fn send_path(&mut self, points: &[PlannedPoint]) -> Result<u8, PlannerError> {
        if points.len() < 2 || points.len() > MAX_PATH_POINTS {
            return Err(PlannerError::PointCount(points.len()));
        }
        let path_id = self.next_path_id;
        self.next_path_id = (path_id + 1) & 0x0F;
        let c = self.counter(HEADER);
        self.queue.push_back(
            PathHeader {
                path_id,
                count: points.len() as u16,
            }
            .encode(c),
        );
        for (i, p) in points.iter().enumerate() {
            let index = i as u8;
            let c = self.counter(POINT);
            self.queue.push_back(
                PathPoint {
                    path_id,
                    index,
                    east_m: p.east_m as f32,
                    north_m: p.north_m as f32,
                }
                .encode(c),
            );
            let c = self.counter(LIMITS);
            self.queue.push_back(
                PathLimits {
                    path_id,
                    index,
                    speed_mps: p.speed_mps as f32,
                    left_m: p.left_m as f32,
                    right_m: p.right_m as f32,
                }
                .encode(c),
            );
        }
        Ok(path_id)
    }

    /// Queues the obstacles into slots 0.., clearing the remaining slots.
    pub fn send_obstacles(&mut self, obstacles: &[PlannedObstacle]) -> Result<(), PlannerError> {
        if obstacles.len() > OBSTACLE_SLOTS {
            return Err(PlannerError::TooManyObstacles(obstacles.len()));
        }
        for slot in 0..OBSTACLE_SLOTS {
            let circle = obstacles.get(slot).map(|o| ObstacleCircle {
                east_m: o.east_m as f32,
                north_m: o.north_m as f32,
                radius_m: o.radius_m as f32,
            });
            let c = self.counter(OBSTACLE);
            self.queue.push_back(
                Obstacle {
                    obstacle_id: slot as u8,
                    circle,
                }
                .encode(c),
            );
        }
        Ok(())
    }

    /// OBSTACLE frames for `circles` (east, north, radius) in slots 0.., to send at once, not
    /// queued: an obstacle that moves, sent every tick where it is.
    pub fn obstacle_frames(&mut self, circles: &[(f64, f64, f64)]) -> Vec<CanFrame> {
        circles
            .iter()
            .take(OBSTACLE_SLOTS)
            .enumerate()
            .map(|(slot, &(east_m, north_m, radius_m))| {
                let c = self.counter(OBSTACLE);
                Obstacle {
                    obstacle_id: slot as u8,
                    circle: Some(ObstacleCircle {
                        east_m: east_m as f32,
                        north_m: north_m as f32,
                        radius_m: radius_m as f32,
                    }),
                }
                .encode(c)
            })
            .collect()
    }

    /// The frames to send during the next tick, at most [`PATH_FRAMES_PER_TICK`].
    pub fn take_tick_frames(&mut self) -> Vec<CanFrame> {
        let n = self.queue.len().min(PATH_FRAMES_PER_TICK);
        self.queue.drain(..n).collect()
    }

    /// Frames still queued.
    pub fn pending(&self) -> usize {
        self.queue.len()
    }
}

/// The frames of a straight path of `n` points due north, `spacing_m` apart (3 m/s, 2 m of
/// corridor each side), in the order this planner sends them: the tests' path.
#[cfg(test)]
pub(crate) fn straight_path_frames(n: usize, spacing_m: f64) -> Vec<CanFrame> {
    let points: Vec<PlannedPoint> = (0..n)
        .map(|i| PlannedPoint {
            east_m: 0.0,
            north_m: spacing_m * i as f64,
            speed_mps: 3.0,
            left_m: 2.0,
            right_m: 2.0,
        })
        .collect();
    path_frames(&points)
}

/// The frames of a path of `points`, in the order this planner sends them (tests).
#[cfg(test)]
pub(crate) fn path_frames(points: &[PlannedPoint]) -> Vec<CanFrame> {
    let mut planner = Planner::new();
    planner.send_path(points).expect("a valid path");
    let mut frames = Vec::new();
    while planner.pending() > 0 {
        frames.extend(planner.take_tick_frames());
    }
    frames
}
