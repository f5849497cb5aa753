//! `Node`: one pure 20 ms step that takes the frames received since the last tick and the tick
//! time, and returns the frames to send. The board, QEMU and host replay run exactly this code.
//!
//! (In progress: the signature below is the contract the platforms are written against.)
use crate::can::{CanFrame, TimedFrame};
use crate::SAMPLE_PERIOD_US;

/// Most frames one tick can send (predictions, state, status).
pub const MAX_TX_FRAMES: usize = 16;

/// The frames one tick sends, in transmit order.
pub type TxFrames = heapless::Vec<CanFrame, MAX_TX_FRAMES>;

/// What only the platform can know; `None` where it cannot measure (sent as "not available").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PlatformStats {
    /// Ticks that started late (missed their 20 ms slot) since boot.
    pub overruns: u32,
    /// Frames dropped because the receive queue was full, since boot.
    pub rx_queue_drops: u32,
    /// Duration of the previous step in microseconds, where a cycle counter exists (board).
    pub last_step_us: Option<u32>,
    /// Deepest stack use seen so far, bytes, where the stack is painted.
    pub stack_high_water_bytes: Option<u32>,
    /// The last reset was caused by the watchdog.
    pub watchdog_reset: bool,
}

/// The input of one tick.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Tick {
    /// The tick's scheduled time, us on the input's time base.
    pub now_us: u64,
    /// Platform counters.
    pub platform: PlatformStats,
}

/// The first tick's time for a stream whose first frame arrived at `first_frame_us`: rounded up
/// to a whole multiple of the 20 ms period (docs/architecture.md, "Tick schedule").
pub const fn first_tick_us(first_frame_us: u64) -> u64 {
    first_frame_us.div_ceil(SAMPLE_PERIOD_US) * SAMPLE_PERIOD_US
}

/// The node (in progress).
#[derive(Debug, Default)]
pub struct Node {}

impl Node {
    /// Runs one tick: consumes `rx` (frames with `t_us <= tick.now_us`), appends frames to `tx`.
    pub fn step(&mut self, tick: &Tick, rx: &[TimedFrame], tx: &mut TxFrames) {
        let _ = (tick, rx, tx);
    }
}
