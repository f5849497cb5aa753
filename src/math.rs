//! The few `f32` transcendental functions the node uses, each with a measured error bound.
//!
//! Why not `micromath`: the node must hold position to 1 cm over a 40 m horizon (2.5e-4
//! relative) and heading to 1 mrad. `micromath` trades accuracy for speed and misses that by one
//! to three orders of magnitude (measured by `host-tests/tests/math_bounds.rs` on the same grids
//! as below: sin/cos 1.1e-3 absolute, atan/atan2 2.8e-3 rad, sqrt 6.1e-2 relative, tan 2.3e-2
//! relative on ±0.7 rad).
//!
//! Why not `libm` for sin/cos/tan: its `sinf`/`cosf`/`tanf` evaluate in `f64`, which the
//! Cortex-M4F (single-precision FPU) emulates in software: 1 200 to 2 300 instructions per call
//! (measured in QEMU), a tenth of the node's tick budget for four calls. [`sin_cos`] and [`tan`]
//! here are pure `f32`: Cody-Waite reduction by pi/2 with a three-part constant, then Taylor
//! polynomials on [-pi/4, pi/4] (truncation < 1e-9, below f32 rounding), about 40
//! instructions. `atan`/`atan2`/`sqrt` stay `libm`: they are `f32` throughout and cheap
//! (80 to 110 instructions for `atan2f`).
//!
//! Bit-identity across targets (host replay vs Cortex-M4F, see `docs/architecture.md`): only
//! additions, multiplications, divisions, comparisons and float/int conversions, evaluated in
//! source order (Rust never fuses a multiply-add on its own), so x86-64 and the M4F give the
//! same bits. `libm` is plain Rust
//! arithmetic too, with one target-specific path: on x86-64 `sqrtf` is the `sqrtss`
//! instruction. IEEE 754 requires square root to be correctly rounded, and `libm`'s software
//! `sqrtf` is correctly rounded too, so both give the same bits.
//!
//! Bounds below are the worst case over dense grids (`cargo test -p catmodel-host-tests --test
//! math_bounds`), measured against `f64` `std` functions, and asserted there.

/// pi as `f32` (rounded up: 3.14159274 > pi by 8.7e-8).
pub const PI: f32 = core::f32::consts::PI;
/// 2 pi split in two for exact range reduction (Cody-Waite): `TAU_HI` has trailing zero bits
/// so `k * TAU_HI` is exact for |k| < 2^8, and `TAU_HI + TAU_LO` = 2 pi to 3e-12.
const TAU_HI: f32 = 6.283_081;
const TAU_LO: f32 = 1.042_524_9e-4;

/// pi / 2 in three parts for the reduction of [`sin_cos`] and [`tan`]: `PIO2_1` has 8
/// significant bits and `PIO2_2` 11, so `k * PIO2_1` and `k * PIO2_2` are exact for
/// |k| < 2^13; the three sum to pi / 2 within 1.8e-15.
const PIO2_1: f32 = 1.570_312_5;
const PIO2_2: f32 = 4.837_513e-4;
const PIO2_3: f32 = 7.549_79e-8;
/// 2 / pi, rounded to f32 (only selects the quadrant; the reduction itself is exact).
const FRAC_2_PI: f32 = core::f32::consts::FRAC_2_PI;
/// Largest |x| [`sin_cos`] and [`tan`] accept: 2^13 quadrants of pi / 2 (about 12 868 rad).
pub const TRIG_MAX_ARG: f32 = 12_000.0;

/// 1/n! for the Taylor series, rounded to f32.
const INV_3F: f32 = 1.0 / 6.0;
const INV_5F: f32 = 1.0 / 120.0;
const INV_7F: f32 = 1.0 / 5_040.0;
const INV_9F: f32 = 1.0 / 362_880.0;
const INV_4F: f32 = 1.0 / 24.0;
const INV_6F: f32 = 1.0 / 720.0;
const INV_8F: f32 = 1.0 / 40_320.0;
const INV_10F: f32 = 1.0 / 3_628_800.0;

/// `x` reduced to `r` in about [-pi/4, pi/4] with `x = r + k pi/2`; returns `(r, k mod 4)`.
/// Callers check |x| <= [`TRIG_MAX_ARG`] first.
#[inline(always)]
fn reduce_pio2(x: f32) -> (f32, u32) {
    let t = x * FRAC_2_PI;
    // Round half away from zero; |t| < 2^13, so the conversion is exact and in range.
    let k = (if t >= 0.0 { t + 0.5 } else { t - 0.5 }) as i32;
    let kf = k as f32;
    let r = ((x - kf * PIO2_1) - kf * PIO2_2) - kf * PIO2_3;
    (r, (k & 3) as u32)
}

/// sin and cos of `r` in [-pi/4, pi/4] by Taylor series to r^9 and r^10 (truncation
/// < 7e-10 and < 1.2e-10 there).
#[inline(always)]
fn sin_cos_kernel(r: f32) -> (f32, f32) {
    let r2 = r * r;
    let s = r + r * r2 * (-INV_3F + r2 * (INV_5F + r2 * (-INV_7F + r2 * INV_9F)));
    let c = 1.0 - 0.5 * r2 + r2 * r2 * (INV_4F + r2 * (-INV_6F + r2 * (INV_8F - r2 * INV_10F)));
    (s, c)
}

/// `(sin x, cos x)` of `x` rad, pure `f32` (one reduction for both, see the module doc).
/// Measured worst error on [-pi, pi] (heading, increments, steering): 9.1e-8 absolute for
/// each (1.5 ulp near 1); 1.0e-7 over the whole domain |x| <= [`TRIG_MAX_ARG`]. Larger |x| or
/// non-finite gives (NaN, NaN).
///
/// One function, called: inlined at each of the node's dozen calls it cost the board 4.2 KiB
/// of flash (`cargo xtask size`). The loops the tick's instruction bound counts call
/// [`sin_cos_inlined`], the same arithmetic.
#[inline(never)]
pub fn sin_cos(x: f32) -> (f32, f32) {
    sin_cos_inlined(x)
}

/// [`sin_cos`] inlined where it is called: for the per-stage and per-point loops (the
/// predictor's, the MPC's, a path's load), where a call per iteration shows in the tick's
/// bound (`cargo qemu`).
#[inline(always)]
pub fn sin_cos_inlined(x: f32) -> (f32, f32) {
    if x.is_nan() || x.abs() > TRIG_MAX_ARG {
        return (f32::NAN, f32::NAN);
    }
    let (r, q) = reduce_pio2(x);
    let (s, c) = sin_cos_kernel(r);
    match q {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

/// Sine of `x` rad: [`sin_cos`]`(x).0`, same bound.
#[inline]
pub fn sin(x: f32) -> f32 {
    sin_cos(x).0
}

/// Cosine of `x` rad: [`sin_cos`]`(x).1`, same bound.
#[inline]
pub fn cos(x: f32) -> f32 {
    sin_cos(x).1
}

/// Tangent of `x` rad, pure `f32`: the reduced sine over cosine (or minus cosine over sine in
/// odd quadrants). Measured worst relative error on [-1.4, 1.4] (covers steering angles to
/// ±0.7 rad with margin), and on [1.4, 1.55] towards the pole: 2.2e-7. |x| > [`TRIG_MAX_ARG`] or non-finite gives NaN.
/// One function, called, as [`sin_cos`] is (2.5 KiB of flash inlined); [`tan_inlined`] for loops.
#[inline(never)]
pub fn tan(x: f32) -> f32 {
    tan_inlined(x)
}

/// [`tan`] inlined where it is called (see [`sin_cos_inlined`]).
#[inline(always)]
pub fn tan_inlined(x: f32) -> f32 {
    if x.is_nan() || x.abs() > TRIG_MAX_ARG {
        return f32::NAN;
    }
    let (r, q) = reduce_pio2(x);
    let (s, c) = sin_cos_kernel(r);
    if q & 1 == 0 {
        s / c
    } else {
        -c / s
    }
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

/// Square root, correctly rounded (IEEE 754), so relative error <= 2^-24 (6.0e-8); measured
/// 6.0e-8 on 0..1e6. On a hard-float Arm target the FPU's `VSQRT.F32` (IEEE 754's correctly
/// rounded square root: the same bits as `libm::sqrtf`, whose integer routine is some forty
/// instructions on the M4F); elsewhere `libm::sqrtf`.
#[inline]
pub fn sqrt(x: f32) -> f32 {
    #[cfg(all(target_arch = "arm", target_abi = "eabihf"))]
    {
        // SAFETY: `catmodel_vsqrtf` (below) reads its argument from s0 and returns in s0, as
        // the hard-float procedure call standard passes an `f32`; it touches nothing else.
        unsafe { catmodel_vsqrtf(x) }
    }
    #[cfg(not(all(target_arch = "arm", target_abi = "eabihf")))]
    {
        libm::sqrtf(x)
    }
}

// The FPU's square root as a function of the hard-float ABI (stable Rust names no Arm FPU
// register class for inline assembly without the unstable `vfp2` target feature).
#[cfg(all(target_arch = "arm", target_abi = "eabihf"))]
core::arch::global_asm!(
    ".section .text.catmodel_vsqrtf,\"ax\",%progbits",
    ".global catmodel_vsqrtf",
    ".type catmodel_vsqrtf,%function",
    ".fpu fpv4-sp-d16",
    ".thumb_func",
    "catmodel_vsqrtf:",
    "vsqrt.f32 s0, s0",
    "bx lr",
    ".size catmodel_vsqrtf, . - catmodel_vsqrtf",
);

#[cfg(all(target_arch = "arm", target_abi = "eabihf"))]
unsafe extern "C" {
    fn catmodel_vsqrtf(x: f32) -> f32;
}

/// sqrt(x^2 + y^2) without intermediate overflow. `libm::hypotf` (it works in `f64`, soft on
/// the M4F: not for the node's tick; host tools only). Measured worst relative
/// error on |x|, |y| <= 1e4: 9.0e-8.
#[inline]
pub fn hypot(x: f32, y: f32) -> f32 {
    libm::hypotf(x, y)
}

/// Wraps an angle in rad to [-PI, PI) (with `PI` the `f32` constant above). Inputs already in
/// range are returned unchanged (bit-exact); others are reduced by k * 2 pi with a two-part
/// 2 pi, so the result is within 1.2e-7 rad of the exact reduction for |x| <= 100 rad (measured;
/// the node's heading only ever leaves the range by one increment). Non-finite in, NaN out.
/// The range check is inlined at every call, the reduction is one function: the node calls
/// this some forty places, and a reduction inlined at each cost the board's flash.
#[inline(always)]
pub fn wrap_pi(x: f32) -> f32 {
    if (-PI..PI).contains(&x) {
        x
    } else {
        wrap_pi_reduce(x)
    }
}

/// [`wrap_pi`] of an angle outside [-PI, PI).
#[inline(never)]
fn wrap_pi_reduce(x: f32) -> f32 {
    // One turn out, the usual case (a heading plus an increment, a difference of two
    // headings, a course in [0, 2 pi)): k = +-1 without the division and `floorf`; the same
    // result as the general reduction with that k.
    let k = if (PI..3.0 * PI).contains(&x) {
        1.0
    } else if (-3.0 * PI..-PI).contains(&x) {
        -1.0
    } else if x.is_finite() {
        libm::floorf((x + PI) / (TAU_HI + TAU_LO))
    } else {
        return f32::NAN;
    };
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

/// `x as f32`, the same rounding of the same value, but through `u32` where it fits: the
/// Cortex-M4 converts 32-bit integers with one VCVT, 64-bit ones with a soft-float call.
#[inline(always)]
pub fn u64_to_f32(x: u64) -> f32 {
    match u32::try_from(x) {
        Ok(small) => small as f32,
        Err(_) => x as f32,
    }
}

/// `x as f32` through `i32` where it fits (see [`u64_to_f32`]).
#[inline(always)]
pub fn i64_to_f32(x: i64) -> f32 {
    match i32::try_from(x) {
        Ok(small) => small as f32,
        Err(_) => x as f32,
    }
}

// ---------------------------------------------------------------------------------------------
// Comparisons that never panic and never call software maxNum/minNum: `f32::clamp` asserts
// `lo <= hi` with a message that formats both floats (linking ~20 KiB of float formatting into
// the firmware, and a panic path the no-panic check refuses), and `f32::max`/`min` are IEEE
// maxNum/minNum, which the Cortex-M4F has no instruction for (a call to software `fmaxf`:
// measured, the MPC solver's iterations took a third more instructions with it).

/// One step of a running median of magnitudes (a stochastic approximation, in its logarithm:
/// up by `step` of itself when a sample is larger, down when not) towards a sample given by
/// its square `sample_sq`, kept within `[lo, hi]`; a step that is not finite keeps `median`.
/// The node's gates learn their receiver's scatter with it, with no square root per sample.
#[inline]
pub fn median_step(median: f32, sample_sq: f32, step: f32, lo: f32, hi: f32) -> f32 {
    let next = if sample_sq > median * median {
        median * (1.0 + step)
    } else {
        median * (1.0 - step)
    };
    if next.is_finite() {
        clamp(next, lo, hi)
    } else {
        median
    }
}

/// The larger of `a` and `b` by one comparison (`b` if either is NaN).
#[inline(always)]
pub fn max(a: f32, b: f32) -> f32 {
    if a > b {
        a
    } else {
        b
    }
}

/// The smaller of `a` and `b` by one comparison (`b` if either is NaN).
#[inline(always)]
pub fn min(a: f32, b: f32) -> f32 {
    if a < b {
        a
    } else {
        b
    }
}

/// `v` limited to `[lo, hi]` by comparisons (`lo <= hi` expected, never checked); a NaN `v`
/// gives `lo`.
#[inline(always)]
pub fn clamp(v: f32, lo: f32, hi: f32) -> f32 {
    min(max(v, lo), hi)
}

/// `v` limited to `[lo, hi]`; `lo` when `v` is not finite (a NaN or an infinity never becomes
/// an output).
#[inline]
pub fn clamp_finite(v: f32, lo: f32, hi: f32) -> f32 {
    if v.is_finite() {
        clamp(v, lo, hi)
    } else {
        lo
    }
}

/// `v` if finite, else `fallback`.
#[inline]
pub fn finite_or(v: f32, fallback: f32) -> f32 {
    if v.is_finite() {
        v
    } else {
        fallback
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn integer_to_f32_through_32_bits_rounds_like_the_64_bit_cast() {
        let mut edges: Vec<i64> = vec![0, 1, -1, i64::MAX, i64::MIN];
        for shift in 0..63 {
            for delta in -3i64..=3 {
                edges.push((1i64 << shift).wrapping_add(delta));
                edges.push((1i64 << shift).wrapping_neg().wrapping_add(delta));
            }
        }
        // And a pseudo-random sweep (xorshift).
        let mut r = 0x9E37_79B9_7F4A_7C15u64;
        for _ in 0..200_000 {
            r ^= r << 13;
            r ^= r >> 7;
            r ^= r << 17;
            edges.push(r as i64 >> (r % 40));
        }
        for x in edges {
            assert_eq!(super::i64_to_f32(x).to_bits(), (x as f32).to_bits(), "{x}");
            let u = x as u64;
            assert_eq!(super::u64_to_f32(u).to_bits(), (u as f32).to_bits(), "{u}");
        }
    }

    use super::*;

    #[test]
    fn tau_split_is_two_pi() {
        let tau = TAU_HI as f64 + TAU_LO as f64;
        assert!((tau - core::f64::consts::TAU).abs() < 5e-12, "{tau}");
        // TAU_HI must have at least 8 trailing zero mantissa bits for exact k * TAU_HI.
        assert_eq!(TAU_HI.to_bits() & 0xff, 0);
    }

    #[test]
    fn comparisons_never_pass_a_nan_through_clamp() {
        assert_eq!(clamp(f32::NAN, -1.0, 2.0), -1.0);
        assert_eq!(clamp(5.0, -1.0, 2.0), 2.0);
        assert_eq!(clamp(-5.0, -1.0, 2.0), -1.0);
        assert_eq!(clamp_finite(f32::INFINITY, -1.0, 2.0), -1.0);
        assert_eq!(finite_or(f32::NEG_INFINITY, 0.5), 0.5);
        assert_eq!(max(1.0, 3.0), 3.0);
        assert_eq!(min(1.0, 3.0), 1.0);
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
