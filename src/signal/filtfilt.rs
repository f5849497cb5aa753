//! Offline zero-phase FIR filtering, equal to `scipy.signal.filtfilt(b, [1.0], x)` with its
//! defaults (the paper's offline pipeline filtered logs without delay, II-C).
//!
//! scipy's defaults, reproduced: `padtype='odd'`, `padlen = 3 * len(b)`: the signal is extended
//! at each end by `padlen` samples mirrored through the end value (`2 x[0] - x[padlen..1]`);
//! it is filtered forward with `lfilter_zi` initial conditions scaled by the first extended
//! sample, then backward the same way, and the extension is cut off. For an FIR filter,
//! `lfilter_zi(b, 1) * v` is exactly the state left by an input that was `v` forever, so both
//! passes here are direct convolutions whose history before the first sample is that constant.

/// Why [`filtfilt`] refused its input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FiltfiltError {
    /// `b` is empty.
    NoTaps,
    /// A tap or a sample is NaN or infinite.
    NonFinite,
    /// The signal must be longer than `padlen = 3 * len(b)` (scipy raises the same).
    SignalTooShort {
        /// Samples given.
        len: usize,
        /// 3 * number of taps.
        padlen: usize,
    },
    /// `y` must have the length of `x`.
    OutputLengthMismatch,
    /// `scratch` must hold [`filtfilt_scratch_len`] values.
    ScratchTooSmall {
        /// Values needed.
        needed: usize,
    },
}

/// Scratch length [`filtfilt`] needs: the signal plus `3 * taps` samples at each end.
pub const fn filtfilt_scratch_len(num_taps: usize, signal_len: usize) -> usize {
    signal_len + 6 * num_taps
}

/// Zero-phase filters `x` with the FIR taps `b` into `y` (same length as `x`), using `scratch`
/// (at least [`filtfilt_scratch_len`]`(b.len(), x.len())` values). Equal to
/// `scipy.signal.filtfilt(b, [1.0], x)` to rounding (~1e-15 relative). The effective response
/// is |B(f)|^2 with zero phase. Units of `y` are those of `x`.
pub fn filtfilt(
    b: &[f64],
    x: &[f64],
    y: &mut [f64],
    scratch: &mut [f64],
) -> Result<(), FiltfiltError> {
    let nb = b.len();
    if nb == 0 {
        return Err(FiltfiltError::NoTaps);
    }
    let n = x.len();
    let edge = 3 * nb;
    if n <= edge {
        return Err(FiltfiltError::SignalTooShort {
            len: n,
            padlen: edge,
        });
    }
    if y.len() != n {
        return Err(FiltfiltError::OutputLengthMismatch);
    }
    if b.iter().chain(x.iter()).any(|v| !v.is_finite()) {
        return Err(FiltfiltError::NonFinite);
    }
    let total = filtfilt_scratch_len(nb, n);
    let ext = match scratch.get_mut(..total) {
        Some(s) => s,
        None => return Err(FiltfiltError::ScratchTooSmall { needed: total }),
    };
    // Note: n > edge >= 3, so x[0], x[n-1] and the mirrored ranges below all exist; the
    // `if let`s never take their empty branch.
    let (Some(&first), Some(&last)) = (x.first(), x.last()) else {
        return Err(FiltfiltError::SignalTooShort {
            len: n,
            padlen: edge,
        });
    };

    // Odd extension: [2 x0 - x[edge], ..., 2 x0 - x[1], x..., 2 xl - x[n-2], ..., 2 xl - x[n-1-edge]].
    let (left, rest) = ext.split_at_mut(edge);
    let (middle, right) = rest.split_at_mut(n);
    for (slot, v) in left.iter_mut().zip(x.iter().skip(1).take(edge).rev()) {
        *slot = 2.0 * first - v;
    }
    middle.copy_from_slice(x);
    for (slot, v) in right.iter_mut().zip(x.iter().rev().skip(1).take(edge)) {
        *slot = 2.0 * last - v;
    }

    // Forward pass, in place from the end: out[i] = sum_k b[k] ext[i - k], history = ext[0].
    let before = ext.first().copied().unwrap_or(0.0);
    for i in (0..total).rev() {
        let mut acc = 0.0;
        for (k, bk) in b.iter().enumerate() {
            let v = match i.checked_sub(k) {
                Some(j) => ext.get(j).copied().unwrap_or(before),
                None => before,
            };
            acc += bk * v;
        }
        if let Some(slot) = ext.get_mut(i) {
            *slot = acc;
        }
    }

    // Backward pass, in place from the start: out[i] = sum_k b[k] fwd[i + k], future = fwd[end].
    let after = ext.last().copied().unwrap_or(0.0);
    for i in 0..total {
        let mut acc = 0.0;
        for (k, bk) in b.iter().enumerate() {
            acc += bk * ext.get(i + k).copied().unwrap_or(after);
        }
        if let Some(slot) = ext.get_mut(i) {
            *slot = acc;
        }
    }

    if let Some(src) = ext.get(edge..edge + n) {
        y.copy_from_slice(src);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identity_filter_and_constant() {
        let x: Vec<f64> = (0..10).map(|i| (i * i) as f64).collect();
        let mut y = vec![0.0; 10];
        let mut s = vec![0.0; filtfilt_scratch_len(1, 10)];
        filtfilt(&[1.0], &x, &mut y, &mut s).unwrap();
        assert_eq!(x, y);
        // A unit-DC-gain filter passes a constant unchanged (the extension is constant too).
        let b = [0.25, 0.5, 0.25];
        let c = vec![3.0; 10];
        let mut s = vec![0.0; filtfilt_scratch_len(3, 10)];
        filtfilt(&b, &c, &mut y, &mut s).unwrap();
        assert!(y.iter().all(|v| (v - 3.0).abs() < 1e-15));
    }

    #[test]
    fn errors() {
        let mut y = [0.0; 9];
        let mut s = [0.0; 100];
        assert_eq!(
            filtfilt(&[0.5, 0.5, 0.0], &[1.0; 9], &mut y, &mut s),
            Err(FiltfiltError::SignalTooShort { len: 9, padlen: 9 })
        );
        let mut y = [0.0; 10];
        assert_eq!(
            filtfilt(&[0.5, 0.5, 0.0], &[1.0; 10], &mut y, &mut s[..10]),
            Err(FiltfiltError::ScratchTooSmall { needed: 28 })
        );
        assert!(filtfilt(&[0.5, 0.5, 0.0], &[1.0; 10], &mut y, &mut s).is_ok());
        assert_eq!(
            filtfilt(&[], &[1.0; 10], &mut y, &mut s),
            Err(FiltfiltError::NoTaps)
        );
    }
}
