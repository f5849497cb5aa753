//! The GNSS part of stages 1 and 3: fixes into the local frame, through the plausibility gate
//! and into the lowpass ([`super::estimator`]), gaps refilled by dead reckoning; then the
//! heading (receiver COG, else the filtered track's course) and the rear-axle position.
//! Bounded per tick ([`super::stage`]): the fixes, the filled fixes and the restarts after a
//! long gap each have a per-tick cap.
use crate::can::freshness::Input;
use crate::geodesy::{Enu, GeodesyError, LocalFrame};
use crate::math;
use crate::model::kinematic::Pose;

use super::estimator::{
    CogCorrection, EstimatorConfig, EstimatorState, Rates, TrackCorrection, Xy,
};
use super::inputs::{GnssCourse, GnssFix, Inputs};
use super::stage::{Stage, StageProbe, GAP_FILL_PER_TICK, GNSS_FIXES_PER_TICK};
use super::{bump, NodeConfig};

/// Consecutive fix intervals off the model file's period (at least 1.5 periods, or under
/// half a period) after which the receiver is taken to run at another rate than the model
/// file declares (`gnss_rate_hz`); as many intervals on the period end it. A receiver at the
/// declared rate that loses fixes at random makes such a run once in `1 / p^20` fixes at a loss
/// rate `p` (`p` = 0.5: once in 10^6).
pub const RATE_MISMATCH_FIXES: u16 = 20;

/// Declared periods over which the fixes that arrive are counted, used or over a tick's cap
/// ([`GNSS_FIXES_PER_TICK`]): a receiver faster than declared whose intervals scatter about
/// half a period (200 Hz on a 100 Hz file: 4 and 6 ms) never makes [`RATE_MISMATCH_FIXES`]
/// short intervals in a row, and one at twice the rate makes none (50 ms on a 10 Hz file is
/// not under half of 100 ms); the fixes over a tick's cap never reach the intervals at all
/// (the eighth black-box probe: 230-240 Hz counted as gate rejects, the rate never named).
pub const RATE_WINDOW_PERIODS: u32 = 20;
/// A window of [`RATE_WINDOW_PERIODS`] with at least this many tenths of its periods in fixes
/// is crowded, and two in a row say the receiver runs at least 1.4 times faster than
/// declared. A receiver at the declared rate brings one fix more or less per window with its
/// jitter; a gateway that holds its fixes back and hands them over at once moves them from
/// one window into the next, which a single window would count as crowded (a tenth of a
/// second's fixes: 30 of 20), never into two windows in a row.
pub const CROWDED_TENTHS: u32 = 14;
/// A window with at most this many tenths of its periods in fixes ends a crowded receiver.
pub const UNCROWDED_TENTHS: u32 = 12;

/// The plausibility gate learns the receiver: it tracks the median distance of the fixes from
/// where dead reckoning put the antenna at their time, and rejects a fix beyond this many
/// times that median (the model file's `gnss_gate_m` stays the most the gate allows). For
/// fixes scattered as a 2-D Gaussian of sigma per axis the median distance is 1.1774 sigma,
/// so 5.1 medians are 6 sigma. A median, not a mean square: outliers as frequent as one fix
/// in seven move a mean square enough to let themselves through, and barely move a median. A
/// survey-grade receiver's fixes are centimetres from there, and a multipath fix metres off
/// passed the 10 m gate into the lowpass: on the closed-loop rig with RTK and 2 % of fixes off
/// by up to 6 m per axis, the loop at 10 m/s was 0.08-0.13 m RMS off the path instead of
/// 0.03, and the lane change at 12 m/s hit cones on three seeds of four (docs/findings.md).
pub const GATE_MEDIANS: f32 = 5.1;

/// The learnt gate is never tighter than this, m: the dead reckoning's drift over a fix
/// period at the grip limit, and a survey-grade receiver's own jumps (RTK float), pass.
pub const GATE_FLOOR_M: f32 = 1.0;

/// The learnt gate widens by about this much per second since the last accepted fix, m/s:
/// the dead reckoning bridging a gap drifts.
pub const GATE_GAP_MPS: f32 = 1.0;

/// The median's step per fix, as a share of it: up when a fix is farther, down when nearer
/// (a stochastic approximation of the median, in its logarithm). From the configured gate
/// it comes down to a survey-grade receiver's in about 200 fixes (2 s at 100 Hz).
pub const GATE_MEDIAN_STEP: f32 = 0.03;

/// Whether the receiver's fixes come at the rate the estimator was designed for
/// ([`EstimatorConfig::design`] from the model file's `gnss_rate_hz`, never on the MCU). The
/// lowpass, the course chord and the gap filling all count in fixes of that period: a 10 Hz
/// receiver declared as 100 Hz makes every fix a gap of nine, filled by dead reckoning, and
/// the heading follows the dead reckoning instead of the track (measured on the closed-loop
/// rig: north for a car driving east, the position metres off). So fixes at another rate are not used: counted
/// (`Counters::gnss_rate_mismatch`), flagged (NODE_STATUS `gnss_rate_mismatch`), no position.
#[derive(Clone, Copy, Debug, Default)]
struct RateCheck {
    /// Receive time of the previous fix, us.
    last_us: Option<u64>,
    /// Consecutive intervals of at least 1.5 periods.
    slow_in_row: u16,
    /// Consecutive intervals under half a period.
    fast_in_row: u16,
    /// Consecutive intervals on the period (they end a mismatch).
    normal_in_row: u16,
    /// The intervals say the receiver runs at another rate than declared.
    off_intervals: bool,
    /// The latest interval off the period, us (0: none yet): the receiver's period when in
    /// mismatch (the mean interval of the last crowded window, when crowded).
    off_interval_us: u32,
    /// Where the window of [`RATE_WINDOW_PERIODS`] counted in started, us.
    window_start_us: Option<u64>,
    /// The fixes that arrived in it (a window of more than 65 535 fixes is crowded anyway).
    arrivals: u16,
    /// Windows crowded in a row ([`CROWDED_TENTHS`]), up to 2.
    crowded_windows: u8,
    /// Two windows in a row were crowded, and none since uncrowded.
    crowded: bool,
    /// The mismatch as the last used fix found it: a new one forgets the estimator once.
    reported: bool,
}

/// What one fix's interval changed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum RateChange {
    /// Nothing: use the fix if not in mismatch.
    None,
    /// The rate has just been found off the declared one.
    Began,
}

impl RateCheck {
    /// Whether the receiver runs at another rate than declared, by its intervals or its count.
    fn mismatch(&self) -> bool {
        self.off_intervals || self.crowded
    }

    /// A fix arrived at `t_us`, used or over a tick's cap: counted in the window of
    /// [`RATE_WINDOW_PERIODS`] of `period_us`, which the first fix at or past its end closes.
    /// Integer work only (a division when crowded, one instruction on the MCU).
    fn arrive(&mut self, t_us: u64, period_us: u32) {
        let start = *self.window_start_us.get_or_insert(t_us);
        // A window that lasts over 71 minutes (a receiver silent that long) is not judged.
        let elapsed = u32::try_from(t_us.saturating_sub(start)).unwrap_or(u32::MAX);
        if u64::from(elapsed) >= u64::from(period_us) * u64::from(RATE_WINDOW_PERIODS) {
            // `arrivals` fixes in `elapsed`: at least CROWDED_TENTHS / 10 of its periods?
            // (Under 2^16 times 2^32 times 10, over 2^32 times 14: no overflow.)
            let fixes_tenths = u64::from(self.arrivals) * u64::from(period_us) * 10;
            let elapsed_tenths = |tenths: u32| u64::from(elapsed) * u64::from(tenths);
            if elapsed < u32::MAX && fixes_tenths >= elapsed_tenths(CROWDED_TENTHS) {
                self.crowded_windows = self.crowded_windows.saturating_add(1).min(2);
                if self.crowded_windows >= 2 {
                    self.crowded = true;
                    self.off_interval_us = elapsed / u32::from(self.arrivals.max(1));
                }
            } else {
                self.crowded_windows = 0;
                if fixes_tenths <= elapsed_tenths(UNCROWDED_TENTHS) {
                    self.crowded = false;
                }
            }
            self.window_start_us = Some(t_us);
            self.arrivals = 0;
        }
        self.arrivals = self.arrivals.saturating_add(1);
    }

    /// The fix received at `t_us`, with the estimator designed for fixes `period_us` apart:
    /// [`RateChange::Began`] when the receiver has just been found at another rate, by its
    /// intervals or by its count ([`Self::arrive`]). Integer work only: it runs for every fix
    /// of the estimating tick.
    fn observe(&mut self, t_us: u64, period_us: u32) -> RateChange {
        self.arrive(t_us, period_us);
        self.observe_interval(t_us, period_us);
        let now = self.mismatch();
        let began = now && !self.reported;
        self.reported = now;
        if began {
            RateChange::Began
        } else {
            RateChange::None
        }
    }

    /// The interval from the last used fix to `t_us`: [`RATE_MISMATCH_FIXES`] in a row off
    /// the period set [`Self::off_intervals`], as many on it clear it.
    fn observe_interval(&mut self, t_us: u64, period_us: u32) {
        let Some(last) = self.last_us.replace(t_us) else {
            return;
        };
        let interval = u32::try_from(t_us.saturating_sub(last)).unwrap_or(u32::MAX);
        let slow = interval >= period_us.saturating_add(period_us / 2);
        let fast = interval < period_us / 2;
        if slow || fast {
            self.off_interval_us = interval;
        }
        let bump_if = |n: u16, yes: bool| if yes { n.saturating_add(1) } else { 0 };
        self.slow_in_row = bump_if(self.slow_in_row, slow);
        self.fast_in_row = bump_if(self.fast_in_row, fast);
        self.normal_in_row = bump_if(self.normal_in_row, !(slow || fast));
        if self.slow_in_row >= RATE_MISMATCH_FIXES || self.fast_in_row >= RATE_MISMATCH_FIXES {
            self.off_intervals = true;
        } else if self.normal_in_row >= RATE_MISMATCH_FIXES {
            self.off_intervals = false;
        }
    }
}

/// The receiver's period the estimator was designed for, us.
fn period_us(cfg: &EstimatorConfig) -> u32 {
    (cfg.gnss_period_s * 1e6) as u32
}

/// The GNSS fixes of one tick, in arrival order (at most [`GNSS_FIXES_PER_TICK`]).
pub type TickFixes = heapless::Vec<GnssFix, GNSS_FIXES_PER_TICK>;

/// The times the tick's fixes are taken at: fixes that reached the node together (less than
/// half a period apart: a recorder or an adapter that stamps a batch of frames with one time,
/// a simulator that sends two fixes per 20 ms at one instant) get the receiver's spacing, the
/// latest keeping its receive time and each earlier one a period before the next, as they were
/// measured; fixes further apart keep theirs. Taken at their receive times, two fixes at one
/// instant every 20 ms from a 100 Hz receiver read as a fix, a 20 ms gap filled by dead
/// reckoning and the same fix again: three samples where the lowpass expects two, and a course
/// over its span of fixes too short to give the heading, so the node never had a position
/// (docs/findings.md). The rate check still judges the receive times ([`RateCheck`]): a
/// receiver faster than declared is found by its intervals and its count as before.
fn spaced_times(fixes: &TickFixes, period_us: u32) -> [u64; GNSS_FIXES_PER_TICK] {
    let mut taken = [0u64; GNSS_FIXES_PER_TICK];
    let half_us = u64::from(period_us / 2);
    // (receive time, time taken) of the fix after this one.
    let mut next: Option<(u64, u64)> = None;
    for (fix, taken_us) in fixes.iter().zip(taken.iter_mut()).rev() {
        let received = fix.t_us;
        *taken_us = match next {
            Some((next_received, next_taken))
                if next_received.saturating_sub(received) < half_us =>
            {
                received.min(next_taken.saturating_sub(u64::from(period_us)))
            }
            _ => received,
        };
        next = Some((received, *taken_us));
    }
    taken
}

/// What one tick may still spend: one local frame built (at the first fix, or moved), and on
/// gaps filling missing fixes one by one, or one restart on the dead-reckoned track, not both ([`super::stage::Exclusive::GnssGap`]: the tick's bound
/// counts the dearer of the two, not their sum).
struct GapBudget {
    /// Whether it may still build a local frame ([`Stage::GnssOrigin`]: once per tick).
    frame_left: bool,
    /// Missing fixes it may still fill one by one.
    fills_left: u32,
    /// Whether it may still restart the filters on the dead-reckoned track.
    restart_left: bool,
}

/// GNSS state.
#[derive(Clone, Debug, Default)]
pub struct Gnss {
    /// The local frame, from the configured origin or the first fix.
    frame: Option<LocalFrame>,
    /// Whether the frame is the node's own (built at its first fix, no origin configured or
    /// received): the node may move it ([`LocalFrame`]'s validity radius).
    frame_own: bool,
    /// The node moved its own frame since [`Self::take_frame_moved`] last looked.
    frame_moved: bool,
    /// Fixes that lay beyond the local frame's validity radius (among the gate's rejections).
    beyond_frame: u32,
    estimator: EstimatorState,
    /// The receiver's course (rad) and its receive time, while the car moves.
    cog: Option<(f32, u64)>,
    /// Courses in a row within [`COG_AGREE_RAD`] of the one before ([`COG_AGREEING`]), as the
    /// ticks see them (the latest of each tick: judged once a tick, not in the frame stage),
    /// and the last one seen.
    cog_agreeing: u8,
    cog_seen: Option<(f32, u64)>,
    /// Courses seen before there was a heading ([`COG_AWAITED`]).
    cogs_before_heading: u8,
    /// Consecutive fixes the gate rejected.
    rejects_in_row: u16,
    /// When the gate last rejected a fix.
    last_reject_us: Option<u64>,
    /// The receiver's rate against the model file's.
    rate: RateCheck,
    /// The learnt gate ([`GATE_MEDIANS`]).
    gate: GateStats,
    /// The step gate ([`StepGate`]).
    step: StepGate,
}

/// The learnt gate's state ([`GATE_MEDIANS`]).
#[derive(Clone, Copy, Debug, Default)]
struct GateStats {
    /// The median distance of the fixes from where the antenna should have been, m; `None`
    /// until a fix was compared (then it starts at the configured gate's).
    median_m: Option<f32>,
    /// When the last fix was accepted, us.
    last_accept_us: Option<u64>,
}

impl GateStats {
    /// The gate's square for a fix received at `t_us`, m^2: [`GATE_MEDIANS`] times the median,
    /// at least [`GATE_FLOOR_M`], widened by `g` = [`GATE_GAP_MPS`] per second since the last
    /// accepted fix as `base^2 + 2 floor g + g^2` (at most `(base + g)^2`, at least
    /// `base^2 + g^2`: no square root per fix on the MCU), at most the configured gate's.
    fn gate_m2(&self, configured_m: f32, t_us: u64) -> f32 {
        let configured_m2 = configured_m * configured_m;
        let Some(median) = self.median_m else {
            return configured_m2;
        };
        let gap_s = self
            .last_accept_us
            .map_or(0.0, |a| math::u64_to_f32(t_us.saturating_sub(a)) * 1e-6);
        let g = GATE_GAP_MPS * gap_s;
        let base = math::max(GATE_MEDIANS * median, GATE_FLOOR_M);
        let learnt_m2 = base * base + 2.0 * GATE_FLOOR_M * g + g * g;
        if learnt_m2.is_finite() {
            math::min(learnt_m2, configured_m2)
        } else {
            configured_m2
        }
    }

    /// A fix `d2_m2` (squared) from where the antenna should have been: the median steps
    /// towards it, whether the fix is accepted or not (rejected fixes are above the median).
    fn observe(&mut self, d2_m2: f32, configured_m: f32) {
        // Within the gate's range: never above the configured gate's, never below the floor's
        // (below it the gate does not tighten, and a lasting step would have further to
        // climb: from the floor's median a 2.5 m step opens the gate in about 30 fixes).
        self.median_m = Some(median_step(
            self.median_m.unwrap_or(configured_m / GATE_MEDIANS),
            d2_m2,
            GATE_FLOOR_M / GATE_MEDIANS,
            math::max(configured_m, GATE_FLOOR_M) / GATE_MEDIANS,
        ));
    }
}

/// One step of a learnt median ([`GATE_MEDIAN_STEP`]) towards a sample `d2_m2` (squared),
/// kept within `[lo_m, hi_m]`.
fn median_step(median_m: f32, d2_m2: f32, lo_m: f32, hi_m: f32) -> f32 {
    math::median_step(median_m, d2_m2, GATE_MEDIAN_STEP, lo_m, hi_m)
}

/// The step gate: a fix's step from the last accepted fix, against the dead reckoning's
/// displacement between the two fixes' instants, across the heading. The plausibility gate
/// ([`GATE_MEDIANS`]) compares a fix with the filtered track carried forward, whose error in a
/// manoeuvre at the grip limit is decimetres, so its floor is a metre, and a multipath glitch
/// under a metre passed into the lowpass: the sixth black-box probe's two fixes 1 m to the
/// side at 20 Hz turned the heading and took the car out of its corridor (docs/findings.md).
/// Between two fixes the dead reckoning drifts by far less (its heading's error, the turn it
/// may have misjudged and [`STEP_SLIDE_PER_M`] for the slide, times the distance driven),
/// and the receiver's own scatter from fix to fix is learnt as a median, so a step across the
/// heading beyond both is a glitch. Along the heading a fix's latency jitter and the wheel
/// speed's scale move it, and the lateral control does not feel it, so only the side is
/// judged. A step that lasts is the receiver's new level (an RTK solution changing from
/// fixed to float): after [`STEP_PERSIST_S`] of rejections the fix is taken, before the
/// receiver would count as stale.
#[derive(Clone, Copy, Debug, Default)]
struct StepGate {
    /// The last accepted fix (`None` after the filters restarted: no reference).
    last: Option<StepRef>,
    /// The learnt median of the step's error across the heading, m (`None`: the configured
    /// gate's, as for [`GateStats`]).
    median_m: Option<f32>,
    /// Fixes the step gate rejected in a row.
    rejects_in_row: u16,
    /// What this tick allows per metre driven, and per metre squared (the turn), and after
    /// how many rejections a step is the receiver's: set once a tick by [`Gnss::propagate`]
    /// (the heading and its variance move only between ticks' fixes), so that each fix pays
    /// for the comparison alone.
    per_m: f32,
    per_m2: f32,
    persist: u16,
}

/// An accepted fix, as the step gate remembers it.
#[derive(Clone, Copy, Debug)]
struct StepRef {
    /// The fix, local m.
    fix: Xy,
    /// Where dead reckoning had the antenna at the fix's instant.
    odo: Xy,
}

/// The step gate rejects a step across the heading beyond this many of its learnt medians
/// ([`StepGate`]): the median of |x| for a Gaussian x of sigma is 0.6745 sigma, so 6 sigma.
pub const STEP_MEDIANS: f32 = 8.9;

/// The step gate never rejects a step across the heading under this, m: a fix's quantum on
/// the bus is 0.011 m (1e-7 degree), and a gateway's jitter in a turn moves a fix sideways by
/// centimetres.
pub const STEP_FLOOR_M: f32 = 0.15;

/// The dead reckoning's sideways slide the step gate allows per metre driven between two
/// fixes: the rear axle's slide the single-track model misjudges at the grip limit (0.5 m/s
/// at 10 m/s).
pub const STEP_SLIDE_PER_M: f32 = 0.05;

/// The heading's error the step gate allows, in standard deviations of the heading filter's
/// own variance, times the distance driven between the fixes.
pub const STEP_HEADING_SIGMAS: f32 = 3.0;

/// The share of the turn between two fixes the step gate allows the dead reckoning to have
/// misjudged, times the distance driven (an arc of curvature k over d metres lies k d^2 / 2
/// to the side of its chord: the whole of that sideways motion, misjudged; k is the tick's
/// yaw rate over the speed).
pub const STEP_TURN_SHARE: f32 = 0.5;

/// A step that lasts this long is the receiver's, s ([`StepGate`]): its fix this many periods,
/// rounded, after the last accepted one is taken; at least two fixes. Under the GNSS timeout
/// at every rate (0.2 s at least, 2.5 periods).
pub const STEP_PERSIST_S: f32 = 0.15;

/// Before the node has a heading, a course sets it only when this many courses in a row each
/// agreed with the one before within [`COG_AGREE_RAD`]: a course from the carrier's Doppler
/// does at once, one differenced from noisy fixes at walking pace never
/// ([`super::estimator::CogCorrection::NoHeading`]); else the filtered track sets it, once
/// [`COG_AWAITED`] courses have come without agreeing.
pub const COG_AGREEING: u8 = 3;
/// Courses a receiver that sends them is given to agree ([`COG_AGREEING`]) before the
/// filtered track's chord may set the first heading instead. A chord only just long enough at
/// a crawl is mostly the fixes' noise: a random SIL sweep's truck at 1.7 m/s, with exact
/// courses and a 5 Hz receiver of 0.3 m noise, took its first heading 0.61 rad off from a
/// chord one course before its courses had agreed, and then judged its exact courses
/// scattered against that heading (docs/findings.md, "A heading settled by time alone").
pub const COG_AWAITED: u8 = 2 * COG_AGREEING;
/// See [`COG_AGREEING`], rad.
pub const COG_AGREE_RAD: f32 = 0.05;

/// The step gate's verdict on a fix.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum StepVerdict {
    /// Use the fix.
    Accept,
    /// A glitch: reject the fix.
    Reject,
}

impl StepGate {
    /// What the tick allows ([`Self::per_m`]): the heading's variance, the car's speed and
    /// yaw rate this tick.
    fn set_tick(
        &mut self,
        cfg: &EstimatorConfig,
        heading_var_rad2: f32,
        speed_mps: f32,
        yaw_rps: f32,
    ) {
        self.per_m = STEP_SLIDE_PER_M + STEP_HEADING_SIGMAS * math::sqrt(heading_var_rad2);
        let curvature = yaw_rps.abs() / math::max(speed_mps.abs(), cfg.course_min_speed_mps);
        self.per_m2 = STEP_TURN_SHARE * 0.5 * curvature;
        if self.persist == 0 {
            self.persist = math::max(STEP_PERSIST_S / cfg.gnss_period_s + 0.5, 2.0) as u16;
        }
    }

    /// The fix `fix`, taken when dead reckoning had the antenna at `odo`, with the heading's
    /// sine and cosine `(s, c)`.
    fn check(&mut self, configured_m: f32, fix: Xy, odo: Xy, (s, c): (f32, f32)) -> StepVerdict {
        let Some(last) = self.last else {
            return StepVerdict::Accept;
        };
        let (dx, dy) = (odo.x_m - last.odo.x_m, odo.y_m - last.odo.y_m);
        let (ex, ey) = (fix.x_m - last.fix.x_m - dx, fix.y_m - last.fix.y_m - dy);
        // Right of the heading is (cos, -sin) (headings clockwise from north).
        let across = ex * c - ey * s;
        let d = math::sqrt(dx * dx + dy * dy);
        let allowed = STEP_FLOOR_M + d * (self.per_m + d * self.per_m2);
        let median = self.median_m.unwrap_or(configured_m * (1.0 / STEP_MEDIANS));
        let limit = math::max(STEP_MEDIANS * median, allowed);
        self.median_m = Some(median_step(
            median,
            across * across,
            STEP_FLOOR_M / STEP_MEDIANS,
            math::max(configured_m, STEP_FLOOR_M) * (1.0 / STEP_MEDIANS),
        ));
        // `!(a <= b)`: a NaN step is rejected.
        #[allow(clippy::neg_cmp_op_on_partial_ord)]
        let beyond = !(across.abs() <= limit);
        if beyond && self.rejects_in_row.saturating_add(1) < self.persist {
            self.rejects_in_row = self.rejects_in_row.saturating_add(1);
            return StepVerdict::Reject;
        }
        self.rejects_in_row = 0;
        StepVerdict::Accept
    }
}

/// A course (rad) as the heading it measures: turned half round when the car reverses (the
/// antenna moves backwards).
#[inline(always)]
fn along_heading(course_rad: f32, reversing: bool) -> f32 {
    if reversing {
        math::wrap_pi(course_rad + core::f32::consts::PI)
    } else {
        course_rad
    }
}

impl Gnss {
    /// The local frame's origin once known (lat, lon in 1e-7 deg).
    pub fn origin_e7(&self) -> Option<(i32, i32)> {
        self.frame.map(|f| (f.origin_lat_e7(), f.origin_lon_e7()))
    }

    /// The planner's map origin (LOCAL_ORIGIN, 1e-7 deg) becomes the local frame. If it differs
    /// from the frame in use, the filters restart in the new frame (the heading survives: it
    /// is the car's); returns whether the frame changed. A frame not set yet is simply set.
    /// An origin the local frame cannot take ([`LocalFrame::new`]: beyond 80 degrees of
    /// latitude, where the DBC allows 90) is refused: `Err`, the frame in use stays.
    pub fn set_origin(&mut self, (lat_e7, lon_e7): (i32, i32)) -> Result<bool, GeodesyError> {
        if self.origin_e7() == Some((lat_e7, lon_e7)) {
            return Ok(false);
        }
        let frame = LocalFrame::new(lat_e7, lon_e7)?;
        let changed = self.frame.is_some();
        self.frame = Some(frame);
        self.frame_own = false;
        if changed {
            self.estimator.reset();
            self.rejects_in_row = 0;
        }
        Ok(changed)
    }

    /// Whether the node moved its own frame to a fix beyond the old one's validity radius
    /// since the last call (the planner's path in the old frame no longer holds); clears it.
    pub fn take_frame_moved(&mut self) -> bool {
        core::mem::take(&mut self.frame_moved)
    }

    /// Fixes that lay beyond the local frame's validity radius so far (counted among the
    /// gate's rejections on the bus): the origin is too far from the drive.
    pub fn fixes_beyond_frame(&self) -> u32 {
        self.beyond_frame
    }

    /// The antenna's dead-reckoned position ([`EstimatorState::dead_reckoned`]).
    pub fn dead_reckoned(&self) -> Xy {
        self.estimator.dead_reckoned()
    }

    /// The heading's error variance, rad^2 ([`EstimatorState::heading_var_rad2`]).
    pub fn heading_var_rad2(&self) -> f32 {
        self.estimator.heading_var_rad2()
    }

    /// The track ran against the heading ([`EstimatorState::direction_ambiguous`]).
    pub fn direction_ambiguous(&self) -> bool {
        self.estimator.direction_ambiguous()
    }

    /// When a fix was last rejected.
    pub fn last_reject_us(&self) -> Option<u64> {
        self.last_reject_us
    }

    /// Whether the receiver's fixes come at another rate than the model file declares
    /// ([`RATE_MISMATCH_FIXES`]): they are not used.
    pub fn rate_mismatch(&self) -> bool {
        self.rate.mismatch()
    }

    /// The latest interval between the receiver's fixes that was off the declared period, us
    /// (`None` while there has been none): the receiver's period when [`Self::rate_mismatch`].
    pub fn off_rate_interval_us(&self) -> Option<u32> {
        (self.rate.off_interval_us > 0).then_some(self.rate.off_interval_us)
    }

    /// Dead reckoning over `dt_s` (see [`EstimatorState::propagate`]).
    pub fn propagate(&mut self, cfg: &EstimatorConfig, speed_mps: f32, rates: Rates, dt_s: f32) {
        self.estimator.propagate(cfg, speed_mps, rates, dt_s);
        self.step.set_tick(
            cfg,
            self.estimator.heading_var_rad2(),
            speed_mps,
            rates.yaw_rps,
        );
    }

    /// The heading's error bound grown by a yaw rate the dead reckoning did not see
    /// ([`EstimatorState::turn_unseen`]).
    pub fn turn_unseen(&mut self, unseen_yaw_rps: f32, dt_s: f32) {
        self.estimator.turn_unseen(unseen_yaw_rps, dt_s);
    }

    /// A course from the receiver (PGN 129026): kept, with its receive time, while the car
    /// moves (COG is meaningless when standing still); only true north is understood.
    pub fn receive_course(&mut self, config: &NodeConfig, course: &GnssCourse) {
        if course.sog_mps >= config.estimator.course_min_speed_mps && course.reference == 0 {
            self.cog = Some((math::wrap_pi(course.cog_rad), course.t_us));
        }
    }

    /// A fix received at `t_us` over the tick's cap ([`GNSS_FIXES_PER_TICK`]) was rejected
    /// (counted by the caller): it still counts in the receiver's rate ([`RateCheck::arrive`]).
    pub fn over_cap(&mut self, config: &NodeConfig, t_us: u64) {
        self.last_reject_us = Some(t_us);
        self.rate.arrive(t_us, period_us(&config.estimator));
    }

    /// The tick's fixes (received before `now_us`, in arrival order), with the car at
    /// `speed_mps`: each into the local frame, through the gate and into the lowpass, gaps
    /// before them filled. Bounded work ([`super::stage`]): at most [`GNSS_FIXES_PER_TICK`]
    /// fixes, [`GAP_FILL_PER_TICK`] filled fixes and one restart on the track per tick.
    pub fn receive_fixes<P: StageProbe>(
        &mut self,
        config: &NodeConfig,
        now_us: u64,
        fixes: &TickFixes,
        speed_mps: f32,
        inputs: &mut Inputs,
        probe: &mut P,
    ) {
        let taken_us = spaced_times(fixes, period_us(&config.estimator));
        let mut gaps = GapBudget {
            frame_left: self.frame.is_some(),
            fills_left: GAP_FILL_PER_TICK,
            restart_left: true,
        };
        for (fix, taken_us) in fixes.iter().zip(taken_us) {
            let timed = (fix, taken_us);
            self.receive_fix(config, now_us, timed, speed_mps, inputs, &mut gaps, probe);
        }
    }

    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn receive_fix<P: StageProbe>(
        &mut self,
        config: &NodeConfig,
        now_us: u64,
        (fix, t_us): (&GnssFix, u64),
        speed_mps: f32,
        inputs: &mut Inputs,
        gaps: &mut GapBudget,
        probe: &mut P,
    ) {
        let GnssFix {
            t_us: received_us,
            lat_e7,
            lon_e7,
        } = *fix;
        let counters = &mut inputs.counters;
        let cfg = &config.estimator;
        if self.rate.observe(received_us, period_us(cfg)) == RateChange::Began {
            self.estimator.forget();
            self.cog = None;
        }
        if self.rate.mismatch() {
            bump(&mut counters.gnss_rate_mismatch);
            probe.lap(Stage::GnssFixCheck);
            return;
        }
        if self.frame.is_none() {
            let origin = config.origin_e7.unwrap_or((lat_e7, lon_e7));
            // Built once, at the configured origin or the first fix; after that only a
            // LOCAL_ORIGIN or the car leaving the node's own frame (below) moves it. A refused
            // origin is refused by cheap range checks before any of the set-up.
            if let Ok(frame) = LocalFrame::new(origin.0, origin.1) {
                self.frame = Some(frame);
                self.frame_own = config.origin_e7.is_none();
                probe.lap(Stage::GnssOrigin);
            }
        }
        let (enu, moved) = match self.frame.map(|fr| fr.to_local(lat_e7, lon_e7)) {
            Some(Ok(enu)) => (enu, false),
            Some(Err(GeodesyError::BeyondValidityRadius)) if self.frame_own => {
                self.beyond_frame = self.beyond_frame.saturating_add(1);
                // The car has left the frame the node chose at its first fix (its expansion
                // holds within `VALIDITY_RADIUS_M`): fixes beyond it are rejected as the gate
                // rejects them, and once enough of them in a row say the car is there (not one
                // wild fix), the frame moves to this fix and the filters restart in it, as for
                // a LOCAL_ORIGIN. A planner's frame is the planner's to move.
                self.rejects_in_row = self.rejects_in_row.saturating_add(1);
                bump(&mut counters.gnss_gate_rejects);
                self.last_reject_us = Some(t_us);
                let frame = (self.rejects_in_row >= config.gnss_reacquire_fixes && gaps.frame_left)
                    .then(|| LocalFrame::new(lat_e7, lon_e7).ok())
                    .flatten();
                let Some(frame) = frame else {
                    probe.lap(Stage::GnssFixCheck);
                    return;
                };
                gaps.frame_left = false;
                self.frame = Some(frame);
                self.frame_moved = true;
                self.estimator.reset();
                self.gate = GateStats::default();
                probe.lap(Stage::GnssOrigin);
                (Enu::default(), true)
            }
            other => {
                if let Some(Err(GeodesyError::BeyondValidityRadius)) = other {
                    self.beyond_frame = self.beyond_frame.saturating_add(1);
                }
                bump(&mut counters.gnss_gate_rejects);
                self.last_reject_us = Some(t_us);
                probe.lap(Stage::GnssFixCheck);
                return;
            }
        };
        let fix = Xy {
            x_m: enu.east_m,
            y_m: enu.north_m,
        };
        // Plausibility gate against where the car should have been at the fix's time, learnt
        // from the receiver's fixes ([`GATE_MEDIANS`]); repeated rejections mean the car
        // really is there (e.g. after a long gap): restart the filters on the fixes. A moved
        // frame has restarted them already.
        let age_s = math::u64_to_f32(now_us.saturating_sub(t_us)) * 1e-6;
        let mut antenna = if moved {
            None
        } else {
            self.estimator.antenna_position(cfg)
        };
        if let Some(p) = antenna {
            let then = self.estimator.dead_reckoned_back(p, age_s, speed_mps);
            let (dx, dy) = (fix.x_m - then.x_m, fix.y_m - then.y_m);
            let d2 = dx * dx + dy * dy;
            let gate_m2 = self.gate.gate_m2(config.gnss_gate_m, t_us);
            self.gate.observe(d2, config.gnss_gate_m);
            if d2.is_nan() || d2 > gate_m2 {
                self.rejects_in_row = self.rejects_in_row.saturating_add(1);
                bump(&mut counters.gnss_gate_rejects);
                self.last_reject_us = Some(t_us);
                if self.rejects_in_row < config.gnss_reacquire_fixes {
                    probe.lap(Stage::GnssFixCheck);
                    return;
                }
                self.estimator.reset();
                // The fixes won: the receiver's statistics are learnt again from them.
                self.gate = GateStats::default();
                antenna = None;
            }
        }
        // The step gate, while the filters run on fixes (after a restart there is no step).
        let odo =
            self.estimator
                .dead_reckoned_back(self.estimator.dead_reckoned(), age_s, speed_mps);
        let heading = self.estimator.heading_rad();
        if antenna.is_some() && heading.is_some() {
            let verdict = self.step.check(
                config.gnss_gate_m,
                fix,
                odo,
                self.estimator.heading_sin_cos(),
            );
            if verdict == StepVerdict::Reject {
                bump(&mut counters.gnss_gate_rejects);
                self.last_reject_us = Some(t_us);
                probe.lap(Stage::GnssFixCheck);
                return;
            }
        }
        self.step.last = heading.map(|_| StepRef { fix, odo });
        self.rejects_in_row = 0;
        self.gate.last_accept_us = Some(t_us);
        probe.lap(Stage::GnssFixCheck);
        // The lowpass assumes one fix per period. Fixes missing since the last accepted one
        // (a dropout, or fixes the gate rejected) are filled with where dead reckoning puts
        // the antenna at those instants, oldest first, up to the tick's budget; a longer gap
        // restarts the filters on that dead-reckoned track at once (what filling the filters'
        // whole memory would do). Without a position (filters not warm, or just restarted)
        // there is nothing to dead-reckon from.
        let prev = inputs.freshness.last_us(Input::Gnss);
        if let (Some(prev), Some(antenna)) = (prev, antenna) {
            let gap_periods =
                math::u64_to_f32(t_us.saturating_sub(prev)) * 1e-6 / cfg.gnss_period_s;
            let missing = ((gap_periods + 0.5) as u32).saturating_sub(1);
            if missing > 0 && missing <= gaps.fills_left {
                gaps.fills_left -= missing;
                gaps.restart_left = false;
                for k in (1..=missing).rev() {
                    let age_k = age_s + k as f32 * cfg.gnss_period_s;
                    let p = self.estimator.dead_reckoned_back(antenna, age_k, speed_mps);
                    self.estimator.add_fix(cfg, p, age_k, speed_mps);
                    probe.lap(Stage::GnssFill);
                }
            } else if missing > 0 && gaps.restart_left {
                gaps.restart_left = false;
                gaps.fills_left = 0;
                self.estimator
                    .restart_on_track(cfg, antenna, age_s, missing, speed_mps);
                probe.lap(Stage::GnssRestart);
            } else if missing > 0 {
                // A second gap within one tick that the tick can no longer fill or restart on
                // (only a backlog of fixes makes one: a fill and a restart exclude each other
                // in a tick, see GapBudget): this fix cannot be placed now; counted, and the
                // next one fills in after it.
                bump(&mut inputs.counters.gnss_gate_rejects);
                self.last_reject_us = Some(t_us);
                probe.lap(Stage::GnssFixFilter);
                return;
            }
        }
        self.estimator.add_fix_at(cfg, fix, odo);
        inputs.freshness.mark(Input::Gnss, t_us);
        probe.lap(Stage::GnssFixFilter);
    }

    /// Stage 3's GNSS part: the heading pulled towards the receiver's COG when it is fresh, else
    /// towards the filtered track's course, while the car moves; then the rear axle's position
    /// (`None` while invalid), whether GNSS is fresh, and the heading the course measured this
    /// tick (`None` when none was). A receiver silent for longer than `gnss_lost_us` restarts
    /// the filters.
    ///
    /// `speed_mps` is the speed along the heading: negative while the car reverses (SPEED_REPORT
    /// `direction`), when the receiver's course and the track's run half a turn from the
    /// heading and are turned round before they correct it (the chords compare the track with
    /// a dead reckoning that moved backwards too, and need no turn).
    pub fn estimate(
        &mut self,
        config: &NodeConfig,
        now_us: u64,
        speed_mps: f32,
        rates: Rates,
        inputs: &Inputs,
    ) -> (Option<Pose>, bool, Option<f32>) {
        let cfg = &config.estimator;
        let gnss_timeout_us = config.freshness.timeout_us(Input::Gnss);
        let moving = speed_mps.abs() >= cfg.course_min_speed_mps;
        let reversing = speed_mps < 0.0;
        // The receiver's course while it is fresh; the chords of the filtered track when there
        // is none, or its courses scatter too much to steer the heading.
        let from_cog = match self.cog {
            Some((cog, t)) if moving && now_us.saturating_sub(t) <= gnss_timeout_us => {
                let age_s = math::u64_to_f32(now_us.saturating_sub(t)) * 1e-6;
                Some(self.estimator.correct_heading_on_cog(
                    cfg,
                    along_heading(cog, reversing),
                    age_s,
                    speed_mps,
                    rates,
                ))
            }
            _ => None,
        };
        // Before there is a heading: do the courses agree with each other?
        if self.estimator.heading_rad().is_none() && self.cog != self.cog_seen {
            let agrees = match (self.cog, self.cog_seen) {
                (Some((now, _)), Some((before, _))) => {
                    math::wrap_pi(now - before).abs() <= COG_AGREE_RAD
                }
                _ => false,
            };
            self.cog_agreeing = if agrees {
                self.cog_agreeing.saturating_add(1)
            } else {
                0
            };
            self.cog_seen = self.cog;
            self.cogs_before_heading = self.cogs_before_heading.saturating_add(1);
        }
        let measured = match from_cog {
            Some(CogCorrection::Applied { measured_rad }) => Some(measured_rad),
            Some(CogCorrection::NoHeading) if self.cog_agreeing >= COG_AGREEING => {
                let (cog, t) = self.cog.unwrap_or_default();
                let age_s = math::u64_to_f32(now_us.saturating_sub(t)) * 1e-6;
                self.estimator.courses_agreed();
                Some(self.estimator.correct_heading(
                    cfg,
                    along_heading(cog, reversing),
                    age_s,
                    speed_mps,
                    rates,
                ))
            }
            Some(CogCorrection::Refused) => None,
            Some(CogCorrection::Scattered | CogCorrection::NoHeading) | None if moving => {
                // The time since the latest fix: with a slow receiver the same chord steers
                // the heading for a whole period, while the car keeps turning.
                let since_fix_us = inputs
                    .freshness
                    .last_us(Input::Gnss)
                    .map_or(0, |t| now_us.saturating_sub(t));
                let since_fix_s = math::u64_to_f32(since_fix_us) * 1e-6;
                match self.estimator.correct_heading_on_track(cfg, since_fix_s) {
                    TrackCorrection::Applied { measured_rad } => Some(measured_rad),
                    TrackCorrection::ShortChord => None,
                    // The receiver's courses have not agreed yet: they set the first heading.
                    TrackCorrection::NoHistory
                        if matches!(from_cog, Some(CogCorrection::NoHeading))
                            && self.cogs_before_heading < COG_AWAITED =>
                    {
                        None
                    }
                    TrackCorrection::NoHistory => {
                        self.estimator.track_course(cfg).map(|(course, age_fixes)| {
                            let age_s = age_fixes * cfg.gnss_period_s + since_fix_s;
                            let course = along_heading(course, reversing);
                            self.estimator
                                .correct_heading(cfg, course, age_s, speed_mps, rates)
                        })
                    }
                }
            }
            _ => None,
        };

        let gnss_age = inputs
            .freshness
            .last_us(Input::Gnss)
            .map(|t| now_us.saturating_sub(t));
        let gnss_fresh = matches!(gnss_age, Some(a) if a <= gnss_timeout_us);
        if matches!(gnss_age, Some(a) if a > config.gnss_lost_us) && self.estimator.fixes() > 0 {
            self.estimator.reset();
        }
        let pose = match (self.estimator.position(cfg), self.estimator.heading_rad()) {
            (Some(p), Some(h)) if p.x_m.is_finite() && p.y_m.is_finite() && h.is_finite() => {
                Some(Pose::new(p.x_m, p.y_m, h))
            }
            _ => None,
        };
        (pose, gnss_fresh, measured)
    }
}
