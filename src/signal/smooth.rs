//! MATLAB `smooth(y, span)` (default method `'moving'`), the paper's "moving average filter with
//! a span of 10 elements" (II-C). Offline, f64, centred (zero-phase).
//!
//! MATLAB's semantics, reproduced:
//! - `span` is first limited to `length(y)`, then an even span is reduced by one (so
//!   `smooth(y, 10)` averages 9 samples: the paper's filter is really a span-9 average);
//! - away from the ends, `out[i]` is the mean of the `span` samples centred on `i`;
//! - near the ends the window shrinks symmetrically: `out[i]` is the mean of
//!   `y[i-w ..= i+w]` with `w = min((span-1)/2, i, n-1-i)`, so `out[0] = y[0]` and
//!   `out[n-1] = y[n-1]`.
//!
//! MATLAB treats NaN samples specially (it averages the non-NaN ones); here they are rejected.

/// Why [`smooth`] refused its input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SmoothError {
    /// `y` is empty.
    Empty,
    /// `span` is 0.
    ZeroSpan,
    /// `out` must have the length of `y`.
    OutputLengthMismatch,
    /// A sample is NaN or infinite.
    NonFinite {
        /// Index of the first offending sample.
        index: usize,
    },
}

/// Writes MATLAB `smooth(y, span)` into `out` (same length as `y`, same units).
pub fn smooth(y: &[f64], span: usize, out: &mut [f64]) -> Result<(), SmoothError> {
    let n = y.len();
    if n == 0 {
        return Err(SmoothError::Empty);
    }
    if span == 0 {
        return Err(SmoothError::ZeroSpan);
    }
    if out.len() != n {
        return Err(SmoothError::OutputLengthMismatch);
    }
    if let Some(index) = y.iter().position(|v| !v.is_finite()) {
        return Err(SmoothError::NonFinite { index });
    }
    let span = span.min(n);
    let width = if span.is_multiple_of(2) {
        span - 1
    } else {
        span
    };
    let half = (width - 1) / 2;
    for (i, o) in out.iter_mut().enumerate() {
        let w = half.min(i).min(n - 1 - i);
        // Note: i - w >= 0 and i + w <= n - 1 by the choice of w, so the range is in bounds.
        let window = y.get(i - w..=i + w).unwrap_or(&[]);
        let sum: f64 = window.iter().sum();
        *o = sum / (2 * w + 1) as f64;
    }
    Ok(())
}
