//! catmodel core: the mathematics of the CAT Vehicle system-identification paper
//! (Sheetz, Tadros, Risso, Sprinkle; University of Arizona) and the CAN node that runs it.
//!
//! This crate is `#![no_std]` outside its own unit tests. It never reads a clock (time is always
//! an argument), never allocates, and never panics on input: every function that can meet bad
//! data returns a typed error or a counted rejection. Configuration (immutable coefficients) is
//! kept apart from state (delay lines, model states), `process(&self, state: &mut S, x)` style.
//!
//! Reading order, top-down, with the paper's equations:
//! - [`vehicle`]: steering percent -> centre angle -> radius of curvature (eq 2) -> Ackermann
//!   inner/outer wheel angles (eq 3, 4).
//! - [`signal`]: the uniform 20 ms grid (eq 1), FIR lowpass design and streaming FIR, moving
//!   average, zero-phase filtering, MATLAB-compatible `smooth` (paper II-C).
//! - [`model`]: transfer function -> state space -> ZOH discretization, input delay lines, the
//!   internal-controller model (eq 5) and the dx/dt MISO model (eq 7), the kinematic bicycle
//!   model (eq 8), a dynamic bicycle model, hybrid switching, the horizon predictor.
//! - [`geodesy`]: WGS-84 latitude/longitude <-> local east/north metres.
//! - [`metrics`]: fit % as MATLAB `compare`, mean square error (paper II-E).
//! - [`math`]: the few transcendental functions the node uses, with measured error bounds.
//! - [`control`]: the planner's paths, obstacles and origin; path geometry; the reference
//!   controller (pure pursuit).
//! - [`can`]: the bus protocol of `catmodel.dbc`: frame codecs, CRC-8/SAE-J1850, rolling
//!   counters, freshness, candump text.
//! - [`control`]: the model-predictive controller (speed and steering plans over 2 s).
//! - [`node`]: `Node::step`, the pure 20 ms tick that the board, QEMU and host replay all run.
#![cfg_attr(not(test), no_std)]
#![cfg_attr(
    not(test),
    deny(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic,
        clippy::indexing_slicing,
        clippy::unreachable,
        clippy::todo,
        clippy::unimplemented
    )
)]
#![warn(missing_docs)]

pub mod can;
pub mod control;
pub mod geodesy;
pub mod image;
mod in_place;
pub mod math;
pub mod metrics;
pub mod model;
pub mod node;
pub mod signal;
pub mod vehicle;

/// Sample period of the vehicle bus, of every model and of the node's tick, us: 20 ms = 50 Hz
/// (paper II-B: "the vehicle collects data ... every 0.02 seconds"). The one definition of the
/// period: everything else (the seconds below, the firmware's tick, the model file's
/// `sample_time_s` check, xtask's timing) derives from it. Timestamps in the node are us.
pub const SAMPLE_PERIOD_US: u64 = 20_000;
/// [`SAMPLE_PERIOD_US`] in seconds, f32 (the node's arithmetic): exactly the f32 nearest 0.02.
pub const SAMPLE_PERIOD_S: f32 = SAMPLE_PERIOD_US as f32 / 1_000_000.0;
/// [`SAMPLE_PERIOD_US`] in seconds, f64 (offline work: discretization, identification).
pub const SAMPLE_PERIOD_S_F64: f64 = SAMPLE_PERIOD_US as f64 / 1_000_000.0;
