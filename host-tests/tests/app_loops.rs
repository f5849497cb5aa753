//! The firmware's app layer (`catmodel-app`: receive loop, 20 ms tick loop, transmit loop, and
//! the replay clock QEMU uses) run on the host, on embassy-time's mock driver, against host
//! replay: the same frames, byte for byte, at the same tick times, whatever time the drive
//! starts at (0, a tick boundary, just after one, just before one, an epoch time, random ones).
//! This is the "one tick schedule for every platform" property; `cargo xtask tick-schedule`
//! checks the real QEMU firmware on the same kinds of start.
use std::future::Future;
use std::pin::pin;
use std::sync::Mutex;
use std::task::{Context, Poll, Waker};

use catmodel::can::{CanFrame, TimedFrame};
use catmodel::node::{first_tick_us, NodeConfig};
use catmodel_app::{
    receive_loop, tick_loop, transmit_loop, wait_tx_drained, BusReceiver, BusTransmitter,
    LinkCounters, ReplayClock, RxError, RxQueue, TickPlatform, TickReport, TxQueue,
};
use embassy_futures::join::join;
use embassy_futures::select::{select, Either};
use embassy_time::{Duration, Instant, MockDriver, Timer};
use proptest::prelude::*;

/// The mock driver is one per process: runs take turns.
static DRIVER_LOCK: Mutex<()> = Mutex::new(());

/// Frames released on the replay clock, as QEMU's replay bus does.
struct VecBus<'a> {
    frames: std::slice::Iter<'a, TimedFrame>,
    clock: ReplayClock,
}

impl BusReceiver for VecBus<'_> {
    async fn receive(&mut self) -> Result<TimedFrame, RxError> {
        let Some(frame) = self.frames.next() else {
            return Err(RxError::EndOfInput);
        };
        let release_us = self.clock.release_instant_us(frame.t_us);
        if Instant::now().as_micros() < release_us {
            Timer::at(Instant::from_micros(release_us)).await;
        }
        Ok(*frame)
    }
}

/// The transmitted frames, stamped with their tick's time.
struct VecTx(Vec<(u64, CanFrame)>);

impl BusTransmitter for VecTx {
    async fn transmit(&mut self, frame: &TimedFrame) -> Result<(), ()> {
        self.0.push((frame.t_us, frame.frame));
        Ok(())
    }
}

/// Nothing to measure with on the host.
struct NoCounter;

impl TickPlatform for NoCounter {
    fn counter(&self) -> u32 {
        0
    }
    fn counts_to_us(&self, _counts: u32) -> Option<u32> {
        None
    }
    fn tick_completed(&mut self, _report: &TickReport) {}
}

/// The app layer over `frames` (sorted by time) on the replay clock: the frames it sends, and
/// the ticks it ran.
fn run_app(frames: &[TimedFrame], config: NodeConfig) -> (Vec<(u64, CanFrame)>, u64) {
    let _turn = DRIVER_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let driver = MockDriver::get();
    driver.reset();
    let clock = ReplayClock::new(frames[0].t_us);
    let tick_config = clock.tick_config(frames[frames.len() - 1].t_us);
    let (rx, tx, counters) = (RxQueue::new(), TxQueue::new(), LinkCounters::new());
    let mut bus = VecBus {
        frames: frames.iter(),
        clock,
    };
    let mut out = VecTx(Vec::new());
    let mut node = catmodel_host::new_node(config);
    let mut platform = NoCounter;
    let ticks = {
        let main = async {
            let (_, summary) = join(
                receive_loop(&mut bus, &rx, &counters),
                tick_loop(&mut node, &rx, &tx, &counters, &mut platform, &tick_config),
            )
            .await;
            wait_tx_drained(&counters).await;
            summary
        };
        let mut run = pin!(select(main, transmit_loop(&mut out, &tx, &counters)));
        let mut cx = Context::from_waker(Waker::noop());
        // The drive's length plus a second: a run still going then is stuck.
        let limit_us = frames[frames.len() - 1].t_us - frames[0].t_us + 1_000_000;
        loop {
            match run.as_mut().poll(&mut cx) {
                Poll::Ready(Either::First(summary)) => break summary.ticks,
                Poll::Ready(Either::Second(never)) => match never {},
                // Deadlines and releases are whole multiples of 20 ms: 1 ms steps hit each one.
                Poll::Pending => driver.advance(Duration::from_micros(1_000)),
            }
            assert!(
                Instant::now().as_micros() <= limit_us,
                "the app loops did not finish the drive starting at {} us",
                frames[0].t_us
            );
        }
    };
    assert_eq!(
        counters
            .rx_queue_drops
            .load(std::sync::atomic::Ordering::Relaxed),
        0
    );
    (out.0, ticks)
}

/// Host replay's candump lines of the same run.
fn replay_lines(frames: &[TimedFrame], config: NodeConfig) -> String {
    catmodel_host::replay::replay(frames, config).tx_log
}

fn lines(sent: &[(u64, CanFrame)]) -> String {
    sent.iter()
        .map(|(t, f)| catmodel_host::replay::candump_line(*t, f) + "\n")
        .collect()
}

/// The first `seconds` of the bundled drive, moved to start at `start_us`.
fn drive_from(start_us: u64, seconds: u64) -> Vec<TimedFrame> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/bundled.can.log");
    let frames = catmodel_host::replay::read_candump(&path).unwrap();
    let t0 = frames[0].t_us;
    frames
        .iter()
        .filter(|f| f.t_us - t0 < seconds * 1_000_000)
        .map(|f| TimedFrame {
            t_us: f.t_us - t0 + start_us,
            frame: f.frame,
        })
        .collect()
}

fn config() -> NodeConfig {
    catmodel_model_file::paper().node_config()
}

fn assert_same_as_replay(start_us: u64, seconds: u64) {
    let frames = drive_from(start_us, seconds);
    let (sent, ticks) = run_app(&frames, config());
    let expected = replay_lines(&frames, config());
    assert_eq!(
        ticks,
        catmodel_host::replay::tick_count(&frames),
        "start {start_us}"
    );
    assert_eq!(
        sent.first().map(|(t, _)| *t),
        Some(first_tick_us(start_us)),
        "start {start_us}: first tick"
    );
    assert!(lines(&sent) == expected, "start {start_us}: frames differ");
}

#[test]
fn app_loops_tick_where_host_replay_does_for_named_starts() {
    // 0, a tick boundary, just after one, just before one, an epoch time (the bundled drive's).
    for start_us in [0, 40_000, 40_001, 39_999, 1_700_000_000_003_296] {
        assert_same_as_replay(start_us, 6);
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    /// Any start time, from 0 to beyond 2^40 us, on or off the grid.
    #[test]
    fn app_loops_tick_where_host_replay_does_for_any_start(
        start_us in prop_oneof![
            0u64..200_000,
            (0u64..50_000_000).prop_map(|k| k * 20_000),
            0u64..(1u64 << 41),
        ]
    ) {
        assert_same_as_replay(start_us, 2);
    }
}

/// Frames bunched into single ticks (more than a tick takes: the rest wait for the next ones)
/// and frames the acceptance filter refuses: the app and host replay hand the node the same
/// frames at the same ticks.
#[test]
fn app_loops_hold_back_and_filter_as_host_replay_does() {
    let mut frames = drive_from(1_700_000_000_003_296, 6);
    let t0 = frames[0].t_us;
    for f in &mut frames {
        // Every 0.5 s, 60 ms of traffic arrives at once.
        let phase = (f.t_us - t0) % 500_000;
        if (200_000..260_000).contains(&phase) {
            f.t_us += 260_000 - phase;
        }
    }
    let extra: Vec<TimedFrame> = frames
        .iter()
        .step_by(3)
        .map(|f| TimedFrame {
            t_us: f.t_us,
            frame: CanFrame::new(catmodel::can::CanId::Standard(0x7F0), &[1, 2, 3]).unwrap(),
        })
        .collect();
    frames.extend(extra);
    frames.sort_by_key(|f| f.t_us);
    let burst = frames
        .chunk_by(|a, b| first_tick_us(a.t_us) == first_tick_us(b.t_us))
        .map(|tick| {
            tick.iter()
                .filter(|f| catmodel::can::spec::is_node_input(f.frame.id))
                .count()
        })
        .max()
        .unwrap();
    assert!(
        burst > catmodel::node::MAX_RX_FRAMES_PER_TICK,
        "the drive must hold frames back ({burst} in its fullest tick)"
    );
    let (sent, ticks) = run_app(&frames, config());
    let replay = catmodel_host::replay::replay(&frames, config());
    assert_eq!(ticks, replay.ticks);
    assert!(lines(&sent) == replay.tx_log, "frames differ");
}
