//! (temporary: replaced by the full module list on branch `model`)
pub mod dynamic;
pub mod hybrid;
pub mod kinematic;
pub mod predictor;
