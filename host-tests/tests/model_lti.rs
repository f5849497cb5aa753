//! Model pipeline against scipy: transfer function -> canonical state space -> ZOH (f64) ->
//! f32 runtime block, on the paper's eq 5 and eq 7 and on random stable 1st..3rd order
//! transfer functions (`reference/model_zoh.json`, made by `reference/gen_model.py` with
//! `scipy.signal.cont2discrete` and `dlsim`). Plus properties (proptest) of blocks and delay
//! lines, and the typed errors.
//!
//! Tolerances: f64 discretization vs scipy rtol 1e-9 (atol 1e-12 x coefficient scale);
//! f32 block vs scipy f64 simulation: |err| <= 1e-5 x max|y| + 1e-6 (rounding A, B, C, D to
//! f32 and f32 accumulation).
use catmodel::model::block::{MisoBlock, SsBlock};
use catmodel::model::delay::DelayLine;
use catmodel::model::paper;
use catmodel::model::tf::{ModelError, TransferFunction};
use catmodel::model::zoh::{delay_samples, discretize};
use catmodel_host_tests::{assert_allclose, load_reference};
use proptest::prelude::*;
use serde_json::Value;

const F64_RTOL: f64 = 1e-9;
const F32_REL_TO_PEAK: f64 = 1e-5;

fn vec_f64(v: &Value) -> Vec<f64> {
    v.as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect()
}

fn cases() -> Vec<Value> {
    load_reference("model_zoh.json")["cases"]
        .as_array()
        .expect("cases")
        .clone()
}

fn case_tf(c: &Value) -> TransferFunction {
    TransferFunction::new(
        &vec_f64(&c["num"]),
        &vec_f64(&c["den"]),
        c["delay_s"].as_f64().unwrap(),
    )
    .unwrap()
}

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0f64, |m, x| m.max(x.abs()))
}

/// f64 discretization: discrete TF, matrices (same canonical realization as scipy's tf2ss)
/// and delay, for every reference case.
#[test]
fn zoh_matches_scipy_cont2discrete() {
    let cases = cases();
    assert_eq!(cases.len(), 29);
    let mut worst_tf = 0.0f64;
    for c in &cases {
        let name = c["name"].as_str().unwrap();
        let ts = c["ts"].as_f64().unwrap();
        let tf = case_tf(c);
        let d = discretize(&tf, ts).unwrap();
        assert_eq!(
            d.delay_samples as u64,
            c["delay_samples"].as_u64().unwrap(),
            "{name}: delay"
        );
        let h = d.transfer_function();
        let dnum = vec_f64(&c["dnum"]);
        let dden = vec_f64(&c["dden"]);
        let scale = max_abs(&dnum).max(max_abs(&dden));
        for (a, b) in h
            .numerator()
            .iter()
            .chain(h.denominator())
            .zip(dnum.iter().chain(&dden))
        {
            worst_tf = worst_tf.max((a - b).abs() / scale);
        }
        assert_allclose(
            h.numerator(),
            &dnum,
            F64_RTOL,
            1e-12 * scale,
            &format!("{name} num"),
        );
        assert_allclose(
            h.denominator(),
            &dden,
            F64_RTOL,
            1e-12,
            &format!("{name} den"),
        );
        let n = d.n;
        let ad: Vec<f64> = d.ad.iter().take(n).flat_map(|r| r[..n].to_vec()).collect();
        let ad_ref: Vec<f64> = c["ad"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(vec_f64)
            .collect();
        assert_allclose(&ad, &ad_ref, F64_RTOL, 1e-13, &format!("{name} Ad"));
        assert_allclose(
            &d.bd[..n],
            &vec_f64(&c["bd"]),
            F64_RTOL,
            1e-13,
            &format!("{name} Bd"),
        );
        assert_allclose(
            &d.cd[..n],
            &vec_f64(&c["cd"]),
            F64_RTOL,
            1e-13,
            &format!("{name} Cd"),
        );
        assert_allclose(&[d.dd], &[c["dd"].as_f64().unwrap()], F64_RTOL, 1e-15, name);
    }
    println!(
        "worst discrete-TF coefficient error relative to the largest coefficient: {worst_tf:.3e}"
    );
}

/// Eq 5 discretized at 20 ms (ZOH), as computed once with scipy.signal.cont2discrete (8
/// significant digits): num [0.03679, -0.07732120, 0.04083214], den [1, -1.96764899, 0.96794501].
#[test]
fn eq5_discrete_tf_matches_facts() {
    let d = discretize(&paper::EQ5_INTERNAL_CONTROLLER, 0.02).unwrap();
    let h = d.transfer_function();
    assert_eq!(h.delay_samples, 21);
    assert_allclose(
        h.numerator(),
        &[0.03679, -0.07732120, 0.04083214],
        0.0,
        5e-9,
        "num",
    );
    assert_allclose(
        h.denominator(),
        &[1.0, -1.96764899, 0.96794501],
        0.0,
        5e-9,
        "den",
    );
}

/// f32 blocks (any order 1..3, through the const-generic N) vs scipy dlsim, on a step and
/// on a random input, delay included.
#[test]
fn f32_blocks_match_scipy_dlsim() {
    fn run<const N: usize>(c: &Value, worst: &mut f64) {
        let name = c["name"].as_str().unwrap();
        let ts = c["ts"].as_f64().unwrap();
        let block = SsBlock::<N>::from_tf(&case_tf(c), ts).unwrap();
        for (u_of, key) in [
            (None, "y_step"),
            (Some(vec_f64(&c["u_random"])), "y_random"),
        ] {
            let y_ref = vec_f64(&c[key]);
            let mut st = block.zero_state();
            let y: Vec<f64> = (0..y_ref.len())
                .map(|k| {
                    let u = u_of.as_ref().map_or(1.0, |u| u[k]) as f32;
                    f64::from(block.step(&mut st, u))
                })
                .collect();
            let peak = max_abs(&y_ref);
            let err = y
                .iter()
                .zip(&y_ref)
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
            *worst = worst.max(err / peak);
            assert_allclose(
                &y,
                &y_ref,
                0.0,
                F32_REL_TO_PEAK * peak + 1e-6,
                &format!("{name} {key}"),
            );
        }
    }
    let mut worst = 0.0;
    for c in &cases() {
        match c["den"].as_array().unwrap().len() - 1 {
            1 => run::<1>(c, &mut worst),
            2 => run::<2>(c, &mut worst),
            3 => run::<3>(c, &mut worst),
            n => panic!("order {n}"),
        }
    }
    println!("worst f32 block error relative to peak: {worst:.3e}");
}

/// Eq 5 step response: zero for 21 samples, a jump of b0 = 0.03679 at 0.42 s, the dip of the
/// right-half-plane zeros, DC gain 1.01662.
#[test]
fn eq5_step_response_shape() {
    let block = SsBlock::<2>::from_tf(&paper::EQ5_INTERNAL_CONTROLLER, 0.02).unwrap();
    let mut st = block.zero_state();
    let y: Vec<f32> = (0..3000).map(|_| block.step(&mut st, 1.0)).collect();
    assert!(
        y[..21].iter().all(|&v| v == 0.0),
        "exactly zero before 0.42 s"
    );
    assert!((y[21] - 0.03679).abs() < 1e-4, "jump at 0.42 s: {}", y[21]);
    // The dip: after the jump the response first falls (numerator zeros in the RHP).
    assert!(
        y[22] < y[21] && y[23] < y[22],
        "dip after the jump: {:?}",
        &y[20..25]
    );
    let min_after = y[22..100].iter().cloned().fold(f32::INFINITY, f32::min);
    println!("eq 5 step: jump {} then minimum {min_after}", y[21]);
    assert!((y[2999] - 1.01662).abs() < 1e-4, "DC: {}", y[2999]);
    assert!((block.dc_gain().unwrap() - 1.01662).abs() < 1e-5);
}

/// A block started at the equilibrium for a measured output stays there.
#[test]
fn steady_state_start_holds() {
    let block = SsBlock::<2>::from_tf(&paper::EQ5_INTERNAL_CONTROLLER, 0.02).unwrap();
    let v_mps = 12.5f32;
    let mut st = block.steady_state_for_output(v_mps).unwrap();
    let u = v_mps / block.dc_gain().unwrap();
    for k in 0..500 {
        let y = block.step(&mut st, u);
        assert!((y - v_mps).abs() < 1e-4 * v_mps, "step {k}: {y}");
    }
    let miso = MisoBlock::<2, 4>::from_tfs(&paper::EQ7_DX_DT, 0.02).unwrap();
    let inputs = [10.0, 3.0, -2.0, 0.1];
    let mut st = miso.steady_state_for(&inputs).unwrap();
    let y_ss = miso.steady_output_for(&inputs).unwrap();
    let expect: f64 = paper::EQ7_DX_DT
        .iter()
        .zip(inputs)
        .map(|(tf, u)| tf.dc_gain().unwrap() * f64::from(u))
        .sum();
    assert!((f64::from(y_ss) - expect).abs() < 1e-4 * expect.abs());
    for _ in 0..200 {
        let y = miso.step(&mut st, &inputs);
        assert!(
            (f64::from(y) - expect).abs() < 2e-4 * expect.abs(),
            "{y} vs {expect}"
        );
    }
}

/// Eq 7 as a MISO block equals the sum of the four scipy-simulated SISO responses.
#[test]
fn eq7_miso_is_sum_of_references() {
    let cases = cases();
    let by_name = |n: &str| cases.iter().find(|c| c["name"] == n).unwrap().clone();
    let refs: Vec<Value> = ["eq7_h1", "eq7_h2", "eq7_h3", "eq7_h4"]
        .iter()
        .map(|n| by_name(n))
        .collect();
    let miso = MisoBlock::<2, 4>::from_tfs(&paper::EQ7_DX_DT, 0.02).unwrap();
    let us: Vec<Vec<f64>> = refs.iter().map(|c| vec_f64(&c["u_random"])).collect();
    let ys: Vec<Vec<f64>> = refs.iter().map(|c| vec_f64(&c["y_random"])).collect();
    let y_ref: Vec<f64> = (0..ys[0].len())
        .map(|k| ys.iter().map(|y| y[k]).sum())
        .collect();
    let mut st = miso.zero_state();
    let y: Vec<f64> = (0..y_ref.len())
        .map(|k| {
            let u = [
                us[0][k] as f32,
                us[1][k] as f32,
                us[2][k] as f32,
                us[3][k] as f32,
            ];
            f64::from(miso.step(&mut st, &u))
        })
        .collect();
    let peaks: f64 = ys.iter().map(|y| max_abs(y)).sum();
    assert_allclose(&y, &y_ref, 0.0, F32_REL_TO_PEAK * peaks, "eq7 MISO");
}

#[test]
fn typed_errors() {
    let tf = |n: &[f64], d: &[f64], t: f64| TransferFunction::new(n, d, t);
    assert!(matches!(
        tf(&[1.0, 0.0, 0.0], &[1.0, 1.0], 0.0),
        Err(ModelError::Improper {
            numerator_degree: 2,
            denominator_degree: 1
        })
    ));
    assert_eq!(
        tf(&[1.0], &[0.0, 1.0, 2.0], 0.0),
        Err(ModelError::ZeroLeadingDenominator)
    );
    assert_eq!(
        tf(&[1.0, f64::NAN], &[1.0, 1.0], 0.0),
        Err(ModelError::NotFinite)
    );
    assert_eq!(
        tf(&[1.0], &[1.0, 4.0, 6.0, 4.0, 1.0], 0.0),
        Err(ModelError::OrderTooHigh { order: 4, max: 3 })
    );
    let delayed = tf(&[1.0], &[1.0, 1.0], 0.05).unwrap();
    assert_eq!(
        discretize(&delayed, 0.02),
        Err(ModelError::FractionalDelay {
            delay_s: 0.05,
            ts_s: 0.02
        })
    );
    assert_eq!(delay_samples(0.05, 0.025), Ok(2));
    assert_eq!(
        SsBlock::<3>::from_tf(&paper::EQ5_INTERNAL_CONTROLLER, 0.02),
        Err(ModelError::OrderMismatch {
            expected: 3,
            found: 2
        })
    );
    assert_eq!(
        SsBlock::<2, 20>::from_tf(&paper::EQ5_INTERNAL_CONTROLLER, 0.02),
        Err(ModelError::DelayTooLong {
            delay_samples: 21,
            capacity: 20
        })
    );
    assert!(SsBlock::<2, 21>::from_tf(&paper::EQ5_INTERNAL_CONTROLLER, 0.02).is_ok());
    let integrator = tf(&[1.0], &[1.0, 0.0], 0.0).unwrap();
    let block = SsBlock::<1>::from_tf(&integrator, 0.02).unwrap();
    assert_eq!(block.steady_state_for(1.0), Err(ModelError::NoEquilibrium));
}

/// A random stable 2nd-order TF, poles -sigma ± j omega (sigma in [0.3, 15]), numerator
/// coefficients in [-5, 5], delay 0..5 samples.
fn stable_block() -> impl Strategy<Value = SsBlock<2, 8>> {
    (
        0.3f64..15.0,
        0.0f64..12.0,
        prop::array::uniform3(-5.0f64..5.0),
        0usize..6,
        prop::sample::select(vec![0.02f64, 0.05, 0.1]),
    )
        .prop_map(|(sigma, omega, num, delay, ts)| {
            let den = [1.0, 2.0 * sigma, sigma * sigma + omega * omega];
            let tf = TransferFunction::new(&num, &den, delay as f64 * ts).unwrap();
            SsBlock::<2, 8>::from_tf(&tf, ts).unwrap()
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn stable_block_bounded_input_bounded_output(
        block in stable_block(),
        u in prop::collection::vec(-100.0f32..100.0, 1..400),
    ) {
        let mut st = block.zero_state();
        for &uk in &u {
            let y = block.step(&mut st, uk);
            prop_assert!(y.is_finite());
            // |u| <= 100 and the impulse response of these TFs has an l1 norm far below 1e4.
            prop_assert!(y.abs() < 100.0 * 1e4, "y = {}", y);
        }
    }

    #[test]
    fn superposition(
        block in stable_block(),
        u1 in prop::collection::vec(-10.0f32..10.0, 60),
        u2 in prop::collection::vec(-10.0f32..10.0, 60),
        a in -3.0f32..3.0,
        b in -3.0f32..3.0,
    ) {
        let run = |u: &mut dyn Iterator<Item = f32>| {
            let mut st = block.zero_state();
            u.map(|x| block.step(&mut st, x)).collect::<Vec<f32>>()
        };
        let y1 = run(&mut u1.iter().copied());
        let y2 = run(&mut u2.iter().copied());
        let y12 = run(&mut u1.iter().zip(&u2).map(|(x1, x2)| a * x1 + b * x2));
        let scale = y1.iter().chain(&y2).fold(1.0f32, |m, v| m.max(v.abs()))
            * (a.abs() + b.abs() + 1.0);
        for k in 0..y12.len() {
            let lin = a * y1[k] + b * y2[k];
            prop_assert!((y12[k] - lin).abs() <= 1e-5 * scale, "k {}: {} vs {}", k, y12[k], lin);
        }
    }

    #[test]
    fn delay_line_delays_by_exactly_d(
        d in 0usize..=16,
        prime in -5.0f32..5.0,
        xs in prop::collection::vec(any::<f32>(), 0..100),
    ) {
        let line = DelayLine::<16>::new(d).unwrap();
        let mut st = line.state_primed(prime);
        for (k, &x) in xs.iter().enumerate() {
            let y = line.push(&mut st, x);
            let expect = if k >= d { xs[k - d] } else { prime };
            prop_assert_eq!(y.to_bits(), expect.to_bits());
        }
    }
}
