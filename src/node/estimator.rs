//! The node's current-state estimate: GNSS fixes through the paper's lowpass (streaming
//! 20th-order FIR + moving average, at the GNSS rate, paper II-A and II-C), with the filters'
//! group delay compensated by dead reckoning, and a heading estimate.
//!
//! Receiver rate: the paper's filter is for its 100 Hz receiver, and its shape is a trade-off
//! that depends on the rate; [`EstimatorConfig::design`] scales it for any rate from 1 to
//! 100 Hz (see there for the rule and its derivation).
//!
//! A plain causal lowpass lags: at 10 m/s its ~0.145 s group delay puts the filtered position
//! ~1.5 m behind the car, worse than raw GNSS. So every fix also records where dead reckoning
//! (measured speed, estimated heading) had the car at that instant; the filter output, which
//! describes the car `group_delay` fixes ago, is moved forward by the dead-reckoned
//! displacement since then. Dead reckoning only has to be right over ~0.15 s, where its drift is
//! millimetres, and GNSS keeps it anchored.
//!
//! Heading: propagated with the kinematic yaw rate (eq 8 with eq 2's understeer) every tick,
//! and pulled towards the course of the filtered GNSS track (or the receiver's COG, PGN 129026,
//! when it is fresh) while the car moves, by a complementary filter.
//!
//! Lever arm: the receiver measures its antenna, which sits `antenna_ahead_m` ahead of and
//! `antenna_left_m` left of the reference point of eq 8 (the rear axle, whose velocity points
//! along the heading). Everything inside the filter is the antenna's;
//! [`EstimatorState::position`] moves the result back to the rear axle, and the antenna's course,
//! which in a turn leads the heading by `atan((ahead * yaw_rate + rear_side) / (v + left *
//! yaw_rate))`, is corrected before it steers the heading.
//!
//! Side slip: eq 8's rear axle moves along the heading, but a real one slides outwards in a
//! turn by its tyres' slip angle, `m l_f a_y / (L C_r)`: 0.042 rad for the CAT Vehicle at
//! 5 m/s^2 (a 20 m arc at 10 m/s), which a course taken for the heading turns into a heading
//! error of the same size and a tracking offset of 0.19 m. The node's lateral model gives the
//! rear axle's sideways velocity ([`Rates::rear_side_mps`]: `v_y - l_r r` of the dynamic
//! single-track model, in either mode; 0 without one), and both the dead reckoning and the
//! course's lead use it.
use crate::image::{Image, ImageError, ImageReader, ImageWriter};
use crate::math;
use crate::signal::fir::{FilterError, Fir, FirState};
use crate::signal::moving_average::{MovingAverage, MovingAverageState};

/// GNSS lowpass length: 20th order (paper II-C).
pub const GNSS_FIR_TAPS: usize = 21;
/// Moving-average span (the paper's "span of 10 elements").
pub const GNSS_MA_SPAN: usize = 10;
/// Fixes of filtered track kept for the course estimate: 0.64 s at 100 Hz. (A restart on the
/// dead-reckoned track writes one entry per missing fix up to this many: the stage drives'
/// long gaps reach it, `xtask/src/drives.rs`.)
pub const TRACK_LEN: usize = 64;
/// Time spanned by the chord of the course estimate, s: the paper rate's 63 fixes.
const TRACK_SPAN_S: f64 = 0.63;
/// The paper's receiver rate (NovAtel, "every 0.01 seconds", paper II-B), Hz: the rate the
/// paper's lowpass (21 taps at 2 Hz, then 10 samples) is for, and the anchor of the scaling.
pub const PAPER_GNSS_RATE_HZ: f64 = 100.0;
/// Below this rate the course gain falls with the rate, Hz (see [`EstimatorConfig::design`]).
const COURSE_GAIN_FULL_RATE_HZ: f64 = 25.0;
/// Half the window the yaw rate at a course's time is averaged over, s (the antenna's lead
/// correction).
const LEAD_WINDOW_S: f32 = 0.1;
/// The heading filter's gain towards the course per 20 ms tick at 25 Hz and above, at its
/// largest (a 0.4 s time constant): while the heading is uncertain and, in steady state, for
/// chords of [`COURSE_FULL_GAIN_CHORD_M`] or longer.
const COURSE_GAIN: f32 = 0.05;
/// In steady state the course gain is full for a chord this long or longer and falls as the
/// square of the chord's length below it, m ([`EstimatorState::correct_heading_on_track`]):
/// 0.63 s at 9.5 m/s.
pub const COURSE_FULL_GAIN_CHORD_M: f32 = 6.0;
/// A chord's error across it, m: a standard receiver's white noise left after the lowpass and
/// its bias's wander over the chord's 0.63 s (0.8 m with a 60 s correlation: 0.12 m), together.
const CHORD_NOISE_M: f32 = 0.13;
/// Ticks over which the chords' errors are correlated (each chord shares all but one fix with
/// the previous tick's): the chord's 0.63 s.
const CHORD_CORRELATED_TICKS: f32 = 31.5;
/// The antenna's velocity error a receiver's course over ground carries, one sigma, m/s: a
/// course from the carrier's Doppler is good to 0.05 m/s (u-blox NEO-M8 data sheet, velocity
/// accuracy); a receiver that differences its own fixes does worse, hence four times that.
/// The course's error is this over the speed (`EstimatorState::correct_heading_on_cog`).
const COG_NOISE_MPS: f32 = 0.2;
/// A course over ground further from the heading than this many standard deviations of their
/// difference (the heading's variance and the course's) is refused: a receiver whose course
/// is differenced from its own fixes turns a multipath glitch of a metre into a course tens
/// of degrees off, which the fixes' step gate (`super::gnss`) does not see.
const COG_GATE_SIGMAS: f32 = 5.0;
/// ... or further than this many of the learnt median of their differences (the receiver's
/// own scatter, whatever it is: 8.9 medians of |x| are 6 sigma), whichever is wider.
const COG_GATE_MEDIANS: f32 = 8.9;
/// The learnt median of the course's difference from the heading starts here and stays
/// within `[COG_MEDIAN_MIN_RAD, COG_MEDIAN_MAX_RAD]`, rad (the gate from 0.9 rad wide, and
/// never narrower than 5 sigma of the course's own error).
const COG_MEDIAN_START_RAD: f32 = 0.1;
const COG_MEDIAN_MIN_RAD: f32 = 0.001;
const COG_MEDIAN_MAX_RAD: f32 = 1.0;
/// A receiver whose courses' learnt median difference from the heading is above this, rad, is
/// not used for the heading (until it is below [`COG_USABLE_BELOW_RAD`]): the filtered track's
/// chords correct it instead ([`EstimatorState::correct_heading_on_track`]). A course
/// differenced from the receiver's own fixes scatters by their noise over the distance between
/// two fixes (0.5 m of noise at 10 Hz and 8 m/s: 0.9 rad), and pulled the heading about until
/// the car left its corridor by metres (`scripts/sil-drive.py --cog-from-fixes`,
/// docs/findings.md); a course from the carrier's Doppler is within hundredths of a radian.
/// The median follows the heading's error too: a heading that has drifted leaves the courses
/// to the chords until they have brought it back.
pub const COG_SCATTERED_ABOVE_RAD: f32 = 0.06;
/// See [`COG_SCATTERED_ABOVE_RAD`].
pub const COG_USABLE_BELOW_RAD: f32 = 0.04;
/// The learnt median's step per tick, as a share of it (from the start to a Doppler course's
/// in about 150 ticks).
const COG_MEDIAN_STEP: f32 = 0.03;
/// Courses refused for this many ticks in a row are the heading's error, not the course's:
/// the next is taken, its difference counted in the heading's variance (0.5 s).
const COG_REFUSED_TICKS_MAX: u16 = 25;
/// A chord whose error is further from the heading than this many standard deviations of
/// their difference (the heading's variance and one chord's own error,
/// `chord_var_rad2 / CHORD_CORRELATED_TICKS`) counts as beyond it; chords beyond it for longer
/// than any one fix stays in them ([`chord_persist_ticks`]) are the heading's error, not the
/// chords': its variance is raised to that error squared
/// ([`EstimatorState::correct_heading_on_track`]).
const CHORD_GATE_SIGMAS: f32 = 3.0;
/// The chords' error, once it persists, beyond which the track runs against the dead reckoning
/// (rad, 90 degrees): the car reverses without saying so (SPEED_REPORT's speed is a magnitude,
/// and without its `direction` the node dead-reckons forwards) or the heading is half a turn
/// off, which a straight track cannot tell apart ([`EstimatorState::direction_ambiguous`]). A
/// car that reports reverse is dead-reckoned backwards (a negative speed), and its track runs
/// with the dead reckoning.
const AGAINST_THE_TRACK_RAD: f32 = core::f32::consts::FRAC_PI_2;
/// The turn the dead reckoning makes with the chords agreeing, rad, after which a heading the
/// track ran against is trusted again: in a turn a reversing car's track bends the other way
/// from the turn the steering makes forwards, so the chords agree through it only when the car
/// drives forwards on the heading ([`EstimatorState::direction_ambiguous`]).
const DIRECTION_CONFIRM_TURN_RAD: f32 = 0.5;
/// The heading's variance when a first course sets it, rad^2: one course at the lowest speed
/// a course is read at, 0.5 rad (one sigma).
const HEADING_INITIAL_VAR_RAD2: f32 = 0.25;
/// The heading's variance never grows past this, rad^2 (1 rad, one sigma).
const HEADING_MAX_VAR_RAD2: f32 = 1.0;
/// Dead-reckoning history, one entry per fix: it must span the course chord (at most
/// `TRACK_LEN - 1` fixes) beyond the group delay (14.5 fixes at 100 Hz), for
/// [`EstimatorState::correct_heading_on_track`].
const ODO_LEN: usize = 128;
const _: () = assert!(ODO_LEN >= TRACK_LEN + 16);
/// How far back the dead reckoning's heading change is kept, ticks: 2.56 s, more than the
/// oldest course the heading is corrected with (the chord's half span plus the filter's group
/// delay plus the time since the fix: 0.47 s at 100 Hz, 1.7 s at 1 Hz). Older courses are
/// carried forward with the current yaw rate for the rest.
pub const TURN_HISTORY_TICKS: usize = 128;

/// Estimator tuning. Immutable configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct EstimatorConfig {
    /// The paper's lowpass, designed for the GNSS rate.
    pub fir: Fir<GNSS_FIR_TAPS>,
    /// The moving average after it.
    pub ma: MovingAverage<GNSS_MA_SPAN>,
    /// FIR + MA group delay, in fixes.
    pub group_delay_fixes: f32,
    /// Course from the filtered track needs at least this displacement, m.
    pub course_min_baseline_m: f32,
    /// Fixes spanned by the chord of the course estimate (1..=`TRACK_LEN - 1`).
    pub track_span_fixes: u32,
    /// The heading filter's largest gain towards the GNSS course, per tick (0..1): the COG's
    /// and the start's gain, and the cap of the chords' (see
    /// [`EstimatorState::correct_heading_on_track`]).
    pub course_gain: f32,
    /// Heading is only corrected above this speed, m/s.
    pub course_min_speed_mps: f32,
    /// GNSS antenna ahead of the rear axle (the reference point of eq 8), m; 0 = on the axle.
    pub antenna_ahead_m: f32,
    /// GNSS antenna left of the car's centre line, m (negative: right).
    pub antenna_left_m: f32,
    /// The receiver's fix period, s: the rate the lowpass is designed for and the unit of the
    /// gap logic.
    pub gnss_period_s: f32,
}

/// Lowpass cutoff for GNSS at the paper's 100 Hz, Hz: the paper's 2 Hz, which passes the car's
/// motion (manoeuvres below 1 Hz) and removes the receiver's white noise. Other rates scale it
/// ([`EstimatorConfig::design`]).
pub const GNSS_CUTOFF_HZ: f64 = 2.0;

/// How the lowpass's window time scales with the receiver rate: `T ~ rate^-WINDOW_EXPONENT`
/// (see [`EstimatorConfig::design`] for the derivation of 1/3).
pub const WINDOW_EXPONENT: f64 = 1.0 / 3.0;

impl Image for EstimatorConfig {
    fn write(&self, w: &mut ImageWriter<'_>) {
        let Self {
            fir,
            ma,
            group_delay_fixes,
            track_span_fixes,
            course_min_baseline_m,
            course_gain,
            course_min_speed_mps,
            antenna_ahead_m,
            antenna_left_m,
            gnss_period_s,
        } = self;
        fir.write(w);
        ma.write(w);
        track_span_fixes.write(w);
        for v in [
            group_delay_fixes,
            course_min_baseline_m,
            course_gain,
            course_min_speed_mps,
            antenna_ahead_m,
            antenna_left_m,
            gnss_period_s,
        ] {
            v.write(w);
        }
    }
    fn read(r: &mut ImageReader<'_>) -> Result<Self, ImageError> {
        Ok(Self {
            fir: Fir::read(r)?,
            ma: MovingAverage::read(r)?,
            track_span_fixes: match u32::read(r)? {
                n @ 1..=63 => n,
                _ => return Err(r.out_of_range()),
            },
            group_delay_fixes: f32::read(r)?,
            course_min_baseline_m: f32::read(r)?,
            course_gain: f32::read(r)?,
            course_min_speed_mps: f32::read(r)?,
            antenna_ahead_m: f32::read(r)?,
            antenna_left_m: f32::read(r)?,
            gnss_period_s: f32::read(r)?,
        })
    }
}

/// Planar position, m (east, north).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Xy {
    /// East, m.
    pub x_m: f32,
    /// North, m.
    pub y_m: f32,
}

/// The body's motion the dead reckoning integrates, from the node's lateral model.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Rates {
    /// Yaw rate, rad/s, clockwise.
    pub yaw_rps: f32,
    /// The rear axle's velocity to the right of the heading (tyre slip), m/s; 0 in the
    /// kinematic model.
    pub rear_side_mps: f32,
}

/// What the dead reckoning swept since some instant: heading change (rad, clockwise, wrapped to
/// +-pi) and the rear axle's sideways travel in the body frame (m, right; wrapped to
/// +-[`SLID_WRAP_M`]). Only differences over less than half a wrap are used.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Swept {
    turned_rad: f32,
    slid_m: f32,
    /// The course corrections applied to the heading (rad, wrapped to +-pi).
    corrected_rad: f32,
}

/// The sideways travel's wrap, m: a difference over the course's age is at most a few metres,
/// and f32 keeps millimetres up to here.
const SLID_WRAP_M: f32 = 1024.0;

fn wrap_slid(x: f32) -> f32 {
    if x > SLID_WRAP_M {
        x - 2.0 * SLID_WRAP_M
    } else if x < -SLID_WRAP_M {
        x + 2.0 * SLID_WRAP_M
    } else {
        x
    }
}

impl Swept {
    fn minus(self, other: Self) -> Self {
        Self {
            turned_rad: math::wrap_pi(self.turned_rad - other.turned_rad),
            slid_m: wrap_slid(self.slid_m - other.slid_m),
            corrected_rad: math::wrap_pi(self.corrected_rad - other.corrected_rad),
        }
    }
}

/// What [`EstimatorState::correct_heading_on_cog`] did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CogCorrection {
    /// The heading was pulled towards the course.
    Applied {
        /// The heading the course measured now (the course carried to now, its lead removed).
        measured_rad: f32,
    },
    /// The course was too far from the heading, and refused ([`COG_GATE_SIGMAS`]).
    Refused,
    /// The receiver's courses scatter too much to steer the heading
    /// ([`COG_SCATTERED_ABOVE_RAD`]): the caller corrects it on the track instead.
    Scattered,
    /// No heading yet: a course is judged against one, so the first heading comes from the
    /// filtered track ([`EstimatorState::track_course`]), whose chord is 1.5 m long at
    /// least. A receiver's course at walking pace can be anything (differenced from fixes
    /// with 2 cm of noise at 100 Hz and 2 m/s, it is: `scripts/sil-drive.py
    /// --cog-from-fixes` set the heading 3.1 rad off, and the node lost its path before it
    /// had driven).
    NoHeading,
}

/// What [`EstimatorState::correct_heading_on_track`] did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TrackCorrection {
    /// The heading was pulled towards the chords' agreement.
    Applied {
        /// The heading the chords measured now: the heading before the correction plus the
        /// error they found, rad.
        measured_rad: f32,
    },
    /// The car moved less than `course_min_baseline_m` over the chord: nothing to learn, the
    /// heading is left to the dead reckoning.
    ShortChord,
    /// No dead-reckoning history as long as the chord yet (at the start, after a restart of
    /// the filters): the caller may use the track's own course instead.
    NoHistory,
}

/// The variance the heading filter gives a chord's course error measured over a chord of
/// `chord_sq_m2` squared length with a per-tick gain cap of `course_gain`, rad^2: the chord's
/// error across it over its length, squared, for every tick it is correlated over, and larger
/// in the proportion a lower rate's cap is lower (the cap falls as the square root of the
/// rate: [`EstimatorConfig::design`]).
fn chord_var_rad2(course_gain: f32, chord_sq_m2: f32) -> f32 {
    let rate_scale = COURSE_GAIN / math::max(course_gain, 1e-6);
    CHORD_NOISE_M * CHORD_NOISE_M / math::max(chord_sq_m2, 1e-6)
        * CHORD_CORRELATED_TICKS
        * rate_scale
        * rate_scale
}

/// Ticks in a row the chords' error must stay beyond [`CHORD_GATE_SIGMAS`] before the heading's
/// variance is raised to it: the time one fix stays in the chords (the chord's span plus the
/// lowpass's taps and moving-average samples, in fixes; 0.94 s at 100 Hz, 1.3 s at 10 Hz, 3 s
/// at 1 Hz), so that no single fix's error, a glitch the step gate let through, can hold the
/// chords there that long.
fn chord_persist_ticks(cfg: &EstimatorConfig, span_fixes: usize) -> f32 {
    let fixes = (span_fixes + cfg.fir.len() + cfg.ma.len()) as f32;
    fixes * cfg.gnss_period_s / crate::SAMPLE_PERIOD_S
}

/// What the dead reckoning's heading drift adds to its variance over `dt_s` at `speed_mps`,
/// rad^2. The yaw rate's error goes as the speed (a curvature error times the speed), so the
/// variance it adds per tick goes as the square of the distance a chord spans at that speed.
/// Its scale is what makes the steady-state gain the course gain at a chord of
/// [`COURSE_FULL_GAIN_CHORD_M`] and fall as the chord's length squared below it: for a small
/// gain the steady state is sqrt(drift / chord variance), and the chord's variance goes as
/// 1 / length^2 ([`chord_var_rad2`]).
fn heading_drift_var_rad2(cfg: &EstimatorConfig, speed_mps: f32, dt_s: f32) -> f32 {
    /// `chord_var_rad2` of a full-gain chord at the full course gain.
    const FULL_CHORD_VAR_RAD2: f32 = CHORD_NOISE_M * CHORD_NOISE_M
        / (COURSE_FULL_GAIN_CHORD_M * COURSE_FULL_GAIN_CHORD_M)
        * CHORD_CORRELATED_TICKS;
    let span_s = cfg.track_span_fixes as f32 * cfg.gnss_period_s;
    let share = speed_mps * span_s / COURSE_FULL_GAIN_CHORD_M;
    FULL_CHORD_VAR_RAD2 * COURSE_GAIN * COURSE_GAIN * share * share * math::max(dt_s, 0.0)
        / crate::SAMPLE_PERIOD_S
}

/// Estimator state.
#[derive(Clone, Debug)]
pub struct EstimatorState {
    fir_x: FirState<GNSS_FIR_TAPS>,
    fir_y: FirState<GNSS_FIR_TAPS>,
    ma_x: MovingAverageState<GNSS_MA_SPAN>,
    ma_y: MovingAverageState<GNSS_MA_SPAN>,
    /// Filter output of the latest fix (describes the car `group_delay` fixes earlier).
    filtered: Option<Xy>,
    /// Dead-reckoned position at each of the last fixes (ring, newest at `odo_head`).
    odo_at_fix: [Xy; ODO_LEN],
    odo_head: usize,
    /// Entries of `odo_at_fix` recorded in a row with a heading estimate (since it was first
    /// set, or since the filters restarted on the dead-reckoned track).
    odo_valid: u32,
    fixes: u32,
    /// Filtered track for the course estimate (ring).
    track: [Xy; TRACK_LEN],
    track_head: usize,
    /// Dead-reckoned antenna position now (arbitrary origin: only differences are used).
    odo_now: Xy,
    /// Heading estimate, rad clockwise from north; `None` until a course was seen.
    heading_rad: Option<f32>,
    /// sin and cos of the heading at this tick's dead-reckoning step.
    heading_sin_cos: (f32, f32),
    /// What the dead reckoning swept (yaw rate and the rear axle's sideways velocity
    /// integrated, without the course corrections) at the end of each of the last ticks (ring,
    /// newest at `turned_head`).
    turned: [Swept; TURN_HISTORY_TICKS],
    turned_head: usize,
    /// Valid entries of `turned`.
    turned_len: usize,
    /// Every course correction applied to the heading, summed (rad, wrapped to +-pi).
    corrected_rad: f32,
    /// The heading's error variance as the heading filter reckons it, rad^2
    /// ([`Self::correct_heading_on_track`]).
    heading_var_rad2: f32,
    /// Ticks in a row whose course over ground the gate refused
    /// ([`Self::correct_heading_on_cog`]).
    cog_refused_ticks: u16,
    /// Ticks in a row whose chords' error was beyond [`CHORD_GATE_SIGMAS`]
    /// ([`Self::correct_heading_on_track`]).
    chord_beyond_ticks: u16,
    /// The learnt median of the course's difference from the heading, rad ([`COG_GATE_MEDIANS`]).
    cog_median_rad: f32,
    /// The track ran against the dead reckoning ([`Self::direction_ambiguous`]).
    direction_ambiguous: bool,
    /// The turn made since, with the chords agreeing, rad ([`DIRECTION_CONFIRM_TURN_RAD`]).
    confirming_turn_rad: f32,
    /// The receiver's courses scatter too much to use ([`COG_SCATTERED_ABOVE_RAD`]).
    cog_scattered: bool,
}

impl Default for EstimatorState {
    fn default() -> Self {
        Self {
            fir_x: FirState::default(),
            fir_y: FirState::default(),
            ma_x: MovingAverageState::default(),
            ma_y: MovingAverageState::default(),
            filtered: None,
            odo_at_fix: [Xy::default(); ODO_LEN],
            odo_head: 0,
            odo_valid: 0,
            fixes: 0,
            track: [Xy::default(); TRACK_LEN],
            track_head: 0,
            odo_now: Xy::default(),
            heading_rad: None,
            heading_sin_cos: (0.0, 1.0),
            turned: [Swept::default(); TURN_HISTORY_TICKS],
            turned_head: 0,
            turned_len: 0,
            corrected_rad: 0.0,
            heading_var_rad2: HEADING_INITIAL_VAR_RAD2,
            cog_refused_ticks: 0,
            chord_beyond_ticks: 0,
            cog_median_rad: COG_MEDIAN_START_RAD,
            direction_ambiguous: false,
            confirming_turn_rad: 0.0,
            // Unproven until its scatter is learnt (0.6 s of a Doppler receiver's courses).
            cog_scattered: true,
        }
    }
}

impl EstimatorConfig {
    /// The receiver's rate the model file declares, Hz: `1 / gnss_period_s` with the f32
    /// period's rounding undone to a thousandth of a hertz (100 Hz is 100, not 100.0000002), for
    /// host tools that must reproduce that receiver exactly (the stage drives, the rig's plant).
    pub fn declared_gnss_rate_hz(&self) -> f64 {
        libm::round(1e3 / f64::from(self.gnss_period_s)) / 1e3
    }

    /// The lowpass and heading filter for a receiver at `gnss_rate_hz` (1..100 Hz; designed in
    /// f64, on the host or in the firmware build, never on the MCU), the antenna
    /// `antenna_ahead_m` ahead of the rear axle and `antenna_left_m` left of the centre line.
    ///
    /// At the paper's 100 Hz this is the paper's filter: a 21-tap Hamming lowpass at 2 Hz, then
    /// a 10-sample moving average, a 0.3 s window with a 0.145 s group delay. At other rates
    /// the window is scaled, not kept in fixes or in seconds:
    /// - the window averages the receiver's white noise: its residual is about
    ///   `sigma / sqrt(rate T)` for a window of T seconds;
    /// - the dead reckoning that moves the output forward over the group delay (about T / 2)
    ///   drifts in proportion to T (heading error x speed x T);
    /// - the sum of the two squares is least for `T ~ rate^(-1/3)` ([`WINDOW_EXPONENT`]).
    ///
    /// So the window holds `30 (rate / 100)^(2/3)` fixes, shared between FIR taps (odd, 21 at
    /// 100 Hz) and moving-average samples (10 at 100 Hz) in the paper's proportion, and the
    /// cutoff follows the window's time scale, `2 Hz (rate / 100)^(1/3)`: at 10 Hz 5 taps at
    /// 0.93 Hz and 2 samples (a 0.6 s window, 0.25 s delay); at 1 Hz 1 tap and 1 sample (each
    /// fix as it is, moved by dead reckoning). A window of 30 fixes at every rate (the paper's
    /// filter designed at the receiver's rate) lags 1.45 s at 10 Hz and lets the heading diverge;
    /// 0.3 s at every rate averages too few fixes (the comparison on the second car:
    /// `cargo run --release -p catmodel-host --example gnss_rate -- --exponents`).
    ///
    /// The course chord spans 0.63 s (63 fixes at 100 Hz, at least one fix), and below 25 Hz
    /// the course gain falls as the square root of
    /// the rate (0.032 per tick at 10 Hz, 0.01 at 1 Hz): a complementary filter's best gain
    /// goes as sqrt(process noise / measurement noise), and the course's noise variance grows
    /// as the rate falls (fewer fixes in each chord).
    pub fn design(
        gnss_rate_hz: f64,
        antenna_ahead_m: f32,
        antenna_left_m: f32,
    ) -> Result<Self, FilterError> {
        Self::design_scaled(
            gnss_rate_hz,
            WINDOW_EXPONENT,
            antenna_ahead_m,
            antenna_left_m,
        )
    }

    /// The lowpass cutoff of [`EstimatorConfig::design_scaled`], Hz: it follows the window's
    /// time scale, `2 Hz (rate / 100)^window_exponent`, and stays below 0.45 x the rate (below
    /// Nyquist; never binding from 1 to 100 Hz with the design's exponent).
    pub fn scaled_cutoff_hz(gnss_rate_hz: f64, window_exponent: f64) -> f64 {
        let scale = gnss_rate_hz / PAPER_GNSS_RATE_HZ;
        (GNSS_CUTOFF_HZ * libm::pow(scale, window_exponent)).min(0.45 * gnss_rate_hz)
    }

    /// [`EstimatorConfig::design`] with the window time scaling as `rate^-window_exponent`
    /// (0: the paper's 0.3 s at every rate; 1: its 30 fixes at every rate), for the comparison
    /// that chose [`WINDOW_EXPONENT`].
    pub fn design_scaled(
        gnss_rate_hz: f64,
        window_exponent: f64,
        antenna_ahead_m: f32,
        antenna_left_m: f32,
    ) -> Result<Self, FilterError> {
        if !(gnss_rate_hz.is_finite() && gnss_rate_hz > 0.0) {
            return Err(FilterError::InvalidSampleRate);
        }
        if !(antenna_ahead_m.is_finite()
            && antenna_left_m.is_finite()
            && window_exponent.is_finite())
        {
            return Err(FilterError::NonFiniteTap);
        }
        let scale = gnss_rate_hz / PAPER_GNSS_RATE_HZ;
        let window_share = libm::pow(scale, 1.0 - window_exponent);
        let taps = libm::round(GNSS_FIR_TAPS as f64 * window_share) as usize;
        // Odd, so that the group delay is a whole number of fixes, as the paper's 21 taps.
        let taps = (taps | 1).clamp(1, GNSS_FIR_TAPS);
        let span =
            (libm::round(GNSS_MA_SPAN as f64 * window_share) as usize).clamp(1, GNSS_MA_SPAN);
        let cutoff_hz = Self::scaled_cutoff_hz(gnss_rate_hz, window_exponent);
        let fir = Fir::lowpass_len(taps, cutoff_hz, gnss_rate_hz)?;
        let ma = MovingAverage::with_span(span).ok_or(FilterError::NoTaps)?;
        let group_delay_fixes = fir.group_delay_samples() + ma.group_delay_samples();
        let track_span_fixes =
            (libm::round(TRACK_SPAN_S * gnss_rate_hz) as u32).clamp(1, TRACK_LEN as u32 - 1);
        let course_gain =
            COURSE_GAIN * libm::sqrt((gnss_rate_hz / COURSE_GAIN_FULL_RATE_HZ).min(1.0)) as f32;
        Ok(Self {
            fir,
            ma,
            group_delay_fixes,
            track_span_fixes,
            course_min_baseline_m: 1.5,
            course_gain,
            course_min_speed_mps: 1.5,
            antenna_ahead_m,
            antenna_left_m,
            gnss_period_s: (1.0 / gnss_rate_hz) as f32,
        })
    }
}

impl EstimatorState {
    /// Forgets every fix (e.g. after a GNSS outage or a position jump): the next fix primes
    /// the filters. Only the fix count and the filter output are cleared: nothing reads the
    /// histories below the fix count (the next fix overwrites the filters' memory, the rings
    /// are read at most `fixes` back), so this is the same as starting afresh, in a few
    /// instructions instead of rewriting the whole state. The heading survives a position
    /// reset: it is still the car's.
    pub fn reset(&mut self) {
        self.fixes = 0;
        self.odo_valid = 0;
        self.filtered = None;
        self.chord_beyond_ticks = 0;
    }

    /// [`Self::reset`], and the heading forgotten too: for fixes that were not what the
    /// configuration says (their rate), whose course cannot be trusted either.
    pub fn forget(&mut self) {
        self.reset();
        self.heading_rad = None;
        self.direction_ambiguous = false;
    }

    /// The antenna's dead-reckoned position, m: continuous (fixes never move it), so its change
    /// over a tick is the car's motion alone.
    pub fn dead_reckoned(&self) -> Xy {
        self.odo_now
    }

    /// The sine and cosine of the heading the last [`Self::propagate`] moved along.
    pub fn heading_sin_cos(&self) -> (f32, f32) {
        self.heading_sin_cos
    }

    /// The heading's error variance as the heading filter reckons it, rad^2.
    pub fn heading_var_rad2(&self) -> f32 {
        self.heading_var_rad2
    }

    /// The GNSS track ran against the dead reckoning (the chords' error beyond
    /// [`AGAINST_THE_TRACK_RAD`] for longer than a fix stays in them), and the heading has not
    /// been confirmed since by a turn of [`DIRECTION_CONFIRM_TURN_RAD`] through which the
    /// chords agreed. Without SPEED_REPORT's `direction` the node's speed has no sign: a car
    /// that reverses is, to the node, a car facing the other way, and the chords turn the heading half round to
    /// the track's direction, where they then agree; the heading is half a turn off, the
    /// rear axle twice the antenna's lever arm off, and the heading filter sure of both (a
    /// black-box probe: 3.13 rad off for 528 ticks, `heading_uncertain` clear;
    /// docs/findings.md). While this holds STATE_MOTION says the heading is uncertain.
    pub fn direction_ambiguous(&self) -> bool {
        self.direction_ambiguous
    }

    /// Current heading estimate, rad.
    pub fn heading_rad(&self) -> Option<f32> {
        self.heading_rad
    }

    /// Fixes filtered since the last reset.
    pub fn fixes(&self) -> u32 {
        self.fixes
    }

    /// Dead reckoning of the antenna: the car moved `dt_s` at `speed_mps` (rear axle, along the
    /// heading; negative reversing) while turning at `rates.yaw_rps` and sliding sideways at
    /// `rates.rear_side_mps`; the antenna also swings sideways by `antenna_ahead * yaw_rate`
    /// and, off the centre line, moves `antenna_left * yaw_rate` faster along (the outside of a
    /// turn travels farther).
    /// Call once per tick, before the tick's fixes are applied with their time offsets.
    pub fn propagate(&mut self, cfg: &EstimatorConfig, speed_mps: f32, rates: Rates, dt_s: f32) {
        let heading = self.heading_rad.unwrap_or(0.0);
        let mid = heading + 0.5 * rates.yaw_rps * dt_s;
        let (s, c) = math::sin_cos(mid);
        // Close enough to the end-of-step heading for the <= 20 ms look-backs of `add_fix`.
        self.heading_sin_cos = (s, c);
        let along_m = (speed_mps + cfg.antenna_left_m * rates.yaw_rps) * dt_s;
        // Right of the heading is (cos, -sin); positive yaw rate (clockwise) swings the antenna
        // to the right.
        let across_m = (cfg.antenna_ahead_m * rates.yaw_rps + rates.rear_side_mps) * dt_s;
        self.odo_now.x_m += along_m * s + across_m * c;
        self.odo_now.y_m += along_m * c - across_m * s;
        if let Some(h) = self.heading_rad.as_mut() {
            *h = math::wrap_pi(*h + rates.yaw_rps * dt_s);
        }
        if self.direction_ambiguous {
            self.confirming_turn_rad += (rates.yaw_rps * dt_s).abs();
            // `!(a < b)`: a NaN turn confirms nothing (it is counted where the rates are).
            if self.confirming_turn_rad >= DIRECTION_CONFIRM_TURN_RAD {
                self.direction_ambiguous = false;
            }
        }
        self.heading_var_rad2 = math::min(
            self.heading_var_rad2 + heading_drift_var_rad2(cfg, speed_mps, dt_s),
            HEADING_MAX_VAR_RAD2,
        );
        let swept = self
            .turned
            .get(self.turned_head)
            .copied()
            .unwrap_or_default();
        self.turned_head = (self.turned_head + 1) % TURN_HISTORY_TICKS;
        if let Some(slot) = self.turned.get_mut(self.turned_head) {
            *slot = Swept {
                turned_rad: math::wrap_pi(swept.turned_rad + rates.yaw_rps * dt_s),
                slid_m: wrap_slid(swept.slid_m + rates.rear_side_mps * dt_s),
                corrected_rad: self.corrected_rad,
            };
        }
        self.turned_len = (self.turned_len + 1).min(TURN_HISTORY_TICKS);
    }

    /// The car may have turned at up to `unseen_yaw_rps` over `dt_s` without the dead
    /// reckoning seeing it (the steering report stale: the lateral model steers straight on):
    /// the heading's standard deviation grows by that turn, a bound rather than a random walk
    /// (a car that yaws so all along is that far off). Once it reaches the largest the filter
    /// holds (1 rad), the heading is forgotten and taken again from the courses or the track,
    /// as at the start: a black-box probe's drive with every input silent for 10 s came back
    /// with the heading of before, 2.28 rad off, the position valid and nothing flagged
    /// (docs/findings.md). Call after [`Self::propagate`].
    pub fn turn_unseen(&mut self, unseen_yaw_rps: f32, dt_s: f32) {
        if self.heading_rad.is_none() {
            return;
        }
        let sigma = math::sqrt(self.heading_var_rad2) + unseen_yaw_rps.abs() * dt_s;
        // `!(a < b)`: a NaN is the unknown heading too.
        #[allow(clippy::neg_cmp_op_on_partial_ord)]
        if !(sigma * sigma < HEADING_MAX_VAR_RAD2) {
            self.heading_rad = None;
            self.direction_ambiguous = false;
            self.heading_var_rad2 = HEADING_INITIAL_VAR_RAD2;
            return;
        }
        self.heading_var_rad2 = sigma * sigma;
    }

    /// How far the dead reckoning turned (rad, clockwise) and the rear axle slid sideways (m)
    /// over the last `age_s`: the rates of the ticks in between, integrated (interpolated within
    /// a tick; beyond the history, `now_rates` for the rest). A course measured `age_s` ago plus
    /// the turn is the course now, whatever the yaw rate did in between: a turn that starts or
    /// ends within the age is not extrapolated with the yaw rate of now.
    fn swept_since(&self, age_s: f32, now_rates: Rates) -> Swept {
        let age_ticks = math::max(age_s, 0.0) / crate::SAMPLE_PERIOD_S;
        let Some(now) = self.turned.get(self.turned_head).copied() else {
            return Swept {
                turned_rad: now_rates.yaw_rps * age_s,
                slid_m: now_rates.rear_side_mps * age_s,
                corrected_rad: 0.0,
            };
        };
        let available = self.turned_len.saturating_sub(1);
        let within = math::min(age_ticks, available as f32);
        let k0 = within as usize; // floor: within >= 0
        let w = within - k0 as f32;
        let at = |k: usize| {
            self.turned
                .get(
                    (self.turned_head + TURN_HISTORY_TICKS - k % TURN_HISTORY_TICKS)
                        % TURN_HISTORY_TICKS,
                )
                .copied()
                .unwrap_or(now)
        };
        let a = now.minus(at(k0));
        let b = if k0 < available {
            now.minus(at(k0 + 1))
        } else {
            a
        };
        let beyond_s = (age_ticks - within) * crate::SAMPLE_PERIOD_S;
        Swept {
            turned_rad: a.turned_rad
                + (b.turned_rad - a.turned_rad) * w
                + now_rates.yaw_rps * beyond_s,
            slid_m: a.slid_m + (b.slid_m - a.slid_m) * w + now_rates.rear_side_mps * beyond_s,
            corrected_rad: a.corrected_rad + (b.corrected_rad - a.corrected_rad) * w,
        }
    }

    /// One GNSS fix in local metres, `age_s` before the current dead-reckoning instant
    /// (fixes arrive between ticks), with the car's speed then.
    pub fn add_fix(&mut self, cfg: &EstimatorConfig, fix: Xy, age_s: f32, speed_mps: f32) {
        let odo_fix = self.dead_reckoned_back(self.odo_now, age_s, speed_mps);
        self.add_fix_at(cfg, fix, odo_fix);
    }

    /// [`Self::add_fix`] with where dead reckoning had the antenna at the fix's instant
    /// already known (`dead_reckoned_back(dead_reckoned(), age_s, speed_mps)`: the step gate
    /// computed it).
    pub fn add_fix_at(&mut self, cfg: &EstimatorConfig, fix: Xy, odo_fix: Xy) {
        if self.fixes == 0 {
            self.fir_x.prime(fix.x_m);
            self.fir_y.prime(fix.y_m);
            cfg.ma.prime(&mut self.ma_x, fix.x_m);
            cfg.ma.prime(&mut self.ma_y, fix.y_m);
        }
        let (lx, ly) = cfg
            .fir
            .process_pair((&mut self.fir_x, &mut self.fir_y), (fix.x_m, fix.y_m));
        let fx = cfg.ma.process(&mut self.ma_x, lx);
        let fy = cfg.ma.process(&mut self.ma_y, ly);
        let filtered = Xy { x_m: fx, y_m: fy };
        self.filtered = Some(filtered);
        self.odo_head = (self.odo_head + 1) % ODO_LEN;
        if let Some(slot) = self.odo_at_fix.get_mut(self.odo_head) {
            *slot = odo_fix;
        }
        self.odo_valid = if self.heading_rad.is_some() {
            self.odo_valid.saturating_add(1)
        } else {
            0
        };
        self.track_head = (self.track_head + 1) % TRACK_LEN;
        if let Some(slot) = self.track.get_mut(self.track_head) {
            *slot = filtered;
        }
        self.fixes = self.fixes.saturating_add(1);
    }

    /// Restarts the filters on the dead-reckoned track after a gap of `missing` fixes whose
    /// newest one would have come one period before a fix of age `age_s`, the antenna being at
    /// `antenna` now: the state is what filling the filters' whole memory with dead-reckoned
    /// positions gives (for a gap as long as that memory, what filling fix by fix does, to
    /// rounding), computed directly in fixed work. On that straight, evenly spaced track a
    /// unit-gain symmetric FIR and the moving average are pure delays, so each filter's history
    /// is the track itself, shifted by its group delay.
    pub fn restart_on_track(
        &mut self,
        cfg: &EstimatorConfig,
        antenna: Xy,
        age_s: f32,
        missing: u32,
        speed_mps: f32,
    ) {
        let (s, c) = self.heading_sin_cos;
        // The antenna `k` periods before the fix, moved `delay` fixes further back: `back_m`
        // metres behind where it is now.
        let step_m = speed_mps * cfg.gnss_period_s;
        let back_m = |k: usize, delay: f32| speed_mps * age_s + (k as f32 + delay) * step_m;
        let at = |back: f32| Xy {
            x_m: antenna.x_m - back * s,
            y_m: antenna.y_m - back * c,
        };
        self.fir_x.load(|k| at(back_m(k + 1, 0.0)).x_m);
        self.fir_y.load(|k| at(back_m(k + 1, 0.0)).y_m);
        let fir_delay = cfg.fir.group_delay_samples();
        cfg.ma
            .load(&mut self.ma_x, |k| at(back_m(k + 1, fir_delay)).x_m);
        cfg.ma
            .load(&mut self.ma_y, |k| at(back_m(k + 1, fir_delay)).y_m);
        // The histories get one entry per missing fix, oldest first, as filling would give:
        // the dead-reckoned position then, and the filters' output then. Of the dead-reckoning
        // history only the entries the delay compensation can still read are written (it reads
        // `group_delay` and one more fixes back; older entries only get older).
        let odo = self.odo_now;
        // Only those few entries: the chord comparison waits for a history of its own.
        self.odo_valid = 0;
        let odo_entries = (missing as usize).min(ODO_LEN);
        let odo_read = (math::max(cfg.group_delay_fixes, 0.0) as usize + 2).min(odo_entries);
        self.odo_head = (self.odo_head + odo_entries - odo_read) % ODO_LEN;
        for k in (1..=odo_read).rev() {
            let back = back_m(k, 0.0);
            self.odo_head = (self.odo_head + 1) % ODO_LEN;
            if let Some(slot) = self.odo_at_fix.get_mut(self.odo_head) {
                *slot = Xy {
                    x_m: odo.x_m - back * s,
                    y_m: odo.y_m - back * c,
                };
            }
        }
        // The track's entries, oldest first: each one step further along the heading than the
        // one before (added, not recomputed: the tick's dearest loop when the gap is long).
        let entries = (missing as usize).min(TRACK_LEN);
        let mut p = at(back_m(entries, cfg.group_delay_fixes));
        let (dx, dy) = (step_m * s, step_m * c);
        for _ in 0..entries {
            self.track_head = (self.track_head + 1) % TRACK_LEN;
            if let Some(slot) = self.track.get_mut(self.track_head) {
                *slot = p;
            }
            p.x_m += dx;
            p.y_m += dy;
        }
        self.filtered = Some(at(back_m(1, cfg.group_delay_fixes)));
        self.fixes = self.fixes.saturating_add(missing);
    }

    /// Dead-reckoned position `k` fixes ago (0 = the latest fix); `None` if not recorded yet.
    fn odo_fixes_ago(&self, k: usize) -> Option<Xy> {
        if k >= ODO_LEN || (k as u32) >= self.fixes {
            return None;
        }
        self.odo_at_fix
            .get((self.odo_head + ODO_LEN - k) % ODO_LEN)
            .copied()
    }

    /// The rear axle now: [`Self::antenna_position`] moved back by the lever arm (ahead along
    /// the heading `(sin, cos)`, left along `(-cos, sin)`). `None` without a position or a
    /// heading.
    pub fn position(&self, cfg: &EstimatorConfig) -> Option<Xy> {
        let antenna = self.antenna_position(cfg)?;
        let (s, c) = math::sin_cos(self.heading_rad?);
        Some(Xy {
            x_m: antenna.x_m - cfg.antenna_ahead_m * s + cfg.antenna_left_m * c,
            y_m: antenna.y_m - cfg.antenna_ahead_m * c - cfg.antenna_left_m * s,
        })
    }

    /// Where dead reckoning puts the antenna `age_s` before it was at `antenna` (straight back
    /// along this tick's heading at `speed_mps`): the stand-in for a missing fix.
    pub fn dead_reckoned_back(&self, antenna: Xy, age_s: f32, speed_mps: f32) -> Xy {
        let (s, c) = self.heading_sin_cos;
        let back_m = speed_mps * age_s;
        Xy {
            x_m: antenna.x_m - back_m * s,
            y_m: antenna.y_m - back_m * c,
        }
    }

    /// The antenna now: the filtered position moved forward by dead reckoning,
    /// `filtered + (odo_now - odo(delayed fix))`. `None` until the filters have seen enough
    /// fixes to be past their start-up transient.
    pub fn antenna_position(&self, cfg: &EstimatorConfig) -> Option<Xy> {
        let filtered = self.filtered?;
        if (self.fixes as f32) < cfg.group_delay_fixes * 2.0 {
            return None;
        }
        let d = math::max(cfg.group_delay_fixes, 0.0);
        let k0 = d as usize; // floor: d >= 0
        let w = d - k0 as f32;
        let a = self.odo_fixes_ago(k0)?;
        let b = self.odo_fixes_ago(k0 + 1).unwrap_or(a);
        let odo_then = Xy {
            x_m: a.x_m + (b.x_m - a.x_m) * w,
            y_m: a.y_m + (b.y_m - a.y_m) * w,
        };
        Some(Xy {
            x_m: filtered.x_m + (self.odo_now.x_m - odo_then.x_m),
            y_m: filtered.y_m + (self.odo_now.y_m - odo_then.y_m),
        })
    }

    /// Pulls the heading towards the antenna's course (rad, clockwise from north) measured
    /// `age_s` ago, given the current speed (> 0) and rates. The antenna's course leads the
    /// heading by `atan((antenna_ahead * yaw_rate + rear_side) / (v + antenna_left * yaw_rate))`
    /// (the rear axle's slip plus the lever arm's swing), with the rates of then; that is
    /// removed first, and the course is carried to now by the heading change the dead reckoning
    /// integrated since (`swept_since`; carrying it with the current yaw rate instead
    /// lags the truth in every transient, e.g. 0.05 rad in a lane change at 10 m/s with a
    /// 0.47 s old course). The first course initialises the heading. Returns the heading the
    /// course measured now (the course carried to now, its lead removed).
    pub fn correct_heading(
        &mut self,
        cfg: &EstimatorConfig,
        course_rad: f32,
        age_s: f32,
        speed_mps: f32,
        rates: Rates,
    ) -> f32 {
        let course_now = self.course_now(cfg, course_rad, age_s, speed_mps, rates);
        match self.heading_rad {
            None => {
                self.heading_rad = Some(course_now);
                self.heading_var_rad2 = HEADING_INITIAL_VAR_RAD2;
            }
            Some(h) => self.turn_heading(h, cfg.course_gain * math::wrap_pi(course_now - h)),
        }
        course_now
    }

    /// The antenna's course measured `age_s` ago, its lead removed and carried to now
    /// ([`Self::correct_heading`]).
    fn course_now(
        &self,
        cfg: &EstimatorConfig,
        course_rad: f32,
        age_s: f32,
        speed_mps: f32,
        rates: Rates,
    ) -> f32 {
        // The antenna's speed along the heading; the course says nothing when it is not ahead.
        // The rates when the course was measured: the sweep over a window around then.
        let turned = self.swept_since(age_s, rates).turned_rad;
        let half_window_s = math::min(age_s, LEAD_WINDOW_S);
        let window = self
            .swept_since(age_s + LEAD_WINDOW_S, rates)
            .minus(self.swept_since(age_s - half_window_s, rates));
        let window_s = LEAD_WINDOW_S + half_window_s;
        let (yaw_then_rps, side_then_mps) =
            (window.turned_rad / window_s, window.slid_m / window_s);
        let antenna_along_mps = speed_mps + cfg.antenna_left_m * yaw_then_rps;
        // Reversing (a negative speed): the course is the antenna's motion backwards, turned
        // half round by the caller, and the same lead (along and across both change sign).
        let ahead = speed_mps > 0.0 && antenna_along_mps > 0.0;
        let behind = speed_mps < 0.0 && antenna_along_mps < 0.0;
        let lead_rad = if ahead || behind {
            math::atan((cfg.antenna_ahead_m * yaw_then_rps + side_then_mps) / antenna_along_mps)
        } else {
            0.0
        };
        math::wrap_pi(course_rad - lead_rad + turned)
    }

    /// [`Self::correct_heading`] with the receiver's course over ground, and the heading's
    /// variance updated for it (the same scalar filter as the chords',
    /// [`Self::correct_heading_on_track`], at the course gain): the course's error is
    /// [`COG_NOISE_MPS`] over the speed, and one course pulls the heading on every tick until
    /// the next one comes, so its variance counts once per tick of the receiver's period.
    /// Without it the variance grew to its cap while a receiver's course held the heading
    /// to hundredths of a radian, and what reads it (the control pose's drift, the step
    /// gate in `super::gnss`) took the heading for unknown.
    pub fn correct_heading_on_cog(
        &mut self,
        cfg: &EstimatorConfig,
        course_rad: f32,
        age_s: f32,
        speed_mps: f32,
        rates: Rates,
    ) -> CogCorrection {
        let Some(heading) = self.heading_rad else {
            return CogCorrection::NoHeading;
        };
        if self.cog_scattered {
            // While the courses scatter they only teach the median: as received, neither
            // carried to now (a course is at most a period old: 0.01 rad at 100 Hz and
            // 1 rad/s) nor its lead (the antenna's swing in a turn) taken off. The tick
            // corrects the heading on the chords instead, and does not pay for both (the
            // estimating tick's bound).
            let innovation = math::wrap_pi(course_rad - heading);
            self.learn_cog_scatter(innovation);
            return CogCorrection::Scattered;
        }
        let course_now = self.course_now(cfg, course_rad, age_s, speed_mps, rates);
        let ticks = math::max(cfg.gnss_period_s / crate::SAMPLE_PERIOD_S, 1.0);
        let sigma = COG_NOISE_MPS / math::max(speed_mps.abs(), cfg.course_min_speed_mps);
        let cog_var = sigma * sigma * ticks;
        let innovation = math::wrap_pi(course_now - heading);
        let mut var = self.heading_var_rad2;
        let limit = math::max(
            COG_GATE_SIGMAS * math::sqrt(var + cog_var),
            COG_GATE_MEDIANS * self.cog_median_rad,
        );
        // (Scattered from the next tick on, if so.)
        self.learn_cog_scatter(innovation);
        // `!(a <= b)`: a NaN course is refused.
        #[allow(clippy::neg_cmp_op_on_partial_ord)]
        if !(innovation.abs() <= limit) {
            if self.cog_refused_ticks < COG_REFUSED_TICKS_MAX {
                self.cog_refused_ticks += 1;
                return CogCorrection::Refused;
            }
            var = math::max(var, innovation * innovation);
        }
        self.cog_refused_ticks = 0;
        let gain = cfg.course_gain;
        self.turn_heading(heading, gain * innovation);
        self.heading_var_rad2 = math::min(
            (1.0 - gain) * (1.0 - gain) * var + gain * gain * cog_var,
            HEADING_MAX_VAR_RAD2,
        );
        CogCorrection::Applied {
            measured_rad: course_now,
        }
    }

    /// Courses that agreed with each other set the first heading (`super::gnss::COG_AGREEING`):
    /// they start as usable, their learnt median half the [`COG_USABLE_BELOW_RAD`] it would
    /// otherwise have to fall below (from [`COG_MEDIAN_START_RAD`], about 0.6 s of courses),
    /// and it rises from there with their differences from the heading. While they had to
    /// prove themselves, the chords alone corrected the heading, and at a crawl a chord that
    /// passed its baseline on the fixes' noise pulled it off by more than the courses then
    /// counted as usable: a SIL sweep's car at 2.1 m/s with exact courses judged them
    /// scattered against it for good (docs/findings.md, "Exact courses over ground").
    pub fn courses_agreed(&mut self) {
        self.cog_median_rad = 0.5 * COG_USABLE_BELOW_RAD;
        self.cog_scattered = false;
    }

    /// A course's difference from the heading, into the learnt median and the scattered
    /// state ([`COG_SCATTERED_ABOVE_RAD`], [`COG_USABLE_BELOW_RAD`]).
    fn learn_cog_scatter(&mut self, innovation_rad: f32) {
        self.cog_median_rad = math::median_step(
            self.cog_median_rad,
            innovation_rad * innovation_rad,
            COG_MEDIAN_STEP,
            COG_MEDIAN_MIN_RAD,
            COG_MEDIAN_MAX_RAD,
        );
        self.cog_scattered = if self.cog_scattered {
            self.cog_median_rad >= COG_USABLE_BELOW_RAD
        } else {
            self.cog_median_rad > COG_SCATTERED_ABOVE_RAD
        };
        if self.cog_scattered {
            self.cog_refused_ticks = 0;
        }
    }

    /// The heading moved by a course correction, which is remembered for
    /// [`Self::correct_heading_on_track`].
    fn turn_heading(&mut self, heading_rad: f32, correction_rad: f32) {
        self.heading_rad = Some(math::wrap_pi(heading_rad + correction_rad));
        self.corrected_rad = math::wrap_pi(self.corrected_rad + correction_rad);
    }

    /// The course corrections applied over the last `age_s` (rad).
    fn corrected_since(&self, age_s: f32) -> f32 {
        let since_tick = self.turned.get(self.turned_head).map_or(0.0, |now| {
            math::wrap_pi(self.corrected_rad - now.corrected_rad)
        });
        math::wrap_pi(self.swept_since(age_s, Rates::default()).corrected_rad + since_tick)
    }

    /// Pulls the heading towards agreement between the filtered GNSS track and the dead
    /// reckoning over the same stretch: the chord of the track's last `track_span_fixes` fixes
    /// against the chord the dead reckoning drew between the instants those filtered fixes
    /// describe (each `group_delay_fixes` before its fix). The dead reckoning's chord is turned
    /// from the truth's by the heading's error over that stretch, whatever the car did along it
    /// (a course read off the chord itself is the course of the stretch's mean velocity, which
    /// after the turns of a lane change is hundredths of a radian from the course at its
    /// middle: `tests::heading_in_a_weave`); the
    /// corrections applied since its middle are already in the heading and are taken off. The
    /// lever arm and the rear axle's slide are in both chords.
    ///
    /// The gain is a scalar Kalman filter's on the heading's error variance, capped at the
    /// course gain: a chord's course error has the variance `chord_var_rad2` (its ends' error
    /// across it over its length, so 1 / length^2), the dead reckoning's drift adds
    /// `heading_drift_var_rad2` per tick (as the speed^2). A first course sets the variance
    /// large (0.5 rad), so a heading that starts off converges at the full gain; in steady
    /// state the gain is the course gain for chords of [`COURSE_FULL_GAIN_CHORD_M`] and longer
    /// (at 9.5 m/s and above) and falls as the chord's length squared below it, so that a
    /// standard receiver's chords at a crawl no longer pull the heading about (0.1-0.14 rad
    /// off the truth at 2-3 m/s with the full gain; docs/findings.md).
    ///
    /// A steady state's small variance is only the filter's belief: when the dead reckoning
    /// turned without the car (a slide at full lock the lateral model did not see), the chords'
    /// error stays beyond [`CHORD_GATE_SIGMAS`] of what that variance and one chord's own error
    /// explain, and once it has for longer than one fix stays in the chords
    /// ([`chord_persist_ticks`]), the variance is raised to the error squared (as for a course
    /// over ground refused too long, [`Self::correct_heading_on_cog`]): the gain is back at the
    /// course gain's cap until the heading is. Before, a radian left by a slide at 3 m/s took
    /// 9 s to come within 0.1 rad (docs/findings.md).
    ///
    /// `since_fix_s`: time since the latest fix. Does nothing while either chord is shorter than
    /// `course_min_baseline_m` ([`TrackCorrection::ShortChord`]), and until the dead
    /// reckoning has a history with a heading as long as the chord plus the group delay (at the
    /// start, after a restart of the filters: [`TrackCorrection::NoHistory`];
    /// [`Self::correct_heading`] with [`Self::track_course`] then).
    pub fn correct_heading_on_track(
        &mut self,
        cfg: &EstimatorConfig,
        since_fix_s: f32,
    ) -> TrackCorrection {
        let Some(heading) = self.heading_rad else {
            return TrackCorrection::NoHistory;
        };
        let span = (cfg.track_span_fixes as usize).clamp(1, TRACK_LEN - 1);
        let delay = math::max(cfg.group_delay_fixes, 0.0);
        let k0 = delay as usize; // floor: delay >= 0
        let w = delay - k0 as f32;
        if (self.odo_valid as usize) < k0 + span + 2 || (self.fixes as usize) < span + 2 * k0 {
            return TrackCorrection::NoHistory;
        }
        let odo_at = |k: usize| -> Option<Xy> {
            let a = self.odo_fixes_ago(k)?;
            let b = self.odo_fixes_ago(k + 1)?;
            Some(Xy {
                x_m: a.x_m + (b.x_m - a.x_m) * w,
                y_m: a.y_m + (b.y_m - a.y_m) * w,
            })
        };
        let (Some(now), Some(then), Some(odo_now), Some(odo_then)) = (
            self.track.get(self.track_head),
            self.track
                .get((self.track_head + TRACK_LEN - span) % TRACK_LEN),
            odo_at(k0),
            odo_at(k0 + span),
        ) else {
            return TrackCorrection::NoHistory;
        };
        let (gx, gy) = (now.x_m - then.x_m, now.y_m - then.y_m);
        let (dx, dy) = (odo_now.x_m - odo_then.x_m, odo_now.y_m - odo_then.y_m);
        let min2 = cfg.course_min_baseline_m * cfg.course_min_baseline_m;
        if gx * gx + gy * gy < min2 || dx * dx + dy * dy < min2 {
            return TrackCorrection::ShortChord;
        }
        // The angle from the dead reckoning's chord to the track's, clockwise (headings are
        // clockwise from north: atan2(east, north)).
        let error_then = math::atan2(dy * gx - dx * gy, dx * gx + dy * gy);
        let age_s = (span as f32 * 0.5 + delay) * cfg.gnss_period_s + since_fix_s;
        let error_now = math::wrap_pi(error_then - self.corrected_since(age_s));
        // A scalar Kalman update of the heading's variance with the gain capped at the
        // course gain (Joseph form: right for any gain).
        let chord_var = chord_var_rad2(cfg.course_gain, dx * dx + dy * dy);
        let mut var = self.heading_var_rad2;
        // The chords' error persistently beyond what the heading's variance and one chord's
        // own error explain: the heading is that far off (a slide the lateral model did not
        // see), and the variance says so, as for a course over ground refused too long. (A
        // NaN error is never beyond.)
        let spread_var = var + chord_var * (1.0 / CHORD_CORRELATED_TICKS);
        if error_now * error_now > CHORD_GATE_SIGMAS * CHORD_GATE_SIGMAS * spread_var {
            self.chord_beyond_ticks = self.chord_beyond_ticks.saturating_add(1);
            if f32::from(self.chord_beyond_ticks) >= chord_persist_ticks(cfg, span) {
                var = math::min(math::max(var, error_now * error_now), HEADING_MAX_VAR_RAD2);
                self.chord_beyond_ticks = 0;
                // Whatever the error, the turn that confirms a heading starts again.
                self.confirming_turn_rad = 0.0;
                if error_now.abs() > AGAINST_THE_TRACK_RAD {
                    self.direction_ambiguous = true;
                }
            }
        } else {
            self.chord_beyond_ticks = 0;
        }
        let gain = math::min(cfg.course_gain, var / (var + chord_var));
        self.heading_var_rad2 = (1.0 - gain) * (1.0 - gain) * var + gain * gain * chord_var;
        self.turn_heading(heading, gain * error_now);
        TrackCorrection::Applied {
            measured_rad: math::wrap_pi(heading + error_now),
        }
    }

    /// Course of the filtered track over the last `track_span_fixes` fixes, with its age in fixes
    /// (the chord's midpoint plus the filter delay); `None` if the car moved too little.
    pub fn track_course(&self, cfg: &EstimatorConfig) -> Option<(f32, f32)> {
        let span = (cfg.track_span_fixes as usize).clamp(1, TRACK_LEN - 1);
        if (self.fixes as usize) < span + (cfg.group_delay_fixes as usize) * 2 {
            return None;
        }
        let now = self.track.get(self.track_head)?;
        let then = self
            .track
            .get((self.track_head + TRACK_LEN - span) % TRACK_LEN)?;
        let (dx, dy) = (now.x_m - then.x_m, now.y_m - then.y_m);
        if dx * dx + dy * dy < cfg.course_min_baseline_m * cfg.course_min_baseline_m {
            return None;
        }
        let age_fixes = span as f32 * 0.5 + cfg.group_delay_fixes;
        Some((math::atan2(dx, dy), age_fixes))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// After a gap longer than the filters' memory, restarting them on the dead-reckoned track
    /// in one step gives what filling the missing fixes one by one gives (the FIR and the
    /// moving average are pure delays on that track), to f32 rounding; so do the fixes after.
    #[test]
    fn restart_on_the_track_is_filling_the_gap() {
        let cfg = EstimatorConfig::design(100.0, 1.478, 0.0).unwrap();
        let (v, heading) = (10.0f32, 0.7f32);
        let mut warm = EstimatorState::default();
        warm.correct_heading(&cfg, heading, 0.0, v, Rates::default());
        let (s, c) = (heading.sin(), heading.cos());
        let mut t = 0.0f32;
        let at = |t: f32| Xy {
            x_m: 20.0 + v * t * s,
            y_m: -5.0 + v * t * c,
        };
        for _ in 0..100 {
            warm.propagate(&cfg, v, Rates::default(), 0.02);
            t += 0.02;
            for age in [0.01f32, 0.0] {
                warm.add_fix(&cfg, at(t - age), age, v);
            }
        }
        // 40 fixes missing, then the fix of this tick (age 0).
        let missing = 40u32;
        warm.propagate(&cfg, v, Rates::default(), 0.02);
        t += 0.02;
        let antenna = warm.antenna_position(&cfg).unwrap();
        let mut filled = warm.clone();
        for k in (1..=missing).rev() {
            let age_k = k as f32 * cfg.gnss_period_s;
            let p = filled.dead_reckoned_back(antenna, age_k, v);
            filled.add_fix(&cfg, p, age_k, v);
        }
        let mut restarted = warm.clone();
        restarted.restart_on_track(&cfg, antenna, 0.0, missing, v);
        assert_eq!(filled.fixes(), restarted.fixes());
        for step in 0..40 {
            for state in [&mut filled, &mut restarted] {
                if step > 0 {
                    state.propagate(&cfg, v, Rates::default(), 0.01);
                }
                state.add_fix(&cfg, at(t + step as f32 * 0.01), 0.0, v);
            }
            let (a, b) = (
                filled.position(&cfg).unwrap(),
                restarted.position(&cfg).unwrap(),
            );
            let d = ((a.x_m - b.x_m).powi(2) + (a.y_m - b.y_m).powi(2)).sqrt();
            assert!(d < 1e-4, "fix {step}: {d} m, {a:?} vs {b:?}");
        }
    }

    /// A car at 5 m/s on a straight line, exact fixes, a gap of a few fixes or many, then the
    /// filters restarted on the dead-reckoned track as the GNSS stage restarts them: the antenna
    /// stays on the car at every receiver rate. At 4 and 10 Hz the moving average's window is
    /// shorter than its storage, and a restart that filled all of the storage put the antenna
    /// 5-36 m behind the car for good (docs/findings.md); at 100 Hz it is all of it.
    #[test]
    fn a_restart_on_the_track_keeps_the_antenna_on_the_car_at_every_rate() {
        for (rate, gap_s) in [
            (4.0f32, 0.9f32),
            (4.0, 2.9),
            (5.0, 0.7),
            (10.0, 0.35),
            (10.0, 3.9),
            (100.0, 0.035),
            (100.0, 0.45),
        ] {
            let period = 1.0 / rate;
            let cfg = EstimatorConfig::design(f64::from(rate), 1.0, 0.0).unwrap();
            let (v, heading) = (5.0f32, 1.25f32);
            let mut st = EstimatorState::default();
            st.correct_heading(&cfg, heading, 0.0, v, Rates::default());
            let (s, c) = (heading.sin(), heading.cos());
            let at = |t: f32| Xy {
                x_m: v * t * s,
                y_m: v * t * c,
            };
            let (mut next_fix, mut last_fix) = (period, None::<f32>);
            let (mut worst, mut restarted) = (0.0f32, false);
            for tick in 1..900 {
                let t = tick as f32 * 0.02;
                st.propagate(&cfg, v, Rates::default(), 0.02);
                while t + 1e-4 >= next_fix {
                    let fix_t = next_fix;
                    next_fix += period;
                    if (10.0..10.0 + gap_s).contains(&fix_t) {
                        continue;
                    }
                    let age = t - fix_t;
                    if let (Some(prev), Some(antenna)) = (last_fix, st.antenna_position(&cfg)) {
                        let missing = ((fix_t - prev) / period + 0.5) as u32 - 1;
                        if missing > 0 {
                            st.restart_on_track(&cfg, antenna, age, missing, v);
                            restarted = true;
                        }
                    }
                    st.add_fix(&cfg, at(fix_t), age, v);
                    last_fix = Some(fix_t);
                }
                if let (true, Some(p)) = (t > 9.0, st.antenna_position(&cfg)) {
                    let truth = at(t);
                    worst = worst.max((p.x_m - truth.x_m).hypot(p.y_m - truth.y_m));
                }
            }
            assert!(restarted, "{rate} Hz");
            assert!(worst < 0.01, "{rate} Hz, gap {gap_s} s: {worst} m off");
        }
    }

    /// A car at 10 m/s due east, exact GNSS at 100 Hz, ticks at 50 Hz: the compensated filter
    /// output is on the car (the uncompensated one trails by ~1.45 m).
    #[test]
    fn compensation_removes_the_filter_lag() {
        let cfg = EstimatorConfig::design(100.0, 0.0, 0.0).unwrap();
        let mut st = EstimatorState::default();
        st.correct_heading(
            &cfg,
            core::f32::consts::FRAC_PI_2,
            0.0,
            10.0,
            Rates::default(),
        );
        let v = 10.0;
        let mut t = 0.0f32;
        for _tick in 0..200 {
            st.propagate(&cfg, v, Rates::default(), 0.02);
            t += 0.02;
            // two fixes per tick, at t - 0.01 and t
            for age in [0.01f32, 0.0] {
                let fix = Xy {
                    x_m: v * (t - age),
                    y_m: 0.0,
                };
                st.add_fix(&cfg, fix, age, v);
            }
        }
        let p = st.position(&cfg).unwrap();
        assert!((p.x_m - v * t).abs() < 0.02, "{p:?} vs {}", v * t);
        let lag = v * t - st.filtered.unwrap().x_m;
        assert!(
            (lag - v * cfg.group_delay_fixes * 0.01).abs() < 0.05,
            "{lag}"
        );
    }

    /// A steady right turn at 10 m/s on a 20 m radius whose rear axle slides 0.042 rad out of
    /// the turn (the CAT Vehicle's linear-tyre slip at 5 m/s^2), exact GNSS at 100 Hz from an
    /// antenna 1.478 m ahead: told the slide, the heading estimate settles on the heading;
    /// told nothing (eq 8's no-slip rear axle), it settles on the rear axle's course, off by
    /// the slip angle.
    #[test]
    fn heading_in_a_sliding_turn() {
        let cfg = EstimatorConfig::design(100.0, 1.478, 0.0).unwrap();
        let (v, r, slip) = (10.0f32, 0.5f32, -0.042f32);
        let side = v * slip.tan();
        let run = |told: Rates| {
            let mut st = EstimatorState::default();
            // Truth, integrated finely: rear axle position and heading.
            let (mut x, mut y, mut psi) = (0.0f64, 0.0f64, 0.3f64);
            let antenna = |x: f64, y: f64, psi: f64| Xy {
                x_m: (x + 1.478 * psi.sin()) as f32,
                y_m: (y + 1.478 * psi.cos()) as f32,
            };
            st.correct_heading(&cfg, psi as f32, 0.0, v, told);
            for _tick in 0..500 {
                st.propagate(&cfg, v, told, 0.02);
                let mut fixes = [Xy::default(); 2];
                for fix in fixes.iter_mut() {
                    for _ in 0..10 {
                        let dt = 0.001f64;
                        let (s, c) = (psi.sin(), psi.cos());
                        x += dt * (f64::from(v) * s + f64::from(side) * c);
                        y += dt * (f64::from(v) * c - f64::from(side) * s);
                        psi += dt * f64::from(r);
                    }
                    *fix = antenna(x, y, psi);
                }
                st.add_fix(&cfg, fixes[0], 0.01, v);
                st.add_fix(&cfg, fixes[1], 0.0, v);
                if let Some((course, age_fixes)) = st.track_course(&cfg) {
                    st.correct_heading(&cfg, course, age_fixes * cfg.gnss_period_s, v, told);
                }
            }
            math::wrap_pi(st.heading_rad().unwrap() - psi as f32)
        };
        let yaw = |rear_side_mps| Rates {
            yaw_rps: r,
            rear_side_mps,
        };
        let told = run(yaw(side));
        assert!(told.abs() < 0.005, "told the slide: {told} rad");
        let untold = run(yaw(0.0));
        assert!(
            (untold - slip).abs() < 0.01,
            "not told: {untold} rad, the slip is {slip}"
        );
    }

    /// A weave at 14 m/s (heading 0.15 sin(2 pi t / 1.6 s): lane changes back and forth at
    /// 3.6 m/s^2 peak lateral acceleration), exact GNSS from an antenna 1.478 m ahead, the yaw
    /// rate told exactly, the heading started 0.05 rad off: the heading corrected by the
    /// chords compared settles on the heading without overshooting, at 100 Hz and with a 10 Hz
    /// receiver (whose chord steers the heading for five ticks: the corrections since are
    /// taken off); the course read off the chord (the mean velocity's over 0.63 s, not the
    /// course at the chord's middle) stays 0.02 rad off at 100 Hz and overshoots at 10 Hz.
    #[test]
    fn heading_in_a_weave() {
        let v = 14.0f32;
        let (amp, period) = (0.15f64, 1.6f64);
        let w = 2.0 * core::f64::consts::PI / period;
        let psi = |t: f64| amp * (w * t).sin();
        // Largest heading error after the first 2 s, and the error's largest overshoot below
        // zero while it settles (the start is 0.05 rad clockwise of the truth).
        let run = |chords: bool, rate_hz: f64| {
            let cfg = EstimatorConfig::design(rate_hz, 1.478, 0.0).unwrap();
            let mut st = EstimatorState::default();
            let (mut x, mut y, mut t) = (0.0f64, 0.0f64, 0.0f64);
            let antenna = |x: f64, y: f64, t: f64| Xy {
                x_m: (x + 1.478 * psi(t).sin()) as f32,
                y_m: (y + 1.478 * psi(t).cos()) as f32,
            };
            st.correct_heading(&cfg, 0.05, 0.0, v, Rates::default());
            let period_ms = libm::round(1000.0 / rate_hz) as u32;
            let (mut ms, mut last_fix_ms) = (0u32, 0u32);
            let (mut worst, mut undershoot) = (0.0f32, 0.0f32);
            for tick in 0..600 {
                let rates = Rates {
                    yaw_rps: (amp * w * (w * (t + 0.01)).cos()) as f32,
                    rear_side_mps: 0.0,
                };
                st.propagate(&cfg, v, rates, 0.02);
                for _ in 0..20 {
                    let dt = 0.001f64;
                    let h = psi(t + 0.5 * dt);
                    x += dt * f64::from(v) * h.sin();
                    y += dt * f64::from(v) * h.cos();
                    t += dt;
                    ms += 1;
                    if ms % period_ms == 0 {
                        let age_s = (20 * (tick + 1) - ms) as f32 * 1e-3;
                        st.add_fix(&cfg, antenna(x, y, t), age_s, v);
                        last_fix_ms = ms;
                    }
                }
                let since_fix_s = (ms - last_fix_ms) as f32 * 1e-3;
                let on_track = chords.then(|| st.correct_heading_on_track(&cfg, since_fix_s));
                if !matches!(
                    on_track,
                    Some(TrackCorrection::Applied { .. } | TrackCorrection::ShortChord)
                ) {
                    if let Some((course, age_fixes)) = st.track_course(&cfg) {
                        let age_s = age_fixes * cfg.gnss_period_s + since_fix_s;
                        st.correct_heading(&cfg, course, age_s, v, rates);
                    }
                }
                let error = math::wrap_pi(st.heading_rad().unwrap() - psi(t) as f32);
                undershoot = undershoot.min(error);
                if tick > 100 {
                    worst = worst.max(error.abs());
                }
            }
            (worst, undershoot)
        };
        let (chords, under) = run(true, 100.0);
        assert!(chords < 0.005, "chords compared, 100 Hz: {chords} rad");
        assert!(
            under > -0.005,
            "chords compared, 100 Hz: overshoot {under} rad"
        );
        // At 10 Hz the lowpass's 0.6 s window smooths the weave's track, which the dead
        // reckoning's chord is not: 0.012 rad left, against the chord's course's 0.027 rad with
        // a 0.017 rad overshoot.
        let (chords, under) = run(true, 10.0);
        let (course, course_under) = run(false, 10.0);
        assert!(
            chords < 0.6 * course,
            "10 Hz: chords {chords} rad, course {course} rad"
        );
        assert!(
            under > -0.005,
            "chords compared, 10 Hz: overshoot {under} rad"
        );
        assert!(
            course_under < -0.01,
            "the chord's course, 10 Hz: {course_under} rad"
        );
        let (course, _) = run(false, 100.0);
        assert!(course > 0.015, "the chord's course: {course} rad");
    }

    /// A standard receiver at parking-lot speed: 100 Hz fixes with 0.3 m of white noise and a
    /// 0.8 m bias wandering with a 60 s correlation (the CAT Vehicle's, paper II-A), the car at
    /// 3 m/s on a 40 m circle, its dead reckoning turning 0.002 rad/m too fast (a 0.3 deg
    /// steering error on a 2.6 m wheelbase). The heading set 0.5 rad off by a first course
    /// comes within 0.1 rad in 3 s (0.015-0.059 rad on these seeds: the filter's variance
    /// starts large, so does the gain; a gain falling with the chord's length alone left it
    /// 0.31-0.33 rad off), and after 10 s its RMS error is 0.021-0.032 rad, the largest
    /// 0.047-0.072 rad. With a constant gain (before) they were 0.043-0.050 and 0.12-0.13 rad:
    /// 1.9 m chords at full gain carry their ends' noise into the heading.
    #[test]
    fn heading_at_a_crawl_with_a_noisy_receiver() {
        let (v, radius, drift) = (3.0f64, 40.0f64, 0.002f64);
        let mut results = [(0.0f32, 0.0f32, 0.0f32); 3];
        for (seed, result) in results.iter_mut().enumerate() {
            let cfg = EstimatorConfig::design(100.0, 0.0, 0.0).unwrap();
            let mut st = EstimatorState::default();
            // A xorshift stream and Box-Muller normals: the same draw on every machine.
            let mut state = 0x9E37_79B9_7F4A_7C15u64 ^ (seed as u64 + 1);
            let mut uniform = move || {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
            };
            let mut normal = move || {
                let (u1, u2) = (uniform(), uniform());
                libm::sqrt(-2.0 * libm::log(u1)) * libm::cos(2.0 * core::f64::consts::PI * u2)
            };
            let (white, bias_sigma, bias_tau) = (0.3f64, 0.8f64, 60.0f64);
            let phi = libm::exp(-0.01 / bias_tau);
            let mut bias = [bias_sigma * normal(), bias_sigma * normal()];
            let yaw = v / radius;
            let truth = |t: f64| yaw * t;
            st.correct_heading(&cfg, 0.5, 0.0, v as f32, Rates::default());
            let (mut sum_sq, mut n, mut worst, mut at_3s) = (0.0f32, 0u32, 0.0f32, 0.0f32);
            for tick in 1..=3000u32 {
                let rates = Rates {
                    yaw_rps: (yaw + drift * v) as f32,
                    rear_side_mps: 0.0,
                };
                st.propagate(&cfg, v as f32, rates, 0.02);
                for k in 1..=2u32 {
                    // Fixes at 100 Hz, the second at the tick's instant.
                    let t = (tick as f64 - 1.0) * 0.02 + k as f64 * 0.01;
                    for b in &mut bias {
                        *b = phi * *b + bias_sigma * libm::sqrt(1.0 - phi * phi) * normal();
                    }
                    let (s, c) = (libm::sin(truth(t)), libm::cos(truth(t)));
                    // A circle through the origin, turning clockwise: centre `radius` east.
                    let fix = Xy {
                        x_m: (radius * (1.0 - c) + bias[0] + white * normal()) as f32,
                        y_m: (radius * s + bias[1] + white * normal()) as f32,
                    };
                    st.add_fix(&cfg, fix, (0.02 - k as f64 * 0.01) as f32, v as f32);
                }
                if st.correct_heading_on_track(&cfg, 0.0) == TrackCorrection::NoHistory {
                    if let Some((course, age_fixes)) = st.track_course(&cfg) {
                        let age_s = age_fixes * cfg.gnss_period_s;
                        st.correct_heading(&cfg, course, age_s, v as f32, rates);
                    }
                }
                let t = tick as f64 * 0.02;
                let error = math::wrap_pi(st.heading_rad().unwrap() - truth(t) as f32).abs();
                if tick == 150 {
                    at_3s = error;
                }
                if t > 10.0 {
                    sum_sq += error * error;
                    n += 1;
                    worst = worst.max(error);
                }
            }
            *result = (at_3s, libm::sqrtf(sum_sq / n as f32), worst);
        }
        for (seed, (at_3s, rms, worst)) in results.iter().enumerate() {
            assert!(*at_3s < 0.1, "seed {seed}: {at_3s} rad off after 3 s");
            assert!(
                *rms < 0.035 && *worst < 0.09,
                "seed {seed}: {rms} rad RMS, {worst} at most"
            );
        }
    }

    /// The sideways travel is kept wrapped to +-1024 m; a window that spans the wrap still
    /// measures the travel in it (a car circling for hours slides that far).
    #[test]
    fn sideways_travel_across_the_wrap() {
        let cfg = EstimatorConfig::design(100.0, 0.0, 0.0).unwrap();
        let mut st = EstimatorState::default();
        let rates = Rates {
            yaw_rps: 0.0,
            rear_side_mps: 3.0,
        };
        let mut crossed = false;
        for _ in 0..20_000 {
            st.propagate(&cfg, 20.0, rates, 0.02);
            let window = st.swept_since(0.5, rates);
            assert!(
                (window.slid_m - 1.5).abs() < 1e-2,
                "{} m over 0.5 s",
                window.slid_m
            );
            let now = st.turned[st.turned_head].slid_m;
            crossed |= now < 0.0;
        }
        assert!(crossed, "the integral wrapped");
    }

    /// Courses that agreed set the first heading and are used from the next tick on (a fresh
    /// state leaves them to the chords until their scatter is learnt, about 0.6 s); courses
    /// that scatter by half a radian after agreeing are left to the chords within a second.
    #[test]
    fn agreeing_courses_are_used_at_once_and_dropped_once_they_scatter() {
        let cfg = EstimatorConfig::design(5.0, 0.0, 0.0).unwrap();
        let v = 2.1f32;
        let straight = Rates::default();
        for agreed in [false, true] {
            let mut st = EstimatorState::default();
            if agreed {
                st.courses_agreed();
            }
            st.correct_heading(&cfg, 1.0, 0.0, v, straight);
            st.propagate(&cfg, v, straight, 0.02);
            let taken = st.correct_heading_on_cog(&cfg, 1.01, 0.0, v, straight);
            assert_eq!(
                matches!(taken, CogCorrection::Applied { .. }),
                agreed,
                "agreed {agreed}: {taken:?}"
            );
        }
        let mut st = EstimatorState::default();
        st.courses_agreed();
        st.correct_heading(&cfg, 1.0, 0.0, v, straight);
        let used_late = (0..150u32)
            .filter(|&tick| {
                st.propagate(&cfg, v, straight, 0.02);
                let wild = 1.0 + 0.5 * libm::sinf(tick as f32 * 2.3);
                let taken = st.correct_heading_on_cog(&cfg, wild, 0.0, v, straight);
                tick >= 50 && matches!(taken, CogCorrection::Applied { .. })
            })
            .count();
        assert_eq!(used_late, 0);
    }

    /// A receiver's course over ground: used once its scatter about the heading is learnt to
    /// be small (within a second), it holds the heading's variance to what it measures (the
    /// variance grew to its cap before); a course far off for a few ticks (a receiver that
    /// differences a multipath glitch of its own fixes) does not turn the heading; a heading
    /// that is off by half a radian follows the courses after half a second of them; courses
    /// that scatter by half a radian are not used.
    #[test]
    fn courses_over_ground_are_gated_against_the_heading() {
        let cfg = EstimatorConfig::design(20.0, 0.0, 0.0).unwrap();
        let v = 6.0f32;
        let straight = Rates::default();
        let mut st = EstimatorState::default();
        assert_eq!(
            st.correct_heading_on_cog(&cfg, 1.0, 0.0, v, straight),
            CogCorrection::NoHeading
        );
        st.correct_heading(&cfg, 1.0, 0.0, v, straight);
        // A receiver's courses scattered by 0.03 rad about the truth (1 rad) for 4 s.
        let scatter = |tick: u32| 0.03 * libm::sinf(tick as f32 * 1.7);
        for tick in 0..200 {
            st.propagate(&cfg, v, straight, 0.02);
            let taken = st.correct_heading_on_cog(&cfg, 1.0 + scatter(tick), 0.0, v, straight);
            if tick >= 50 {
                assert!(
                    matches!(taken, CogCorrection::Applied { .. }),
                    "tick {tick}: a healthy course refused: {taken:?}"
                );
            }
        }
        let sigma = math::sqrt(st.heading_var_rad2());
        assert!(sigma < 0.05, "{sigma}");
        assert!((st.heading_rad().unwrap() - 1.0).abs() < 0.01);
        // Three ticks of a course 1.2 rad off (a glitch of 1 m to the side at 20 Hz and 6 m/s,
        // differenced): refused, the heading unmoved.
        for _ in 0..3 {
            st.propagate(&cfg, v, straight, 0.02);
            assert_eq!(
                st.correct_heading_on_cog(&cfg, 2.2, 0.0, v, straight),
                CogCorrection::Refused
            );
        }
        assert!((st.heading_rad().unwrap() - 1.0).abs() < 0.01);
        // The heading off by 0.5 rad (say a wrong steering gain turned it): the courses are
        // refused or left to the chords, never pulled in half a radian at once; once the chords
        // (the node's; here set by hand) have the heading back, the courses are used again
        // within 1.5 s.
        st.heading_rad = Some(0.5);
        for tick in 0..100 {
            st.propagate(&cfg, v, straight, 0.02);
            let before = st.heading_rad().unwrap();
            st.correct_heading_on_cog(&cfg, 1.0 + scatter(tick), 0.0, v, straight);
            let step = (st.heading_rad().unwrap() - before).abs();
            assert!(step < 0.03, "tick {tick}: {step}");
        }
        st.heading_rad = Some(1.0);
        let back = (0..100u32).find(|&tick| {
            st.propagate(&cfg, v, straight, 0.02);
            let taken = st.correct_heading_on_cog(&cfg, 1.0 + scatter(tick), 0.0, v, straight);
            matches!(taken, CogCorrection::Applied { .. })
        });
        assert!(matches!(back, Some(t) if t < 75), "{back:?}");
        // Courses scattered by half a radian (differenced from fixes with 0.5 m of noise at
        // 10 Hz and 6 m/s): left to the chords within a second, the heading not pulled about.
        let heading = st.heading_rad().unwrap();
        let mut used_late = 0;
        for tick in 0..250u32 {
            st.propagate(&cfg, v, straight, 0.02);
            let wild = 1.0 + 0.5 * libm::sinf(tick as f32 * 2.3) * libm::cosf(tick as f32 * 0.37);
            let taken = st.correct_heading_on_cog(&cfg, wild, 0.0, v, straight);
            if tick >= 50 && matches!(taken, CogCorrection::Applied { .. }) {
                used_late += 1;
            }
        }
        assert_eq!(used_late, 0);
        let moved = (st.heading_rad().unwrap() - heading).abs();
        assert!(moved < 0.05, "{moved}");
    }
}
