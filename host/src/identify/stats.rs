//! The robust statistics the identification's checks share: one median, one period, one noise
//! estimate, so that every check reads a log the same way; and the weights that pool logs of
//! unequal noise in one fit.

/// The median of `v` (sorted in place): the middle value, or the mean of the two middle ones
/// for an even count; NaN for none.
pub fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    match n {
        0 => f64::NAN,
        _ if n % 2 == 1 => v[n / 2],
        _ => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    }
}

/// The median of the absolute value of a unit normal: a median absolute deviation over this is
/// the deviation of Gaussian noise.
pub const MEDIAN_ABS_UNIT_NORMAL: f64 = 0.6745;

/// The median interval between consecutive times, s (NaN for fewer than two).
pub fn median_interval(t: &[f64]) -> f64 {
    let mut d: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    median(&mut d)
}

/// The deviation of white noise on a signal from the absolute second differences of its
/// samples, `|x[k+1] - 2 x[k] + x[k-1]|` (reordered in place): their median over its value for
/// noise of unit deviation, `0.6745 sqrt(6)`. A smooth signal's own second differences (a
/// ramp's corners, a car's acceleration) are few or small, and the median leaves them out.
/// NaN for none.
pub fn noise_from_second_differences(d2: &mut [f64]) -> f64 {
    median(d2) / (MEDIAN_ABS_UNIT_NORMAL * 6f64.sqrt())
}

/// Residuals a log needs for its own noise to weigh it in [`inverse_noise_weights`] (5 s at
/// 20 ms); a log of fewer takes the pool's.
pub const MIN_NOISE_SAMPLES: usize = 250;
/// The steadiest a log counts for in [`inverse_noise_weights`], relative to the pool's mean
/// square: a log that fits exactly weighs a thousand times the pool's deviation, not infinitely.
const MIN_NOISE_OF_POOL: f64 = 1e-6;

/// Weights for a least-squares fit pooled over logs whose noise differs (logs of a standard
/// and of a survey-grade receiver, of a slow and of a fast one): one over each log's residual
/// deviation, from `residuals[g]` (log `g`'s residuals of a first fit with every log alike).
/// A log of fewer than [`MIN_NOISE_SAMPLES`] takes the pool's deviation. With equal noise every
/// weight is about the same, and the fit is the unweighted one; without, a log that carries
/// most of the noise no longer sets the fit's error for all (measured: a survey-grade
/// receiver's step steers determine a car's stiffnesses to 2.4 % and 3.8 %; with the
/// paper-sized set of a standard receiver's drives beside them, all alike, 14 % and 21 %).
/// All ones where the pool has no noise to measure (none, or no samples).
pub fn inverse_noise_weights(residuals: &[&[f64]]) -> Vec<f64> {
    let mean_square = |r: &[f64]| r.iter().map(|x| x * x).sum::<f64>() / r.len().max(1) as f64;
    let all: Vec<f64> = residuals.concat();
    let pooled = mean_square(&all);
    if !(pooled.is_finite() && pooled > 0.0) {
        return vec![1.0; residuals.len()];
    }
    residuals
        .iter()
        .map(|r| {
            let own = if r.len() >= MIN_NOISE_SAMPLES {
                mean_square(r).max(MIN_NOISE_OF_POOL * pooled)
            } else {
                pooled
            };
            1.0 / own.sqrt()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_of_odd_even_and_no_values() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 2.5);
        assert!(median(&mut []).is_nan());
        assert!(median_interval(&[1.0]).is_nan());
        assert_eq!(median_interval(&[0.0, 0.1, 0.2, 0.9, 1.0]), 0.1);
    }

    /// Gaussian noise of deviation 0.3 (a fixed LCG and Box-Muller, no crate) on a ramp: the
    /// estimate within 5 % of 0.3 over 20 000 samples, and the ramp alone gives 0.
    #[test]
    fn the_noise_of_a_ramp_is_its_noise() {
        let mut state = 12345u64;
        let mut uniform = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let x: Vec<f64> = (0..20_000)
            .map(|k| {
                let g = (-2.0 * uniform().ln()).sqrt() * (std::f64::consts::TAU * uniform()).cos();
                0.5 * k as f64 + 0.3 * g
            })
            .collect();
        let mut d2: Vec<f64> = x
            .windows(3)
            .map(|w| (w[2] - 2.0 * w[1] + w[0]).abs())
            .collect();
        let sigma = noise_from_second_differences(&mut d2);
        assert!((sigma - 0.3).abs() < 0.015, "{sigma}");
        let mut ramp: Vec<f64> = vec![0.0; 100];
        assert_eq!(noise_from_second_differences(&mut ramp), 0.0);
    }

    /// Logs of deviations 0.1 and 1 (alternating signs, 10 000 samples each): weights 10 and
    /// 1; a log of too few samples (and one of none) takes the pool's deviation, sqrt(0.505)
    /// (hand-derived: (100 + 10 000 + 200 x 4) / 20 200 with the short log's deviation 2, and
    /// (100 + 10 000) / 20 000 without it); a log that fits exactly weighs a thousand times the
    /// pool's deviation (the pool's mean square 10 000 / 10 300); no noise at all: every weight 1.
    #[test]
    fn logs_are_weighted_by_their_own_noise() {
        let log = |sigma: f64, n: usize| -> Vec<f64> {
            (0..n)
                .map(|k| if k % 2 == 0 { sigma } else { -sigma })
                .collect()
        };
        let (quiet, noisy, short) = (log(0.1, 10_000), log(1.0, 10_000), log(2.0, 200));
        let w = inverse_noise_weights(&[&quiet, &noisy, &short, &[]]);
        let pool = ((100.0 + 10_000.0 + 800.0) / 20_200.0f64).sqrt();
        assert!((w[0] - 10.0).abs() < 1e-9, "{w:?}");
        assert!((w[1] - 1.0).abs() < 1e-9, "{w:?}");
        assert!((w[2] - 1.0 / pool).abs() < 1e-9, "{w:?}");
        assert!((w[3] - 1.0 / pool).abs() < 1e-9, "{w:?}");
        let exact = inverse_noise_weights(&[&[0.0; 300], &noisy]);
        assert!(
            (exact[0] - 1e3 / (10_000.0 / 10_300.0f64).sqrt()).abs() < 1e-6,
            "{exact:?}"
        );
        assert_eq!(inverse_noise_weights(&[&[0.0; 5], &[]]), vec![1.0, 1.0]);
    }
}
