//! Continuous-time state space from a transfer function: the controllable canonical
//! realization, the same one `scipy.signal.tf2ss` (and MATLAB `tf2ss`) returns.
//!
//! For monic `den = s^n + a_1 s^{n-1} + ... + a_n` and `num = b_0 s^n + ... + b_n`:
//! `D = b_0`; the strictly proper remainder `r(s) = num(s) - D den(s)` has coefficients
//! `r_i = b_i - D a_i` (i = 1..n);
//! `A = [[-a_1, -a_2, ..., -a_n], [1, 0, ...], ..., [0, ..., 1, 0]]`, `B = e_1`,
//! `C = [r_1, ..., r_n]`.
//! Storage is fixed `MAX_ORDER`-sized arrays, zero-padded beyond the runtime order `n`.
//! f64, offline only. The input delay is carried along untouched.

use super::tf::{TransferFunction, MAX_ORDER};

/// `dx/dt = A x + B u(t - delay_s)`, `y = C x + D u(t - delay_s)`; order `n <= MAX_ORDER`,
/// entries beyond `n` are zero.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StateSpace {
    /// Number of states.
    pub n: usize,
    /// State matrix, rows of `MAX_ORDER` (only the leading `n x n` block is used), 1/s.
    pub a: [[f64; MAX_ORDER]; MAX_ORDER],
    /// Input vector (leading `n` entries used).
    pub b: [f64; MAX_ORDER],
    /// Output row (leading `n` entries used).
    pub c: [f64; MAX_ORDER],
    /// Direct feedthrough (non-zero for a proper, not strictly proper, transfer function).
    pub d: f64,
    /// Input delay, s.
    pub delay_s: f64,
}

impl StateSpace {
    /// Controllable canonical realization of `tf` (see the module doc). Cannot fail: a
    /// [`TransferFunction`] is valid by construction.
    pub fn from_tf(tf: &TransferFunction) -> Self {
        let monic = tf.to_monic();
        let n = monic.order();
        let num = monic.numerator();
        let den = monic.denominator();
        let d = num.first().copied().unwrap_or(0.0);
        let mut ss = Self {
            n,
            a: [[0.0; MAX_ORDER]; MAX_ORDER],
            b: [0.0; MAX_ORDER],
            c: [0.0; MAX_ORDER],
            d,
            delay_s: tf.delay_s(),
        };
        if let Some(first_row) = ss.a.first_mut() {
            for (a, den_i) in first_row.iter_mut().zip(den.iter().skip(1)) {
                *a = -den_i;
            }
        }
        // Sub-diagonal of ones: x_{i+1}' = x_i.
        for (i, row) in
            ss.a.iter_mut()
                .enumerate()
                .skip(1)
                .take(n.saturating_sub(1))
        {
            if let Some(a) = row.get_mut(i - 1) {
                *a = 1.0;
            }
        }
        if n > 0 {
            if let Some(b) = ss.b.first_mut() {
                *b = 1.0;
            }
        }
        for ((c, num_i), den_i) in
            ss.c.iter_mut()
                .zip(num.iter().skip(1))
                .zip(den.iter().skip(1))
        {
            *c = num_i - d * den_i;
        }
        ss
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_scipy_tf2ss_form() {
        // scipy.signal.tf2ss([2, 3, 4], [2, 6, 10]): monic den [1, 3, 5], num [1, 1.5, 2]
        // -> A = [[-3, -5], [1, 0]], B = [1, 0], C = [1.5 - 3, 2 - 5] = [-1.5, -3], D = 1.
        let tf = TransferFunction::without_delay(&[2.0, 3.0, 4.0], &[2.0, 6.0, 10.0]).unwrap();
        let ss = StateSpace::from_tf(&tf);
        assert_eq!(ss.n, 2);
        assert_eq!(ss.a[0][..2], [-3.0, -5.0]);
        assert_eq!(ss.a[1][..2], [1.0, 0.0]);
        assert_eq!(ss.b[..2], [1.0, 0.0]);
        assert_eq!(ss.c[..2], [-1.5, -3.0]);
        assert_eq!(ss.d, 1.0);
        assert_eq!(ss.a[2], [0.0; 3]);
    }

    #[test]
    fn static_gain_has_no_states() {
        let tf = TransferFunction::without_delay(&[3.0], &[2.0]).unwrap();
        let ss = StateSpace::from_tf(&tf);
        assert_eq!(ss.n, 0);
        assert_eq!(ss.d, 1.5);
        assert_eq!(ss.b, [0.0; 3]);
    }
}
