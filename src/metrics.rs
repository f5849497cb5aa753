//! Goodness-of-fit figures of the paper (II-E, tables): fit percent as MATLAB `compare` reports
//! it, and mean square error. Offline, f64 slices; `yhat` is a pure simulation of the model
//! (not a one-step-ahead prediction), which is what `compare` computes.

/// Why a metric could not be computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MetricsError {
    /// `y` and `yhat` differ in length.
    LengthMismatch,
    /// No samples.
    Empty,
    /// A value is NaN or infinite.
    NonFinite {
        /// Index of the first offending sample (in `y`, else in `yhat`).
        index: usize,
    },
    /// `y` is constant: `||y - mean(y)|| = 0`, so fit % is undefined.
    ZeroVariance,
}

fn check(y: &[f64], yhat: &[f64]) -> Result<(), MetricsError> {
    if y.len() != yhat.len() {
        return Err(MetricsError::LengthMismatch);
    }
    if y.is_empty() {
        return Err(MetricsError::Empty);
    }
    if let Some(index) = y
        .iter()
        .position(|v| !v.is_finite())
        .or_else(|| yhat.iter().position(|v| !v.is_finite()))
    {
        return Err(MetricsError::NonFinite { index });
    }
    Ok(())
}

/// Fit in percent, as MATLAB `compare`: `100 (1 - ||y - yhat|| / ||y - mean(y)||)` (2-norms).
/// 100 = perfect, 0 = no better than the mean of `y`, negative = worse. Unitless.
pub fn fit_percent(y: &[f64], yhat: &[f64]) -> Result<f64, MetricsError> {
    check(y, yhat)?;
    let mean = y.iter().sum::<f64>() / y.len() as f64;
    let err2: f64 = y.iter().zip(yhat).map(|(a, b)| (a - b) * (a - b)).sum();
    let var2: f64 = y.iter().map(|a| (a - mean) * (a - mean)).sum();
    if var2 == 0.0 {
        return Err(MetricsError::ZeroVariance);
    }
    Ok(100.0 * (1.0 - libm::sqrt(err2) / libm::sqrt(var2)))
}

/// Mean square error, `mean((y - yhat)^2)`, in the square of the units of `y`.
pub fn mse(y: &[f64], yhat: &[f64]) -> Result<f64, MetricsError> {
    check(y, yhat)?;
    let err2: f64 = y.iter().zip(yhat).map(|(a, b)| (a - b) * (a - b)).sum();
    Ok(err2 / y.len() as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_values() {
        // y = [1, 2, 3], mean 2, ||y - mean|| = sqrt(2); yhat = [1, 2, 4]: ||e|| = 1.
        let y = [1.0, 2.0, 3.0];
        let f = fit_percent(&y, &[1.0, 2.0, 4.0]).unwrap();
        assert!((f - 100.0 * (1.0 - 1.0 / 2f64.sqrt())).abs() < 1e-12, "{f}");
        assert_eq!(fit_percent(&y, &y), Ok(100.0));
        assert_eq!(fit_percent(&y, &[2.0; 3]), Ok(0.0));
        assert!((mse(&y, &[1.0, 2.0, 4.0]).unwrap() - 1.0 / 3.0).abs() < 1e-15);
        assert_eq!(fit_percent(&[1.0; 3], &y), Err(MetricsError::ZeroVariance));
        assert_eq!(fit_percent(&y, &[1.0]), Err(MetricsError::LengthMismatch));
        assert_eq!(fit_percent(&[], &[]), Err(MetricsError::Empty));
        assert_eq!(
            mse(&y, &[1.0, f64::NAN, 3.0]),
            Err(MetricsError::NonFinite { index: 1 })
        );
    }
}
