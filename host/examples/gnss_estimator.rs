//! Scratch experiment: the node's GNSS estimator on a simulated car at its receiver rate.
//! usage: gnss_estimator VEHICLE.toml SCENARIO SEED... [-- key=value ...]
use std::path::Path;

use catmodel::node::estimator::EstimatorConfig;
use catmodel::node::NodeConfig;
use catmodel_host::evaluate::{self, Truth};
use catmodel_host::sim::config::VehicleConfig;
use catmodel_host::sim::scenario::Scenario;
use catmodel_host::sim::{self, SimOptions};
use catmodel_host::{csv2can, replay, SIM_ORIGIN_DEG};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let cfg = VehicleConfig::load(Path::new(&args[0])).unwrap();
    let scenario = Scenario::builtin(&args[1]).unwrap();
    let mut seeds = Vec::new();
    let mut kv = Vec::new();
    for a in &args[2..] {
        if let Some((k, v)) = a.split_once('=') {
            kv.push((k.to_string(), v.parse::<f64>().unwrap()));
        } else {
            seeds.push(a.parse::<u64>().unwrap());
        }
    }
    let get = |k: &str, d: f64| kv.iter().find(|x| x.0 == k).map_or(d, |x| x.1);
    let rate_hz = get("rate", 1.0 / cfg.sensors.gnss.period_s);
    let cutoff = get("cutoff", 2.0);
    let antenna = cfg.sensors.gnss.antenna_ahead_of_rear_axle_m;
    let dir = std::env::temp_dir().join("h2-gnss-estimator");
    std::fs::create_dir_all(&dir).unwrap();
    let (mut sum_ratio, mut worst_raw) = (0.0, 0.0f64);
    for &seed in &seeds {
        let out = sim::simulate(
            &scenario,
            &cfg,
            &SimOptions {
                seed,
                ..Default::default()
            },
        );
        let frames = csv2can::encode_log(&out.log).unwrap().frames;
        let mut config = NodeConfig::paper().unwrap();
        config.origin_e7 = Some((
            (SIM_ORIGIN_DEG.0 * 1e7).round() as i32,
            (SIM_ORIGIN_DEG.1 * 1e7).round() as i32,
        ));
        config.gnss_period_s = (1.0 / rate_hz) as f32;
        config.estimator = EstimatorConfig::paper(rate_hz, cutoff, antenna as f32).unwrap();
        config.estimator.course_gain = get("gain", 0.05) as f32;
        config.timeouts.gnss_us = get("timeout_us", 200_000.0) as u64;
        let r = replay::replay(&frames, config);
        let pred_path = dir.join("pred.csv");
        std::fs::write(&pred_path, &r.predictions_csv).unwrap();
        let can_path = dir.join("in.can.log");
        std::fs::write(&can_path, csv2can::to_candump(&frames)).unwrap();
        let preds = catmodel_host::read_predictions(&pred_path).unwrap();
        let inputs = catmodel_host::baseline_inputs(&can_path, SIM_ORIGIN_DEG).unwrap();
        let vehicle = catmodel::vehicle::VehicleParams {
            wheelbase_m: cfg.chassis.wheelbase_m as f32,
            track_m: cfg.chassis.track_m as f32,
            max_steer_rad: cfg.chassis.max_steer_deg.to_radians() as f32,
            understeer_s2_per_m2: cfg.understeer_s2_per_m2() as f32,
        };
        let e = evaluate::evaluate(&preds, &Truth::new(out.truth), &inputs, &vehicle, antenna);
        let b = &e.bias_floor;
        let h1 = e.horizons.iter().find(|h| (h.horizon_s - 1.0).abs() < 1e-9).unwrap();
        println!(
            "seed {seed}: floor {:.3} m, filtered {:.3} m ({:.3} x), raw axle {:.3} m ({:.3} x), heading {:.4} rad; 1 s node {:.3} base {:.3}",
            b.pos_rms_m,
            b.filtered_pos_rms_m,
            b.filtered_ratio.unwrap(),
            e.raw_gnss_at_axle.pos_rms_m,
            b.raw_at_axle_ratio.unwrap(),
            e.horizons[0].node.heading_rms_rad,
            h1.node.pos_rms_m,
            h1.baseline.pos_rms_m
        );
        sum_ratio += b.filtered_ratio.unwrap();
        worst_raw = worst_raw.max(b.filtered_pos_rms_m / e.raw_gnss_at_axle.pos_rms_m);
    }
    println!(
        "mean ratio {:.4}; worst filtered/raw {:.3}",
        sum_ratio / seeds.len() as f64,
        worst_raw
    );
}
