//! The steering actuator's lag, from a session in which something commanded the steering over
//! the bus: CONTROL_COMMAND's `steer_cmd_pct` (what the drive-by-wire was told) beside
//! STEERING_REPORT's `steer_pct` (where the steering went), as a recorder on the bus writes
//! them (`catmodel identify-steering`; docs/controller.md, "A slow steering actuator").
//!
//! The actuator is taken to be what a steer-by-wire actuator is to first order, and what the
//! model file says of it: the command, after a transport delay `d`, is followed at most at the
//! rate limit the model file gives (`max_steer_rate_pct_per_s`), and the steering follows that
//! rate-limited target through a first-order lag of time constant `tau`. `(tau, d)` is the pair
//! whose simulation from the reports' first value matches the reports best (least squares, a
//! grid of 5 ms and then of 1 ms around its best): the lag is what `[vehicle] steer_lag_s`
//! declares; the delay is the bus's and the drive-by-wire's, which the controller's one tick
//! already covers. Only the window in which the controller drove counts: from a second after
//! its first tracking command (a drive-by-wire arms once it sees one) or from `--from`.
use anyhow::{bail, Result};
use catmodel::can::codec::{ControlCommand, ControlStatus, SteeringReport};
use catmodel::can::frame::TimedFrame;

use crate::sim::config::SteeringActuator as SteerParams;
use crate::sim::controller::SteeringActuator;

/// Grid of the coarse search, s.
const COARSE_S: f64 = 0.005;
/// Grid of the fine search around the coarse best, s.
const FINE_S: f64 = 0.001;
/// Longest lag searched, s: the model file's `steer_lag_s` range.
pub const MAX_LAG_S: f64 = 0.25;
/// Longest transport delay searched, s.
pub const MAX_DELAY_S: f64 = 0.1;
/// The simulation's step, s.
const STEP_S: f64 = 0.001;
/// The window starts this long after the first tracking command when not given, s.
pub const ARM_S: f64 = 1.0;
/// The commands must move the steering at least this much in the window, %: with less the
/// lag does not show above the reports' resolution and noise.
pub const MIN_SPAN_PCT: f64 = 5.0;

/// The session's steering: commands and reports, in time order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SteeringSeries {
    /// `(t s, steering command %, status)` of every valid CONTROL_COMMAND with a steering value.
    pub commands: Vec<(f64, f64, ControlStatus)>,
    /// `(t s, steering %)` of every valid STEERING_REPORT with a value.
    pub reports: Vec<(f64, f64)>,
    /// Frames with the two identifiers that did not decode (CRC, range, DLC), counted.
    pub rejected: usize,
}

impl SteeringSeries {
    /// The two messages out of a session's frames (any order of logs merged by time; other
    /// identifiers are skipped).
    pub fn from_frames(frames: &[TimedFrame]) -> Self {
        let mut s = Self::default();
        let mut frames: Vec<&TimedFrame> = frames.iter().collect();
        frames.sort_by_key(|f| f.t_us);
        for f in frames {
            let t = f.t_us as f64 * 1e-6;
            match f.frame.id {
                id if id == catmodel::can::spec::STEERING_REPORT.id => {
                    match SteeringReport::decode(&f.frame) {
                        Ok((r, _)) => {
                            if let Some(pct) = r.steer_pct {
                                s.reports.push((t, f64::from(pct)));
                            }
                        }
                        Err(_) => s.rejected += 1,
                    }
                }
                id if id == catmodel::can::spec::CONTROL_COMMAND.id => {
                    match ControlCommand::decode(&f.frame) {
                        Ok((c, _)) => {
                            if let Some(pct) = c.steer_cmd_pct {
                                s.commands.push((t, f64::from(pct), c.status));
                            }
                        }
                        Err(_) => s.rejected += 1,
                    }
                }
                _ => {}
            }
        }
        s
    }
}

/// What the fit found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SteeringFit {
    /// First-order lag, s (`[vehicle] steer_lag_s`).
    pub lag_s: f64,
    /// Transport delay, s.
    pub delay_s: f64,
    /// RMS of the simulation's error at the reports, %.
    pub rms_pct: f64,
    /// The same with neither lag nor delay: how much the two explain.
    pub rms_without_pct: f64,
    /// The window, s.
    pub from_s: f64,
    /// End of the window (the last report), s.
    pub to_s: f64,
    /// Reports in the window.
    pub reports: usize,
    /// Commands in the window.
    pub commands: usize,
    /// Largest minus smallest command in the window, %.
    pub span_pct: f64,
}

impl SteeringFit {
    /// How far the steering trails a ramp command, s: the lag plus the delay. What the MPC's
    /// command must lead its plan by (less the tick it adds itself), and what `[vehicle]
    /// steer_lag_s` declares; the two parts trade against each other in the fit (a lag and a
    /// delay of the same sum differ only in the corners of the ramps), their sum does not.
    pub fn trail_s(&self) -> f64 {
        self.lag_s + self.delay_s
    }
}

/// Fits the lag and the delay of an actuator with rate limit `rate_pct_per_s` to `series`,
/// over the window from `from_s` (or [`ARM_S`] after the first tracking or avoiding command).
pub fn fit(
    series: &SteeringSeries,
    rate_pct_per_s: f64,
    from_s: Option<f64>,
) -> Result<SteeringFit> {
    if !(rate_pct_per_s.is_finite() && rate_pct_per_s > 0.0) {
        bail!("steering rate limit {rate_pct_per_s} %/s: must be positive");
    }
    if series.commands.is_empty() {
        bail!("no CONTROL_COMMAND (0x320) with a steering command in the logs: give the log of the frames sent to the drive-by-wire too");
    }
    if series.reports.is_empty() {
        bail!(
            "no STEERING_REPORT (0x100) with a value in the logs ({} frames of the two messages rejected: CRC, range or length)",
            series.rejected
        );
    }
    let from = match from_s {
        Some(t) => t,
        None => match series
            .commands
            .iter()
            .find(|c| matches!(c.2, ControlStatus::Tracking | ControlStatus::Avoiding))
        {
            Some(c) => c.0 + ARM_S,
            None => bail!("no CONTROL_COMMAND with status tracking or avoiding: the controller never drove (give --from)"),
        },
    };
    let window: Vec<(f64, f64)> = series
        .reports
        .iter()
        .copied()
        .filter(|r| r.0 >= from)
        .collect();
    let (Some(first), Some(last)) = (window.first(), window.last()) else {
        bail!("no STEERING_REPORT after {from:.2} s");
    };
    let in_window = series
        .commands
        .iter()
        .filter(|c| c.0 >= from - MAX_DELAY_S && c.0 <= last.0);
    let (mut lo, mut hi, mut commands) = (f64::INFINITY, f64::NEG_INFINITY, 0usize);
    for c in in_window {
        lo = lo.min(c.1);
        hi = hi.max(c.1);
        commands += 1;
    }
    let span_pct = if commands > 0 { hi - lo } else { 0.0 };
    if span_pct < MIN_SPAN_PCT {
        bail!(
            "the commands move the steering by {span_pct:.1} % from {from:.2} s to {:.2} s: at least {MIN_SPAN_PCT} % is needed to see its lag (a lane change or a slalom does)",
            last.0
        );
    }
    let cost = |lag: f64, delay: f64| {
        simulate_rms(
            &series.commands,
            &window,
            first.1,
            rate_pct_per_s,
            lag,
            delay,
        )
    };
    let mut best = (f64::INFINITY, 0.0, 0.0);
    let grid =
        |max: f64, step: f64| (0..=(max / step).round() as usize).map(move |i| i as f64 * step);
    for lag in grid(MAX_LAG_S, COARSE_S) {
        for delay in grid(MAX_DELAY_S, COARSE_S) {
            let c = cost(lag, delay);
            if c < best.0 {
                best = (c, lag, delay);
            }
        }
    }
    let (_, lag0, delay0) = best;
    let around = |centre: f64, max: f64| {
        (-5..=5)
            .map(move |i| centre + f64::from(i) * FINE_S)
            .filter(move |v| (0.0..=max + 1e-9).contains(v))
    };
    for lag in around(lag0, MAX_LAG_S) {
        for delay in around(delay0, MAX_DELAY_S) {
            let c = cost(lag, delay);
            if c < best.0 {
                best = (c, lag, delay);
            }
        }
    }
    Ok(SteeringFit {
        lag_s: best.1,
        delay_s: best.2,
        rms_pct: best.0,
        rms_without_pct: cost(0.0, 0.0),
        from_s: from,
        to_s: last.0,
        reports: window.len(),
        commands,
        span_pct,
    })
}

/// RMS error at `reports` of the actuator model started at `start_pct` at the first report:
/// the built-in plant's actuator (`sim::controller::SteeringActuator`, the same rate-limited
/// first-order lag) with this rate limit and lag, stepped every millisecond.
fn simulate_rms(
    commands: &[(f64, f64, ControlStatus)],
    reports: &[(f64, f64)],
    start_pct: f64,
    rate_pct_per_s: f64,
    lag_s: f64,
    delay_s: f64,
) -> f64 {
    let positions = simulate(commands, reports, start_pct, rate_pct_per_s, lag_s, delay_s);
    let (mut sum, mut n) = (0.0, 0usize);
    for (p, r) in positions.iter().zip(reports) {
        let e = p - r.1;
        sum += e * e;
        n += 1;
    }
    if n == 0 {
        return f64::INFINITY;
    }
    (sum / n as f64).sqrt()
}

/// The actuator's position at each report's time, from `start_pct` at the first report; the
/// command in force at `t` is the last one sent at or before `t - delay_s`.
fn simulate(
    commands: &[(f64, f64, ControlStatus)],
    reports: &[(f64, f64)],
    start_pct: f64,
    rate_pct_per_s: f64,
    lag_s: f64,
    delay_s: f64,
) -> Vec<f64> {
    let Some(&(t0, _)) = reports.first() else {
        return Vec::new();
    };
    let params = SteerParams {
        rate_limit_pct_per_s: rate_pct_per_s,
        lag_s,
    };
    let mut actuator = SteeringActuator::new(&params, STEP_S, start_pct);
    let mut next = commands.partition_point(|c| c.0 + delay_s <= t0);
    let mut target = next
        .checked_sub(1)
        .and_then(|i| commands.get(i))
        .map_or(start_pct, |c| c.1);
    let (mut t, mut position) = (t0, start_pct);
    let mut out = Vec::with_capacity(reports.len());
    for &(tr, _) in reports {
        while t + STEP_S <= tr {
            t += STEP_S;
            while let Some(c) = commands.get(next) {
                if c.0 + delay_s > t {
                    break;
                }
                target = c.1;
                next += 1;
            }
            position = actuator.step(target);
        }
        out.push(position);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reports of a known actuator, hand-driven by a square wave of commands: its simulated
    /// positions rounded to the report's 0.1 %.
    fn series(lag_s: f64, delay_s: f64, rate: f64) -> SteeringSeries {
        let commands: Vec<(f64, f64, ControlStatus)> = (0..1000)
            .map(|i| {
                let t = i as f64 * 0.02;
                let cmd = if (i / 75) % 2 == 0 { 20.0 } else { -20.0 };
                (t, cmd, ControlStatus::Tracking)
            })
            .collect();
        let times: Vec<(f64, f64)> = (0..1000).map(|i| (i as f64 * 0.02 + 0.01, 0.0)).collect();
        let positions = simulate(&commands, &times, 0.0, rate, lag_s, delay_s);
        let reports = times
            .iter()
            .zip(positions)
            .map(|(&(t, _), p)| (t, (p * 10.0).round() / 10.0))
            .collect();
        SteeringSeries {
            commands,
            reports,
            rejected: 0,
        }
    }

    #[test]
    fn the_lag_and_delay_of_a_known_actuator_are_found() {
        for (lag, delay) in [(0.04, 0.0), (0.09, 0.01), (0.15, 0.03)] {
            let f = fit(&series(lag, delay, 60.0), 60.0, Some(0.0)).unwrap();
            // What a ramp trails by (the lead the controller needs) to the millisecond; the
            // split between the lag and the delay, which trade against each other, to 6 ms.
            assert!(
                (f.trail_s() - lag - delay).abs() <= 0.0015,
                "{lag} + {delay}: {f:?}"
            );
            assert!((f.lag_s - lag).abs() <= 0.006, "{lag}: {f:?}");
            assert!((f.delay_s - delay).abs() <= 0.006, "{delay}: {f:?}");
            assert!(
                f.rms_pct < 0.1 && f.rms_without_pct > 5.0 * f.rms_pct,
                "{f:?}"
            );
        }
    }

    #[test]
    fn a_session_that_cannot_show_the_lag_is_refused_with_the_reason() {
        let mut s = series(0.05, 0.0, 60.0);
        for c in &mut s.commands {
            c.1 = 1.0;
        }
        let e = fit(&s, 60.0, Some(0.0)).unwrap_err().to_string();
        assert!(e.contains("at least 5 %"), "{e}");
        let mut idle = series(0.05, 0.0, 60.0);
        for c in &mut idle.commands {
            c.2 = ControlStatus::NoPath;
        }
        let e = fit(&idle, 60.0, None).unwrap_err().to_string();
        assert!(e.contains("never drove"), "{e}");
        let mut corrupt = series(0.05, 0.0, 60.0);
        corrupt.rejected = corrupt.reports.len();
        corrupt.reports.clear();
        let e = fit(&corrupt, 60.0, None).unwrap_err().to_string();
        assert!(
            e.contains("1000 frames of the two messages rejected"),
            "{e}"
        );
        let e = fit(&SteeringSeries::default(), 60.0, None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("CONTROL_COMMAND"), "{e}");
        assert!(fit(&series(0.05, 0.0, 60.0), f64::NAN, None).is_err());
    }
}
