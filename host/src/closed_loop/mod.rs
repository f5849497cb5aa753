//! The closed loop on the host: the plant simulator driven by the controller's CONTROL_COMMAND
//! frames through the bus, the node in the loop, a simulated planner sending paths and
//! obstacles, and the scenarios (ISO 3888-2 double lane change, an obstacle, a loop).
pub mod planner;
