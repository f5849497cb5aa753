//! Zero-order-hold discretization (f64, offline): `Ad = e^{A Ts}`, `Bd = ∫_0^Ts e^{A s} ds B`,
//! `Cd = C`, `Dd = D`, and the input delay as a whole number of samples.
//!
//! `Ad` and `Bd` come from one matrix exponential of the augmented matrix
//! `[[A, B], [0, 0]] Ts` (Van Loan), computed by scaling and squaring with a degree-20 Taylor
//! approximant: the matrix is halved until its 1-norm is <= 1/2, where the truncation error
//! is below `0.5^21 / 21! ≈ 1e-26`, then squared back. This is what
//! `scipy.signal.cont2discrete(method="zoh")` computes (scipy uses a Padé approximant); the
//! integration tests compare the two to rtol 1e-9.
//!
//! Delays must be whole samples: `delay_s / ts_s` must be within a relative 1e-9 of an
//! integer. Fractional delays (Thiran all-pass, modified z-transform) are not supported and
//! give [`ModelError::FractionalDelay`].

use super::ss::StateSpace;
use super::tf::{ModelError, TransferFunction, MAX_COEFFS, MAX_ORDER};

/// Size of the augmented matrix `[[A, B], [0, 0]]` at the largest order.
const AUG: usize = MAX_ORDER + 1;

/// Relative tolerance on `delay_s / ts_s` being an integer.
pub const DELAY_INTEGER_RTOL: f64 = 1e-9;

/// Largest accepted delay in samples; a longer one is certainly a units mistake
/// (2^20 samples = 5.8 h at 20 ms).
pub const MAX_DELAY_SAMPLES: usize = 1 << 20;

/// Discrete-time state space, `x[k+1] = Ad x[k] + Bd u[k - d]`, `y[k] = Cd x[k] + Dd u[k - d]`,
/// `d = delay_samples`. Arrays are `MAX_ORDER`-sized, zero beyond the order `n`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiscreteStateSpace {
    /// Number of states.
    pub n: usize,
    /// State transition matrix `e^{A Ts}` (rows).
    pub ad: [[f64; MAX_ORDER]; MAX_ORDER],
    /// Input vector `∫_0^Ts e^{A s} ds B`.
    pub bd: [f64; MAX_ORDER],
    /// Output row (equal to the continuous `C`).
    pub cd: [f64; MAX_ORDER],
    /// Direct feedthrough (equal to the continuous `D`).
    pub dd: f64,
    /// Sample period, s.
    pub ts_s: f64,
    /// Input delay, whole samples.
    pub delay_samples: usize,
}

/// Discrete transfer function `z^{-delay_samples} (b_0 + b_1 z^-1 + ... + b_n z^-n) /
/// (1 + a_1 z^-1 + ... + a_n z^-n)`: the `(num, den)` that `scipy.signal.cont2discrete` returns
/// for a transfer function (the delay kept apart).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiscreteTf {
    num: [f64; MAX_COEFFS],
    den: [f64; MAX_COEFFS],
    order: usize,
    /// Input delay, whole samples.
    pub delay_samples: usize,
}

impl DiscreteTf {
    /// `b_0 .. b_n`, `order + 1` coefficients in ascending powers of `z^-1`.
    pub fn numerator(&self) -> &[f64] {
        self.num.get(..=self.order).unwrap_or(&[])
    }
    /// `1, a_1 .. a_n`, `order + 1` coefficients in ascending powers of `z^-1`.
    pub fn denominator(&self) -> &[f64] {
        self.den.get(..=self.order).unwrap_or(&[])
    }
    /// `n`.
    pub fn order(&self) -> usize {
        self.order
    }
}

/// `delay_s / ts_s` as a whole number of samples, or a typed error if it is not one (within
/// [`DELAY_INTEGER_RTOL`]), if `ts_s <= 0`, or if it exceeds [`MAX_DELAY_SAMPLES`].
pub fn delay_samples(delay_s: f64, ts_s: f64) -> Result<usize, ModelError> {
    check_ts(ts_s)?;
    if !delay_s.is_finite() {
        return Err(ModelError::NotFinite);
    }
    if delay_s < 0.0 {
        return Err(ModelError::NegativeDelay);
    }
    let ratio = delay_s / ts_s;
    if ratio > MAX_DELAY_SAMPLES as f64 {
        return Err(ModelError::DelayTooLong {
            delay_samples: MAX_DELAY_SAMPLES + 1,
            capacity: MAX_DELAY_SAMPLES,
        });
    }
    let nearest = libm::round(ratio);
    // A delay that rounds to no sample is no delay only if it is none: 0.88 s at a sample
    // period of 1e9 s (ratio 8.8e-10, within the tolerance of 0) was taken as 0 samples.
    if (ratio - nearest).abs() > DELAY_INTEGER_RTOL * nearest.max(1.0)
        || (nearest == 0.0 && delay_s > 0.0)
    {
        return Err(ModelError::FractionalDelay { delay_s, ts_s });
    }
    // Note: 0 <= nearest <= 2^20, exact in usize.
    Ok(nearest as usize)
}

fn check_ts(ts_s: f64) -> Result<(), ModelError> {
    if !ts_s.is_finite() {
        return Err(ModelError::NotFinite);
    }
    if ts_s <= 0.0 {
        return Err(ModelError::InvalidSamplePeriod);
    }
    Ok(())
}

/// ZOH discretization of a transfer function at `ts_s` (realized as in [`StateSpace::from_tf`]).
pub fn discretize(tf: &TransferFunction, ts_s: f64) -> Result<DiscreteStateSpace, ModelError> {
    discretize_ss(&StateSpace::from_tf(tf), ts_s)
}

/// ZOH discretization of a continuous state space at `ts_s`.
pub fn discretize_ss(ss: &StateSpace, ts_s: f64) -> Result<DiscreteStateSpace, ModelError> {
    check_ts(ts_s)?;
    let delay_samples = delay_samples(ss.delay_s, ts_s)?;
    let n = ss.n.min(MAX_ORDER);
    // Augmented [[A, B], [0, 0]] Ts, with B in column n; rows and columns beyond n + 1 stay
    // zero and decouple (their exponential is the identity there).
    let mut m = [[0.0; AUG]; AUG];
    for ((m_row, a_row), b) in m.iter_mut().zip(&ss.a).zip(&ss.b).take(n) {
        for (mij, aij) in m_row.iter_mut().zip(a_row).take(n) {
            *mij = aij * ts_s;
        }
        if let Some(mib) = m_row.get_mut(n) {
            *mib = b * ts_s;
        }
    }
    let e = expm(&m)?;
    let mut out = DiscreteStateSpace {
        n,
        ad: [[0.0; MAX_ORDER]; MAX_ORDER],
        bd: [0.0; MAX_ORDER],
        cd: ss.c,
        dd: ss.d,
        ts_s,
        delay_samples,
    };
    for ((ad_row, bd), e_row) in out.ad.iter_mut().zip(out.bd.iter_mut()).zip(&e).take(n) {
        for (adij, eij) in ad_row.iter_mut().zip(e_row).take(n) {
            *adij = *eij;
        }
        *bd = e_row.get(n).copied().unwrap_or(0.0);
    }
    Ok(out)
}

impl DiscreteStateSpace {
    /// The discrete transfer function: `den = det(zI - Ad)`,
    /// `num = det(zI - Ad + Bd Cd) + (Dd - 1) den` (as `scipy.signal.ss2tf`).
    pub fn transfer_function(&self) -> DiscreteTf {
        let den = char_poly(&self.ad, self.n);
        let mut a_minus_bc = self.ad;
        for (row, bi) in a_minus_bc.iter_mut().zip(&self.bd) {
            for (aij, cj) in row.iter_mut().zip(&self.cd) {
                *aij -= bi * cj;
            }
        }
        let p = char_poly(&a_minus_bc, self.n);
        let mut num = [0.0; MAX_COEFFS];
        for ((nu, pi), di) in num.iter_mut().zip(&p).zip(&den).take(self.n + 1) {
            *nu = pi + (self.dd - 1.0) * di;
        }
        DiscreteTf {
            num,
            den,
            order: self.n,
            delay_samples: self.delay_samples,
        }
    }

    /// The state `x*` with `x* = Ad x* + Bd u` for `u = 1` (the equilibrium per unit input),
    /// by Gaussian elimination with partial pivoting on `(I - Ad) x = Bd`.
    /// [`ModelError::NoEquilibrium`] if `I - Ad` is singular (a pole at z = 1).
    pub fn equilibrium_per_unit_input(&self) -> Result<[f64; MAX_ORDER], ModelError> {
        let n = self.n;
        let mut m = [[0.0; MAX_ORDER + 1]; MAX_ORDER];
        for (i, (m_row, ad_row)) in m.iter_mut().zip(&self.ad).enumerate().take(n) {
            for (j, (mij, aij)) in m_row.iter_mut().zip(ad_row).enumerate().take(n) {
                *mij = if i == j { 1.0 - aij } else { -aij };
            }
            if let Some(rhs) = m_row.get_mut(MAX_ORDER) {
                *rhs = self.bd.get(i).copied().unwrap_or(0.0);
            }
        }
        let scale = m.iter().flatten().fold(0.0f64, |acc, v| acc.max(v.abs()));
        for col in 0..n {
            // Partial pivot.
            let pivot_row = (col..n)
                .max_by(|&r1, &r2| {
                    let v1 = m.get(r1).and_then(|r| r.get(col)).map_or(0.0, |v| v.abs());
                    let v2 = m.get(r2).and_then(|r| r.get(col)).map_or(0.0, |v| v.abs());
                    v1.total_cmp(&v2)
                })
                .unwrap_or(col);
            swap_rows(&mut m, col, pivot_row);
            let pivot = m.get(col).and_then(|r| r.get(col)).copied().unwrap_or(0.0);
            if pivot.abs() <= 1e-14 * scale.max(f64::MIN_POSITIVE) {
                return Err(ModelError::NoEquilibrium);
            }
            let pivot_row_vals = m.get(col).copied().unwrap_or([0.0; MAX_ORDER + 1]);
            for (r, row) in m.iter_mut().enumerate().take(n) {
                if r == col {
                    continue;
                }
                let factor = row.get(col).copied().unwrap_or(0.0) / pivot;
                for (v, p) in row.iter_mut().zip(&pivot_row_vals) {
                    *v -= factor * p;
                }
            }
        }
        let mut x = [0.0; MAX_ORDER];
        for (i, (xi, row)) in x.iter_mut().zip(&m).enumerate().take(n) {
            let diag = row.get(i).copied().unwrap_or(1.0);
            *xi = row.get(MAX_ORDER).copied().unwrap_or(0.0) / diag;
        }
        if x.iter().all(|v| v.is_finite()) {
            Ok(x)
        } else {
            Err(ModelError::NoEquilibrium)
        }
    }
}

/// Swaps rows `a` and `b` of `m`; out-of-range indices leave it unchanged (`<[T]>::swap` would
/// panic: the core has no panic path, `cargo xtask no-panic`).
fn swap_rows<T>(m: &mut [T], a: usize, b: usize) {
    let (lo, hi) = (a.min(b), a.max(b));
    if let Some((head, tail)) = m.split_at_mut_checked(hi) {
        if let (Some(x), Some(y)) = (head.get_mut(lo), tail.first_mut()) {
            core::mem::swap(x, y);
        }
    }
}

/// Characteristic polynomial `det(zI - M) = z^n + c_1 z^{n-1} + ... + c_n` of the leading
/// `n x n` block, returned as `[1, c_1, ..., c_n, 0...]` (Faddeev-LeVerrier; exact enough for
/// n <= 3, where it reduces to trace / principal minors / determinant).
fn char_poly(m: &[[f64; MAX_ORDER]; MAX_ORDER], n: usize) -> [f64; MAX_COEFFS] {
    let mut out = [0.0; MAX_COEFFS];
    if let Some(c0) = out.first_mut() {
        *c0 = 1.0;
    }
    // M_0 = 0; M_k = M M_{k-1} + c_{k-1} I; c_k = -tr(M M_k) / k.
    let mut mk = [[0.0; MAX_ORDER]; MAX_ORDER];
    let mut c_prev = 1.0;
    for k in 1..=n {
        let mut next = mat_mul(m, &mk, n);
        for (i, row) in next.iter_mut().enumerate().take(n) {
            if let Some(d) = row.get_mut(i) {
                *d += c_prev;
            }
        }
        mk = next;
        let prod = mat_mul(m, &mk, n);
        let trace: f64 = prod
            .iter()
            .enumerate()
            .take(n)
            .map(|(i, row)| row.get(i).copied().unwrap_or(0.0))
            .sum();
        let ck = -trace / k as f64;
        if let Some(slot) = out.get_mut(k) {
            *slot = ck;
        }
        c_prev = ck;
    }
    out
}

fn mat_mul<const K: usize>(x: &[[f64; K]; K], y: &[[f64; K]; K], n: usize) -> [[f64; K]; K] {
    let mut out = [[0.0; K]; K];
    for (out_row, x_row) in out.iter_mut().zip(x).take(n) {
        for (j, out_ij) in out_row.iter_mut().enumerate().take(n) {
            *out_ij = x_row
                .iter()
                .zip(y)
                .take(n)
                .map(|(xik, y_row)| xik * y_row.get(j).copied().unwrap_or(0.0))
                .sum();
        }
    }
    out
}

/// Matrix exponential of a small dense matrix: scaling and squaring with a degree-20 Taylor
/// polynomial (see the module doc). [`ModelError::NotFinite`] for non-finite input,
/// [`ModelError::NumericalFailure`] if the result overflows.
pub fn expm<const K: usize>(m: &[[f64; K]; K]) -> Result<[[f64; K]; K], ModelError> {
    const TAYLOR_DEGREE: usize = 20;
    if !m.iter().flatten().all(|v| v.is_finite()) {
        return Err(ModelError::NotFinite);
    }
    let norm1 = (0..K)
        .map(|j| {
            m.iter()
                .map(|row| row.get(j).map_or(0.0, |v| v.abs()))
                .sum::<f64>()
        })
        .fold(0.0f64, f64::max);
    // Halve until ||m / 2^s||_1 <= 1/2; at most ~1030 halvings for any finite f64.
    let mut squarings = 0u32;
    let mut scale = 1.0f64;
    while norm1 * scale > 0.5 {
        scale *= 0.5;
        squarings += 1;
    }
    let mut scaled = *m;
    for v in scaled.iter_mut().flatten() {
        *v *= scale;
    }
    // Horner: e^X ≈ I + X (I + X/2 (I + X/3 (... (I + X/20)))).
    let mut acc = identity::<K>();
    for k in (1..=TAYLOR_DEGREE).rev() {
        let mut next = mat_mul(&scaled, &acc, K);
        for v in next.iter_mut().flatten() {
            *v /= k as f64;
        }
        for (i, row) in next.iter_mut().enumerate() {
            if let Some(d) = row.get_mut(i) {
                *d += 1.0;
            }
        }
        acc = next;
    }
    for _ in 0..squarings {
        acc = mat_mul(&acc, &acc, K);
    }
    if acc.iter().flatten().all(|v| v.is_finite()) {
        Ok(acc)
    } else {
        Err(ModelError::NumericalFailure)
    }
}

fn identity<const K: usize>() -> [[f64; K]; K] {
    let mut out = [[0.0; K]; K];
    for (i, row) in out.iter_mut().enumerate() {
        if let Some(d) = row.get_mut(i) {
            *d = 1.0;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol * (1.0 + b.abs())
    }

    #[test]
    fn expm_of_rotation_and_scalar() {
        // exp([[0, -w], [w, 0]] t) is a rotation by w t.
        let theta = 2.5f64;
        let e = expm(&[[0.0, -theta], [theta, 0.0]]).unwrap();
        assert!(close(e[0][0], libm::cos(theta), 1e-14));
        assert!(close(e[1][0], libm::sin(theta), 1e-14));
        let e = expm(&[[-30.0]]).unwrap();
        assert!(close(e[0][0], libm::exp(-30.0), 1e-13));
        assert_eq!(expm(&[[f64::NAN]]), Err(ModelError::NotFinite));
        assert_eq!(expm(&[[1e300]]), Err(ModelError::NumericalFailure));
    }

    #[test]
    fn first_order_closed_form() {
        // 1/(s + p): Ad = e^{-p Ts}, Bd = (1 - Ad)/p, C = 1; discrete num [0, (1-Ad)/p].
        let p = 3.0;
        let ts = 0.1;
        let tf = TransferFunction::without_delay(&[1.0], &[1.0, p]).unwrap();
        let d = discretize(&tf, ts).unwrap();
        let ad = libm::exp(-p * ts);
        assert!(close(d.ad[0][0], ad, 1e-15));
        assert!(close(d.bd[0], (1.0 - ad) / p, 1e-15));
        let h = d.transfer_function();
        assert!(close(h.denominator()[1], -ad, 1e-15));
        assert!(close(h.numerator()[1], (1.0 - ad) / p, 1e-15));
        assert!(h.numerator()[0].abs() < 1e-15);
        let x = d.equilibrium_per_unit_input().unwrap();
        assert!(close(x[0], 1.0 / p, 1e-14));
    }

    #[test]
    fn delays() {
        assert_eq!(delay_samples(0.42, 0.02), Ok(21));
        assert_eq!(delay_samples(0.0, 0.02), Ok(0));
        assert_eq!(
            delay_samples(0.43, 0.02),
            Err(ModelError::FractionalDelay {
                delay_s: 0.43,
                ts_s: 0.02
            })
        );
        assert_eq!(
            delay_samples(0.1, 0.0),
            Err(ModelError::InvalidSamplePeriod)
        );
        assert_eq!(delay_samples(0.1, f64::NAN), Err(ModelError::NotFinite));
        // A delay far shorter than one sample is no whole number of them (a probe's `discretize
        // --ts 1e9` wrote 0 samples for 0.88 s, where `--ts 100` refused).
        assert_eq!(
            delay_samples(0.88, 1e9),
            Err(ModelError::FractionalDelay {
                delay_s: 0.88,
                ts_s: 1e9
            })
        );
        assert!(matches!(
            delay_samples(1e9, 0.02),
            Err(ModelError::DelayTooLong { .. })
        ));
        let tf = TransferFunction::new(&[1.0], &[1.0, 1.0], 0.03).unwrap();
        assert!(matches!(
            discretize(&tf, 0.02),
            Err(ModelError::FractionalDelay { .. })
        ));
    }

    #[test]
    fn integrator_has_no_equilibrium() {
        let tf = TransferFunction::without_delay(&[1.0], &[1.0, 0.0]).unwrap();
        let d = discretize(&tf, 0.02).unwrap();
        assert_eq!(d.ad[0][0], 1.0);
        assert!(close(d.bd[0], 0.02, 1e-15));
        assert_eq!(
            d.equilibrium_per_unit_input(),
            Err(ModelError::NoEquilibrium)
        );
    }
}
