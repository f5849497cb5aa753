//! The fixes' clock against the other sensors': a recorder that stamps the GNSS fixes with the
//! receiver's time and the bus sensors with its own puts the fixes seconds off (GPS time logged
//! as UTC: 18 s of leap seconds since 1980, as of 2017). The speed along the track is matched
//! with the wheel speed over a wide range of lags, cheaply (both as chords and means over 2 s,
//! every 0.1 s); a lag beyond any receiver's latency that the match determines is another
//! clock, and the fixes are moved onto the sensors' (`identify`'s preprocessing, with a note).
//! Latencies a receiver can have are [`super::units::gnss_latency`]'s to time and name.
use super::units::GNSS_LATENCY_WIDE_SEARCH_S;

/// Spacing of the speeds compared, s.
pub const STEP_S: f64 = 0.1;
/// The track's speed is its chord over twice this, and the wheel speed's mean over as long, s:
/// a standard receiver's metre of noise is a tenth of a m/s over 2 s of 100 Hz fixes averaged
/// over [`AVERAGE_HALF_S`].
const CHORD_HALF_S: f64 = 1.0;
/// Each end of a chord is the mean of the fixes within this of it (the nearest two's straight
/// line when there is none), s.
const AVERAGE_HALF_S: f64 = 0.25;
/// Lags searched each way, s: two minutes, far beyond the 18 s of GPS time against UTC.
pub const SEARCH_S: f64 = 120.0;
/// A lag is compared over this much overlap at least, s, ...
const MIN_OVERLAP_S: f64 = 20.0;
/// ... and this share of the track's samples: a short overlap can match by chance.
const MIN_OVERLAP_SHARE: f64 = 0.5;
/// The speeds must correlate this well at the lag found: the simulator's drives on time, a
/// circle at 2.5 m/s with a standard receiver included, do at 0.90 to 1.00.
const MIN_CORRELATION: f64 = 0.9;
/// The lag found is determined when the share of the track's speed the wheel speed leaves
/// unexplained (`1 - rho^2`) is this many times smaller there than at lag 0 and at every lag
/// outside the lobe around it (no other lag matches nearly as well: a drive whose speed
/// repeats itself is not timed).
const LOBE_FACTOR: f64 = 4.0;
/// ... with the unexplained share counted as this at least (a noise-free match's is 0).
const MIN_UNEXPLAINED: f64 = 1e-4;

/// The fixes' clock's offset from the wheel speed's found in a log.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClockOffset {
    /// How far behind the wheel speed the fixes are stamped, s (negative: ahead).
    pub behind_s: f64,
    /// The speeds' correlation at that lag.
    pub correlation: f64,
    /// The best correlation within the latency search's reach
    /// ([`GNSS_LATENCY_WIDE_SEARCH_S`]), lag 0 among it.
    pub correlation_near: f64,
}

impl ClockOffset {
    /// The note for log `name`, whose fixes were moved by it.
    pub fn note(&self, name: &str) -> String {
        let (side, moved, fix) = if self.behind_s > 0.0 {
            ("behind", "earlier", "subtract it from")
        } else {
            ("ahead of", "later", "add it to")
        };
        let s = self.behind_s.abs();
        format!(
            "{name}: the GNSS fixes run {s:.2} s {side} the other sensors (the lag at which \
             the speed along the track matches `vel`, correlation {:.3} there and {:.3} at \
             most within {GNSS_LATENCY_WIDE_SEARCH_S} s of 0): far beyond a receiver's \
             latency: another clock (a receiver's GPS time beside a logger's UTC is 18 s off, \
             as of 2017); the fixes' times are moved {s:.2} s {moved} for identify (the node \
             stamps frames as they arrive, so its fixes are not off); fix the recorder's \
             clock, or {fix} the fixes' `t`",
            self.correlation, self.correlation_near
        )
    }
}

/// Prefix sums of `v` (one more than `v`).
fn prefix(v: impl Iterator<Item = f64>) -> Vec<f64> {
    let mut out = vec![0.0];
    let mut sum = 0.0;
    for x in v {
        sum += x;
        out.push(sum);
    }
    out
}

/// `y` at `at` by the straight line between the samples of `t` around it (the ends held).
fn interpolate(t: &[f64], y: &[f64], at: f64) -> f64 {
    let k = t.partition_point(|x| *x < at);
    match (k.checked_sub(1), t.get(k)) {
        (Some(i), Some(&t1)) if t1 > t[i] => y[i] + (at - t[i]) / (t1 - t[i]) * (y[k] - y[i]),
        (Some(i), _) => y[i],
        (None, _) => y.first().copied().unwrap_or(0.0),
    }
}

/// The mean of `y` (prefix sums `sums`) over the samples of `t` within `half` of `at`, or the
/// straight line's value there when there is none.
fn mean_near(t: &[f64], y: &[f64], sums: &[f64], at: f64, half: f64) -> f64 {
    let lo = t.partition_point(|x| *x < at - half);
    let hi = t.partition_point(|x| *x <= at + half);
    if hi > lo {
        (sums[hi] - sums[lo]) / (hi - lo) as f64
    } else {
        interpolate(t, y, at)
    }
}

/// Logs whose sensors span longer than this are not timed, s: 4 hours, half a second of
/// matching (the log's pauses are refused after the fixes are cleaned, so a span here may be
/// anything the reader takes).
const MAX_SPAN_S: f64 = 4.0 * 3600.0;

/// Times every [`STEP_S`] from `from` to `to` s, on whole steps from `origin` (the track's and
/// the wheel's grids share it, so that a lag is a whole number of steps); none over
/// [`MAX_SPAN_S`].
fn grid(origin: f64, from: f64, to: f64) -> Vec<f64> {
    let first = ((from - origin) / STEP_S).ceil();
    let last = ((to - origin) / STEP_S).floor();
    if !(first.is_finite() && last.is_finite() && last > first)
        || (last - first) * STEP_S > MAX_SPAN_S
    {
        return Vec::new();
    }
    (first as i64..=last as i64)
        .map(|k| origin + k as f64 * STEP_S)
        .collect()
}

/// The speed along the track of the fixes `tg`, `xy` (metres), every [`STEP_S`]: (first time,
/// speeds).
fn track_speed(origin: f64, tg: &[f64], xy: &[[f64; 2]]) -> (f64, Vec<f64>) {
    let (Some(&first), Some(&last)) = (tg.first(), tg.last()) else {
        return (0.0, Vec::new());
    };
    let reach = CHORD_HALF_S + AVERAGE_HALF_S;
    let times = grid(origin, first + reach, last - reach);
    let east: Vec<f64> = xy.iter().map(|p| p[0]).collect();
    let north: Vec<f64> = xy.iter().map(|p| p[1]).collect();
    let (se, sn) = (prefix(east.iter().copied()), prefix(north.iter().copied()));
    let at = |x: f64| {
        (
            mean_near(tg, &east, &se, x, AVERAGE_HALF_S),
            mean_near(tg, &north, &sn, x, AVERAGE_HALF_S),
        )
    };
    let speeds = times
        .iter()
        .map(|&x| {
            let (a, b) = (at(x - CHORD_HALF_S), at(x + CHORD_HALF_S));
            (b.0 - a.0).hypot(b.1 - a.1) / (2.0 * CHORD_HALF_S)
        })
        .collect();
    (times.first().copied().unwrap_or(0.0), speeds)
}

/// The wheel speed `(tv, vel)` averaged as the track's chord, every [`STEP_S`]: (first time,
/// speeds).
fn wheel_speed(origin: f64, tv: &[f64], vel: &[f64]) -> (f64, Vec<f64>) {
    let (Some(&first), Some(&last)) = (tv.first(), tv.last()) else {
        return (0.0, Vec::new());
    };
    let times = grid(origin, first + CHORD_HALF_S, last - CHORD_HALF_S);
    let sums = prefix(vel.iter().map(|v| v.abs()));
    let abs: Vec<f64> = vel.iter().map(|v| v.abs()).collect();
    let speeds = times
        .iter()
        .map(|&x| mean_near(tv, &abs, &sums, x, CHORD_HALF_S))
        .collect();
    (times.first().copied().unwrap_or(0.0), speeds)
}

/// The correlation of the track's speeds `track` (from `t0`) with the wheel's `wheel` (from
/// `w0`) `lag` samples of [`STEP_S`] earlier, over their overlap, when it is long enough
/// ([`MIN_OVERLAP_S`], [`MIN_OVERLAP_SHARE`]) and neither is constant there.
fn correlation_at(track: (f64, &[f64]), wheel: (f64, &[f64]), lag: isize) -> Option<f64> {
    let (t0, a) = track;
    let (w0, b) = wheel;
    // Track sample i at t0 + i STEP_S meets wheel sample j at t0 + i STEP_S - lag STEP_S.
    let offset = ((t0 - w0) / STEP_S).round() as isize - lag;
    let (mut n, mut sa, mut sb, mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for (i, &x) in a.iter().enumerate() {
        let j = i as isize + offset;
        let Some(&y) = usize::try_from(j).ok().and_then(|j| b.get(j)) else {
            continue;
        };
        n += 1.0;
        sa += x;
        sb += y;
        sab += x * y;
        saa += x * x;
        sbb += y * y;
    }
    if n * STEP_S < MIN_OVERLAP_S || n < MIN_OVERLAP_SHARE * a.len() as f64 {
        return None;
    }
    let cov = sab - sa * sb / n;
    let (va, vb) = (saa - sa * sa / n, sbb - sb * sb / n);
    let rho = cov / (va * vb).sqrt();
    (va > 1e-9 && vb > 1e-9 && rho.is_finite()).then_some(rho)
}

/// The offset of the fixes' clock (`tg`, their positions `xy` in metres) from the wheel
/// speed's (`tv`, `vel`), when the speeds determine one beyond the latency search's reach
/// ([`GNSS_LATENCY_WIDE_SEARCH_S`]): the lag within [`SEARCH_S`] at which the track's speed
/// correlates best with the wheel speed, [`MIN_CORRELATION`] at least, its unexplained share
/// [`LOBE_FACTOR`] times smaller than at lag 0 and at any lag outside its lobe; refined
/// between the samples by a parabola. `None` otherwise (the clocks agree, or the drive does
/// not tell).
pub fn clock_offset(
    tg: &[f64],
    xy: &[[f64; 2]],
    (tv, vel): (&[f64], &[f64]),
) -> Option<ClockOffset> {
    let origin = tg.first().copied().unwrap_or(0.0);
    let (t0, track) = track_speed(origin, tg, xy);
    let (w0, wheel) = wheel_speed(origin, tv, vel);
    if track.is_empty() || wheel.is_empty() {
        return None;
    }
    let reach = (SEARCH_S / STEP_S).round() as isize;
    let rho: Vec<Option<f64>> = (-reach..=reach)
        .map(|lag| correlation_at((t0, &track), (w0, &wheel), lag))
        .collect();
    // The share of the track's speed the wheel speed leaves unexplained; all of it where the
    // two go opposite ways.
    let unexplained: Vec<Option<f64>> = rho
        .iter()
        .map(|r| r.map(|r| if r > 0.0 { 1.0 - r * r } else { 1.0 }))
        .collect();
    let (k, least) = unexplained
        .iter()
        .enumerate()
        .filter_map(|(k, u)| u.map(|u| (k, u)))
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    let correlation = rho[k]?;
    let lag_s = (k as isize - reach) as f64 * STEP_S;
    if correlation < MIN_CORRELATION || lag_s.abs() <= GNSS_LATENCY_WIDE_SEARCH_S {
        return None;
    }
    // The lobe around the best lag; lag 0, or any lag outside it, as good: not determined.
    let bound = LOBE_FACTOR * least.max(MIN_UNEXPLAINED);
    let within = |j: usize| unexplained[j].is_some_and(|u| u < bound);
    let (mut lo, mut hi) = (k, k);
    while lo > 0 && within(lo - 1) {
        lo -= 1;
    }
    while hi + 1 < unexplained.len() && within(hi + 1) {
        hi += 1;
    }
    let zero = reach as usize;
    let elsewhere = (0..unexplained.len()).any(|j| !(lo..=hi).contains(&j) && within(j));
    if (lo..=hi).contains(&zero) || elsewhere {
        return None;
    }
    let neighbour = |j: Option<usize>| j.and_then(|j| unexplained.get(j).copied().flatten());
    let shift = match (neighbour(k.checked_sub(1)), neighbour(Some(k + 1))) {
        (Some(before), Some(after)) if before - 2.0 * least + after > 0.0 => {
            (0.5 * (before - after) / (before - 2.0 * least + after)).clamp(-0.5, 0.5)
        }
        _ => 0.0,
    };
    let near = (GNSS_LATENCY_WIDE_SEARCH_S / STEP_S).round() as usize;
    let correlation_near = rho[zero.saturating_sub(near)..=(zero + near).min(rho.len() - 1)]
        .iter()
        .flatten()
        .fold(-1.0, |a: f64, b| a.max(*b));
    Some(ClockOffset {
        behind_s: lag_s + shift * STEP_S,
        correlation,
        correlation_near,
    })
}
