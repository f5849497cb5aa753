//! `cargo xtask tick-schedule-drives`: one tick schedule on every platform, whatever the first
//! timestamp (docs/architecture.md, "Tick schedule"). The bundled drive is re-stamped so that
//! its first frame falls at 0 (`(0000000000.000000)`), on a tick boundary, just after one, and
//! at epoch times (on a boundary and just after); for each, the QEMU firmware and host replay
//! must send byte-identical frames (but the stack field, [`super::txcompare`]), and the first
//! tick must be the first boundary at or after the first frame.
use std::fmt::Write as _;
use std::path::Path;
use std::process::Command;

use anyhow::{bail, Context, Result};
use catmodel::can::candump::{format_line, parse_line};
use catmodel::node::first_tick_us;

use super::{cargo_build, root, run_qemu, txcompare};

/// First-frame times of the drives, us: 0, a boundary, just after one, just before one, an
/// epoch time on a boundary (2023-11-14 22:13:20 UTC) and just after it.
const FIRST_FRAME_US: [u64; 6] = [
    0,
    20_000,
    20_001,
    39_999,
    1_700_000_000_000_000,
    1_700_000_000_000_001,
];

/// The candump `text` with every timestamp moved so that the first frame is at `first_us`.
fn restamp(text: &str, first_us: u64) -> Result<String> {
    let mut out = String::with_capacity(text.len() + 16 * 1024);
    let mut shift: Option<(u64, u64)> = None;
    for (i, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let mut frame = parse_line(line).map_err(|e| anyhow::anyhow!("line {}: {e:?}", i + 1))?;
        let (t0, to) = *shift.get_or_insert((frame.t_us, first_us));
        frame.t_us = frame.t_us - t0 + to;
        format_line(&frame, "can0", &mut out).map_err(|_| anyhow::anyhow!("formatting"))?;
        out.push('\n');
    }
    Ok(out)
}

/// The first timestamp of a candump file, us.
fn first_stamp(path: &Path) -> Result<u64> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let line = text.lines().next().context("empty output")?;
    Ok(parse_line(line)
        .map_err(|e| anyhow::anyhow!("{}: {e:?}", path.display()))?
        .t_us)
}

pub fn tick_schedule_drives() -> Result<()> {
    let source = std::fs::read_to_string(root().join("data").join("bundled.can.log"))
        .context("reading data/bundled.can.log")?;
    let elf = cargo_build("qemu", "catmodel-qemu")?;
    let dir = root().join("target").join("tick-schedule");
    std::fs::create_dir_all(&dir)?;
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let mut report = String::new();
    for first in FIRST_FRAME_US {
        let drive = dir.join(format!("first-{first}.can.log"));
        std::fs::write(&drive, restamp(&source, first)?)?;
        let qemu_dir = dir.join(format!("qemu-{first}"));
        run_qemu(&elf, &qemu_dir, Some(&drive), &[])?;
        let host_tx = dir.join(format!("replay-{first}.tx.log"));
        let status = Command::new(&cargo)
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
            .arg(&drive)
            .arg("--out")
            .arg(dir.join(format!("replay-{first}.csv")))
            .arg("--tx-out")
            .arg(&host_tx)
            .status()
            .context("running catmodel replay")?;
        if !status.success() {
            bail!("catmodel replay failed on {}", drive.display());
        }
        let firmware_tx = qemu_dir.join("tx.log");
        let compared = txcompare::compare_files(&firmware_tx, &host_tx)
            .with_context(|| format!("first frame at {first} us"))?;
        let expected = first_tick_us(first);
        for (who, path) in [("QEMU", &firmware_tx), ("replay", &host_tx)] {
            let got = first_stamp(path)?;
            if got != expected {
                bail!("first frame at {first} us: {who}'s first tick at {got} us, expected {expected} us");
            }
        }
        let _ = writeln!(
            report,
            "first frame {first:>16} us: first tick {expected:>16} us on both, {} frames identical",
            compared.frames
        );
    }
    print!("{report}");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn restamping_keeps_the_gaps_and_moves_the_first_frame() {
        let text = "(0000000005.000700) can0 100#01\n(0000000005.020700) can0 101#02\n\n";
        let out = restamp(text, 0).unwrap();
        assert_eq!(
            out,
            "(0000000000.000000) can0 100#01\n(0000000000.020000) can0 101#02\n"
        );
        let out = restamp(text, 1_700_000_000_000_001).unwrap();
        assert!(out.starts_with("(1700000000.000001) can0 100#01\n(1700000000.020001) can0"));
    }
}
