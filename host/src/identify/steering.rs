//! The steering actuator's lag, from a session in which something commanded the steering over
//! the bus: CONTROL_COMMAND's `steer_cmd_pct` (what the drive-by-wire was told) beside
//! STEERING_REPORT's `steer_pct` (where the steering went), as a recorder on the bus writes
//! them (`catmodel identify-steering`; docs/controller.md, "A slow steering actuator").
//!
//! The actuator is taken to be what a steer-by-wire actuator is to first order, and what the
//! model file says of it: the command, after a transport delay `d`, is followed at most at a
//! rate limit `R` (`max_steer_rate_pct_per_s`), and the steering follows that rate-limited
//! target through a first-order lag of time constant `tau`. `(tau, d)` is the pair whose
//! simulation from the reports' first value matches the reports best (least squares, a grid of
//! 5 ms and then of 1 ms around its best): the lag is what `[vehicle] steer_lag_s` declares;
//! the delay is the bus's and the drive-by-wire's, which the controller's one tick already
//! covers. Only the window in which the controller drove counts: from a second after its first
//! tracking command (a drive-by-wire arms once it sees one) or from `--from`.
//!
//! The rate limit is measured when the session shows it: the pair is fitted first with no limit,
//! then `R` on a 1 % grid from the steering's fastest movement (a rate-limited lag never moves
//! faster than `R`) to twice that, and the pair again at the best `R`. The limit is taken as
//! measured only if it explains the reports: their error with it at most [`RATE_SHOWN_RATIO`]
//! of the error without any. A session whose commands never ask for more than the actuator
//! gives does not show it (the lag alone slows every step): then the model file's limit is used
//! if one is given, and the fastest movement is reported as what the limit is at least.
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
/// A rate limit is measured when it takes from the reports' mean square error more than this
/// share of their noise's variance ([`report_noise`]; the built-in plant's reports have 0.2 %
/// RMS). Commands held a tick each step, and a limit slows the steps within the tick: that
/// shows in reports free of noise, and is not what a limit is measured from.
pub const RATE_SHOWN_SHARE: f64 = 0.1;
/// The fastest movement is the largest change of the steering, averaged over
/// [`MOVE_AVERAGE`] reports, over this span, s: the reports' noise, differenced over a short
/// span, would read as speed (0.2 % over 0.1 s: 2.8 %/s of noise, whose largest of a thousand
/// windows is three times that).
const MOVE_SPAN_S: f64 = 0.2;
/// Reports averaged for the fastest movement.
const MOVE_AVERAGE: usize = 5;
/// The rate limit is searched from this many times the fastest movement (the average's noise
/// may still read as a little speed) ...
const RATE_SEARCH_LOW: f64 = 0.8;
/// ... to this many times it (a short ramp ends before the lag has caught up with it).
const RATE_SEARCH_FACTOR: f64 = 2.0;
/// Step of the joint grid's limit, as a share of the fastest movement, and of its lag and delay, s.
const COARSE_RATE_STEP: f64 = 0.02;
const COARSE_JOINT_S: f64 = 0.01;
/// The joint searches around the best: the limit's step (a share of it), the lag's and the
/// delay's, s, and how many times at most each is repeated while the best moves.
const JOINT_STEPS: [(f64, f64, usize); 3] =
    [(0.01, 0.005, 4), (0.005, 0.002, 4), (0.0025, 0.001, 8)];

/// Reports (or commands) further apart than this many of their median intervals split the
/// session into stretches, fitted apart (a recorder paused, logs of two sessions): the
/// simulation runs within each stretch, from its first report, never across a gap, so the
/// fit costs the data's time, not the span's ...
pub const GAP_PERIODS: f64 = 10.0;
/// ... and further apart than this, s.
pub const MIN_GAP_S: f64 = 0.2;

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

impl SteeringSeries {
    /// The two messages out of several logs' frames (`(name, frames)`), each log read apart:
    /// logs whose reports (or commands) overlap in time are two sessions on clocks that
    /// overlap (each recorded from 0), which would be merged into one: refused, naming them.
    /// A log that repeats another's messages exactly (the same times and values: one
    /// recording given twice, or a bus log beside the node's own log of its commands) is read
    /// once.
    pub fn from_logs(logs: &[(String, &[TimedFrame])]) -> Result<Self> {
        let series: Vec<Self> = logs.iter().map(|(_, f)| Self::from_frames(f)).collect();
        let times = |s: &Self, reports: bool| -> Vec<(f64, f64)> {
            if reports {
                s.reports.clone()
            } else {
                s.commands.iter().map(|c| (c.0, c.1)).collect()
            }
        };
        for (reports, name) in [(true, "STEERING_REPORT"), (false, "CONTROL_COMMAND")] {
            for i in 0..series.len() {
                for j in i + 1..series.len() {
                    let (a, b) = (times(&series[i], reports), times(&series[j], reports));
                    let (Some(a0), Some(a1), Some(b0), Some(b1)) =
                        (a.first(), a.last(), b.first(), b.last())
                    else {
                        continue;
                    };
                    let (from, to) = (a0.0.max(b0.0), a1.0.min(b1.0));
                    if from > to {
                        continue;
                    }
                    let within = |v: &[(f64, f64)]| -> Vec<(f64, f64)> {
                        v.iter()
                            .copied()
                            .filter(|x| x.0 >= from && x.0 <= to)
                            .collect()
                    };
                    let (wa, wb) = (within(&a), within(&b));
                    if wa == wb {
                        continue;
                    }
                    bail!(
                        "{} and {} both hold {name}s from {from:.2} s to {to:.2} s ({} and {} \
                         of them): two sessions whose times overlap (each recorded from 0?), \
                         which would be fitted as one: give each session's logs to \
                         identify-steering on its own",
                        logs[i].0,
                        logs[j].0,
                        wa.len(),
                        wb.len()
                    );
                }
            }
        }
        let mut out = Self::default();
        for s in series {
            out.commands.extend(s.commands);
            out.reports.extend(s.reports);
            out.rejected += s.rejected;
        }
        out.commands.sort_by(|a, b| a.0.total_cmp(&b.0));
        out.reports.sort_by(|a, b| a.0.total_cmp(&b.0));
        out.commands.dedup();
        out.reports.dedup();
        Ok(out)
    }
}

/// The actuator's rate limit, as the session shows it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RateLimit {
    /// The reports are explained by the limit: `pct_per_s`; their error RMS without a limit
    /// was `rms_unlimited_pct`.
    Measured {
        /// The limit, %/s.
        pct_per_s: f64,
        /// Report error RMS of the best fit with no limit, %.
        rms_unlimited_pct: f64,
    },
    /// The commands never asked for more than the actuator gives: the limit is at least the
    /// steering's fastest movement, `at_least_pct_per_s`.
    NotShown {
        /// The steering's fastest movement (over 0.1 s), %/s.
        at_least_pct_per_s: f64,
    },
}

/// What the fit found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SteeringFit {
    /// The rate limit.
    pub rate: RateLimit,
    /// The rate limit the lag and delay were fitted with, %/s (`inf`: none).
    pub fitted_with_pct_per_s: f64,
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
    /// Stretches the window was split into at gaps in the reports or commands
    /// ([`GAP_PERIODS`], [`MIN_GAP_S`]), fitted apart; their reports' time, s.
    pub stretches: usize,
    pub fitted_s: f64,
    /// The gaps between the stretches: how many, and the longest's start and end, s.
    pub gaps: usize,
    pub longest_gap: Option<(f64, f64)>,
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

/// Fits the rate limit, the lag and the delay of the actuator to `series`, over the window
/// from `from_s` (or [`ARM_S`] after the first tracking or avoiding command). `file_rate`: the
/// model file's rate limit, %/s, used when the session does not show the limit.
pub fn fit(
    series: &SteeringSeries,
    file_rate: Option<f64>,
    from_s: Option<f64>,
) -> Result<SteeringFit> {
    if let Some(r) = file_rate {
        if !(r.is_finite() && r > 0.0) {
            bail!("steering rate limit {r} %/s: must be positive");
        }
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
    let (Some(_), Some(last)) = (window.first(), window.last()) else {
        bail!("no STEERING_REPORT after {from:.2} s");
    };
    let split = stretches(&window, &series.commands);
    if split.ranges.is_empty() {
        bail!("no two STEERING_REPORTs after {from:.2} s without a gap between them in the reports or the commands");
    }
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
    let parts: Vec<&[(f64, f64)]> = split.ranges.iter().map(|r| &window[r.clone()]).collect();
    let cost =
        |rate: f64, lag: f64, delay: f64| simulate_rms(&series.commands, &parts, rate, lag, delay);
    let lag_and_delay = |rate: f64| lag_and_delay_at(&cost, rate);
    // With no limit; and with a limit, the three fitted jointly.
    let moved = parts
        .iter()
        .map(|p| fastest_movement(p))
        .fold(0.0f64, f64::max);
    let unlimited = lag_and_delay(f64::INFINITY);
    let (limit, at_limit) = if moved > 0.0 {
        rate_lag_and_delay(&cost, moved)
    } else {
        (f64::INFINITY, unlimited)
    };
    // The limit shows when it explains more of the reports' mean square error than a share of
    // their noise's: an error that is mostly noise does not tell a limit from none.
    let noise = report_noise(&parts);
    let explained = unlimited.0 * unlimited.0 - at_limit.0 * at_limit.0;
    let shown = limit.is_finite() && explained > RATE_SHOWN_SHARE * noise * noise;
    let (rate, best) = if shown {
        let rate = RateLimit::Measured {
            pct_per_s: limit,
            rms_unlimited_pct: unlimited.0,
        };
        (rate, (limit, at_limit))
    } else {
        let rate = RateLimit::NotShown {
            at_least_pct_per_s: moved,
        };
        match file_rate {
            Some(r) => (rate, (r, lag_and_delay(r))),
            None => (rate, (f64::INFINITY, unlimited)),
        }
    };
    let (fitted_with, best) = best;
    Ok(SteeringFit {
        rate,
        fitted_with_pct_per_s: fitted_with,
        lag_s: best.1,
        delay_s: best.2,
        rms_pct: best.0,
        rms_without_pct: cost(fitted_with, 0.0, 0.0),
        from_s: from,
        to_s: last.0,
        reports: parts.iter().map(|p| p.len()).sum(),
        commands,
        span_pct,
        stretches: parts.len(),
        fitted_s: parts
            .iter()
            .map(|p| p.last().map_or(0.0, |l| l.0) - p.first().map_or(0.0, |f| f.0))
            .sum(),
        gaps: split.gaps,
        longest_gap: split.longest_gap,
    })
}

/// The window's stretches: the reports between gaps ([`stretches`]).
struct Split {
    /// Each stretch's reports, as a range of the window's (two at least).
    ranges: Vec<std::ops::Range<usize>>,
    /// The gaps between stretches, and the longest's start and end, s.
    gaps: usize,
    longest_gap: Option<(f64, f64)>,
}

/// Splits the window's `reports` into stretches wherever two reports are further apart than
/// [`GAP_PERIODS`] of their median interval and [`MIN_GAP_S`], or the commands are (the
/// reports from the last command before such a gap to [`MAX_DELAY_S`] after the first one
/// after it are left out: what the actuator was told there is not known).
fn stretches(reports: &[(f64, f64)], commands: &[(f64, f64, ControlStatus)]) -> Split {
    let limit = |t: &[f64]| (GAP_PERIODS * super::stats::median_interval(t)).max(MIN_GAP_S);
    let report_gap = limit(&reports.iter().map(|r| r.0).collect::<Vec<_>>());
    let command_times: Vec<f64> = commands.iter().map(|c| c.0).collect();
    let command_gap = limit(&command_times);
    let silent: Vec<(f64, f64)> = command_times
        .windows(2)
        .filter(|w| w[1] - w[0] > command_gap)
        .map(|w| (w[0], w[1] + MAX_DELAY_S))
        .collect();
    let mut split = Split {
        ranges: Vec::new(),
        gaps: 0,
        longest_gap: None,
    };
    let mut start: Option<usize> = None;
    let mut last_end: Option<f64> = None;
    let mut close = |split: &mut Split, start: &mut Option<usize>, end: usize| {
        if let Some(s) = start.take() {
            if end - s >= 2 {
                let (t0, t1) = (reports[s].0, reports[end - 1].0);
                if let Some(previous) = last_end {
                    split.gaps += 1;
                    if split.longest_gap.is_none_or(|(a, b)| t0 - previous > b - a) {
                        split.longest_gap = Some((previous, t0));
                    }
                }
                last_end = Some(t1);
                split.ranges.push(s..end);
            }
        }
    };
    let mut k = 0;
    for (i, r) in reports.iter().enumerate() {
        while silent.get(k).is_some_and(|g| g.1 <= r.0) {
            k += 1;
        }
        let quiet = silent.get(k).is_some_and(|g| g.0 < r.0);
        if quiet {
            close(&mut split, &mut start, i);
            continue;
        }
        if i > 0 && r.0 - reports[i - 1].0 > report_gap {
            close(&mut split, &mut start, i);
        }
        if start.is_none() {
            start = Some(i);
        }
    }
    close(&mut split, &mut start, reports.len());
    split
}

/// `0, step, 2 step, ...` up to `max`.
fn grid(max: f64, step: f64) -> impl Iterator<Item = f64> {
    (0..=(max / step).round() as usize).map(move |i| i as f64 * step)
}

/// Whether a lag and a delay lie in the searched ranges.
fn in_range(lag: f64, delay: f64) -> bool {
    (0.0..=MAX_LAG_S + 1e-9).contains(&lag) && (0.0..=MAX_DELAY_S + 1e-9).contains(&delay)
}

/// The `(cost, lag, delay)` of least `cost(rate, lag, delay)` at a given rate limit: a grid
/// of [`COARSE_S`], then of [`FINE_S`] around its best.
fn lag_and_delay_at(cost: &impl Fn(f64, f64, f64) -> f64, rate: f64) -> (f64, f64, f64) {
    let mut best = (f64::INFINITY, 0.0, 0.0);
    for lag in grid(MAX_LAG_S, COARSE_S) {
        for delay in grid(MAX_DELAY_S, COARSE_S) {
            let c = cost(rate, lag, delay);
            if c < best.0 {
                best = (c, lag, delay);
            }
        }
    }
    let (_, lag0, delay0) = best;
    for i in -5..=5 {
        for j in -5..=5 {
            let (lag, delay) = (lag0 + f64::from(i) * FINE_S, delay0 + f64::from(j) * FINE_S);
            if in_range(lag, delay) {
                let c = cost(rate, lag, delay);
                if c < best.0 {
                    best = (c, lag, delay);
                }
            }
        }
    }
    best
}

/// The rate limit and the `(cost, lag, delay)` of least cost, the three jointly: a grid of the
/// limit from [`RATE_SEARCH_LOW`] to [`RATE_SEARCH_FACTOR`] times the fastest movement `moved`
/// (which a saturated ramp approaches), then searches around the best on the finer steps of
/// [`JOINT_STEPS`] (the limit and the lag trade along a valley that a search of one at a time
/// crawls down: 44 %/s and 0.098 s for a 43 %/s, 0.087 s actuator).
fn rate_lag_and_delay(cost: &impl Fn(f64, f64, f64) -> f64, moved: f64) -> (f64, (f64, f64, f64)) {
    let mut best = (f64::INFINITY, (f64::INFINITY, 0.0, 0.0));
    for r in grid(RATE_SEARCH_FACTOR - RATE_SEARCH_LOW, COARSE_RATE_STEP) {
        let rate = moved * (RATE_SEARCH_LOW + r);
        for lag in grid(MAX_LAG_S, COARSE_JOINT_S) {
            for delay in grid(MAX_DELAY_S, COARSE_JOINT_S) {
                let c = cost(rate, lag, delay);
                if c < best.1 .0 {
                    best = (rate, (c, lag, delay));
                }
            }
        }
    }
    for (rate_step, time_step, rounds) in JOINT_STEPS {
        for _ in 0..rounds {
            let (rate0, (c0, lag0, delay0)) = best;
            for i in -2..=2 {
                let rate = rate0 * (1.0 + f64::from(i) * rate_step);
                for j in -2..=2 {
                    for k in -2..=2 {
                        let lag = lag0 + f64::from(j) * time_step;
                        let delay = delay0 + f64::from(k) * time_step;
                        if in_range(lag, delay) {
                            let c = cost(rate, lag, delay);
                            if c < best.1 .0 {
                                best = (rate, (c, lag, delay));
                            }
                        }
                    }
                }
            }
            if best.1 .0 == c0 {
                break;
            }
        }
    }
    best
}

/// The largest change of the reported steering (each averaged with its neighbours over
/// [`MOVE_AVERAGE`] reports) over [`MOVE_SPAN_S`] (or the next report after it), per second: a
/// rate-limited actuator never moves faster than its limit.
fn fastest_movement(reports: &[(f64, f64)]) -> f64 {
    let averaged: Vec<(f64, f64)> = reports
        .windows(MOVE_AVERAGE)
        .map(|w| {
            let n = w.len() as f64;
            let t = w.iter().map(|r| r.0).sum::<f64>() / n;
            (t, w.iter().map(|r| r.1).sum::<f64>() / n)
        })
        .collect();
    let mut fastest = 0.0f64;
    for (i, &(t, p)) in averaged.iter().enumerate() {
        let later = averaged.get(i..).unwrap_or_default();
        let Some(&(t2, p2)) = later.iter().find(|r| r.0 >= t + MOVE_SPAN_S) else {
            break;
        };
        fastest = fastest.max((p2 - p).abs() / (t2 - t));
    }
    fastest
}

/// The reports' noise, %, from their second differences: the steering itself, a lagged and
/// rate-limited movement, bends only at a ramp's corners, which the median leaves out.
fn report_noise(stretches: &[&[(f64, f64)]]) -> f64 {
    let mut d2: Vec<f64> = stretches
        .iter()
        .flat_map(|s| s.windows(3))
        .filter_map(|w| match w {
            [a, b, c] => Some((a.1 - 2.0 * b.1 + c.1).abs()),
            _ => None,
        })
        .collect();
    if d2.is_empty() {
        return 0.0;
    }
    super::stats::noise_from_second_differences(&mut d2)
}

/// RMS error at the reports of each stretch of the actuator model started at the stretch's
/// first report: the built-in plant's actuator (`sim::controller::SteeringActuator`, the same
/// rate-limited first-order lag) with this rate limit and lag, stepped every millisecond
/// within each stretch.
fn simulate_rms(
    commands: &[(f64, f64, ControlStatus)],
    stretches: &[&[(f64, f64)]],
    rate_pct_per_s: f64,
    lag_s: f64,
    delay_s: f64,
) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for reports in stretches {
        let Some(&(_, start_pct)) = reports.first() else {
            continue;
        };
        let positions = simulate(commands, reports, start_pct, rate_pct_per_s, lag_s, delay_s);
        for (p, r) in positions.iter().zip(reports.iter()) {
            let e = p - r.1;
            sum += e * e;
            n += 1;
        }
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
            let f = fit(&series(lag, delay, 60.0), Some(60.0), Some(0.0)).unwrap();
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

    /// The square wave asks for 40 % in a tick: the actuator's limit shows, and is measured to
    /// 1 % whatever the model file says (or without one), with the lag as before.
    #[test]
    fn the_rate_limit_of_a_known_actuator_is_measured() {
        for (rate, lag) in [(43.0, 0.087), (60.0, 0.05), (110.0, 0.02)] {
            for file in [None, Some(60.0)] {
                let f = fit(&series(lag, 0.0, rate), file, Some(0.0)).unwrap();
                let RateLimit::Measured {
                    pct_per_s,
                    rms_unlimited_pct,
                } = f.rate
                else {
                    panic!("{rate}: {f:?}");
                };
                assert!((pct_per_s / rate - 1.0).abs() <= 0.01, "{rate}: {f:?}");
                assert_eq!(f.fitted_with_pct_per_s, pct_per_s);
                assert!((f.trail_s() - lag).abs() <= 0.0015, "{lag}: {f:?}");
                assert!(f.rms_pct < 0.1 && rms_unlimited_pct > 1.0, "{f:?}");
            }
        }
    }

    /// Commands slower than the actuator (a 0.3 Hz sine of 20 %, at most 37.7 %/s, to a 60 %/s
    /// actuator; reports with the plant's noise) do not show its limit: it is reported as at
    /// least the fastest movement, the lag is found all the same, with the model file's limit
    /// or none.
    #[test]
    fn a_limit_the_commands_never_reach_is_not_measured() {
        let commands: Vec<(f64, f64, ControlStatus)> = (0..1000)
            .map(|i| {
                let t = i as f64 * 0.02;
                let cmd = 20.0 * (2.0 * std::f64::consts::PI * 0.3 * t).sin();
                (t, (cmd * 10.0).round() / 10.0, ControlStatus::Tracking)
            })
            .collect();
        let times: Vec<(f64, f64)> = (0..1000).map(|i| (i as f64 * 0.02 + 0.01, 0.0)).collect();
        let positions = simulate(&commands, &times, 0.0, 60.0, 0.07, 0.0);
        // The plant's report noise, 0.2 % RMS (uniform, from a fixed linear congruential
        // sequence).
        let mut state = 12345u64;
        let reports = times
            .iter()
            .zip(positions)
            .map(|(&(t, _), p)| {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let u = (state >> 11) as f64 / (1u64 << 53) as f64;
                let noise = (u - 0.5) * 0.2 * 12f64.sqrt();
                (t, ((p + noise) * 10.0).round() / 10.0)
            })
            .collect();
        let s = SteeringSeries {
            commands,
            reports,
            rejected: 0,
        };
        for file in [None, Some(60.0)] {
            let f = fit(&s, file, Some(0.0)).unwrap();
            let RateLimit::NotShown { at_least_pct_per_s } = f.rate else {
                panic!("{f:?}");
            };
            // 37.7 %/s less the lag's loss, plus the reports' 0.1 % resolution over 0.1 s.
            assert!(
                at_least_pct_per_s > 35.0 && at_least_pct_per_s <= 38.7,
                "{f:?}"
            );
            assert_eq!(f.fitted_with_pct_per_s, file.unwrap_or(f64::INFINITY));
            // A sine tells a lag from a delay by its amplitude alone (0.9 % here, about the
            // reports' resolution): the trail to 6 ms.
            assert!((f.trail_s() - 0.07).abs() <= 0.006, "{f:?}");
        }
    }

    #[test]
    fn a_session_that_cannot_show_the_lag_is_refused_with_the_reason() {
        let mut s = series(0.05, 0.0, 60.0);
        for c in &mut s.commands {
            c.1 = 1.0;
        }
        let e = fit(&s, Some(60.0), Some(0.0)).unwrap_err().to_string();
        assert!(e.contains("at least 5 %"), "{e}");
        let mut idle = series(0.05, 0.0, 60.0);
        for c in &mut idle.commands {
            c.2 = ControlStatus::NoPath;
        }
        let e = fit(&idle, Some(60.0), None).unwrap_err().to_string();
        assert!(e.contains("never drove"), "{e}");
        let mut corrupt = series(0.05, 0.0, 60.0);
        corrupt.rejected = corrupt.reports.len();
        corrupt.reports.clear();
        let e = fit(&corrupt, None, None).unwrap_err().to_string();
        assert!(
            e.contains("1000 frames of the two messages rejected"),
            "{e}"
        );
        let e = fit(&SteeringSeries::default(), None, None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("CONTROL_COMMAND"), "{e}");
        assert!(fit(&series(0.05, 0.0, 60.0), Some(f64::NAN), None).is_err());
    }
}
