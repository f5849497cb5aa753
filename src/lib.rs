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

#[cfg(all(target_os = "none", any(feature = "board", feature = "qemu")))]
pub mod app;
pub mod can;
pub mod control;
pub mod geodesy;
pub mod health;
pub mod math;
pub mod metrics;
pub mod model;
pub mod node;
#[cfg(all(target_os = "none", any(feature = "board", feature = "qemu")))]
pub mod platform;
pub mod signal;
pub mod vehicle;

/// Sample period of the vehicle bus and of every model: 20 ms = 50 Hz (paper II-B: "the vehicle
/// collects data ... every 0.02 seconds").
pub const SAMPLE_PERIOD_S: f32 = 0.02;
/// [`SAMPLE_PERIOD_S`] in microseconds, the unit of every timestamp in the node.
pub const SAMPLE_PERIOD_US: u64 = 20_000;
