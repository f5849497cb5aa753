//! The no-panic proof of the core (issue 6, docs/faults.md "No panic path"): this program builds
//! the node from the baked model and runs `Node::step` forever on inputs the compiler cannot see
//! (volatile reads of every field: frame IDs, lengths and bytes, tick times, platform counters).
//! Its panic handler calls a function that does not exist, so the program links only if the
//! optimised firmware build (profile `firmware`) has no path from `baked::node` or `Node::step`
//! to a panic: any bounds check, `unwrap`, overflow check or assertion the optimiser cannot
//! remove makes the link fail with "undefined symbol: catmodel_core_can_panic". `cargo xtask
//! no-panic` builds it (CI). It is never run.
//!
//! It is built without defmt (feature `nopanic-check` only): defmt's linker script keeps its
//! default panic entry whether anything calls it or not, which would fail the link for nothing.
//! The core's defmt use is `derive(Format)` only; it has no defmt panic macros.
#![no_std]
#![no_main]

use core::ptr::{addr_of, addr_of_mut, read_volatile, write_volatile};

use catmodel::can::{CanFrame, CanId, TimedFrame};
use catmodel::node::{PlatformStats, Tick, TxFrames};
use cortex_m_rt::entry;

/// Frames given to one tick: more than the node's cap (`MAX_RX_FRAMES_PER_TICK`, the app's
/// batch), so that the path that counts the excess is linked too.
const BATCH: usize = catmodel::node::MAX_RX_FRAMES_PER_TICK + 4;

/// Raw input words, written by nobody the compiler knows of.
static mut INPUT: [u32; 4 + BATCH * 5] = [0; 4 + BATCH * 5];
/// Sink for the outputs, so that nothing is optimised away.
static mut OUTPUT: [u32; 4] = [0; 4];

fn input(i: usize) -> u32 {
    // SAFETY: a plain static read through a raw pointer; `get` keeps it in bounds.
    unsafe {
        let words = &*addr_of!(INPUT);
        words.get(i).map_or(0, |w| read_volatile(w))
    }
}

fn output(i: usize, value: u32) {
    // SAFETY: as above.
    unsafe {
        let words = &mut *addr_of_mut!(OUTPUT);
        if let Some(w) = words.get_mut(i) {
            write_volatile(w, value);
        }
    }
}

fn opt(word: u32) -> Option<u32> {
    (word & 1 == 1).then_some(word >> 1)
}

#[entry]
fn main() -> ! {
    // What the board and QEMU do at boot.
    let Ok(mut node) = catmodel_firmware::baked::node() else {
        output(0, 0xDEAD);
        loop {
            cortex_m::asm::wfi();
        }
    };
    let mut rx: heapless::Vec<TimedFrame, BATCH> = heapless::Vec::new();
    let mut tx = TxFrames::new();
    loop {
        let now_us = u64::from(input(0)) << 32 | u64::from(input(1));
        let flags = input(2);
        let tick = Tick {
            now_us,
            platform: PlatformStats {
                overruns: input(3),
                rx_queue_drops: input(3).rotate_left(7),
                last_step_us: opt(flags),
                stack_high_water_bytes: opt(flags.rotate_left(11)),
                watchdog_reset: flags & 0x8000_0000 != 0,
            },
        };
        rx.clear();
        let n = (flags >> 16) as usize & (BATCH - 1);
        for k in 0..n {
            let w = |j: usize| input(4 + k * 5 + j);
            let head = w(0);
            let id = if head & 0x8000_0000 != 0 {
                CanId::Extended(head & 0x1FFF_FFFF)
            } else {
                CanId::Standard((head & 0xFFFF) as u16)
            };
            let (a, b) = (w(1).to_le_bytes(), w(2).to_le_bytes());
            let frame = CanFrame {
                id,
                len: (head >> 16) as u8,
                data: [a[0], a[1], a[2], a[3], b[0], b[1], b[2], b[3]],
            };
            let t_us = u64::from(w(3)) << 32 | u64::from(w(4));
            let _ = rx.push(TimedFrame { t_us, frame });
        }
        tx.clear();
        let estimate = node.step(&tick, &rx, &mut tx);
        output(1, tx.len() as u32);
        for f in &tx {
            output(
                2,
                u32::from_le_bytes([f.data[0], f.data[3], f.data[5], f.data[7]]),
            );
        }
        output(3, estimate.pose.map_or(0, |p| p.x_m.to_bits()));
    }
}

#[cfg(not(catmodel_nopanic_locate))]
#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    extern "C" {
        /// Does not exist: a reachable panic fails the link.
        fn catmodel_core_can_panic() -> !;
    }
    // SAFETY: never called in a program that links.
    unsafe { catmodel_core_can_panic() }
}

/// `cargo xtask no-panic` builds this variant only after the check failed, to list the sites.
#[cfg(catmodel_nopanic_locate)]
#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    loop {
        cortex_m::asm::udf();
    }
}
