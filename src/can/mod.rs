//! The bus protocol of `catmodel.dbc` (the single source of truth): frame types, codecs of every
//! message, CRC-8/SAE-J1850, rolling counters, freshness, and candump text.
//!
//! Never panics on bus data: every decoder returns a typed [`DecodeError`]-style result and the
//! node counts each rejection.
pub mod frame;

pub use frame::{CanFrame, CanId, TimedFrame};
