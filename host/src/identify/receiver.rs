//! The GNSS receiver's error, from a log of the car parked: what `[control]
//! position_uncertainty_m` declares (`catmodel receiver-error`; docs/controller.md, "The
//! obstacle and the receiver").
//!
//! A parked car's fixes scatter around where it stands by the receiver's error alone. A
//! single-point receiver's error is mostly a bias that wanders over tens of seconds (the
//! simulator's: 0.8 m per axis, 60 s correlation) beside a white noise that the node's lowpass
//! removes; so each axis is averaged over [`AVERAGE_S`] (the white noise gone, the bias kept)
//! and its standard deviation about the mean taken. How long the bias takes to forget is its
//! correlation time (the lag at which the averaged series' autocorrelation falls below 1/e);
//! a log of `T` seconds holds about `T / (2 tau)` independent values of it, and a standard
//! deviation from `n` of them is uncertain by about `1 / sqrt(2 n)`: a log shorter than
//! [`MIN_INDEPENDENT`] independent values, or than [`MIN_LOG_S`], is reported as too short. The bound to declare is
//! [`SIGMAS`] standard deviations of the worse axis.
use crate::model_file;
use anyhow::{bail, Result};
use catmodel::can::codec::{GnssPosition, SpeedReport};
use catmodel::can::frame::TimedFrame;
use catmodel::geodesy::LocalFrame;

/// Each axis is averaged over this long before its deviation is taken, s.
pub const AVERAGE_S: f64 = 1.0;
/// The bound to declare, in standard deviations of the averaged error (docs/controller.md).
pub const SIGMAS: f64 = 2.5;
/// A log shorter than this many independent values of the bias is too short to bound it.
pub const MIN_INDEPENDENT: f64 = 20.0;
/// A log shorter than this is too short whatever its correlation time looks like (a short
/// log's autocorrelation understates a bias that wanders over minutes), s.
pub const MIN_LOG_S: f64 = 600.0;
/// A speed report above this means the car was not parked, m/s.
pub const PARKED_MPS: f64 = 0.05;
/// At least this many fixes are needed.
const MIN_FIXES: usize = 20;

/// One axis's error.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisError {
    /// Standard deviation of the fixes about their mean, m.
    pub sigma_m: f64,
    /// The same of the fixes averaged over [`AVERAGE_S`], m: the part the node keeps.
    pub slow_sigma_m: f64,
    /// Correlation time of the averaged error, s (`None`: it never fell below 1/e within a
    /// quarter of the log).
    pub correlation_s: Option<f64>,
}

/// A log's fixes further apart than this many of their median intervals split it into
/// stretches (a recorder paused, a receiver reset), measured apart: the 1 s average and the
/// autocorrelation follow the receiver's rate within a stretch, and never reach across a gap.
pub const GAP_PERIODS: f64 = 10.0;
/// ... and at least this far apart, s (a pause of the log, as the reader names it).
pub const MIN_GAP_S: f64 = 1.0;

/// What the logs show.
#[derive(Debug, Clone, PartialEq)]
pub struct ReceiverError {
    /// East.
    pub east: AxisError,
    /// North.
    pub north: AxisError,
    /// Fixes used.
    pub fixes: usize,
    /// Their time span within the stretches (pauses and the time between logs not counted), s.
    pub duration_s: f64,
    /// Interval between fixes, s: the median within the stretches.
    pub interval_s: f64,
    /// Independent values of the bias the logs hold (`duration / (2 tau)` of the longer
    /// correlation time; `None` when it is not determined).
    pub independent: Option<f64>,
    /// Speed reports in the window, and the largest speed among them, m/s.
    pub speed_reports: usize,
    /// Frames of PGN 129025 from the receiver that did not decode (not available, range).
    pub rejected: usize,
    /// The logs with fixes, and the stretches their fixes were split into.
    pub logs: usize,
    pub stretches: usize,
    /// Gaps between fixes within a log that split it ([`GAP_PERIODS`], [`MIN_GAP_S`]), and the
    /// longest: its log (index among those given), start and end, s.
    pub gaps: usize,
    pub longest_gap: Option<(usize, f64, f64)>,
}

impl ReceiverError {
    /// The bound to declare: [`SIGMAS`] times the worse axis's averaged deviation, m, rounded
    /// up to 0.1 m.
    pub fn uncertainty_m(&self) -> f64 {
        let s = self.east.slow_sigma_m.max(self.north.slow_sigma_m);
        (SIGMAS * s * 10.0).ceil() / 10.0
    }

    /// Whether the log holds enough of the bias to bound it: [`MIN_INDEPENDENT`] values of it
    /// and [`MIN_LOG_S`].
    pub fn long_enough(&self) -> bool {
        self.duration_s >= MIN_LOG_S && self.independent.is_some_and(|n| n >= MIN_INDEPENDENT)
    }

    /// How long a log would be long enough, s (`None`: not known, the error never forgot
    /// itself within the log).
    pub fn log_needed_s(&self) -> Option<f64> {
        let tau = self.east.correlation_s?.max(self.north.correlation_s?);
        Some((2.0 * MIN_INDEPENDENT * tau).max(MIN_LOG_S))
    }
}

/// One stretch of a log's fixes: times, s, and positions east and north, m.
struct Stretch {
    log: usize,
    t: Vec<f64>,
    east: Vec<f64>,
    north: Vec<f64>,
}

/// The error of the receiver at NMEA 2000 `source` from `logs` (each a log's frames, any
/// order), the car parked: refused when a speed report says it moved, or with fewer than
/// [`MIN_FIXES`] fixes. Each log is taken apart from the others (two logs stamped from 0 are
/// not interleaved, two a day apart not joined), and split at its pauses into stretches; the
/// statistics are pooled over the stretches, none taken across a pause or between logs. The
/// deviations are about each log's own mean (the car stands in one place for a log, perhaps
/// another for the next).
pub fn measure(logs: &[&[TimedFrame]], source: u8) -> Result<ReceiverError> {
    let mut per_log: Vec<Vec<(f64, i32, i32)>> = Vec::new();
    let (mut speed_reports, mut rejected) = (0usize, 0usize);
    let mut other_sources = [0u64; 256];
    for frames in logs {
        let mut frames: Vec<&TimedFrame> = frames.iter().collect();
        frames.sort_by_key(|f| f.t_us);
        let mut fixes = Vec::new();
        for f in frames {
            let t = f.t_us as f64 * 1e-6;
            if f.frame.id == catmodel::can::spec::SPEED_REPORT.id {
                if let Ok((r, _)) = SpeedReport::decode(&f.frame) {
                    if let Some(v) = r.speed_mps {
                        speed_reports += 1;
                        if f64::from(v).abs() > PARKED_MPS {
                            bail!(
                                "the car moved: {v:.2} m/s at {t:.2} s (speed report): record the receiver with the car parked"
                            );
                        }
                    }
                }
                continue;
            }
            match GnssPosition::decode(&f.frame, source) {
                Ok(p) => fixes.push((t, p.lat_e7, p.lon_e7)),
                Err(catmodel::can::codec::DecodeError::WrongSource { got }) => {
                    other_sources[usize::from(got)] += 1;
                }
                Err(catmodel::can::codec::DecodeError::WrongId) => {}
                Err(_) => rejected += 1,
            }
        }
        per_log.push(fixes);
    }
    let total: usize = per_log.iter().map(Vec::len).sum();
    if total < MIN_FIXES {
        let others: Vec<(u8, u64)> = other_sources
            .iter()
            .enumerate()
            .filter(|(_, n)| **n > 0)
            .map(|(sa, n)| (sa as u8, *n))
            .collect();
        let advice = match crate::replay::other_sources_list(&others) {
            Some((list, busiest)) => format!(
                "; {list} did send PGN 129025: if that is the car's receiver, set \
                 gnss_source_address = {busiest} in the model file's [inputs] (--model)"
            ),
            None => String::new(),
        };
        bail!(
            "{total} GNSS fixes (PGN 129025 from source address {source}, the model file's \
             [inputs] gnss_source_address) in the logs ({rejected} rejected): at least \
             {MIN_FIXES} are needed{advice}"
        );
    }
    let Some(&(_, lat0, lon0)) = per_log.iter().find_map(|l| l.first()) else {
        bail!("no GNSS fix in the logs");
    };
    let frame = LocalFrame::new(lat0, lon0).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let mut stretches: Vec<Stretch> = Vec::new();
    let (mut gaps, mut longest_gap) = (0usize, None::<(usize, f64, f64)>);
    for (log, fixes) in per_log.iter().enumerate() {
        let times: Vec<f64> = fixes.iter().map(|f| f.0).collect();
        let period = super::stats::median_interval(&times);
        let split = (GAP_PERIODS * period).max(MIN_GAP_S);
        let mut previous: Option<f64> = None;
        for &(ti, lat, lon) in fixes {
            let enu = frame
                .to_local(lat, lon)
                .map_err(|e| anyhow::anyhow!("fix at {ti:.2} s: {e:?}"))?;
            let new_stretch = match previous {
                None => true,
                Some(p) if ti - p > split => {
                    gaps += 1;
                    if longest_gap.is_none_or(|(_, a, b)| ti - p > b - a) {
                        longest_gap = Some((log, p, ti));
                    }
                    true
                }
                Some(_) => false,
            };
            if new_stretch {
                stretches.push(Stretch {
                    log,
                    t: Vec::new(),
                    east: Vec::new(),
                    north: Vec::new(),
                });
            }
            if let Some(s) = stretches.last_mut() {
                s.t.push(ti);
                s.east.push(f64::from(enu.east_m));
                s.north.push(f64::from(enu.north_m));
            }
            previous = Some(ti);
        }
    }
    let span =
        |s: &Stretch| s.t.last().copied().unwrap_or(0.0) - s.t.first().copied().unwrap_or(0.0);
    let duration_s: f64 = stretches.iter().map(span).sum();
    if duration_s.is_nan() || duration_s < AVERAGE_S {
        bail!(
            "the {total} fixes span {duration_s:.3} s of the logs' clock: the receiver's error needs their times (a log of the car parked for 10 minutes or more)"
        );
    }
    let mut intervals: Vec<f64> = stretches
        .iter()
        .flat_map(|s| s.t.windows(2).map(|w| w[1] - w[0]))
        .collect();
    let interval_s = super::stats::median(&mut intervals);
    // Each stretch's fixes averaged over about a second at its own rate: how many make a
    // second, and how long that many take.
    let shape: Vec<(usize, usize, f64)> = stretches
        .iter()
        .map(|s| {
            let n = s.t.len();
            let median = super::stats::median_interval(&s.t);
            let per = if median > 0.0 {
                ((AVERAGE_S / median).round() as usize).max(1)
            } else {
                1
            };
            let mean = if n > 1 { span(s) / (n - 1) as f64 } else { 0.0 };
            (s.log, per, per as f64 * mean)
        })
        .collect();
    let e = axis(
        &stretches
            .iter()
            .map(|s| s.east.as_slice())
            .collect::<Vec<_>>(),
        &shape,
    );
    let n = axis(
        &stretches
            .iter()
            .map(|s| s.north.as_slice())
            .collect::<Vec<_>>(),
        &shape,
    );
    let independent = match (e.correlation_s, n.correlation_s) {
        (Some(a), Some(b)) => Some(duration_s / (2.0 * a.max(b))),
        _ => None,
    };
    let measured = ReceiverError {
        east: e,
        north: n,
        fixes: total,
        duration_s,
        interval_s,
        independent,
        speed_reports,
        rejected,
        logs: per_log.iter().filter(|l| !l.is_empty()).count(),
        stretches: stretches.len(),
        gaps,
        longest_gap,
    };
    // A bound beyond what the model file takes is no receiver's error: the car moved (a
    // black-box probe's drive with its speed reports filtered out of the log was taken to be
    // parked, and `position_uncertainty_m = 410.7` advised, which the reader refuses).
    let bound = measured.uncertainty_m();
    if let Some(why) = model_file::range_problem("control.position_uncertainty_m", bound) {
        let all = |f: fn(&Stretch) -> &Vec<f64>| {
            let v = stretches.iter().flat_map(|s| f(s).iter().copied());
            v.clone().fold(f64::NEG_INFINITY, f64::max) - v.fold(f64::INFINITY, f64::min)
        };
        let (east_span, north_span) = (all(|s| &s.east), all(|s| &s.north));
        bail!(
            "the fixes spread over {east_span:.0} m east and {north_span:.0} m north, a bound of \
             {bound:.1} m ({why}): the car moved{}; record the receiver with the car parked",
            if speed_reports == 0 {
                " (the logs have no speed report to tell: SPEED_REPORT, 0x101)"
            } else {
                ""
            }
        );
    }
    Ok(measured)
}

/// One axis over its stretches (`shape`: each stretch's log, the fixes averaged into one
/// value, and the time those take, s): the fixes' deviation and that of their averages, each
/// about its log's mean, pooled; and the averaged series' correlation time, pooled over the
/// stretches (no average and no lag across a pause).
fn axis(stretches: &[&[f64]], shape: &[(usize, usize, f64)]) -> AxisError {
    let slow: Vec<Vec<f64>> = stretches
        .iter()
        .zip(shape)
        .map(|(x, &(_, per, _))| {
            x.chunks(per)
                .filter(|c| c.len() == per)
                .map(|c| c.iter().sum::<f64>() / per as f64)
                .collect()
        })
        .collect();
    // Each log's mean, of its fixes and of its averages.
    let logs = shape.iter().map(|s| s.0 + 1).max().unwrap_or(0);
    let mut sums = vec![(0.0, 0usize, 0.0, 0usize); logs];
    for ((x, s), &(log, _, _)) in stretches.iter().zip(&slow).zip(shape) {
        let m = &mut sums[log];
        m.0 += x.iter().sum::<f64>();
        m.1 += x.len();
        m.2 += s.iter().sum::<f64>();
        m.3 += s.len();
    }
    let mean = |sum: f64, n: usize| if n > 0 { sum / n as f64 } else { 0.0 };
    let (mut fast_sq, mut fast_n, mut slow_sq, mut slow_n) = (0.0, 0usize, 0.0, 0usize);
    let mut deviations: Vec<Vec<f64>> = Vec::with_capacity(slow.len());
    for ((x, s), &(log, _, _)) in stretches.iter().zip(&slow).zip(shape) {
        let (sum, n, slow_sum, slow_count) = sums[log];
        let (m, ms) = (mean(sum, n), mean(slow_sum, slow_count));
        fast_sq += x.iter().map(|v| (v - m) * (v - m)).sum::<f64>();
        fast_n += x.len();
        let d: Vec<f64> = s.iter().map(|v| v - ms).collect();
        slow_sq += d.iter().map(|v| v * v).sum::<f64>();
        slow_n += d.len();
        deviations.push(d);
    }
    // The averages' step, s: the stretches' own, weighted by their averages.
    let step_s = slow
        .iter()
        .zip(shape)
        .map(|(s, &(_, _, step))| s.len() as f64 * step)
        .sum::<f64>()
        / slow_n.max(1) as f64;
    AxisError {
        sigma_m: (fast_sq / fast_n.max(1) as f64).sqrt(),
        slow_sigma_m: if slow_n > 1 {
            (slow_sq / slow_n as f64).sqrt()
        } else {
            0.0
        },
        correlation_s: correlation_time(&deviations).map(|lags| lags * step_s),
    }
}

/// The first lag (in samples, interpolated) at which the series' autocorrelation falls below
/// 1/e, within a quarter of the longest stretch's length: `d` holds each stretch's deviations
/// from its log's mean, and the autocorrelation at a lag sums the products within each
/// stretch long enough for that lag over those stretches' variance (one stretch: the usual
/// estimate).
fn correlation_time(d: &[Vec<f64>]) -> Option<f64> {
    let longest = d.iter().map(Vec::len).max().unwrap_or(0);
    if longest < 8 {
        return None;
    }
    let energy: Vec<f64> = d.iter().map(|s| s.iter().map(|v| v * v).sum()).collect();
    if energy.iter().sum::<f64>() <= 0.0 {
        return None;
    }
    let threshold = (-1.0f64).exp();
    let mut previous = 1.0;
    for lag in 1..=longest / 4 {
        let (mut c, mut c0) = (0.0, 0.0);
        for (s, e) in d.iter().zip(&energy) {
            if s.len() > lag {
                c += s
                    .iter()
                    .zip(s.iter().skip(lag))
                    .map(|(a, b)| a * b)
                    .sum::<f64>();
                c0 += e;
            }
        }
        let c = c / c0;
        if c < threshold {
            // Between lag - 1 (previous) and lag (c).
            let f = (previous - threshold) / (previous - c);
            return Some(lag as f64 - 1.0 + f);
        }
        previous = c;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::rng::{SimRng as Rng, Stream};

    /// A first-order Gauss-Markov series of deviation `sigma` and correlation `tau`, sampled
    /// every `dt`, plus white noise of deviation `white`.
    fn gauss_markov(
        rng: &mut Rng,
        n: usize,
        dt: f64,
        sigma: f64,
        tau: f64,
        white: f64,
    ) -> Vec<f64> {
        let a = (-dt / tau).exp();
        let q = sigma * (1.0 - a * a).sqrt();
        let mut b = sigma * rng.normal();
        (0..n)
            .map(|_| {
                b = a * b + q * rng.normal();
                b + white * rng.normal()
            })
            .collect()
    }

    /// A known bias (0.8 m, 60 s) under white noise (0.3 m), 10 fixes a second: over two hours
    /// (60 independent values of the bias) its deviation to 20 %, its correlation time to 35 %,
    /// and the white noise averaged away.
    #[test]
    fn a_known_bias_is_measured() {
        let mut rng = Rng::new(7, Stream::Gnss);
        let x = gauss_markov(&mut rng, 72_000, 0.1, 0.8, 60.0, 0.3);
        let a = axis(&[&x], &[(0, 10, 1.0)]);
        assert!((a.slow_sigma_m / 0.8 - 1.0).abs() < 0.2, "{a:?}");
        assert!(a.sigma_m > a.slow_sigma_m, "{a:?}");
        let tau = a.correlation_s.unwrap();
        assert!((tau / 60.0 - 1.0).abs() < 0.35, "{a:?}");
    }

    /// White noise alone: averaged over a second, ten fixes leave a third of it, and it forgets
    /// within a sample.
    #[test]
    fn white_noise_averages_away() {
        let mut rng = Rng::new(3, Stream::Gnss);
        let x = gauss_markov(&mut rng, 20_000, 0.1, 0.0, 60.0, 0.5);
        let a = axis(&[&x], &[(0, 10, 1.0)]);
        assert!((a.sigma_m / 0.5 - 1.0).abs() < 0.05, "{a:?}");
        assert!(
            (a.slow_sigma_m / (0.5 / 10f64.sqrt()) - 1.0).abs() < 0.1,
            "{a:?}"
        );
        assert!(a.correlation_s.unwrap() <= 1.0, "{a:?}");
    }
}
