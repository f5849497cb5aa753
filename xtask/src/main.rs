//! catmodel automation.
//!
//! - `cargo qemu [-- FILE.log]` (= `cargo xtask qemu`): checks the MCU target and
//!   qemu-system-arm first ([`prereq`]), builds the QEMU firmware (profile `firmware`, the one
//!   we ship), runs it on QEMU's netduinoplus2 over the bundled drive or FILE.log, writes
//!   `target/qemu/tx.log` (candump) and `target/qemu/timing.json`, prints the timing table and
//!   one summary line (drive, machine, PASS or FAIL, slowest tick against the budget, bound),
//!   and fails if the run failed or a tick exceeded the instruction budget.
//! - `cargo xtask qemu-overrun-test`: a QEMU run with stalled ticks; checks that the overruns are
//!   counted in `PlatformStats`, that the stale slot is skipped, and that every tick and every tx
//!   frame stays on the 20 ms grid; then a 500 ms stall that overflows the receive queue: every
//!   dropped frame is counted, and the count reaches the status frames.
//! - `cargo xtask qemu-stack-guard-test`: the firmware overflows its stack on purpose; checks
//!   that the core faults as the stack pointer crosses the bottom of SRAM (memory.x).
//! - `cargo xtask size`: flash and static RAM of the board firmware against the budgets.
//! - `cargo xtask no-panic`: links the core with an undefined panic handler ([`nopanic`]).
//! - `cargo xtask tx-compare FW.log HOST.log`: firmware vs host replay output ([`txcompare`]).
//! - `cargo xtask bench-target [--check]`: instructions per call of each firmware component in
//!   QEMU ([`bench`]).
//! - `cargo xtask tick-schedule`: QEMU and host replay tick at the same times on drives that
//!   start at 0, on a tick boundary, just after and before one, and at an epoch time
//!   ([`schedule`]).
//! - `cargo xtask model-corpus`: the firmware build and `catmodel replay --model` refuse every
//!   bad model file of `models/bad/` with the same message ([`corpus`]).
//! - `cargo xtask random-cars --out DIR [--count N] [--seed S] [--qemu]`: model files drawn at
//!   random over the reader's ranges, for `CATMODEL_MODEL=FILE cargo qemu`, which `--qemu` runs
//!   for each ([`cars`]).
//! - `cargo xtask adversarial [--runs N] [--seed S]`: drives made to break the tick's
//!   worst-case bound ([`bound`]), run in QEMU; fails if a tick exceeds it ([`adversarial`]).
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};
use std::time::Instant;

use anyhow::{anyhow, bail, Context, Result};

mod adversarial;
mod bench;
mod bound;
mod cars;
mod corpus;
mod drives;
mod nopanic;
mod prereq;
mod schedule;
mod txcompare;

const TARGET: &str = "thumbv7em-none-eabihf";
/// The cargo profile the firmware is built, shipped and measured with (Cargo.toml: fat LTO, one
/// codegen unit); `release` is the host's.
const FIRMWARE_PROFILE: &str = "firmware";
use catmodel::SAMPLE_PERIOD_US as TICK_US;
use catmodel_app::budget::{
    CONTROL_TICK_BUDGET_INSTRUCTIONS as CONTROL_BUDGET_INSTRUCTIONS, CYCLES_PER_TICK,
    FLASH_BUDGET_BYTES as FLASH_BUDGET, RAM_BUDGET_BYTES as RAM_BUDGET, STACK_USE_LIMIT,
    TICK_BUDGET_INSTRUCTIONS as BUDGET_INSTRUCTIONS,
};
use catmodel_app::record::{self, TickRecord, Trailer};
/// Instructions available in one 20 ms tick at the board's 168 MHz, if one instruction took one
/// cycle: the basis of `share_of_tick_percent`.
const INSTRUCTIONS_PER_TICK_AT_168MHZ: f64 = CYCLES_PER_TICK as f64;
const INSTALL_QEMU: &str = "apt-get update && apt-get install -y qemu-system-arm";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("qemu") => qemu(args.get(1..).unwrap_or(&[])),
        Some("qemu-overrun-test") => overrun_test(),
        Some("size") => size(),
        Some("qemu-stack-guard-test") => stack_guard_test(),
        Some("no-panic") => nopanic::no_panic(),
        Some("tx-compare") => txcompare::tx_compare(args.get(1..).unwrap_or(&[])),
        Some("bench-target") => bench::bench_target(args.get(1..).unwrap_or(&[])),
        Some("model-corpus") => corpus::model_corpus(),
        Some("random-cars") => cars::random_cars(args.get(1..).unwrap_or(&[])),
        Some("tick-schedule") => schedule::tick_schedule(),
        Some("adversarial") => adversarial::adversarial(args.get(1..).unwrap_or(&[])),
        _ => Err(anyhow!(
            "usage: cargo xtask qemu [-- FILE.log] | qemu-overrun-test | qemu-stack-guard-test | size | no-panic | tx-compare FW.log HOST.log\n\
             | bench-target [--check] | model-corpus | random-cars --out DIR [--count N] [--seed S] [--qemu]\n\
             | tick-schedule | adversarial [--runs N] [--seed S]\n\
             (`cargo qemu` is `cargo xtask qemu`)"
        )),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) if error.is::<Reported>() => ExitCode::FAILURE,
        Err(error) => {
            eprintln!("xtask: error: {error:#}");
            ExitCode::FAILURE
        }
    }
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."))
}

fn cargo_build(features: &str, bin: &str) -> Result<PathBuf> {
    cargo_build_all(features, &[bin])?
        .pop()
        .ok_or_else(|| anyhow!("no binary to build"))
}

/// [`cargo_build`] of several binaries of one feature set in one cargo run: their fat-LTO links
/// (one codegen unit each, one core each) run side by side.
fn cargo_build_all(features: &str, bins: &[&str]) -> Result<Vec<PathBuf>> {
    // Said before minutes of building, not after.
    prereq::ensure_target()?;
    if features == "qemu" {
        prereq::ensure_qemu()?;
    }
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let status = Command::new(cargo)
        .current_dir(root())
        .args([
            "build",
            "--profile",
            FIRMWARE_PROFILE,
            "-p",
            "catmodel-firmware",
            "--features",
            features,
        ])
        .args(bins.iter().flat_map(|bin| ["--bin", bin]))
        .args(["--target", TARGET])
        .status()
        .context("running cargo build")?;
    if !status.success() {
        bail!("building {} failed", bins.join(", "));
    }
    let dir = root().join("target").join(TARGET).join(FIRMWARE_PROFILE);
    Ok(bins.iter().map(|bin| dir.join(bin)).collect())
}

// ---------------------------------------------------------------------------------------------
// QEMU runs

fn u32_at(bytes: &[u8], at: usize) -> u32 {
    let mut b = [0u8; 4];
    b.copy_from_slice(&bytes[at..at + 4]);
    u32::from_le_bytes(b)
}

/// The QEMU firmware's tick records and trailer (`catmodel_app::record`, the format both ends
/// share).
fn parse_ticks(bytes: &[u8]) -> Result<(Vec<TickRecord>, Trailer)> {
    match record::parse(bytes) {
        Ok((records, trailer)) => Ok((records.collect(), trailer)),
        Err(record::RecordError::BadHeader) => bail!("tick records: bad header"),
        Err(record::RecordError::Version(v)) => bail!(
            "tick records: format version {v} (expected {})",
            record::FORMAT_VERSION
        ),
        Err(record::RecordError::Truncated) => {
            bail!("tick records: truncated (the firmware did not finish)")
        }
    }
}

struct QemuRun {
    records: Vec<TickRecord>,
    trailer: Trailer,
    wall_s: f64,
}

/// QEMU's netduinoplus2 (STM32F405) running `elf` with semihosting, and with instruction-exact
/// virtual time: under `-icount shift=0,align=off,sleep=off` TIM2 counts one per executed
/// instruction and runs are bit-for-bit repeatable (docs/firmware.md).
fn qemu_command(elf: &Path) -> Command {
    let mut command = Command::new("qemu-system-arm");
    command
        .current_dir(root())
        .args(["-M", "netduinoplus2", "-nographic"])
        .args(["-semihosting-config", "enable=on,target=native"])
        .args(["-icount", "shift=0,align=off,sleep=off"])
        .arg("-kernel")
        .arg(kernel_path(elf));
    command
}

/// What a QEMU run of `elf` with `append` printed on stderr, from `target/qemu/cache` when the
/// very same run was made before. A run is deterministic (`-icount shift=0`: the same kernel,
/// command line and input files execute the same instructions and print the same counts), so
/// its key is a hash of what it depends on: QEMU's version, the kernel's bytes, the command
/// line, and each input file's name and bytes. The measurements every `cargo qemu` repeats
/// (the stage firmware over its drives, the controller's worst-case solve) then run once per
/// firmware build and drives. Only successful runs are kept.
fn qemu_stderr_cached(elf: &Path, append: &str, inputs: &[PathBuf]) -> Result<String> {
    let version = Command::new("qemu-system-arm").arg("--version").output();
    let version = match version {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            bail!("qemu-system-arm is not installed; install it with:\n    {INSTALL_QEMU}")
        }
        other => other.context("running qemu-system-arm --version")?.stdout,
    };
    let mut key = Fnv64::default();
    key.field(&version);
    key.field(&std::fs::read(elf).with_context(|| format!("reading {}", elf.display()))?);
    key.field(append.as_bytes());
    for input in inputs {
        key.field(input.as_os_str().as_encoded_bytes());
        key.field(&std::fs::read(input).with_context(|| format!("reading {}", input.display()))?);
    }
    let cache = root().join("target").join("qemu").join("cache");
    let name = elf
        .file_name()
        .map_or_else(|| "run".into(), |n| n.to_string_lossy());
    let entry = cache.join(format!("{name}-{:016x}.stderr", key.0));
    if let Ok(stderr) = std::fs::read_to_string(&entry) {
        return Ok(stderr);
    }
    let output = qemu_command(elf)
        .args(["-append", append])
        .output()
        .context("running qemu-system-arm")?;
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    if !output.status.success() {
        bail!("{} failed ({}):\n{stderr}", name, output.status);
    }
    std::fs::create_dir_all(&cache).with_context(|| format!("creating {}", cache.display()))?;
    std::fs::write(&entry, &stderr).with_context(|| format!("writing {}", entry.display()))?;
    Ok(stderr)
}

/// FNV-1a, 64 bits, over length-prefixed fields (so that no two field lists hash the same
/// bytes): a cache key, not a digest against tampering.
struct Fnv64(u64);

impl Default for Fnv64 {
    fn default() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }
}

impl Fnv64 {
    fn field(&mut self, bytes: &[u8]) {
        for &b in (bytes.len() as u64).to_le_bytes().iter().chain(bytes) {
            self.0 = (self.0 ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
}

/// The kernel's path as QEMU is given it: relative to the repository, QEMU's working
/// directory, when inside (QEMU passes it on as the firmware's first argument, [`qemu_append`]).
fn kernel_path(elf: &Path) -> &Path {
    elf.strip_prefix(root()).unwrap_or(elf)
}

/// Runs the QEMU firmware with `args` appended; outputs go to `out_dir`.
fn run_qemu(elf: &Path, out_dir: &Path, input: Option<&Path>, extra: &[&str]) -> Result<QemuRun> {
    std::fs::create_dir_all(out_dir).with_context(|| format!("creating {}", out_dir.display()))?;
    let tx = out_dir.join("tx.log");
    let ticks = out_dir.join("ticks.bin");
    let _ = std::fs::remove_file(&ticks);
    let mut append = vec!["catmodel-qemu".to_string()];
    if let Some(input) = input {
        let input = input
            .canonicalize()
            .with_context(|| format!("input {}", input.display()))?;
        append.extend(["--in".into(), qemu_path(&input)?]);
    }
    append.extend([
        "--tx".into(),
        qemu_path(&tx)?,
        "--ticks".into(),
        qemu_path(&ticks)?,
    ]);
    append.extend(extra.iter().map(|s| s.to_string()));
    let append = qemu_append(elf, &append)?;

    let started = Instant::now();
    let output = qemu_command(elf)
        .args(["-append", &append])
        .output()
        .context("running qemu-system-arm")?;
    let wall_s = started.elapsed().as_secs_f64();
    // The firmware reports in text on stderr; defmt output (if any dependency logs) goes to
    // stdout as binary frames: keep it for `defmt-print -e ELF`.
    let _ = std::fs::write(out_dir.join("defmt.bin"), &output.stdout);
    if !output.status.success() {
        eprint!("{}", String::from_utf8_lossy(&output.stderr));
        bail!("the QEMU firmware failed ({})", output.status);
    }
    // On success the firmware's one line of counts repeats the trailer, which the callers
    // print: not echoed.
    let bytes = std::fs::read(&ticks).with_context(|| format!("reading {}", ticks.display()))?;
    let (records, trailer) = parse_ticks(&bytes)?;
    if records.len() as u64 != trailer.ticks {
        bail!(
            "tick records: {} records, trailer says {}",
            records.len(),
            trailer.ticks
        );
    }
    Ok(QemuRun {
        records,
        trailer,
        wall_s,
    })
}

/// The QEMU firmwares' semihosting command line buffer, bytes (`CMDLINE_BYTES` in
/// firmware/src/platform/qemu/run.rs and firmware/src/bin/qemu_stages.rs).
const QEMU_CMDLINE_BYTES: usize = 512;

/// `path` as a QEMU firmware opens it: relative to the repository (QEMU's working directory,
/// [`qemu_command`]) when it lies inside, so that the command line does not grow with the
/// checkout's path.
fn qemu_path(path: &Path) -> Result<String> {
    let inside = path
        .strip_prefix(root())
        .map(Path::to_path_buf)
        .ok()
        .or_else(|| {
            let canonical = path.canonicalize().ok()?;
            let canonical_root = root().canonicalize().ok()?;
            canonical
                .strip_prefix(canonical_root)
                .ok()
                .map(Path::to_path_buf)
        });
    let path = inside.as_deref().unwrap_or(path);
    let text = path.to_str().ok_or_else(|| anyhow!("non-UTF-8 path"))?;
    if text.contains(char::is_whitespace) || text.len() > 250 {
        bail!("QEMU's command line cannot carry the path {text:?} (spaces or too long)");
    }
    Ok(text.to_string())
}

/// `words` as QEMU's `-append`, checked to fit the firmware's command line: QEMU hands the
/// firmware the kernel's path, a space and `-append` (`semihosting_arg_fallback`), NUL-terminated.
fn qemu_append(elf: &Path, words: &[String]) -> Result<String> {
    let append = words.join(" ");
    let bytes = kernel_path(elf).as_os_str().len() + 1 + append.len() + 1;
    if bytes > QEMU_CMDLINE_BYTES {
        bail!(
            "the QEMU command line would be {bytes} bytes, more than the firmware's \
             {QEMU_CMDLINE_BYTES}: {} {append}",
            kernel_path(elf).display()
        );
    }
    Ok(append)
}

/// min, median, p99, max by nearest rank.
fn stats(values: &[u32]) -> [u32; 4] {
    let mut sorted = values.to_vec();
    sorted.sort_unstable();
    if sorted.is_empty() {
        return [0; 4];
    }
    let rank =
        |p: f64| sorted[((p * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len()) - 1];
    [sorted[0], rank(0.5), rank(0.99), sorted[sorted.len() - 1]]
}

fn stats_json(values: &[u32]) -> serde_json::Value {
    let [min, median, p99, max] = stats(values);
    serde_json::json!({ "min": min, "median": median, "p99": p99, "max": max })
}

/// The machine `cargo qemu` runs on, as its summary line names it.
const QEMU_MACHINE: &str = "QEMU netduinoplus2 (STM32F405, Cortex-M4F)";

/// An error the command has already reported (its summary line says FAIL).
#[derive(Debug)]
struct Reported;

impl std::fmt::Display for Reported {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("reported above")
    }
}

impl std::error::Error for Reported {}

/// What one `cargo qemu` run found: the slowest tick, the bound if `timing.json` has one, and
/// what failed.
#[derive(Clone, Debug, Default, PartialEq)]
struct Verdict {
    /// The slowest tick in which no controller planned.
    max_instructions: u32,
    /// The slowest tick in which a controller planned, if any did.
    max_control_instructions: Option<u32>,
    /// The worst-case bound of ticks in which no controller plans.
    bound_instructions: Option<u64>,
    /// The worst-case bound of ticks in which a controller plans.
    control_bound_instructions: Option<u64>,
    failures: Vec<String>,
    /// Checks turned into warnings (CATMODEL_BUDGET_WARN_ONLY).
    waived: Vec<String>,
}

/// `21267` -> `21 267`: figures as the README writes them.
fn grouped(n: u64) -> String {
    let digits = n.to_string();
    let mut out = String::new();
    for (i, c) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i).is_multiple_of(3) {
            out.push(' ');
        }
        out.push(c);
    }
    out
}

/// The one line `cargo qemu` ends with: the drive, the machine, PASS or FAIL, the slowest tick
/// against the budget, and the worst-case bound.
fn summary_line(drive: &str, v: &Verdict) -> String {
    let verdict = if v.failures.is_empty() {
        if v.waived.is_empty() {
            "PASS".to_string()
        } else {
            format!("PASS with checks waived ({})", v.waived.join("; "))
        }
    } else {
        format!("FAIL ({})", v.failures.join("; "))
    };
    let share = f64::from(v.max_instructions) / f64::from(BUDGET_INSTRUCTIONS) * 100.0;
    let control = v.max_control_instructions.map_or(String::new(), |c| {
        format!(
            ", slowest controller tick {} = {:.0} % of the {} budget",
            grouped(u64::from(c)),
            f64::from(c) / f64::from(CONTROL_BUDGET_INSTRUCTIONS) * 100.0,
            grouped(u64::from(CONTROL_BUDGET_INSTRUCTIONS)),
        )
    });
    let bound = match (v.bound_instructions, v.control_bound_instructions) {
        (Some(b), Some(c)) => format!(
            "bound {} instructions (controller ticks: {})",
            grouped(b),
            grouped(c)
        ),
        (Some(b), None) => format!("bound {} instructions", grouped(b)),
        _ => "bound: not computed".to_string(),
    };
    // No tick takes 0 instructions: 0 means every tick was a controller tick.
    let plain = if v.max_instructions == 0 && v.max_control_instructions.is_some() {
        "every tick a controller tick".to_string()
    } else {
        format!(
            "slowest tick {} instructions = {share:.0} % of the {} budget",
            grouped(u64::from(v.max_instructions)),
            grouped(u64::from(BUDGET_INSTRUCTIONS)),
        )
    };
    format!("cargo qemu: {drive} on {QEMU_MACHINE}: {verdict}, {plain}{control}, {bound}")
}

fn qemu(args: &[String]) -> Result<()> {
    let input = match args {
        [] => None,
        [flag] if flag == "--" => None,
        [flag, file] if flag == "--" => Some(PathBuf::from(file)),
        [file] => Some(PathBuf::from(file)),
        _ => bail!("usage: cargo qemu [-- FILE.log]"),
    };
    let drive = input.as_ref().map_or_else(
        || "data/bundled.can.log".to_string(),
        |p| p.display().to_string(),
    );
    // A failed run leaves no other run's figures behind to be read as its own.
    let timing = root().join("target").join("qemu").join("timing.json");
    if timing.exists() {
        std::fs::remove_file(&timing).with_context(|| format!("removing {}", timing.display()))?;
    }
    resolve_model_env()?;
    match qemu_run(input.as_deref()) {
        Ok(verdict) => {
            println!("{}", summary_line(&drive, &verdict));
            if verdict.failures.is_empty() {
                Ok(())
            } else {
                Err(Reported.into())
            }
        }
        Err(error) => {
            eprintln!("xtask: error: {error:#}");
            println!("cargo qemu: {drive} on {QEMU_MACHINE}: FAIL (the run did not complete: see the error above)");
            Err(Reported.into())
        }
    }
}

/// Makes `CATMODEL_MODEL` absolute for the firmware's build script and the bound, which run in
/// the repository: a relative path is taken from the directory `cargo qemu` runs in, as its LOG
/// is, and else from the repository root (as documented before; the same from the root). Neither
/// there: an error naming both places.
fn resolve_model_env() -> Result<()> {
    let Some(model) = std::env::var_os("CATMODEL_MODEL") else {
        return Ok(());
    };
    let given = PathBuf::from(&model);
    if given.is_absolute() {
        return Ok(());
    }
    let here = std::env::current_dir().context("the current directory")?;
    let resolved = [here.join(&given), root().join(&given)]
        .into_iter()
        .find(|p| p.is_file())
        .ok_or_else(|| {
            anyhow!(
                "CATMODEL_MODEL={}: no such file in the current directory {} nor in the \
                 repository root {}",
                given.display(),
                here.display(),
                root().display()
            )
        })?;
    std::env::set_var("CATMODEL_MODEL", resolved);
    Ok(())
}

/// Builds and runs the QEMU firmware over `input` (default: the bundled drive), writes
/// `target/qemu/timing.json`, prints the table, and checks the run.
fn qemu_run(input: Option<&Path>) -> Result<Verdict> {
    // The stage-measurement firmware of the bound (below) with it, in one build.
    let elf = cargo_build_all("qemu", &["catmodel-qemu", "catmodel-qemu-stages"])?.remove(0);
    let out_dir = root().join("target").join("qemu");
    let run = run_qemu(&elf, &out_dir, input, &[])?;

    let whole: Vec<u32> = run.records.iter().map(|r| r.tick).collect();
    let drain: Vec<u32> = run.records.iter().map(|r| r.drain).collect();
    let step: Vec<u32> = run.records.iter().map(|r| r.step).collect();
    let handoff: Vec<u32> = run
        .records
        .iter()
        .map(|r| r.tick.saturating_sub(r.drain).saturating_sub(r.step))
        .collect();
    let plain: Vec<u32> = run
        .records
        .iter()
        .filter(|r| !r.controller())
        .map(|r| r.tick)
        .collect();
    let control: Vec<u32> = run
        .records
        .iter()
        .filter(|r| r.controller())
        .map(|r| r.tick)
        .collect();
    let [_, _, _, max_plain] = stats(&plain);
    let max_control = control.iter().copied().max();
    let [_, _, _, max] = stats(&whole);
    let share = f64::from(max) / INSTRUCTIONS_PER_TICK_AT_168MHZ * 100.0;
    let bound = bound::measure()?;
    let bound_total = bound.total();
    let timing = serde_json::json!({
        "ticks": run.records.len(),
        "unit": "instructions (QEMU -icount shift=0: TIM2 counts one per executed instruction); not Cortex-M4 cycles",
        "instructions": stats_json(&whole),
        "budget_instructions": BUDGET_INSTRUCTIONS,
        "worst_case_bound_instructions": bound.total(),
        "worst_case_bound_controller_instructions": bound.total_control(),
        "worst_case": bound.json(),
        "controller_ticks": control.len(),
        "controller_instructions": stats_json(&control),
        "controller_budget_instructions": CONTROL_BUDGET_INSTRUCTIONS,
        "share_of_tick_percent": (share * 1000.0).round() / 1000.0,
        "share_of_tick_basis": "max instructions / (0.02 s * 168e6), i.e. as if one instruction took one 168 MHz cycle",
        "components": {
            "drain_rx_queue": stats_json(&drain),
            "node_step": stats_json(&step),
            "handoff_tx_queue": stats_json(&handoff),
        },
        "overruns": run.trailer.overruns,
        "skipped_slots": run.trailer.skipped_slots,
        "rx_queue_drops": run.trailer.rx_queue_drops,
        "input_frames": run.trailer.input_frames,
        "input_frames_skipped_remote_or_fd": run.trailer.input_unsupported,
        "rx_frames_to_node": run.records.iter().map(|r| u64::from(r.rx_frames)).sum::<u64>(),
        "rx_bus_errors": run.trailer.rx_bus_errors,
        "rx_unsupported": run.trailer.rx_unsupported,
        "tx_frames": run.records.iter().map(|r| u64::from(r.tx_frames)).sum::<u64>(),
        "stack_high_water_bytes": run.trailer.stack_high_water,
        "stack_size_bytes": run.trailer.stack_size,
        "node_boot_instructions": run.trailer.node_boot_instructions,
        "qemu_wall_seconds": (run.wall_s * 1000.0).round() / 1000.0,
    });
    std::fs::write(
        out_dir.join("timing.json"),
        serde_json::to_string_pretty(&timing)? + "\n",
    )?;

    let mut table = String::new();
    let _ = writeln!(
        table,
        "{} ticks, {} frames in, {} tx frames; QEMU wall time {:.2} s",
        run.records.len(),
        run.trailer.input_frames,
        timing["tx_frames"],
        run.wall_s
    );
    let _ = writeln!(
        table,
        "instructions per tick (QEMU instruction counts, not cycles):"
    );
    let _ = writeln!(
        table,
        "  {:<18}{:>9}{:>9}{:>9}{:>9}",
        "", "min", "median", "p99", "max"
    );
    for (name, values) in [
        ("whole tick", &whole),
        ("  drain rx queue", &drain),
        ("  Node::step", &step),
        ("  handoff tx", &handoff),
    ] {
        let [a, b, c, d] = stats(values);
        let _ = writeln!(table, "  {name:<18}{a:>9}{b:>9}{c:>9}{d:>9}");
    }
    let _ = writeln!(
        table,
        "budget {BUDGET_INSTRUCTIONS} instructions; slowest tick = {share:.3} % of a 20 ms tick at 168 MHz"
    );
    if let Some(c) = max_control {
        let _ = writeln!(
            table,
            "{} ticks in which a controller planned: slowest {c} instructions, budget {CONTROL_BUDGET_INSTRUCTIONS}",
            control.len()
        );
    }
    let _ = writeln!(
        table,
        "overruns {}, skipped slots {}, rx queue drops {}",
        run.trailer.overruns, run.trailer.skipped_slots, run.trailer.rx_queue_drops
    );
    let _ = writeln!(
        table,
        "node built at boot in {} instructions (configuration image checked and read)",
        run.trailer.node_boot_instructions
    );
    let stack_share =
        f64::from(run.trailer.stack_high_water) / f64::from(run.trailer.stack_size.max(1));
    let _ = writeln!(
        table,
        "stack high-water mark {} B of the {} B stack ({:.0} %; limit {:.0} %)",
        run.trailer.stack_high_water,
        run.trailer.stack_size,
        stack_share * 100.0,
        STACK_USE_LIMIT * 100.0
    );
    table.push_str(&bound.table());
    let _ = writeln!(table, "wrote target/qemu/tx.log, target/qemu/timing.json");
    print!("{table}");

    let mut verdict = Verdict {
        max_instructions: max_plain,
        max_control_instructions: max_control,
        bound_instructions: timing["worst_case_bound_instructions"].as_u64(),
        control_bound_instructions: timing["worst_case_bound_controller_instructions"].as_u64(),
        ..Verdict::default()
    };
    if run.trailer.stack_high_water == 0 {
        verdict
            .failures
            .push("stack high-water mark 0: the stack was not painted".into());
    } else if stack_share > STACK_USE_LIMIT {
        verdict.failures.push(format!(
            "stack high-water mark {:.0} % of the stack, over {:.0} %",
            stack_share * 100.0,
            STACK_USE_LIMIT * 100.0
        ));
    }
    verdict.failures.extend(bound.check(max_plain, max_control));
    let over_control = max_control.filter(|&c| c > CONTROL_BUDGET_INSTRUCTIONS);
    if let Some(c) = over_control {
        verdict.failures.push(format!(
            "a controller tick took {}, over its budget",
            grouped(u64::from(c))
        ));
    }
    if bound.total_control() > u64::from(CONTROL_BUDGET_INSTRUCTIONS) {
        verdict.failures.push(format!(
            "the controller's worst-case bound {} is over its budget",
            grouped(bound.total_control())
        ));
    }
    if max_plain > BUDGET_INSTRUCTIONS || bound.total() > u64::from(BUDGET_INSTRUCTIONS) {
        // CI sets CATMODEL_BUDGET_WARN_ONLY=1 while the node is over budget (README, "Status"):
        // the run, its outputs and every other check still count.
        let over = format!(
            "worst-case bound {} (slowest tick {}), over the budget",
            grouped(bound_total),
            grouped(u64::from(max_plain))
        );
        if std::env::var_os("CATMODEL_BUDGET_WARN_ONLY").is_some() {
            verdict
                .waived
                .push(format!("{over}: CATMODEL_BUDGET_WARN_ONLY"));
        } else {
            verdict.failures.push(over);
        }
    }
    if run.trailer.overruns != 0 || run.trailer.rx_queue_drops != 0 {
        verdict.failures.push(format!(
            "{} overruns, {} receive-queue drops",
            run.trailer.overruns, run.trailer.rx_queue_drops
        ));
    }
    if run.trailer.tx_queue_drops != 0 || run.trailer.tx_bus_errors != 0 {
        verdict.failures.push(format!(
            "{} transmit frames lost",
            u64::from(run.trailer.tx_queue_drops) + u64::from(run.trailer.tx_bus_errors)
        ));
    }
    Ok(verdict)
}

/// Parses the timestamps of a candump file, us.
fn candump_times(text: &str) -> Result<Vec<u64>> {
    let mut times = Vec::new();
    for (n, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let stamp = line
            .split_whitespace()
            .next()
            .and_then(|s| s.strip_prefix('('))
            .and_then(|s| s.strip_suffix(')'))
            .and_then(|s| s.split_once('.'))
            .ok_or_else(|| anyhow!("tx.log line {}: no timestamp", n + 1))?;
        let secs: u64 = stamp.0.parse()?;
        let micros: u64 = stamp.1.parse()?;
        times.push(secs * 1_000_000 + micros);
    }
    Ok(times)
}

/// Stalls slot 10 for 30 ms (its tick ends after slot 11 is due: one overrun, nothing skipped)
/// and slot 30 for 50 ms (ends after slot 32 is due: one overrun, slot 31 is stale and skipped,
/// one more overrun).
fn overrun_test() -> Result<()> {
    let elf = cargo_build("qemu", "catmodel-qemu")?;
    let out_dir = root().join("target").join("qemu").join("overrun-test");
    let run = run_qemu(
        &elf,
        &out_dir,
        None,
        &["--stall", "10:30", "--stall", "30:50"],
    )?;
    let records = &run.records;
    let mut failures = Vec::new();
    let mut check = |ok: bool, what: String| {
        println!("{} {what}", if ok { "ok  " } else { "FAIL" });
        if !ok {
            failures.push(what);
        }
    };
    let Some(first) = records.first() else {
        bail!("no ticks recorded");
    };
    if records.len() < 40 {
        bail!(
            "the drive is too short for the stall test ({} ticks)",
            records.len()
        );
    }
    let overruns_at = |slot: u64| records.iter().find(|r| r.slot == slot).map(|r| r.overruns);
    check(
        run.trailer.overruns == 3,
        format!("3 overruns counted in total (got {})", run.trailer.overruns),
    );
    check(
        run.trailer.skipped_slots == 1,
        format!("1 slot skipped (got {})", run.trailer.skipped_slots),
    );
    check(
        overruns_at(10) == Some(0) && overruns_at(11) == Some(1),
        format!(
            "PlatformStats.overruns 0 at slot 10, 1 from slot 11 (got {:?}, {:?})",
            overruns_at(10),
            overruns_at(11)
        ),
    );
    check(
        overruns_at(31).is_none() && overruns_at(32) == Some(3),
        format!(
            "slot 31 skipped, PlatformStats.overruns 3 at slot 32 (got {:?}, {:?})",
            overruns_at(31).is_some(),
            overruns_at(32)
        ),
    );
    let slots: Vec<u64> = records.iter().map(|r| r.slot).collect();
    let expected: Vec<u64> = (0..=slots[slots.len() - 1]).filter(|&s| s != 31).collect();
    check(
        slots == expected,
        "every other slot ran once, in order (no catch-up burst)".into(),
    );
    check(
        records
            .iter()
            .all(|r| r.tick_us == first.tick_us + r.slot * TICK_US),
        "every tick time is on the 20 ms grid".into(),
    );
    let tx_text = std::fs::read_to_string(out_dir.join("tx.log"))?;
    let tx_times = candump_times(&tx_text)?;
    let tick_times: std::collections::BTreeSet<u64> = records.iter().map(|r| r.tick_us).collect();
    check(
        tx_times.iter().all(|t| tick_times.contains(t)),
        format!(
            "all {} tx frames are stamped with a tick time on the grid",
            tx_times.len()
        ),
    );
    let expected_tx: u64 = records.iter().map(|r| u64::from(r.tx_frames)).sum();
    check(
        tx_times.len() as u64 == expected_tx,
        format!("tx.log holds the {expected_tx} frames the ticks returned"),
    );
    let unexpected_drops = records.iter().any(|r| r.rx_queue_drops != 0);
    check(!unexpected_drops, "no receive-queue drops".into());
    println!("QEMU wall time {:.2} s", run.wall_s);

    // A 500 ms stall: the receive task cannot run either, so about 125 frames are due at once
    // when it resumes, twice what the 64-frame receive queue holds. The excess must be dropped
    // and counted (never silently): in the trailer, in PlatformStats, and in the status frames.
    let flood_dir = root().join("target").join("qemu").join("rx-overflow-test");
    let flood = run_qemu(&elf, &flood_dir, None, &["--stall", "100:500"])?;
    let drops = flood.trailer.rx_queue_drops;
    check(
        drops > 0,
        format!("a 500 ms stall overflows the receive queue: {drops} frames dropped and counted"),
    );
    let last = flood.records.last().map(|r| r.rx_queue_drops);
    check(
        last == Some(drops),
        format!("PlatformStats.rx_queue_drops reaches the same count (got {last:?})"),
    );
    let delivered: u64 = flood.records.iter().map(|r| u64::from(r.rx_frames)).sum();
    check(
        delivered + u64::from(drops) == u64::from(flood.trailer.input_frames),
        format!(
            "every input frame was either handed to the node or counted as dropped ({delivered} + {drops} = {})",
            flood.trailer.input_frames
        ),
    );
    let status_drops =
        rx_queue_drops_in_status(&std::fs::read_to_string(flood_dir.join("tx.log"))?);
    check(
        status_drops == Some(drops),
        format!("NODE_STATUS page 3 reports {drops} receive-queue drops (got {status_drops:?})"),
    );
    if failures.is_empty() {
        println!("overrun test passed");
        Ok(())
    } else {
        bail!("overrun test: {} check(s) failed", failures.len())
    }
}

/// The last receive-queue drop count NODE_STATUS page 3 reported in a candump text.
fn rx_queue_drops_in_status(candump: &str) -> Option<u32> {
    use catmodel::can::NodeStatus;
    candump
        .lines()
        .filter_map(|line| catmodel::can::candump::parse_line(line).ok())
        .filter_map(|f| match NodeStatus::decode(&f.frame) {
            Ok((NodeStatus::Platform { rx_queue_drops, .. }, _)) => Some(rx_queue_drops),
            _ => None,
        })
        .next_back()
}

// ---------------------------------------------------------------------------------------------
// Size

/// Flash and static RAM of an ELF32 little-endian image, from its section headers: allocated
/// sections in flash (0x0800_0000..) count as flash; allocated sections in RAM (0x2000_0000..)
/// count as RAM, and those with contents (.data) count as flash too (their load image).
fn elf_flash_ram(bytes: &[u8]) -> Result<(u64, u64)> {
    if bytes.len() < 52 || &bytes[..4] != b"\x7fELF" || bytes[4] != 1 || bytes[5] != 1 {
        bail!("not a little-endian ELF32 file");
    }
    let u16_at = |at: usize| u16::from_le_bytes([bytes[at], bytes[at + 1]]);
    let shoff = u32_at(bytes, 0x20) as usize;
    let shentsize = u16_at(0x2E) as usize;
    let shnum = u16_at(0x30) as usize;
    const SHF_ALLOC: u32 = 0x2;
    const SHT_NOBITS: u32 = 8;
    let (mut flash, mut ram) = (0u64, 0u64);
    for i in 0..shnum {
        let at = shoff + i * shentsize;
        if at + 40 > bytes.len() {
            bail!("truncated section header table");
        }
        let kind = u32_at(bytes, at + 4);
        let flags = u32_at(bytes, at + 8);
        let addr = u32_at(bytes, at + 12);
        let size = u64::from(u32_at(bytes, at + 20));
        if flags & SHF_ALLOC == 0 || size == 0 {
            continue;
        }
        match addr >> 24 {
            0x08 => flash += size,
            0x20 => {
                ram += size;
                if kind != SHT_NOBITS {
                    flash += size;
                }
            }
            _ => {}
        }
    }
    Ok((flash, ram))
}

/// The stack guard (memory.x, firmware/src/platform/stack.rs) in action: the QEMU firmware recurses until
/// its stack runs out. The guard holds if the core faults with the stack pointer just below
/// SRAM (0x2000_0000), i.e. after the whole stack region and before anything else: the fault
/// cannot be stacked either, so the core locks up and QEMU stops ("Lockup") with the registers.
fn stack_guard_test() -> Result<()> {
    let elf = cargo_build("qemu", "catmodel-qemu")?;
    let output = qemu_command(&elf)
        .args(["-append", "catmodel-qemu --stack-overflow-test"])
        .output()
        .context("running qemu-system-arm")?;
    let stderr = String::from_utf8_lossy(&output.stderr);
    if output.status.success() || !stderr.contains("Lockup") {
        bail!(
            "expected a lockup from the stack guard, got {}:\n{stderr}",
            output.status
        );
    }
    let sp = stderr
        .split_whitespace()
        .find_map(|w| w.strip_prefix("R13="))
        .and_then(|hex| u32::from_str_radix(hex, 16).ok())
        .context("no R13 in QEMU's register dump")?;
    // One 256-byte frame plus the exception frame below the bottom at most.
    if !(0x2000_0000 - 1024..0x2000_0000).contains(&sp) {
        bail!("the fault came with SP = 0x{sp:08x}, not just below 0x2000_0000");
    }
    println!(
        "stack guard: the overflow faulted at SP = 0x{sp:08x}, just below SRAM; nothing above the stack region was written"
    );
    Ok(())
}

/// The value of symbol `name` in an ELF32 little-endian image (from `.symtab`).
fn elf_symbol(bytes: &[u8], name: &str) -> Option<u32> {
    let u16_at = |at: usize| Some(u16::from_le_bytes(bytes.get(at..at + 2)?.try_into().ok()?));
    let u32_le = |at: usize| Some(u32::from_le_bytes(bytes.get(at..at + 4)?.try_into().ok()?));
    let shoff = u32_le(0x20)? as usize;
    let shentsize = usize::from(u16_at(0x2E)?);
    let shnum = usize::from(u16_at(0x30)?);
    const SHT_SYMTAB: u32 = 2;
    let section = |i: usize| shoff + i * shentsize;
    let symtab = (0..shnum).find(|&i| u32_le(section(i) + 4) == Some(SHT_SYMTAB))?;
    let (sym_off, sym_size) = (
        u32_le(section(symtab) + 16)? as usize,
        u32_le(section(symtab) + 20)? as usize,
    );
    let strtab = u32_le(section(symtab) + 24)? as usize;
    let str_off = u32_le(section(strtab) + 16)? as usize;
    (0..sym_size / 16).find_map(|k| {
        let at = sym_off + k * 16;
        let name_at = str_off + u32_le(at)? as usize;
        let rest = bytes.get(name_at..)?;
        let end = rest.iter().position(|&b| b == 0)?;
        (&rest[..end] == name.as_bytes()).then(|| u32_le(at + 4))?
    })
}

fn size() -> Result<()> {
    let elf = cargo_build("board", "catmodel-board")?;
    let bytes = std::fs::read(&elf)?;
    let (flash, ram) = elf_flash_ram(&bytes)?;
    let stack_top = elf_symbol(&bytes, "_stack_start").context("no _stack_start symbol")?;
    let stack_bottom = elf_symbol(&bytes, "_stack_end").context("no _stack_end symbol")?;
    let data_start = elf_symbol(&bytes, "__sdata").context("no __sdata symbol")?;
    let stack = u64::from(stack_top.saturating_sub(stack_bottom));
    println!("catmodel-board (profile {FIRMWARE_PROFILE}, {TARGET}):");
    println!(
        "  flash {:>7} B = {:6.1} KiB of {} KiB budget",
        flash,
        flash as f64 / 1024.0,
        FLASH_BUDGET / 1024
    );
    println!(
        "  RAM   {:>7} B = {:6.1} KiB of {} KiB budget: static (.data + .bss + .uninit) {:.1} KiB + the stack region {:.1} KiB",
        ram + stack,
        (ram + stack) as f64 / 1024.0,
        RAM_BUDGET / 1024,
        ram as f64 / 1024.0,
        stack as f64 / 1024.0
    );
    // The overflow guard (memory.x, firmware/src/platform/stack.rs): the stack starts at the bottom of
    // SRAM and every static lies above its top, so an overflow faults below 0x2000_0000.
    if stack_bottom != 0x2000_0000 || stack_top > data_start {
        bail!(
            "stack layout: the stack must sit at the bottom of SRAM below every static \
             (stack 0x{stack_bottom:08x}..0x{stack_top:08x}, .data at 0x{data_start:08x})"
        );
    }
    println!(
        "  stack 0x{stack_bottom:08x}..0x{stack_top:08x} below .data/.bss (0x{data_start:08x}..): an overflow faults instead of overwriting statics"
    );
    if flash > FLASH_BUDGET || ram + stack > RAM_BUDGET {
        if std::env::var_os("CATMODEL_BUDGET_WARN_ONLY").is_some() {
            eprintln!("xtask: WARNING: the board firmware is over budget (not fatal: CATMODEL_BUDGET_WARN_ONLY)");
        } else {
            bail!("the board firmware is over budget")
        };
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cache_key_is_fnv1a_and_keeps_its_fields_apart() {
        // FNV-1a 64 of "a" (the published test vector), with this key's length prefix taken off
        // by hashing the raw byte after the offset basis.
        let mut raw = Fnv64::default();
        raw.0 = (raw.0 ^ u64::from(b'a')).wrapping_mul(0x0000_0100_0000_01b3);
        assert_eq!(raw.0, 0xaf63_dc4c_8601_ec8c);
        let key = |fields: &[&[u8]]| {
            let mut k = Fnv64::default();
            fields.iter().for_each(|f| k.field(f));
            k.0
        };
        assert_ne!(key(&[b"ab", b"c"]), key(&[b"a", b"bc"]));
        assert_ne!(key(&[b"", b"x"]), key(&[b"x", b""]));
        assert_eq!(key(&[b"ab", b"c"]), key(&[b"ab", b"c"]));
    }

    #[test]
    fn the_command_line_check_is_the_firmwares_buffer() {
        for file in [
            "firmware/src/platform/qemu/run.rs",
            "firmware/src/bin/qemu_stages.rs",
        ] {
            let text = std::fs::read_to_string(root().join(file)).unwrap();
            let declared = format!("const CMDLINE_BYTES: usize = {QEMU_CMDLINE_BYTES};");
            assert!(
                text.contains(&declared),
                "{file} does not declare {declared}"
            );
        }
        let elf = root().join("target/thumbv7em-none-eabihf/firmware/catmodel-qemu");
        let deep = "/a".repeat(100);
        // Paths inside the repository go relative; one outside stays absolute and is counted.
        let inside = qemu_path(&root().join("target/qemu/tx.log")).unwrap();
        assert_eq!(inside, "target/qemu/tx.log");
        let outside = qemu_path(Path::new(&format!("{deep}/drive.log"))).unwrap();
        assert!(outside.starts_with("/a/a"));
        assert!(qemu_append(&elf, &["catmodel-qemu".into(), "--in".into(), inside]).is_ok());
        let words = [
            "catmodel-qemu".into(),
            "--in".into(),
            outside.clone(),
            "--tx".into(),
            outside.clone(),
            "--ticks".into(),
            outside,
        ];
        let error = qemu_append(&elf, &words).unwrap_err().to_string();
        assert!(error.contains("more than the firmware's 512"), "{error}");
    }

    #[test]
    fn nearest_rank_statistics() {
        let values: Vec<u32> = (1..=100).rev().collect();
        assert_eq!(stats(&values), [1, 50, 99, 100]);
        assert_eq!(stats(&[7]), [7, 7, 7, 7]);
        assert_eq!(stats(&[3, 1, 2]), [1, 2, 3, 3]);
    }

    #[test]
    fn tick_records_round_trip_and_truncation_is_an_error() {
        let mut bytes = b"CMQT".to_vec();
        bytes.extend(4u32.to_le_bytes());
        bytes.extend(44u32.to_le_bytes());
        for field in [
            &1_000u64.to_le_bytes()[..],
            &2u64.to_le_bytes(),
            &3u32.to_le_bytes(),
        ] {
            bytes.extend(field);
        }
        bytes.extend(4u32.to_le_bytes());
        bytes.extend(5u16.to_le_bytes());
        bytes.extend(6u16.to_le_bytes());
        for v in [7u32, 8, 9, 1] {
            bytes.extend(v.to_le_bytes());
        }
        bytes.extend(b"END!");
        bytes.extend(1u64.to_le_bytes());
        for v in 10u32..22 {
            bytes.extend(v.to_le_bytes());
        }
        let (records, trailer) = parse_ticks(&bytes).unwrap();
        assert_eq!(records.len(), 1);
        let r = records[0];
        assert_eq!(
            (
                r.tick_us,
                r.slot,
                r.overruns,
                r.rx_queue_drops,
                r.rx_frames,
                r.tx_frames
            ),
            (1_000, 2, 3, 4, 5, 6)
        );
        assert_eq!((r.drain, r.step, r.tick), (7, 8, 9));
        assert!(r.controller());
        assert_eq!(
            (trailer.ticks, trailer.overruns, trailer.input_unsupported),
            (1, 10, 18)
        );
        assert_eq!((trailer.stack_high_water, trailer.stack_size), (19, 20));
        assert_eq!(trailer.node_boot_instructions, 21);
        assert!(parse_ticks(&bytes[..bytes.len() - 1]).is_err());
        assert!(parse_ticks(&bytes[..bytes.len() - 60]).is_err());
        let mut old = bytes.clone();
        old[4] = 1;
        assert!(parse_ticks(&old).is_err());
    }

    #[test]
    fn summary_line_names_drive_machine_verdict_and_budget() {
        assert_eq!(grouped(21_267), "21 267");
        assert_eq!(grouped(999), "999");
        assert_eq!(grouped(1_000_000), "1 000 000");
        let pass = Verdict {
            max_instructions: 21_267,
            ..Verdict::default()
        };
        let driving = Verdict {
            max_instructions: 21_267,
            max_control_instructions: Some(474_256),
            ..Verdict::default()
        };
        assert!(
            summary_line("s.log", &driving).contains(
                "slowest tick 21 267 instructions = 85 % of the 25 000 budget, slowest controller \
                 tick 474 256 = 79 % of the 600 000 budget, bound: not computed"
            ),
            "{}",
            summary_line("s.log", &driving)
        );
        let session = Verdict {
            max_instructions: 0,
            max_control_instructions: Some(438_248),
            ..Verdict::default()
        };
        assert!(
            summary_line("s.log", &session)
                .contains("PASS, every tick a controller tick, slowest controller tick 438 248"),
            "{}",
            summary_line("s.log", &session)
        );
        assert_eq!(
            summary_line("data/bundled.can.log", &pass),
            "cargo qemu: data/bundled.can.log on QEMU netduinoplus2 (STM32F405, Cortex-M4F): PASS, \
             slowest tick 21 267 instructions = 85 % of the 25 000 budget, bound: not computed"
        );
        let fail = Verdict {
            max_instructions: 31_000,
            bound_instructions: Some(45_000),
            control_bound_instructions: Some(500_000),
            max_control_instructions: None,
            failures: vec![
                "a tick took 31 000, over the budget".into(),
                "1 overruns".into(),
            ],
            waived: Vec::new(),
        };
        let line = summary_line("d.log", &fail);
        assert!(
            line.contains(": FAIL (a tick took 31 000, over the budget; 1 overruns), slowest tick 31 000 instructions = 124 % of the 25 000 budget, bound 45 000 instructions (controller ticks: 500 000)"),
            "{line}"
        );
        assert_eq!(line.lines().count(), 1);
    }

    #[test]
    fn candump_timestamps() {
        let text = "(1700000000.020000) can0 123#00\n\n(0000000001.000001) can0 1FFFFFFF#\n";
        assert_eq!(
            candump_times(text).unwrap(),
            vec![1_700_000_000_020_000, 1_000_001]
        );
        assert!(candump_times("can0 123#00").is_err());
    }
}
