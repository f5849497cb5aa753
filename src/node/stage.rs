//! The stages of a tick and how often each may run in one tick: the structure the tick's
//! worst-case bound is computed from (docs/firmware.md, "Worst-case tick").
//!
//! [`Node::step`](super::Node::step) is a fixed sequence of stages. Every loop in it runs over
//! a bounded count: the received frames (at most [`MAX_RX_FRAMES_PER_TICK`]), the GNSS fixes
//! among them ([`GNSS_FIXES_PER_TICK`]), the missing fixes filled after a gap
//! ([`GAP_FILL_PER_TICK`]); everything else runs once per tick, with fixed loop counts inside.
//! Some stages exclude one another: a tick that completes a long path does not also plan
//! ([`Branch`]), and a tick that fills missing GNSS fixes does not also restart the lowpass
//! after a long gap, nor the other way round ([`Exclusive`]). So a tick's work is at most
//! `sum over the common stages of max_per_tick(stage) x most expensive run of the stage`
//! `+ max over the branches of the same sum over the branch's stages`,
//! whatever the input, where the stages of one exclusive set count as the dearest of them. [`TICK_STAGES`] writes the first factor and the branches down next to
//! the code;
//! `cargo xtask bench-target` measures the second in QEMU on each stage's costliest path
//! (`firmware/src/bin/qemu_bench.rs`) and `cargo qemu` adds the product up into
//! `worst_case_bound_instructions`. Adding a stage to the tick is adding a [`Stage`], a
//! [`StageProbe::lap`] call where it ends, and a row here.
//!
//! Measuring: [`Node::step_probed`](super::Node::step_probed) calls [`StageProbe::lap`] at the
//! end of each piece of work; everything since the previous lap belongs to that stage. In
//! [`Node::step`](super::Node::step) the probe is [`NoProbe`], whose laps compile to nothing.
//! `host-tests/tests/tick_stages.rs` runs the node over adversarial ticks with a counting probe
//! and checks that no stage ever runs more often than its row says, and that no tick runs
//! stages of two branches.

/// Frames one tick decodes at most: 12. The inputs of `catmodel.dbc` are 7 frames per 20 ms at
/// their highest rates (steering, speed and pedal reports at 50 Hz: 3; GNSS position and
/// COG/SOG at up to 100 Hz: 4), so 12 leaves 70 % above the nominal traffic for jitter and
/// bursts (a backlog drains at 5 frames a tick). Frames beyond it wait for the next tick (the app's receive queue and host replay
/// hold them; the queue drops beyond its length and counts it); a caller that hands
/// `Node::step` more has the rest counted (`Counters::rx_over_cap`, NODE_STATUS page 3) and not
/// used.
pub const MAX_RX_FRAMES_PER_TICK: usize = 12;
/// Frames a conforming planner sends per 20 ms at most: 4. With the vehicle's inputs at their
/// highest rates (7 frames per tick, see [`MAX_RX_FRAMES_PER_TICK`]) that is 11 of the 12 a
/// tick takes, so a path transfer never builds a backlog that grows from tick to tick (the
/// spare frame drains what jitter bunches). A 256-point path (513 frames) then takes 129
/// ticks, 2.6 s. A planner that sends faster has its excess wait in the receive queue, and
/// what the queue cannot hold is dropped and counted (NODE_STATUS page 3).
pub const PLANNER_FRAMES_PER_TICK: usize = 4;
/// Paths of at most this many points are "short": 5, the most a path can have whose
/// 2 x points + 1 frames (header, points, limits) all fit in one tick's
/// [`MAX_RX_FRAMES_PER_TICK`] (12). A longer path must have started in an earlier tick, and
/// the planner side assembles one path at a time (a new header abandons the old assembly), so
/// one tick completes at most one path that is not short ([`Stage::PathComplete`]) and at most
/// three short ones ([`Stage::PathCompleteShort`]: the one carried over, and two more of at
/// least 5 frames each in the remaining 11).
pub const SHORT_PATH_POINTS: usize = (MAX_RX_FRAMES_PER_TICK - 1) / 2;
// A short path is not held to the lateral limit (`Path::set_lateral_limit`): its windows are
// not counted in a tick that also solves.
const _: () = assert!(SHORT_PATH_POINTS <= crate::control::path::TURN_FEW_POINTS);
/// GNSS fixes one tick filters at most: 3, one more than a 100 Hz receiver (the fastest the
/// node is designed for, the paper's) delivers per 20 ms, for timing jitter. Further fixes in
/// the same tick are rejected and counted (`gnss_gate_rejects`).
pub const GNSS_FIXES_PER_TICK: usize = 3;
/// Missing fixes one tick fills by dead reckoning at most (a receiver that skipped one or two
/// fixes); a longer gap restarts the lowpass on the dead-reckoned track in one step instead
/// ([`super::estimator::EstimatorState::restart_on_track`]), at most once per tick, and not in
/// a tick that filled ([`Exclusive::GnssGap`]).
pub const GAP_FILL_PER_TICK: u32 = 2;

/// A piece of a tick's work, for measuring it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Stage {
    /// Dead reckoning moved to the tick's time (and the call into `Node::step`).
    Advance,
    /// One received frame decoded, validated and applied (a GNSS fix is kept for the GNSS
    /// stages).
    Frame,
    /// A planner frame that completed a path of more than [`SHORT_PATH_POINTS`] points: the
    /// frame, the path's validation and load over its points, the controller's restart.
    PathComplete,
    /// A planner frame that completed a path of at most [`SHORT_PATH_POINTS`] points.
    PathCompleteShort,
    /// The planner's map origin (LOCAL_ORIGIN) made the local frame: the frame built, the
    /// filters and the controller's path reset when it moved; or the controller's path reset
    /// when the node moved its own frame.
    Origin,
    /// The local frame built at the first fix, or moved to a fix beyond the node's own frame
    /// (the fix's check, the frame and the filters' restart).
    GnssOrigin,
    /// One fix into the local frame and through the plausibility gate (with the filters'
    /// restart after repeated rejections).
    GnssFixCheck,
    /// One missing fix filled by dead reckoning and filtered.
    GnssFill,
    /// The lowpass restarted on the dead-reckoned track after a long gap.
    GnssRestart,
    /// One fix through the lowpass, its receive time marked.
    GnssFixFilter,
    /// The fresh inputs, the speed model (eq 5), the hybrid switch and the lateral model.
    Models,
    /// Heading, filtered rear-axle position, eq 7.
    Estimate,
    /// The model-predictive controller's problem: the car on the path, the reference sampled
    /// at the stations the plan reaches, the corridor, the obstacles placed along the path.
    DriveReference,
    /// The model-predictive controller's solve. Its iterations are capped
    /// (`MpcTuning::admm`), so its worst case is a property of the code, measured with every
    /// row active and no early exit (`catmodel-qemu-mpc-bench`, `mpc_worst_*`); the bound
    /// takes the larger of that and what the stage drives showed.
    MpcSolve,
    /// The model-predictive controller in a tick that completed a long path
    /// ([`Stage::PathComplete`]): no solve, the previous tick's plan moved on by one tick
    /// (`MpcConfig::coast`); the next tick solves on the new path. Also a tick that found the
    /// car on another part of its path (`Tracking::left_window`, the search that found it
    /// included): the plan moved on, or a hold without one; the next tick solves from there.
    DriveCoast,
    /// The controller's commands (CONTROL_COMMAND; after the model-predictive controller's
    /// solve its checks and plan, the pure pursuit's step, or holding without a path).
    Drive,
    /// The 2 s horizon roll-out.
    Predict,
    /// The tick's frames encoded.
    Publish,
}

/// Where each stage ends, for measuring a tick stage by stage.
pub trait StageProbe {
    /// `stage` has just finished one run: everything since the previous lap was its work.
    fn lap(&mut self, stage: Stage);
}

/// The probe of an unmeasured tick: nothing.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoProbe;

impl StageProbe for NoProbe {
    #[inline(always)]
    fn lap(&mut self, _stage: Stage) {}
}

/// Which of a tick's mutually exclusive branches a stage belongs to. A tick runs the
/// [`Branch::Common`] stages and the stages of at most one other branch: a tick that completes
/// a path of more than [`SHORT_PATH_POINTS`] points (its validation and load, the controller's
/// restart) does not also plan; its drive stage moves the previous plan on by one tick instead
/// and the next tick plans on the new path (`super::drive`). Whatever may run in the same tick
/// as a plan (short paths, LOCAL_ORIGIN) is common.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Branch {
    /// Any tick.
    Common,
    /// A tick that completes a long path.
    PathLoad,
    /// A tick in which the model-predictive controller plans.
    Plan,
}

impl Branch {
    /// Short name (the stage measurement's output, `timing.json`).
    pub const fn key(self) -> &'static str {
        match self {
            Branch::Common => "common",
            Branch::PathLoad => "path_load",
            Branch::Plan => "plan",
        }
    }
}

/// Stages of which one tick runs one at most, whatever its branch: the bound counts the
/// dearest of them (its runs per tick times its most expensive run), not their sum.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Exclusive {
    /// A gap in the GNSS fixes: missing fixes filled one by one ([`Stage::GnssFill`]) or the
    /// lowpass restarted on the dead-reckoned track ([`Stage::GnssRestart`]). A tick that did
    /// one does not do the other (`super::gnss`, `GapBudget`); a gap it can no longer deal
    /// with has its fix rejected and counted, and the next tick fills in after it.
    GnssGap,
}

impl Exclusive {
    /// Short name (the stage measurement's output, `timing.json`).
    pub const fn key(self) -> &'static str {
        match self {
            Exclusive::GnssGap => "gnss_gap",
        }
    }
}

/// The branch a tick has taken and the stage of each exclusive set it has run, for checking
/// that it takes one branch at most and runs one stage of each [`Exclusive`] set at most (the
/// stage measurement in QEMU and `host-tests/tests/tick_stages.rs`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BranchTaken {
    branch: Option<Branch>,
    gnss_gap: Option<Stage>,
}

impl BranchTaken {
    /// A new tick: no branch yet, no exclusive stage run.
    pub const fn new() -> Self {
        Self {
            branch: None,
            gnss_gap: None,
        }
    }

    /// `stage` ran; false if its branch is not the one this tick took before, or if another
    /// stage of its exclusive set ran in this tick before.
    pub fn enter(&mut self, stage: Stage) -> bool {
        let Some(row) = bound_of(stage) else {
            return true;
        };
        let branch_ok = match row.branch {
            Branch::Common => true,
            branch => *self.branch.get_or_insert(branch) == branch,
        };
        let exclusive_ok = match row.exclusive {
            None => true,
            Some(Exclusive::GnssGap) => *self.gnss_gap.get_or_insert(stage) == stage,
        };
        branch_ok && exclusive_ok
    }

    /// The branch taken, if any.
    pub const fn taken(&self) -> Option<Branch> {
        self.branch
    }
}

/// One row of the tick's structure: a stage, how often it may run in one tick, and its branch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StageBound {
    /// The stage.
    pub stage: Stage,
    /// Short name (tables, `timing.json`).
    pub key: &'static str,
    /// Runs per tick, at most.
    pub max_per_tick: u32,
    /// Why no more (the constant or the rule that bounds it).
    pub because: &'static str,
    /// Which stages it may run beside.
    pub branch: Branch,
    /// The set of stages of which a tick runs one at most, if it is in one.
    pub exclusive: Option<Exclusive>,
}

/// The tick's structure, in the order the stages run. Each stage's `max_per_tick` is enforced
/// by the code it names.
pub const TICK_STAGES: [StageBound; 18] = [
    StageBound {
        stage: Stage::Advance,
        key: "advance",
        max_per_tick: 1,
        because: "once per tick",
        branch: Branch::Common,
        exclusive: None,
    },
    StageBound {
        stage: Stage::Frame,
        key: "frame",
        max_per_tick: MAX_RX_FRAMES_PER_TICK as u32,
        because: "MAX_RX_FRAMES_PER_TICK",
        branch: Branch::Common,
        exclusive: None,
    },
    StageBound {
        stage: Stage::PathComplete,
        key: "path_complete",
        max_per_tick: 1,
        because: "one path assembled at a time; only a path begun in an earlier tick is long",
        branch: Branch::PathLoad,
        exclusive: None,
    },
    StageBound {
        stage: Stage::PathCompleteShort,
        key: "path_complete_short",
        max_per_tick: 3,
        because: "SHORT_PATH_POINTS: the carried-over path and 2 x 5 frames of the 12",
        branch: Branch::Common,
        exclusive: None,
    },
    StageBound {
        stage: Stage::Origin,
        key: "origin",
        max_per_tick: 1,
        because: "the tick's last LOCAL_ORIGIN only, after the frames, or the node's own frame moved (never both)",
        branch: Branch::Common,
        exclusive: None,
    },
    StageBound {
        stage: Stage::GnssOrigin,
        key: "gnss_origin",
        max_per_tick: 1,
        because: "a frame built at most once per tick (the first fix, or the car leaving the node's own frame)",
        branch: Branch::Common,
        exclusive: None,
    },
    StageBound {
        stage: Stage::GnssFixCheck,
        key: "gnss_fix_check",
        max_per_tick: GNSS_FIXES_PER_TICK as u32,
        because: "GNSS_FIXES_PER_TICK",
        branch: Branch::Common,
        exclusive: None,
    },
    StageBound {
        stage: Stage::GnssFill,
        key: "gnss_fill",
        max_per_tick: GAP_FILL_PER_TICK,
        because: "GAP_FILL_PER_TICK; not in a tick that restarts",
        branch: Branch::Common,
        exclusive: Some(Exclusive::GnssGap),
    },
    StageBound {
        stage: Stage::GnssRestart,
        key: "gnss_restart",
        max_per_tick: 1,
        because: "at most one restart on the track per tick, not in a tick that fills",
        branch: Branch::Common,
        exclusive: Some(Exclusive::GnssGap),
    },
    StageBound {
        stage: Stage::GnssFixFilter,
        key: "gnss_fix_filter",
        max_per_tick: GNSS_FIXES_PER_TICK as u32,
        because: "GNSS_FIXES_PER_TICK",
        branch: Branch::Common,
        exclusive: None,
    },
    StageBound {
        stage: Stage::Models,
        key: "models",
        max_per_tick: 1,
        because: "once per tick",
        branch: Branch::Common,
        exclusive: None,
    },
    StageBound {
        stage: Stage::Estimate,
        key: "estimate",
        max_per_tick: 1,
        because: "once per tick",
        branch: Branch::Common,
        exclusive: None,
    },
    StageBound {
        stage: Stage::DriveReference,
        key: "drive_reference",
        max_per_tick: 1,
        because: "once per tick, over the reference's fixed stations",
        branch: Branch::Plan,
        exclusive: None,
    },
    StageBound {
        stage: Stage::MpcSolve,
        key: "mpc_solve",
        max_per_tick: 1,
        because: "once per tick; ADMM iterations capped (MpcTuning::admm), worst case from catmodel-qemu-mpc-bench",
        branch: Branch::Plan,
        exclusive: None,
    },
    StageBound {
        stage: Stage::DriveCoast,
        key: "drive_coast",
        max_per_tick: 1,
        because: "once per tick, in place of the solve (a path loaded, or the car found elsewhere on it)",
        branch: Branch::PathLoad,
        exclusive: None,
    },
    StageBound {
        stage: Stage::Drive,
        key: "drive",
        max_per_tick: 1,
        because: "once per tick",
        branch: Branch::Common,
        exclusive: None,
    },
    StageBound {
        stage: Stage::Predict,
        key: "predict",
        max_per_tick: 1,
        because: "once per tick",
        branch: Branch::Common,
        exclusive: None,
    },
    StageBound {
        stage: Stage::Publish,
        key: "publish",
        max_per_tick: 1,
        because: "once per tick",
        branch: Branch::Common,
        exclusive: None,
    },
];

/// The row of `stage` in [`TICK_STAGES`].
pub fn bound_of(stage: Stage) -> Option<&'static StageBound> {
    TICK_STAGES.iter().find(|row| row.stage == stage)
}
