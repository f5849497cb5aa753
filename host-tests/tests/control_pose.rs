//! The control pose (`catmodel::node::smoothing`): the estimate with a slow, noisy receiver's
//! fix jumps spread out by as much as the jumps measured on line call for, and a quiet
//! receiver's estimate passed as it is.
use catmodel::model::kinematic::Pose;
use catmodel::node::estimator::{EstimatorConfig, Xy};
use catmodel::node::smoothing::{
    Smoothing, DRIFT_DIFFUSION_M2_PER_S, DRIFT_FLOOR_M2_PER_S, SNAP_M, SPEED_SCALE_ERROR,
};
use catmodel::SAMPLE_PERIOD_S;

/// Antenna 1.2 m ahead of the rear axle, on the centre line.
const AHEAD_M: f32 = 1.2;

fn config(rate_hz: f64) -> EstimatorConfig {
    EstimatorConfig::design(rate_hz, AHEAD_M, 0.0).unwrap()
}

/// Deterministic standard normal draws (xorshift64*, Box-Muller).
struct Normal(u64);

impl Normal {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        ((self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    fn next(&mut self) -> f32 {
        let (a, b) = (self.uniform(), self.uniform());
        ((-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()) as f32
    }
}

/// The heading's variance the estimator reckons at speed with a 100 Hz receiver, rad^2 (about
/// 7e-4, 0.027 rad, on the closed-loop rig's loop; rounded up here).
const HEADING_VAR_RAD2: f32 = 1e-3;

/// A car driving east at 5 m/s; its estimate's antenna off the truth by `error(tick)`; the dead
/// reckoning exact. Returns, per tick, the truth's rear axle, the estimate and the control pose.
fn drive(
    smoothing: &mut Smoothing,
    cfg: &EstimatorConfig,
    ticks: usize,
    error: impl FnMut(usize) -> (f32, f32),
) -> Vec<(Pose, Pose, Pose)> {
    drive_at(smoothing, cfg, ticks, 5.0, HEADING_VAR_RAD2, error)
}

/// [`drive`] at `speed_mps` with the heading's variance `heading_var_rad2`.
fn drive_at(
    smoothing: &mut Smoothing,
    cfg: &EstimatorConfig,
    ticks: usize,
    speed_mps: f32,
    heading_var_rad2: f32,
    mut error: impl FnMut(usize) -> (f32, f32),
) -> Vec<(Pose, Pose, Pose)> {
    let heading = core::f32::consts::FRAC_PI_2;
    (0..ticks)
        .map(|k| {
            let x = speed_mps * SAMPLE_PERIOD_S * k as f32;
            let truth = Pose::new(x, 0.0, heading);
            let (ex, ey) = error(k);
            let estimate = Pose::new(x + ex, ey, heading);
            // The dead-reckoned antenna: the truth's, from an arbitrary origin.
            let odo = Xy {
                x_m: 100.0 + x + AHEAD_M,
                y_m: -50.0,
            };
            let control = smoothing.control_pose(cfg, estimate, odo, speed_mps, heading_var_rad2);
            (truth, estimate, control)
        })
        .collect()
}

/// The RMS of the tick-to-tick steps of the pose `pick` takes from each of `run`'s rows, less
/// the car's own motion of `east_m` a tick east, m.
fn step_rms(run: &[(Pose, Pose, Pose)], east_m: f32, pick: fn(&(Pose, Pose, Pose)) -> Pose) -> f32 {
    let sum: f32 = run
        .windows(2)
        .map(|w| {
            let (a, b) = (pick(&w[0]), pick(&w[1]));
            (b.x_m - a.x_m - east_m).powi(2) + (b.y_m - a.y_m).powi(2)
        })
        .sum();
    (sum / (run.len() - 1) as f32).sqrt()
}

/// The steady-state Kalman gain of a random walk with process noise `q` per step measured with
/// noise `r`, by iterating the Riccati recursion (independent of the closed form the node uses).
fn kalman_gain(q: f64, r: f64) -> f64 {
    let mut p = r;
    let mut k = 0.0;
    for _ in 0..100_000 {
        let prior = p + q;
        k = prior / (prior + r);
        p = (1.0 - k) * prior;
    }
    k
}

/// Fix errors of a receiver at `rate_hz` with `sigma_m` per axis, held between fixes.
fn fix_errors(rate_hz: f32, sigma_m: f32, seed: u64) -> impl FnMut(usize) -> (f32, f32) {
    let ticks_per_fix = ((1.0 / rate_hz) / SAMPLE_PERIOD_S).round().max(1.0) as usize;
    let mut normal = Normal(seed);
    let mut held = (0.0, 0.0);
    move |k| {
        if k % ticks_per_fix == 0 {
            held = (sigma_m * normal.next(), sigma_m * normal.next());
        }
        held
    }
}

#[test]
fn an_estimate_that_moves_with_the_dead_reckoning_is_followed_exactly() {
    // No jumps but f32 rounding: nothing to smooth, whatever the receiver's rate; the pose
    // passes to within rounding (the position's f32 ulp at 300 m is 3e-5 m).
    for rate in [1.0, 5.0, 10.0, 100.0] {
        let cfg = config(rate);
        let mut smoothing = Smoothing::for_estimator(&cfg);
        for (_, estimate, control) in drive(&mut smoothing, &cfg, 3_000, |_| (0.3, -0.2)) {
            let off = (control.x_m - estimate.x_m).hypot(control.y_m - estimate.y_m);
            assert!(off < 1e-4, "{rate} Hz: {off} m");
            assert_eq!(control.heading_rad, estimate.heading_rad);
        }
    }
}

#[test]
fn the_pull_per_tick_is_the_kalman_gain_per_window_spread_over_its_ticks() {
    // 5 Hz: the lowpass's window is three fixes (0.6 s, 30 ticks). Fix errors independent from
    // fix to fix, so a window's jump has the mean square of two fixes' errors, 2 r, plus the
    // drift allowed for over the window, q (the jumps the node measures carry no drift here:
    // the dead reckoning is exact). q is the heading's and the wheel speed's errors times the
    // window's distance, plus the floor, at most the diffusion's: at 1 m/s (0.6 m a window)
    // the distance's, at 20 m/s (12 m) the diffusion's. The node's pull per tick `g` must
    // satisfy (1 - g)^30 = 1 - K for the steady-state gain K of process noise q against
    // measurement noise (mean square jump - q) / 2.
    let cfg = config(5.0);
    let window_fixes = 2.0 * cfg.group_delay_fixes + 1.0;
    assert_eq!(window_fixes, 3.0);
    let scale2 = f64::from(SPEED_SCALE_ERROR).powi(2);
    let heading_var = f64::from(HEADING_VAR_RAD2);
    for (speed, q) in [
        (
            1.0f32,
            (heading_var + scale2) * 0.36 + f64::from(DRIFT_FLOOR_M2_PER_S) * 0.6,
        ),
        (20.0, f64::from(DRIFT_DIFFUSION_M2_PER_S) * 0.6),
    ] {
        for sigma in [0.2f32, 0.5, 1.0] {
            let mut smoothing = Smoothing::for_estimator(&cfg);
            drive_at(
                &mut smoothing,
                &cfg,
                20_000,
                speed,
                HEADING_VAR_RAD2,
                fix_errors(5.0, sigma, 7),
            );
            // The mean square jump the node saw over its last 5 s (8 windows) is noisy; take
            // the one it would see on average: per axis 2 sigma^2, two axes.
            let jump_ms = 4.0 * f64::from(sigma) * f64::from(sigma);
            let k = kalman_gain(q, (jump_ms - q) / 2.0);
            let g = f64::from(smoothing.gain());
            let k_node = 1.0 - (1.0 - g).powi(30);
            // The window's estimate of the mean square scatters by about sqrt(2 / 8) = 50 %; K
            // goes about as its square root.
            assert!(
                (k_node / k - 1.0).abs() < 0.3,
                "{speed} m/s, sigma {sigma}: K {k:.3}, the node's {k_node:.3}"
            );
        }
    }
}

/// The errors of a receiver at 100 Hz as the estimate carries them: white noise of
/// `white_m` and a first-order Gauss-Markov bias of `bias_m` (60 s) per axis, through a moving
/// average of the lowpass's 30 fixes; the estimate is read every tick (every other fix).
fn lowpassed_fast_receiver(
    white_m: f32,
    bias_m: f32,
    seed: u64,
) -> impl FnMut(usize) -> (f32, f32) {
    let mut normal = Normal(seed);
    let phi = (-0.01f32 / 60.0).exp();
    let drive = bias_m * (1.0 - phi * phi).sqrt();
    let mut bias = (bias_m * normal.next(), bias_m * normal.next());
    let mut window = std::collections::VecDeque::new();
    move |_| {
        for _ in 0..2 {
            bias.0 = phi * bias.0 + drive * normal.next();
            bias.1 = phi * bias.1 + drive * normal.next();
            window.push_back((
                bias.0 + white_m * normal.next(),
                bias.1 + white_m * normal.next(),
            ));
            if window.len() > 30 {
                window.pop_front();
            }
        }
        let n = window.len() as f32;
        let sum = window
            .iter()
            .fold((0.0, 0.0), |a, e| (a.0 + e.0, a.1 + e.1));
        (sum.0 / n, sum.1 / n)
    }
}

#[test]
fn a_fast_noisy_receivers_lowpassed_noise_is_measured_over_the_window() {
    // A standard receiver at 100 Hz (0.3 m white, 0.8 m bias per axis). The lowpass's output
    // moves by millimetres from one fix to the next (its noise is shared across its 30-fix
    // window), so the jumps per fix looked like a survey-grade receiver's and nothing was
    // smoothed: the controllers steered at the lowpass's output noise (the steering moved
    // 35-40 %/s on the loop at 3 and 8 m/s, docs/findings.md). Over the window the jumps are
    // the noise's own size: the node smooths, and the control pose moves less from tick to
    // tick than the estimate.
    let cfg = config(100.0);
    let mut smoothing = Smoothing::for_estimator(&cfg);
    let run = drive(
        &mut smoothing,
        &cfg,
        15_000,
        lowpassed_fast_receiver(0.3, 0.8, 21),
    );
    let g = smoothing.gain();
    assert!(g < 0.3, "100 Hz standard receiver: pull {g} per tick");
    // The car's own motion is 0.1 m east per tick.
    let (est, ctl) = (
        step_rms(&run[1_000..], 0.1, |s| s.1),
        step_rms(&run[1_000..], 0.1, |s| s.2),
    );
    assert!(
        ctl < 0.8 * est,
        "step RMS {ctl} m vs the estimate's {est} m"
    );
    // A survey-grade receiver at the same rate (1 cm, 1 cm): its jumps over the window are
    // below the drift allowed for, and the estimate passes exactly as it is.
    let mut smoothing = Smoothing::for_estimator(&cfg);
    for (_, estimate, control) in drive(
        &mut smoothing,
        &cfg,
        15_000,
        lowpassed_fast_receiver(0.01, 0.01, 22),
    ) {
        assert_eq!((control.x_m, control.y_m), (estimate.x_m, estimate.y_m));
    }
    assert_eq!(smoothing.gain(), 1.0);
}

#[test]
fn a_survey_grade_receiver_is_followed_at_a_stop_and_a_noisy_one_smoothed_most_at_a_crawl() {
    // Standing, the dead reckoning drifts by the floor alone (0.003 m^2 over a 100 Hz
    // receiver's 0.6 s window): a survey-grade receiver's jumps are below it and its estimate
    // passes exactly as it is.
    let cfg = config(100.0);
    let mut smoothing = Smoothing::for_estimator(&cfg);
    for (_, estimate, control) in drive_at(
        &mut smoothing,
        &cfg,
        5_000,
        0.0,
        HEADING_VAR_RAD2,
        lowpassed_fast_receiver(0.01, 0.01, 5),
    ) {
        assert_eq!((control.x_m, control.y_m), (estimate.x_m, estimate.y_m));
    }
    // A standard receiver (0.3 m white noise, 0.8 m bias) is pulled in less per tick the less
    // the car moves per window: its noise is the same, the dead reckoning's drift smaller.
    // (Its bias wanders as a drift would, so the drift measured over the long lag is larger
    // than the distance's at a crawl, and the distance's bound decides: 0.0035 m^2 a window
    // at 1 m/s, 0.011 at 4 m/s, and the pull goes about as the square root, 0.56 times.)
    let pull = |speed| {
        let mut smoothing = Smoothing::for_estimator(&cfg);
        drive_at(
            &mut smoothing,
            &cfg,
            5_000,
            speed,
            HEADING_VAR_RAD2,
            lowpassed_fast_receiver(0.3, 0.8, 6),
        );
        smoothing.gain()
    };
    let (crawl, town, road) = (pull(1.0), pull(4.0), pull(15.0));
    assert!(
        crawl < 0.7 * town && town < 0.7 * road,
        "pull per tick at 1 / 4 / 15 m/s: {crawl} / {town} / {road}"
    );
}

#[test]
fn a_fast_receivers_white_noise_is_smoothed_at_speed_once_the_drift_is_measured() {
    // 0.3 m of white noise alone at 100 Hz at 15 m/s: the distance's bound allows the most
    // drift there is (0.03 m^2 a window), more than the jumps (about 0.015 m^2), so without
    // the measured drift nothing was smoothed. The jumps over 4 windows are no larger than
    // over one (the dead reckoning is exact here): the drift measured is its standard error,
    // and the noise is smoothed. A dead reckoning that drifts steadily (0.2 m/s across the
    // track: a 0.013 rad heading error) shows in the long lag and is followed as before.
    let cfg = config(100.0);
    let run_with = |drift_mps: f32| {
        let mut smoothing = Smoothing::for_estimator(&cfg);
        let mut noise = lowpassed_fast_receiver(0.3, 0.0, 8);
        let run = drive_at(&mut smoothing, &cfg, 6_000, 15.0, HEADING_VAR_RAD2, |k| {
            let (x, y) = noise(k);
            (x, y + drift_mps * SAMPLE_PERIOD_S * k as f32)
        });
        (smoothing.gain(), run)
    };
    let (quiet, run) = run_with(0.0);
    let (drifting, drift_run) = run_with(0.2);
    println!("pull per tick: dead reckoning exact {quiet}, drifting {drifting}");
    assert!(quiet < 0.2, "white noise at 15 m/s: pull {quiet} per tick");
    assert!(
        drifting > 10.0 * quiet,
        "a drifting dead reckoning: pull {drifting} per tick"
    );
    // The smoothed pose moves less from tick to tick than the estimate...
    let (est, ctl) = (
        step_rms(&run[3_000..], 0.3, |s| s.1),
        step_rms(&run[3_000..], 0.3, |s| s.2),
    );
    assert!(
        ctl < 0.5 * est,
        "step RMS {ctl} m vs the estimate's {est} m"
    );
    // ... and the drifting one stays with the estimate: what smoothing is left there is the
    // distance's bound's (the jumps scatter about it), a lag of at most 0.16 m here.
    let lag = drift_run[3_000..]
        .iter()
        .map(|(_, e, c)| (c.x_m - e.x_m).hypot(c.y_m - e.y_m))
        .fold(0.0f32, f32::max);
    assert!(lag < 0.25, "a drifting dead reckoning: lag {lag} m");
}

#[test]
fn a_survey_grade_receiver_is_followed_and_a_noisy_slow_one_smoothed() {
    // RTK at 10 Hz (1 cm): the jumps are below the drift allowed for, the pull is close to 1.
    let cfg = config(10.0);
    let mut smoothing = Smoothing::for_estimator(&cfg);
    drive(&mut smoothing, &cfg, 3_000, fix_errors(10.0, 0.01, 3));
    assert!(smoothing.gain() > 0.5, "RTK: {}", smoothing.gain());
    // An uncorrected receiver at 5 Hz (0.5 m per axis at the estimate): each fix's jump is
    // spread over several fix periods; the control pose moves by far less per tick and is
    // nearer the truth than the estimate.
    let cfg = config(5.0);
    let mut smoothing = Smoothing::for_estimator(&cfg);
    let run = drive(&mut smoothing, &cfg, 10_000, fix_errors(5.0, 0.5, 11));
    let g = smoothing.gain();
    assert!(g < 0.05, "5 Hz, 0.5 m: {g}");
    let settled = &run[2_000..];
    let rms = |f: &dyn Fn(&(Pose, Pose, Pose)) -> f32| {
        (settled.iter().map(|s| f(s).powi(2)).sum::<f32>() / settled.len() as f32).sqrt()
    };
    let est_err = rms(&|(t, e, _)| (e.x_m - t.x_m).hypot(e.y_m - t.y_m));
    let ctl_err = rms(&|(t, _, c)| (c.x_m - t.x_m).hypot(c.y_m - t.y_m));
    assert!(ctl_err < 0.6 * est_err, "error {ctl_err} vs {est_err}");
    let steps = |pick: fn(&(Pose, Pose, Pose)) -> Pose| {
        settled
            .windows(2)
            .map(|w| {
                let (a, b) = (pick(&w[0]), pick(&w[1]));
                // The car's own motion is 0.1 m east per tick.
                (b.x_m - a.x_m - 0.1).abs().max((b.y_m - a.y_m).abs())
            })
            .fold(0.0f32, f32::max)
    };
    let est_step = steps(|s| s.1);
    let ctl_step = steps(|s| s.2);
    assert!(
        ctl_step < 0.2 * est_step,
        "largest step {ctl_step} vs {est_step}"
    );
}

#[test]
fn a_lasting_offset_is_followed_within_the_gains_time() {
    // A noisy 5 Hz receiver; then the estimate moves 1 m north and stays (the dead reckoning
    // had drifted): the control pose follows at the pull per tick, no slower.
    let cfg = config(5.0);
    let mut smoothing = Smoothing::for_estimator(&cfg);
    let mut noise = fix_errors(5.0, 0.3, 5);
    let run = drive(&mut smoothing, &cfg, 4_000, |k| {
        let (x, y) = noise(k);
        if k < 3_000 {
            (x, y)
        } else {
            (0.0, 1.0)
        }
    });
    // After n ticks of the offset (the statistics saw one jump of 1 m more, the pull grew),
    // at most (1 - g_before)^n of it is left.
    let before = {
        let mut s = Smoothing::for_estimator(&cfg);
        let mut noise = fix_errors(5.0, 0.3, 5);
        drive(&mut s, &cfg, 3_000, &mut noise);
        s.gain()
    };
    assert!(before < 0.1, "0.3 m at 5 Hz: pull {before} per tick");
    for n in [50usize, 200, 500] {
        let (_, e, c) = run[3_000 + n];
        let left = (e.y_m - c.y_m).abs();
        let bound = (1.0 - before).powi(n as i32) + 0.3;
        assert!(
            left <= bound,
            "after {n} ticks {left} m of 1 m left (bound {bound})"
        );
    }
    let (_, e, c) = run[3_999];
    assert!((e.y_m - c.y_m).abs() < 0.05);
}

#[test]
fn a_jump_beyond_the_snap_distance_is_taken_at_once_and_not_counted() {
    let cfg = config(5.0);
    let mut smoothing = Smoothing::for_estimator(&cfg);
    let mut noise = fix_errors(5.0, 0.3, 9);
    let run = drive(&mut smoothing, &cfg, 2_500, |k| {
        let (x, y) = noise(k);
        if k < 2_000 {
            (x, y)
        } else {
            (x, y + 2.0 * SNAP_M)
        }
    });
    let (_, e, c) = run[2_000];
    assert_eq!(c, e, "the restarted estimate is taken as it is");
    // The 6 m jump stayed out of the statistics: the receiver still counts as noisy.
    assert!(smoothing.gain() < 0.1, "{}", smoothing.gain());
}

#[test]
fn forgetting_takes_the_next_estimate_as_it_is_and_keeps_the_receivers_statistics() {
    let cfg = config(5.0);
    let mut smoothing = Smoothing::for_estimator(&cfg);
    let run = drive(&mut smoothing, &cfg, 2_000, fix_errors(5.0, 0.5, 13));
    assert!(run[1_000..].iter().any(|(_, e, c)| c != e));
    let gain = smoothing.gain();
    assert!(gain < 0.1);
    smoothing.forget();
    assert_eq!(smoothing.gain(), gain);
    let run = drive(&mut smoothing, &cfg, 2, |_| (0.7, -0.4));
    assert_eq!(
        run[0].2, run[0].1,
        "the first pose after forget is the estimate"
    );
}

#[test]
fn the_heading_settles_after_three_time_constants_of_its_correction() {
    use catmodel::node::smoothing::{HeadingSettle, HEADING_SETTLE_TIME_CONSTANTS};
    for rate in [1.0, 5.0, 100.0] {
        let cfg = config(rate);
        let needed = (HEADING_SETTLE_TIME_CONSTANTS / cfg.course_gain).ceil() as u32;
        let mut settle = HeadingSettle::new();
        // A pose whose heading the estimator did not correct (standing, or a chord too short
        // to correct it), or a correction without a pose: nothing counts.
        for _ in 0..10 * needed {
            assert!(!settle.update(&cfg, true, false));
            assert!(!settle.update(&cfg, false, true));
        }
        for k in 1..needed {
            assert!(!settle.update(&cfg, true, true), "{rate} Hz after {k}");
            // Ticks without a correction between the corrections do not count either.
            assert!(!settle.update(&cfg, true, false), "{rate} Hz after {k}");
        }
        assert!(settle.update(&cfg, true, true), "{rate} Hz after {needed}");
        // Once settled it stays so: nothing corrected, the pose lost.
        assert!(settle.update(&cfg, false, false));
    }
}
