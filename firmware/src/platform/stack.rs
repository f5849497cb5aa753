//! The stack: where it is, and how deep it has been (both platforms).
//!
//! Layout (`memory.x`): the stack has its own 16 KiB region at the very bottom of SRAM,
//! 0x2000_0000..0x2000_4000, and every static (.data, .bss) lies above it. It grows down, so an
//! overflow runs off 0x2000_0000 into reserved address space and faults at once (BusFault ->
//! HardFault) instead of silently overwriting the node's state: the layout flip-link produces,
//! made by the linker script so that no extra linker is needed. `cargo xtask size` checks it.
//!
//! cortex-m-rt's `paint-stack` fills the region with [`catmodel_app::health::STACK_PAINT`] before
//! `main`; [`StackMeter`] finds the deepest scrubbed word a few words per tick
//! ([`catmodel_app::health::StackScan`]).
use core::ptr::{addr_of, read_volatile};

use catmodel_app::health::StackScan;

extern "C" {
    /// Top of the stack (highest address + 1), from `memory.x`.
    static _stack_start: u32;
    /// Bottom of the stack (lowest address), from `memory.x`.
    static _stack_end: u32;
}

/// Words read per tick: 64 words cost about 250 instructions, outside the measured tick.
pub const SCAN_WORDS_PER_TICK: usize = 64;

/// The high-water meter of the painted stack.
pub struct StackMeter {
    bottom: *const u32,
    scan: StackScan,
}

impl StackMeter {
    /// A meter over the linker's stack region.
    pub fn new() -> Self {
        // SAFETY: only the symbols' addresses are taken; they are never read as statics.
        let (bottom, top) = (addr_of!(_stack_end), addr_of!(_stack_start));
        let bytes = (top as usize).saturating_sub(bottom as usize);
        Self {
            bottom,
            scan: StackScan::new(bytes / 4),
        }
    }

    /// Stack size, bytes.
    pub fn size_bytes(&self) -> u32 {
        // SAFETY: as in `new`.
        let top = addr_of!(_stack_start) as usize;
        u32::try_from(top.saturating_sub(self.bottom as usize)).unwrap_or(u32::MAX)
    }

    fn read(bottom: *const u32, index: usize) -> u32 {
        // SAFETY: `StackScan` only asks for indices below the region's length in words, so the
        // address lies inside the stack region, which is RAM. Volatile: the words below the
        // stack pointer are written by code the compiler does not see as aliasing this read.
        unsafe { read_volatile(bottom.wrapping_add(index)) }
    }

    /// Scans [`SCAN_WORDS_PER_TICK`] more words; the deepest use so far, bytes (`None` until
    /// the first scrubbed word is found, within the first ~1 s).
    pub fn step(&mut self) -> Option<u32> {
        let bottom = self.bottom;
        self.scan
            .step(SCAN_WORDS_PER_TICK, |i| Self::read(bottom, i))
    }

    /// The exact deepest use now (a full pass; for end-of-run reports).
    pub fn finish(&mut self) -> Option<u32> {
        let bottom = self.bottom;
        self.scan.finish(|i| Self::read(bottom, i))
    }
}

impl Default for StackMeter {
    fn default() -> Self {
        Self::new()
    }
}
