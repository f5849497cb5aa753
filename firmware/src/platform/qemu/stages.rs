//! The tick's stages measured one by one in QEMU: the per-stage maxima of the worst-case bound
//! (`catmodel::node::stage`, docs/firmware.md "Worst-case tick").
//!
//! Each drive (a candump file, one fresh node each) goes through the firmware's own receive
//! path and tick: frames due at the tick pass the acceptance filter into an [`RxQueue`], the
//! tick drains at most its batch ([`RxQueue::drain_due`]), runs `Node::step_probed` with a
//! probe that reads TIM2 at the end of every stage, and hands the frames to a [`TxQueue`]
//! ([`hand_off`]). A second node, fed the same frames, runs the plain `Node::step`, timed whole:
//! what the probed run cannot see (the difference between the two builds of the step) is
//! reported as its own row. Every count is TIM2's, one per instruction under `-icount shift=0`.
//!
//! Output (semihosting stderr), tab-separated: one
//! `stage KEY MAX_PER_TICK RUNS MAX DRIVE MAX_CONTROL DRIVE_CONTROL BRANCH EXCLUSIVE WHY` line
//! per row (the node's rows of `TICK_STAGES`, then the app's; MAX over the ticks in which no
//! controller planned, MAX_CONTROL over every tick; DRIVE is the index of the drive that showed
//! the maximum; BRANCH the row's `Branch::key`, the app's rows are common; EXCLUSIVE the row's
//! `Exclusive::key`, `-` when it is in no exclusive set), one `stage-ticks TICKS MAX_TICK DRIVE MAX_CONTROL_TICK DRIVE_CONTROL` line (the
//! largest whole ticks measured, without and with a controller planning), and `stage-done`.
//! A tick is a controller tick when a controller planned in it or a planner path was completed
//! in it (`TickEstimate::controller_tick`), as the app flags it (`TickReport::controller`).
//! `cargo qemu` and `cargo xtask bench-target` turn them into the bound.
use core::ffi::CStr;
use core::sync::atomic::{compiler_fence, Ordering};

use catmodel::can::spec::is_node_input;
use catmodel::can::{candump, TimedFrame};
use catmodel::node::drive::Drive;
use catmodel::node::{
    first_tick_us, Branch, BranchTaken, Node, PlatformStats, Stage, StageProbe, Tick, TxFrames,
    TICK_STAGES,
};
use catmodel::SAMPLE_PERIOD_US;
use catmodel_app::{hand_off, LinkCounters, RxQueue, TxBatch, TxQueue, RX_BATCH_LEN};

use super::icount;
use super::replay::{LineReader, Source, LINE_MAX};

/// Rows of the node's structure.
const NODE_ROWS: usize = TICK_STAGES.len();

/// The largest run of each stage (in ticks without and with a controller planning), and how
/// often each ran in the current tick.
pub struct Laps {
    last: u32,
    overhead: u32,
    /// The drive being measured (index into the paths).
    drive: u32,
    /// Largest run in a tick without a controller planning, and the drive that showed it.
    plain: [(u32, u32); NODE_ROWS],
    /// Largest run in any tick, and the drive that showed it.
    any: [(u32, u32); NODE_ROWS],
    runs: [u32; NODE_ROWS],
    this_tick: [u32; NODE_ROWS],
    /// Largest run of each stage in the current tick.
    tick_max: [u32; NODE_ROWS],
    tick_sum: u32,
    /// The branch the current tick took.
    branch: BranchTaken,
    /// A stage ran more often in one tick than its row allows, or beside a stage of another
    /// branch (the structure is wrong).
    pub over_structure: Option<Stage>,
}

impl Laps {
    const fn new() -> Self {
        Self {
            last: 0,
            overhead: 0,
            drive: 0,
            plain: [(0, 0); NODE_ROWS],
            any: [(0, 0); NODE_ROWS],
            runs: [0; NODE_ROWS],
            this_tick: [0; NODE_ROWS],
            tick_max: [0; NODE_ROWS],
            tick_sum: 0,
            branch: BranchTaken::new(),
            over_structure: None,
        }
    }

    /// Starts a tick: the first stage's run begins now.
    #[inline(always)]
    fn start(&mut self) {
        self.this_tick = [0; NODE_ROWS];
        self.tick_max = [0; NODE_ROWS];
        self.tick_sum = 0;
        self.branch = BranchTaken::new();
        compiler_fence(Ordering::SeqCst);
        self.last = icount::now();
    }

    /// Ends a tick: its stages' runs count towards the plain maxima unless a controller
    /// planned in it, and towards the maxima of any tick.
    fn end_tick(&mut self, controller: bool) {
        let drive = self.drive;
        for (i, &n) in self.tick_max.iter().enumerate() {
            if let Some(slot) = self.any.get_mut(i) {
                keep_max(slot, n, drive);
            }
            if !controller {
                if let Some(slot) = self.plain.get_mut(i) {
                    keep_max(slot, n, drive);
                }
            }
        }
    }

    /// Instructions since the last lap (the probe's own are excluded).
    #[inline(always)]
    fn since_last(&self, now: u32) -> u32 {
        now.wrapping_sub(self.last).saturating_sub(self.overhead)
    }
}

impl StageProbe for Laps {
    #[inline(always)]
    fn lap(&mut self, stage: Stage) {
        compiler_fence(Ordering::SeqCst);
        let now = icount::now();
        let n = self.since_last(now);
        if let Some(i) = TICK_STAGES.iter().position(|row| row.stage == stage) {
            if let (Some(max), Some(runs), Some(this), Some(row)) = (
                self.tick_max.get_mut(i),
                self.runs.get_mut(i),
                self.this_tick.get_mut(i),
                TICK_STAGES.get(i),
            ) {
                *max = (*max).max(n);
                *runs += 1;
                *this += 1;
                if *this > row.max_per_tick || !self.branch.enter(stage) {
                    self.over_structure = Some(stage);
                }
            }
        }
        self.tick_sum += n;
        self.last = icount::now();
        compiler_fence(Ordering::SeqCst);
    }
}

/// The app's part of the tick, and what the probe cannot attribute: each the largest seen,
/// with the drive that showed it, in ticks without a controller planning (`.0`) and in any
/// tick (`.1`).
#[derive(Default)]
struct AppMax {
    drain: [(u32, u32); 2],
    handoff: [(u32, u32); 2],
    step_return: [(u32, u32); 2],
    unattributed: [(u32, u32); 2],
    whole_tick: [(u32, u32); 2],
    ticks: u32,
}

/// Keeps `n` in the plain slot (unless `controller`) and in the any-tick slot.
fn keep_both(slots: &mut [(u32, u32); 2], n: u32, drive: u32, controller: bool) {
    let [plain, any] = slots;
    if !controller {
        keep_max(plain, n, drive);
    }
    keep_max(any, n, drive);
}

/// Keeps the larger of `(max, drive)` and `(n, drive)`.
fn keep_max(slot: &mut (u32, u32), n: u32, drive: u32) {
    if n > slot.0 {
        *slot = (n, drive);
    }
}

static RX: RxQueue = RxQueue::new();
static TX: TxQueue = TxQueue::new();
static COUNTERS: LinkCounters = LinkCounters::new();
/// The two nodes, their drive stages and the drive's reader live in statics: two nodes
/// (2.6 KiB each), two drive stages (35 KiB each) and a reader (1 KiB) on the 16 KiB stack
/// would leave too little for the ticks themselves.
static mut PROBED: Option<Node<&'static mut Drive>> = None;
static mut PLAIN: Option<Node<&'static mut Drive>> = None;
static mut PROBED_DRIVE: Drive = Drive::new();
static mut PLAIN_DRIVE: Drive = Drive::new();
static mut READER: Option<LineReader> = None;

/// Why a drive could not be measured.
#[derive(Clone, Copy, Debug)]
pub enum StageError {
    /// The file could not be opened or read.
    Io,
    /// The baked model does not build.
    Model,
    /// A stage ran more often in one tick than `TICK_STAGES` allows, or beside a stage of
    /// another branch.
    Structure(Stage),
}

/// Instructions between two reads of the counter with nothing in between (subtracted from
/// every lap).
fn calibrate(laps: &mut Laps) -> u32 {
    let mut min = u32::MAX;
    for _ in 0..64 {
        laps.start();
        let a = icount::now();
        let b = icount::now();
        core::hint::black_box(&mut *laps);
        min = min.min(b.wrapping_sub(a));
    }
    min
}

/// Measures every drive in `paths` (host paths, NUL-terminated) and prints the rows.
pub fn measure(paths: &[&CStr]) -> Result<(), StageError> {
    let laps = &mut Laps::new();
    laps.overhead = calibrate(laps);
    let mut app = AppMax::default();
    // SAFETY: the only references to these statics; `measure` runs once, single-threaded, no
    // interrupts.
    let (probed, plain, reader) = unsafe {
        (
            &mut *core::ptr::addr_of_mut!(PROBED),
            &mut *core::ptr::addr_of_mut!(PLAIN),
            &mut *core::ptr::addr_of_mut!(READER),
        )
    };
    for (index, path) in paths.iter().enumerate() {
        laps.drive = index as u32;
        let file = semihosting::fs::File::open(path).map_err(|_| StageError::Io)?;
        *reader = Some(LineReader::new(Source::File(file)));
        let config = crate::baked::node_config().map_err(|_| StageError::Model)?;
        // The previous drive's nodes go first: they hold the only references to the drive
        // stages.
        *probed = None;
        *plain = None;
        // SAFETY: the nodes that held these references were dropped just above; the new
        // nodes are the only holders until the next drive drops them again.
        let (probed_drive, plain_drive) = unsafe {
            (
                &mut *core::ptr::addr_of_mut!(PROBED_DRIVE),
                &mut *core::ptr::addr_of_mut!(PLAIN_DRIVE),
            )
        };
        *probed = Some(Node::new(config.clone(), probed_drive));
        *plain = Some(Node::new(config, plain_drive));
        if let (Some(reader), Some(probed), Some(plain)) =
            (reader.as_mut(), probed.as_mut(), plain.as_mut())
        {
            drive(reader, probed, plain, laps, &mut app)?;
        }
    }
    if let Some(stage) = laps.over_structure {
        return Err(StageError::Structure(stage));
    }
    for (i, row) in TICK_STAGES.iter().enumerate() {
        let (plain, any) = (
            laps.plain.get(i).copied().unwrap_or((0, 0)),
            laps.any.get(i).copied().unwrap_or((0, 0)),
        );
        semihosting::eprintln!(
            "stage\t{}\t{}\t{}\t{}\t{}\t{}\t{}\t{}\t{}\t{}",
            row.key,
            row.max_per_tick,
            laps.runs.get(i).copied().unwrap_or(0),
            plain.0,
            plain.1,
            any.0,
            any.1,
            row.branch.key(),
            row.exclusive.map_or("-", |e| e.key()),
            row.because
        );
    }
    for (key, max, why) in [
        (
            "rx_drain",
            app.drain,
            "app: RxQueue::drain_due, a full batch",
        ),
        ("tx_handoff", app.handoff, "app: hand_off, one batch"),
        (
            "step_return",
            app.step_return,
            "the return from Node::step after its last stage",
        ),
        (
            "unattributed",
            app.unattributed,
            "Node::step without probes minus the sum of the probed stages, when positive",
        ),
    ] {
        let [plain, any] = max;
        semihosting::eprintln!(
            "stage\t{key}\t1\t{}\t{}\t{}\t{}\t{}\t{}\t-\t{why}",
            app.ticks,
            plain.0,
            plain.1,
            any.0,
            any.1,
            Branch::Common.key()
        );
    }
    let [plain, any] = app.whole_tick;
    semihosting::eprintln!(
        "stage-ticks\t{}\t{}\t{}\t{}\t{}",
        app.ticks,
        plain.0,
        plain.1,
        any.0,
        any.1
    );
    semihosting::eprintln!("stage-done");
    Ok(())
}

/// One drive, on fresh nodes.
fn drive(
    reader: &mut LineReader,
    probed: &mut Node<&'static mut Drive>,
    plain: &mut Node<&'static mut Drive>,
    laps: &mut Laps,
    app: &mut AppMax,
) -> Result<(), StageError> {
    let mut line = [0u8; LINE_MAX];
    let mut read = |reader: &mut LineReader| -> Result<Option<TimedFrame>, StageError> {
        loop {
            let Some(text) = reader.next_line(&mut line).map_err(|_| StageError::Io)? else {
                return Ok(None);
            };
            let Ok(text) = core::str::from_utf8(text) else {
                continue;
            };
            if let Ok(frame) = candump::parse_line(text) {
                return Ok(Some(frame));
            }
        }
    };
    let mut next = read(reader)?;
    let Some(first) = next else {
        return Ok(());
    };
    let mut now = first_tick_us(first.t_us);
    let mut batch: heapless::Vec<TimedFrame, RX_BATCH_LEN> = heapless::Vec::new();
    let mut spare = TxBatch::new();
    let mut plain_out = TxFrames::new();
    loop {
        // The receive path: every frame due by this tick through the acceptance filter.
        while let Some(frame) = next.filter(|f| f.t_us <= now) {
            if is_node_input(frame.frame.id) {
                let _ = RX.try_push(frame);
            }
            next = read(reader)?;
        }
        let tick = Tick {
            now_us: now,
            platform: PlatformStats::default(),
        };
        let t0 = icount::now();
        RX.drain_due(now, core::hint::black_box(&mut batch));
        let t1 = icount::now();
        // The hand-off's first half, as `tick_loop` does it: the batch the step fills in place.
        let mut slot = core::hint::black_box(TX.reserve());
        let out = match slot.as_deref_mut() {
            Some(out) => out,
            None => &mut spare,
        };
        out.tick_us = now;
        out.frames.clear();
        let t1_reserved = icount::now();
        laps.start();
        let estimate =
            core::hint::black_box(probed.step_probed(&tick, &batch, &mut out.frames, laps));
        let t2 = icount::now();
        let step_return = laps.since_last(t2);
        let t3 = icount::now();
        plain_out.clear();
        core::hint::black_box(plain.step(
            core::hint::black_box(&tick),
            core::hint::black_box(&batch),
            core::hint::black_box(&mut plain_out),
        ));
        let t4 = icount::now();
        core::hint::black_box(hand_off(slot, &spare, &COUNTERS));
        let t5 = icount::now();
        // The transmit side, untimed: empty the queue for the next tick.
        while TX.try_receive().is_some() {
            COUNTERS
                .tx_batches_in_flight
                .fetch_sub(1, Ordering::Relaxed);
        }
        let overhead = laps.overhead;
        let drain = t1.wrapping_sub(t0).saturating_sub(overhead);
        let plain_step = t4.wrapping_sub(t3).saturating_sub(overhead);
        let handoff =
            (t5.wrapping_sub(t4) + t1_reserved.wrapping_sub(t1)).saturating_sub(2 * overhead);
        let d = laps.drive;
        let controller = estimate.controller_tick();
        laps.end_tick(controller);
        keep_both(&mut app.drain, drain, d, controller);
        keep_both(&mut app.handoff, handoff, d, controller);
        keep_both(&mut app.step_return, step_return, d, controller);
        keep_both(
            &mut app.unattributed,
            plain_step.saturating_sub(laps.tick_sum + step_return),
            d,
            controller,
        );
        keep_both(
            &mut app.whole_tick,
            drain + plain_step + handoff,
            d,
            controller,
        );
        app.ticks += 1;
        if let Some(stage) = laps.over_structure {
            return Err(StageError::Structure(stage));
        }
        if next.is_none() && RX.is_empty() {
            return Ok(());
        }
        now += SAMPLE_PERIOD_US;
    }
}
