//! The controller: model-predictive control over the identified models, which turns a planned
//! path, its corridor and obstacles into steering and speed commands every 20 ms.
pub mod mpc;
