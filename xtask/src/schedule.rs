//! `cargo xtask tick-schedule`: one tick schedule on every platform, whatever time a drive
//! starts at. The bundled drive is moved to start at 0, on a tick boundary, just after one,
//! just before one and at an epoch time; on each, the QEMU firmware's frames must equal host
//! replay's (`catmodel replay --tx-out`), timestamps included (the firmware-only stack field
//! aside, as `tx-compare`). The host-side property test is `host-tests/tests/app_loops.rs`.
//! The epoch drive is also written as `candump -t A -N -x` prints it (a date, nanoseconds,
//! `RX - -`, the screen format), and the firmware's frames on it must be the same bytes.
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
    recorder_notation(&elf, &dir, &bundled)?;
    flooded(&elf, &dir, &bundled)?;
    println!(
        "tick schedule: QEMU and host replay tick at the same times on drives starting at {STARTS_US:?} us, \
         alike on the epoch drive in candump's screen format with dates and nanoseconds, and on a \
         bus whose receive queue overflows"
    );
    Ok(())
}

/// The epoch drive as `candump -t A -N -x can0 > FILE` prints it (a date, nanoseconds, `RX -
/// -`, the screen format): host replay's frames must be the log format's, byte for byte, and the
/// QEMU firmware's the same (but the stack field, as `tx-compare`).
fn recorder_notation(elf: &Path, dir: &Path, bundled: &str) -> Result<()> {
    let start = STARTS_US[4];
    let mut screen = String::new();
    for line in shifted(bundled, start)?.lines() {
        let frame = parse_line(line).map_err(|e| anyhow::anyhow!("{line}: {e:?}"))?;
        let id = match frame.frame.id {
            catmodel::can::CanId::Standard(id) => format!("{id:>8X}"),
            catmodel::can::CanId::Extended(id) => format!("{id:08X}"),
        };
        let bytes: Vec<String> = frame
            .frame
            .payload()
            .iter()
            .map(|b| format!("{b:02X}"))
            .collect();
        screen.push_str(&format!(
            " ({}.{:06}123)  can0  RX - -  {id}   [{}]  {}\n",
            utc_date(frame.t_us / 1_000_000),
            frame.t_us % 1_000_000,
            bytes.len(),
            bytes.join(" ")
        ));
    }
    let drive = dir.join("start-epoch-dated.can.log");
    std::fs::write(&drive, screen)?;
    let out = dir.join("qemu-epoch-dated");
    run_qemu(elf, &out, Some(&drive), &[])?;
    let host_tx = dir.join("replay-epoch-dated.tx.log");
    replay(&drive, &host_tx)?;
    // Host replay: the same bytes as on the log format; the firmware: the same frames but the
    // stack field it measures.
    let plain_tx = dir.join(format!("replay-{start}.tx.log"));
    if std::fs::read(&host_tx)? != std::fs::read(&plain_tx)? {
        bail!(
            "{}: host replay's frames differ from the same drive's in the log format",
            drive.display()
        );
    }
    print!("start {start:>16} us, `candump -t A -N -x`: ");
    txcompare::tx_compare(&[
        out.join("tx.log").display().to_string(),
        plain_tx.display().to_string(),
    ])?;
    Ok(())
}

/// The bundled drive on a bus with four more GNSS receivers (source addresses 0x1D, 0x00, 0x01
/// and 0x02, each repeating every position: the acceptance filter admits a position of any
/// source), about 14 frames a tick to the node's 12: the receive queue overflows and drops
/// frames. Host replay must drop the same frames as the firmware (it held every frame back
/// before, never dropping one, and its frames then differed from the firmware's).
fn flooded(elf: &Path, dir: &Path, bundled: &str) -> Result<()> {
    let mut text = String::new();
    for line in bundled.lines().filter(|l| !l.trim().is_empty()) {
        let frame = parse_line(line).map_err(|e| anyhow::anyhow!("{line}: {e:?}"))?;
        format_line(&frame, "can0", &mut text).map_err(|e| anyhow::anyhow!("{e:?}"))?;
        text.push('\n');
        if let catmodel::can::CanId::Extended(id) = frame.frame.id {
            if id & 0x00FF_FF00 == 0x00F8_0100 {
                for source in [0x1D, 0x00, 0x01, 0x02] {
                    let mut other = frame;
                    other.frame.id = catmodel::can::CanId::Extended((id & !0xFF) | source);
                    format_line(&other, "can0", &mut text).map_err(|e| anyhow::anyhow!("{e:?}"))?;
                    text.push('\n');
                }
            }
        }
    }
    let drive = dir.join("flooded.can.log");
    std::fs::write(&drive, text)?;
    let out = dir.join("qemu-flooded");
    // (`cargo qemu` calls a run with drops a FAIL; here its frames are what is compared.)
    run_qemu(elf, &out, Some(&drive), &[])?;
    let host_tx = dir.join("replay-flooded.tx.log");
    replay(&drive, &host_tx)?;
    print!("flooded bus: ");
    txcompare::tx_compare(&[
        out.join("tx.log").display().to_string(),
        host_tx.display().to_string(),
    ])?;
    let drops = page3_drops(&host_tx)?;
    if drops == 0 {
        bail!("{}: the receive queue never overflowed", drive.display());
    }
    println!("flooded bus: {drops} frames dropped by the receive queue, on both");
    Ok(())
}

/// The last NODE_STATUS page 3 `rx_queue_drops` of a candump of the node's frames.
fn page3_drops(tx: &Path) -> Result<u32> {
    use catmodel::can::NodeStatus;
    let mut drops = 0;
    for line in std::fs::read_to_string(tx)?.lines() {
        let frame = parse_line(line).map_err(|e| anyhow::anyhow!("{line}: {e:?}"))?;
        if let Ok((NodeStatus::Platform { rx_queue_drops, .. }, _)) =
            NodeStatus::decode(&frame.frame)
        {
            drops = rx_queue_drops;
        }
    }
    Ok(drops)
}

/// `strftime("%Y-%m-%d %H:%M:%S")` of `secs` since 1970, UTC.
fn utc_date(secs: u64) -> String {
    let leap = |y: u64| y.is_multiple_of(4) && (!y.is_multiple_of(100) || y.is_multiple_of(400));
    let (mut days, in_day) = (secs / 86_400, secs % 86_400);
    let mut year = 1970;
    while days >= 365 + u64::from(leap(year)) {
        days -= 365 + u64::from(leap(year));
        year += 1;
    }
    let mut month = 1;
    for len in [
        31,
        28 + u64::from(leap(year)),
        31,
        30,
        31,
        30,
        31,
        31,
        30,
        31,
        30,
        31,
    ] {
        if days < len {
            break;
        }
        days -= len;
        month += 1;
    }
    format!(
        "{year}-{month:02}-{:02} {:02}:{:02}:{:02}",
        days + 1,
        in_day / 3600,
        in_day / 60 % 60,
        in_day % 60
    )
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

#[cfg(test)]
mod tests {
    /// Dates against Python's `time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime(SECS))`.
    #[test]
    fn utc_dates() {
        for (secs, date) in [
            (0, "1970-01-01 00:00:00"),
            (951_782_400, "2000-02-29 00:00:00"),
            (1_700_000_000, "2023-11-14 22:13:20"),
            (1_735_689_599, "2024-12-31 23:59:59"),
            (4_107_542_400, "2100-03-01 00:00:00"),
        ] {
            assert_eq!(super::utc_date(secs), date);
        }
    }
}
