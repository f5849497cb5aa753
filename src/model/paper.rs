//! The published models and fit figures (Sheetz, Tadros, Risso, Sprinkle, CAT Vehicle system
//! identification), as continuous-time [`TransferFunction`]s, coefficients copied from the
//! paper's text (`reference/paper.txt`). Sample time of every model: 20 ms
//! ([`crate::SAMPLE_PERIOD_S`]).
//!
//! Both models are proper 2nd order (numerator degree 2 = denominator degree 2), so their
//! realizations have a direct feedthrough `D != 0`. The text calls eq 5 "a continuous time
//! transfer function model of order 3"; the equation printed is 2nd order, and that is what
//! is implemented.

use super::tf::TransferFunction;

/// Sample period of the published models, s, in f64 for the offline discretization.
/// Use this, not `f64::from(crate::SAMPLE_PERIOD_S)`: the f32 0.02 widens to
/// 0.019999999552965164, and 0.42 s / that is not a whole number of samples within 1e-9.
pub const PAPER_TS_S: f64 = 0.02;

/// Eq 5 numerator, descending powers of s (dimensionless: m/s of speed per m/s of command).
pub const EQ5_NUM: [f64; 3] = [0.03679, -0.1981, 0.7647];
/// Eq 5 denominator, descending powers of s.
pub const EQ5_DEN: [f64; 3] = [1.0, 1.629, 0.7522];
/// Eq 5 input delay, s (= 21 samples of 20 ms exactly).
pub const EQ5_DELAY_S: f64 = 0.42;
/// Eq 5 input delay at 20 ms, samples.
pub const EQ5_DELAY_SAMPLES: usize = 21;

/// Eq 5, the internal speed controller: commanded speed `input_vel` (m/s) -> measured speed
/// `vel` (m/s), `h(s) = e^{-0.42 s} (0.03679 s^2 - 0.1981 s + 0.7647) / (s^2 + 1.629 s +
/// 0.7522)`. DC gain 0.7647 / 0.7522 = 1.01662; poles -0.8145 ± 0.298j; zeros 2.69 ± 3.68j
/// (right half plane: the step response jumps by 0.03679 at 0.42 s, then dips below zero).
pub const EQ5_INTERNAL_CONTROLLER: TransferFunction =
    TransferFunction::second_order_unchecked(EQ5_NUM, EQ5_DEN, EQ5_DELAY_S);

/// Eq 7 `h1`: measured speed `v_m` (m/s) -> `dx/dt` (m/s); dimensionless.
pub const EQ7_H1: TransferFunction =
    TransferFunction::second_order_unchecked([-4.122, 49.61, -4.098], [1.0, 6.211, 26.79], 0.0);
/// Eq 7 `h2`: east position `x` (m) -> `dx/dt` (m/s); gain unit 1/s.
pub const EQ7_H2: TransferFunction =
    TransferFunction::second_order_unchecked([20.55, -110.4, 12.08], [1.0, 37.03, 111.7], 0.0);
/// Eq 7 `h3`: north position `y` (m) -> `dx/dt` (m/s); gain unit 1/s.
pub const EQ7_H3: TransferFunction = TransferFunction::second_order_unchecked(
    [-0.06946, -0.06244, 0.0002256],
    [1.0, 1.416, 0.5473],
    0.0,
);
/// Eq 7 `h4`: angle `phi` (rad) -> `dx/dt` (m/s); gain unit m/s per rad. The paper does not
/// define `phi`; its measurement list names "the steering angle measured in radians" among
/// the computed inputs, the most likely reading (inferred, not stated).
pub const EQ7_H4: TransferFunction =
    TransferFunction::second_order_unchecked([-22.3, 371.5, -26.08], [1.0, 6.59, 18.78], 0.0);
/// Eq 7 as one MISO row `dx/dt = [h1 h2 h3 h4] [v_m, x, y, phi]^T`, in that input order.
pub const EQ7_DX_DT: [TransferFunction; 4] = [EQ7_H1, EQ7_H2, EQ7_H3, EQ7_H4];
/// Eq 7 input names, in order, with units.
pub const EQ7_INPUTS: [&str; 4] = ["v_m [m/s]", "x [m]", "y [m]", "phi [rad]"];

/// Eq 5 fit on the test set, % (MATLAB `compare` fit, paper table after eq 5).
pub const EQ5_FIT_TEST_PERCENT: f64 = 78.53;
/// Eq 5 fit on the training set, %.
pub const EQ5_FIT_TRAINING_PERCENT: f64 = 74.53;
/// Eq 7 fit, % ("an associated fit percentage of 85.67%").
pub const EQ7_FIT_PERCENT: f64 = 85.67;
/// Speed MSE of the kinematic model (eq 8) on one experiment, (m/s)^2 (paper E.1).
pub const SPEED_MSE_KINEMATIC_M2_PER_S2: f64 = 1.0972;
/// Speed MSE of eq 5 on the same experiment, (m/s)^2.
pub const SPEED_MSE_EQ5_M2_PER_S2: f64 = 0.7430;
/// dx/dt MSE of the kinematic model (eq 8) on one experiment, (m/s)^2 (paper E.2).
pub const DX_DT_MSE_KINEMATIC_M2_PER_S2: f64 = 79.8702;
/// dx/dt MSE of eq 7 on the same experiment, (m/s)^2.
pub const DX_DT_MSE_EQ7_M2_PER_S2: f64 = 13.1558;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constants_pass_validation() {
        let checked = TransferFunction::new(&EQ5_NUM, &EQ5_DEN, EQ5_DELAY_S).unwrap();
        assert_eq!(checked, EQ5_INTERNAL_CONTROLLER);
        for tf in EQ7_DX_DT {
            let again = TransferFunction::new(tf.numerator(), tf.denominator(), tf.delay_s());
            assert_eq!(again, Ok(tf));
            assert!(!tf.is_strictly_proper());
        }
        assert!((EQ5_INTERNAL_CONTROLLER.dc_gain().unwrap() - 1.01662).abs() < 1e-5);
        assert_eq!(
            crate::model::zoh::delay_samples(EQ5_DELAY_S, f64::from(crate::SAMPLE_PERIOD_S)),
            Err(crate::model::tf::ModelError::FractionalDelay {
                delay_s: EQ5_DELAY_S,
                ts_s: f64::from(crate::SAMPLE_PERIOD_S)
            }),
            "f32 0.02 widened to f64 is not 0.02: callers must use an f64 sample period"
        );
        assert_eq!(
            crate::model::zoh::delay_samples(EQ5_DELAY_S, PAPER_TS_S),
            Ok(EQ5_DELAY_SAMPLES)
        );
    }
}
