//! A thread-mode embassy executor that sleeps with WFI.
//!
//! embassy-executor's stock thread executor sleeps with WFE, which QEMU implements as a no-op:
//! it busy-spins (about 22 s of host time per virtual second). WFI does halt the CPU, and with
//! `-icount ...,sleep=off` QEMU then jumps the virtual clock straight to the next timer event.
//! The lost-wakeup race (a task woken between `poll` and WFI) is closed by checking the pender
//! flag with interrupts masked: WFI still wakes on a pending interrupt while PRIMASK is set.
use core::sync::atomic::{AtomicBool, Ordering};

use embassy_executor::{raw, Spawner};

/// Set when a task has been woken and the executor must poll again.
static WORK_PENDING: AtomicBool = AtomicBool::new(false);

/// Called by embassy-executor whenever a task is woken (this build does not enable the
/// crate's own cortex-m executors, so the pender is ours).
#[unsafe(export_name = "__pender")]
fn pender(_context: *mut ()) {
    WORK_PENDING.store(true, Ordering::Release);
}

/// Runs the executor forever; `init` spawns the tasks.
pub fn run(init: impl FnOnce(Spawner)) -> ! {
    let Some(executor) =
        cortex_m::singleton!(: raw::Executor = raw::Executor::new(core::ptr::null_mut()))
    else {
        // Note: `run` is called once from `main`; a second call is a programming error.
        crate::platform::qemu::run::fail("executor started twice", 3)
    };
    let executor: &'static raw::Executor = executor;
    init(executor.spawner());
    loop {
        WORK_PENDING.store(false, Ordering::Release);
        // Safety: `poll` is only ever called here, from thread mode, never re-entered.
        unsafe { executor.poll() };
        cortex_m::interrupt::free(|_| {
            if !WORK_PENDING.load(Ordering::Acquire) {
                cortex_m::asm::wfi();
            }
        });
    }
}
