//! What sits on the bus in the node's place during a closed-loop run or a SIL session: one
//! tick in (the frames received since the previous tick), the tick's frames out.
//!
//! [`NodeDriver`] is the very same `catmodel::node::Node` the firmware runs, plus the
//! controller fed with the node's estimate: until the node runs the controller itself, the
//! controller (pure pursuit, [`catmodel::control::pure_pursuit`]) runs here, beside it, on the
//! same frames, and its CONTROL_COMMAND goes out after the node's frames with the tick's
//! counter. Once `Node` sends CONTROL_COMMAND, [`NodeDriver`] drops its own controller: the
//! switch is the one `match` in [`NodeDriver::tick`].
//!
//! Frames: until the node adopts LOCAL_ORIGIN itself, it keeps its own local frame (the first
//! fix, as in the firmware, so that a recorded session replays identically in QEMU), and the
//! controller beside it moves the node's pose into the planner's frame by the offset between
//! the two origins (the tangent planes' rotation is below 1e-5 rad within 60 km: ignored).
use catmodel::can::codec::{decode_planner, ControlCommand, ControlStatus};
use catmodel::can::{CanFrame, TimedFrame};
use catmodel::control::path::Tracking;
use catmodel::control::planner::PlannerEvent;
use catmodel::control::planner::PlannerInputs;
use catmodel::control::pure_pursuit::{CarState, PurePursuitConfig, PurePursuitState};
use catmodel::geodesy::LocalFrame;
use catmodel::model::kinematic::Pose;
use catmodel::node::{Node, NodeConfig, PlatformStats, Tick, TxFrames};

/// A node on the bus: one tick at a time.
pub trait Driver {
    /// Runs the tick at `now_us` over `rx` (frames stamped at or before it, in arrival order)
    /// and appends the frames it sends to `tx`.
    fn tick(&mut self, now_us: u64, rx: &[TimedFrame], tx: &mut Vec<CanFrame>) -> TickReport;
}

/// What a tick did, for the closed loop's records (never on the bus).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TickReport {
    /// The node's estimate of the rear axle, in the planner's frame.
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
    /// The reference controller with this tuning.
    PurePursuit(PurePursuitConfig),
}

/// The node and, beside it, the controller on the node's estimate.
pub struct NodeDriver {
    node: Node,
    planner: PlannerInputs,
    controller: Controller,
    pursuit: PurePursuitState,
    /// The planner's map origin (1e-7 deg), once LOCAL_ORIGIN arrived.
    planner_origin_e7: Option<(i32, i32)>,
}

impl NodeDriver {
    /// A fresh node with `config`, driving with `controller`.
    pub fn new(config: NodeConfig, controller: Controller) -> Self {
        Self {
            node: Node::new(config),
            planner: PlannerInputs::new(),
            controller,
            pursuit: PurePursuitState::default(),
            planner_origin_e7: None,
        }
    }

    /// The node's local frame origin in the planner's frame (east, north), m: zero while the
    /// planner sent no origin (its frame is the node's).
    fn frame_offset(&self) -> Option<(f32, f32)> {
        let Some((lat, lon)) = self.planner_origin_e7 else {
            return Some((0.0, 0.0));
        };
        let node = self.node.origin_e7()?;
        let enu = LocalFrame::new(lat, lon)
            .ok()?
            .to_local(node.0, node.1)
            .ok()?;
        Some((enu.east_m, enu.north_m))
    }

    /// The node.
    pub fn node(&self) -> &Node {
        &self.node
    }

    /// The planner's inputs as the controller has them.
    pub fn planner(&self) -> &PlannerInputs {
        &self.planner
    }
}

impl Driver for NodeDriver {
    fn tick(&mut self, now_us: u64, rx: &[TimedFrame], tx: &mut Vec<CanFrame>) -> TickReport {
        // The node sees every frame (it counts the planner's as unknown until it runs the
        // controller): exactly what the firmware sees when it replays the session.
        let mut node_tx = TxFrames::new();
        let tick = Tick {
            now_us,
            platform: PlatformStats::default(),
        };
        let estimate = self.node.step(&tick, rx, &mut node_tx);
        for f in rx.iter().filter(|f| f.t_us <= now_us) {
            if let Ok(m) = decode_planner(&f.frame) {
                if let PlannerEvent::Origin { lat_e7, lon_e7 } = self.planner.receive(&m) {
                    self.planner_origin_e7 = Some((lat_e7, lon_e7));
                }
            }
        }
        tx.extend_from_slice(&node_tx);
        let counter = (self.node.tick_count().wrapping_sub(1) & 0x0F) as u8;
        let offset = self.frame_offset();
        let pose = estimate
            .pose
            .zip(offset)
            .map(|(p, (e, n))| Pose::new(p.x_m + e, p.y_m + n, p.heading_rad));
        let car = CarState {
            pose,
            speed_mps: estimate.speed_mps,
        };
        let (command, tracking) = match self.controller {
            Controller::PurePursuit(cfg) => {
                let out = cfg.process(
                    &mut self.pursuit,
                    self.planner.path(),
                    self.planner.obstacles(),
                    &car,
                );
                let command = ControlCommand {
                    status: out.status,
                    steer_cmd_pct: Some(out.steer_cmd_pct),
                    speed_cmd_mps: Some(out.speed_cmd_mps),
                };
                (command, out.tracking)
            }
        };
        tx.push(command.encode(counter));
        TickReport {
            pose,
            speed_mps: estimate.speed_mps,
            command,
            tracking,
        }
    }
}

/// The command a driver sends when it has nothing (for records before the first tick).
pub const IDLE_COMMAND: ControlCommand = ControlCommand {
    status: ControlStatus::NoPath,
    steer_cmd_pct: Some(0.0),
    speed_cmd_mps: Some(0.0),
};
