//! Instruction counting with TIM2.
//!
//! Under `qemu-system-arm -icount shift=0,align=off,sleep=off` every executed instruction
//! advances QEMU's virtual clock by exactly 1 ns, and QEMU's STM32 timers count virtual
//! nanoseconds (times the prescaler). With prescaler 0 and auto-reload 0xFFFF_FFFF, TIM2's
//! counter (0x4000_0024) is therefore a free-running instruction counter (it wraps after
//! 4.29 s; differences use wrapping arithmetic). These are instruction counts, not Cortex-M4
//! cycles: a real M4 needs about 1.1-1.5 cycles per instruction plus flash wait states.
//!
//! Only for QEMU: on a real STM32F405 TIM2 counts APB1 timer clocks and is the board's
//! embassy time driver.

const TIM2_BASE: usize = 0x4000_0000;
const TIM2_CR1: *mut u32 = TIM2_BASE as *mut u32;
const TIM2_EGR: *mut u32 = (TIM2_BASE + 0x14) as *mut u32;
const TIM2_CNT: *const u32 = (TIM2_BASE + 0x24) as *const u32;
const TIM2_PSC: *mut u32 = (TIM2_BASE + 0x28) as *mut u32;
const TIM2_ARR: *mut u32 = (TIM2_BASE + 0x2C) as *mut u32;

/// Starts TIM2 as a free-running counter: prescaler 0, auto-reload 0xFFFF_FFFF.
pub fn init() {
    // Safety: TIM2's registers are valid MMIO on the STM32F405 and in QEMU's netduinoplus2, and
    // nothing else in the QEMU build uses TIM2 (its time driver is SysTick).
    unsafe {
        TIM2_CR1.write_volatile(0);
        TIM2_PSC.write_volatile(0);
        TIM2_ARR.write_volatile(0xFFFF_FFFF);
        // UG: load the prescaler and reset the counter.
        TIM2_EGR.write_volatile(1);
        // CEN.
        TIM2_CR1.write_volatile(1);
    }
}

/// The instruction counter.
#[inline(always)]
pub fn now() -> u32 {
    // Safety: a read of TIM2_CNT, a read-only-in-effect MMIO register with no side effects.
    unsafe { TIM2_CNT.read_volatile() }
}

/// Instructions of an empty timed call (two counter reads around a `black_box`): the least of
/// 64 tries. The benchmarks subtract it from every measurement.
pub fn calibrate() -> u32 {
    let mut min = u32::MAX;
    for i in 0..64u32 {
        let t0 = now();
        core::hint::black_box(core::hint::black_box(i));
        let t1 = now();
        min = min.min(t1.wrapping_sub(t0));
    }
    min
}

/// Runs `f` between two reads of the counter: its result and the instructions it took, minus
/// `overhead` (from [`calibrate`]). Inputs and outputs go through `black_box`, so nothing is
/// constant-folded or moved out of the window.
#[inline(always)]
pub fn timed<R>(overhead: u32, f: impl FnOnce() -> R) -> (R, u32) {
    let t0 = now();
    let r = core::hint::black_box(f());
    let t1 = now();
    (r, t1.wrapping_sub(t0).saturating_sub(overhead))
}
