//! `catmodel::signal` against scipy/numpy references (`reference/gen_signal.py`), hand-derived
//! MATLAB `smooth` vectors, and proptest invariants.
use catmodel::signal::{
    design_lowpass, filtfilt, filtfilt_scratch_len, fixed_period_grid, fixed_period_len,
    interp_linear, smooth, uniform_grid_eq1, FiltfiltError, Fir, FirState, MovingAverage,
    MovingAverageState, ResampleError, SmoothError,
};
use catmodel_host_tests::{assert_allclose, load_reference};
use proptest::prelude::*;
use serde_json::Value;

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

/// JSON array of numbers (null = NaN, a missing sample).
fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().unwrap_or(f64::NAN))
        .collect()
}

#[test]
fn design_lowpass_equals_firwin() {
    let r = load_reference("signal_firwin.json");
    let cases = r["cases"].as_array().unwrap();
    assert!(cases.len() >= 8);
    for c in cases {
        let numtaps = c["numtaps"].as_u64().unwrap() as usize;
        let cutoff = c["cutoff_hz"].as_f64().unwrap();
        let fs = c["fs_hz"].as_f64().unwrap();
        let mut taps = vec![0.0; numtaps];
        design_lowpass(&mut taps, cutoff, fs).unwrap();
        println!(
            "firwin({numtaps}, {cutoff}, fs={fs}): max |diff| {:.1e}",
            max_abs_diff(&taps, &floats(&c["taps"]))
        );
        // Taps are O(0.1); scipy evaluates the window as general_cosine (linspace of angles),
        // we as 0.54 - 0.46 cos: rounding differences ~1e-17.
        assert_allclose(
            &taps,
            &floats(&c["taps"]),
            1e-12,
            1e-15,
            &format!("firwin({numtaps}, {cutoff}, fs={fs})"),
        );
    }
}

#[test]
fn streaming_fir_equals_lfilter() {
    let r = load_reference("signal_lfilter.json");
    let b: [f64; 21] = floats(&r["b"]).try_into().unwrap();
    let x = floats(&r["x"]);
    let fir = Fir::<21>::from_taps_f64(&b).unwrap();
    assert_eq!(fir.group_delay_samples(), 10.0);
    // The node's f32 arithmetic against scipy's f64: signal values are O(5), 21 f32 products
    // with |taps| summing to ~1.1, so ~1e-6 absolute.
    for (primed, key) in [(false, "y_zero_state"), (true, "y_primed")] {
        let mut state = if primed {
            FirState::primed(x[0] as f32)
        } else {
            FirState::new()
        };
        let y: Vec<f64> = x
            .iter()
            .map(|&v| fir.process(&mut state, v as f32) as f64)
            .collect();
        println!(
            "{key}: max |diff| {:.1e}",
            max_abs_diff(&y, &floats(&r[key]))
        );
        assert_allclose(&y, &floats(&r[key]), 0.0, 3e-6, key);
    }
    // Reset then prime gives the same as a fresh primed state.
    let mut a = FirState::<21>::primed(1.0);
    fir.process(&mut a, 7.0);
    a.reset();
    assert_eq!(a, FirState::new());
    a.prime(2.5);
    assert_eq!(a, FirState::primed(2.5));
}

#[test]
fn filtfilt_equals_scipy() {
    let r = load_reference("signal_filtfilt.json");
    for (i, c) in r["cases"].as_array().unwrap().iter().enumerate() {
        let b = floats(&c["b"]);
        let x = floats(&c["x"]);
        let mut y = vec![0.0; x.len()];
        let mut scratch = vec![f64::NAN; filtfilt_scratch_len(b.len(), x.len())];
        filtfilt(&b, &x, &mut y, &mut scratch).unwrap();
        println!(
            "filtfilt case {i}: max |diff| {:.1e}",
            max_abs_diff(&y, &floats(&c["y"]))
        );
        assert_allclose(
            &y,
            &floats(&c["y"]),
            1e-12,
            1e-12,
            &format!("filtfilt case {i}"),
        );
    }
    // scipy: "The length of the input vector x must be greater than padlen" (63 for 21 taps).
    let b = [1.0 / 21.0; 21];
    let x = vec![1.0; 63];
    let mut y = vec![0.0; 63];
    let mut s = vec![0.0; filtfilt_scratch_len(21, 63)];
    assert_eq!(
        filtfilt(&b, &x, &mut y, &mut s),
        Err(FiltfiltError::SignalTooShort {
            len: 63,
            padlen: 63
        })
    );
    let x = vec![1.0; 64];
    let mut y = vec![0.0; 64];
    let mut s = vec![0.0; filtfilt_scratch_len(21, 64)];
    assert!(filtfilt(&b, &x, &mut y, &mut s).is_ok());
}

#[test]
fn interp_equals_numpy_interp_per_signal() {
    let r = load_reference("signal_interp.json");
    let t = floats(&r["t"]);
    let grid = floats(&r["grid"]);
    assert!(grid.len() > 200);
    for (sig, expected) in [("speed", "speed_on_grid"), ("steer", "steer_on_grid")] {
        let y = floats(&r[sig]);
        assert!(y.iter().any(|v| v.is_nan()), "{sig} must have gaps");
        let mut out = vec![0.0; grid.len()];
        interp_linear(&t, &y, &grid, &mut out).unwrap();
        println!(
            "interp {sig}: max |diff| {:.1e}",
            max_abs_diff(&out, &floats(&r[expected]))
        );
        assert_allclose(&out, &floats(&r[expected]), 1e-13, 1e-13, sig);
    }
    // Extrapolation is refused: the speed column starts with three NaN rows.
    let speed = floats(&r["speed"]);
    let mut out = [0.0; 1];
    assert_eq!(
        interp_linear(&t, &speed, &[t[1]], &mut out),
        Err(ResampleError::GridOutsideData { index: 0 })
    );
    let after = t.last().unwrap() + 0.01;
    assert_eq!(
        interp_linear(&t, &speed, &[t[5], after], &mut [0.0; 2]),
        Err(ResampleError::GridOutsideData { index: 1 })
    );
}

#[test]
fn eq1_grid_equals_reference() {
    let r = load_reference("signal_interp.json");
    let e = &r["eq1"];
    let n = e["n"].as_u64().unwrap() as usize;
    let mut g = vec![0.0; n];
    uniform_grid_eq1(
        e["t_s"].as_f64().unwrap(),
        e["t_e"].as_f64().unwrap(),
        &mut g,
    )
    .unwrap();
    assert_allclose(&g, &floats(&e["grid"]), 1e-15, 1e-13, "eq1");
}

#[test]
fn fixed_period_grid_is_uniform_and_ends_at_te() {
    let n = fixed_period_len(3.0, 63.0, 0.02).unwrap();
    assert_eq!(n, 3001);
    let mut g = vec![0.0; n];
    fixed_period_grid(3.0, 0.02, &mut g).unwrap();
    assert_eq!(g[0], 3.0);
    assert!((g[n - 1] - 63.0).abs() < 1e-12);
    for (k, v) in g.iter().enumerate() {
        assert!((v - (3.0 + 0.02 * k as f64)).abs() < 1e-12);
    }
}

#[test]
fn resample_errors() {
    let mut out = [0.0; 2];
    assert_eq!(
        interp_linear(&[], &[], &[0.0, 1.0], &mut out),
        Err(ResampleError::Empty)
    );
    assert_eq!(
        interp_linear(&[0.0, 1.0], &[1.0], &[0.0, 1.0], &mut out),
        Err(ResampleError::LengthMismatch)
    );
    assert_eq!(
        interp_linear(&[0.0, f64::NAN], &[1.0, 2.0], &[0.0, 1.0], &mut out),
        Err(ResampleError::NonFiniteTime { index: 1 })
    );
    assert_eq!(
        interp_linear(&[1.0, 0.5], &[1.0, 2.0], &[0.0, 1.0], &mut out),
        Err(ResampleError::TimeNotIncreasing { index: 1 })
    );
    assert_eq!(
        interp_linear(&[0.0, 1.0], &[1.0, 2.0], &[0.9, 0.1], &mut out),
        Err(ResampleError::GridNotIncreasing { index: 1 })
    );
    assert_eq!(
        interp_linear(&[0.0, 1.0], &[f64::NAN; 2], &[0.5, 0.6], &mut out),
        Err(ResampleError::NoValidSamples)
    );
    assert_eq!(
        uniform_grid_eq1(2.0, 2.0, &mut out),
        Err(ResampleError::TimeNotIncreasing { index: 1 })
    );
    assert_eq!(
        uniform_grid_eq1(0.0, f64::INFINITY, &mut out),
        Err(ResampleError::NonFiniteTime { index: 0 })
    );
    assert_eq!(
        fixed_period_len(0.0, 1e9, 1e-9),
        Err(ResampleError::GridTooLong)
    );
}

/// MATLAB `smooth(y, span)`, derived by hand from its documented definition:
/// out(1) = y(1); out(2) = (y(1)+y(2)+y(3))/3; out(3) = (y(1)+...+y(5))/5; ... shrinking
/// symmetric windows at the ends, span reduced to odd.
#[test]
fn smooth_matches_matlab_by_hand() {
    let y = [1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0];
    let mut out = [0.0; 7];
    smooth(&y, 5, &mut out).unwrap();
    let by_hand = [
        1.0,                                    // window y(1)
        (1.0 + 2.0 + 4.0) / 3.0,                // y(1:3)
        (1.0 + 2.0 + 4.0 + 8.0 + 16.0) / 5.0,   // y(1:5) = 31/5
        (2.0 + 4.0 + 8.0 + 16.0 + 32.0) / 5.0,  // 62/5
        (4.0 + 8.0 + 16.0 + 32.0 + 64.0) / 5.0, // 124/5
        (16.0 + 32.0 + 64.0) / 3.0,             // y(5:7) = 112/3
        64.0,                                   // y(7)
    ];
    assert_allclose(&out, &by_hand, 1e-15, 0.0, "smooth(y, 5)");

    // span 6 is even: MATLAB uses 5, so the result is identical.
    let mut out6 = [0.0; 7];
    smooth(&y, 6, &mut out6).unwrap();
    assert_eq!(out6, out);

    // The paper's span 10 acts as 9. On a line every symmetric mean equals the centre value,
    // so a line passes unchanged, shrinking windows included. On y = k^2, k = 0..=19, the
    // centred 9-window at k = 9 is (5..=13)^2: (25+36+49+64+81+100+121+144+169)/9 = 789/9
    // (an 11-window would give 946/11, a one-sided 10-window something else).
    let line: Vec<f64> = (0..20).map(|k| k as f64).collect();
    let mut o = vec![0.0; 20];
    smooth(&line, 10, &mut o).unwrap();
    assert_allclose(&o, &line, 1e-15, 1e-15, "smooth(line, 10)");
    let sq: Vec<f64> = (0..20).map(|k| (k * k) as f64).collect();
    smooth(&sq, 10, &mut o).unwrap();
    assert!((o[9] - 789.0 / 9.0).abs() < 1e-12, "{}", o[9]);
    // k = 3: window shrinks to 3 +- 3 = 0..=6: (0+1+4+9+16+25+36)/7 = 91/7 = 13.
    assert!((o[3] - 13.0).abs() < 1e-12, "{}", o[3]);
    // k = 18: window 17..=19: (289+324+361)/3 = 974/3.
    assert!((o[18] - 974.0 / 3.0).abs() < 1e-12, "{}", o[18]);

    // span larger than the signal is limited to its length (4 -> 3 after the odd reduction).
    let mut o4 = [0.0; 4];
    smooth(&[1.0, 2.0, 3.0, 10.0], 50, &mut o4).unwrap();
    assert_allclose(&o4, &[1.0, 2.0, 5.0, 10.0], 1e-15, 0.0, "span > n");
    // span 1 and 2 leave the data unchanged.
    smooth(&[1.0, 2.0, 3.0, 10.0], 2, &mut o4).unwrap();
    assert_eq!(o4, [1.0, 2.0, 3.0, 10.0]);

    assert_eq!(smooth(&[], 5, &mut []), Err(SmoothError::Empty));
    assert_eq!(smooth(&[1.0], 0, &mut [0.0]), Err(SmoothError::ZeroSpan));
    assert_eq!(
        smooth(&[1.0, f64::NAN], 3, &mut [0.0; 2]),
        Err(SmoothError::NonFinite { index: 1 })
    );
    assert_eq!(
        smooth(&[1.0, 2.0], 3, &mut [0.0; 3]),
        Err(SmoothError::OutputLengthMismatch)
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// Any valid design is exactly symmetric (linear phase) with unit DC gain.
    #[test]
    fn fir_design_symmetric_unit_dc(numtaps in 1usize..128, fs in 1.0f64..1000.0, frac in 0.001f64..0.999) {
        let cutoff = frac * fs / 2.0;
        let mut taps = vec![0.0; numtaps];
        design_lowpass(&mut taps, cutoff, fs).unwrap();
        for i in 0..numtaps {
            prop_assert_eq!(taps[i], taps[numtaps - 1 - i]);
        }
        let dc: f64 = taps.iter().sum();
        prop_assert!((dc - 1.0).abs() < 1e-12, "dc {}", dc);
    }

    /// The streaming FIR is linear: filter(a x1 + x2) = a filter(x1) + filter(x2), to f32
    /// rounding: each output is 21 products (sum |taps| ~ 1.1), so a few ulp of the signal
    /// scale (|a| 100 + 50); the bound allows 21 ulp per filter.
    #[test]
    fn streaming_fir_superposition(
        xs in prop::collection::vec((-100.0f32..100.0, -50.0f32..50.0), 1..80),
        a in -3.0f32..3.0,
    ) {
        let fir = Fir::<21>::lowpass(2.0, 50.0).unwrap();
        let tol = 3.0 * 21.0 * f32::EPSILON * 1.2 * (a.abs() * 100.0 + 50.0);
        let (mut s1, mut s2, mut s3) = (FirState::new(), FirState::new(), FirState::new());
        for &(u, v) in &xs {
            let y1 = fir.process(&mut s1, u);
            let y2 = fir.process(&mut s2, v);
            let y3 = fir.process(&mut s3, a * u + v);
            prop_assert!((y3 - (a * y1 + y2)).abs() <= tol, "{} vs {}", y3, a * y1 + y2);
        }
    }

    /// The moving average of a constant is the constant (to N ulp), primed or not.
    #[test]
    fn moving_average_of_constant(c in -1.0e6f32..1.0e6, n in 1usize..40, primed in any::<bool>()) {
        let ma = MovingAverage::<10>::new();
        let mut s = if primed { MovingAverageState::primed(c) } else { MovingAverageState::new() };
        for _ in 0..n {
            let y = ma.process(&mut s, c);
            prop_assert!((y - c).abs() <= 10.0 * f32::EPSILON * c.abs(), "{} vs {}", y, c);
        }
    }
}

/// A shorter filter inside a longer one (the node's GNSS lowpass sized at run time for the
/// receiver's rate) is bit for bit the filter of that size: FIR and moving average, over a
/// random signal, for every length the node can choose.
#[test]
fn run_time_lengths_equal_the_fixed_size_filters() {
    fn check<const M: usize>(signal: &[f32]) {
        let (fc, fs) = (0.9, 10.0);
        let short = Fir::<M>::lowpass(fc, fs).expect("design");
        let long = Fir::<21>::lowpass_len(M, fc, fs).expect("design");
        assert_eq!(long.len(), M);
        assert_eq!(long.group_delay_samples(), short.group_delay_samples());
        let ma_short = MovingAverage::<M>::new();
        let ma_long = MovingAverage::<21>::with_span(M).expect("span");
        assert_eq!(
            ma_long.group_delay_samples(),
            ma_short.group_delay_samples()
        );
        let (mut s1, mut s2) = (FirState::<M>::new(), FirState::<21>::new());
        let (mut m1, mut m2) = (
            MovingAverageState::<M>::new(),
            MovingAverageState::<21>::new(),
        );
        ma_short.prime(&mut m1, signal[0]);
        ma_long.prime(&mut m2, signal[0]);
        for &x in signal {
            let (a, b) = (short.process(&mut s1, x), long.process(&mut s2, x));
            assert_eq!(a.to_bits(), b.to_bits(), "FIR {M} taps");
            let (a, b) = (ma_short.process(&mut m1, x), ma_long.process(&mut m2, x));
            assert_eq!(a.to_bits(), b.to_bits(), "moving average over {M}");
        }
    }
    let signal: Vec<f32> = (0..500)
        .map(|k| (k as f32 * 0.37).sin() * 30.0 + (k as f32 * 2.9).cos() * 3.0 + 1000.0)
        .collect();
    check::<1>(&signal);
    check::<3>(&signal);
    check::<5>(&signal);
    check::<11>(&signal);
    check::<21>(&signal);
    // Out of range lengths are refused.
    assert!(Fir::<21>::lowpass_len(0, 0.9, 10.0).is_err());
    assert!(Fir::<21>::lowpass_len(22, 0.9, 10.0).is_err());
    assert!(MovingAverage::<10>::with_span(0).is_none());
    assert!(MovingAverage::<10>::with_span(11).is_none());
}
