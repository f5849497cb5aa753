//! The QEMU run: command line, set-up, per-tick records for `cargo qemu`, and exit codes.
//!
//! Command line (QEMU `-append`): `[--in FILE.log] [--tx TX.log] [--ticks TICKS.bin]
//! [--stall SLOT:MS]... [--stack-overflow-test]`. Without `--in` the drive bundled in the firmware is replayed.
//! Paths are host paths, relative to QEMU's working directory.
//!
//! `TICKS.bin`, read by xtask: the tick-record format of `catmodel_app::record` (one record per
//! tick, then a trailer with the run's totals and the stack's high-water mark). A file without
//! the trailer is an incomplete run.
//!
//! Exit codes: 0 done; 1 I/O error on a host file; 2 bad input or command line; 3 internal.
use core::ffi::CStr;
use core::sync::atomic::Ordering;

use embassy_time::Duration;
use semihosting::io::Write;

use super::icount;
use super::replay::{self, InputSummary, LineReader, ReplayError, Source};
use crate::platform::stack::StackMeter;
use catmodel_app::record::{self, Trailer};
use catmodel_app::{LinkCounters, ReplayClock, TickConfig, TickPlatform, TickReport, TickSummary};

/// The drive replayed when no `--in` is given (data/bundled.can.log, copied by build.rs).
pub static BUNDLED_DRIVE: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/bundled.can.log"));

/// Most `--stall` options.
pub const MAX_STALLS: usize = 4;
const PATH_CAP: usize = 256;
/// The semihosting command line's capacity, bytes: QEMU passes the kernel's path and `-append`
/// (xtask/src/main.rs, `QEMU_CMDLINE_BYTES`, checks a command line fits before it runs QEMU).
const CMDLINE_BYTES: usize = 512;

/// A test stall: the tick of grid slot `slot` busy-waits `ms` milliseconds after its step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Stall {
    /// Grid slot (0 = first tick).
    pub slot: u64,
    /// Busy-wait, ms.
    pub ms: u32,
}

/// A host path as a NUL-terminated string for semihosting.
#[derive(Clone, Debug)]
pub struct HostPath(heapless::Vec<u8, PATH_CAP>);

impl HostPath {
    fn new(text: &str) -> Option<Self> {
        let mut bytes = heapless::Vec::new();
        bytes.extend_from_slice(text.as_bytes()).ok()?;
        bytes.push(0).ok()?;
        CStr::from_bytes_with_nul(&bytes).ok()?;
        Some(Self(bytes))
    }

    fn as_cstr(&self) -> &CStr {
        // Note: `new` checked that the bytes are one NUL-terminated string.
        CStr::from_bytes_with_nul(&self.0).unwrap_or(c"")
    }
}

/// The parsed command line.
#[derive(Clone, Debug)]
pub struct Options {
    /// The drive; `None` = the bundled one.
    pub input: Option<HostPath>,
    /// Where the transmitted frames go (candump).
    pub tx_log: HostPath,
    /// Where the tick records go.
    pub ticks: HostPath,
    /// Test stalls.
    pub stalls: heapless::Vec<Stall, MAX_STALLS>,
    /// `--stack-overflow-test`: overflow the stack on purpose instead of running
    /// (`cargo xtask qemu-stack-guard-test`).
    pub stack_overflow_test: bool,
}

fn parse_stall(text: &str) -> Option<Stall> {
    let (slot, ms) = text.split_once(':')?;
    Some(Stall {
        slot: slot.parse().ok()?,
        ms: ms.parse().ok()?,
    })
}

/// Reads the semihosting command line.
pub fn options() -> Result<Options, &'static str> {
    let args = semihosting::experimental::env::args::<CMDLINE_BYTES>()
        .map_err(|_| "no command line, or one longer than 512 bytes")?;
    let mut options = Options {
        input: None,
        tx_log: HostPath::new("target/qemu/tx.log").ok_or("path")?,
        ticks: HostPath::new("target/qemu/ticks.bin").ok_or("path")?,
        stalls: heapless::Vec::new(),
        stack_overflow_test: false,
    };
    let mut args = (&args).filter_map(Result::ok);
    while let Some(arg) = args.next() {
        match arg {
            "--in" => {
                options.input = Some(
                    HostPath::new(args.next().ok_or("--in needs a path")?)
                        .ok_or("--in: path too long")?,
                );
            }
            "--tx" => {
                options.tx_log = HostPath::new(args.next().ok_or("--tx needs a path")?)
                    .ok_or("--tx: path too long")?;
            }
            "--ticks" => {
                options.ticks = HostPath::new(args.next().ok_or("--ticks needs a path")?)
                    .ok_or("--ticks: path too long")?;
            }
            "--stall" => {
                let stall = args
                    .next()
                    .and_then(parse_stall)
                    .ok_or("--stall needs SLOT:MS")?;
                options.stalls.push(stall).map_err(|_| "too many --stall")?;
            }
            "--stack-overflow-test" => options.stack_overflow_test = true,
            // The first word is the program name (QEMU passes the kernel path); flags are above.
            other if other.starts_with("--") => return Err("unknown option"),
            _ => {}
        }
    }
    Ok(options)
}

/// Recurses with 256-byte frames until the stack runs out: the guard test. With the stack at
/// the bottom of SRAM (memory.x), the push below 0x2000_0000 faults; the fault cannot be
/// stacked either, so the core locks up (QEMU reports "Lockup" and exits), having written
/// nothing above the stack region.
#[allow(unconditional_recursion)]
pub fn overflow_stack(depth: u32) -> u32 {
    let mut frame = [0u8; 256];
    if let Some(first) = frame.first_mut() {
        *first = depth as u8;
    }
    let frame = core::hint::black_box(frame);
    let below = overflow_stack(depth.wrapping_add(1));
    below.wrapping_add(u32::from(frame.iter().fold(0u8, |a, b| a ^ b)))
}

/// Prints `message` on the host's stderr and ends the run with `code`.
pub fn fail(message: &str, code: i32) -> ! {
    semihosting::eprintln!("catmodel-qemu: error: {message}");
    semihosting::process::exit(code)
}

/// Opens the drive and checks it; returns the reader (rewound) and what it holds.
pub fn open_input(options: &Options) -> (LineReader, InputSummary) {
    let source = match &options.input {
        Some(path) => match semihosting::fs::File::open(path.as_cstr()) {
            Ok(file) => Source::File(file),
            Err(_) => fail("cannot open the input file", 1),
        },
        None => Source::Bundled {
            bytes: BUNDLED_DRIVE,
            pos: 0,
        },
    };
    let mut reader = LineReader::new(source);
    match replay::scan(&mut reader) {
        Ok(summary) => (reader, summary),
        Err(ReplayError::Io) => fail("cannot read the input file", 1),
        Err(ReplayError::Empty) => fail("the input holds no CAN frame", 2),
        Err(ReplayError::LineTooLong(line)) => {
            semihosting::eprintln!("catmodel-qemu: input line {line} is too long");
            semihosting::process::exit(2)
        }
        Err(ReplayError::Syntax(line, error)) => {
            semihosting::eprintln!(
                "catmodel-qemu: input line {line} is not a candump frame: {error:?}"
            );
            semihosting::process::exit(2)
        }
    }
}

/// The tick loop's configuration for the drive `summary` describes ([`ReplayClock`]).
pub fn tick_config(summary: &InputSummary) -> TickConfig {
    ReplayClock::new(summary.first_t_us).tick_config(summary.last_t_us)
}

/// Creates (truncates) a host file for writing.
pub fn create(path: &HostPath) -> semihosting::fs::File {
    match semihosting::fs::File::create(path.as_cstr()) {
        Ok(file) => file,
        Err(_) => fail("cannot create an output file (does target/qemu/ exist?)", 1),
    }
}

const RECORDS_BUFFERED: usize = 64;

/// The QEMU [`TickPlatform`]: TIM2 instruction counts, one record per tick to the host, and
/// the test stalls.
pub struct TickRecorder {
    file: semihosting::fs::File,
    stack: StackMeter,
    buf: heapless::Vec<u8, { record::RECORD_LEN * RECORDS_BUFFERED }>,
    stalls: heapless::Vec<Stall, MAX_STALLS>,
    failed: bool,
}

impl TickRecorder {
    /// Writes the header to `file`.
    pub fn new(file: semihosting::fs::File, stalls: heapless::Vec<Stall, MAX_STALLS>) -> Self {
        let mut recorder = Self {
            file,
            stack: StackMeter::new(),
            buf: heapless::Vec::new(),
            stalls,
            failed: false,
        };
        let header = record::header();
        recorder.push(&header);
        recorder
    }

    fn flush(&mut self) {
        if !self.buf.is_empty() && self.file.write_all(&self.buf).is_err() {
            self.failed = true;
        }
        self.buf.clear();
    }

    fn push(&mut self, bytes: &[u8]) {
        if self.buf.capacity() - self.buf.len() < bytes.len() {
            self.flush();
        }
        if self.buf.extend_from_slice(bytes).is_err() {
            self.failed = true;
        }
    }

    /// Writes the trailer (with the stack's exact high-water mark now) and flushes; returns
    /// whether every write succeeded.
    pub fn finish(&mut self, trailer: &Trailer) -> bool {
        let stack_high_water = self.stack.finish().unwrap_or(0);
        let stack_size = self.stack.size_bytes();
        let bytes = record::Trailer {
            stack_high_water,
            stack_size,
            ..*trailer
        }
        .encode();
        self.push(&bytes);
        self.flush();
        !self.failed
    }
}

impl TickPlatform for TickRecorder {
    fn counter(&self) -> u32 {
        icount::now()
    }

    fn counts_to_us(&self, _counts: u32) -> Option<u32> {
        // Instruction counts are not board time: "not available", as in host replay.
        None
    }

    fn tick_completed(&mut self, report: &TickReport) {
        let record = record::TickRecord {
            tick_us: report.tick_us,
            slot: report.slot,
            overruns: report.platform.overruns,
            rx_queue_drops: report.platform.rx_queue_drops,
            rx_frames: report.rx_frames,
            tx_frames: report.tx_frames,
            drain: report.drain_counts,
            step: report.step_counts,
            tick: report.tick_counts,
            flags: if report.controller {
                record::FLAG_CONTROLLER
            } else {
                0
            },
        }
        .encode();
        self.push(&record);
        if let Some(stall) = self.stalls.iter().find(|s| s.slot == report.slot) {
            embassy_time::block_for(Duration::from_millis(u64::from(stall.ms)));
        }
    }

    fn stack_high_water_bytes(&mut self) -> Option<u32> {
        self.stack.step()
    }
}

/// The run's totals for the trailer (the stack figures are filled in by
/// [`TickRecorder::finish`], the boot figure by the caller).
pub fn trailer(summary: &TickSummary, counters: &LinkCounters, input: &InputSummary) -> Trailer {
    Trailer {
        ticks: summary.ticks,
        overruns: summary.overruns,
        skipped_slots: summary.skipped_slots,
        rx_queue_drops: counters.rx_queue_drops.load(Ordering::Relaxed),
        rx_bus_errors: counters.rx_bus_errors.load(Ordering::Relaxed),
        rx_unsupported: counters.rx_unsupported.load(Ordering::Relaxed),
        tx_queue_drops: counters.tx_queue_drops.load(Ordering::Relaxed),
        tx_bus_errors: counters.tx_bus_errors.load(Ordering::Relaxed),
        input_frames: input.frames,
        input_unsupported: input.unsupported,
        stack_high_water: 0,
        stack_size: 0,
        node_boot_instructions: 0,
    }
}
