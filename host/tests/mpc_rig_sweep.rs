//! Tuning sweeps of the model-predictive controller on the closed-loop rig (the node, the bus,
//! the built-in plant): ignored; they print, the goals are pinned in `closed_loop_goals.rs`.
use catmodel::control::mpc::MpcTuning;
use catmodel::node::drive::mpc_tuning;
use catmodel::node::NodeConfig;
use catmodel_host::closed_loop::driver::{Controller, NodeDriver};
use catmodel_host::closed_loop::scenario::{self, Kind};
use catmodel_host::closed_loop::{load_setup, run, Receiver, RunOptions};
use catmodel_host::sim::config::VehicleConfig;

/// The car: VEHICLE and MODEL name another (paths from the repository's root, as the CLI's).
fn setup() -> (VehicleConfig, NodeConfig) {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let vehicle = std::env::var("VEHICLE").ok().map(|p| root.join(p));
    let model = std::env::var("MODEL").ok().map(|p| root.join(p));
    load_setup(vehicle.as_deref(), model.as_deref()).unwrap()
}

fn dlc(tuning: MpcTuning, speed: f64, seed: u64) -> (usize, f64, f64, f64) {
    let (vehicle, node) = setup();
    let kind =
        std::env::var("SCENARIO").map_or(Kind::DoubleLaneChange, |s| Kind::from_name(&s).unwrap());
    let course = scenario::course(kind, &vehicle.body, speed);
    let mut driver = NodeDriver::new(node, Controller::MpcTuned(tuning));
    let options = RunOptions::new(seed, Receiver::Rtk);
    let m = run(&vehicle, &course, &mut driver, "mpc", &options).metrics;
    (
        m.cone_hits + m.gates_missed,
        m.lateral_rms_m.unwrap_or(f64::NAN),
        m.lateral_max_m.unwrap_or(f64::NAN),
        m.min_cone_clearance_m.unwrap_or(f64::NAN),
    )
}

#[test]
#[ignore = "tuning sweep on the rig; prints"]
fn sweep() {
    let variants: Vec<(&str, MpcTuning)> = {
        // The car's own tuning: the built-in one with what its model file sets.
        let base = mpc_tuning(&setup().1);
        let mut v = vec![("default", base)];
        let var = std::env::var("SWEEP").unwrap_or_default();
        for item in var.split(';').filter(|s| !s.is_empty()) {
            let mut t = base;
            for kv in item.split(',') {
                let (k, val) = kv.split_once('=').unwrap();
                let x: f32 = val.parse().unwrap();
                let w = &mut t.weights;
                match k {
                    "lat" => w.lateral_per_m2 = x,
                    "head" => w.heading_per_rad2 = x,
                    "steer" => w.steer_per_rad2 = x,
                    "rate" => w.steer_rate = x,
                    "term" => w.terminal_factor = x,
                    "vy" => w.lateral_speed_per_mps2 = x,
                    "r" => w.yaw_rate_per_rps2 = x,
                    "lead" => t.steer_lead_s = x,
                    "margin" => w.corridor_margin_m = x,
                    "cw" => w.corridor_weight_per_m = x,
                    "rc" => w.rho_corridor = x,
                    "rs" => w.rho_steer = x,
                    "rr" => w.rho_steer_rate = x,
                    "trust" => t.steer_trust_s = x,
                    "share" => t.steer_rate_share = x,
                    "iter" => t.admm.max_iterations = x as u16,
                    "return" => t.corridor_return_mps2 = x,
                    "bias" => t.speed.bias_time_constant_s = x,
                    "norule" => t.line_rule = None,
                    _ => panic!("{k}"),
                }
            }
            v.push((Box::leak(item.to_string().into_boxed_str()), t));
        }
        v
    };
    let speeds: Vec<f64> = std::env::var("SPEEDS")
        .unwrap_or("5,8,10,11,12,13,14".into())
        .split(',')
        .map(|s| s.parse().unwrap())
        .collect();
    for (name, t) in variants {
        let mut line = format!("{name:40}");
        let seeds: u64 = std::env::var("SEEDS").map_or(1, |s| s.parse().unwrap());
        for &v in &speeds {
            if seeds == 1 {
                let (hits, rms, max, clr) = dlc(t, v, 1);
                line += &format!(" | {v}: {hits} {rms:.2}/{max:.2} {clr:+.2}");
            } else {
                let runs: Vec<_> = (0..seeds).map(|s| dlc(t, v, s)).collect();
                let clean = runs.iter().filter(|r| r.0 == 0).count();
                let worst = runs.iter().map(|r| r.3).fold(f64::INFINITY, f64::min);
                line += &format!(" {v}:{clean}/{seeds}({worst:+.2})");
            }
        }
        println!("{line}");
    }
}
