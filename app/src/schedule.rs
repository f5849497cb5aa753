//! The 20 ms tick grid: which slot runs next, and how many deadlines were missed.
//!
//! Pure bookkeeping on microsecond timestamps (no clock is read here), so that the overrun policy
//! is the same on the board and in QEMU and is unit-tested on the host; and [`ReplayClock`], how a
//! replayed drive's time base maps onto the firmware's clock (QEMU), property-tested on the host
//! against host replay (`host-tests/tests/schedule.rs`).
//!
//! Policy (docs/firmware.md, "Overruns"):
//! - Slot `k` is due at `origin_us + k * period_us`. Every slot either completes its tick before
//!   the next slot is due, or it counts as one overrun.
//! - A tick that finishes after the next slot's time counts one overrun (its work overran).
//! - A tick that *starts* one full period late or more would be stale: its slot is skipped (no
//!   catch-up burst of old ticks), and each skipped slot counts one overrun. The tick then runs
//!   for the latest slot whose time has come, so tick times stay on the grid and never drift.

use catmodel::node::first_tick_us;
use catmodel::SAMPLE_PERIOD_US;

use crate::TickConfig;

/// How a replayed input's time base (candump timestamps, us) maps onto the firmware's clock
/// (embassy time, us since boot), so that the firmware ticks at exactly the times host replay
/// does, whatever the first timestamp (0, a tick boundary, just after one, an epoch time).
///
/// Host replay ticks at `first_tick_us(first frame) + k * 20 ms` (`catmodel::node`). Here the
/// first tick runs one period after boot (so the receive task has a period to queue the first
/// frames), at embassy time [`SAMPLE_PERIOD_US`]: input time = embassy time + `input_offset_us`,
/// with the offset `first_tick - 20 ms` taken modulo 2^64 (a drive starting at 0 has a negative
/// offset; every sum below wraps back into range). A frame is released one period before the
/// tick that consumes it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ReplayClock {
    offset_us: u64,
}

impl ReplayClock {
    /// The clock for a drive whose first frame is stamped `first_frame_us`.
    pub const fn new(first_frame_us: u64) -> Self {
        Self {
            offset_us: first_tick_us(first_frame_us).wrapping_sub(SAMPLE_PERIOD_US),
        }
    }

    /// Input time minus embassy time, modulo 2^64.
    pub const fn input_offset_us(&self) -> u64 {
        self.offset_us
    }

    /// Input time of embassy time `instant_us`.
    pub const fn input_us(&self, instant_us: u64) -> u64 {
        instant_us.wrapping_add(self.offset_us)
    }

    /// Embassy time at which a frame stamped `frame_t_us` is handed to the receive queue: one
    /// period before the tick that consumes it.
    pub const fn release_instant_us(&self, frame_t_us: u64) -> u64 {
        first_tick_us(frame_t_us)
            .wrapping_sub(SAMPLE_PERIOD_US)
            .wrapping_sub(self.offset_us)
    }

    /// The tick loop's configuration for a drive whose last frame is stamped `last_frame_us`:
    /// the last tick is the one that consumes it.
    pub const fn tick_config(&self, last_frame_us: u64) -> TickConfig {
        TickConfig {
            first_tick_instant_us: SAMPLE_PERIOD_US,
            input_offset_us: self.offset_us,
            last_tick_us: Some(first_tick_us(last_frame_us)),
            watchdog_reset: false,
        }
    }
}

/// Position on the tick grid and the deadline misses seen so far.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TickGrid {
    origin_us: u64,
    period_us: u64,
    slot: u64,
    overruns: u32,
    skipped_slots: u32,
}

impl TickGrid {
    /// A grid whose slot 0 is due at `origin_us`, one slot every `period_us` (> 0).
    pub const fn new(origin_us: u64, period_us: u64) -> Self {
        Self {
            origin_us,
            period_us: if period_us == 0 { 1 } else { period_us },
            slot: 0,
            overruns: 0,
            skipped_slots: 0,
        }
    }

    /// The current slot's index (0 = the first tick).
    pub const fn slot(&self) -> u64 {
        self.slot
    }

    /// When the current slot is due, us on the grid's clock.
    pub const fn deadline_us(&self) -> u64 {
        self.origin_us
            .saturating_add(self.slot.saturating_mul(self.period_us))
    }

    /// Deadline misses so far: ticks that finished after the next slot was due, plus skipped
    /// slots. This is `PlatformStats::overruns`.
    pub const fn overruns(&self) -> u32 {
        self.overruns
    }

    /// Slots skipped because their tick would have started a full period late or more.
    pub const fn skipped_slots(&self) -> u32 {
        self.skipped_slots
    }

    /// The tick task woke at `now_us` for the current slot. If that slot is stale (the next one
    /// is already due), moves to the latest due slot and counts each skipped slot as an overrun.
    /// Returns the number of slots skipped.
    pub fn start(&mut self, now_us: u64) -> u32 {
        let next_due_us = self.deadline_us().saturating_add(self.period_us);
        if now_us < next_due_us {
            return 0;
        }
        let latest_due = now_us.saturating_sub(self.origin_us) / self.period_us;
        let skipped = latest_due.saturating_sub(self.slot);
        self.slot = latest_due;
        let skipped = u32::try_from(skipped).unwrap_or(u32::MAX);
        self.skipped_slots = self.skipped_slots.saturating_add(skipped);
        self.overruns = self.overruns.saturating_add(skipped);
        skipped
    }

    /// The tick of the current slot completed at `now_us`: counts an overrun if that is after the
    /// next slot's time, then moves to the next slot. Returns whether it overran.
    pub fn finish(&mut self, now_us: u64) -> bool {
        let next_due_us = self.deadline_us().saturating_add(self.period_us);
        let overran = now_us > next_due_us;
        if overran {
            self.overruns = self.overruns.saturating_add(1);
        }
        self.slot = self.slot.saturating_add(1);
        overran
    }
}

#[cfg(test)]
mod tests {
    use super::{ReplayClock, TickGrid};

    #[test]
    fn replay_clock_ticks_where_replay_does_for_every_kind_of_start() {
        // 0, a tick boundary, just after one, just before one, an epoch time.
        for first in [0, 40_000, 40_001, 39_999, 1_700_000_000_003_000u64] {
            let clock = ReplayClock::new(first);
            let config = clock.tick_config(first + 1_000_000);
            let first_tick = catmodel::node::first_tick_us(first);
            // The first tick (at embassy time one period) is the first tick of host replay.
            assert_eq!(clock.input_us(config.first_tick_instant_us), first_tick);
            // The first frame is released before (or as) that tick runs, never after.
            assert!(clock.release_instant_us(first) <= config.first_tick_instant_us);
            assert_eq!(
                clock.release_instant_us(first) + P,
                config.first_tick_instant_us
            );
        }
    }

    const P: u64 = 20_000;

    /// Runs slots on time (woken at the deadline plus `jitter_us`, done `work_us` later).
    fn run_on_time(grid: &mut TickGrid, n: u32, jitter_us: u64, work_us: u64) -> Vec<u64> {
        let mut times = Vec::new();
        for _ in 0..n {
            let woke = grid.deadline_us() + jitter_us;
            assert_eq!(grid.start(woke), 0);
            times.push(grid.deadline_us());
            assert!(!grid.finish(woke + work_us));
        }
        times
    }

    #[test]
    fn on_time_ticks_follow_the_grid_without_overruns() {
        let mut grid = TickGrid::new(40_000, P);
        let times = run_on_time(&mut grid, 5, 7, 300);
        assert_eq!(times, vec![40_000, 60_000, 80_000, 100_000, 120_000]);
        assert_eq!(grid.overruns(), 0);
        assert_eq!(grid.skipped_slots(), 0);
    }

    #[test]
    fn a_tick_that_finishes_after_the_next_slot_counts_one_overrun_and_skips_nothing() {
        let mut grid = TickGrid::new(0, P);
        run_on_time(&mut grid, 3, 0, 100);
        // Slot 3 (60 ms) runs 30 ms: ends at 90 ms, after slot 4 (80 ms) was due.
        assert_eq!(grid.start(60_000), 0);
        assert!(grid.finish(90_000));
        assert_eq!(grid.overruns(), 1);
        // Slot 4 starts 10 ms late: late, but not stale, so it runs with its grid time.
        assert_eq!(grid.start(90_001), 0);
        assert_eq!(grid.deadline_us(), 80_000);
        assert!(!grid.finish(90_100));
        // Back on the grid.
        let times = run_on_time(&mut grid, 2, 0, 100);
        assert_eq!(times, vec![100_000, 120_000]);
        assert_eq!(grid.overruns(), 1);
        assert_eq!(grid.skipped_slots(), 0);
    }

    #[test]
    fn a_stall_past_the_next_slot_skips_it_without_a_catch_up_burst() {
        let mut grid = TickGrid::new(0, P);
        run_on_time(&mut grid, 2, 0, 100);
        // Slot 2 (40 ms) stalls 50 ms: ends at 90 ms; slot 3 (60 ms) and slot 4 (80 ms) are due.
        assert_eq!(grid.start(40_000), 0);
        assert!(grid.finish(90_000));
        // Waking at 90 ms for slot 3: stale, so slot 3 is skipped and slot 4 (80 ms) runs.
        assert_eq!(grid.start(90_000), 1);
        assert_eq!(grid.deadline_us(), 80_000);
        assert!(!grid.finish(90_050));
        assert_eq!(grid.overruns(), 2);
        assert_eq!(grid.skipped_slots(), 1);
        let times = run_on_time(&mut grid, 3, 3, 100);
        assert_eq!(times, vec![100_000, 120_000, 140_000]);
        assert_eq!(grid.overruns(), 2);
    }

    #[test]
    fn a_long_stall_skips_every_missed_slot_and_lands_on_the_latest_due_one() {
        let mut grid = TickGrid::new(1_000_000, P);
        // Woken 1 s late for slot 0: slots 0..49 are skipped, slot 50 runs.
        assert_eq!(grid.start(2_000_000), 50);
        assert_eq!(grid.deadline_us(), 2_000_000);
        assert_eq!(grid.slot(), 50);
        assert_eq!(grid.overruns(), 50);
        // Every tick time stays a whole number of periods from the origin.
        assert_eq!((grid.deadline_us() - 1_000_000) % P, 0);
    }

    #[test]
    fn finishing_exactly_at_the_next_deadline_is_on_time() {
        let mut grid = TickGrid::new(0, P);
        assert_eq!(grid.start(0), 0);
        assert!(!grid.finish(P));
        assert_eq!(grid.start(P), 0);
        assert_eq!(grid.overruns(), 0);
    }
}
