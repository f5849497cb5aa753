//! `identify` on the paper-sized experiment set (issue 7), as README "Identify, compare,
//! discretize" runs it: 11 one-minute simulator drives for training (straight-2.5/5/7.5/10,
//! turn-left/right, circle-left/right with seed 1; straight-2.5/5/10 with seed 2) and the
//! 5-minute validation drive (seed 3). The drives are generated once in the setup with the
//! library's simulator, written to CSV text and parsed back (so the rows carry exactly the
//! precision of the files `catmodel simulate-drive` writes), then preprocessed.
//!
//! Run: `cargo bench -p catmodel-host --bench identify`
//!
//! - `identify/paper_set`: `identify::identify` on the preprocessed experiments: step
//!   responses, correlation ranking, ARX + speed model (delay scan, simulation-error fit), eq 7
//!   MISO dx/dt, lateral model, simulation and scores on training and validation data. This is
//!   the "identified in ... s" of `catmodel identify` (the CLI adds reading and preprocessing
//!   the CSVs and writing the model file).
//! - `identify/speed_model`: `identify::identify_speed` alone (ARX selection, delay scan,
//!   simulation-error fit of the eq 5-form model), the part `scripts/peers/identify_scipy.py`
//!   reimplements.
//! - `identify/preprocess_12_logs`: `preprocess_rows` on the 12 logs' rows (20 ms grid,
//!   zero-phase FIR + smooth, GNSS to metres, derived signals).
use std::hint::black_box;
use std::path::Path;
use std::time::Duration;

use catmodel_host::identify::preprocess::{preprocess_rows, Experiment, PreprocessOptions};
use catmodel_host::identify::{self, IdentifyOptions};
use catmodel_host::logcsv::{self, LogRow};
use catmodel_host::model_file::{self, VehicleSection};
use catmodel_host::sim::scenario::PAPER_SIZED_TRAINING;
use catmodel_host::sim::{self, SimOptions};
use criterion::{criterion_group, criterion_main, BatchSize, Criterion};

/// A named log: (file stem, rows).
type Log = (String, Vec<LogRow>);

/// The log rows of one simulated drive, through the CSV text `simulate-drive` writes.
fn drive(name: &str, seed: u64) -> Log {
    let out = sim::run_named(
        name,
        None,
        &SimOptions {
            seed,
            ..SimOptions::default()
        },
    )
    .expect("built-in scenario");
    let mut text = Vec::new();
    logcsv::write_log_to(&mut text, &out.log).expect("simulator rows are writable");
    let text = String::from_utf8(text).expect("CSV is UTF-8");
    let rows = logcsv::parse_log(&text, Path::new(name))
        .expect("written CSV parses")
        .rows;
    (name.to_string(), rows)
}

/// (training drives, validation drive), as in README "Identify, compare, discretize".
fn paper_set() -> (Vec<Log>, Vec<Log>) {
    let training = PAPER_SIZED_TRAINING
        .iter()
        .map(|&(n, seed)| drive(n, seed))
        .collect();
    (training, vec![drive("validation", 3)])
}

fn preprocess(logs: &[Log], vehicle: &VehicleSection) -> Vec<Experiment> {
    logs.iter()
        .map(|(name, rows)| {
            preprocess_rows(name, rows, vehicle, &PreprocessOptions::default())
                .expect("simulated logs preprocess")
        })
        .collect()
}

fn bench_identify(c: &mut Criterion) {
    let base = model_file::load(&model_file::paper_path()).expect("models/paper.toml");
    let (train_logs, val_logs) = paper_set();
    let training = preprocess(&train_logs, &base.vehicle);
    let validation = preprocess(&val_logs, &base.vehicle);
    assert_eq!(training.len(), 11);
    let opts = IdentifyOptions::default();
    // The result is the one README reports (speed validation fit about 92 %).
    {
        let id = identify::identify(training.clone(), validation.clone(), &base, &opts)
            .expect("the paper-sized set identifies");
        let fit = id
            .validation_scores
            .and_then(|s| s.vel_model.fit_percent)
            .expect("validation fit");
        assert!(fit > 87.0, "validation speed fit {fit:.2} %");
        eprintln!("identify/paper_set: validation speed fit {fit:.2} %");
    }

    let mut group = c.benchmark_group("identify");
    group.sample_size(10);
    group.measurement_time(Duration::from_secs(30));
    group.bench_function("paper_set", |b| {
        b.iter_batched(
            || (training.clone(), validation.clone()),
            |(t, v)| {
                let id = identify::identify(t, v, &base, &opts).expect("identifies");
                black_box(id.speed.tf)
            },
            BatchSize::LargeInput,
        )
    });
    group.bench_function("speed_model", |b| {
        b.iter(|| {
            let s = identify::identify_speed(black_box(&training), &validation, &opts)
                .expect("identifies");
            black_box(s.tf)
        })
    });
    group.measurement_time(Duration::from_secs(5));
    group.bench_function("preprocess_12_logs", |b| {
        b.iter(|| {
            let t = preprocess(black_box(&train_logs), &base.vehicle);
            let v = preprocess(black_box(&val_logs), &base.vehicle);
            black_box(t.len() + v.len())
        })
    });
    group.finish();
}

criterion_group!(benches, bench_identify);
criterion_main!(benches);
