//! Scratch: the node's GNSS estimator on simulated drives, with knobs.
//! usage: gnss_rate VEHICLE.toml MODEL.toml SCENARIO SEED... [key=value ...]
use std::path::Path;

use catmodel::node::estimator::EstimatorConfig;
use catmodel_host::evaluate::{self, Truth};
use catmodel_host::sim::config::VehicleConfig;
use catmodel_host::sim::scenario::Scenario;
use catmodel_host::sim::{self, SimOptions};
use catmodel_host::{csv2can, model_file, replay, Car, SIM_ORIGIN_DEG};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let cfg = VehicleConfig::load(Path::new(&args[0])).unwrap();
    let model = model_file::load(Path::new(&args[1])).unwrap();
    let scenario = Scenario::builtin(&args[2]).unwrap();
    let mut seeds = Vec::new();
    let mut kv = Vec::new();
    for a in &args[3..] {
        if let Some((k, v)) = a.split_once('=') {
            kv.push((k.to_string(), v.parse::<f64>().unwrap()));
        } else {
            seeds.push(a.parse::<u64>().unwrap());
        }
    }
    let get = |k: &str, d: f64| kv.iter().find(|x| x.0 == k).map_or(d, |x| x.1);
    let rate_hz = 1.0 / cfg.sensors.gnss.period_s;
    let car = Car::from_model(&model);
    let dir = std::env::temp_dir().join("h2-gnss-rate");
    std::fs::create_dir_all(&dir).unwrap();
    let mut sums = [0.0; 4];
    for &seed in &seeds {
        let out = sim::simulate(
            &scenario,
            &cfg,
            &SimOptions {
                seed,
                faults: get("faults", 0.0) > 0.0,
                ..Default::default()
            },
        );
        let frames = csv2can::encode_log(&out.log).unwrap().frames;
        let mut config = model.node_config();
        config.origin_e7 = Some((
            (SIM_ORIGIN_DEG.0 * 1e7).round() as i32,
            (SIM_ORIGIN_DEG.1 * 1e7).round() as i32,
        ));
        let e = &mut config.estimator;
        *e = EstimatorConfig::design_scaled(
            rate_hz,
            get("exp", 1.0 / 3.0),
            e.antenna_ahead_m,
            e.antenna_left_m,
        )
        .unwrap();
        e.course_gain = get("gain", f64::from(e.course_gain)) as f32;
        e.track_span_fixes = get("span", f64::from(e.track_span_fixes)) as u32;
        let r = replay::replay(&frames, config);
        let pred_path = dir.join("pred.csv");
        std::fs::write(&pred_path, &r.predictions_csv).unwrap();
        let can_path = dir.join("in.can.log");
        std::fs::write(&can_path, csv2can::to_candump(&frames)).unwrap();
        let preds = catmodel_host::read_predictions(&pred_path).unwrap();
        let inputs = catmodel_host::baseline_inputs(&can_path, SIM_ORIGIN_DEG, &car).unwrap();
        let ev = evaluate::evaluate(
            &preds,
            &Truth::new(out.truth),
            &inputs,
            &car.vehicle,
            car.antenna_ahead_m,
        );
        let b = &ev.bias_floor;
        let h1 = ev
            .horizons
            .iter()
            .find(|h| (h.horizon_s - 1.0).abs() < 1e-9)
            .unwrap();
        let above = |x: f64| (x * x - b.pos_rms_m * b.pos_rms_m).max(0.0).sqrt();
        let ratio1 = above(h1.node.pos_rms_m) / above(h1.baseline.pos_rms_m);
        println!(
            "seed {seed}: floor {:.3}, filtered {:.3} x, vs raw {:.3}, heading {:.4}; 1 s above-floor ratio {:.3}",
            b.pos_rms_m,
            b.filtered_ratio.unwrap(),
            b.filtered_pos_rms_m / ev.raw_gnss_at_axle.pos_rms_m,
            ev.horizons[0].node.heading_rms_rad,
            ratio1
        );
        sums[0] += b.filtered_ratio.unwrap();
        sums[1] = f64::max(
            sums[1],
            b.filtered_pos_rms_m / ev.raw_gnss_at_axle.pos_rms_m,
        );
        sums[2] += ev.horizons[0].node.heading_rms_rad;
        sums[3] = f64::max(sums[3], ratio1);
    }
    let n = seeds.len() as f64;
    println!(
        "mean floor ratio {:.4}; worst vs raw {:.3}; mean heading {:.4}; worst 1 s above-floor ratio {:.3}",
        sums[0] / n,
        sums[1],
        sums[2] / n,
        sums[3]
    );
}
