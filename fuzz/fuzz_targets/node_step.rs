//! `Node::step` fed arbitrary frame sequences and tick times: raw frames (mostly rejected by
//! CRC, DLC or ID) mixed with well-formed input messages carrying arbitrary values (NaN,
//! infinities, out-of-range numbers, stuck or jumping counters, fixes anywhere on Earth) at
//! arbitrary times, with ticks that may stall, jump or go backwards.
//!
//! Asserts: no panic; every frame the node sends decodes with its own decoder (valid CRC, every
//! value inside its DBC range, so nothing non-finite left); at most `MAX_TX_FRAMES` frames;
//! every counter is monotonic; the estimate is finite.
#![no_main]
use arbitrary::Arbitrary;
use catmodel::can::codec::{
    Direction, GnssCogSog, GnssPosition, NodeStatus, PedalReport, Prediction, SpeedReport,
    StateMotion, StatePosition, SteeringReport,
};
use catmodel::can::spec::N2K_DEFAULT_SOURCE;
use catmodel::can::{CanFrame, CanId, TimedFrame};
use catmodel::node::{Counters, NodeConfig, PlatformStats, Tick, TxFrames};
use catmodel_fuzz::RawFrame;
use libfuzzer_sys::fuzz_target;

const ORIGIN: (i32, i32) = (322_319_000, -1_109_501_000);

#[derive(Arbitrary, Debug)]
enum Input {
    Raw(RawFrame),
    Steering {
        pct: f32,
        counter: u8,
    },
    Speed {
        v: f32,
        cmd: Option<f32>,
        /// SPEED_REPORT `direction`, raw (any of its four values).
        direction: u8,
        counter: u8,
    },
    Pedal {
        accel: f32,
        brake: f32,
        counter: u8,
    },
    /// A fix `(d_lat, d_lon)` 1e-7 deg from the origin (within ~3 km), or anywhere.
    FixNear {
        d_lat: i16,
        d_lon: i16,
    },
    FixAnywhere {
        lat_e7: i32,
        lon_e7: i32,
    },
    Cog {
        cog: f32,
        sog: f32,
    },
}

#[derive(Arbitrary, Debug)]
struct Received {
    /// Microseconds before the tick (may be "after" it: a clock mismatch).
    before_tick_us: i32,
    input: Input,
}

#[derive(Arbitrary, Debug)]
struct Step {
    /// Time since the previous tick, us; 0 and huge jumps included.
    advance_us: u32,
    /// The clock went backwards by `advance_us` instead.
    backwards: bool,
    frames: Vec<Received>,
    platform_overruns: u32,
}

fn encode(input: &Input) -> CanFrame {
    match *input {
        Input::Raw(r) => r.frame(),
        Input::Steering { pct, counter } => SteeringReport {
            steer_pct: Some(pct),
        }
        .encode(counter),
        Input::Speed {
            v,
            cmd,
            direction,
            counter,
        } => SpeedReport {
            speed_mps: Some(v),
            speed_cmd_mps: cmd,
            direction: [
                Direction::NotReported,
                Direction::Forward,
                Direction::Reverse,
                Direction::Invalid,
            ][usize::from(direction % 4)],
        }
        .encode(counter),
        Input::Pedal {
            accel,
            brake,
            counter,
        } => PedalReport {
            accel_pct: Some(accel),
            brake_pct: Some(brake),
        }
        .encode(counter),
        Input::FixNear { d_lat, d_lon } => GnssPosition {
            lat_e7: ORIGIN.0 + i32::from(d_lat) * 4,
            lon_e7: ORIGIN.1 + i32::from(d_lon) * 4,
        }
        .encode(N2K_DEFAULT_SOURCE),
        Input::FixAnywhere { lat_e7, lon_e7 } => {
            GnssPosition { lat_e7, lon_e7 }.encode(N2K_DEFAULT_SOURCE)
        }
        Input::Cog { cog, sog } => GnssCogSog {
            sid: 0,
            cog_reference: 0,
            cog_rad: Some(cog),
            sog_mps: Some(sog),
        }
        .encode(N2K_DEFAULT_SOURCE),
    }
}

fn assert_decodes(f: &CanFrame) {
    let CanId::Standard(id) = f.id else {
        panic!("the node sent an extended frame {f:?}");
    };
    let ok = match id {
        0x300 => StatePosition::decode(f).is_ok(),
        0x301 => StateMotion::decode(f).is_ok(),
        0x320 => catmodel::can::codec::ControlCommand::decode(f).is_ok(),
        0x310..=0x319 => Prediction::decode(f).is_ok(),
        0x3F0 => NodeStatus::decode(f).is_ok(),
        _ => false,
    };
    assert!(ok, "the node sent a frame its own decoder rejects: {f:?}");
}

fn counters_monotonic(a: &Counters, b: &Counters) {
    let fields = |c: &Counters| {
        [
            c.crc_errors,
            c.counter_errors,
            c.dlc_errors,
            c.range_errors,
            c.gnss_gate_rejects,
            c.unknown_ids,
            c.time_errors,
            c.nonfinite,
            c.saturated,
        ]
    };
    for (x, y) in fields(a).into_iter().zip(fields(b)) {
        assert!(y >= x, "a counter went down: {a:?} -> {b:?}");
    }
}

/// The published car (`models/paper.toml`), read once.
fn published() -> &'static NodeConfig {
    static CONFIG: std::sync::OnceLock<NodeConfig> = std::sync::OnceLock::new();
    CONFIG.get_or_init(|| catmodel_host::model_file::paper().node_config())
}

fuzz_target!(|input: (bool, Vec<Step>)| {
    let (fixed_origin, steps) = input;
    let mut config = published().clone();
    if fixed_origin {
        config.origin_e7 = Some(ORIGIN);
    }
    let mut node = catmodel_host::new_node(config);
    let mut now: u64 = 1_000_000_000;
    let mut overruns = 0u32;
    for step in steps.iter().take(400) {
        now = if step.backwards {
            now.saturating_sub(u64::from(step.advance_us))
        } else {
            now.saturating_add(u64::from(step.advance_us))
        };
        overruns = overruns.saturating_add(step.platform_overruns % 4);
        let rx: Vec<TimedFrame> = step
            .frames
            .iter()
            .take(64)
            .map(|r| TimedFrame {
                t_us: now.saturating_add_signed(-i64::from(r.before_tick_us)),
                frame: encode(&r.input),
            })
            .collect();
        let before = *node.counters();
        let mut tx = TxFrames::new();
        let est = node.step(
            &Tick {
                now_us: now,
                platform: PlatformStats {
                    overruns,
                    ..PlatformStats::default()
                },
            },
            &rx,
            &mut tx,
        );
        for f in &tx {
            assert_decodes(f);
        }
        counters_monotonic(&before, node.counters());
        assert!(est.speed_mps.is_finite(), "{est:?}");
        if let Some(p) = est.pose {
            assert!(
                p.x_m.is_finite() && p.y_m.is_finite() && p.heading_rad.is_finite(),
                "{est:?}"
            );
        }
    }
});
