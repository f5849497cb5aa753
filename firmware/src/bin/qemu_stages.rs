//! The tick's stages measured one by one over dedicated drives (`catmodel-qemu-stages --stages
//! LIST`, LIST naming the drives one per line): the per-stage maxima of the worst-case bounds.
//! Run by `cargo qemu`, `cargo xtask bench-target` and `cargo xtask adversarial`
//! (xtask/src/bound.rs), which turn its output into `worst_case_bound_instructions` and
//! `worst_case_bound_controller_instructions` (docs/firmware.md, "Worst-case tick"). The method and the output format are
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

/// The semihosting command line's capacity, bytes: QEMU passes the kernel's path and `-append`
/// (xtask/src/main.rs, `QEMU_CMDLINE_BYTES`, checks a command line fits before it runs QEMU).
const CMDLINE_BYTES: usize = 512;
/// Most drives of one `--stages` run, and the drive list's capacity, bytes.
const STAGE_DRIVES: usize = 32;
const LIST_BYTES: usize = 4096;

/// The drive list as read, then NUL-terminated lines (a static: the stack is for the nodes'
/// ticks).
static mut LIST: [u8; LIST_BYTES] = [0; LIST_BYTES];

/// Reads the file the command line's `--stages LIST` names into `list`; its length (less than
/// `list.len()`: room for the last line's NUL). Not inlined: the command line's buffer is gone
/// before the measurement runs.
#[inline(never)]
fn read_list(list: &mut [u8]) -> usize {
    let Ok(args) = semihosting::experimental::env::args::<CMDLINE_BYTES>() else {
        fail("the command line does not fit its 512 bytes")
    };
    let mut args = (&args).filter_map(Result::ok);
    if !args.any(|a| a == "--stages") {
        fail("usage: catmodel-qemu-stages --stages LIST (LIST: the drives' paths, one per line)")
    }
    let mut path = heapless::Vec::<u8, 256>::new();
    let named = args
        .next()
        .is_some_and(|arg| path.extend_from_slice(arg.as_bytes()).is_ok() && path.push(0).is_ok());
    let Some(path) = named
        .then(|| core::ffi::CStr::from_bytes_with_nul(&path).ok())
        .flatten()
    else {
        fail("--stages needs the drive list's path (at most 255 bytes)")
    };
    let Ok(mut file) = semihosting::fs::File::open(path) else {
        fail("--stages: cannot open the drive list")
    };
    let mut len = 0;
    loop {
        let Some(rest) = list.get_mut(len..list.len() - 1) else {
            fail("--stages: the drive list is too long")
        };
        if rest.is_empty() {
            fail("--stages: the drive list is longer than 4 KiB")
        }
        match semihosting::io::Read::read(&mut file, rest) {
            Ok(0) => return len,
            Ok(n) => len += n,
            Err(_) => fail("--stages: cannot read the drive list"),
        }
    }
}

/// `--stages LIST`: the stage measurement over the drives LIST names.
fn stage_mode() -> ! {
    // SAFETY: the only reference to LIST; single-threaded, no interrupts.
    let list = unsafe { &mut *core::ptr::addr_of_mut!(LIST) };
    let len = read_list(list);
    // Lines become NUL-terminated strings; `read_list` left the byte after the last one.
    let text = list.get_mut(..=len).unwrap_or_default();
    for byte in text.iter_mut() {
        if *byte == b'\n' || *byte == b'\r' {
            *byte = 0;
        }
    }
    if let Some(last) = text.last_mut() {
        *last = 0;
    }
    let mut cstrs: heapless::Vec<&core::ffi::CStr, STAGE_DRIVES> = heapless::Vec::new();
    let mut rest: &[u8] = text;
    while let Ok(line) = core::ffi::CStr::from_bytes_until_nul(rest) {
        let taken = line.to_bytes().len() + 1;
        if taken > 1 && cstrs.push(line).is_err() {
            fail("--stages: more than 32 drives")
        }
        rest = rest.get(taken..).unwrap_or_default();
    }
    if cstrs.is_empty() {
        fail("--stages: the drive list names no drive")
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
    stage_mode()
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
