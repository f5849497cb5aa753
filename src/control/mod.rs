//! The controller's side of the node: what the planner sends (paths, obstacles, the map
//! origin), the path geometry a controller tracks, the model-predictive controller and the
//! reference controller it is measured against.
//!
//! - [`path`]: fixed-capacity path storage; projection of the rear axle (station, lateral and
//!   heading error); the reference (pose, curvature, target speed, corridor) at any station.
//! - [`planner`]: assembling PATH_HEADER / PATH_POINT / PATH_LIMITS frames into a path (a new
//!   path replaces the active one only once complete), the obstacle slots, LOCAL_ORIGIN.
//! - [`mpc`]: model-predictive control over the identified models (docs/mpc.md), which turns
//!   the path, its corridor and the obstacles into steering and speed commands every 20 ms.
//! - [`pure_pursuit`]: pure pursuit with a speed-dependent lookahead and a PI speed loop: the
//!   reference controller the model-predictive controller is measured against.
//!
//! Like the rest of the core: never allocates, never reads a clock, never panics on input;
//! configuration apart from state.
pub mod mpc;
pub mod path;
pub mod planner;
pub mod pure_pursuit;
