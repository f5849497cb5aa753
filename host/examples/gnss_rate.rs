//! The node's GNSS estimator at receiver rates from 1 to 100 Hz: the figures behind
//! `EstimatorConfig::design` (README, "Any receiver rate").
//!
//! ```sh
//! cargo run --release -p catmodel-host --example gnss_rate                   # the design, 1..100 Hz
//! cargo run --release -p catmodel-host --example gnss_rate -- --exponents    # the window rule at 10 Hz
//! ```
//! For each rate: the second car (host/vehicles/vw-polo.toml, its car file for the node) with its
//! receiver set to that rate, the 5-minute validation drive with seeds 0, 5, 7 and 9 (none of
//! them used to choose anything), replayed and scored against truth: the filtered position's
//! ratio to the bias floor (mean), its ratio to raw GNSS at the rear axle (worst), the heading
//! error (mean RMS) and, 1 s ahead, the node's error above the floor over the kinematic
//! baseline's (worst). `--exponents` compares window rules `T ~ rate^-e` at 10 Hz instead.
use std::path::Path;

use anyhow::{Context, Result};
use catmodel::node::estimator::{EstimatorConfig, WINDOW_EXPONENT};
use catmodel_host::evaluate::{self, Truth};
use catmodel_host::sim::config::VehicleConfig;
use catmodel_host::sim::scenario::Scenario;
use catmodel_host::sim::{self, SimOptions};
use catmodel_host::{csv2can, identify, model_file, replay, Car, SIM_ORIGIN_DEG};

const SEEDS: [u64; 4] = [0, 5, 7, 9];
const RATES_HZ: [f64; 7] = [1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0];

/// Scores of one configuration over the seeds.
#[derive(Default)]
struct Row {
    floor_ratio_mean: f64,
    vs_raw_worst: f64,
    heading_mean_rad: f64,
    ahead_1s_worst: f64,
}

/// Scores of one drive.
struct Drive {
    floor_ratio: f64,
    vs_raw: f64,
    heading_rad: f64,
    ahead_1s: f64,
}

impl Row {
    fn over(drives: &[Drive]) -> Row {
        let n = drives.len() as f64;
        drives.iter().fold(Row::default(), |row, d| Row {
            floor_ratio_mean: row.floor_ratio_mean + d.floor_ratio / n,
            vs_raw_worst: row.vs_raw_worst.max(d.vs_raw),
            heading_mean_rad: row.heading_mean_rad + d.heading_rad / n,
            ahead_1s_worst: row.ahead_1s_worst.max(d.ahead_1s),
        })
    }
}

/// One validation drive of the second car with its receiver at `rate_hz`, replayed through the
/// node with the window rule `window_exponent`, scored against truth.
fn score(rate_hz: f64, window_exponent: f64, seed: u64) -> Result<Drive> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut plant = VehicleConfig::load(&root.join("host/vehicles/vw-polo.toml"))
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    plant.sensors.gnss.period_s = 1.0 / rate_hz;
    let mut file = identify::car::apply(
        &model_file::paper(),
        &root.join("host/vehicles/vw-polo.car.toml"),
    )?
    .file;
    file.vehicle.gnss_rate_hz = rate_hz;
    let car = Car::from_model(&file);
    let scenario = Scenario::builtin("validation").context("built-in scenario")?;
    let dir = std::env::temp_dir().join(format!(
        "catmodel-gnss-rate-{}-{rate_hz}-{window_exponent}-{seed}",
        std::process::id()
    ));
    std::fs::create_dir_all(&dir)?;
    let out = sim::simulate(
        &scenario,
        &plant,
        &SimOptions {
            seed,
            ..Default::default()
        },
    );
    let frames = csv2can::encode_log(&out.log)?.frames;
    let mut config = file.node_config();
    config.origin_e7 = Some(catmodel_host::sim_origin_e7());
    let e = &config.estimator;
    config.estimator = EstimatorConfig::design_scaled(
        rate_hz,
        window_exponent,
        e.antenna_ahead_m,
        e.antenna_left_m,
    )
    .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let predictions = dir.join("pred.csv");
    std::fs::write(
        &predictions,
        replay::replay(&frames, config).predictions_csv,
    )?;
    let inputs = dir.join("in.can.log");
    std::fs::write(&inputs, csv2can::to_candump(&frames))?;
    let ev = evaluate::evaluate(
        &catmodel_host::read_predictions(&predictions)?,
        &Truth::new(out.truth),
        &catmodel_host::baseline_inputs(&inputs, SIM_ORIGIN_DEG, &car)?,
        &car.vehicle,
        car.antenna_ahead_m,
    );
    std::fs::remove_dir_all(&dir)?;
    let floor = &ev.bias_floor;
    let ahead = ev
        .horizons
        .iter()
        .find(|h| (h.horizon_s - 1.0).abs() < 1e-9)
        .context("no 1 s horizon")?;
    let above = |x: f64| (x * x - floor.pos_rms_m * floor.pos_rms_m).max(0.0).sqrt();
    Ok(Drive {
        floor_ratio: floor.filtered_ratio.unwrap_or(f64::NAN),
        vs_raw: floor.filtered_pos_rms_m / ev.raw_gnss_at_axle.pos_rms_m,
        heading_rad: ev.horizons[0].node.heading_rms_rad,
        ahead_1s: above(ahead.node.pos_rms_m) / above(ahead.baseline.pos_rms_m),
    })
}

/// Every (configuration, seed) drive, on as many threads as the machine has; results in the
/// order of `jobs` (each drive is independent and deterministic, so the table does not depend
/// on the threads).
fn score_all(jobs: &[(f64, f64, u64)]) -> Result<Vec<Drive>> {
    let next = std::sync::atomic::AtomicUsize::new(0);
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut done: Vec<(usize, Result<Drive>)> = std::thread::scope(|s| {
        let workers: Vec<_> = (0..threads.min(jobs.len()))
            .map(|_| {
                s.spawn(|| {
                    let mut mine = Vec::new();
                    loop {
                        let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        let Some(&(rate_hz, exponent, seed)) = jobs.get(i) else {
                            return mine;
                        };
                        mine.push((i, score(rate_hz, exponent, seed)));
                    }
                })
            })
            .collect();
        workers
            .into_iter()
            .flat_map(|w| w.join().unwrap_or_default())
            .collect()
    });
    anyhow::ensure!(done.len() == jobs.len(), "a worker thread panicked");
    done.sort_by_key(|(i, _)| *i);
    done.into_iter().map(|(_, d)| d).collect()
}

fn main() -> Result<()> {
    let exponents = std::env::args().any(|a| a == "--exponents");
    println!(
        "| rate Hz | window exponent | FIR taps / MA span / cutoff Hz | filtered / bias floor (mean) | filtered / raw GNSS (worst) | heading RMS rad (mean) | 1 s above floor, node / baseline (worst) |"
    );
    println!("|---|---|---|---|---|---|---|");
    let runs: Vec<(f64, f64)> = if exponents {
        [0.0, WINDOW_EXPONENT, 0.5, 1.0]
            .iter()
            .map(|e| (10.0, *e))
            .collect()
    } else {
        RATES_HZ.iter().map(|r| (*r, WINDOW_EXPONENT)).collect()
    };
    let jobs: Vec<(f64, f64, u64)> = runs
        .iter()
        .flat_map(|&(rate_hz, exponent)| SEEDS.iter().map(move |&seed| (rate_hz, exponent, seed)))
        .collect();
    let drives = score_all(&jobs)?;
    for (&(rate_hz, exponent), drives) in runs.iter().zip(drives.chunks(SEEDS.len())) {
        let design = EstimatorConfig::design_scaled(rate_hz, exponent, 0.0, 0.0)
            .map_err(|e| anyhow::anyhow!("{e:?}"))?;
        let cutoff = EstimatorConfig::scaled_cutoff_hz(rate_hz, exponent);
        let r = Row::over(drives);
        println!(
            "| {rate_hz} | {exponent:.3} | {} / {} / {cutoff:.2} | {:.3} | {:.3} | {:.4} | {:.3} |",
            design.fir.len(),
            design.ma.len(),
            r.floor_ratio_mean,
            r.vs_raw_worst,
            r.heading_mean_rad,
            r.ahead_1s_worst
        );
    }
    Ok(())
}
