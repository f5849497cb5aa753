//! `Node::step` on realistic traffic: the bundled drive (`data/bundled.can.log`, the 15 s smoke
//! drive `cargo qemu` runs), scheduled exactly as `catmodel replay` does (docs/architecture.md,
//! "Tick schedule").
//!
//! Run: `cargo bench -p catmodel-host --bench node_step`
//!
//! - `node_step/one_tick`: one tick in the middle of the drive (the car moving, filters warm,
//!   the full horizon rolled out), its own frames (steering, speed, pedal, GNSS), from the node
//!   state the replay had reached just before it (cloned per iteration, outside the timing).
//! - `node_step/bundled_drive`: every tick of the drive from a fresh node, no CSV or candump
//!   output; throughput in ticks.
use std::hint::black_box;
use std::path::Path;

use catmodel::can::TimedFrame;
use catmodel::node::{first_tick_us, PlatformStats, Tick, TxFrames};
use catmodel::SAMPLE_PERIOD_US;
use catmodel_host::replay::read_candump;
use criterion::{criterion_group, criterion_main, BatchSize, Criterion, Throughput};

/// The ticks of a drive: (tick time, range of `frames` that tick consumes), as `replay` runs them.
fn schedule(frames: &[TimedFrame]) -> Vec<(u64, std::ops::Range<usize>)> {
    let (Some(first), Some(last)) = (frames.first(), frames.last()) else {
        return Vec::new();
    };
    let mut ticks = Vec::new();
    let mut now = first_tick_us(first.t_us);
    let mut next = 0;
    while now <= first_tick_us(last.t_us) {
        let start = next;
        while next < frames.len() && frames[next].t_us <= now {
            next += 1;
        }
        ticks.push((now, start..next));
        now += SAMPLE_PERIOD_US;
    }
    ticks
}

fn tick(now_us: u64) -> Tick {
    Tick {
        now_us,
        platform: PlatformStats::default(),
    }
}

fn bench_node_step(c: &mut Criterion) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/bundled.can.log");
    let frames = read_candump(&path).expect("data/bundled.can.log");
    let ticks = schedule(&frames);
    let config = catmodel_host::model_file::paper().node_config();

    // State just before the middle tick.
    let mid = ticks.len() / 2;
    let mut node = catmodel_host::new_node(config.clone());
    let mut tx = TxFrames::new();
    for (now, range) in &ticks[..mid] {
        tx.clear();
        node.step(&tick(*now), &frames[range.clone()], &mut tx);
    }
    let (mid_now, mid_range) = ticks[mid].clone();
    let mid_frames = &frames[mid_range];
    // Check the tick is a representative one: a pose and all 10 predictions go out.
    {
        let mut probe = node.clone();
        tx.clear();
        let est = probe.step(&tick(mid_now), mid_frames, &mut tx);
        assert!(est.pose.is_some(), "mid-drive tick has no position");
        assert_eq!(tx.len(), 14, "3 state + 10 predictions + 1 status frame");
    }

    let mut group = c.benchmark_group("node_step");
    group.throughput(Throughput::Elements(1));
    group.bench_function("one_tick", |b| {
        b.iter_batched_ref(
            || (node.clone(), TxFrames::new()),
            |(n, tx)| {
                n.step(black_box(&tick(mid_now)), black_box(mid_frames), tx);
            },
            BatchSize::SmallInput,
        )
    });
    group.throughput(Throughput::Elements(ticks.len() as u64));
    group.bench_function("bundled_drive", |b| {
        b.iter(|| {
            let mut n = catmodel_host::new_node(config.clone());
            let mut tx = TxFrames::new();
            for (now, range) in &ticks {
                tx.clear();
                n.step(&tick(*now), black_box(&frames[range.clone()]), &mut tx);
            }
            black_box(n.tick_count())
        })
    });
    group.finish();
}

criterion_group!(benches, bench_node_step);
criterion_main!(benches);
