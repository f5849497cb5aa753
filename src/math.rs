//! The few `f32` transcendental functions the node uses, each with a measured error bound.
//!
//! Why these and not `micromath`: the node must hold position to 1 cm over a 40 m horizon
//! (2.5e-4 relative) and heading to 1 mrad. `micromath` trades accuracy for speed and misses
//! that by one to three orders of magnitude (measured by `host-tests/tests/math_bounds.rs` on
//! the same grids as below: sin/cos 1.1e-3 absolute, atan/atan2 2.8e-3 rad, sqrt 6.1e-2
//! relative, tan 2.3e-2 relative on ±0.7 rad). So every function here is the pure-Rust `libm` one
//! (a port of musl/FreeBSD msun), which is within a few ulp of the true value.
//!
//! Bit-identity across targets (host replay vs Cortex-M4F, see `docs/architecture.md`): `libm`
//! is plain Rust arithmetic (its `sinf`/`cosf`/`tanf` use `f64` internally, which the M4F
//! emulates in software with IEEE-exact results), with one target-specific path: on x86-64
//! `sqrtf` is the `sqrtss` instruction. IEEE 754 requires square root to be correctly rounded,
//! and `libm`'s software `sqrtf` is correctly rounded too, so both give the same bits.
//! Cost on the M4F: `sqrt` is cheap; `sin`/`cos`/`tan` pay for soft `f64` (order of a few
//! hundred cycles each), which the 20 ms tick affords for the handful of calls per step.
//!
//! Bounds below are the worst case over dense grids (`cargo test -p catmodel-host-tests --test
//! math_bounds`), measured against `f64` `std` functions, and asserted there.

/// pi as `f32` (rounded up: 3.14159274 > pi by 8.7e-8).
pub const PI: f32 = core::f32::consts::PI;
/// 2 pi split in two for exact range reduction (Cody-Waite): `TAU_HI` has trailing zero bits
/// so `k * TAU_HI` is exact for |k| < 2^8, and `TAU_HI + TAU_LO` = 2 pi to 3e-12.
const TAU_HI: f32 = 6.283_081;
const TAU_LO: f32 = 1.042_524_9e-4;

/// Sine of `x` rad. `libm::sinf`. Measured worst error on [-pi, pi] (covers heading, increments
/// to ±0.1 rad and steering to ±0.7 rad): 3.0e-8 absolute (half an ulp near 1).
#[inline]
pub fn sin(x: f32) -> f32 {
    libm::sinf(x)
}

/// Cosine of `x` rad. `libm::cosf`. Measured worst error on [-pi, pi]: 3.0e-8 absolute.
#[inline]
pub fn cos(x: f32) -> f32 {
    libm::cosf(x)
}

/// `(sin x, cos x)` of `x` rad. `libm::sincosf` (one range reduction for both). Measured worst
/// error on [-pi, pi]: 3.0e-8 absolute for each (same values as [`sin`] and [`cos`]).
#[inline]
pub fn sin_cos(x: f32) -> (f32, f32) {
    libm::sincosf(x)
}

/// Tangent of `x` rad. `libm::tanf`. Measured worst relative error on [-1.4, 1.4] (covers
/// steering angles to ±0.7 rad with margin): 8.0e-8.
#[inline]
pub fn tan(x: f32) -> f32 {
    libm::tanf(x)
}

/// Arctangent of `x`, in rad, in (-pi/2, pi/2). `libm::atanf`. Measured worst error on
/// [-1e3, 1e3]: 9.0e-8 rad absolute (under 1 ulp of results near pi/2).
#[inline]
pub fn atan(x: f32) -> f32 {
    libm::atanf(x)
}

/// Angle of the vector (x, y) in rad, in [-pi, pi], `y` first as in C. `libm::atan2f`.
/// Measured worst error over the full plane (radii 1e-3..1e4, all directions): 2.4e-7 rad
/// absolute (under 1 ulp of results near pi).
#[inline]
pub fn atan2(y: f32, x: f32) -> f32 {
    libm::atan2f(y, x)
}

/// Square root. `libm::sqrtf`: correctly rounded (IEEE 754), so relative error <= 2^-24
/// (6.0e-8); measured 6.0e-8 on 0..1e6.
#[inline]
pub fn sqrt(x: f32) -> f32 {
    libm::sqrtf(x)
}

/// sqrt(x^2 + y^2) without intermediate overflow. `libm::hypotf`. Measured worst relative
/// error on |x|, |y| <= 1e4: 9.0e-8.
#[inline]
pub fn hypot(x: f32, y: f32) -> f32 {
    libm::hypotf(x, y)
}

/// Wraps an angle in rad to [-PI, PI) (with `PI` the `f32` constant above). Inputs already in
/// range are returned unchanged (bit-exact); others are reduced by k * 2 pi with a two-part
/// 2 pi, so the result is within 1.2e-7 rad of the exact reduction for |x| <= 100 rad (measured;
/// the node's heading only ever leaves the range by one increment). Non-finite in, NaN out.
pub fn wrap_pi(x: f32) -> f32 {
    if (-PI..PI).contains(&x) {
        return x;
    }
    if !x.is_finite() {
        return f32::NAN;
    }
    let k = libm::floorf((x + PI) / (TAU_HI + TAU_LO));
    let mut r = (x - k * TAU_HI) - k * TAU_LO;
    // Rounding can leave r a hair outside the half-open range; one correction step suffices.
    if r >= PI {
        r -= TAU_HI;
        r -= TAU_LO;
    } else if r < -PI {
        r += TAU_HI;
        r += TAU_LO;
    }
    // The correction itself rounds; this keeps the half-open contract in the last ulp.
    if r >= PI {
        -PI
    } else {
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tau_split_is_two_pi() {
        let tau = TAU_HI as f64 + TAU_LO as f64;
        assert!((tau - core::f64::consts::TAU).abs() < 5e-12, "{tau}");
        // TAU_HI must have at least 8 trailing zero mantissa bits for exact k * TAU_HI.
        assert_eq!(TAU_HI.to_bits() & 0xff, 0);
    }

    #[test]
    fn wrap_pi_examples() {
        assert_eq!(wrap_pi(0.5), 0.5);
        assert_eq!(wrap_pi(-PI), -PI);
        // PI (f32) exceeds pi by 8.7e-8, so it wraps to -pi + 8.7e-8, the f32 just above -PI.
        let w = wrap_pi(PI);
        assert!(w > -PI && w < -PI + 1e-6, "{w}");
        let w = wrap_pi(3.0 * core::f32::consts::PI / 2.0);
        assert!((w + core::f32::consts::FRAC_PI_2).abs() < 1e-6, "{w}");
        assert!(wrap_pi(f32::NAN).is_nan());
        assert!(wrap_pi(f32::INFINITY).is_nan());
    }
}
