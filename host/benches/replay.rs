//! A full `replay` of the 5-minute validation drive (`simulate-drive --scenario validation`,
//! seed 0), generated in the setup with the library's simulator and `csv2can` encoder, exactly
//! what `catmodel simulate-drive` writes.
//!
//! Run: `cargo bench -p catmodel-host --bench replay`
//!
//! - `replay/validation_5min`: `catmodel_host::replay::replay` over the frames in memory: every
//!   tick of the node plus decoding its frames into the predictions CSV and the candump TX log
//!   (the CLI's work minus file I/O and candump parsing).
//! - `replay/validation_5min_node_only`: only the node's ticks over the same frames (the
//!   schedule precomputed), no CSV or candump text: what the formatting costs is the difference.
//! - `replay/validation_5min_from_text`: the same, starting from the candump text (parsing
//!   every line first, then `replay`).
//! - `replay/validation_5min_cli`: what `catmodel replay FILE.log --out P.csv` does after
//!   reading the file, minus writing it: `replay_text_into` (the text parsed on one thread
//!   ahead of the node, the CSV formatted on another behind it) into `io::sink()`, no TX text.
//!
//! `identify` on the paper-sized experiment set has its own bench: `host/benches/identify.rs`.
use std::hint::black_box;

use catmodel::can::{candump, TimedFrame};
use catmodel::node::{first_tick_us, NodeConfig, PlatformStats, Tick, TxFrames};
use catmodel::SAMPLE_PERIOD_US;
use catmodel_host::{csv2can, replay, sim};
use criterion::{criterion_group, criterion_main, Criterion, Throughput};

fn validation_frames() -> Vec<TimedFrame> {
    let out =
        sim::run_named("validation", None, &sim::SimOptions::default()).expect("built-in scenario");
    csv2can::encode_log(&out.log)
        .expect("simulated times are >= 0")
        .frames
}

fn config() -> NodeConfig {
    let mut config = catmodel_host::model_file::paper().node_config();
    config.origin_e7 = Some(catmodel_host::sim_origin_e7());
    config
}

fn bench_replay(c: &mut Criterion) {
    let frames = validation_frames();
    let text = csv2can::to_candump(&frames);
    let ticks = replay::tick_count(&frames);
    assert!(
        ticks >= 14_000,
        "about 5 minutes at 50 Hz, got {ticks} ticks"
    );
    let config = config();

    let mut group = c.benchmark_group("replay");
    group.sample_size(10);
    group.throughput(Throughput::Elements(ticks));
    group.bench_function("validation_5min", |b| {
        b.iter(|| {
            let out = replay::replay(black_box(&frames), config.clone());
            black_box(out.predictions_csv.len() + out.tx_log.len())
        })
    });
    let schedule: Vec<(u64, std::ops::Range<usize>)> = {
        let mut out = Vec::new();
        let mut now = first_tick_us(frames[0].t_us);
        let last = first_tick_us(frames[frames.len() - 1].t_us);
        let mut next = 0;
        while now <= last {
            let start = next;
            while next < frames.len() && frames[next].t_us <= now {
                next += 1;
            }
            out.push((now, start..next));
            now += SAMPLE_PERIOD_US;
        }
        out
    };
    assert_eq!(schedule.len() as u64, ticks);
    group.bench_function("validation_5min_node_only", |b| {
        b.iter(|| {
            let mut node = catmodel_host::new_node(config.clone());
            let mut tx = TxFrames::new();
            for (now, range) in &schedule {
                tx.clear();
                let tick = Tick {
                    now_us: *now,
                    platform: PlatformStats::default(),
                };
                node.step(&tick, black_box(&frames[range.clone()]), &mut tx);
            }
            black_box(node.tick_count())
        })
    });
    group.bench_function("validation_5min_from_text", |b| {
        b.iter(|| {
            let parsed: Vec<TimedFrame> = black_box(&text)
                .lines()
                .filter_map(|l| candump::parse_line(l).ok())
                .collect();
            let out = replay::replay(&parsed, config.clone());
            black_box(out.predictions_csv.len() + out.tx_log.len())
        })
    });
    let text_path = std::path::Path::new("validation.can.log");
    group.bench_function("validation_5min_cli", |b| {
        b.iter(|| {
            let stats = replay::replay_text_into(
                text_path,
                black_box(&text),
                config.clone(),
                std::io::sink(),
                None::<std::io::Sink>,
                |_| {},
            )
            .expect("valid log");
            black_box(stats.ticks)
        })
    });
    group.finish();
}

criterion_group!(benches, bench_replay);
criterion_main!(benches);
