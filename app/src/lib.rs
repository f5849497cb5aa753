//! The app layer: the three async loops the board and QEMU share (bus receive, 20 ms tick, bus
//! transmit), generic over a small bus trait and the embassy-time clock.
//!
//! ```text
//! bus --BusReceiver--> receive_loop --RxQueue--> tick_loop --TxQueue--> transmit_loop --BusTransmitter--> bus
//!                      (drops counted)           (Node::step every 20 ms)  (drops counted)
//! ```
//! The receive queue carries single frames; the transmit queue carries each tick's frames as
//! one [`TxBatch`], so the tick pays one queue operation for its ~14 frames, not 14.
//! What differs between platforms stays behind the traits: how frames arrive and leave
//! ([`BusReceiver`], [`BusTransmitter`]) and what a tick is measured with and what happens after
//! it ([`TickPlatform`]: DWT cycles and the watchdog on the board, TIM2 instruction counts and
//! result records in QEMU). Everything else, including the overrun policy ([`schedule`]), is
//! the same code on both.
//!
//! Time: embassy-time runs at 1 MHz (`tick-hz-1_000_000`), so its ticks are microseconds. The
//! node's time base (the input's, [`catmodel::node::Tick::now_us`]) is the embassy clock plus a
//! fixed offset ([`TickConfig::input_offset_us`]): 0 on the board, `first_tick_us - 20 000` in
//! QEMU (docs/architecture.md, "Tick schedule").
//!
//! Budgets ([`budget`]): one tick (drain + step + handoff) must stay under 25 000 instructions
//! (0.74 % of the 20 ms period at 168 MHz, one instruction per cycle) while no controller plans,
//! and under 600 000 when one does; `cargo qemu` checks every tick and the worst-case bound.
#![cfg_attr(not(test), no_std)]
#![cfg_attr(
    not(test),
    deny(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic,
        clippy::indexing_slicing
    )
)]
#![warn(missing_docs)]

pub mod budget;
pub mod health;
pub mod record;
pub mod schedule;

use core::future::{poll_fn, Future};
use core::sync::atomic::{AtomicU32, Ordering};
use core::task::Poll;

use core::cell::{RefCell, UnsafeCell};

use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::waitqueue::WakerRegistration;
use embassy_time::{Instant, Timer};
use heapless::Deque;

use catmodel::can::spec::is_node_input;
use catmodel::can::TimedFrame;
use core::borrow::BorrowMut;

use catmodel::node::drive::Drive;
use catmodel::node::{Node, PlatformStats, Tick, TxFrames};
use catmodel::SAMPLE_PERIOD_US;

pub use schedule::{ReplayClock, TickGrid};

/// Frames the receive queue holds between two ticks: the core's
/// [`catmodel::node::RX_QUEUE_LEN`] (host `sil` keeps the same queue); a full queue drops the
/// newest frame and counts it ([`LinkCounters::rx_queue_drops`]).
pub const RX_QUEUE_LEN: usize = catmodel::node::RX_QUEUE_LEN;
/// Frames one tick hands to the node at most: the node's own cap
/// ([`catmodel::node::MAX_RX_FRAMES_PER_TICK`]), so that its worst case holds. Any further due
/// frames stay in the queue, in order, for the next tick (they are not dropped).
pub const RX_BATCH_LEN: usize = catmodel::node::MAX_RX_FRAMES_PER_TICK;
/// Tick batches waiting for the bus: two ticks' worth (each up to
/// [`catmodel::node::MAX_TX_FRAMES`] frames).
pub const TX_QUEUE_LEN: usize = 2;

/// Received frames, stamped with their receive time on the input's time base, oldest first.
///
/// The receive loop pushes and the tick drains; neither waits on the queue (the tick runs on
/// its timer, the receive loop drops when full), so it is a plain ring under a critical
/// section rather than an async channel: the tick takes all its due frames in one critical
/// section, peeking at each frame's time before taking it (about 40 instructions a frame,
/// against about 400 through `embassy_sync::Channel::try_receive`).
pub struct RxQueue {
    frames: Mutex<CriticalSectionRawMutex, RefCell<Deque<TimedFrame, RX_QUEUE_LEN>>>,
}

impl Default for RxQueue {
    fn default() -> Self {
        Self::new()
    }
}

impl RxQueue {
    /// Empty.
    pub const fn new() -> Self {
        Self {
            frames: Mutex::new(RefCell::new(Deque::new())),
        }
    }

    /// Appends `frame`; gives it back when the queue is full.
    pub fn try_push(&self, frame: TimedFrame) -> Result<(), TimedFrame> {
        self.frames
            .lock(|q| with(q, |q| q.push_back(frame)).unwrap_or(Err(frame)))
    }

    /// Frames waiting.
    pub fn len(&self) -> usize {
        self.frames.lock(|q| with(q, |q| q.len()).unwrap_or(0))
    }

    /// Whether no frame is waiting.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Moves the frames due at `tick_us` (receive time <= tick time), oldest first, into
    /// `batch` (cleared first) until it is full; later frames, and due frames beyond the
    /// batch, stay for the next tick.
    pub fn drain_due(&self, tick_us: u64, batch: &mut heapless::Vec<TimedFrame, RX_BATCH_LEN>) {
        batch.clear();
        self.frames.lock(|q| {
            with(q, |q| {
                while !batch.is_full() && q.front().is_some_and(|f| f.t_us <= tick_us) {
                    if let Some(frame) = q.pop_front() {
                        // Note: cannot fail, the batch is not full (checked by the loop).
                        let _ = batch.push(frame);
                    }
                }
            })
        });
    }
}
/// `f` on the contents of `cell`, borrowed inside a lock's critical section, which holds no
/// other borrow of it (so `None` is never returned there): `RefCell::borrow_mut` would panic
/// on a second borrow, and that panic's code and message cost the board 150 B of flash.
fn with<T, R>(cell: &RefCell<T>, f: impl FnOnce(&mut T) -> R) -> Option<R> {
    cell.try_borrow_mut().ok().map(|mut v| f(&mut v))
}

/// Frames to send, one batch per tick: a ring of [`TX_QUEUE_LEN`] batches that the tick fills
/// in place ([`TxQueue::reserve`]: `Node::step` writes its frames straight into the batch the
/// transmit loop will read, [`TxSlot::commit`] queues it) and the transmit loop empties
/// ([`TxQueue::receive`]). A channel that takes its items by value moved each ~320-byte batch
/// twice on the way in (into the hand-off, then into the channel: two library `memcpy`s, about
/// 560 of the hand-off's 665 instructions in QEMU), inside the tick's measured work.
pub struct TxQueue {
    slots: [UnsafeCell<TxBatch>; TX_QUEUE_LEN],
    ring: Mutex<CriticalSectionRawMutex, RefCell<TxRing>>,
}

/// Which slots are queued, and who waits.
struct TxRing {
    /// Oldest queued slot.
    front: usize,
    /// Slots queued, from `front` on.
    len: usize,
    /// The slot after the queued ones is being filled ([`TxSlot`]).
    reserved: bool,
    /// The transmit loop, waiting for a batch.
    receiver: WakerRegistration,
}

// SAFETY: a slot is reached only through the ring's state, under its critical section: the
// transmit side reads the queued slots (`front`, `len`), the tick side writes the one slot after
// them, and only while `reserved` says no other `TxSlot` holds it. A queued slot is never the
// reserved one (the consumer advancing `front` keeps `front + len` where it was), and a slot is
// queued only when its `TxSlot` has given it up. `TxBatch` is plain data (`Send`).
unsafe impl Sync for TxQueue {}

impl Default for TxQueue {
    fn default() -> Self {
        Self::new()
    }
}

impl TxQueue {
    /// Empty.
    pub const fn new() -> Self {
        Self {
            slots: [const { UnsafeCell::new(TxBatch::new()) }; TX_QUEUE_LEN],
            ring: Mutex::new(RefCell::new(TxRing {
                front: 0,
                len: 0,
                reserved: false,
                receiver: WakerRegistration::new(),
            })),
        }
    }

    /// The next free batch to fill in place, or `None` when every batch waits for the bus (or
    /// one is being filled already). Dropping the slot without [`TxSlot::commit`] gives it
    /// back unsent.
    pub fn reserve(&self) -> Option<TxSlot<'_>> {
        let index = self.ring.lock(|ring| {
            with(ring, |ring| {
                if ring.reserved || ring.len >= TX_QUEUE_LEN {
                    return None;
                }
                ring.reserved = true;
                Some((ring.front + ring.len) % TX_QUEUE_LEN)
            })
            .flatten()
        })?;
        match self.slots.get(index) {
            // SAFETY: `reserved` was clear and is now set: this slot (the one after the queued
            // ones) is neither queued nor held by another `TxSlot` until this one goes (see
            // `impl Sync for TxQueue`).
            Some(cell) => Some(TxSlot {
                queue: self,
                batch: unsafe { &mut *cell.get() },
                committed: false,
            }),
            // Note: the index is taken modulo the slots' count; never reached.
            None => {
                self.release();
                None
            }
        }
    }

    fn release(&self) {
        self.ring
            .lock(|ring| with(ring, |ring| ring.reserved = false));
    }

    /// The oldest queued batch, copied out and its slot freed; `None` when none is queued.
    pub fn try_receive(&self) -> Option<TxBatch> {
        self.ring
            .lock(|ring| with(ring, |ring| self.pop(ring)).flatten())
    }

    /// Waits for the oldest queued batch ([`TxQueue::try_receive`]).
    pub async fn receive(&self) -> TxBatch {
        poll_fn(|cx| {
            self.ring.lock(|ring| {
                with(ring, |ring| match self.pop(ring) {
                    Some(batch) => Poll::Ready(batch),
                    None => {
                        ring.receiver.register(cx.waker());
                        Poll::Pending
                    }
                })
                .unwrap_or(Poll::Pending)
            })
        })
        .await
    }

    fn pop(&self, ring: &mut TxRing) -> Option<TxBatch> {
        if ring.len == 0 {
            return None;
        }
        let cell = self.slots.get(ring.front)?;
        // SAFETY: the front slot is queued: its `TxSlot` has committed it, and the tick side
        // writes only the slot after the queued ones.
        let batch = unsafe { (*cell.get()).clone() };
        ring.front = (ring.front + 1) % TX_QUEUE_LEN;
        ring.len -= 1;
        Some(batch)
    }

    /// Whether no batch is queued.
    pub fn is_empty(&self) -> bool {
        self.ring
            .lock(|ring| with(ring, |ring| ring.len == 0).unwrap_or(true))
    }
}

/// A batch of the transmit queue being filled in place ([`TxQueue::reserve`]).
pub struct TxSlot<'a> {
    queue: &'a TxQueue,
    batch: &'a mut TxBatch,
    committed: bool,
}

impl TxSlot<'_> {
    /// Queues the batch for the transmit loop.
    pub fn commit(mut self) {
        self.committed = true;
        self.queue.ring.lock(|ring| {
            with(ring, |ring| {
                ring.len += 1;
                ring.reserved = false;
                ring.receiver.wake();
            })
        });
    }
}

impl Drop for TxSlot<'_> {
    fn drop(&mut self) {
        if !self.committed {
            self.queue.release();
        }
    }
}

impl core::ops::Deref for TxSlot<'_> {
    type Target = TxBatch;
    fn deref(&self) -> &TxBatch {
        self.batch
    }
}

impl core::ops::DerefMut for TxSlot<'_> {
    fn deref_mut(&mut self) -> &mut TxBatch {
        self.batch
    }
}

/// The frames one tick produced, in transmit order, with the tick's time (each frame goes out
/// stamped with it).
#[derive(Clone, Debug, Default)]
pub struct TxBatch {
    /// The tick's time on the input's time base, us.
    pub tick_us: u64,
    /// The frames.
    pub frames: TxFrames,
}

impl TxBatch {
    /// No frames, at time 0.
    pub const fn new() -> Self {
        Self {
            tick_us: 0,
            frames: TxFrames::new(),
        }
    }
}

/// Counters of the bus paths, shared between the tasks (all since boot).
#[derive(Debug, Default)]
pub struct LinkCounters {
    /// Frames dropped because the receive queue was full.
    pub rx_queue_drops: AtomicU32,
    /// Frames the acceptance filter refused (not a node input: [`catmodel::can::spec::is_node_input`]).
    /// Zero on the board, whose hardware filters never pass them to the CPU.
    pub rx_filtered: AtomicU32,
    /// Receive errors reported by the bus (error frames, hardware FIFO overruns).
    pub rx_bus_errors: AtomicU32,
    /// Frames received that the node cannot represent (remote frames), dropped.
    pub rx_unsupported: AtomicU32,
    /// Frames dropped because the transmit queue was full.
    pub tx_queue_drops: AtomicU32,
    /// Batches handed to the transmit queue whose frames are not all sent yet.
    pub tx_batches_in_flight: AtomicU32,
    /// Frames the bus failed to send.
    pub tx_bus_errors: AtomicU32,
}

impl LinkCounters {
    /// All zero.
    pub const fn new() -> Self {
        Self {
            rx_queue_drops: AtomicU32::new(0),
            rx_filtered: AtomicU32::new(0),
            rx_bus_errors: AtomicU32::new(0),
            rx_unsupported: AtomicU32::new(0),
            tx_queue_drops: AtomicU32::new(0),
            tx_batches_in_flight: AtomicU32::new(0),
            tx_bus_errors: AtomicU32::new(0),
        }
    }
}

fn bump(counter: &AtomicU32) {
    // Note: a plain load + store would do (one writer per counter), but fetch_add is as cheap on
    // a Cortex-M4 (LDREX/STREX) and stays right if a second writer ever appears.
    counter.fetch_add(1, Ordering::Relaxed);
}

/// Why a bus receive returned no frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RxError {
    /// A bus error (error frame, FIFO overrun); counted, the loop goes on.
    Bus,
    /// A frame the node cannot use (remote frame); counted, the loop goes on.
    Unsupported,
    /// The input has ended (replay only); the receive loop returns.
    EndOfInput,
}

/// Where frames come from.
#[allow(async_fn_in_trait)]
pub trait BusReceiver {
    /// Waits for the next frame; its `t_us` is the receive time on the input's time base.
    async fn receive(&mut self) -> Result<TimedFrame, RxError>;
}

/// Where frames go.
#[allow(async_fn_in_trait)]
pub trait BusTransmitter {
    /// Sends one frame (`t_us` is the time of the tick that produced it). `Err` is counted.
    async fn transmit(&mut self, frame: &TimedFrame) -> Result<(), ()>;
    /// Called whenever the transmit queue has run empty (QEMU flushes its output file here).
    fn idle(&mut self) {}
}

/// The receive path: moves the node's input frames from the bus to the tick's queue without
/// ever blocking the bus: frames that are not node inputs are refused by the acceptance filter
/// (the board's hardware has refused them already) and counted; when the queue is full the
/// frame is dropped and counted. Returns at end of input.
pub async fn receive_loop<B: BusReceiver>(bus: &mut B, queue: &RxQueue, counters: &LinkCounters) {
    loop {
        match bus.receive().await {
            Ok(frame) if !is_node_input(frame.frame.id) => bump(&counters.rx_filtered),
            Ok(frame) => {
                if queue.try_push(frame).is_err() {
                    bump(&counters.rx_queue_drops);
                }
            }
            Err(RxError::Bus) => bump(&counters.rx_bus_errors),
            Err(RxError::Unsupported) => bump(&counters.rx_unsupported),
            Err(RxError::EndOfInput) => return,
        }
    }
}

/// The transmit path: sends each tick's frames in order.
pub async fn transmit_loop<B: BusTransmitter>(
    bus: &mut B,
    queue: &TxQueue,
    counters: &LinkCounters,
) -> ! {
    loop {
        let batch = queue.receive().await;
        for frame in &batch.frames {
            let timed = TimedFrame {
                t_us: batch.tick_us,
                frame: *frame,
            };
            if bus.transmit(&timed).await.is_err() {
                bump(&counters.tx_bus_errors);
            }
        }
        if queue.is_empty() {
            bus.idle();
        }
        counters
            .tx_batches_in_flight
            .fetch_sub(1, Ordering::Relaxed);
    }
}

/// The measurements of one completed tick.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TickReport {
    /// Slot index on the grid (0 = first tick); a gap means skipped slots.
    pub slot: u64,
    /// The tick's time on the input's time base, us.
    pub tick_us: u64,
    /// What the node was told about the platform in this tick.
    pub platform: PlatformStats,
    /// Frames handed to the node.
    pub rx_frames: u16,
    /// Frames the node returned.
    pub tx_frames: u16,
    /// Counter ticks ([`TickPlatform::counter`]) spent moving due frames out of the queue.
    pub drain_counts: u32,
    /// Counter ticks spent in `Node::step`.
    pub step_counts: u32,
    /// Counter ticks for the whole tick: drain + step + handoff to the transmit queue.
    pub tick_counts: u32,
    /// A controller planned in this tick, or a planner path was completed in it
    /// (`TickEstimate::controller_tick`; its budget differs: `budget`).
    pub controller: bool,
}

/// What the tick loop needs from its platform.
pub trait TickPlatform {
    /// A free-running 32-bit counter to measure the tick with (board: DWT cycles; QEMU: TIM2
    /// counting instructions). Differences are taken with wrapping arithmetic.
    fn counter(&self) -> u32;
    /// `counts` of [`Self::counter`] as microseconds for `PlatformStats::last_step_us`, or `None`
    /// where the counter does not measure board time (QEMU, host replay: "not available").
    fn counts_to_us(&self, counts: u32) -> Option<u32>;
    /// Called after every completed tick (board: feeds the watchdog; QEMU: records the counts).
    fn tick_completed(&mut self, report: &TickReport);
    /// Deepest stack use so far, bytes, where the stack is painted; called once per tick after
    /// [`Self::tick_completed`] (outside the measured tick), reported in the next tick's status.
    fn stack_high_water_bytes(&mut self) -> Option<u32> {
        None
    }
}

/// Fixed parameters of the tick loop.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TickConfig {
    /// Embassy time (us) of the first tick.
    pub first_tick_instant_us: u64,
    /// Added to embassy time to get the input's time base, us, modulo 2^64 (a replayed drive
    /// that starts at time 0 has a negative offset: [`ReplayClock`]).
    pub input_offset_us: u64,
    /// Stop after the tick at or past this time (input time base, us) once the receive queue
    /// is empty; `None` runs forever.
    pub last_tick_us: Option<u64>,
    /// The last reset was caused by the watchdog (board; read once at boot).
    pub watchdog_reset: bool,
}

/// What the tick loop saw, returned when it stops (QEMU).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TickSummary {
    /// Ticks that ran.
    pub ticks: u64,
    /// Deadline misses ([`TickGrid::overruns`]).
    pub overruns: u32,
    /// Slots skipped.
    pub skipped_slots: u32,
}

/// The 20 ms tick: at each slot of the grid, hands the due frames to `Node::step` and the frames
/// it returns to the transmit queue, then reports the tick to the platform. Overruns follow
/// [`schedule`]: a late tick is counted, a stale slot is skipped (no catch-up burst), and tick
/// times stay on the 20 ms grid. Returns only when [`TickConfig::last_tick_us`] is reached and
/// no received frame waits any more.
pub async fn tick_loop<P: TickPlatform, D: BorrowMut<Drive>>(
    node: &mut Node<D>,
    rx: &RxQueue,
    tx: &TxQueue,
    counters: &LinkCounters,
    platform: &mut P,
    config: &TickConfig,
) -> TickSummary {
    let mut grid = TickGrid::new(config.first_tick_instant_us, SAMPLE_PERIOD_US);
    let mut batch: heapless::Vec<TimedFrame, RX_BATCH_LEN> = heapless::Vec::new();
    let mut spare = TxBatch::new();
    let mut last_step_us = None;
    let mut stack_high_water_bytes = None;
    let mut ticks = 0u64;
    loop {
        Timer::at(Instant::from_micros(grid.deadline_us())).await;
        grid.start(Instant::now().as_micros());
        let tick_us = grid.deadline_us().wrapping_add(config.input_offset_us);

        let tick = Tick {
            now_us: tick_us,
            platform: PlatformStats {
                overruns: grid.overruns(),
                rx_queue_drops: counters.rx_queue_drops.load(Ordering::Relaxed),
                last_step_us,
                stack_high_water_bytes,
                watchdog_reset: config.watchdog_reset,
            },
        };
        // The measured tick: the drain, the step and the hand-off (the reservation of the
        // batch the step writes into and its commit), each measured alone in `cargo xtask
        // bench-target` for the worst-case bound.
        let c0 = platform.counter();
        rx.drain_due(tick_us, &mut batch);
        let c1 = platform.counter();
        let mut slot = tx.reserve();
        // A full queue: the step writes into the spare batch, whose frames are dropped. The
        // node appends its frames: a slot is reused, so it is emptied first.
        let out = match slot.as_deref_mut() {
            Some(out) => out,
            None => &mut spare,
        };
        out.tick_us = tick_us;
        out.frames.clear();
        let c2 = platform.counter();
        let estimate = node.step(&tick, &batch, &mut out.frames);
        let c3 = platform.counter();
        let tx_frames = hand_off(slot, &spare, counters);
        let c4 = platform.counter();

        let step_counts = c3.wrapping_sub(c2);
        last_step_us = platform.counts_to_us(step_counts);
        ticks = ticks.saturating_add(1);
        platform.tick_completed(&TickReport {
            slot: grid.slot(),
            tick_us,
            platform: tick.platform,
            rx_frames: u16::try_from(batch.len()).unwrap_or(u16::MAX),
            tx_frames: u16::try_from(tx_frames).unwrap_or(u16::MAX),
            drain_counts: c1.wrapping_sub(c0),
            step_counts,
            tick_counts: c4.wrapping_sub(c0),
            controller: estimate.controller_tick(),
        });
        stack_high_water_bytes = platform.stack_high_water_bytes();
        grid.finish(Instant::now().as_micros());
        // The last tick is the one at or after the last frame, once no frame waits any more
        // (frames beyond a tick's batch are taken by the ticks after it).
        if config.last_tick_us.is_some_and(|last| tick_us >= last) && rx.is_empty() {
            return TickSummary {
                ticks,
                overruns: grid.overruns(),
                skipped_slots: grid.skipped_slots(),
            };
        }
    }
}

/// Hands a tick's frames to the transmit loop: commits the slot the step filled, or, when the
/// queue was full and the step filled `spare` instead, drops its frames and counts them
/// ([`LinkCounters::tx_queue_drops`]). Returns how many frames the tick produced.
pub fn hand_off(slot: Option<TxSlot<'_>>, spare: &TxBatch, counters: &LinkCounters) -> usize {
    match slot {
        Some(slot) => {
            let frames = slot.frames.len();
            counters
                .tx_batches_in_flight
                .fetch_add(1, Ordering::Relaxed);
            slot.commit();
            frames
        }
        None => {
            let frames = spare.frames.len();
            counters
                .tx_queue_drops
                .fetch_add(u32::try_from(frames).unwrap_or(u32::MAX), Ordering::Relaxed);
            frames
        }
    }
}

/// Lets every other ready task run once before continuing.
pub fn yield_now() -> impl Future<Output = ()> {
    let mut yielded = false;
    poll_fn(move |cx| {
        if yielded {
            Poll::Ready(())
        } else {
            yielded = true;
            cx.waker().wake_by_ref();
            Poll::Pending
        }
    })
}

/// Waits until the transmit task has sent (and, by [`BusTransmitter::idle`], flushed) every
/// queued batch.
pub async fn wait_tx_drained(counters: &LinkCounters) {
    while counters.tx_batches_in_flight.load(Ordering::Relaxed) > 0 {
        yield_now().await;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use catmodel::can::{CanFrame, CanId};

    /// Fills a reserved slot with `n` frames at `t_us` and commits it.
    fn send(tx: &TxQueue, t_us: u64, n: u8) {
        let mut slot = tx.reserve().unwrap();
        slot.tick_us = t_us;
        slot.frames.clear();
        for tag in 0..n {
            slot.frames.push(frame(t_us, tag).frame).unwrap();
        }
        slot.commit();
    }

    #[test]
    fn the_transmit_queue_hands_batches_over_in_order_and_refuses_when_full() {
        let tx = TxQueue::new();
        assert!(tx.is_empty() && tx.try_receive().is_none());
        // Around the ring several times: each batch out as it went in.
        for round in 0..5u64 {
            send(&tx, 2 * round, 3);
            send(&tx, 2 * round + 1, 5);
            // Both slots queued: nothing left to fill.
            assert!(tx.reserve().is_none(), "round {round}");
            let a = tx.try_receive().unwrap();
            assert_eq!((a.tick_us, a.frames.len()), (2 * round, 3));
            // A slot freed is the next to fill while the other still waits.
            send(&tx, 99, 1);
            let b = tx.try_receive().unwrap();
            assert_eq!((b.tick_us, b.frames.len()), (2 * round + 1, 5));
            assert_eq!(tx.try_receive().unwrap().tick_us, 99);
            assert!(tx.is_empty());
        }
    }

    #[test]
    fn a_slot_is_held_by_one_filler_and_given_back_unsent_when_dropped() {
        let tx = TxQueue::new();
        let mut held = tx.reserve().unwrap();
        held.tick_us = 7;
        // Held: no second slot to fill, and nothing queued for the transmit loop.
        assert!(tx.reserve().is_none());
        assert!(tx.try_receive().is_none());
        drop(held);
        assert!(tx.is_empty());
        // Given back: the same slot is filled again and goes out.
        send(&tx, 8, 2);
        let out = tx.try_receive().unwrap();
        assert_eq!((out.tick_us, out.frames.len()), (8, 2));
    }

    fn frame(t_us: u64, tag: u8) -> TimedFrame {
        TimedFrame {
            t_us,
            frame: CanFrame::new(CanId::Standard(0x100), &[tag]).unwrap_or(CanFrame::EMPTY),
        }
    }

    #[test]
    fn a_tick_takes_its_due_frames_in_order_up_to_the_batch() {
        let q = RxQueue::new();
        // 20 frames due at the tick, then 3 later ones.
        for i in 0..20u8 {
            assert!(q.try_push(frame(1_000 + u64::from(i), i)).is_ok());
        }
        for i in 20..23u8 {
            assert!(q.try_push(frame(30_000, i)).is_ok());
        }
        let mut batch = heapless::Vec::new();
        q.drain_due(20_000, &mut batch);
        let tags: heapless::Vec<u8, RX_BATCH_LEN> = batch.iter().map(|f| f.frame.data[0]).collect();
        assert_eq!(batch.len(), RX_BATCH_LEN);
        assert!(tags.iter().enumerate().all(|(i, t)| usize::from(*t) == i));
        // The rest of the due frames go first at the next tick; the later ones wait.
        q.drain_due(20_000, &mut batch);
        assert_eq!(batch.len(), 20 - RX_BATCH_LEN);
        assert_eq!(
            batch.first().map(|f| f.frame.data[0]),
            Some(RX_BATCH_LEN as u8)
        );
        assert_eq!(q.len(), 3);
        q.drain_due(40_000, &mut batch);
        assert_eq!(batch.len(), 3);
        assert!(q.is_empty());
        // A full queue gives the frame back.
        for i in 0..RX_QUEUE_LEN {
            assert!(q.try_push(frame(i as u64, 0)).is_ok());
        }
        assert_eq!(q.try_push(frame(0, 9)), Err(frame(0, 9)));
    }
}
