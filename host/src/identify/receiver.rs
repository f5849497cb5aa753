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

/// What the log shows.
#[derive(Debug, Clone, PartialEq)]
pub struct ReceiverError {
    /// East.
    pub east: AxisError,
    /// North.
    pub north: AxisError,
    /// Fixes used.
    pub fixes: usize,
    /// Their time span, s.
    pub duration_s: f64,
    /// Mean interval between fixes, s.
    pub interval_s: f64,
    /// Independent values of the bias the log holds (`duration / (2 tau)` of the longer
    /// correlation time; `None` when it is not determined).
    pub independent: Option<f64>,
    /// Speed reports in the window, and the largest speed among them, m/s.
    pub speed_reports: usize,
    /// Frames of PGN 129025 from the receiver that did not decode (not available, range).
    pub rejected: usize,
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

/// The error of the receiver at NMEA 2000 `source` from `frames` (any order), the car parked:
/// refused when a speed report says it moved, or with fewer than [`MIN_FIXES`] fixes.
pub fn measure(frames: &[TimedFrame], source: u8) -> Result<ReceiverError> {
    let mut frames: Vec<&TimedFrame> = frames.iter().collect();
    frames.sort_by_key(|f| f.t_us);
    let mut fixes: Vec<(f64, i32, i32)> = Vec::new();
    let (mut speed_reports, mut rejected) = (0usize, 0usize);
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
            Err(
                catmodel::can::codec::DecodeError::WrongId
                | catmodel::can::codec::DecodeError::WrongSource { .. },
            ) => {}
            Err(_) => rejected += 1,
        }
    }
    if fixes.len() < MIN_FIXES {
        bail!(
            "{} GNSS fixes (PGN 129025 from source address {source}) in the logs ({rejected} rejected): at least {MIN_FIXES} are needed",
            fixes.len()
        );
    }
    let (_, lat0, lon0) = fixes[0];
    let frame = LocalFrame::new(lat0, lon0).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let mut t = Vec::with_capacity(fixes.len());
    let (mut east, mut north) = (Vec::new(), Vec::new());
    for &(ti, lat, lon) in &fixes {
        let enu = frame
            .to_local(lat, lon)
            .map_err(|e| anyhow::anyhow!("fix at {ti:.2} s: {e:?}"))?;
        t.push(ti);
        east.push(f64::from(enu.east_m));
        north.push(f64::from(enu.north_m));
    }
    let duration_s = t.last().copied().unwrap_or(0.0) - t.first().copied().unwrap_or(0.0);
    if duration_s.is_nan() || duration_s < AVERAGE_S {
        bail!(
            "the {} fixes span {duration_s:.3} s of the logs' clock: the receiver's error needs their times (a log of the car parked for 10 minutes or more)",
            fixes.len()
        );
    }
    let interval_s = duration_s / (t.len() - 1) as f64;
    let per = ((AVERAGE_S / interval_s).round() as usize).max(1);
    let (e, n) = (axis(&east, per, interval_s), axis(&north, per, interval_s));
    let independent = match (e.correlation_s, n.correlation_s) {
        (Some(a), Some(b)) => Some(duration_s / (2.0 * a.max(b))),
        _ => None,
    };
    let measured = ReceiverError {
        east: e,
        north: n,
        fixes: fixes.len(),
        duration_s,
        interval_s,
        independent,
        speed_reports,
        rejected,
    };
    // A bound beyond what the model file takes is no receiver's error: the car moved (a
    // black-box probe's drive with its speed reports filtered out of the log was taken to be
    // parked, and `position_uncertainty_m = 410.7` advised, which the reader refuses).
    let bound = measured.uncertainty_m();
    if let Some(why) = model_file::range_problem("control.position_uncertainty_m", bound) {
        let east_span = east.iter().fold(f64::NEG_INFINITY, |m, v| m.max(*v))
            - east.iter().fold(f64::INFINITY, |m, v| m.min(*v));
        let north_span = north.iter().fold(f64::NEG_INFINITY, |m, v| m.max(*v))
            - north.iter().fold(f64::INFINITY, |m, v| m.min(*v));
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

/// Standard deviation about the mean.
fn sigma(x: &[f64]) -> f64 {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    (x.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n).sqrt()
}

/// One axis: its deviation, its average over `per` fixes' deviation, and the averaged series'
/// correlation time (fixes `interval_s` apart).
fn axis(x: &[f64], per: usize, interval_s: f64) -> AxisError {
    let slow: Vec<f64> = x
        .chunks(per)
        .filter(|c| c.len() == per)
        .map(|c| c.iter().sum::<f64>() / per as f64)
        .collect();
    let step_s = per as f64 * interval_s;
    AxisError {
        sigma_m: sigma(x),
        slow_sigma_m: if slow.len() > 1 { sigma(&slow) } else { 0.0 },
        correlation_s: correlation_time(&slow).map(|lags| lags * step_s),
    }
}

/// The first lag (in samples, interpolated) at which the series' autocorrelation falls below
/// 1/e, within a quarter of its length.
fn correlation_time(x: &[f64]) -> Option<f64> {
    let n = x.len();
    if n < 8 {
        return None;
    }
    let mean = x.iter().sum::<f64>() / n as f64;
    let d: Vec<f64> = x.iter().map(|v| v - mean).collect();
    let c0: f64 = d.iter().map(|v| v * v).sum::<f64>();
    if c0 <= 0.0 {
        return None;
    }
    let threshold = (-1.0f64).exp();
    let mut previous = 1.0;
    for lag in 1..=n / 4 {
        let c: f64 = d
            .iter()
            .zip(d.iter().skip(lag))
            .map(|(a, b)| a * b)
            .sum::<f64>()
            / c0;
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
        let a = axis(&x, 10, 0.1);
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
        let a = axis(&x, 10, 0.1);
        assert!((a.sigma_m / 0.5 - 1.0).abs() < 0.05, "{a:?}");
        assert!(
            (a.slow_sigma_m / (0.5 / 10f64.sqrt()) - 1.0).abs() < 0.1,
            "{a:?}"
        );
        assert!(a.correlation_s.unwrap() <= 1.0, "{a:?}");
    }
}
