//! What sits on the bus in the node's place during a closed-loop run or a SIL session: one
//! tick in (the frames received since the previous tick), the tick's frames out.
//!
//! [`NodeDriver`] is the very same `catmodel::node::Node` the firmware runs, controller
//! included: the node assembles the planner's path, runs the controller its configuration
//! names (`[control]` of the model file) and sends CONTROL_COMMAND itself. The closed-loop
//! tools may drive with another controller than the model file's ([`Controller`]), and tune
//! the reference controller; a SIL session runs the node exactly as configured.
use catmodel::can::codec::{ControlCommand, ControlStatus, FallbackCause, GnssPosition};
use catmodel::can::{CanFrame, TimedFrame};
use catmodel::control::mpc::MpcTuning;
use catmodel::control::path::{PathCar, Tracking};
use catmodel::control::planner::PlannerCounters;
use catmodel::control::pure_pursuit::PurePursuitTuning;
use catmodel::model::kinematic::Pose;
use catmodel::node::drive::Controller as NodeController;
use catmodel::node::{Counters, NodeConfig, Tick, TxFrames};

use crate::HostNode;

/// A node on the bus: one tick at a time.
pub trait Driver {
    /// Runs `tick` (its time, and the platform's counters) over `rx` (frames stamped at or
    /// before it, in arrival order) and appends the frames it sends to `tx`.
    fn tick(&mut self, tick: &Tick, rx: &[TimedFrame], tx: &mut Vec<CanFrame>) -> TickReport;

    /// The node's rejection counters so far (the ones no status page carries among them).
    fn counters(&self) -> Counters;

    /// Why the node did not use the GNSS fixes, if their rate was not the model file's
    /// ([`crate::gnss_rate_note`]).
    fn gnss_rate_note(&self) -> Option<String> {
        None
    }

    /// What the node's steering check found, if it used a gain other than the model file's
    /// ([`crate::steering_note`]).
    fn steering_note(&self) -> Option<String> {
        None
    }

    /// The node's planner counters so far (paths loaded and refused; on no status page:
    /// `sil` sums them up).
    fn planner_counters(&self) -> PlannerCounters {
        PlannerCounters::default()
    }

    /// The car the node checks paths against (`sil` names what a refused path asks of it).
    fn path_car(&self) -> PathCar {
        PathCar::default()
    }

    /// The path the node is receiving, if it is mid-way through one: its id, how many of its
    /// points and limits are in, and how many points its header announced.
    fn path_receiving(&self) -> Option<(u8, usize, usize, usize)> {
        None
    }
}

/// What a tick did, for the closed loop's records (never on the bus).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TickReport {
    /// The node's estimate of the rear axle, in its local frame (the planner's).
    pub pose: Option<Pose>,
    /// The node's speed, m/s.
    pub speed_mps: f32,
    /// The command sent.
    pub command: ControlCommand,
    /// Where the controller saw the car relative to its path.
    pub tracking: Option<Tracking>,
}

/// Which controller drives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Controller {
    /// The one the model file names.
    FromModel,
    /// The model-predictive controller.
    Mpc,
    /// The model-predictive controller with this tuning (tuning sweeps).
    MpcTuned(MpcTuning),
    /// The reference controller with this tuning.
    PurePursuit(PurePursuitTuning),
}

/// The node, controller included.
pub struct NodeDriver {
    node: HostNode,
    /// The times of the receiver's position frames the node was given, for the rate the
    /// session shows ([`crate::ReceiverRate`]).
    fix_times_us: Vec<u64>,
}

impl NodeDriver {
    /// A fresh node with `config`, driving with `controller`.
    pub fn new(mut config: NodeConfig, controller: Controller) -> Self {
        match controller {
            Controller::FromModel => {}
            Controller::Mpc | Controller::MpcTuned(_) => config.controller = NodeController::Mpc,
            Controller::PurePursuit(_) => config.controller = NodeController::PurePursuit,
        }
        let mut node = crate::new_node(config.clone());
        match controller {
            Controller::PurePursuit(tuning) => node.drive_mut().tune_pursuit(&config, tuning),
            Controller::MpcTuned(tuning) => {
                // A refused tuning leaves the controller in its fallback: the run shows it.
                let _ = node.drive_mut().tune_mpc(&config, tuning);
            }
            Controller::FromModel | Controller::Mpc => {}
        }
        Self {
            node,
            fix_times_us: Vec::new(),
        }
    }

    /// The node.
    pub fn node(&self) -> &HostNode {
        &self.node
    }
}

impl Driver for NodeDriver {
    fn counters(&self) -> Counters {
        *self.node.counters()
    }

    fn gnss_rate_note(&self) -> Option<String> {
        crate::gnss_rate_note(
            self.node.counters(),
            crate::ReceiverRate::measure(&self.fix_times_us),
            1.0 / f64::from(self.node.config().estimator.gnss_period_s),
        )
    }

    fn steering_note(&self) -> Option<String> {
        crate::steering_note(self.node.steering(), None)
    }

    fn planner_counters(&self) -> PlannerCounters {
        *self.node.drive().planner().counters()
    }

    fn path_car(&self) -> PathCar {
        *self.node.drive().planner().car()
    }

    fn path_receiving(&self) -> Option<(u8, usize, usize, usize)> {
        self.node.drive().planner().receiving()
    }

    fn tick(&mut self, tick: &Tick, rx: &[TimedFrame], tx: &mut Vec<CanFrame>) -> TickReport {
        let mut node_tx = TxFrames::new();
        let source = self.node.config().gnss_source;
        self.fix_times_us.extend(
            rx.iter()
                .filter(|f| GnssPosition::decode(&f.frame, source).is_ok())
                .map(|f| f.t_us),
        );
        let estimate = self.node.step(tick, rx, &mut node_tx);
        tx.extend_from_slice(&node_tx);
        let drive = self.node.drive();
        TickReport {
            pose: estimate.pose,
            speed_mps: estimate.speed_mps,
            command: drive.last_command(),
            tracking: drive.last_tracking(),
        }
    }
}

/// The command a driver sends when it has nothing (for records before the first tick).
pub const IDLE_COMMAND: ControlCommand = ControlCommand {
    status: ControlStatus::NoPath,
    fallback: FallbackCause::None,
    steer_cmd_pct: Some(0.0),
    speed_cmd_mps: Some(0.0),
};
