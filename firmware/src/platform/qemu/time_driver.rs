//! embassy-time driver for QEMU (where embassy-stm32's TIM2 driver cannot run): SysTick
//! interrupts drive the alarms, TIM2 keeps the time.
//!
//! - Time: QEMU's STM32 timers count virtual nanoseconds. TIM2, free-running at prescaler 0
//!   ([`super::icount`]), is extended to 64 bits here (it wraps every 4.29 s; the 1 kHz
//!   interrupt sees every wrap) and divided to the 1 MHz embassy tick. Under `-icount shift=0`
//!   virtual time is exact: 1 ns per executed instruction, and jumps to the next timer deadline
//!   while the CPU sleeps in WFI (`sleep=off`).
//! - Alarms: SysTick interrupts every 1 ms (168 000 core clocks at the netduinoplus2's 168 MHz)
//!   and wakes the timers that are due; the timer queue is embassy-time-queue-utils' (integrated
//!   with the executor's tasks). A wake-up is therefore up to one interrupt period late.
//!
//! Why not count SysTick interrupts as the clock: measured under `-icount
//! shift=0,align=off,sleep=off`, QEMU 7.2 delivers SysTick every 2 ms of virtual time while the
//! CPU sleeps (every other wrap is merged into one pending interrupt), so a millisecond counter
//! runs at half speed whenever the node is idle. TIM2 has no such gap.
use core::cell::{Cell, RefCell};
use core::task::Waker;

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::SYST;
use cortex_m_rt::exception;
use critical_section::{CriticalSection, Mutex};
use embassy_time_driver::Driver;
use embassy_time_queue_utils::Queue;

use super::icount;

/// Core clock of the netduinoplus2 machine (QEMU's STM32F405 SoC model), Hz.
const CORE_HZ: u32 = 168_000_000;
/// SysTick reload for a 1 kHz alarm interrupt.
const SYSTICK_RELOAD: u32 = CORE_HZ / 1000 - 1;
/// TIM2 counts (virtual ns) per embassy tick (us).
const COUNTS_PER_US: u64 = 1000;

struct Tim2Clock {
    /// TIM2 wraps seen so far.
    wraps: u64,
    /// TIM2 at the last reading.
    last: u32,
    /// The 64-bit count at [`start`] (time 0).
    epoch: u64,
}

struct QemuDriver {
    clock: Mutex<Cell<Tim2Clock>>,
    /// The earliest pending alarm, us (`u64::MAX`: none).
    alarm_us: Mutex<Cell<u64>>,
    queue: Mutex<RefCell<Queue>>,
}

impl Clone for Tim2Clock {
    fn clone(&self) -> Self {
        *self
    }
}
impl Copy for Tim2Clock {}

impl QemuDriver {
    /// The 64-bit virtual-ns count; must be called at least once per TIM2 wrap (4.29 s).
    fn counts_cs(&self, cs: CriticalSection<'_>) -> u64 {
        let cell = self.clock.borrow(cs);
        let mut clock = cell.get();
        let now = icount::now();
        if now < clock.last {
            clock.wraps = clock.wraps.saturating_add(1);
        }
        clock.last = now;
        cell.set(clock);
        (clock.wraps << 32) | u64::from(now)
    }

    fn now_cs(&self, cs: CriticalSection<'_>) -> u64 {
        let epoch = self.clock.borrow(cs).get().epoch;
        self.counts_cs(cs).saturating_sub(epoch) / COUNTS_PER_US
    }

    fn fire_alarms(&self, cs: CriticalSection<'_>) {
        let now_us = self.now_cs(cs);
        if now_us >= self.alarm_us.borrow(cs).get() {
            // Note: the queue is only borrowed inside critical sections, which do not nest
            // here, so the borrow cannot fail; were it to, the alarm stays due and the next
            // interrupt retries (no panic path: `cargo xtask no-panic`).
            if let Ok(mut queue) = self.queue.borrow(cs).try_borrow_mut() {
                let next = queue.next_expiration(now_us);
                self.alarm_us.borrow(cs).set(next);
            }
        }
    }
}

impl Driver for QemuDriver {
    fn now(&self) -> u64 {
        critical_section::with(|cs| self.now_cs(cs))
    }

    fn schedule_wake(&self, at: u64, waker: &Waker) {
        critical_section::with(|cs| {
            let Ok(mut queue) = self.queue.borrow(cs).try_borrow_mut() else {
                // Note: cannot happen (see `fire_alarms`); a spurious wake-up makes the timer
                // poll again and reschedule, which is always correct.
                waker.wake_by_ref();
                return;
            };
            if queue.schedule_wake(at, waker) {
                // Wakes what is already due (an alarm in the past) and finds the next one.
                let next = queue.next_expiration(self.now_cs(cs));
                self.alarm_us.borrow(cs).set(next);
            }
        });
    }
}

embassy_time_driver::time_driver_impl!(static DRIVER: QemuDriver = QemuDriver {
    clock: Mutex::new(Cell::new(Tim2Clock { wraps: 0, last: 0, epoch: 0 })),
    alarm_us: Mutex::new(Cell::new(u64::MAX)),
    queue: Mutex::new(RefCell::new(Queue::new())),
});

/// Starts the clock at 0 us ([`super::icount::init`] must have run). Call it last before the
/// executor runs, so that set-up work (reading the input) is not elapsed time.
pub fn start(mut syst: SYST) {
    critical_section::with(|cs| {
        let epoch = DRIVER.counts_cs(cs);
        let cell = DRIVER.clock.borrow(cs);
        let mut clock = cell.get();
        clock.epoch = epoch;
        cell.set(clock);
    });
    syst.disable_counter();
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(SYSTICK_RELOAD);
    syst.clear_current();
    syst.enable_interrupt();
    syst.enable_counter();
}

#[exception]
fn SysTick() {
    critical_section::with(|cs| DRIVER.fire_alarms(cs));
}
