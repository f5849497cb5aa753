//! The tick's stages measured one by one over dedicated drives (`catmodel-qemu-stages --stages
//! FILE...`): the per-stage maxima of the worst-case bounds. Run by `cargo qemu`, `cargo xtask
//! bench-target` and `cargo xtask adversarial` (xtask/src/bound.rs), which turn its output
//! into `worst_case_bound_instructions` and `worst_case_bound_controller_instructions`
//! (docs/firmware.md, "Worst-case tick"). The method and the output format are
//! [`catmodel_firmware::platform::qemu::stages`]'s. Its own firmware (not a mode of
//! `catmodel-qemu-bench`): two nodes with their drive stages (35 KiB each) do not fit in RAM
//! beside the component benchmark's sample stores.
#![no_std]
#![no_main]
#![deny(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use catmodel_firmware::platform::qemu::icount;
use catmodel_firmware::platform::qemu::stages::{self, StageError};
use cortex_m_rt::entry;
// The `defmt` feature is on for the core's types; nothing here logs through it, but a global
// logger must exist for any dependency that does.
use defmt_semihosting as _;

/// Most drives of one `--stages` run, and the longest path of one.
const STAGE_DRIVES: usize = 24;
const STAGE_PATH: usize = 96;

/// The `--stages` paths, NUL-terminated (a static: the stack is for the nodes' ticks).
static mut STAGE_PATHS: heapless::Vec<heapless::Vec<u8, STAGE_PATH>, STAGE_DRIVES> =
    heapless::Vec::new();

/// The command line's `--stages` paths into `paths`; false without `--stages`. Not inlined: the
/// command line's buffer is gone before the measurement runs.
#[inline(never)]
fn stage_paths(paths: &mut heapless::Vec<heapless::Vec<u8, STAGE_PATH>, STAGE_DRIVES>) -> bool {
    let Ok(args) = semihosting::experimental::env::args::<1024>() else {
        return false;
    };
    let mut args = (&args).filter_map(Result::ok);
    if !args.any(|a| a == "--stages") {
        return false;
    }
    for arg in args {
        let mut bytes = heapless::Vec::new();
        if bytes.extend_from_slice(arg.as_bytes()).is_err()
            || bytes.push(0).is_err()
            || paths.push(bytes).is_err()
        {
            fail("--stages: too many or too long paths");
        }
    }
    true
}

/// `--stages FILE...`: the stage measurement over those drives.
fn stage_mode() {
    // SAFETY: the only reference to STAGE_PATHS; single-threaded, no interrupts.
    let paths = unsafe { &mut *core::ptr::addr_of_mut!(STAGE_PATHS) };
    if !stage_paths(paths) {
        return;
    }
    let mut cstrs: heapless::Vec<&core::ffi::CStr, STAGE_DRIVES> = heapless::Vec::new();
    for bytes in paths.iter() {
        match core::ffi::CStr::from_bytes_with_nul(bytes) {
            Ok(c) => {
                let _ = cstrs.push(c);
            }
            Err(_) => fail("--stages: bad path"),
        }
    }
    match stages::measure(&cstrs) {
        Ok(()) => semihosting::process::exit(0),
        Err(StageError::Io) => fail("--stages: cannot read a drive"),
        Err(StageError::Model) => fail("the baked model does not build"),
        Err(StageError::Structure(stage)) => {
            semihosting::eprintln!(
                "catmodel-qemu-stages: error: stage {stage:?} ran more often in one tick than TICK_STAGES allows, or beside a stage of another branch"
            );
            semihosting::process::exit(3)
        }
    }
}

#[entry]
fn main() -> ! {
    icount::init();
    stage_mode();
    fail("usage: catmodel-qemu-stages --stages FILE...")
}

fn fail(message: &str) -> ! {
    semihosting::eprintln!("catmodel-qemu-stages: error: {message}");
    semihosting::process::exit(3)
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    semihosting::eprintln!("catmodel-qemu-stages: panic: {info}");
    semihosting::process::exit(101)
}
