//! The highest speed at which a controller drives the double lane change cleanly (no cone hit,
//! completed), on several seeds: a scan up in [`SCAN_STEP_MPS`] steps to the first speed that
//! fails on any seed, then bisection between the last clean and the first failing speed to
//! [`TOLERANCE_MPS`]. The scan, not bisection alone, because a tracking controller is not
//! monotone in speed near its limit (a speed can fail where a higher one passes by luck of
//! phase); the reported speed is the highest with every scanned speed below it clean.
use super::driver::{Controller, NodeDriver};
use super::scenario::{self, Kind};
use super::{run, Receiver, RunOptions};
use crate::sim::config::VehicleConfig;
use catmodel::node::NodeConfig;

/// Scan step, m/s.
pub const SCAN_STEP_MPS: f64 = 0.5;
/// Bisection tolerance, m/s.
pub const TOLERANCE_MPS: f64 = 0.1;
/// Seeds every speed is run with (sensor noise and clocks).
pub const SEEDS: [u64; 3] = [0, 1, 2];

/// Whether `controller` drives the double lane change cleanly at `speed_mps` on every seed.
pub fn clean_at(
    vehicle: &VehicleConfig,
    node: &NodeConfig,
    controller: Controller,
    receiver: Receiver,
    speed_mps: f64,
) -> bool {
    let course = scenario::course(Kind::DoubleLaneChange, &vehicle.body, speed_mps);
    SEEDS.iter().all(|&seed| {
        let mut driver = NodeDriver::new(node.clone(), controller);
        let options = RunOptions {
            seed,
            receiver,
            max_time_s: 120.0,
        };
        run(vehicle, &course, &mut driver, "", &options)
            .metrics
            .clean
    })
}

/// The highest clean speed in `[from, to]` by scan and bisection (see the module doc); `None`
/// if `from` already fails.
pub fn highest_clean_speed(mut clean: impl FnMut(f64) -> bool, from: f64, to: f64) -> Option<f64> {
    if !clean(from) {
        return None;
    }
    let mut good = from;
    let mut bad = None;
    let mut v = from + SCAN_STEP_MPS;
    while v <= to + 1e-9 {
        if clean(v) {
            good = v;
            v += SCAN_STEP_MPS;
        } else {
            bad = Some(v);
            break;
        }
    }
    let Some(mut bad) = bad else {
        return Some(good);
    };
    while bad - good > TOLERANCE_MPS {
        let mid = 0.5 * (good + bad);
        if clean(mid) {
            good = mid;
        } else {
            bad = mid;
        }
    }
    Some(good)
}
