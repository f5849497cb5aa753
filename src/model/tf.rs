//! Continuous-time transfer functions with an input delay: `h(s) = e^{-delay_s s} num(s) / den(s)`.
//!
//! This module owns validation: a [`TransferFunction`] that exists is proper (numerator degree
//! <= denominator degree), has a non-zero leading denominator coefficient, finite coefficients,
//! order <= [`MAX_ORDER`] and a finite, non-negative delay. Coefficients are stored in fixed
//! arrays (no allocation), in descending powers of `s`, as MATLAB `tf` and `scipy.signal` write
//! them. Arithmetic is f64: this is offline (design-time) data; the node runs the f32
//! [`crate::model::block::SsBlock`] built from it.

use core::fmt;

/// Highest denominator degree a [`TransferFunction`] may have. The paper's models are 2nd order
/// (eq 5, eq 7); 3 leaves room for a re-identified model (the paper's text speaks of "order 3").
pub const MAX_ORDER: usize = 3;

/// Coefficient storage length: a polynomial of degree [`MAX_ORDER`] has `MAX_ORDER + 1` terms.
pub const MAX_COEFFS: usize = MAX_ORDER + 1;

/// Every way building, realizing or discretizing a model can fail.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ModelError {
    /// A coefficient, the delay or the sample period is NaN or infinite.
    NotFinite,
    /// The numerator or denominator has no coefficients at all.
    EmptyPolynomial,
    /// The leading (highest-power) denominator coefficient is zero: the order is ill-defined.
    ZeroLeadingDenominator,
    /// Numerator degree above denominator degree: not realizable in state space.
    Improper {
        /// Degree of the numerator after stripping its leading zeros.
        numerator_degree: usize,
        /// Degree of the denominator.
        denominator_degree: usize,
    },
    /// Denominator degree above [`MAX_ORDER`] (or above a block's fixed order).
    OrderTooHigh {
        /// Degree found.
        order: usize,
        /// Largest degree accepted.
        max: usize,
    },
    /// Input delay below zero (a non-causal model).
    NegativeDelay,
    /// Sample period not strictly positive.
    InvalidSamplePeriod,
    /// `delay_s / ts_s` is not an integer within a relative 1e-9: fractional delays (a
    /// Thiran filter or a modified z-transform) are not supported.
    FractionalDelay {
        /// Input delay, s.
        delay_s: f64,
        /// Sample period, s.
        ts_s: f64,
    },
    /// The delay in samples exceeds the capacity of the delay line that must hold it.
    DelayTooLong {
        /// Delay asked for, samples.
        delay_samples: usize,
        /// Delay line capacity, samples.
        capacity: usize,
    },
    /// A fixed-order block was built from a transfer function of another order.
    OrderMismatch {
        /// The block's order `N`.
        expected: usize,
        /// The transfer function's order.
        found: usize,
    },
    /// The model has a pole at s = 0 (z = 1): no finite DC gain, no equilibrium for a
    /// non-zero input.
    NoEquilibrium,
    /// The discretization produced non-finite numbers (coefficients too large for f64).
    NumericalFailure,
}

impl fmt::Display for ModelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NotFinite => write!(f, "coefficient, delay or sample period is not finite"),
            Self::EmptyPolynomial => write!(f, "numerator or denominator has no coefficients"),
            Self::ZeroLeadingDenominator => {
                write!(f, "leading denominator coefficient is zero")
            }
            Self::Improper {
                numerator_degree,
                denominator_degree,
            } => write!(
                f,
                "improper transfer function: numerator degree {numerator_degree} > denominator degree {denominator_degree}"
            ),
            Self::OrderTooHigh { order, max } => {
                write!(f, "order {order} is above the maximum {max}")
            }
            Self::NegativeDelay => write!(f, "input delay is negative"),
            Self::InvalidSamplePeriod => write!(f, "sample period must be > 0"),
            Self::FractionalDelay { delay_s, ts_s } => write!(
                f,
                "delay {delay_s} s is not a whole number of {ts_s} s samples (fractional delays are not supported)"
            ),
            Self::DelayTooLong {
                delay_samples,
                capacity,
            } => write!(
                f,
                "delay of {delay_samples} samples exceeds the delay line capacity {capacity}"
            ),
            Self::OrderMismatch { expected, found } => {
                write!(f, "block of order {expected} built from a model of order {found}")
            }
            Self::NoEquilibrium => write!(f, "pole at s = 0: no finite DC gain or equilibrium"),
            Self::NumericalFailure => write!(f, "discretization produced non-finite values"),
        }
    }
}

/// `h(s) = e^{-delay_s s} (b_0 s^n + ... + b_n) / (a_0 s^n + ... + a_n)`, `n = order() <= 3`.
///
/// Stored with the numerator padded by leading zeros to the denominator's length `n + 1`, so
/// `numerator()[i]` and `denominator()[i]` multiply the same power `s^{n-i}`. Not normalised:
/// [`TransferFunction::to_monic`] divides by `a_0`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TransferFunction {
    num: [f64; MAX_COEFFS],
    den: [f64; MAX_COEFFS],
    order: usize,
    delay_s: f64,
}

impl TransferFunction {
    /// Validates and stores `num(s)/den(s)` (descending powers of `s`) with an input delay.
    ///
    /// Leading zeros of the numerator are ignored (`[0, 1]` is `1`); a leading zero of the
    /// denominator is an error, since it would silently change the order.
    pub fn new(num: &[f64], den: &[f64], delay_s: f64) -> Result<Self, ModelError> {
        if num.is_empty() || den.is_empty() {
            return Err(ModelError::EmptyPolynomial);
        }
        if !num.iter().chain(den).all(|c| c.is_finite()) || !delay_s.is_finite() {
            return Err(ModelError::NotFinite);
        }
        if den.first().is_some_and(|&a0| a0 == 0.0) {
            return Err(ModelError::ZeroLeadingDenominator);
        }
        let order = den.len() - 1;
        if order > MAX_ORDER {
            return Err(ModelError::OrderTooHigh {
                order,
                max: MAX_ORDER,
            });
        }
        let num_trimmed = match num.iter().position(|&c| c != 0.0) {
            Some(first_nonzero) => num.get(first_nonzero..).unwrap_or(&[]),
            None => &[],
        };
        let numerator_degree = num_trimmed.len().saturating_sub(1);
        if numerator_degree > order {
            return Err(ModelError::Improper {
                numerator_degree,
                denominator_degree: order,
            });
        }
        if delay_s < 0.0 {
            return Err(ModelError::NegativeDelay);
        }
        let mut tf = Self {
            num: [0.0; MAX_COEFFS],
            den: [0.0; MAX_COEFFS],
            order,
            delay_s,
        };
        for (dst, src) in tf.den.iter_mut().zip(den) {
            *dst = *src;
        }
        // Right-align the numerator so index i multiplies s^(order - i) in both polynomials.
        let offset = (order + 1) - num_trimmed.len();
        for (dst, src) in tf.num.iter_mut().skip(offset).zip(num_trimmed) {
            *dst = *src;
        }
        Ok(tf)
    }

    /// A proper 2nd-order model from coefficients known at compile time (the paper's
    /// constants). The caller vouches for validity (`den[0] != 0`, finite, `delay_s >= 0`);
    /// unit tests check every use against [`TransferFunction::new`].
    pub(crate) const fn second_order_unchecked(num: [f64; 3], den: [f64; 3], delay_s: f64) -> Self {
        Self {
            num: [num[0], num[1], num[2], 0.0],
            den: [den[0], den[1], den[2], 0.0],
            order: 2,
            delay_s,
        }
    }

    /// Same as [`TransferFunction::new`] with no input delay.
    pub fn without_delay(num: &[f64], den: &[f64]) -> Result<Self, ModelError> {
        Self::new(num, den, 0.0)
    }

    /// Denominator degree `n` (number of states of a minimal-size realization).
    pub fn order(&self) -> usize {
        self.order
    }

    /// Numerator coefficients, `order() + 1` of them, descending powers of `s`, zero-padded at
    /// the front (index i multiplies `s^{order - i}`).
    pub fn numerator(&self) -> &[f64] {
        self.num.get(..=self.order).unwrap_or(&[])
    }

    /// Denominator coefficients, `order() + 1` of them, descending powers of `s`.
    pub fn denominator(&self) -> &[f64] {
        self.den.get(..=self.order).unwrap_or(&[])
    }

    /// Input delay, s (the `e^{-delay_s s}` factor).
    pub fn delay_s(&self) -> f64 {
        self.delay_s
    }

    /// The same model with its denominator divided by its leading coefficient (`a_0 = 1`).
    pub fn to_monic(&self) -> Self {
        let a0 = self.den.first().copied().unwrap_or(1.0);
        let mut out = *self;
        for c in out.num.iter_mut().chain(out.den.iter_mut()) {
            *c /= a0;
        }
        out
    }

    /// Steady-state gain `h(0) = b_n / a_n` (the delay does not change it).
    ///
    /// Errors with [`ModelError::NoEquilibrium`] when `a_n = 0` (a pole at the origin).
    pub fn dc_gain(&self) -> Result<f64, ModelError> {
        let bn = self.num.get(self.order).copied().unwrap_or(0.0);
        let an = self.den.get(self.order).copied().unwrap_or(0.0);
        if an == 0.0 {
            return Err(ModelError::NoEquilibrium);
        }
        Ok(bn / an)
    }

    /// True when the numerator degree is below the denominator degree (no direct feedthrough).
    pub fn is_strictly_proper(&self) -> bool {
        self.num.first().is_some_and(|&b0| b0 == 0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pads_numerator_and_reports_gain() {
        let tf = TransferFunction::new(&[0.0, 2.0, 4.0], &[2.0, 3.0, 8.0], 0.1).unwrap();
        assert_eq!(tf.order(), 2);
        assert_eq!(tf.numerator(), &[0.0, 2.0, 4.0]);
        assert_eq!(tf.denominator(), &[2.0, 3.0, 8.0]);
        assert_eq!(tf.dc_gain().unwrap(), 0.5);
        assert!(tf.is_strictly_proper());
        let m = tf.to_monic();
        assert_eq!(m.denominator(), &[1.0, 1.5, 4.0]);
        assert_eq!(m.numerator(), &[0.0, 1.0, 2.0]);
        assert_eq!(m.dc_gain().unwrap(), 0.5);
        let short = TransferFunction::without_delay(&[3.0], &[1.0, 1.0]).unwrap();
        assert_eq!(short.numerator(), &[0.0, 3.0]);
    }

    #[test]
    fn typed_errors() {
        use ModelError::*;
        let e = |n: &[f64], d: &[f64], t: f64| TransferFunction::new(n, d, t).unwrap_err();
        assert_eq!(
            e(&[1.0, 0.0, 0.0], &[1.0, 1.0], 0.0),
            Improper {
                numerator_degree: 2,
                denominator_degree: 1
            }
        );
        assert_eq!(e(&[1.0], &[0.0, 1.0], 0.0), ZeroLeadingDenominator);
        assert_eq!(e(&[f64::NAN], &[1.0, 1.0], 0.0), NotFinite);
        assert_eq!(e(&[1.0], &[1.0, f64::INFINITY], 0.0), NotFinite);
        assert_eq!(e(&[1.0], &[1.0, 1.0], f64::NAN), NotFinite);
        assert_eq!(e(&[1.0], &[1.0, 1.0], -0.1), NegativeDelay);
        assert_eq!(e(&[], &[1.0], 0.0), EmptyPolynomial);
        assert_eq!(
            e(&[1.0], &[1.0, 1.0, 1.0, 1.0, 1.0], 0.0),
            OrderTooHigh { order: 4, max: 3 }
        );
        // Leading numerator zeros do not count towards the degree.
        assert!(TransferFunction::new(&[0.0, 0.0, 1.0], &[1.0, 1.0], 0.0).is_ok());
        assert_eq!(
            TransferFunction::new(&[1.0], &[1.0, 0.0], 0.0)
                .unwrap()
                .dc_gain(),
            Err(NoEquilibrium)
        );
    }
}
