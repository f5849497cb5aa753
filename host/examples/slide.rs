//! The node's heading after a front-axle slide at full lock (docs/findings.md, "After a slide
//! at full lock the heading estimate stayed off for seconds").
//!
//! ```sh
//! cargo run --release -p catmodel-host --example slide                        # seeds 0..4
//! cargo run --release -p catmodel-host --example slide -- --at 10 --lock 1.5 --second 3 --after 3
//! cargo run --release -p catmodel-host --example slide -- --after 3 1 --trace # seed 1, twice a second
//! ```
//! The CAT Vehicle's plant with steering at 400 %/s (its model file says so too) drives at
//! `--at` m/s (12), steers to full lock right for `--lock` s (1), then full lock left as long
//! with the speed command at `--second` m/s (as `--at`; the car brakes in the slide), then
//! drives straight on for 40 s at `--after` m/s (10). The drive is replayed through the node
//! and its heading (the predictions' horizon 0) compared with the truth's: the largest error
//! in the slide, the error 5 and 10 s after it, and how long after it the error was last
//! above 0.1 rad.
use std::path::Path;

use anyhow::Result;
use catmodel_host::sim::config::VehicleConfig;
use catmodel_host::sim::scenario::Scenario;
use catmodel_host::sim::{self, SimOptions};
use catmodel_host::{csv2can, model_file, replay};

/// Steering rate of the probe's car, %/s.
const STEER_RATE_PCT_PER_S: f64 = 400.0;
/// ... for this long, then full lock the other way as long, s.
const LOCK_S: f64 = 1.0;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let trace = args.iter().any(|a| a == "--trace");
    let arg = |name: &str, default: f64| -> f64 {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
            .and_then(|a| a.parse().ok())
            .unwrap_or(default)
    };
    let slide_mps = arg("--at", 12.0);
    let lock_s = arg("--lock", LOCK_S);
    let after_mps = arg("--after", 10.0);
    // A seed: a number that is not a flag's value.
    let seed = args.iter().enumerate().find_map(|(i, a)| {
        let flag_value = i > 0
            && args
                .get(i - 1)
                .is_some_and(|p| p.starts_with("--") && p != "--trace");
        (!flag_value).then(|| a.parse().ok()).flatten()
    });
    let seeds: Vec<u64> = match seed {
        Some(s) => vec![s],
        None => (0..5).collect(),
    };
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut plant = VehicleConfig::load(&root.join("host/vehicles/cat-vehicle.toml"))
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    plant.steering.rate_limit_pct_per_s = STEER_RATE_PCT_PER_S;
    // The CAT Vehicle's model file is the published one (models/paper.toml).
    let mut file = model_file::paper();
    file.vehicle.max_steer_rate_pct_per_s = STEER_RATE_PCT_PER_S;
    let scenario = Scenario::slide(slide_mps, lock_s, arg("--second", slide_mps), after_mps);
    println!("| seed | largest error in the slide, rad | error 5 s after, rad | 10 s after | error above 0.1 rad until, s after the slide |");
    println!("|---|---|---|---|---|");
    for seed in seeds {
        let out = sim::simulate(
            &scenario,
            &plant,
            &SimOptions {
                seed,
                vary_commands: false,
                ..Default::default()
            },
        );
        let frames = csv2can::encode_log(&out.log)?.frames;
        let mut config = file.node_config();
        config.origin_e7 = Some(catmodel_host::sim_origin_e7());
        let csv = replay::replay(&frames, config).predictions_csv;
        // t,step,horizon_s,x,y,heading,speed,mode: the estimate is the horizon-0 row.
        let mut errors: Vec<(f64, f64)> = Vec::new();
        for line in csv.lines().skip(1) {
            let f: Vec<&str> = line.split(',').collect();
            let (Some(t), Some(h), Some(heading)) = (f.first(), f.get(2), f.get(5)) else {
                continue;
            };
            let (t, h, heading): (f64, f64, f64) = (t.parse()?, h.parse()?, heading.parse()?);
            if h != 0.0 {
                continue;
            }
            let i = out.truth.partition_point(|r| r.t < t);
            let Some(truth) = out.truth.get(i) else {
                continue;
            };
            let e = (heading - truth.heading + std::f64::consts::PI)
                .rem_euclid(2.0 * std::f64::consts::PI)
                - std::f64::consts::PI;
            errors.push((t, e));
        }
        let end_s = Scenario::SLIDE_START_S + 2.0 * lock_s;
        let in_slide = errors
            .iter()
            .filter(|(t, _)| *t >= Scenario::SLIDE_START_S && *t <= end_s + 1.0)
            .map(|(_, e)| e.abs())
            .fold(0.0, f64::max);
        let at = |s: f64| {
            errors
                .iter()
                .find(|(t, _)| *t >= end_s + s)
                .map_or(f64::NAN, |(_, e)| *e)
        };
        let last_bad = errors
            .iter()
            .filter(|(t, e)| *t >= end_s && e.abs() > 0.1)
            .map(|(t, _)| t - end_s)
            .fold(0.0, f64::max);
        println!(
            "| {seed} | {in_slide:.2} | {:.2} | {:.2} | {last_bad:.1} |",
            at(5.0),
            at(10.0)
        );
        if trace {
            for (t, e) in errors
                .iter()
                .filter(|(t, _)| *t >= Scenario::SLIDE_START_S - 1.0)
            {
                if ((t * 50.0).round() as i64) % 25 == 0 {
                    println!("t {t:.2} error {e:+.3}");
                }
            }
        }
        if let Some(w) = sim::slide_summary("slide", &out.truth, &plant) {
            eprintln!("{w}");
        }
    }
    Ok(())
}
