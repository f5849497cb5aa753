//! Models: continuous transfer function ([`tf`]) -> controllable canonical state space
//! ([`ss`]) -> ZOH discretization ([`zoh`], f64, offline) -> the f32 runtime blocks
//! ([`block`], with input [`delay`] lines) the node steps every 20 ms; the published models
//! of eq 5 and eq 7 ([`paper`]); the kinematic (eq 8) and dynamic bicycle models, hybrid
//! switching and the horizon predictor.
//!
//! Nothing here allocates, reads a clock or panics on data: bad models are typed
//! [`tf::ModelError`]s.

pub mod block;
pub mod delay;
pub mod paper;
pub mod ss;
pub mod tf;
pub mod zoh;

pub mod dynamic;
pub mod hybrid;
pub mod kinematic;
pub mod predictor;

pub use block::{MisoBlock, MisoBlockState, SsBlock, SsBlockState};
pub use delay::{DelayLine, DelayLineState};
pub use tf::{ModelError, TransferFunction, MAX_ORDER};
