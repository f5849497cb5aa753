//! The bus protocol of `catmodel.dbc` (the single source of truth): frame types, codecs of every
//! message, CRC-8/SAE-J1850, rolling counters, freshness, and candump text. `docs/bus.md`
//! describes the messages, the bus-load budget and this API.
//!
//! - [`frame`]: [`CanId`], [`CanFrame`], [`TimedFrame`].
//! - [`spec`]: the descriptor table (one [`spec::MessageSpec`] per DBC message) and the generic
//!   little-endian bit packer; `host-tests/tests/dbc.rs` checks it against the DBC.
//! - [`codec`]: one typed struct per message with `encode(&self, counter) -> CanFrame` and
//!   `decode(&CanFrame) -> Result<(Self, counter), DecodeError>`; [`codec::decode_input`] (the
//!   vehicle's reports) and [`codec::decode_planner`] (paths, obstacles, origin).
//! - [`crc`]: [`crc8_sae_j1850`] and the per-frame CRC of byte 7.
//! - [`counter`]: rolling-counter checking of the inputs.
//! - [`freshness`]: timeouts and ages of the inputs.
//! - [`candump`]: `parse_line` / `format_line` of the SocketCAN log format.
//!
//! Never panics on bus data: every decoder returns a typed [`DecodeError`] and the node counts
//! each rejection.
pub mod candump;
pub mod codec;
pub mod counter;
pub mod crc;
pub mod frame;
pub mod freshness;
pub mod spec;

pub use codec::{
    decode_input, decode_planner, ControlCommand, ControlStatus, DecodeError, Direction,
    EncodeReport, FallbackCause, GnssCogSog, GnssPosition, HealthFlags, InputMessage, LocalOrigin,
    ModelMode, ModelOutputs, NodeStatus, Obstacle, ObstacleCircle, PathHeader, PathLimits,
    PathPoint, PedalReport, PlannerMessage, Prediction, PredictionPoint, SpeedReport, StateMotion,
    StatePosition, SteeringReport,
};
pub use crc::crc8_sae_j1850;
pub use frame::{CanFrame, CanId, TimedFrame};
