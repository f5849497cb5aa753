//! Step 1 of the paper's pipeline (II-C): every signal of a log onto the uniform 20 ms grid
//! (eq 1 with a fixed period), the 20th-order FIR lowpass and the moving-average smoothing
//! applied zero-phase (offline), GNSS to local metres, steering percent to the centre-tyre
//! angle (eq 2-4), and the derived signals the models need (dx/dt, heading, yaw rate).
//!
//! Filtering is the same linear, zero-phase operation on every signal, so an input/output pair
//! of an LTI system stays an input/output pair of the same system after it (up to the edges).
use std::path::Path;

use super::stats::{median, median_interval, noise_from_second_differences};

use anyhow::{anyhow, bail, Context, Result};
use catmodel::geodesy::{geodetic_to_enu, Geodetic};
use catmodel::signal::{filtfilt, fir, resample, smooth};

use crate::logcsv::{self, LogRow};
use crate::model_file::VehicleSection;
use catmodel::node::estimator::PAPER_GNSS_RATE_HZ;

/// How logs are preprocessed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PreprocessOptions {
    /// Grid period, s (the car's 20 ms).
    pub ts_s: f64,
    /// FIR taps (20th order = 21 taps, paper II-C); 0 = no FIR.
    pub fir_taps: usize,
    /// FIR cutoff, Hz.
    pub cutoff_hz: f64,
    /// MATLAB `smooth` span (paper: 10, which MATLAB applies as 9); 0 or 1 = none.
    pub smooth_span: usize,
    /// Half-width of the central difference for dx/dt and yaw rate with the paper's 100 Hz
    /// receiver, samples (12 = +-0.24 s): differentiating GNSS positions needs a baseline wider
    /// than one sample. Slower receivers get a wider one ([`diff_half_width`]).
    pub diff_half_width: usize,
    /// Shortest accepted log after resampling, s.
    pub min_duration_s: f64,
}

impl Default for PreprocessOptions {
    fn default() -> Self {
        Self {
            ts_s: catmodel::SAMPLE_PERIOD_S_F64,
            fir_taps: 21,
            cutoff_hz: 2.0,
            smooth_span: 10,
            diff_half_width: 12,
            min_duration_s: 10.0,
        }
    }
}

/// One experiment on the uniform grid, filtered. Every vector has the length of `t`.
#[derive(Debug, Clone, PartialEq)]
pub struct Experiment {
    /// Name (the file stem).
    pub name: String,
    /// Time, s, uniform with period `ts_s`.
    pub t: Vec<f64>,
    /// Grid period, s.
    pub ts_s: f64,
    /// Measured speed, m/s.
    pub vel: Vec<f64>,
    /// Commanded speed, m/s.
    pub input_vel: Vec<f64>,
    /// Steering, %, positive = right.
    pub steer_pct: Vec<f64>,
    /// Centre-tyre angle, rad (`max_steer_deg / 100 * steer_pct`): the paper's `phi`.
    pub delta_rad: Vec<f64>,
    /// Accelerator pedal, % (zeros when the log has none).
    pub accel_pct: Vec<f64>,
    /// Brake pedal, % (zeros when the log has none).
    pub brake_pct: Vec<f64>,
    /// East of the first fix, m.
    pub x: Vec<f64>,
    /// North of the first fix, m.
    pub y: Vec<f64>,
    /// dx/dt (east velocity), m/s, central difference of the filtered `x`.
    pub dx: Vec<f64>,
    /// dy/dt (north velocity), m/s.
    pub dy: Vec<f64>,
    /// Course over ground, clockwise from north, rad, unwrapped (held where the wheel speed is below 1 m/s).
    pub heading: Vec<f64>,
    /// Yaw rate from the course, rad/s, positive clockwise (0 where the wheel speed is below 1 m/s);
    /// central difference over +-4 `diff_half_width` (the course is noisier than positions).
    pub yaw_rate: Vec<f64>,
    /// Origin of `x`, `y`: the first GNSS fix (lat, lon), degrees.
    pub origin_deg: (f64, f64),
    /// Half-width of the central difference that made `yaw_rate` from the course, samples.
    pub yaw_half_width: usize,
    /// What reading the log noticed without refusing it ([`logcsv::LogNotes::messages`]).
    pub log_notes: Vec<String>,
    /// Warnings on the file as read ([`logcsv::LogNotes::warnings`]: a last line cut short),
    /// for stderr.
    pub log_warnings: Vec<String>,
    /// The receiver's fix rate in this log: the reciprocal of the median interval between
    /// fixes, Hz.
    pub gnss_rate_hz: f64,
    /// The wheel speed against the GNSS track ([`super::units`]): about 1 when `vel` is in
    /// m/s; `None` when the log has too few moving stretches to judge by.
    pub speed_scale: Option<super::units::SpeedScale>,
    /// The longest span over which the wheel speed and the GNSS track disagree (a wheel speed
    /// that sticks, [`super::units::disagreement`]), or else over which it holds one value
    /// while the track's speed changes ([`super::units::held_speed`]); `None`: none.
    pub speed_disagreement: Option<super::units::Disagreement>,
    /// Samples whose GNSS-derived signals (`dx`, `dy`, `heading`, `yaw_rate`) rest on the
    /// interpolation across an outage ([`gnss_gaps`]): left out of the fits and scores that
    /// use them. Empty: none.
    pub gnss_gap: Vec<bool>,
    /// The first sample at or after the first fix: 0 unless the receiver started more than
    /// [`GNSS_LEAD_S`] after the bus sensors (the grid then spans theirs, the fixes held before
    /// it). The track's models are simulated from it ([`super::validate::simulate_all`]).
    pub track_from: usize,
    /// Samples where the commanded speed did not drive the car ([`command_not_followed`]: a
    /// driver's takeover, the speed control disengaged), with the time the speed loop takes
    /// to answer after them: left out of the speed model's fit. Empty: none.
    pub speed_skip: Vec<bool>,
    /// The intervals between the log's `steer` samples and between its `vel` or `input_vel`
    /// samples (the further apart), as the steering and speed reports on the bus would come
    /// ([`crate::replay::ReportIntervals::of_log_columns`], against the default timeouts;
    /// `identify` pools them against its base file's: [`super::sensor_rates`]).
    pub report_intervals: [crate::replay::ReportIntervals; 2],
    /// Why `input_vel` is not in m/s by the speed it settles to, before any fit
    /// ([`super::units::settled_command_problem`]: km/h, mph); `catmodel identify` refuses it
    /// with the wheel speed's unit, and [`command_not_followed`] is not run on such a log.
    pub command_unit: Option<String>,
}

impl Experiment {
    /// A yaw rate as `yaw_rate` measures it: `yaw_rate` is the central difference of the
    /// course over +-`yaw_half_width` samples, i.e. the true yaw rate averaged over that
    /// window, and 0 where the car stood during the window ([`zero_unless_moving`]). A model's yaw rate goes
    /// through the same linear operation before it is fitted to or compared with `yaw_rate`
    /// (as every signal goes through the same lowpass): otherwise the model's dynamics would
    /// absorb the measurement's window (a 1 s lag that is not the car's).
    pub fn as_measured_yaw(&self, r: &[f64]) -> Vec<f64> {
        let mut integral = Vec::with_capacity(r.len());
        let mut sum = 0.0;
        for v in r {
            integral.push(sum);
            sum += v * self.ts_s;
        }
        let mut out = derivative(&integral, self.ts_s, self.yaw_half_width);
        zero_unless_moving(&mut out, &self.vel, self.yaw_half_width);
        out
    }

    /// Whether sample `k`'s GNSS-derived signals rest on the interpolation across an outage.
    pub fn in_gnss_gap(&self, k: usize) -> bool {
        self.gnss_gap.get(k).copied().unwrap_or(false)
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t.len()
    }

    /// True if there are no samples.
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }
}

/// Samples of one column: (t, value) where the cell was present.
fn column(rows: &[LogRow], f: impl Fn(&LogRow) -> Option<f64>) -> (Vec<f64>, Vec<f64>) {
    rows.iter().filter_map(|r| f(r).map(|v| (r.t, v))).unzip()
}

/// How far a sample may stand apart from its neighbours on both sides before it is impossible:
/// `tolerance` (the sensor's noise and resolution) plus `max_rate` times the time to the
/// farthest neighbour compared (what the quantity can change in that time).
#[derive(Clone, Copy, Debug)]
struct Plausible {
    /// What follows a value in the note: its physical unit.
    unit: &'static str,
    tolerance: f64,
    max_rate: f64,
}

/// Neighbours compared on each side.
const OUTLIER_NEIGHBOURS: usize = 3;

/// Wheel and commanded speed: 1 m/s of noise, 15 m/s^2 (1.5 g, beyond any car's braking).
const SPEED_PLAUSIBLE: Plausible = Plausible {
    unit: "m/s",
    tolerance: 1.0,
    max_rate: 15.0,
};
/// Steering: 5 % of noise, 1000 %/s (steering actuators turn at 50-400 %/s).
const STEER_PLAUSIBLE: Plausible = Plausible {
    unit: "%",
    tolerance: 5.0,
    max_rate: 1000.0,
};
/// GNSS fixes, metres from the first: the node's 10 m plausibility gate (docs/faults.md)
/// plus 80 m/s (the log schema's top speed).
const FIX_PLAUSIBLE: Plausible = Plausible {
    unit: "of where the log starts",
    tolerance: 10.0,
    max_rate: 80.0,
};

/// Indices of the samples of `t`, `values` (one or more coordinates per sample) that stand
/// apart from the median of their [`OUTLIER_NEIGHBOURS`] neighbours before *and* after by more
/// than `p` allows (a step stays with one side; a spike leaves both). The first and the last
/// sample, with neighbours on one side only, are judged against those ([`OUTLIER_NEIGHBOURS`]
/// of them, the next ones for the first and the previous ones for the last) by the same rule:
/// one corrupt value at a log's end used to pass and ruin the fits (a first `vel` of 70 m/s
/// took a speed fit from 58.5 % to -0.8 %; a first fix far away moved the local origin).
fn impossible_samples<const N: usize>(t: &[f64], values: &[[f64; N]], p: Plausible) -> Vec<usize> {
    let k = OUTLIER_NEIGHBOURS;
    let n = t.len();
    let mut out = Vec::new();
    // With fewer samples than a full side and the sample itself, an end has nothing to be
    // judged against.
    if n <= k {
        return out;
    }
    for i in 0..n {
        let apart = |range: std::ops::Range<usize>| -> bool {
            let mut dist2 = 0.0;
            for c in 0..N {
                let mut side: Vec<f64> = values[range.clone()].iter().map(|v| v[c]).collect();
                let d = values[i][c] - median(&mut side);
                dist2 += d * d;
            }
            let span = range
                .clone()
                .map(|j| (t[j] - t[i]).abs())
                .fold(0.0, f64::max);
            dist2.sqrt() > p.tolerance + p.max_rate * span
        };
        let before = i.saturating_sub(k)..i;
        let after = i + 1..(i + 1 + k).min(n);
        let impossible = match (i, n - 1 - i) {
            (0, _) => apart(after),
            (_, 0) => apart(before),
            _ => apart(before) && apart(after),
        };
        if impossible {
            out.push(i);
        }
    }
    out
}

/// The neighbours a note on the impossible sample `i` of `len` shows: the one on each side, or
/// at an end the two it was judged against.
fn neighbours_shown(i: usize, len: usize) -> (&'static str, usize, usize) {
    if i == 0 {
        ("the samples after it", 1, 2)
    } else if i + 1 == len {
        ("the samples before it", i - 2, i - 1)
    } else {
        ("its neighbours", i - 1, i + 1)
    }
}

/// Leaves out the impossible samples of a column ([`impossible_samples`]), naming each in
/// `notes` (time, value, neighbours), and returns their indices (ascending): one corrupt
/// sample in range used to move the identified model without a word (a speed of 70 m/s in a
/// drive at 5 m/s halved the speed delay).
fn drop_impossible<const N: usize>(
    log: &str,
    name: &str,
    t: &mut Vec<f64>,
    values: &mut Vec<[f64; N]>,
    p: Plausible,
    show: impl Fn(&[f64; N]) -> String,
    notes: &mut Vec<String>,
) -> Vec<usize> {
    let bad = impossible_samples(t, values, p);
    for &i in bad.iter().take(3) {
        let (which, a, b) = neighbours_shown(i, t.len());
        notes.push(format!(
            "{log}: column `{name}`: the sample at t = {} s ({} {}) is impossible beside \
             {which} ({} and {} {}): left out",
            t[i],
            show(&values[i]),
            p.unit,
            show(&values[a]),
            show(&values[b]),
            p.unit
        ));
    }
    if bad.len() > 3 {
        notes.push(format!(
            "{log}: column `{name}`: {} impossible samples left out in all",
            bad.len()
        ));
    }
    for &i in bad.iter().rev() {
        t.remove(i);
        values.remove(i);
    }
    bad
}

/// Time on each side of a GNSS step whose fixes' median position must also have stepped for the
/// step to be a discontinuity, s: a burst of bad fixes shorter than half of it cannot move the
/// median (a lone outlier is left out before, [`drop_impossible`]; a burst of three is not),
/// while two drives joined stay apart. A slow receiver's side takes [`STEP_MIN_FIXES`] at least.
const STEP_WINDOW_S: f64 = 1.0;

/// Fixes needed on each side of a step to tell a discontinuity from a bad fix at a log's end.
const STEP_MIN_FIXES: usize = OUTLIER_NEIGHBOURS;

/// The most a receiver's own error may move its fixes for good, m: ten times the node's 10 m
/// gate ([`FIX_PLAUSIBLE`]). A single-point receiver's reacquisition or an urban canyon's
/// multipath moves fixes by metres to a few tens of metres; a step within this is left to the
/// outlier check and the fit (the simulator's `turn-left` and `circle-right` joined with time
/// continuous step by 21 m, which trains as well as either drive alone, and is kept), while two
/// drives at different places (2 km apart in the review) are far beyond it. With the log
/// schema's top speed (80 m/s) over the time of the fixes compared, no car makes a step beyond.
const STEP_TOLERANCE_M: f64 = 100.0;

/// A GNSS step no car can make, that stays (review finding 02: two drives joined in one CSV,
/// the fix 2 km away 20 ms later, were trained across, dx/dt MSE 519 (m/s)^2 instead of 0.05,
/// with exit 0; a validation drive was then blamed for leaving the training range). The grid
/// would interpolate across it as across a pause, so it is refused as the pause rule refuses a
/// pause ([`check_pauses`]), with the advice to split the log there. `load_experiment` names
/// the line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GnssStep {
    /// The last fix before the step, s.
    pub t_before: f64,
    /// The first fix after it, s.
    pub t_after: f64,
    /// How far apart the two fixes are, m.
    pub distance_m: f64,
    /// How far apart the medians of the fixes on either side are, m, and the most a car can
    /// move in their time plus the receiver's error, m.
    pub medians_m: (f64, f64),
}

impl std::fmt::Display for GnssStep {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "the GNSS fix jumps {:.0} m in {} s (t = {} to {}), and stays there: the median \
             of the fixes in the {STEP_WINDOW_S} s after it lies {:.0} m from that of the \
             {STEP_WINDOW_S} s before, more than the {:.0} m a car can move in that time ({} m for the receiver's error \
             + {} m/s, the log schema's top speed): a discontinuity (two logs joined, or a \
             receiver reset), which identify and compare would interpolate across: split the log at this line",
            self.distance_m,
            round_us(self.t_after - self.t_before),
            self.t_before,
            self.t_after,
            self.medians_m.0,
            self.medians_m.1,
            STEP_TOLERANCE_M,
            FIX_PLAUSIBLE.max_rate
        )
    }
}

impl std::error::Error for GnssStep {}

/// A time difference rounded to the microsecond, for messages (0.02, not 0.019999999999527063).
fn round_us(dt: f64) -> f64 {
    (dt * 1e6).round() / 1e6
}

/// The first step between consecutive fixes (`t`, east and north metres) beyond
/// [`STEP_TOLERANCE_M`] plus the log schema's top speed over its time whose side medians
/// ([`STEP_WINDOW_S`]) are also further apart than that over their span: a jump that
/// stays, not a burst of bad fixes.
fn gnss_discontinuity(t: &[f64], m: &[[f64; 2]]) -> Option<GnssStep> {
    let dist = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).hypot(a[1] - b[1]);
    let allowed = |dt: f64| STEP_TOLERANCE_M + FIX_PLAUSIBLE.max_rate * dt;
    let centre = |r: std::ops::Range<usize>| -> [f64; 2] {
        let mut e: Vec<f64> = m[r.clone()].iter().map(|p| p[0]).collect();
        let mut n: Vec<f64> = m[r].iter().map(|p| p[1]).collect();
        [median(&mut e), median(&mut n)]
    };
    for i in 0..t.len().saturating_sub(1) {
        let step = dist(m[i], m[i + 1]);
        if step <= allowed(t[i + 1] - t[i]) {
            continue;
        }
        // The fixes within STEP_WINDOW_S of the step on each side, STEP_MIN_FIXES at least.
        let first = t[..=i]
            .partition_point(|&x| x < t[i] - STEP_WINDOW_S)
            .min((i + 1).saturating_sub(STEP_MIN_FIXES));
        let end = (i + 1 + t[i + 1..].partition_point(|&x| x <= t[i + 1] + STEP_WINDOW_S))
            .max(i + 1 + STEP_MIN_FIXES)
            .min(t.len());
        let (before, after) = (first..i + 1, i + 1..end);
        if before.len() < STEP_MIN_FIXES || after.len() < STEP_MIN_FIXES {
            continue;
        }
        let span = t[after.end - 1] - t[before.start];
        let apart = dist(centre(before), centre(after));
        if apart > allowed(span) {
            return Some(GnssStep {
                t_before: t[i],
                t_after: t[i + 1],
                distance_m: step,
                medians_m: (apart, allowed(span)),
            });
        }
    }
    None
}

/// Linear interpolation of a column onto the grid.
fn onto_grid(name: &str, t: &[f64], v: &[f64], grid: &[f64]) -> Result<Vec<f64>> {
    let mut out = vec![0.0; grid.len()];
    resample::interp_linear(t, v, grid, &mut out)
        .map_err(|e| anyhow!("column `{name}`: resampling failed: {e:?}"))?;
    Ok(out)
}

/// The longest a needed sensor may stay silent, s, unless its own period is longer than a
/// tenth of it (then ten periods): the grid interpolates between a sensor's samples, which is
/// right within its period and wrong across a pause (a one-hour pause in a one-minute log
/// added 180 000 straight-line samples and improved the fit's MSE 65 times).
pub const MAX_PAUSE_S: f64 = 5.0;

/// Below this wheel speed a sample counts as standing for [`STANDING_NOTE_SHARE`], m/s.
const STANDING_MPS: f64 = 0.1;
/// A log that stands more than this share of its time says so in a note.
pub const STANDING_NOTE_SHARE: f64 = 0.3;

/// A step of the track off what the wheel speed continues, larger than this plus
/// [`BURST_STEP_SHARE`] of the distance driven across it, m, is one end of a burst.
const BURST_STEP_M: f64 = 2.0;
/// See [`BURST_STEP_M`].
const BURST_STEP_SHARE: f64 = 0.2;
/// ... plus this many times the scatter of the windows' medians that the receiver's noise
/// makes.
const BURST_SIGMAS: f64 = 6.0;
/// Receivers whose three fixes span more than this, s, are not searched (below 3 Hz).
const BURST_WINDOW_MAX_S: f64 = 1.0;
/// A burst returns within this, s: less than the longest pause in the fixes that is
/// interpolated ([`MAX_PAUSE_S`]), so that leaving a burst out never makes one.
const BURST_MAX_S: f64 = 4.0;
/// The step back is at least this share of the step off and at most its inverse. (Its
/// direction is not compared: measured along the track's direction over the window before
/// it, which lies inside the burst, it is off by the burst's own drift.)
const BURST_RETURN_SHARE: f64 = 0.5;

/// A fix's windows for [`gnss_bursts`]: its index, the median positions over the window
/// before the one before it, the one before it and the one after it, and the wheel's
/// distance between the last two with the ratio of their time to the first two's.
type StepWindows = (usize, [f64; 2], [f64; 2], [f64; 2], [f64; 2]);

/// Bursts of fixes that step off the track and back (multipath near buildings, a receiver
/// that loses and regains a correction): index ranges of `t` (fixes `a..b`) and how far the
/// first steps off, m. A step is found at fix `i` by comparing the median position of the
/// fixes over the window before it with that over the window after it (a window half a
/// second and three fixes at least: a lone outlier does not move a median) against the
/// distance the wheel speed drives between the windows' middle times, along the track's
/// direction over the window before that (or against the distance alone when the car barely
/// moved there): a vector off by more than [`BURST_STEP_M`] plus [`BURST_STEP_SHARE`] of that
/// distance, and [`BURST_SIGMAS`] times the scatter the receiver's noise gives the medians;
/// and the track's own continuation (its velocity over the window before) must miss it by as
/// much, so that a wheel speed wrong for a moment is no step of the track
/// (a 5 Hz receiver's 0.5 m: about 3 m; a 100 Hz one's 0.3 m: 0.3 m). A step off and the last step of a like size ([`BURST_RETURN_SHARE`]) within
/// [`BURST_MAX_S`] bound a burst (a burst whose offset swells inside it steps there too). The
/// wheel's distance is taken in the track's metres (the median ratio of the two), so that a
/// `vel` in km/h is the unit check's to name. A step with no return is left alone (a jump no car makes is
/// [`gnss_discontinuity`]'s). Black-box probe: one or two bursts of 3-8 m lasting 2 s took the
/// yaw-rate fit from 80.5 % to 68.1 %, five got the lateral model refused; neither the lone
/// outlier's test nor the step's (100 m) saw them.
fn gnss_bursts(t: &[f64], xy: &[[f64; 2]], tv: &[f64], vel: &[f64]) -> Vec<(usize, usize, f64)> {
    let n = t.len();
    let period = median_interval(t);
    if n < 12 || period.is_nan() || period <= 0.0 || tv.len() < 2 {
        return Vec::new();
    }
    let w = ((0.5 / period).round() as usize).max(3);
    if w as f64 * period > BURST_WINDOW_MAX_S {
        // A slow receiver's three fixes span seconds, over which a turn bends the track more
        // than a burst moves it: too slow to tell (a 2 s burst is two fixes at 1 Hz).
        return Vec::new();
    }
    if n < 3 * w {
        // Fewer fixes than the three windows a step is measured over (a receiver that got its
        // fix late in the log, or lost it at once): nothing to compare.
        return Vec::new();
    }
    // The receiver's white noise per axis, from the second differences of the fixes (the
    // car's own acceleration adds a t^2 that is small at any rate a receiver has); the
    // difference of two windows' medians scatters by about 1.25 sigma sqrt(2 / w) per axis.
    let noise = {
        let mut d2: Vec<f64> = xy
            .windows(3)
            .flat_map(|p| [0, 1].map(|a| (p[2][a] - 2.0 * p[1][a] + p[0][a]).abs()))
            .collect();
        noise_from_second_differences(&mut d2)
    };
    let scatter = 1.25 * noise * (2.0 / w as f64).sqrt();
    let centre = |r: std::ops::Range<usize>| -> ([f64; 2], f64) {
        let mut x: Vec<f64> = xy[r.clone()].iter().map(|p| p[0]).collect();
        let mut y: Vec<f64> = xy[r.clone()].iter().map(|p| p[1]).collect();
        let mut tt: Vec<f64> = t[r].to_vec();
        ([median(&mut x), median(&mut y)], median(&mut tt))
    };
    let speed_at = |time: f64| {
        let k = tv.partition_point(|x| *x < time).clamp(1, tv.len() - 1);
        let (t0, t1) = (tv[k - 1], tv[k]);
        let f = if t1 > t0 {
            ((time - t0) / (t1 - t0)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (vel[k - 1] + f * (vel[k] - vel[k - 1])).abs()
    };
    // The step's vector off the continued track at each fix, and its excess over the
    // threshold.
    // Each fix's windows: the medians before and after it and over the window before that,
    // and the wheel's distance between the first two (an outage between them, the gap's
    // interpolation, is another rule's).
    let windows: Vec<StepWindows> = (2 * w..=n - w)
        .filter_map(|i| {
            let (before, tb) = centre(i - w..i);
            let (after, ta) = centre(i..i + w);
            let (earlier, te) = centre(i - 2 * w..i - w);
            let ratio = if tb > te { (ta - tb) / (tb - te) } else { 1.0 };
            (ta - tb <= 4.0 * w as f64 * period).then(|| {
                (
                    i,
                    earlier,
                    before,
                    after,
                    [speed_at(0.5 * (ta + tb)) * (ta - tb), ratio],
                )
            })
        })
        .collect();
    // The wheel's distance in the track's metres: the median ratio of the two where the car
    // moves (1 in m/s; a `vel` in another unit, or a wheel speed the track contradicts, is the
    // unit check's to name, not a burst everywhere).
    let scale = {
        let mut ratios: Vec<f64> = windows
            .iter()
            .filter(|w| w.4[0] > 0.5)
            .map(|w| (w.3[0] - w.2[0]).hypot(w.3[1] - w.2[1]) / w.4[0])
            .collect();
        if ratios.is_empty() {
            1.0
        } else {
            median(&mut ratios)
        }
    };
    let mut steps: Vec<(usize, [f64; 2], f64)> = Vec::new();
    let (mut last_exceeding, mut run_start) = (0, 0);
    for &(i, earlier, before, after, [wheel, ratio]) in &windows {
        let d = scale * wheel;
        let chord = [before[0] - earlier[0], before[1] - earlier[1]];
        let len = chord[0].hypot(chord[1]);
        let moved = [after[0] - before[0], after[1] - before[1]];
        let off = if len > 0.5 {
            [moved[0] - d * chord[0] / len, moved[1] - d * chord[1] / len]
        } else {
            let m = moved[0].hypot(moved[1]);
            let k = if m > 0.0 { (m - d) / m } else { 0.0 };
            [moved[0] * k, moved[1] * k]
        };
        let threshold =
            |distance: f64| BURST_STEP_M + BURST_STEP_SHARE * distance + BURST_SIGMAS * scatter;
        // The track's own continuation (its velocity over the window before) must miss the
        // step too: a wheel speed that is wrong for a moment (a corrupt run of samples) moves
        // the wheel's prediction, not the track.
        let own = [moved[0] - ratio * chord[0], moved[1] - ratio * chord[1]];
        let excess = (off[0].hypot(off[1]) - threshold(d))
            .min(own[0].hypot(own[1]) - threshold(ratio * len));
        if excess > 0.0 {
            // A step spans the run of fixes whose windows straddle it, 2 w at most: one step,
            // at the run's largest (a longer run, a burst that keeps moving, is cut in steps
            // of 2 w).
            match steps.last_mut() {
                Some(last) if i == last_exceeding + 1 && i < run_start + 2 * w => {
                    if excess > last.2 {
                        *last = (i, off, excess);
                    }
                }
                _ => {
                    steps.push((i, off, excess));
                    run_start = i;
                }
            }
            last_exceeding = i;
        }
    }
    let mut bursts = Vec::new();
    let mut used = 0;
    for (j, &(a, off, _)) in steps.iter().enumerate() {
        if j < used {
            continue;
        }
        let size = off[0].hypot(off[1]);
        let back = steps[j + 1..]
            .iter()
            .filter(|s| t[s.0] - t[a] <= BURST_MAX_S)
            .collect::<Vec<_>>()
            .into_iter()
            .rposition(|s| {
                let back = s.1[0].hypot(s.1[1]);
                back > BURST_RETURN_SHARE * size && back < size / BURST_RETURN_SHARE
            });
        if let Some(k) = back {
            let b = steps[j + 1 + k].0;
            bursts.push((a, b, size));
            used = j + 2 + k;
        }
    }
    bursts
}

/// An interval between fixes longer than this many of the receiver's periods is an outage
/// ...
pub const GNSS_GAP_PERIODS: f64 = 2.5;
/// ... and longer than this, s: across a shorter gap a straight line is the track to within
/// 2.5 cm (the sagitta `v T^2 r / 8` at 10 m/s and 0.5 rad/s of yaw rate), the scatter of a
/// survey-grade receiver. A black-box probe's 100 Hz receiver losing 3 % of its fixes at
/// random had two in a row missing (30 ms) often enough that 13 of each minute were left out of
/// the track's fits, and with 10 % lost 53 of them, where the interpolation is exact.
pub const GNSS_GAP_MIN_S: f64 = 0.2;

/// The grid samples whose GNSS-derived signals rest on the interpolation across an outage:
/// those between two fixes more than [`GNSS_GAP_PERIODS`] of the receiver's (median) periods
/// and [`GNSS_GAP_MIN_S`] apart, widened by `reach` samples each way (the lowpass's and the differences' reach), and
/// the outages' total time, s. Black-box probe: eight outages of 2-4 s in turns took the
/// steering gain 4 % low and the yaw-rate fit 12.6 points below what the same model scores on
/// the clean drive (positions interpolated in a straight line across a turn).
fn gnss_gaps(tg: &[f64], grid: &[f64], reach: usize) -> (Vec<bool>, f64) {
    let period = median_interval(tg);
    let mut gap = vec![false; grid.len()];
    let mut total = 0.0;
    if period.is_nan() || period <= 0.0 || grid.is_empty() {
        return (gap, total);
    }
    let (g0, ts) = (
        grid[0],
        if grid.len() > 1 {
            grid[1] - grid[0]
        } else {
            1.0
        },
    );
    let longest_interpolated = (GNSS_GAP_PERIODS * period).max(GNSS_GAP_MIN_S);
    for w in tg.windows(2) {
        if w[1] - w[0] <= longest_interpolated {
            continue;
        }
        total += w[1] - w[0];
        let first = ((w[0] - g0) / ts).floor().max(0.0) as usize;
        let last = (((w[1] - g0) / ts).ceil().max(0.0) as usize).min(grid.len() - 1);
        for flag in &mut gap[first.saturating_sub(reach)..=(last + reach).min(grid.len() - 1)] {
            *flag = true;
        }
    }
    (gap, total)
}

/// Refuses a pause in a needed sensor longer than [`MAX_PAUSE_S`] (or ten of its periods),
/// naming the column and the times around it.
fn check_pauses(name: &str, t: &[f64]) -> Result<()> {
    let limit = MAX_PAUSE_S.max(10.0 * median_interval(t));
    if let Some(w) = t.windows(2).find(|w| w[1] - w[0] > limit) {
        bail!(
            "column `{name}` has no sample for {:.1} s (t = {} to {}), more than the {limit:.1} s \
             identify interpolates across: split the log there, or cut the pause out",
            w[1] - w[0],
            w[0],
            w[1]
        );
    }
    Ok(())
}

/// Zero-phase FIR lowpass (filtfilt) then MATLAB `smooth`, as the paper (II-C).
pub fn filter_signal(x: &[f64], taps: &[f64], span: usize) -> Result<Vec<f64>> {
    let mut y = x.to_vec();
    if !taps.is_empty() {
        let mut scratch = vec![0.0; filtfilt::filtfilt_scratch_len(taps.len(), x.len())];
        filtfilt::filtfilt(taps, x, &mut y, &mut scratch)
            .map_err(|e| anyhow!("zero-phase FIR: {e:?}"))?;
    }
    if span > 1 {
        let mut z = vec![0.0; y.len()];
        smooth::smooth(&y, span, &mut z).map_err(|e| anyhow!("smooth: {e:?}"))?;
        y = z;
    }
    Ok(y)
}

/// The central difference's half-width for a receiver at `gnss_rate_hz`, samples:
/// `opts.diff_half_width` at 100 Hz, times `(100 / rate)^(1/7)` (17 at 10 Hz, 23 at 1 Hz).
/// Why 1/7: a slope fitted over a baseline of T seconds to fixes with white noise has a
/// variance ~ 1 / (rate T^3), and the path's curvature biases it ~ T^2; the sum of the
/// variance and the squared bias is least for T ~ rate^(-1/7). With it the second car's 10 Hz
/// receiver (0.4 m noise) gives a lateral fit of 74 % / 78 % (training / validation,
/// `scripts/second-car.sh`); with the 100 Hz baseline of 12 samples its course is too noisy
/// for the fit floor.
pub fn diff_half_width(opts: &PreprocessOptions, gnss_rate_hz: f64) -> usize {
    let rate = if gnss_rate_hz.is_finite() && gnss_rate_hz > 0.0 {
        gnss_rate_hz
    } else {
        PAPER_GNSS_RATE_HZ
    };
    let scale = (PAPER_GNSS_RATE_HZ / rate).powf(1.0 / 7.0);
    ((opts.diff_half_width as f64 * scale).round() as usize).max(1)
}

/// Central difference with half-width `h` samples (one-sided, shrinking, at the ends).
pub fn derivative(x: &[f64], ts_s: f64, h: usize) -> Vec<f64> {
    let n = x.len();
    (0..n)
        .map(|k| {
            let lo = k.saturating_sub(h);
            let hi = (k + h).min(n.saturating_sub(1));
            if hi == lo {
                0.0
            } else {
                (x[hi] - x[lo]) / ((hi - lo) as f64 * ts_s)
            }
        })
        .collect()
}

/// The FIR taps of the options (empty when the FIR is off).
pub fn taps(opts: &PreprocessOptions) -> Result<Vec<f64>> {
    if opts.fir_taps == 0 {
        return Ok(Vec::new());
    }
    let mut taps = vec![0.0; opts.fir_taps];
    fir::design_lowpass(&mut taps, opts.cutoff_hz, 1.0 / opts.ts_s)
        .map_err(|e| anyhow!("FIR design (cutoff {} Hz): {e:?}", opts.cutoff_hz))?;
    Ok(taps)
}

/// The names the logs at `paths` go by in notes, figures and reports: each file's name without
/// `.csv`, or, for a file name that two of them share (`a/drive.csv`, `b/drive.csv`), the path
/// as given without `.csv` (by the file name alone the notes of one read as the other's).
pub fn log_names(paths: &[&Path]) -> Vec<String> {
    let short = |p: &Path| {
        p.file_name()
            .map(|n| n.to_string_lossy())
            .map(|n| n.strip_suffix(".csv").unwrap_or(&n).to_string())
            .unwrap_or_else(|| "log".into())
    };
    let names: Vec<String> = paths.iter().map(|p| short(p)).collect();
    paths
        .iter()
        .zip(&names)
        .map(
            |(p, name)| match names.iter().filter(|n| *n == name).count() {
                1 => name.clone(),
                _ => {
                    let path = p.display().to_string();
                    path.strip_suffix(".csv").unwrap_or(&path).to_string()
                }
            },
        )
        .collect()
}

/// Reads and preprocesses one log file, named by its file name ([`log_names`]). Errors name
/// the file and what is missing.
pub fn load_experiment(
    path: &Path,
    vehicle: &VehicleSection,
    opts: &PreprocessOptions,
) -> Result<Experiment> {
    let name = log_names(&[path]).remove(0);
    load_named(path, &name, vehicle, opts)
}

/// [`load_experiment`] under the name `name` (one of [`log_names`] of a set of logs).
pub fn load_named(
    path: &Path,
    name: &str,
    vehicle: &VehicleSection,
    opts: &PreprocessOptions,
) -> Result<Experiment> {
    let log = logcsv::read_log(path).map_err(|e| anyhow!("{e}"))?;
    let mut e = match preprocess_rows(name, &log.rows, vehicle, opts) {
        Ok(e) => e,
        // The step's line, where the log is to be split.
        Err(err) => match err.downcast_ref::<GnssStep>() {
            Some(step) => {
                let row = log.rows.partition_point(|r| r.t < step.t_after);
                match log.lines.get(row) {
                    Some(line) => bail!("{}:{line}: {step}", path.display()),
                    None => bail!("{}: {step}", path.display()),
                }
            }
            None => return Err(err.context(path.display().to_string())),
        },
    };
    let mut log_notes = log.notes.messages();
    log_notes.append(&mut e.log_notes);
    e.log_notes = log_notes;
    e.log_warnings = log.notes.warnings();
    Ok(e)
}

/// Preprocesses log rows (see the module doc). Fixes stamped on another clock than the wheel
/// speed's ([`super::gnss_clock`]) are moved onto it, by the offset that matches the speeds and
/// then by what the fine latency search ([`super::units::gnss_latency`]) finds left where its
/// standard error is under the match's [`super::gnss_clock::STEP_S`] (on a turn it read
/// 0.15 s +- 0.14 left, and moved the fixes too far), and named.
pub fn preprocess_rows(
    name: &str,
    rows: &[LogRow],
    vehicle: &VehicleSection,
    opts: &PreprocessOptions,
) -> Result<Experiment> {
    let (mut e, found) = preprocess_on_clock(name, rows, vehicle, opts, None)?;
    if let Some(mut offset) = found {
        // What the fine search finds left, where it times it finer than the match's steps.
        let left = super::units::gnss_latency(&e).filter(|(_, se)| *se < super::gnss_clock::STEP_S);
        if let Some((left, _)) = left {
            offset.behind_s += left;
            e = preprocess_on_clock(name, rows, vehicle, opts, Some(offset.behind_s))?.0;
        }
        e.log_notes.insert(0, offset.note(name));
    }
    Ok(e)
}

/// [`preprocess_rows`] with the fixes moved `clock_shift_s` earlier, or by the clock offset
/// found ([`super::gnss_clock::clock_offset`], returned) when `None`.
fn preprocess_on_clock(
    name: &str,
    rows: &[LogRow],
    vehicle: &VehicleSection,
    opts: &PreprocessOptions,
    clock_shift_s: Option<f64>,
) -> Result<(Experiment, Option<super::gnss_clock::ClockOffset>)> {
    let mut notes = Vec::new();
    let mut needed = |column: &str, get: fn(&LogRow) -> Option<f64>, p: Plausible| {
        plausible_column(name, rows, column, get, p, &mut notes)
    };
    let (tv, vel) = needed("vel", |r| r.vel, SPEED_PLAUSIBLE);
    let (tc, cmd) = needed("input_vel", |r| r.input_vel, SPEED_PLAUSIBLE);
    let (ts_, steer) = needed("steer", |r| r.steer, STEER_PLAUSIBLE);
    let (mut tg, mut latlon) = gnss_fixes(rows);
    drop_held_repeats(name, &mut tg, &mut latlon, &mut notes);
    let clock = clean_fixes(
        name,
        &mut tg,
        &mut latlon,
        (&tv, &vel),
        clock_shift_s,
        &mut notes,
    )?;
    check_needed([
        ("vel", &tv),
        ("input_vel", &tc),
        ("steer", &ts_),
        ("lat/lon", &tg),
    ])?;
    // The track needs the fixes, the speed model does not: a receiver that starts (or stops)
    // more than GNSS_LEAD_S away from the bus sensors leaves the grid on the bus sensors'
    // span, the track's samples outside the fixes' left out like an outage's.
    let with_fixes = overlap_grid([&tv, &tc, &ts_, &tg], opts)?;
    let bus = overlap_grid([&tv, &tc, &ts_, &tv], opts)?;
    let lead = |a: &[f64], b: &[f64], end: fn(&[f64]) -> f64| (end(a) - end(b)).abs();
    let first = |g: &[f64]| g.first().copied().unwrap_or(0.0);
    let last = |g: &[f64]| g.last().copied().unwrap_or(0.0);
    let fixes_late_s = lead(&with_fixes, &bus, first);
    let fixes_early_s = lead(&with_fixes, &bus, last);
    // A slow receiver's first and last fix lie up to a period inside the bus sensors' span.
    let lead_s = GNSS_LEAD_S.max(2.0 * median_interval(&tg));
    let grid = if fixes_late_s > lead_s || fixes_early_s > lead_s {
        bus
    } else {
        with_fixes
    };
    let report_intervals = crate::replay::ReportIntervals::of_log_columns(
        &catmodel::can::freshness::FreshnessConfig::DEFAULT,
        &ts_,
        [&tv, &tc],
    );

    let origin = latlon[0];
    let (xe, yn): (Vec<f64>, Vec<f64>) = local_metres(origin, &latlon)
        .into_iter()
        .map(|[e, n]| (e, n))
        .unzip();

    // On the raw samples: the wheel's distance, moved to the antenna by the steering, against
    // the track's (a `vel` in km/h passes the schema's range in town).
    let lever = super::units::LeverArm::of(vehicle);
    let wheel_track =
        super::units::WheelTrack::new((&tv, &vel), (&ts_, &steer), &lever, &tg, &xe, &yn);
    let speed_scale = wheel_track.as_ref().and_then(super::units::speed_scale);
    let speed_disagreement = wheel_track.as_ref().and_then(|wt| {
        let mut d = super::units::disagreement(wt).or_else(|| super::units::held_speed(wt))?;
        // The log's first fixes (after the bus sensors start, whatever clock offset moved them).
        let first_fix = tg.first().zip(tv.first()).map(|(g, v)| g.max(*v));
        d.from_first_fix = first_fix.is_some_and(|t0| d.from_s - t0 <= 2.0 * d.window_s);
        d.car_stood = d.track_m > d.wheel_m
            && super::units::stood_by_its_sensors(
                (&tv, &vel),
                (&tc, &cmd),
                d.from_s - super::units::STOOD_BEFORE_S,
                d.to_s,
            );
        Some(d)
    });

    let taps = taps(opts)?;
    let onto = OntoGrid {
        grid: &grid,
        taps: &taps,
        smooth_span: opts.smooth_span,
    };
    let vel = onto.filtered("vel", &tv, &vel)?;
    let input_vel = onto.filtered("input_vel", &tc, &cmd)?;
    let steer_pct = onto.filtered("steer", &ts_, &steer)?;
    // Held at the first and last fix across the grid's ends (left out of the track's fits).
    let (mut tgp, mut xep, mut ynp) = (tg.clone(), xe.clone(), yn.clone());
    if let (Some(&g0), Some(&t0)) = (grid.first(), tg.first()) {
        if g0 < t0 {
            tgp.insert(0, g0);
            xep.insert(0, xe[0]);
            ynp.insert(0, yn[0]);
        }
    }
    if let (Some(&g1), Some(&t1)) = (grid.last(), tg.last()) {
        if g1 > t1 {
            tgp.push(g1);
            xep.push(xe[xe.len() - 1]);
            ynp.push(yn[yn.len() - 1]);
        }
    }
    let x = onto.filtered("lat/lon", &tgp, &xep)?;
    let y = onto.filtered("lat/lon", &tgp, &ynp)?;
    let accel_pct = onto.optional(rows, "accel", |r| r.accel)?;
    let brake_pct = onto.optional(rows, "brake", |r| r.brake)?;
    let delta_rad = steer_pct
        .iter()
        .map(|p| vehicle.steer_pct_to_rad(*p))
        .collect();
    // The log's own receiver, not the model file's declared rate: the measured signals are
    // the log's, whatever file they are compared with (before, `compare` measured a 100 Hz log
    // with the windows of the file's `gnss_rate_hz`, and identify's validation figures, taken
    // with its base file's rate, were not what `compare` gave with the file it wrote).
    let half_width = diff_half_width(opts, 1.0 / median_interval(&tg));
    let dx = derivative(&x, opts.ts_s, half_width);
    let dy = derivative(&y, opts.ts_s, half_width);
    // Whether the car moves is the wheel speed's to say: the speed of differentiated GNSS
    // positions is noise-dominated at standstill (a 10 Hz receiver's 0.4 m noise reads as
    // about 1 m/s), and a course made of noise turns into yaw-rate spikes of several rad/s.
    let heading = course(&dx, &dy, &vel, MOVING_MPS);
    let yaw_half_width = 4 * half_width;
    let mut yaw_rate = derivative(&heading, opts.ts_s, yaw_half_width);
    zero_unless_moving(&mut yaw_rate, &vel, yaw_half_width);
    notes.extend(standing_note(name, &vel, opts.ts_s));
    let reach = taps.len() / 2 + opts.smooth_span + half_width + yaw_half_width;
    let (mut gnss_gap, outage_s) = gnss_gaps(&tg, &grid, reach);
    notes.extend(outage_note(name, &gnss_gap, outage_s, opts.ts_s));
    if grid.first() < tg.first() || grid.last() > tg.last() {
        let (t0, t1) = (first(&tg), last(&tg));
        let reach_s = reach as f64 * opts.ts_s;
        let (before, after) = (first(&grid) < t0, last(&grid) > t1);
        for (g, t) in gnss_gap.iter_mut().zip(&grid) {
            *g |= before && *t < t0 + reach_s || after && *t > t1 - reach_s;
        }
        notes.push(format!(
            "{name}: the GNSS fixes span t = {t0:.1} to {t1:.1} s, the bus sensors `vel`, \
             `input_vel` and `steer` t = {:.1} to {:.1} s: the {:.1} s without a fix are \
             used by the speed model, which needs none, and left out of the track's fits and \
             scores (yaw rate, dx/dt, the steering's steady turns)",
            first(&grid),
            last(&grid),
            fixes_late_s + fixes_early_s,
        ));
    }
    // A command in another unit stays off the speed everywhere: named as the unit
    // ([`Experiment::command_unit`]), not as a command the car did not follow.
    let command_unit = super::units::settled_command_problem(&grid, &vel, &input_vel);
    let (speed_skip, not_followed) = match command_unit {
        Some(_) => (Vec::new(), Vec::new()),
        None => command_not_followed(&grid, &vel, &input_vel),
    };
    notes.extend(not_followed.iter().map(|n| n.note(name)));
    let track_from = grid.partition_point(|t| *t < first(&tg));
    Ok(Experiment {
        name: name.to_string(),
        t: grid,
        ts_s: opts.ts_s,
        vel,
        input_vel,
        steer_pct,
        delta_rad,
        accel_pct,
        brake_pct,
        x,
        y,
        dx,
        dy,
        heading,
        yaw_rate,
        origin_deg: origin,
        yaw_half_width,
        gnss_rate_hz: 1.0 / median_interval(&tg),
        speed_scale,
        speed_disagreement,
        log_notes: notes,
        log_warnings: Vec::new(),
        track_from,
        gnss_gap,
        speed_skip,
        report_intervals,
        command_unit,
    })
    .map(|e| (e, clock))
}

/// A stretch whose commanded speed stays at least this far from the car's speed, m/s, ...
const NOT_FOLLOWED_GAP_MPS: f64 = 2.0;
/// ... for at least this long, s, ...
const NOT_FOLLOWED_MIN_S: f64 = 3.0;
/// ... while the speed moves towards it by less than this on average, m/s^2, is a command the
/// car did not follow: a car's speed loop answers a step of 2 m/s or more within its delay
/// (1.28 s at the longest the node runs) at a metre per second squared or so, and braking to
/// a stop from 30 m/s at 0.1 g still moves ten times faster than this.
const NOT_FOLLOWED_TOWARDS_MPS2: f64 = 0.2;
/// A stretch that ends with the speed closing on the command is a slow speed loop's late
/// answer, not a command it did not follow: over its last this many seconds the speed moved
/// towards the command at [`NOT_FOLLOWED_TOWARDS_MPS2`] or faster, and further than the
/// command moved towards the speed. A black-box probe's truck-like car (0.6 s of command delay,
/// a 1.2 s actuator lag, 0.8 m/s^2 at most) launched to 2.5 m/s after 2.3 s and had six logs'
/// launches left out as "not followed"; a takeover's command that comes back to the speed
/// ends the other way.
const NOT_FOLLOWED_ANSWER_S: f64 = 1.0;
/// After such a stretch the speed loop answers the command again: the longest delay the
/// node runs and the loop's settling, s, left out with the stretch.
const NOT_FOLLOWED_SETTLE_S: f64 = 5.0;

/// A stretch of a log whose commanded speed the car did not follow ([`command_not_followed`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NotFollowed {
    /// Start and end of the stretch, s (the log's time).
    pub from_s: f64,
    /// End of the stretch, s.
    pub to_s: f64,
    /// The command's mean distance from the speed over it, m/s (positive: above).
    pub gap_mps: f64,
    /// The car's mean speed over it, m/s.
    pub speed_mps: f64,
}

impl NotFollowed {
    /// The note `identify` prints for log `name`.
    pub fn note(&self, name: &str) -> String {
        format!(
            "{name}: from t = {:.1} to {:.1} s the commanded speed (`input_vel`) stayed {:.1} \
             m/s {} the speed ({:.1} m/s on average) and the car did not follow it (a driver's \
             takeover, the speed control disengaged): left out of the speed model's fit and \
             scores, with the {NOT_FOLLOWED_SETTLE_S:.0} s after it",
            self.from_s,
            self.to_s,
            self.gap_mps.abs(),
            if self.gap_mps > 0.0 { "above" } else { "below" },
            self.speed_mps
        )
    }
}

/// The samples of grid `t` whose commanded speed `cmd` did not drive the car (`vel`): at
/// least [`NOT_FOLLOWED_GAP_MPS`] from the speed on one side for [`NOT_FOLLOWED_MIN_S`] or
/// longer, the speed moving towards it by less than [`NOT_FOLLOWED_TOWARDS_MPS2`] on average,
/// flagged with the [`NOT_FOLLOWED_SETTLE_S`] after, unless the speed closes on the command
/// at the stretch's end ([`NOT_FOLLOWED_ANSWER_S`]: a slow loop's launch); and the stretches.
/// A black-box probe's training log whose `input_vel` read 0 for 5 s while the car cruised at
/// 9.7 m/s (the interface of a speed control that a driver overrode) took the speed model's
/// delay from 0.88 to 0.30 s, with right-half-plane zeros in its numerator, and nothing was
/// said.
pub fn command_not_followed(t: &[f64], vel: &[f64], cmd: &[f64]) -> (Vec<bool>, Vec<NotFollowed>) {
    let n = t.len().min(vel.len()).min(cmd.len());
    let mut skip = vec![false; n];
    let mut found = Vec::new();
    let side = |k: usize| -> i8 {
        let d = cmd[k] - vel[k];
        if d >= NOT_FOLLOWED_GAP_MPS {
            1
        } else if d <= -NOT_FOLLOWED_GAP_MPS {
            -1
        } else {
            0
        }
    };
    let mut k = 0;
    while k < n {
        let s = side(k);
        if s == 0 {
            k += 1;
            continue;
        }
        let a = k;
        while k < n && side(k) == s {
            k += 1;
        }
        let b = k - 1;
        let duration = t[b] - t[a];
        let towards = f64::from(s) * (vel[b] - vel[a]);
        if duration >= NOT_FOLLOWED_MIN_S
            && towards < NOT_FOLLOWED_TOWARDS_MPS2 * duration
            && !answered(t, vel, cmd, (a, b), s)
        {
            let count = (b - a + 1) as f64;
            found.push(NotFollowed {
                from_s: t[a],
                to_s: t[b],
                gap_mps: (a..=b).map(|i| cmd[i] - vel[i]).sum::<f64>() / count,
                speed_mps: vel[a..=b].iter().sum::<f64>() / count,
            });
            let until = t[b] + NOT_FOLLOWED_SETTLE_S;
            for (i, flag) in skip.iter_mut().enumerate().skip(a) {
                if t[i] > until {
                    break;
                }
                *flag = true;
            }
        }
    }
    if found.is_empty() {
        skip.clear();
    }
    (skip, found)
}

/// Whether the stretch `a..=b` of grid `t` where the command `cmd` stayed on side `side` of
/// the speed `vel` (1: above) ends with the speed closing on it ([`NOT_FOLLOWED_ANSWER_S`]):
/// the stretch ends before the log does, and over its last second the speed moved towards the
/// command at [`NOT_FOLLOWED_TOWARDS_MPS2`] or faster, and further than the command moved
/// towards the speed.
fn answered(t: &[f64], vel: &[f64], cmd: &[f64], (a, b): (usize, usize), side: i8) -> bool {
    if b + 1 >= t.len().min(vel.len()).min(cmd.len()) {
        return false;
    }
    let from = a + t[a..=b].partition_point(|x| *x < t[b] - NOT_FOLLOWED_ANSWER_S);
    let span = t[b + 1] - t[from];
    let speed_towards = f64::from(side) * (vel[b + 1] - vel[from]);
    let command_towards = -f64::from(side) * (cmd[b + 1] - cmd[from]);
    span > 0.0
        && speed_towards >= NOT_FOLLOWED_TOWARDS_MPS2 * span
        && speed_towards > command_towards
}

/// A needed sensor's samples of the log `log` (t, value), without its impossible ones
/// ([`drop_impossible`], which names them in `notes`).
fn plausible_column(
    log: &str,
    rows: &[LogRow],
    name: &str,
    get: fn(&LogRow) -> Option<f64>,
    p: Plausible,
    notes: &mut Vec<String>,
) -> (Vec<f64>, Vec<f64>) {
    let (mut t, v) = column(rows, get);
    let mut v: Vec<[f64; 1]> = v.into_iter().map(|x| [x]).collect();
    drop_impossible(log, name, &mut t, &mut v, p, |x| format!("{}", x[0]), notes);
    (t, v.into_iter().map(|[x]| x).collect())
}

/// The GNSS fixes of the rows that have both `lat` and `lon`: (t, (lat, lon)).
fn gnss_fixes(rows: &[LogRow]) -> (Vec<f64>, Vec<(f64, f64)>) {
    rows.iter()
        .filter_map(|r| match (r.lat, r.lon) {
            (Some(a), Some(b)) => Some((r.t, (a, b))),
            _ => None,
        })
        .unzip()
}

/// Leaves out of the fixes `tg`, `latlon` of the log `name` the repeats a logger held
/// ([`logcsv::held_fix_repeats`]), with a note: they are no fixes. Before, a 10 Hz receiver
/// held at 100 Hz measured 100 Hz (the median interval between rows with a fix), the file was
/// written with `gnss_rate_hz = 100` and no note, and the node built from it refused almost
/// every fix; the track was a staircase.
fn drop_held_repeats(
    name: &str,
    tg: &mut Vec<f64>,
    latlon: &mut Vec<(f64, f64)>,
    notes: &mut Vec<String>,
) {
    let Some(held) = logcsv::held_fix_repeats(tg, latlon) else {
        return;
    };
    notes.push(format!(
        "{name}: {}: left out; the receiver's rate ({:.1} Hz) and its track are measured from \
         the fixes that change",
        held.describe(),
        1.0 / held.receiver_period_s
    ));
    let mut keep = vec![true; tg.len()];
    for &i in &held.repeats {
        keep[i] = false;
    }
    let mut k = keep.iter();
    tg.retain(|_| *k.next().unwrap_or(&true));
    let mut k = keep.iter();
    latlon.retain(|_| *k.next().unwrap_or(&true));
}

/// A receiver that starts or stops more than this (or two of its periods) after or before the
/// bus sensors, s, leaves
/// the grid on the bus sensors' span: before, a receiver that started 20 s late cut those
/// 20 s out of the speed model's data without a word (a black-box probe: 29 speed steps ->
/// 21, the speed delay 0.88 s -> 0.68 s, its validation fit 92.3 % -> 90.6 %). A second or
/// less (a receiver's first fix after the logger starts) keeps the common span, as before.
pub const GNSS_LEAD_S: f64 = 1.0;

/// Fixes (lat, lon) in metres east and north of `origin` (lat, lon), degrees.
fn local_metres(origin: (f64, f64), latlon: &[(f64, f64)]) -> Vec<[f64; 2]> {
    let o = Geodetic {
        lat_deg: origin.0,
        lon_deg: origin.1,
        height_m: 0.0,
    };
    latlon
        .iter()
        .map(|(a, b)| {
            let e = geodetic_to_enu(*a, *b, 0.0, &o);
            [e.east_m, e.north_m]
        })
        .collect()
}

/// Fixes whose positions step by more than this are refused, m: `lat`/`lon` written with 4
/// decimals of a degree (11 m). A black-box probe's such log drew dozens of "multipath burst"
/// and "impossible sample" notes and was refused for a steering gain of -0.763, its position's
/// resolution never named; with 5 decimals (1.1 m) the file was written and the dx/dt model
/// validated at 74.5 % against 92.1 % from the same drive written in full.
pub const MAX_FIX_RESOLUTION_M: f64 = 5.0;
/// Fixes stepping by more than this are noted, m: 6 decimals (0.11 m) pass.
const NOTE_FIX_RESOLUTION_M: f64 = 0.5;

/// The decimals of a degree `lat`/`lon` are written with and the step they make north, m, when
/// every fix is a multiple of that step and it is coarser than [`NOTE_FIX_RESOLUTION_M`]
/// (with a receiver's 7 decimals or more, 20 fixes on a coarser grid by chance is 1e-20).
fn coarse_resolution(latlon: &[(f64, f64)]) -> Option<(u32, f64)> {
    if latlon.len() < 20 {
        return None;
    }
    let on_grid = |v: f64, scale: f64| ((v * scale).round() - v * scale).abs() < 1e-6;
    (0..=6u32).find_map(|decimals| {
        let scale = 10f64.powi(decimals as i32);
        let metres = 111_320.0 / scale;
        (metres > NOTE_FIX_RESOLUTION_M
            && latlon
                .iter()
                .all(|(lat, lon)| on_grid(*lat, scale) && on_grid(*lon, scale)))
        .then_some((decimals, metres))
    })
}

/// Where the fixes `latlon` (not empty) start: the median latitude and longitude of the
/// first `2 OUTLIER_NEIGHBOURS + 1`, which one impossible fix among them does not move.
fn start_of(latlon: &[(f64, f64)]) -> (f64, f64) {
    let first = &latlon[..latlon.len().min(2 * OUTLIER_NEIGHBOURS + 1)];
    let mut lat: Vec<f64> = first.iter().map(|f| f.0).collect();
    let mut lon: Vec<f64> = first.iter().map(|f| f.1).collect();
    (median(&mut lat), median(&mut lon))
}

/// Leaves out of the fixes `tg`, `latlon` of the log `name` the impossible ones
/// ([`drop_impossible`]) and the bursts that step off the track the wheel speed (`wheel`: its
/// times and m/s) continues ([`drop_bursts`]), each named in `notes`; a step no car makes
/// ([`gnss_discontinuity`]) is the error [`GnssStep`].
fn clean_fixes(
    name: &str,
    tg: &mut Vec<f64>,
    latlon: &mut Vec<(f64, f64)>,
    wheel: (&[f64], &[f64]),
    clock_shift_s: Option<f64>,
    notes: &mut Vec<String>,
) -> Result<Option<super::gnss_clock::ClockOffset>> {
    if latlon.is_empty() {
        return Ok(None);
    }
    if let Some((decimals, metres)) = coarse_resolution(latlon) {
        let what = format!(
            "`lat`/`lon` are written with {decimals} decimals of a degree: the fixes step by \
             {metres:.1} m (1e-{decimals} deg)"
        );
        if metres > MAX_FIX_RESOLUTION_M {
            bail!(
                "{what}, coarser than the car moves sideways in a turn between fixes: the track \
                 cannot be differentiated into a course and a yaw rate; write `lat`/`lon` with \
                 7 decimals (1 cm) or more"
            );
        }
        notes.push(format!(
            "{name}: {what}, as coarse as a standard receiver's noise: the yaw-rate and dx/dt fits and \
             scores are poorer than the receiver would give; write `lat`/`lon` with 7 decimals \
             (1 cm) or more"
        ));
    }
    // Fixes in metres from the median of the first few (the first may be the impossible
    // one: 6300 km away, it bent the plane the others were judged in), for the plausibility
    // check.
    let mut metres = local_metres(start_of(latlon), latlon);
    let dropped = drop_impossible(
        name,
        "lat/lon",
        tg,
        &mut metres,
        FIX_PLAUSIBLE,
        |m| format!("{:.1} m east, {:.1} m north", m[0], m[1]),
        notes,
    );
    for &i in dropped.iter().rev() {
        latlon.remove(i);
    }
    if let Some(step) = gnss_discontinuity(tg, &metres) {
        return Err(step.into());
    }
    // Fixes stamped on another clock, seconds off the wheel speed's: moved onto it before the
    // wheel speed judges them (a black-box probe's fixes 3-18 s late were refused as a wheel
    // speed that sticks, or fixes of another receiver).
    let found = match clock_shift_s {
        Some(_) => None,
        None => super::gnss_clock::clock_offset(tg, &metres, wheel),
    };
    if let Some(shift) = clock_shift_s.or(found.map(|o| o.behind_s)) {
        for t in tg.iter_mut() {
            *t -= shift;
        }
    }
    drop_bursts(name, tg, latlon, &metres, wheel, notes);
    Ok(found)
}

/// Leaves the bursts of [`gnss_bursts`] out of the fixes `tg`, `latlon` (`metres`: the same
/// fixes in metres; `tv`, `vel`: the wheel speed's times and m/s), with a note.
fn drop_bursts(
    log_name: &str,
    tg: &mut Vec<f64>,
    latlon: &mut Vec<(f64, f64)>,
    metres: &[[f64; 2]],
    (tv, vel): (&[f64], &[f64]),
    notes: &mut Vec<String>,
) {
    let bursts = gnss_bursts(tg, metres, tv, vel);
    if let Some(&(first, _, size)) = bursts.first() {
        let fixes: usize = bursts.iter().map(|b| b.1 - b.0).sum();
        notes.push(format!(
            "{log_name}: {} burst(s) of fixes that step off the track the wheel speed \
             continues and step back (multipath), {fixes} fixes in all, the first at t = \
             {:.2} s ({size:.1} m off): left out",
            bursts.len(),
            tg[first]
        ));
        for &(a, b, _) in bursts.iter().rev() {
            tg.drain(a..b);
            latlon.drain(a..b);
        }
    }
}

/// Refuses a log unless each needed sensor (name, sample times) has two samples at least and
/// no pause ([`check_pauses`]).
fn check_needed(columns: [(&str, &[f64]); 4]) -> Result<()> {
    let missing: Vec<&str> = columns
        .iter()
        .filter(|(_, t)| t.len() < 2)
        .map(|(n, _)| *n)
        .collect();
    if !missing.is_empty() {
        bail!(
            "log has no usable data in column(s) {} (need at least 2 samples each of t, vel, input_vel, steer, lat, lon)",
            missing.join(", ")
        );
    }
    for (name, t) in columns {
        check_pauses(name, t)?;
    }
    Ok(())
}

/// The uniform grid (period `opts.ts_s`) over the needed sensors' sample times `columns`
/// (none empty), refused when shorter than `opts.min_duration_s`.
fn overlap_grid(columns: [&[f64]; 4], opts: &PreprocessOptions) -> Result<Vec<f64>> {
    // The grid spans the time where every needed sensor has reported.
    let t0 = columns
        .iter()
        .map(|t| t[0])
        .fold(f64::NEG_INFINITY, f64::max);
    let t1 = columns
        .iter()
        .map(|t| *t.last().unwrap_or(&0.0))
        .fold(f64::INFINITY, f64::min);
    if (t1 - t0).is_nan() || t1 - t0 < opts.min_duration_s {
        bail!(
            "too short: the sensors overlap for {:.2} s, at least {} s needed",
            (t1 - t0).max(0.0),
            opts.min_duration_s
        );
    }
    let n = resample::fixed_period_len(t0, t1, opts.ts_s)
        .map_err(|e| anyhow!("grid {t0}..{t1}: {e:?}"))?;
    let mut grid = vec![0.0; n];
    resample::fixed_period_grid(t0, opts.ts_s, &mut grid).map_err(|e| anyhow!("grid: {e:?}"))?;
    // Rounding can push the last grid point a hair past t1.
    while grid.last().is_some_and(|g| *g > t1) {
        grid.pop();
    }
    Ok(grid)
}

/// The grid and the filter ([`filter_signal`]) that every column goes through onto it.
struct OntoGrid<'a> {
    /// The grid's times, s.
    grid: &'a [f64],
    /// The FIR lowpass's taps ([`taps`]).
    taps: &'a [f64],
    /// The moving average's span, samples.
    smooth_span: usize,
}

impl OntoGrid<'_> {
    /// A column's samples (`t`, `v`) onto the grid, filtered.
    fn filtered(&self, name: &str, t: &[f64], v: &[f64]) -> Result<Vec<f64>> {
        let g = onto_grid(name, t, v, self.grid)?;
        filter_signal(&g, self.taps, self.smooth_span).with_context(|| format!("column `{name}`"))
    }

    /// An optional column of `rows` onto the grid, filtered; zeros when the log has fewer
    /// than two samples of it.
    fn optional(
        &self,
        rows: &[LogRow],
        name: &str,
        get: fn(&LogRow) -> Option<f64>,
    ) -> Result<Vec<f64>> {
        let grid = self.grid;
        let (mut t, mut v) = column(rows, get);
        if t.len() < 2 {
            return Ok(vec![0.0; grid.len()]);
        }
        // An optional sensor may start late or stop early: hold its end values.
        if let (Some(&g0), Some(&t0), Some(&v0)) = (grid.first(), t.first(), v.first()) {
            if t0 > g0 {
                t.insert(0, g0);
                v.insert(0, v0);
            }
        }
        if let (Some(&g1), Some(&t1), Some(&v1)) = (grid.last(), t.last(), v.last()) {
            if t1 < g1 {
                t.push(g1);
                v.push(v1);
            }
        }
        self.filtered(name, &t, &v)
    }
}

/// The note for a log whose car stands more than [`STANDING_NOTE_SHARE`] of its time (`vel`
/// on the grid of period `ts_s`).
fn standing_note(name: &str, vel: &[f64], ts_s: f64) -> Option<String> {
    // A log that stands much of its time scores its speed models on samples that every model
    // gets right (black-box probe: 300 s of standstill halved the validation MSE and raised
    // the fit 2.8 points for the same model).
    let standing = vel.iter().filter(|v| v.abs() < STANDING_MPS).count();
    (standing as f64 > STANDING_NOTE_SHARE * vel.len() as f64).then(|| {
        format!(
            "{name}: the car stands {:.0} s of the log's {:.0} s ({:.0} %): the fit % and MSE \
             of the speed models count those samples, where every model is right, and read \
             better than over the driving alone",
            standing as f64 * ts_s,
            vel.len() as f64 * ts_s,
            100.0 * standing as f64 / vel.len() as f64
        )
    })
}

/// The note for a log with GNSS outages ([`gnss_gaps`]: `outage_s` in all, the grid samples
/// of period `ts_s` flagged in `gnss_gap` left out).
fn outage_note(name: &str, gnss_gap: &[bool], outage_s: f64, ts_s: f64) -> Option<String> {
    (outage_s > 0.0).then(|| {
        let left_out = gnss_gap.iter().filter(|g| **g).count() as f64 * ts_s;
        format!(
            "{name}: {outage_s:.1} s of GNSS outage (fixes more than {GNSS_GAP_PERIODS} of the \
             receiver's periods and {GNSS_GAP_MIN_S} s apart): the {left_out:.1} s whose track is interpolated across \
             them are left out of the yaw-rate and dx/dt fits and scores"
        )
    })
}

/// Below this wheel speed the car counts as standing: course held, yaw rate 0, m/s.
pub const MOVING_MPS: f64 = 1.0;

/// Sets `r[k]` to 0 unless the wheel speed is at least [`MOVING_MPS`] at every sample within
/// +-`half_width` of k: a course difference that reaches into a standstill compares a held
/// course with one measured at walking pace (noise, with a 10 Hz receiver), and reads as a
/// yaw-rate spike where the car only starts or stops.
fn zero_unless_moving(r: &mut [f64], speed_mps: &[f64], half_width: usize) {
    // Index of the latest standstill sample at or before each k, and the next at or after.
    let n = r.len().min(speed_mps.len());
    let mut last_stop: Option<usize> = None;
    let mut prev = vec![None; n];
    for (k, p) in prev.iter_mut().enumerate() {
        if speed_mps[k] < MOVING_MPS {
            last_stop = Some(k);
        }
        *p = last_stop;
    }
    let mut next_stop: Option<usize> = None;
    for k in (0..n).rev() {
        if speed_mps[k] < MOVING_MPS {
            next_stop = Some(k);
        }
        let near = prev[k].is_some_and(|p| k - p <= half_width)
            || next_stop.is_some_and(|s| s - k <= half_width);
        if near {
            r[k] = 0.0;
        }
    }
}

/// Course over ground from velocity components, clockwise from north, unwrapped; held at the
/// last value (or the first valid one) where `speed_mps` is below `min_speed_mps`.
pub fn course(dx: &[f64], dy: &[f64], speed_mps: &[f64], min_speed_mps: f64) -> Vec<f64> {
    let moving = |v: &f64| *v >= min_speed_mps;
    let first = dx
        .iter()
        .zip(dy)
        .zip(speed_mps)
        .find(|(_, v)| moving(v))
        .map(|((a, b), _)| a.atan2(*b))
        .unwrap_or(0.0);
    let mut out = Vec::with_capacity(dx.len());
    let mut prev = first;
    for ((a, b), v) in dx.iter().zip(dy).zip(speed_mps) {
        if moving(v) {
            let raw = a.atan2(*b);
            let mut d = raw - prev;
            d -= (d / std::f64::consts::TAU).round() * std::f64::consts::TAU;
            prev += d;
        }
        out.push(prev);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 100 Hz receiver's 0.5 s windows are 50 fixes: a log with 12 to 149 fixes (its fix got
    /// late, or was lost at once) has no three windows to compare. It underflowed the window
    /// range and panicked `identify` and `compare` (a black-box probe, 0.15-0.45 s of fixes).
    #[test]
    fn too_few_fixes_for_the_windows_find_no_burst() {
        for n in [12, 49, 50, 99, 149, 150] {
            let t: Vec<f64> = (0..n).map(|k| 10.0 + 0.01 * k as f64).collect();
            let xy: Vec<[f64; 2]> = t.iter().map(|t| [5.0 * t, 0.0]).collect();
            let (tv, vel) = (vec![0.0, 20.0], vec![5.0, 5.0]);
            assert!(gnss_bursts(&t, &xy, &tv, &vel).is_empty(), "{n} fixes");
        }
    }
}
