//! `cargo xtask tick-schedule`: one tick schedule on every platform, whatever time a drive
//! starts at. The bundled drive is moved to start at 0, on a tick boundary, just after one,
//! just before one and at an epoch time; on each, the QEMU firmware's frames must equal host
//! replay's (`catmodel replay --tx-out`), timestamps included (the firmware-only stack field
//! aside, as `tx-compare`). The host-side property test is `host-tests/tests/app_loops.rs`.
use std::path::Path;
use std::process::Command;

use anyhow::{bail, Context, Result};
use catmodel::can::candump::{format_line, parse_line};

use crate::{cargo_build, root, run_qemu, txcompare};

/// The starts checked, us: 0, a boundary, just after and just before one, an epoch time.
const STARTS_US: [u64; 5] = [0, 40_000, 40_001, 39_999, 1_700_000_000_000_000];

/// `input` with every timestamp moved so that the first is `start_us`.
fn shifted(input: &str, start_us: u64) -> Result<String> {
    let mut out = String::new();
    let mut first = None;
    for (i, line) in input.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let frame = parse_line(line)
            .map_err(|e| anyhow::anyhow!("bundled drive, line {}: {e:?}", i + 1))?;
        let t0 = *first.get_or_insert(frame.t_us);
        let mut moved = frame;
        moved.t_us = frame.t_us - t0 + start_us;
        format_line(&moved, "can0", &mut out).map_err(|e| anyhow::anyhow!("{e:?}"))?;
        out.push('\n');
    }
    Ok(out)
}

pub fn tick_schedule() -> Result<()> {
    let elf = cargo_build("qemu", "catmodel-qemu")?;
    let dir = root().join("target/tick-schedule");
    std::fs::create_dir_all(&dir)?;
    let bundled = std::fs::read_to_string(root().join("data/bundled.can.log"))?;
    for start in STARTS_US {
        let drive = dir.join(format!("start-{start}.can.log"));
        std::fs::write(&drive, shifted(&bundled, start)?)?;
        let out = dir.join(format!("qemu-{start}"));
        run_qemu(&elf, &out, Some(&drive), &[])?;
        let host_tx = dir.join(format!("replay-{start}.tx.log"));
        replay(&drive, &host_tx)?;
        let firmware_tx = out.join("tx.log");
        let args = [
            firmware_tx.display().to_string(),
            host_tx.display().to_string(),
        ];
        print!("start {start:>16} us: ");
        txcompare::tx_compare(&args)?;
        let first_line = std::fs::read_to_string(&firmware_tx)?
            .lines()
            .next()
            .map(str::to_owned)
            .unwrap_or_default();
        let first_tick = catmodel::node::first_tick_us(start);
        let stamp = format!(
            "({:010}.{:06})",
            first_tick / 1_000_000,
            first_tick % 1_000_000
        );
        if !first_line.starts_with(&stamp) {
            bail!("start {start}: the first tick is {first_line:?}, expected it at {stamp}");
        }
    }
    println!(
        "tick schedule: QEMU and host replay tick at the same times on drives starting at {STARTS_US:?} us"
    );
    Ok(())
}

fn replay(drive: &Path, tx: &Path) -> Result<()> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let status = Command::new(cargo)
        .current_dir(root())
        .args([
            "run",
            "--quiet",
            "--release",
            "-p",
            "catmodel-host",
            "--",
            "replay",
        ])
        .arg(drive)
        .args(["--out", "/dev/null", "--tx-out"])
        .arg(tx)
        .status()
        .context("running catmodel replay")?;
    if !status.success() {
        bail!("catmodel replay {} failed", drive.display());
    }
    Ok(())
}
