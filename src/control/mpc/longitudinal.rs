//! The speed plan: the speed commands of the next 2 s, from the identified speed model (eq 5:
//! commanded speed -> measured speed, 2nd order, 0.42 s input delay), as a condensed QP.
//!
//! The decision is the change `du_j` of the command against the last one sent, held over knot
//! `j` ([`KNOT_STEPS`] MPC steps = 0.2 s; [`KNOTS`] knots cover [`PLAN_STEPS`]). The model is
//! linear, so the predicted speed at MPC step `k` (0.1 s) is
//! ```text
//! v_k = f_k + bias + sum_j p_{k - 2j} du_j
//! ```
//! with `f` the free response (a copy of the node's model state, delay line included, rolled
//! forward with the last command held: the commands already in flight decide the first 0.42 s
//! exactly, which is how the delay is handled) and `p` the response to a command held over one
//! knot (from the model, once, when the configuration is built). `p_m` is zero while the
//! command is still in the delay line, so the first four steps are not the plan's to change.
//! `f + bias` is taken as no less than 0: a car does not reverse
//! ([`SpeedPlanner::free_response`]).
//!
//! The bias (measured minus modelled speed, held over the horizon: the model's error and the
//! disturbances it does not know, a grade, a load) is low-passed for planning the commands
//! ([`SpeedTuning::bias_time_constant_s`], [`SpeedStart::planning_bias_mps`]); the predicted
//! speeds, which the steering plan linearises at, keep it as measured. Used raw, a car whose
//! speed loop answers faster than its model says turns each correction into a new bias of the
//! opposite sign within the model's delay, and the plan chases it. On a car with a 0.3 s dead
//! time and a 0.6 s lag, driven by eq 5's 0.42 s and 1.2 s, the commands swung between 0 and
//! 14.5 m/s on a 5 m/s path and the car between 3.2 and 8.0 m/s; filtered over 1.5 s, 4.75 to
//! 5.0 m/s (`scripts/sil-sim.py`; docs/controller.md, "A speed loop the model does not
//! describe").
//!
//! Cost `1/2 sum w_v (v_k - r_k)^2 + 1/2 sum w_du (du_j - du_{j-1})^2` (`du_{-1} = 0`: the change
//! against the command sent last); hard bounds `floor <= u_j <= top`: the band about the
//! steady-state commands that hold the plan's targets, as wide as a lead while the model
//! predicts the car and narrower once it misses (`SpeedPlanner::command_band`), within 0 and
//! the maximum speed, and in the stop at the path's end from 0 to the last command or the creep
//! (`SpeedPlanner::plan`); a soft
//! (exact-penalty) bound `v_k <= min(target_k + SPEED_LIMIT_SLACK_MPS, max_speed)` on the
//! prediction: the path's target is a limit as well as a reference. The reference `r` is the
//! path's target speed (its speed envelope, which brakes for every lower target ahead, beyond
//! the horizon too: `crate::control::path`) reached within the acceleration and deceleration
//! limits from the current speed, never past the path's end and not rising in the stop
//! (`SpeedPlanner::reference`).
//!
//! Solver: ADMM on the condensed problem (constraints `z = [du; P du]`). Its matrix
//! `H + rho_u I + rho_v P'P` never changes, so its inverse is computed once, in f32, when the
//! configuration is built; an iteration is three small matrix-vector products. Knots of 0.2 s
//! rather than one command per 0.1 s step: a quarter of the work per iteration, and the speed
//! loop (time constant about 1.2 s for eq 5) cannot follow a finer command anyway.
use nalgebra::{SMatrix, SVector};

use super::{clamp, finite_or, max, min, PLAN_STEPS, TICKS_PER_STEP};
use crate::math;

/// Speed to which the reference may still rise in the stop at a path's end, m/s
/// ([`SpeedPlanner::reference`]): a car at rest short of the end creeps on to it.
pub const STOP_CREEP_MPS: f32 = 1.0;
/// The stop at a path's end ends when the end moves this much farther away, m (a longer path).
pub const STOP_END_MOVED_M: f32 = 1.0;
/// MPC steps per command knot (0.2 s).
pub const KNOT_STEPS: usize = 2;
/// Command knots over the plan.
pub const KNOTS: usize = PLAN_STEPS / KNOT_STEPS;
/// A knot's length, s.
pub const KNOT_S: f32 = KNOT_STEPS as f32 * super::STEP_S;
use crate::model::{SsBlock, SsBlockState};

/// ADMM penalty of the command bounds (per (m/s)^2).
const RHO_COMMAND: f32 = 1.0;
/// ADMM penalty of the predicted-speed bound (per (m/s)^2).
const RHO_SPEED: f32 = 1.0;
/// Exact-penalty weight of the predicted-speed bound, cost per m/s over.
const SPEED_BOUND_WEIGHT: f32 = 100.0;
/// How far a predicted speed may exceed the path's target before the exact penalty of
/// [`SPEED_BOUND_WEIGHT`] holds it, m/s.
pub const SPEED_LIMIT_SLACK_MPS: f32 = 0.2;
/// How far above a lower target ahead (its [`SPEED_LIMIT_SLACK_MPS`] included) the car must be
/// for the speed plan to slow for it beyond its horizon ([`SlowAhead`]), m/s: closer to it,
/// the plan's limit rows within the horizon take the rest, so that a car a few hundredths over
/// a target a few metres ahead is not commanded to a standstill.
pub const SLOW_AHEAD_EXCESS_MPS: f32 = 0.3;
/// The share of the target where the car is that a lower target ahead must be below for the
/// speed plan to slow for it beyond its horizon ([`SlowAhead`]): a half. The bound asks the
/// model's car to reach the target with every later command 0, and eq 5's car, slowed that
/// way to a target not far below its speed, goes on slowing well below it (from 12 to 8 m/s:
/// down to 5.0-6.1 m/s, against 7.4-7.6 without the bound); a step to less than half the
/// speed is where the plan's horizon and the path's envelope miss most
/// (`mpc_properties::the_speed_plan_slows_for_a_lower_target_beyond_its_horizon`).
pub const SLOW_AHEAD_SHARE: f32 = 0.5;

/// How far the model's predictions may miss before the commands' lead is no longer trusted,
/// m/s: the largest recent gap between the speed bias and its low-passed value
/// ([`ModelFit::mismatch_mps`]) takes the band from the full lead (no gap) to its narrowest
/// (this gap or more) ([`SpeedPlanner::command_band`]).
pub const MISMATCH_NO_TRUST_MPS: f32 = 1.0;

/// The largest gap of [`MISMATCH_NO_TRUST_MPS`] is forgotten with this time constant, s.
pub const MISMATCH_TIME_CONSTANT_S: f32 = 3.0;

/// The offset the band's centre corrects for ([`ModelFit::offset_mps`]): the speed bias through
/// a lowpass of this time constant, s, fed only while the bias is steady.
pub const OFFSET_TIME_CONSTANT_S: f32 = 3.0;

/// The bias counts as steady while it is within this of its low-passed value (the planning
/// bias), m/s: a car holding a speed, not one in a transient its model does not describe.
pub const OFFSET_STEADY_MPS: f32 = 0.25;

/// Speed-plan weights and limits. Immutable configuration.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SpeedTuning {
    /// Weight of the speed error, per (m/s)^2.
    pub speed_weight: f32,
    /// Weight of a change of the command from one step to the next, per (m/s)^2.
    pub command_change_weight: f32,
    /// Fastest the plan may go (and command), m/s. [`super::MpcConfig::for_node`] lowers it
    /// to the model file's `max_speed_mps`; the built-in tuning leaves that the limit.
    pub max_speed_mps: f32,
    /// Acceleration the reference assumes, m/s^2.
    pub accel_mps2: f32,
    /// Deceleration the reference assumes, m/s^2.
    pub decel_mps2: f32,
    /// ADMM iterations per solve (fixed).
    pub iterations: u16,
    /// Time constant of the first-order lowpass on the speed bias (measured minus modelled
    /// speed), s; 0: the bias as measured each tick.
    pub bias_time_constant_s: f32,
    /// How far a command may go above the steady-state command that holds the plan's highest
    /// target speed, m/s (the lead a sluggish speed loop needs to follow the reference's
    /// acceleration; infinite: no bound; docs/controller.md, "A speed loop the model does not
    /// describe").
    pub command_lead_mps: f32,
    /// Half the width of the band the commands stay in about the steady-state commands that
    /// hold the plan's targets, for a car at its target speed, m/s
    /// ([`SpeedPlanner::command_band`]; infinite: no band, the commands from 0 to the
    /// steady-state command plus the lead).
    pub command_band_mps: f32,
    /// How much wider the band is per m/s the car is off the targets, up to
    /// [`SpeedTuning::command_lead_mps`].
    pub command_band_per_mps: f32,
}

/// Why a speed planner cannot be built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SpeedPlanError {
    /// A weight or limit is not positive and finite.
    BadTuning,
    /// The model gives no response to a command within the horizon (or a non-finite one).
    NoResponse,
    /// The KKT matrix is not positive definite (cannot happen for positive weights).
    NotPositiveDefinite,
}

/// The speed planner: model responses and the inverse of its ADMM matrix.
#[derive(Clone, Debug, PartialEq)]
pub struct SpeedPlanner {
    /// The speed model (eq 5 form), stepped for the free response.
    model: SsBlock<2>,
    /// `pulse[m]` = speed change `m` steps after the start of a unit command held over one
    /// knot.
    pulse: [f32; PLAN_STEPS + 1],
    /// `P`: `v = f + P du` (steps 1..=PLAN_STEPS by knots).
    p: SMatrix<f32, PLAN_STEPS, KNOTS>,
    /// `(H + rho_u I + rho_v P'P)^-1`.
    kkt_inv: SMatrix<f32, KNOTS, KNOTS>,
    /// The model's coast-out ([`Self::coast_m`]): `r` with `r . x` the sum of the outputs of
    /// all steps from state `x` with no input (`(I - A')^-1 C`), and the DC gain, which every
    /// input in flight adds to that sum per unit. `None` for a model without a finite,
    /// positive DC gain (the reader refuses those; no coast-out, no cap from it).
    coast: Option<Coast>,
    tuning: SpeedTuning,
}

/// The speed planner's warm start.
#[derive(Clone, Debug, PartialEq)]
pub struct SpeedState {
    z_cmd: [f32; KNOTS],
    w_cmd: [f32; KNOTS],
    z_speed: [f32; PLAN_STEPS],
    w_speed: [f32; PLAN_STEPS],
    /// The low-passed speed bias, m/s; infinite before the first plan (a plain `f32`: with an
    /// `Option<f32>` here the solve took 13 600 more instructions in QEMU, from the state's
    /// layout alone).
    bias_mps: f32,
    /// How well the speed model describes the car ([`Self::track_fit`]); the offset infinite
    /// before the first plan.
    fit: ModelFit,
    /// In the stop at the path's end ([`Self::in_stop`]).
    stopping: bool,
    /// The path's end ahead of the car last tick, m (infinite before the first plan).
    to_end_m: f32,
}

/// How well the speed model describes the car ([`SpeedState::track_fit`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelFit {
    /// The offset the model does not know (a grade, a load), m/s: the speed bias while it is
    /// steady, low-passed.
    pub offset_mps: f32,
    /// How far the model's predictions missed lately, m/s: the largest gap between the speed
    /// bias and its low-passed value, forgotten over [`MISMATCH_TIME_CONSTANT_S`].
    pub mismatch_mps: f32,
}

impl ModelFit {
    /// How far the model is trusted: 1 with no miss, 0 from [`MISMATCH_NO_TRUST_MPS`] (and for
    /// a non-finite miss).
    pub fn trust(&self) -> f32 {
        clamp(
            1.0 - finite_or(self.mismatch_mps, MISMATCH_NO_TRUST_MPS) / MISMATCH_NO_TRUST_MPS,
            0.0,
            1.0,
        )
    }
}

/// A speed plan.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpeedPlan {
    /// Command to send now, m/s.
    pub command_mps: f32,
    /// Planned commands per knot, m/s.
    pub commands_mps: [f32; KNOTS],
    /// Predicted speed at steps 0..=PLAN_STEPS (0 = now), m/s, >= 0.
    pub speeds_mps: [f32; PLAN_STEPS + 1],
}

/// What the plan starts from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpeedStart<'a> {
    /// The node's speed-model state: its next step is the command sent now.
    pub model_state: &'a SsBlockState<2>,
    /// Measured minus modelled speed now, m/s (held over the horizon): the predicted speeds'.
    pub bias_mps: f32,
    /// The bias the commands are planned with: `bias_mps` low-passed
    /// ([`SpeedState::filter_bias`]), m/s.
    pub planning_bias_mps: f32,
    /// Measured speed now, m/s.
    pub speed_mps: f32,
    /// The command sent last, m/s.
    pub last_command_mps: f32,
    /// The car is in a turn whose speed the path's lateral limit holds
    /// (`crate::control::path::Path::in_held_turn`): the commands do not lead it faster
    /// ([`SpeedPlanner::command_band`]).
    pub in_held_turn: bool,
    /// The lower target ahead the plan slows for, beyond its horizon too; `None`: none.
    pub slow_ahead: Option<SlowAhead>,
}

/// A lower target ahead of the car, which the speed plan's first command is bounded by as
/// the stop's is (`SpeedPlanner::slow_cap_mps`): the command from which the model's car
/// can still slow to it with every later command 0 until there. The caller picks it among the
/// path's points ahead whose targets are below [`SLOW_AHEAD_SHARE`] of the target where the
/// car is and below its speed by more than
/// [`SPEED_LIMIT_SLACK_MPS`] and [`SLOW_AHEAD_EXCESS_MPS`]: the one that
/// leaves the least room, `ahead_m` plus [`SpeedPlanner::coasted_s`] times `target_mps`
/// (`crate::control::path::Path::slow_ahead`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SlowAhead {
    /// Its distance along the path from the car, m.
    pub ahead_m: f32,
    /// Its target, m/s.
    pub target_mps: f32,
}

impl SpeedPlanner {
    /// Precomputes the pulse response and the ADMM matrix inverse.
    pub fn new(model: &SsBlock<2>, tuning: SpeedTuning) -> Result<Self, SpeedPlanError> {
        let positive = |v: f32| v.is_finite() && v > 0.0;
        if !(positive(tuning.speed_weight)
            && positive(tuning.command_change_weight)
            && positive(tuning.max_speed_mps)
            && positive(tuning.accel_mps2)
            && positive(tuning.decel_mps2)
            && tuning.bias_time_constant_s.is_finite()
            && tuning.bias_time_constant_s >= 0.0
            && tuning.command_lead_mps >= 0.0
            && tuning.command_band_mps >= 0.0
            && tuning.command_band_per_mps.is_finite()
            && tuning.command_band_per_mps >= 0.0)
        {
            return Err(SpeedPlanError::BadTuning);
        }
        // Unit step response at the start of every MPC step (call 5k, k = 0..=PLAN_STEPS), then its
        // differences: the response to a command held over one step.
        let mut st = model.zero_state();
        let step_resp = roll(model, &mut st, 1.0);
        // A command held over one knot is a unit step minus one KNOT_STEPS later.
        let mut pulse = [0.0f32; PLAN_STEPS + 1];
        for (m, p) in pulse.iter_mut().enumerate() {
            let now = step_resp.get(m).copied().unwrap_or(0.0);
            let later = m
                .checked_sub(KNOT_STEPS)
                .and_then(|i| step_resp.get(i))
                .copied()
                .unwrap_or(0.0);
            *p = now - later;
        }
        if pulse.iter().any(|p| !p.is_finite()) || pulse.iter().all(|p| *p == 0.0) {
            return Err(SpeedPlanError::NoResponse);
        }
        // Row i is step k = i + 1; column j the command of knot j (from step KNOT_STEPS j):
        // pulse[k - KNOT_STEPS j], 0 before the knot starts.
        let p = SMatrix::<f32, PLAN_STEPS, KNOTS>::from_fn(|i, j| {
            (i + 1)
                .checked_sub(KNOT_STEPS * j)
                .and_then(|m| pulse.get(m))
                .copied()
                .unwrap_or(0.0)
        });
        let kkt_inv = kkt_inverse(&pulse, &tuning)?;
        Ok(Self {
            model: *model,
            pulse,
            p,
            kkt_inv,
            coast: coast_row(model),
            tuning,
        })
    }

    /// How far the model's car goes from `state` to a standstill with every command from now
    /// on 0, m: the sum of its outputs over all later steps (the inputs in flight through the
    /// delay included) times the step. The model is linear and stable (the reader refuses
    /// unstable and integrating speed models), so the sum is `r . x + G sum(u in flight)`
    /// ([`SpeedPlanner`]'s `coast`), whatever the delay. `None` without that row. Every input
    /// in flight is summed whatever the caller does with it: the solve's cost does not depend
    /// on where the car is (docs/firmware.md, "Worst-case tick").
    pub fn coast_m(&self, state: &SsBlockState<2>) -> Option<f32> {
        let c = self.coast.as_ref()?;
        let (first, then) = self.model.delay().in_flight(&state.delay);
        let in_flight: f32 = first.iter().chain(then).sum();
        let sum = c.row.dot(&state.x) + c.gain * in_flight;
        sum.is_finite().then_some(sum * crate::SAMPLE_PERIOD_S)
    }

    /// How far the model's car coasts, every input 0, to a standstill from a speed it reached
    /// by coasting from four times that speed, per m/s of it, s (the least of `Coast`'s
    /// coasted sums): what a lower target's speed is weighed by when the one that leaves the
    /// least room to slow is picked ([`SlowAhead`]). `None` without a coast-out.
    pub fn coasted_s(&self) -> Option<f32> {
        self.coast.map(|c| c.coasted_s(0.0))
    }

    /// The highest command for the plan's first knot that leaves the car able to slow to
    /// `slow`'s target (and its [`SPEED_LIMIT_SLACK_MPS`]) by where it starts with every later
    /// command 0 until then, m/s; not below 0; infinite without a lower target ahead or a
    /// coast-out. The distance to slow is the model's [`Self::coast_m`] less the target's
    /// coasted sum ([`Coast`]'s `coasted`, at the target's share of the car's speed
    /// `speed_mps`), and the car's speed above the model's (`bias_mps`, measured minus
    /// modelled) taken to fade as a coasted speed does: a car that lags its model while
    /// it slows is slowed earlier, not later (unlike the stop's cap it is not weighed by the
    /// model's trust: a car faster than its model then reaches the lower target early, which
    /// the plan's limit rows allow, where one slower than its model would be over it).
    fn slow_cap_mps(
        &self,
        state: &SsBlockState<2>,
        slow: Option<SlowAhead>,
        (speed_mps, bias_mps): (f32, f32),
    ) -> f32 {
        let (Some(slow), Some(coast), Some(c)) = (slow, self.coast_m(state), self.coast) else {
            return f32::INFINITY;
        };
        let bias = finite_or(bias_mps, 0.0);
        let goal = slow.target_mps + SPEED_LIMIT_SLACK_MPS;
        let k = c.coasted_s(goal / speed_mps);
        let to_target = coast + k * (bias - goal);
        let cap = (slow.ahead_m - to_target) / (c.gain * KNOT_S);
        if cap.is_nan() {
            return 0.0;
        }
        max(cap, 0.0)
    }

    /// The highest command for the plan's first knot that leaves the model's car able to stop
    /// within `to_end_m` with every later command 0 (its [`Self::coast_m`] then, weighed by
    /// `trust`, [`ModelFit::trust`]: a car the model does not describe is stopped by the
    /// reference's taper and the creep, not at the model's pace), m/s; not below 0; infinite
    /// without an end or a coast-out.
    fn stop_cap_mps(&self, state: &SsBlockState<2>, to_end_m: f32, trust: f32) -> f32 {
        let (Some(coast), Some(c)) = (self.coast_m(state), self.coast) else {
            return f32::INFINITY;
        };
        if to_end_m.is_nan() {
            return 0.0;
        }
        max((to_end_m - trust * coast) / (c.gain * KNOT_S), 0.0)
    }

    /// The configuration.
    pub fn tuning(&self) -> &SpeedTuning {
        &self.tuning
    }

    /// Pulse response (see the struct doc).
    pub fn pulse(&self) -> &[f32; PLAN_STEPS + 1] {
        &self.pulse
    }

    /// Free response at steps 1..=PLAN_STEPS with `command_mps` held, plus the bias, m/s; not
    /// below 0. The car does not reverse: a car that brakes harder than its model (a bias below
    /// zero while the model still rolls) would otherwise be predicted to go backwards, and the
    /// plan would command speed to bring it back to a stop (0.3 m before the end of a path,
    /// commands of up to 4.9 m/s on the CAT Vehicle's plant, before).
    pub fn free_response(&self, start: &SpeedStart, command_mps: f32) -> [f32; PLAN_STEPS] {
        let mut st = *start.model_state;
        let all = roll(&self.model, &mut st, command_mps);
        offset(&all, start.bias_mps)
    }

    /// Plans the commands: the reference ([`Self::reference`]) from the targets
    /// (`targets_mps[k]`, k = 0..=PLAN_STEPS, the path's target speed where the car is expected
    /// at step k) and the distance `to_end_m` from the car to the path's end (infinite: no end),
    /// then the QP.
    pub fn plan(
        &self,
        state: &mut SpeedState,
        start: &SpeedStart,
        targets_mps: &[f32; PLAN_STEPS + 1],
        to_end_m: f32,
    ) -> SpeedPlan {
        let t = &self.tuning;
        let last = clamp(finite_or(start.last_command_mps, 0.0), 0.0, t.max_speed_mps);
        let v0 = max(finite_or(start.speed_mps, 0.0), 0.0);
        // The commands are planned with the low-passed bias, the speeds predicted with the bias
        // as measured (the lateral plan's speeds: the car's, not the filter's).
        let mut st = *start.model_state;
        let all = roll(&self.model, &mut st, last);
        let f = SVector::<f32, PLAN_STEPS>::from(offset(&all, start.planning_bias_mps));
        let f_now = SVector::<f32, PLAN_STEPS>::from(offset(&all, start.bias_mps));
        let here = targets_mps.first().copied().unwrap_or(0.0);
        let stopping = state.in_stop(v0, here, last, to_end_m);
        let r =
            SVector::<f32, PLAN_STEPS>::from(self.reference(v0, targets_mps, to_end_m, stopping));
        // Linear cost of du: w_v P' (f - r).
        let lin = self.p.tr_mul(&(f - r)) * t.speed_weight;
        // In the stop at the path's end the commands do not rise either (a car that brakes
        // harder than its model leaves a bias below zero, against which holding even a
        // non-rising reference takes rising commands: on the rig's loop 0.69 -> 2.02 -> 0.40 ->
        // 3.16 m/s with the reference's rule alone), and none asks for more than stops the car
        // at the end from where it is: at the end, 0. The plan's speeds are linear in the
        // commands and a car does not reverse, so against a bias below zero the plan saw no
        // gain in a lower command and held 0.19 m/s past the end (a car of scripts/sil-sim.py
        // with a 0.1 s dead time, 2.3 m past it).
        let top = if stopping {
            let to_end = max(to_end_m, 0.0);
            let creep = max(last, STOP_CREEP_MPS);
            min(
                min(creep, math::sqrt(2.0 * t.decel_mps2 * to_end)),
                t.max_speed_mps,
            )
        } else {
            t.max_speed_mps
        };
        let fit = state.track_fit(start.bias_mps, start.planning_bias_mps);
        let (floor, ceiling) = self.command_band(targets_mps, &fit, v0, start.in_held_turn);
        // The stop by the model: no command the model's car could not stop from at the end
        // with every later command 0 (as far as the model is trusted). The reference's taper
        // alone asks for the deceleration of `decel_mps2` to the end, which eq 5's car cannot
        // follow with commands of 0 or more: its response to a 0 fades with its own time constants, and the plan's 2 s
        // horizon is shorter than its mean response (2.84 s), so it saw that too late (a car
        // exactly eq 5, stopped 0.74-0.87 m past the end; docs/controller.md, "The stop at
        // the path's end").
        // And the same for a lower target ahead, beyond the horizon too ([`SlowAhead`]): the
        // path's envelope asks for `decel_mps2` down to it, which eq 5's car, whose response
        // to a 0 fades as its speed does, does not follow at low speeds (a probe's car exactly
        // eq 5 reached a step from 12 to 1 m/s at 2.94 m/s).
        let top = min(
            min(top, ceiling),
            min(
                self.stop_cap_mps(start.model_state, to_end_m, fit.trust()),
                self.slow_cap_mps(start.model_state, start.slow_ahead, (v0, start.bias_mps)),
            ),
        );
        let floor = if stopping { 0.0 } else { min(floor, top) };
        let lo = floor - last;
        let hi = top - last;
        // The path's target is a limit as well as a reference: no predicted speed above it by
        // more than SPEED_LIMIT_SLACK_MPS, nor above the maximum speed. The path's speed
        // envelope only ever asks for the reference's deceleration; a car above it (braking
        // less than its model says, or a new path's lower target where it is) is braked as
        // hard as the plan must to be under it again, the commands within their band.
        let limits = SVector::<f32, PLAN_STEPS>::from_fn(|k, _| {
            let goal = max(
                finite_or(targets_mps.get(k + 1).copied().unwrap_or(0.0), 0.0),
                0.0,
            );
            min(goal + SPEED_LIMIT_SLACK_MPS, t.max_speed_mps)
        });
        let speed_room = limits - f;
        state.shift();
        let mut du = SVector::<f32, KNOTS>::zeros();
        for _ in 0..t.iterations {
            let zc = SVector::<f32, KNOTS>::from(state.z_cmd);
            let wc = SVector::<f32, KNOTS>::from(state.w_cmd);
            let zs = SVector::<f32, PLAN_STEPS>::from(state.z_speed);
            let ws = SVector::<f32, PLAN_STEPS>::from(state.w_speed);
            let rhs = -lin + (zc - wc) * RHO_COMMAND + self.p.tr_mul(&(zs - ws)) * RHO_SPEED;
            du = self.kkt_inv * rhs;
            let dv = self.p * du;
            for ((z, w), d) in state
                .z_cmd
                .iter_mut()
                .zip(state.w_cmd.iter_mut())
                .zip(du.iter())
            {
                let z_new = clamp(d + *w, lo, hi);
                *w += d - z_new;
                *z = z_new;
            }
            for (((z, w), d), room) in state
                .z_speed
                .iter_mut()
                .zip(state.w_speed.iter_mut())
                .zip(dv.iter())
                .zip(speed_room.iter())
            {
                let v = d + *w;
                let reach = SPEED_BOUND_WEIGHT / RHO_SPEED;
                let z_new = if v > *room { max(*room, v - reach) } else { v };
                *w += d - z_new;
                *z = z_new;
            }
        }
        // The commands are clamped to their bounds exactly (ADMM meets them only in the limit).
        let mut commands = [0.0f32; KNOTS];
        for (c, d) in commands.iter_mut().zip(du.iter()) {
            *c = clamp(finite_or(last + d, floor), floor, top);
        }
        let speeds = self.predict(&f_now, last, &commands, v0);
        SpeedPlan {
            command_mps: commands.first().copied().unwrap_or(0.0),
            commands_mps: commands,
            speeds_mps: speeds,
        }
    }

    /// The band the commands stay in, `(floor, top)`, m/s: about the steady-state commands that
    /// hold the plan's lowest and highest targets, `(target - offset) / dc gain` with the
    /// offset of `fit` (a grade, a load: [`ModelFit::offset_mps`]), by a half-width of
    /// - [`SpeedTuning::command_lead_mps`] while the model predicts the car, falling to
    /// - [`SpeedTuning::command_band_mps`] plus [`SpeedTuning::command_band_per_mps`] times the
    ///   car's distance from that target (`v0_mps` is its speed), at most the lead, as its
    ///   predictions miss by up to [`MISMATCH_NO_TRUST_MPS`] ([`ModelFit::mismatch_mps`]).
    ///
    /// In a turn the path's lateral limit holds the speed in (`in_held_turn`) the top is the
    /// steady-state command of the target where the car is, plus at most
    /// [`SpeedTuning::command_band_mps`]: no lead towards a faster target ahead, whose command
    /// would take effect, on a car faster than its model, while the tyres are still at the
    /// limit (a probe's kinematic car with a 0.4 s dead time, eq 5's file: commanded up to
    /// 12.2 m/s at 120-150 degrees round an 8 m hairpin held to 7.8 m/s; docs/controller.md,
    /// "A turn faster than the tyres").
    ///
    /// A plan with a target of 0 (a stop) has its floor at 0; without a finite positive DC gain
    /// (an integrator) the band is from 0 to the maximum speed; an infinite
    /// [`SpeedTuning::command_band_mps`] leaves the floor at 0 and the top at the full lead.
    ///
    /// Eq 5's slow response needs the lead, and a car it describes keeps it ("A speed loop the
    /// model does not describe", docs/controller.md). A car faster than its model is driven far
    /// past the model's predictions by the commands of a plan that leads: `scripts/sil-sim.py`'s
    /// car with a 0.1 s dead time and a 0.3 s lag swung between 0.2 and 11.8 m/s on its 10 m/s
    /// course under commands from 0 to 14 m/s (the lead bounded only the top). Once the model
    /// is seen to miss, the car is commanded what holds the target, give or take the band, and
    /// led only as far as it is from the target: the same car holds the course's speed within
    /// 1.0 m/s. The centre corrects for the steady offset, not for the planning bias: in that
    /// car's launch the planning bias reached 3 m/s, all of it the model's slow transient, and a
    /// band about it let the car fall by 3-4 m/s.
    pub fn command_band(
        &self,
        targets_mps: &[f32; PLAN_STEPS + 1],
        fit: &ModelFit,
        v0_mps: f32,
        in_held_turn: bool,
    ) -> (f32, f32) {
        let t = &self.tuning;
        let (low, highest) = targets_mps
            .iter()
            .fold((t.max_speed_mps, 0.0f32), |(lo, hi), v| {
                let v = clamp(finite_or(*v, 0.0), 0.0, t.max_speed_mps);
                (min(lo, v), max(hi, v))
            });
        let Some(g) = self.model.dc_gain().filter(|g| g.is_finite() && *g > 0.0) else {
            return (0.0, t.max_speed_mps);
        };
        let offset = finite_or(fit.offset_mps, 0.0);
        let v0 = finite_or(v0_mps, 0.0);
        let trust = fit.trust();
        let width = |off_target: f32| {
            let narrow = min(
                t.command_lead_mps,
                max(t.command_band_mps, t.command_band_per_mps * off_target),
            );
            // (an infinite lead times no trust is no width, not NaN)
            let trusted = if trust > 0.0 {
                t.command_lead_mps * trust
            } else {
                0.0
            };
            max(narrow, trusted)
        };
        let (high, lead) = if in_held_turn {
            let here = targets_mps.first().copied().unwrap_or(0.0);
            let here = clamp(finite_or(here, 0.0), 0.0, t.max_speed_mps);
            (here, min(width(libm::fabsf(here - v0)), t.command_band_mps))
        } else {
            (highest, width(libm::fabsf(highest - v0)))
        };
        let top = clamp((high - offset) / g + lead, 0.0, t.max_speed_mps);
        // A stop is held by no command at all, whatever the offset.
        if !t.command_band_mps.is_finite() || low <= 0.0 {
            return (0.0, top);
        }
        let floor = clamp((low - offset) / g - width(libm::fabsf(v0 - low)), 0.0, top);
        (floor, top)
    }

    /// The speed reference at steps 1..=PLAN_STEPS, from the car's speed `v0_mps` now: the
    /// targets (`targets_mps[k]`: the path's target speed where the car is expected at step k),
    /// reached within the tuning's acceleration and deceleration, under two rules of the stop at
    /// the path's end, `to_end_m` ahead of the car (negative or NaN: there; infinite: no end):
    ///
    /// - **Travel bound.** No step ends faster than stops the reference at the end at the
    ///   tuning's deceleration: its own travel (trapezoidal) plus `v^2 / (2 decel)` within the
    ///   distance left (below `sqrt(2 decel d)`); from a speed with room to stop the reference
    ///   stops within a few millimetres of the end (the last step's partial deceleration). The
    ///   node stops at its path's end whether or not the planner's speeds taper to it.
    /// - **No rise into the stop.** In the stop (`stopping`, [`SpeedState::in_stop`]) the
    ///   reference does not rise above `max(v0, STOP_CREEP_MPS)`: a car that has
    ///   slowed below the path's taper (its brakes are harder than the speed model) is not asked
    ///   to speed up to it before stopping; it rolls on at its speed, or creeps at
    ///   [`STOP_CREEP_MPS`] from a near standstill, until the taper meets it. [`Self::plan`]
    ///   keeps the commands from rising there as well. Before these rules the commands near
    ///   the end of the rig's loop went 4 -> 0.79 -> 3.04 -> 0 m/s (docs/findings.md).
    pub fn reference(
        &self,
        v0_mps: f32,
        targets_mps: &[f32; PLAN_STEPS + 1],
        to_end_m: f32,
        stopping: bool,
    ) -> [f32; PLAN_STEPS] {
        let t = &self.tuning;
        let dt = super::STEP_S;
        let v0 = clamp(finite_or(v0_mps, 0.0), 0.0, t.max_speed_mps);
        // NaN and negative: at the end; +infinity passes (no end).
        let to_end = max(to_end_m, 0.0);
        let ceiling = if stopping {
            max(v0, STOP_CREEP_MPS)
        } else {
            t.max_speed_mps
        };
        let mut r = [0.0f32; PLAN_STEPS];
        let mut prev = v0;
        let mut travelled = 0.0f32;
        for (rk, target) in r.iter_mut().zip(targets_mps.iter().skip(1)) {
            let left = max(to_end - travelled, 0.0);
            // The fastest this step may end at and still stop at the end: its own travel
            // (trapezoidal) and then the deceleration's v^2 / (2 decel) within what is left.
            let (qa, qb, qc) = (0.5 / t.decel_mps2, 0.5 * dt, 0.5 * prev * dt - left);
            let disc = qb * qb - 4.0 * qa * qc;
            let stoppable = if disc > 0.0 {
                (math::sqrt(disc) - qb) / (2.0 * qa)
            } else {
                0.0
            };
            let bound = clamp(stoppable, 0.0, ceiling);
            let goal = clamp(finite_or(*target, 0.0), 0.0, min(t.max_speed_mps, bound));
            let v = clamp(goal, prev - t.decel_mps2 * dt, prev + t.accel_mps2 * dt);
            travelled += 0.5 * (prev + v) * dt;
            prev = v;
            *rk = v;
        }
        r
    }

    /// The predicted speeds (step 0 = `v0`) of a command sequence, from the free response `f`
    /// (with `last` held), clamped at 0.
    pub fn predict(
        &self,
        f: &SVector<f32, PLAN_STEPS>,
        last: f32,
        commands: &[f32; KNOTS],
        v0: f32,
    ) -> [f32; PLAN_STEPS + 1] {
        let du = SVector::<f32, KNOTS>::from_fn(|j, _| commands.get(j).map_or(0.0, |c| c - last));
        let v = f + self.p * du;
        let mut out = [0.0f32; PLAN_STEPS + 1];
        let mut it = out.iter_mut();
        if let Some(first) = it.next() {
            *first = v0;
        }
        for (o, vk) in it.zip(v.iter()) {
            *o = max(finite_or(*vk, 0.0), 0.0);
        }
        out
    }

    /// The plan of the fallback: command 0 (brake to a stop) over the whole horizon. Its
    /// speeds are the model's free response under command 0 (the prediction of zero commands
    /// from the response with the last one held, [`Self::predict`], to rounding; the pulse
    /// matrix's product cost a fallback at the end of a whole solve 1 500 instructions more).
    pub fn stop(&self, start: &SpeedStart) -> SpeedPlan {
        let free = self.free_response(start, 0.0);
        let mut speeds = [0.0f32; PLAN_STEPS + 1];
        let mut it = speeds.iter_mut();
        if let Some(first) = it.next() {
            *first = max(finite_or(start.speed_mps, 0.0), 0.0);
        }
        for (o, v) in it.zip(free) {
            *o = max(finite_or(v, 0.0), 0.0);
        }
        SpeedPlan {
            command_mps: 0.0,
            commands_mps: [0.0f32; KNOTS],
            speeds_mps: speeds,
        }
    }
}

/// The model's outputs at steps 1..=PLAN_STEPS (of `all`, step 0 first) plus `bias_mps`, not
/// below 0 (see [`SpeedPlanner::free_response`]).
fn offset(all: &[f32; PLAN_STEPS + 1], bias_mps: f32) -> [f32; PLAN_STEPS] {
    let mut f = [0.0f32; PLAN_STEPS];
    for (v, y) in f.iter_mut().zip(all.iter().skip(1)) {
        *v = max(y + bias_mps, 0.0);
    }
    f
}

impl SpeedState {
    /// No plan yet. `const`, so that it can initialise a static.
    pub const fn new() -> Self {
        Self {
            z_cmd: [0.0; KNOTS],
            w_cmd: [0.0; KNOTS],
            z_speed: [0.0; PLAN_STEPS],
            w_speed: [0.0; PLAN_STEPS],
            bias_mps: f32::INFINITY,
            fit: ModelFit {
                offset_mps: f32::INFINITY,
                mismatch_mps: 0.0,
            },
            stopping: false,
            to_end_m: f32::INFINITY,
        }
    }

    /// A new path: the stop at the old one's end is over (the speed plan's warm start, bias and
    /// fit are the car's, and stay).
    pub fn new_path(&mut self) {
        self.stopping = false;
        self.to_end_m = f32::INFINITY;
    }

    /// The speed bias to plan with: `raw_mps` (measured minus modelled speed this tick) through
    /// the first-order lowpass of time constant `time_constant_s` (0: `raw_mps`), once per tick;
    /// the first tick (or after a non-finite bias) starts the filter at `raw_mps`.
    pub fn filter_bias(&mut self, raw_mps: f32, time_constant_s: f32) -> f32 {
        let raw = finite_or(raw_mps, 0.0);
        let share = if time_constant_s > crate::SAMPLE_PERIOD_S {
            crate::SAMPLE_PERIOD_S / time_constant_s
        } else {
            1.0
        };
        let b = self.bias_mps;
        let bias = if b.is_finite() {
            b + (raw - b) * share
        } else {
            raw
        };
        self.bias_mps = bias;
        bias
    }

    /// How well the speed model describes the car, once per tick, from the speed bias `raw_mps`
    /// (measured minus modelled speed) and the planning bias `planning_mps`
    /// ([`Self::filter_bias`]): the gap between the two is how far the model's transient misses
    /// (its largest recent value is [`ModelFit::mismatch_mps`]); while the gap is under
    /// [`OFFSET_STEADY_MPS`] the bias is a steady offset, and [`ModelFit::offset_mps`] follows it
    /// through the lowpass of [`OFFSET_TIME_CONSTANT_S`] (from 0: a new state, or after a
    /// non-finite offset).
    pub fn track_fit(&mut self, raw_mps: f32, planning_mps: f32) -> ModelFit {
        let raw = finite_or(raw_mps, 0.0);
        let gap = libm::fabsf(raw - finite_or(planning_mps, 0.0));
        let fit = &mut self.fit;
        let decay = 1.0 - crate::SAMPLE_PERIOD_S / MISMATCH_TIME_CONSTANT_S;
        fit.mismatch_mps = max(gap, finite_or(fit.mismatch_mps, 0.0) * decay);
        let o = fit.offset_mps;
        fit.offset_mps = if !o.is_finite() {
            0.0
        } else if gap < OFFSET_STEADY_MPS {
            o + (raw - o) * (crate::SAMPLE_PERIOD_S / OFFSET_TIME_CONSTANT_S)
        } else {
            o
        };
        *fit
    }

    /// Whether the car is in the stop at the path's end, once per tick. `v0_mps` is its speed,
    /// `target_mps` the path's target where it is, `last_command_mps` the command sent last and
    /// `to_end_m` the end's distance ahead (NaN or negative: there; infinite: no end). The stop
    /// begins on the first tick the end is within the horizon's travel at the car's speed or
    /// the path's (at least [`STOP_CREEP_MPS`]) with the last command not above the car's
    /// speed (the plan cruising or braking, not launching: a path shorter than 2 s at its speed
    /// is still driven up to it), or within the creep's own 2 m whatever the command; it lasts
    /// until the end moves more than [`STOP_END_MOVED_M`] away (a longer path) or the state is
    /// reset (a new path). Held, not judged afresh each tick: a car that brakes harder than its
    /// model slows faster than the end comes nearer, and judged each tick at its own speed it
    /// left the stop 4 m before the end (2 m/s on the rig's loop) and was commanded back up to
    /// 2.5 m/s.
    pub fn in_stop(
        &mut self,
        v0_mps: f32,
        target_mps: f32,
        last_command_mps: f32,
        to_end_m: f32,
    ) -> bool {
        let to_end = max(to_end_m, 0.0);
        if to_end > self.to_end_m + STOP_END_MOVED_M {
            self.stopping = false;
        }
        self.to_end_m = to_end;
        let horizon_s = PLAN_STEPS as f32 * super::STEP_S;
        let v0 = finite_or(v0_mps, 0.0);
        let pace = max(max(v0, finite_or(target_mps, 0.0)), STOP_CREEP_MPS);
        // Every operand finite, or `to_end` infinite: no NaN reaches these comparisons.
        let cruising = finite_or(last_command_mps, 0.0) <= v0;
        if to_end <= STOP_CREEP_MPS * horizon_s || (cruising && to_end <= pace * horizon_s) {
            self.stopping = true;
        }
        self.stopping
    }

    /// Warm start for the next tick: one tick is a fifth of a step, a tenth of a knot.
    pub(super) fn shift(&mut self) {
        let per_step = 1.0 / TICKS_PER_STEP as f32;
        let per_knot = per_step / KNOT_STEPS as f32;
        shift(&mut self.z_cmd, per_knot);
        shift(&mut self.w_cmd, per_knot);
        shift(&mut self.z_speed, per_step);
        shift(&mut self.w_speed, per_step);
    }
}

impl Default for SpeedState {
    fn default() -> Self {
        Self::new()
    }
}

/// Each value moved `f` of the way to the next one (the last held).
fn shift<const N: usize>(v: &mut [f32; N], f: f32) {
    let old = *v;
    for (cur, next) in v.iter_mut().zip(old.iter().skip(1)) {
        *cur += (next - *cur) * f;
    }
}

/// [`SpeedPlanner`]'s coast-out: the model's speed summed over all later steps with no input.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Coast {
    /// `r = (I - A')^-1 C`: the sum is `r . x` from state `x`, in m/s times steps.
    row: SVector<f32, 2>,
    /// The DC gain: what each input in flight adds to the sum per unit.
    gain: f32,
    /// The sum from a car that reached a speed coasting, per m/s of that speed: `r . x` over
    /// the output `y`, `x` the model's state where, coasting (every input 0) from settled at
    /// 1 m/s, it first fell to each of [`COASTED_FRACTIONS`] of it. For a first-order model
    /// that is its time constant at every fraction; for one of higher order it falls with the
    /// fraction (a car that is slowing stops sooner than one that holds its speed), so the
    /// distance to slow from `v` to `w`, the coast-out less `w` times the sum at `w / v`, is
    /// not taken short.
    coasted: [f32; COASTED_FRACTIONS.len()],
}

impl Coast {
    /// The sum from a car that coasted to `fraction` of its speed, per m/s of it, s: `coasted`
    /// interpolated at `fraction` (the nearest beyond [`COASTED_FRACTIONS`]; a fraction above
    /// them, or not finite, is the first's).
    fn coasted_s(&self, fraction: f32) -> f32 {
        let f = finite_or(fraction, 1.0);
        let mut above = (1.0f32, self.coasted.first().copied().unwrap_or(0.0));
        for (&at, &k) in COASTED_FRACTIONS.iter().zip(&self.coasted) {
            if f >= at {
                let (fa, ka) = above;
                let share = if fa > at { (f - at) / (fa - at) } else { 0.0 };
                return (k + (ka - k) * clamp(share, 0.0, 1.0)) * crate::SAMPLE_PERIOD_S;
            }
            above = (at, k);
        }
        above.1 * crate::SAMPLE_PERIOD_S
    }
}

/// The model's [`Coast`]; `None` without a finite, positive DC gain or with `I - A` singular.
fn coast_row(model: &SsBlock<2>) -> Option<Coast> {
    let gain = model.dc_gain().filter(|g| g.is_finite() && *g > 0.0)?;
    let a = model.a();
    let c = model.c();
    // (I - A') r = C, 2 x 2 by Cramer's rule.
    let m11 = 1.0 - a.m11;
    let m12 = -a.m21;
    let m21 = -a.m12;
    let m22 = 1.0 - a.m22;
    let det = m11 * m22 - m12 * m21;
    if !(det.is_finite() && det != 0.0) {
        return None;
    }
    let row = SVector::<f32, 2>::new((c.x * m22 - m12 * c.y) / det, (m11 * c.y - m21 * c.x) / det);
    let coasted = coasted_sums(model, &row);
    (row.x.is_finite() && row.y.is_finite() && coasted.iter().all(|k| k.is_finite() && *k >= 0.0))
        .then_some(Coast { row, gain, coasted })
}

/// The fractions of a settled speed at which `Coast`'s `coasted` sums are taken,
/// descending; between them the sum is interpolated, beyond them the nearest is taken.
pub const COASTED_FRACTIONS: [f32; 4] = [0.9, 0.75, 0.5, 0.25];

/// [`Coast`]'s `coasted`, from the model stepped with every input 0 from its state settled at
/// 1 m/s until its output first falls to each of [`COASTED_FRACTIONS`] (at most a minute of
/// steps; NaN where it does not, or without a settled state). The inputs in flight hold the
/// settled state where it is until they are through, so the steps are `x <- A x` from it.
fn coasted_sums(model: &SsBlock<2>, row: &SVector<f32, 2>) -> [f32; COASTED_FRACTIONS.len()] {
    let mut sums = [f32::NAN; COASTED_FRACTIONS.len()];
    let Ok(settled) = model.steady_state_for_output(1.0) else {
        return sums;
    };
    let (a, c) = (model.a(), model.c());
    let mut x = settled.x;
    let mut next = COASTED_FRACTIONS.iter().zip(sums.iter_mut()).peekable();
    for _ in 0..(60.0 / crate::SAMPLE_PERIOD_S) as usize {
        x = a * x;
        let y = c.dot(&x);
        while let Some((_, sum)) = next.next_if(|(f, _)| y <= **f && y > 0.0) {
            *sum = row.dot(&x) / y;
        }
        if next.peek().is_none() {
            break;
        }
    }
    sums
}

/// The model's output at the start of each MPC step (calls 0, 5, 10, ... of `step`, the call
/// `5k` being the sample at `t + k STEP_S`) with `u` held from now on.
fn roll(model: &SsBlock<2>, st: &mut SsBlockState<2>, u: f32) -> [f32; PLAN_STEPS + 1] {
    let mut out = [0.0f32; PLAN_STEPS + 1];
    for y in out.iter_mut() {
        *y = model.step(st, u);
        for _ in 1..TICKS_PER_STEP {
            model.step(st, u);
        }
    }
    out
}

/// `(H + rho_u I + rho_v P'P)^-1` with `H = w_v P'P + w_du D'D` (D the first difference with
/// `du_{-1} = 0`), in f32 by Cholesky (the
/// matrix is at least `rho_u I`: in f32 `M X = I` holds to 1e-5 over the speed loops of
/// `tests::the_kkt_inverse_in_f32`; f64 linked 2.8 KiB of software floating point, the only
/// f64 arithmetic in the firmware).
fn kkt_inverse(
    pulse: &[f32; PLAN_STEPS + 1],
    t: &SpeedTuning,
) -> Result<SMatrix<f32, KNOTS, KNOTS>, SpeedPlanError> {
    let pm = |k: usize, j: usize| -> f32 {
        (k + 1)
            .checked_sub(KNOT_STEPS * j)
            .and_then(|m| pulse.get(m))
            .map_or(0.0, |v| *v)
    };
    let wv = t.speed_weight + RHO_SPEED;
    let wd = t.command_change_weight;
    // M = (w_v + rho_v) P'P + w_du D'D + rho_u I.
    let mut m = [[0.0f32; KNOTS]; KNOTS];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            let mut ptp = 0.0;
            for k in 0..PLAN_STEPS {
                ptp += pm(k, i) * pm(k, j);
            }
            // D'D: 2 on the diagonal (1 on the last), -1 beside it.
            let dtd = if i == j {
                if i + 1 == KNOTS {
                    1.0
                } else {
                    2.0
                }
            } else if i.abs_diff(j) == 1 {
                -1.0
            } else {
                0.0
            };
            *v = wv * ptp + wd * dtd + if i == j { RHO_COMMAND } else { 0.0 };
        }
    }
    if !cholesky_in_place(&mut m) {
        return Err(SpeedPlanError::NotPositiveDefinite);
    }
    let l = &m;
    // Columns of the inverse: solve L L' x = e_c.
    let mut inv = SMatrix::<f32, KNOTS, KNOTS>::zeros();
    for c in 0..KNOTS {
        let mut y = [0.0f32; KNOTS];
        for i in 0..KNOTS {
            let mut s = if i == c { 1.0 } else { 0.0 };
            for k in 0..i {
                s -= at(l, i, k) * y.get(k).copied().unwrap_or(0.0);
            }
            if let Some(yi) = y.get_mut(i) {
                *yi = s / at(l, i, i);
            }
        }
        let mut x = [0.0f32; KNOTS];
        for i in (0..KNOTS).rev() {
            let mut s = y.get(i).copied().unwrap_or(0.0);
            for k in i + 1..KNOTS {
                s -= at(l, k, i) * x.get(k).copied().unwrap_or(0.0);
            }
            if let Some(xi) = x.get_mut(i) {
                *xi = s / at(l, i, i);
            }
        }
        for (i, xi) in x.iter().enumerate() {
            if let Some(v) = inv.get_mut((i, c)) {
                *v = *xi;
            }
        }
    }
    Ok(inv)
}

/// `m[i][j]`, 0 outside.
fn at(m: &[[f32; KNOTS]; KNOTS], i: usize, j: usize) -> f32 {
    m.get(i).and_then(|r| r.get(j)).copied().unwrap_or(0.0)
}

/// Lower Cholesky factor of a symmetric matrix, written over its lower triangle (each entry
/// is read before it is overwritten); `false` unless positive definite.
fn cholesky_in_place(m: &mut [[f32; KNOTS]; KNOTS]) -> bool {
    for i in 0..KNOTS {
        for j in 0..=i {
            let mut s = at(m, i, j);
            for k in 0..j {
                s -= at(m, i, k) * at(m, j, k);
            }
            let v = if i == j {
                if !(s > 0.0 && s.is_finite()) {
                    return false;
                }
                math::sqrt(s)
            } else {
                s / at(m, j, j)
            };
            if let Some(x) = m.get_mut(i).and_then(|r| r.get_mut(j)) {
                *x = v;
            }
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The inverse in f32 against the matrix built in f64: `M X = I` to 1e-5 for step responses
    /// of a first-order speed loop with a delay (gains 0.5 to 2, time constants 0.3 to 3 s,
    /// delays up to the 1.28 s the model files allow), at the built-in weights and at ten
    /// times them.
    #[test]
    fn the_kkt_inverse_in_f32() {
        for gain in [0.5f64, 1.0, 2.0] {
            for tau in [0.3f64, 1.2, 3.0] {
                for delay in [0.0f64, 0.42, 1.28] {
                    for scale in [1.0f32, 10.0] {
                        let mut pulse = [0.0f32; PLAN_STEPS + 1];
                        for (m, p) in pulse.iter_mut().enumerate() {
                            let t = m as f64 * f64::from(super::super::STEP_S) - delay;
                            *p = if t > 0.0 {
                                gain * (1.0 - (-t / tau).exp())
                            } else {
                                0.0
                            } as f32;
                        }
                        let mut t = super::super::DEFAULT_TUNING.speed;
                        t.speed_weight *= scale;
                        t.command_change_weight *= scale;
                        let inv = kkt_inverse(&pulse, &t).unwrap();
                        let pm = |k: usize, j: usize| -> f64 {
                            (k + 1)
                                .checked_sub(KNOT_STEPS * j)
                                .and_then(|m| pulse.get(m))
                                .map_or(0.0, |v| f64::from(*v))
                        };
                        let wv = f64::from(t.speed_weight + RHO_SPEED);
                        let wd = f64::from(t.command_change_weight);
                        for i in 0..KNOTS {
                            for c in 0..KNOTS {
                                let mut mx = 0.0f64;
                                for j in 0..KNOTS {
                                    let ptp: f64 =
                                        (0..PLAN_STEPS).map(|k| pm(k, i) * pm(k, j)).sum();
                                    let dtd = match (i == j, i.abs_diff(j)) {
                                        (true, _) if i + 1 == KNOTS => 1.0,
                                        (true, _) => 2.0,
                                        (false, 1) => -1.0,
                                        _ => 0.0,
                                    };
                                    let rho = if i == j { f64::from(RHO_COMMAND) } else { 0.0 };
                                    mx += (wv * ptp + wd * dtd + rho) * f64::from(inv[(j, c)]);
                                }
                                let want = if i == c { 1.0 } else { 0.0 };
                                assert!(
                                    (mx - want).abs() < 1e-5,
                                    "gain {gain} tau {tau} delay {delay} x{scale}: (M X)[{i}][{c}] = {mx}"
                                );
                            }
                        }
                    }
                }
            }
        }
    }
}
