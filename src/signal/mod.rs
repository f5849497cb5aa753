//! Signal processing of the paper's preprocessing pipeline (section II-C) and of the node.
//!
//! Offline (f64, on slices, caller-provided output and scratch, no allocation):
//! [`resample`] (the uniform grid of eq 1 and linear interpolation of multi-rate logs),
//! [`fir::design_lowpass`] (the "20th order FIR low pass filter", equal to `scipy.signal.firwin`),
//! [`filtfilt`] (zero-phase, equal to `scipy.signal.filtfilt`), [`smooth`] (MATLAB `smooth`,
//! the "moving average filter with a span of 10 elements").
//!
//! Runtime (f32, configuration separate from state, `process(&self, &mut state, x)`):
//! [`fir::Fir`] + [`fir::FirState`] and [`moving_average::MovingAverage`] +
//! [`moving_average::MovingAverageState`].
//!
//! Nothing here reads a clock, allocates or panics on input: bad input is a typed error.

pub mod filtfilt;
pub mod fir;
pub mod moving_average;
pub mod resample;
pub mod smooth;

pub use filtfilt::{filtfilt, filtfilt_scratch_len, FiltfiltError};
pub use fir::{design_lowpass, FilterError, Fir, FirState};
pub use moving_average::{MovingAverage, MovingAverageState};
pub use resample::{
    fixed_period_grid, fixed_period_len, interp_linear, uniform_grid_eq1, ResampleError,
};
pub use smooth::{smooth, SmoothError};
