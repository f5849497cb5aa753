//! The 20 ms tick grid: which slot runs next, and how many deadlines were missed.
//!
//! Pure bookkeeping on microsecond timestamps (no clock is read here), so that the overrun policy
//! and the meeting of the platform clock with the input's time base ([`DriveClock`]) are the
//! same on the board and in QEMU and are tested on the host.
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

/// Where a platform's clock (embassy time, us) meets the node's time base (the input's, us):
/// tick k runs at clock instant `first_tick_instant_us + k * 20 ms` with node time
/// `first_tick_us + k * 20 ms` (docs/architecture.md, "Tick schedule"). Both sides count up
/// from the first tick, so no offset is ever negative: a drive whose first frame is stamped
/// `(0000000000.000000)` has its first tick at node time 0 on every platform.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DriveClock {
    /// Clock instant of the first tick, us.
    pub first_tick_instant_us: u64,
    /// Node time of the first tick, us (a whole multiple of 20 ms).
    pub first_tick_us: u64,
}

impl DriveClock {
    /// The board: its clock is the node's time base; the first tick at `first_tick_us`.
    pub const fn identity(first_tick_us: u64) -> Self {
        Self {
            first_tick_instant_us: first_tick_us,
            first_tick_us,
        }
    }

    /// A recorded drive whose first frame is stamped `first_frame_us`, replayed on a clock that
    /// starts at 0 (QEMU): its first tick ([`first_tick_us`], as host replay's) one period
    /// after clock 0, so that the frames it consumes can be handed over one period before it.
    pub const fn replay(first_frame_us: u64) -> Self {
        Self {
            first_tick_instant_us: SAMPLE_PERIOD_US,
            first_tick_us: first_tick_us(first_frame_us),
        }
    }

    /// Node time of clock instant `instant_us` (at or after the first tick).
    pub const fn node_us(&self, instant_us: u64) -> u64 {
        self.first_tick_us
            .saturating_add(instant_us.saturating_sub(self.first_tick_instant_us))
    }

    /// Clock instant at which a frame stamped `t_us` (at or after the first frame) is handed
    /// to the node's receive queue: one period before the tick that consumes it, the first
    /// tick at or after `t_us` ([`first_tick_us`]), as in host replay.
    pub const fn release_instant_us(&self, t_us: u64) -> u64 {
        let ticks_after_first = first_tick_us(t_us).saturating_sub(self.first_tick_us);
        self.first_tick_instant_us
            .saturating_add(ticks_after_first)
            .saturating_sub(SAMPLE_PERIOD_US)
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
    use super::TickGrid;

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

    /// One tick schedule for every platform, whatever the first timestamp: for a drive whose
    /// frames are stamped `first + offsets`, host replay runs tick k at node time
    /// `first_tick_us(first) + k P` and gives each frame to the first tick at or after its
    /// stamp; QEMU's tick k (clock `P + k P`) carries the same node time, and each frame is
    /// released to its queue no later than that tick's clock instant (and one period before
    /// it), so it reaches the same tick.
    fn check_drive(first: u64, offsets: &[u64]) {
        use super::DriveClock;
        use catmodel::node::first_tick_us;
        let clock = DriveClock::replay(first);
        let host_first = first_tick_us(first);
        assert_eq!(clock.first_tick_us, host_first);
        // The first tick: at node time 0 for a drive starting at 0, on the boundary itself for
        // one starting on a boundary, the next boundary otherwise.
        assert!(host_first >= first && host_first - first < P);
        for &off in offsets {
            let t = first + off;
            let k = (first_tick_us(t) - host_first) / P;
            let instant = clock.first_tick_instant_us + k * P;
            assert_eq!(clock.node_us(instant), host_first + k * P, "tick {k}");
            let release = clock.release_instant_us(t);
            assert!(
                release <= instant,
                "frame {t} released at {release} after its tick {instant}"
            );
            assert_eq!(instant - release, P, "frame {t}");
            // The tick before would not take it: its node time is before the stamp.
            if k > 0 {
                assert!(clock.node_us(instant - P) < t);
            }
            assert!(clock.node_us(instant) >= t);
        }
    }

    #[test]
    fn first_timestamps_at_zero_on_a_boundary_just_after_and_at_epoch_times() {
        let offsets = [0, 1, 19_999, 20_000, 20_001, 39_999, 1_000_000, 300_000_000];
        for first in [
            0,
            1,
            19_999,
            20_000,
            20_001,
            // 2023-11-14 22:13:20 UTC, on a boundary, and 1 us after.
            1_700_000_000_000_000,
            1_700_000_000_000_001,
            1_700_000_000_019_999,
        ] {
            check_drive(first, &offsets);
        }
        // The drive: first frame `(0000000000.000000)`: first tick at node time 0.
        let clock = super::DriveClock::replay(0);
        assert_eq!(clock.node_us(clock.first_tick_instant_us), 0);
        assert_eq!(clock.release_instant_us(0), 0);
    }

    #[test]
    fn the_board_clock_is_the_node_time_base() {
        let clock = super::DriveClock::identity(40_000);
        for instant in [40_000, 60_000, 1_000_000] {
            assert_eq!(clock.node_us(instant), instant);
        }
    }

    use proptest::prelude::*;

    proptest! {
        #[test]
        fn any_first_timestamp_gives_one_schedule(
            // Up to 3e16 us (year 2920): beyond any recorder; the node saturates at u64::MAX / 2.
            first in prop_oneof![
                0u64..100_000,
                (0u64..1_500_000_000).prop_map(|k| k * P),
                (0u64..1_500_000_000).prop_map(|k| k * P + 1),
                0u64..30_000_000_000_000_000,
            ],
            offsets in prop::collection::vec(0u64..3_600_000_000, 1..40),
        ) {
            check_drive(first, &offsets);
        }
    }
}
