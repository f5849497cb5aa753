//! Uniform time grids and linear interpolation of multi-rate logs onto them (paper II-C, eq 1).
//!
//! The sensors report on their own clocks (vehicle bus every 0.02 s, GNSS every 0.01 s, none of
//! them exactly uniform). Each signal is a column of a table whose time column `t` is strictly
//! increasing; a sensor that did not report at a row has NaN there. [`interp_linear`] maps one
//! such column onto a grid, using only that column's finite samples.
//!
//! Offline, f64, slices in, caller's `&mut [f64]` out; O(len(t) + len(grid)).

/// The paper's number of uniform samples per experiment (eq 1).
pub const PAPER_SAMPLES_PER_EXPERIMENT: usize = 3000;

/// Why a grid or an interpolation was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ResampleError {
    /// No time samples, or an empty output grid.
    Empty,
    /// `t` and `y` (or `grid` and `out`) differ in length.
    LengthMismatch,
    /// A time value (of the data, the grid, or a grid bound) is NaN or infinite.
    NonFiniteTime {
        /// Index of the first offending value (0 for a grid bound).
        index: usize,
    },
    /// `t[index] <= t[index - 1]`: time must strictly increase with the index (for a grid bound:
    /// the end is not after the start).
    TimeNotIncreasing {
        /// Index of the first offending value.
        index: usize,
    },
    /// `grid[index] < grid[index - 1]`: the grid must not decrease.
    GridNotIncreasing {
        /// Index of the first offending grid point.
        index: usize,
    },
    /// `grid[index]` lies before the first or after the last finite sample of the signal
    /// (no extrapolation).
    GridOutsideData {
        /// Index of the first offending grid point.
        index: usize,
    },
    /// Every sample of the signal is NaN.
    NoValidSamples,
    /// The period is not finite and positive.
    InvalidPeriod,
    /// The fixed-period grid would have more than 2^32 points.
    GridTooLong,
}

/// Eq 1 of the paper: `t(k) = (k - 1) (t_e - t_s) / N + t_s`, k = 1..N, with N = `out.len()`
/// (3000 in the paper). Seconds. As printed, the grid starts at `t_s` and stops one step short
/// of `t_e` (the last point is `t_e - (t_e - t_s)/N`), unlike `linspace`; the step is
/// `(t_e - t_s) / N`.
pub fn uniform_grid_eq1(t_s: f64, t_e: f64, out: &mut [f64]) -> Result<(), ResampleError> {
    check_bounds(t_s, t_e)?;
    if out.is_empty() {
        return Err(ResampleError::Empty);
    }
    let step = (t_e - t_s) / out.len() as f64;
    for (k, o) in out.iter_mut().enumerate() {
        *o = k as f64 * step + t_s;
    }
    Ok(())
}

/// Number of points of the fixed-period grid `t_s, t_s + T, ...` that do not pass `t_e`
/// (a point within 1e-9 T of `t_e` counts as on it, so 0..10 s at 0.02 s gives 501 points).
/// Seconds.
pub fn fixed_period_len(t_s: f64, t_e: f64, period_s: f64) -> Result<usize, ResampleError> {
    check_bounds(t_s, t_e)?;
    check_period(period_s)?;
    let steps = libm::floor((t_e - t_s) / period_s + 1e-9);
    // NaN cannot occur (finite, ordered bounds and a positive period), but fails this test too.
    if steps.is_nan() || steps >= 4_294_967_295.0 {
        return Err(ResampleError::GridTooLong);
    }
    Ok(steps as usize + 1)
}

/// The fixed-period grid `out[k] = t_s + k period_s` (each point computed from k, so no
/// accumulated rounding); size `out` with [`fixed_period_len`]. The node's period is
/// [`crate::SAMPLE_PERIOD_S`] (0.02 s). Seconds.
pub fn fixed_period_grid(t_s: f64, period_s: f64, out: &mut [f64]) -> Result<(), ResampleError> {
    if !t_s.is_finite() {
        return Err(ResampleError::NonFiniteTime { index: 0 });
    }
    check_period(period_s)?;
    if out.is_empty() {
        return Err(ResampleError::Empty);
    }
    for (k, o) in out.iter_mut().enumerate() {
        *o = t_s + k as f64 * period_s;
    }
    Ok(())
}

/// Linearly interpolates the signal (`t`, `y`) at the points of `grid` into `out`, as
/// `numpy.interp` does inside the data, skipping NaN samples of `y` (the interpolation runs
/// between the neighbouring finite samples). `t` must be finite and strictly increasing; `grid`
/// finite and non-decreasing, and within [first, last] finite sample (no extrapolation).
/// Units: `t` and `grid` in seconds, `out` in the units of `y`.
pub fn interp_linear(
    t: &[f64],
    y: &[f64],
    grid: &[f64],
    out: &mut [f64],
) -> Result<(), ResampleError> {
    if t.is_empty() || grid.is_empty() {
        return Err(ResampleError::Empty);
    }
    if t.len() != y.len() || grid.len() != out.len() {
        return Err(ResampleError::LengthMismatch);
    }
    check_increasing(t)?;
    if let Some(index) = grid.iter().position(|g| !g.is_finite()) {
        return Err(ResampleError::NonFiniteTime { index });
    }
    if let Some(index) = grid.windows(2).position(|w| w.get(1) < w.first()) {
        return Err(ResampleError::GridNotIncreasing { index: index + 1 });
    }
    if !y.iter().any(|v| v.is_finite()) {
        return Err(ResampleError::NoValidSamples);
    }

    let n = t.len();
    let sample = |i: usize| -> Option<(f64, f64)> {
        match (t.get(i), y.get(i)) {
            (Some(&ti), Some(&yi)) if yi.is_finite() => Some((ti, yi)),
            _ => None,
        }
    };
    // `left`: last finite sample with t <= g; `scan`: first index with t > g;
    // `right`: first finite sample at index >= scan (no finite sample in [scan, right)).
    let mut left: Option<(f64, f64)> = None;
    let mut scan = 0;
    let mut right = 0;
    for (index, (&g, o)) in grid.iter().zip(out.iter_mut()).enumerate() {
        while let Some(&ti) = t.get(scan) {
            if ti > g {
                break;
            }
            if let Some(s) = sample(scan) {
                left = Some(s);
            }
            scan += 1;
        }
        let Some((t0, y0)) = left else {
            return Err(ResampleError::GridOutsideData { index });
        };
        if t0 == g {
            *o = y0;
            continue;
        }
        right = right.max(scan);
        while right < n && sample(right).is_none() {
            right += 1;
        }
        let Some((t1, y1)) = sample(right) else {
            return Err(ResampleError::GridOutsideData { index });
        };
        // numpy.interp's formula.
        let slope = (y1 - y0) / (t1 - t0);
        *o = slope * (g - t0) + y0;
    }
    Ok(())
}

fn check_bounds(t_s: f64, t_e: f64) -> Result<(), ResampleError> {
    if !(t_s.is_finite() && t_e.is_finite()) {
        return Err(ResampleError::NonFiniteTime { index: 0 });
    }
    if t_e <= t_s {
        return Err(ResampleError::TimeNotIncreasing { index: 1 });
    }
    Ok(())
}

fn check_period(period_s: f64) -> Result<(), ResampleError> {
    if period_s.is_finite() && period_s > 0.0 {
        Ok(())
    } else {
        Err(ResampleError::InvalidPeriod)
    }
}

fn check_increasing(t: &[f64]) -> Result<(), ResampleError> {
    let mut prev = f64::NEG_INFINITY;
    for (index, &ti) in t.iter().enumerate() {
        if !ti.is_finite() {
            return Err(ResampleError::NonFiniteTime { index });
        }
        if ti <= prev {
            return Err(ResampleError::TimeNotIncreasing { index });
        }
        prev = ti;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eq1_grid() {
        let mut g = [0.0; 4];
        uniform_grid_eq1(1.0, 3.0, &mut g).unwrap();
        assert_eq!(g, [1.0, 1.5, 2.0, 2.5]);
    }

    #[test]
    fn fixed_grid_counts_endpoint() {
        assert_eq!(fixed_period_len(0.0, 10.0, 0.02).unwrap(), 501);
        assert_eq!(fixed_period_len(0.0, 0.05, 0.02).unwrap(), 3);
        assert_eq!(
            fixed_period_len(0.0, 1.0, 0.0),
            Err(ResampleError::InvalidPeriod)
        );
    }

    #[test]
    fn nan_skipped_per_signal() {
        let t = [0.0, 1.0, 2.0, 3.0];
        let y = [0.0, f64::NAN, f64::NAN, 3.0];
        let mut out = [0.0; 3];
        interp_linear(&t, &y, &[0.5, 1.0, 3.0], &mut out).unwrap();
        assert_eq!(out, [0.5, 1.0, 3.0]);
        assert_eq!(
            interp_linear(&t, &[f64::NAN, 1.0, 2.0, 3.0], &[0.5], &mut out[..1]),
            Err(ResampleError::GridOutsideData { index: 0 })
        );
        assert_eq!(
            interp_linear(&[0.0, 1.0, 1.0], &[1.0; 3], &[0.5], &mut out[..1]),
            Err(ResampleError::TimeNotIncreasing { index: 2 })
        );
    }
}
