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
use catmodel::control::pure_pursuit::PurePursuitConfig;
use catmodel::node::NodeConfig;

/// Scan step, m/s.
pub const SCAN_STEP_MPS: f64 = 0.5;
/// Bisection tolerance, m/s.
pub const TOLERANCE_MPS: f64 = 0.1;
/// Seeds every speed is run with (sensor noise and clocks).
pub const SEEDS: [u64; 3] = [0, 1, 2];

/// Whether `controller` drives the double lane change cleanly at `speed_mps` on every seed, and
/// the mean truth speed at the track's entry.
pub fn clean_at(
    vehicle: &VehicleConfig,
    node: &NodeConfig,
    controller: Controller,
    receiver: Receiver,
    speed_mps: f64,
) -> (bool, f64) {
    let course = scenario::course(Kind::DoubleLaneChange, &vehicle.body, speed_mps);
    let mut entry = 0.0;
    for &seed in &SEEDS {
        let mut driver = NodeDriver::new(node.clone(), controller);
        let options = RunOptions::new(seed, receiver);
        let m = run(vehicle, &course, &mut driver, "", &options).metrics;
        if !m.clean {
            return (false, f64::NAN);
        }
        entry += m.entry_speed_mps.unwrap_or(f64::NAN) / SEEDS.len() as f64;
    }
    (true, entry)
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

/// The three speeds of the double lane change for one car (`catmodel dlc-limits`).
#[derive(Debug, Clone, serde::Serialize)]
pub struct DlcLimits {
    /// Vehicle width `b`, m.
    pub vehicle_width_m: f64,
    /// Each controller's highest clean speed (every seed of [`SEEDS`] clean); `None` if it is
    /// not clean even at the scan's start.
    pub controllers: Vec<ControllerLimit>,
    /// The offline optimiser's limit (speed command held), m/s.
    pub optimal_mps: Option<f64>,
    /// The truth speed at the track's entry of the optimiser's limit, m/s.
    pub optimal_entry_mps: Option<f64>,
    /// Every speed the optimiser searched: (speed, passable, smallest cone clearance).
    pub optimal_search: Vec<(f64, bool, f64)>,
    /// The optimiser's steering command profile at its limit, % per knot of
    /// [`super::optimal::KNOT_S`].
    pub optimal_profile_pct: Vec<f64>,
}

/// One controller's highest clean speed.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ControllerLimit {
    /// Controller name.
    pub name: String,
    /// The target speed of the path (what the speed command holds), m/s.
    pub target_mps: Option<f64>,
    /// The truth speed at the track's entry at that target, mean over the seeds, m/s.
    pub entry_mps: Option<f64>,
}

/// Scan start of the controllers' search, m/s (a walking pace through the cones).
pub const SCAN_FROM_MPS: f64 = 4.0;
/// Scan end, m/s.
pub const SCAN_TO_MPS: f64 = 25.0;

/// Computes the limits of `controllers` (by name) and, with `optimise`, the optimiser's,
/// on the car `vehicle` with the node `node`.
pub fn dlc_limits(
    vehicle: &VehicleConfig,
    node: &NodeConfig,
    controllers: &[String],
    optimise: bool,
) -> anyhow::Result<DlcLimits> {
    let mut speeds = Vec::new();
    let mut pursuit = None;
    for name in controllers {
        let controller =
            super::controller_named(name, super::receiver_rms_m(vehicle, Receiver::Rtk))?;
        if let super::driver::Controller::PurePursuit(tuning) = controller {
            pursuit.get_or_insert(PurePursuitConfig::for_node(node, tuning));
        }
        let mut entries = Vec::new();
        let target = highest_clean_speed(
            |v| {
                let (clean, entry) = clean_at(vehicle, node, controller, Receiver::Rtk, v);
                if clean {
                    entries.push((v, entry));
                }
                clean
            },
            SCAN_FROM_MPS,
            SCAN_TO_MPS,
        );
        let entry = target.and_then(|t| entries.iter().find(|(v, _)| *v == t).map(|e| e.1));
        speeds.push(ControllerLimit {
            name: name.clone(),
            target_mps: target,
            entry_mps: entry,
        });
    }
    let mut out = DlcLimits {
        vehicle_width_m: vehicle.body.width_m,
        controllers: speeds,
        optimal_mps: None,
        optimal_entry_mps: None,
        optimal_search: Vec::new(),
        optimal_profile_pct: Vec::new(),
    };
    if optimise {
        // The optimiser's first guess is the reference controller's steering.
        let pursuit = match pursuit {
            Some(p) => p,
            None => {
                PurePursuitConfig::for_node(node, catmodel::control::pure_pursuit::DEFAULT_TUNING)
            }
        };
        // The search starts where the slowest controller was still clean (or at the scan's
        // start): a speed where a profile is known to pass.
        let from = out
            .controllers
            .iter()
            .filter_map(|c| c.target_mps)
            .fold(SCAN_FROM_MPS, f64::max);
        let (best, log) =
            super::optimal::limit(vehicle, &node.vehicle, &pursuit, from, SCAN_TO_MPS);
        out.optimal_search = log
            .iter()
            .map(|r| (r.speed_mps, r.passable, r.min_clearance_m))
            .collect();
        if let Some(b) = best {
            out.optimal_mps = Some(b.speed_mps);
            out.optimal_entry_mps = Some(b.entry_speed_mps);
            out.optimal_profile_pct = b.profile;
        }
    }
    Ok(out)
}
