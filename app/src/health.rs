//! Platform health logic that is the same on the board and in QEMU, kept here (pure, no
//! hardware access) so that it is tested on the host: the stack high-water scan and the
//! independent watchdog's feeding rule and timing.
//!
//! The platforms (`platform::board`, `platform::qemu`) only supply the memory reads and the
//! watchdog register write.

/// Value cortex-m-rt's `paint-stack` writes over the whole stack before `main`
/// (`cortex_m_rt::STACK_PAINT_VALUE`).
pub const STACK_PAINT: u32 = 0xCCCC_CCCC;

/// Incremental stack high-water scan over a painted stack of `len_words` words, word 0 at the
/// lowest address (the stack grows down towards it from word `len_words`).
///
/// The deepest use is the lowest word that is no longer paint. A full scan of a 16 KiB stack is
/// 4 096 reads; this spreads it over the ticks, `budget_words` reads per call: each pass walks up
/// from word 0 to the deepest word found so far and restarts; a scrubbed word on the way is a
/// new low. Cost per call is bounded; a new low is seen within one pass (painted words / budget
/// calls). Words that a deeper call frame happened to leave equal to the paint value are not
/// seen; the first scrubbed word below them is, which is what every paint-based meter reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StackScan {
    len_words: usize,
    /// Next word to read in the current pass.
    cursor: usize,
    /// Lowest word seen scrubbed (`len_words`: none yet).
    deepest: usize,
}

impl StackScan {
    /// A scan of a stack of `len_words` words that has found nothing yet.
    pub const fn new(len_words: usize) -> Self {
        Self {
            len_words,
            cursor: 0,
            deepest: len_words,
        }
    }

    /// Reads up to `budget_words` words with `read(index)` and returns the high-water mark in
    /// bytes (`None` until a scrubbed word is found).
    pub fn step(&mut self, budget_words: usize, mut read: impl FnMut(usize) -> u32) -> Option<u32> {
        for _ in 0..budget_words {
            if self.cursor >= self.deepest {
                // Everything below the deepest mark is still paint: start a new pass.
                self.cursor = 0;
                if self.deepest == 0 {
                    break;
                }
            }
            if read(self.cursor) != STACK_PAINT {
                self.deepest = self.cursor;
                self.cursor = 0;
            } else {
                self.cursor += 1;
            }
        }
        self.high_water_bytes()
    }

    /// Runs passes until one finds nothing new: the exact mark at this moment (for reports at
    /// the end of a run; costs up to one read per painted word).
    pub fn finish(&mut self, mut read: impl FnMut(usize) -> u32) -> Option<u32> {
        self.cursor = 0;
        while self.cursor < self.deepest {
            if read(self.cursor) != STACK_PAINT {
                self.deepest = self.cursor;
                break;
            }
            self.cursor += 1;
        }
        self.cursor = 0;
        self.high_water_bytes()
    }

    /// Deepest use found so far, bytes; `None` while no scrubbed word has been found.
    pub fn high_water_bytes(&self) -> Option<u32> {
        let words = self.len_words.saturating_sub(self.deepest);
        (words > 0).then(|| u32::try_from(words.saturating_mul(4)).unwrap_or(u32::MAX))
    }
}

/// The independent watchdog's timing: the STM32F4 IWDG counts the LSI oscillator, nominally
/// 32 kHz but 17..47 kHz across parts and temperature (STM32F405 datasheet, LSI
/// characteristics), so a timeout configured for 32 kHz is really between
/// `nominal * 32/47` and `nominal * 32/17`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WatchdogTiming {
    /// Timeout the IWDG is configured with (at the nominal 32 kHz), us.
    pub nominal_timeout_us: u32,
}

/// LSI frequency range of the STM32F405, Hz: minimum, nominal, maximum.
pub const LSI_HZ: [u32; 3] = [17_000, 32_000, 47_000];

impl WatchdogTiming {
    /// Shortest real timeout (fastest LSI), us.
    pub const fn shortest_us(&self) -> u64 {
        self.nominal_timeout_us as u64 * LSI_HZ[1] as u64 / LSI_HZ[2] as u64
    }

    /// Longest real timeout (slowest LSI), us.
    pub const fn longest_us(&self) -> u64 {
        (self.nominal_timeout_us as u64 * LSI_HZ[1] as u64).div_ceil(LSI_HZ[0] as u64)
    }

    /// The longest single-tick stall that can never reset the node: the watchdog is fed after
    /// the tick before the stalled one and again when the stalled one completes, so the gap is
    /// one period plus the stall's excess, and it must stay under the shortest timeout.
    pub const fn longest_safe_stall_us(&self, period_us: u64) -> u64 {
        self.shortest_us().saturating_sub(period_us)
    }
}

/// The feeding rule: the watchdog is fed only after a completed tick, at most once per grid
/// slot. Nothing else feeds it (no timer task, no interrupt), so a tick loop that hangs, dies or
/// is starved by a runaway task or interrupt storm resets the node within
/// [`WatchdogTiming::longest_us`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WatchdogFeeder {
    last_fed_slot: Option<u64>,
}

impl WatchdogFeeder {
    /// A feeder that has not fed yet.
    pub const fn new() -> Self {
        Self {
            last_fed_slot: None,
        }
    }

    /// The tick of grid slot `slot` completed: whether to feed the watchdog now. Slots only
    /// move forward; a repeated or older slot (the loop is not making progress) is not fed.
    pub fn tick_completed(&mut self, slot: u64) -> bool {
        let progress = self.last_fed_slot.is_none_or(|last| slot > last);
        if progress {
            self.last_fed_slot = Some(slot);
        }
        progress
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A painted stack of `n` words, used down to word `low` (words `low..n` scrubbed, with a
    /// few paint-valued words left inside the used part, as real frames leave them).
    fn stack(n: usize, low: usize) -> Vec<u32> {
        (0..n)
            .map(|i| {
                if i < low || (i > low && i % 7 == 0) {
                    STACK_PAINT
                } else {
                    i as u32
                }
            })
            .collect()
    }

    #[test]
    fn the_incremental_scan_finds_the_mark_within_one_pass_and_follows_deeper_use() {
        let mut mem = stack(3072, 2000);
        let mut scan = StackScan::new(3072);
        let mut calls = 0;
        while scan.high_water_bytes().is_none() {
            scan.step(64, |i| mem[i]);
            calls += 1;
        }
        assert_eq!(scan.high_water_bytes(), Some((3072 - 2000) * 4));
        assert_eq!(calls, 2000 / 64 + 1);
        // Deeper use later (a bigger call chain): found within one more pass.
        for w in &mut mem[1500..1510] {
            *w = 1;
        }
        for _ in 0..(2000 / 64 + 2) {
            scan.step(64, |i| mem[i]);
        }
        assert_eq!(scan.high_water_bytes(), Some((3072 - 1500) * 4));
        // The mark never goes back up, and `finish` agrees with the passes.
        assert_eq!(scan.finish(|i| mem[i]), Some((3072 - 1500) * 4));
    }

    #[test]
    fn the_scan_reads_no_more_than_its_budget_and_only_inside_the_stack() {
        let mem = stack(512, 100);
        let mut scan = StackScan::new(512);
        for _ in 0..50 {
            let mut reads = 0;
            scan.step(16, |i| {
                assert!(i < 512);
                reads += 1;
                mem[i]
            });
            assert!(reads <= 16);
        }
        assert_eq!(scan.high_water_bytes(), Some((512 - 100) * 4));
    }

    #[test]
    fn an_overflowed_stack_reports_all_of_it_and_an_unused_one_nothing() {
        let full = vec![0u32; 64];
        let mut scan = StackScan::new(64);
        assert_eq!(scan.step(8, |i| full[i]), Some(256));
        assert_eq!(scan.step(8, |i| full[i]), Some(256));
        let clean = vec![STACK_PAINT; 64];
        let mut scan = StackScan::new(64);
        assert_eq!(scan.step(1000, |i| clean[i]), None);
        assert_eq!(scan.finish(|i| clean[i]), None);
    }

    /// The IWDG as a countdown: reset when the time since the last feed exceeds `timeout_us`.
    /// Ticks are due every 20 ms; tick `k` starts at its slot time and takes `work_us(k)`
    /// (u64::MAX: it never completes). Slots whose time has passed are skipped, as
    /// `app::schedule` does. Returns the time of the reset, if any, within `horizon_us`.
    fn run_until_reset(
        timeout_us: u64,
        horizon_us: u64,
        work_us: impl Fn(u64) -> u64,
    ) -> Option<u64> {
        const P: u64 = 20_000;
        let mut feeder = WatchdogFeeder::new();
        let mut last_feed_us = 0u64;
        let mut now = 0u64;
        let mut slot = 0u64;
        while now < horizon_us {
            now = now.max(slot * P);
            let work = work_us(slot);
            let done = now.saturating_add(work);
            if done.saturating_sub(last_feed_us) > timeout_us {
                return Some(last_feed_us + timeout_us);
            }
            now = done;
            if feeder.tick_completed(slot) {
                last_feed_us = now;
            }
            // Next slot: the latest one due, or the next one.
            slot = (slot + 1).max(now / P);
        }
        None
    }

    const TIMING: WatchdogTiming = WatchdogTiming {
        nominal_timeout_us: 100_000,
    };

    #[test]
    fn the_lsi_tolerance_bounds_the_real_timeout() {
        assert_eq!(TIMING.shortest_us(), 68_085);
        assert_eq!(TIMING.longest_us(), 188_236);
        assert_eq!(TIMING.longest_safe_stall_us(20_000), 48_085);
    }

    #[test]
    fn normal_ticks_and_any_stall_up_to_the_safe_bound_never_reset_even_with_the_fastest_lsi() {
        let safe = TIMING.longest_safe_stall_us(20_000);
        // 10 minutes of 3 ms ticks with one stall every 1000 ticks.
        for stall in [20_000, 40_000, safe] {
            let reset = run_until_reset(TIMING.shortest_us(), 600_000_000, |k| {
                if k % 1000 == 999 {
                    stall
                } else {
                    3_000
                }
            });
            assert_eq!(reset, None, "stall {stall} us");
        }
    }

    #[test]
    fn a_stall_past_the_bound_can_reset_and_a_hung_tick_always_resets_in_time() {
        let safe = TIMING.longest_safe_stall_us(20_000);
        let reset = run_until_reset(TIMING.shortest_us(), 1_000_000, |k| {
            if k == 10 {
                safe + 30_000
            } else {
                3_000
            }
        });
        assert!(reset.is_some());
        // A tick that never completes, with the slowest LSI: reset at most `longest` after the
        // last completed tick.
        for lsi_timeout in [TIMING.shortest_us(), TIMING.longest_us()] {
            let reset = run_until_reset(lsi_timeout, 10_000_000, |k| {
                if k == 50 {
                    u64::MAX
                } else {
                    3_000
                }
            });
            let last_feed = 49 * 20_000 + 3_000;
            assert_eq!(reset, Some(last_feed + lsi_timeout));
        }
    }

    #[test]
    fn the_feeder_feeds_once_per_slot_and_never_for_a_slot_that_went_back() {
        let mut feeder = WatchdogFeeder::new();
        assert!(feeder.tick_completed(0));
        assert!(feeder.tick_completed(1));
        assert!(!feeder.tick_completed(1));
        assert!(!feeder.tick_completed(0));
        assert!(feeder.tick_completed(5));
    }
}
