//! `cargo xtask no-panic`: the link-time proof that the core has no panic path.
//!
//! Builds `firmware/src/bin/nopanic.rs` (profile `firmware`, fat LTO, thumbv7em-none-eabihf: the
//! one we ship), whose panic handler calls a symbol that does not exist. It links only if no
//! panic entry is reachable from `baked::node` (`NodeConfig::from_image`, `Node::new`) and
//! `Node::step` on inputs the optimiser cannot see. On failure it rebuilds with a harmless handler and lists the call sites of the panic
//! entries with their source lines (needs `llvm-objdump`; `apt-get install -y llvm`).
use std::path::PathBuf;
use std::process::Command;

use anyhow::{bail, Context, Result};

use crate::{root, TARGET};

const BIN: &str = "catmodel-nopanic";
/// The undefined symbol the check's panic handler calls (firmware/src/bin/nopanic.rs).
const MARKER: &str = "catmodel_core_can_panic";
/// Functions a panic goes through; a call to any of them from elsewhere is a panic site.
const PANIC_ENTRIES: [&str; 7] = [
    "core::panicking::",
    "core::slice::index::",
    "core::cell::panic_",
    "core::result::unwrap_failed",
    "core::option::unwrap_failed",
    "core::option::expect_failed",
    "rust_begin_unwind",
];

/// Builds the check program; `locate` swaps in a handler that links, to find the sites.
/// Returns the ELF path and, if the link failed, the linker's complaint.
fn build(locate: bool) -> Result<(PathBuf, Option<String>)> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    // Only cortex-m-rt's linker script: defmt's keeps its default panic entry alive whether
    // anything calls it or not (see firmware/src/bin/nopanic.rs). Its own target dir, so that these
    // flags do not invalidate the firmware builds'.
    let mut rustflags = String::from("-C link-arg=-Tlink.x -C target-cpu=cortex-m4");
    if locate {
        rustflags.push_str(" --cfg catmodel_nopanic_locate");
    }
    let target_dir = root().join("target").join("nopanic");
    let output = Command::new(cargo)
        .current_dir(root())
        .env("RUSTFLAGS", rustflags)
        .args([
            "build",
            "--profile",
            crate::FIRMWARE_PROFILE,
            "-p",
            "catmodel-firmware",
            "--features",
            "nopanic-check",
        ])
        .args(["--bin", BIN, "--target", TARGET, "--target-dir"])
        .arg(&target_dir)
        .output()
        .context("running cargo build")?;
    let elf = target_dir
        .join(TARGET)
        .join(crate::FIRMWARE_PROFILE)
        .join(BIN);
    if output.status.success() {
        return Ok((elf, None));
    }
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    if stderr.contains(MARKER) {
        Ok((elf, Some(stderr)))
    } else {
        bail!("building {BIN} failed:\n{stderr}")
    }
}

/// A call into a panic entry from outside the panic machinery, with the source lines
/// `llvm-objdump -l` printed just before it (innermost inlined frame last).
#[derive(Debug, PartialEq)]
struct Site {
    function: String,
    callee: String,
    lines: Vec<String>,
}

fn is_panic_entry(name: &str) -> bool {
    PANIC_ENTRIES.iter().any(|p| name.contains(p))
}

/// Parses `llvm-objdump -d -l -C --no-show-raw-insn` output.
fn panic_sites(disassembly: &str) -> Vec<Site> {
    let mut sites = Vec::new();
    let mut function = String::new();
    let mut lines: Vec<String> = Vec::new();
    for line in disassembly.lines() {
        if let Some((_, name)) = line.strip_suffix(">:").and_then(|l| l.split_once(" <")) {
            // `$t` / `$d` are ARM mapping symbols (code / data starts), not functions.
            if !name.starts_with('$') {
                function = name.to_string();
            }
            lines.clear();
        } else if let Some(source) = line.strip_prefix("; ") {
            if source.contains(".rs:") {
                lines.push(source.to_string());
                if lines.len() > 4 {
                    lines.remove(0);
                }
            }
        } else if let Some((_, target)) = line.split_once(" <") {
            let is_branch = ["\tbl\t", "\tb\t", "\tb.w\t"]
                .iter()
                .any(|op| line.contains(op));
            let callee = target.split(['>', '+']).next().unwrap_or_default();
            if is_branch && is_panic_entry(callee) && !is_panic_entry(&function) {
                sites.push(Site {
                    function: function.clone(),
                    callee: callee.to_string(),
                    lines: lines.clone(),
                });
            }
        }
    }
    sites
}

pub fn no_panic() -> Result<()> {
    let (elf, failure) = build(false)?;
    let Some(linker) = failure else {
        println!(
            "no-panic: {} linked with an undefined panic handler: no panic path from \
             baked::node / Node::new / Node::step (profile firmware, LTO, {TARGET})",
            elf.display()
        );
        return Ok(());
    };
    eprintln!("no-panic: the core can panic: {BIN} references `{MARKER}`.");
    eprintln!(
        "{}",
        linker
            .lines()
            .filter(|l| l.contains(">>>"))
            .collect::<Vec<_>>()
            .join("\n")
    );
    let (elf, _) = build(true)?;
    match Command::new("llvm-objdump")
        .args(["-d", "-l", "-C", "--no-show-raw-insn"])
        .arg(&elf)
        .output()
    {
        Ok(out) if out.status.success() => {
            let sites = panic_sites(&String::from_utf8_lossy(&out.stdout));
            eprintln!("panic call sites ({}):", sites.len());
            for site in &sites {
                eprintln!("  in {} -> {}", site.function, site.callee);
                for l in &site.lines {
                    eprintln!("       {l}");
                }
            }
        }
        _ => eprintln!("(install llvm-objdump to list the sites: apt-get install -y llvm)"),
    }
    bail!("a panic path is reachable from the node")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_calls_into_panic_entries_but_not_inside_them() {
        let dis = "\
08000460 <catmodel::node::Node::step>:
; src/node/mod.rs:400
 8000462:      \tvadd.f32\ts0, s0, s2
; src/node/mod.rs:404
 8000466:      \tbl\t0x8008ff8 <core::panicking::panic_bounds_check> @ imm = #1
 800046a:      \tbl\t0x8008000 <catmodel::model::step> @ imm = #1

08008ff8 <core::panicking::panic_bounds_check>:
 8008ffc:      \tbl\t0x8008fe8 <core::panicking::panic_fmt> @ imm = #-24
";
        let sites = panic_sites(dis);
        assert_eq!(
            sites,
            vec![Site {
                function: "catmodel::node::Node::step".into(),
                callee: "core::panicking::panic_bounds_check".into(),
                lines: vec!["src/node/mod.rs:400".into(), "src/node/mod.rs:404".into()],
            }]
        );
    }
}
