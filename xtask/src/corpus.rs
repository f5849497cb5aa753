//! `cargo xtask model-corpus`: the two readers of a model file refuse the same files with the
//! same message. For every file of `models/bad/`, the firmware build
//! (`CATMODEL_MODEL=FILE cargo build -p catmodel-firmware --features qemu ...`: its build
//! script reads the file) must fail, `catmodel replay --model FILE` must fail, both must print
//! the same message, and it must contain the text the file's `# expect:` line names. Every
//! file of `models/good/` must build.
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{bail, Context, Result};

use crate::{root, TARGET};

/// The message after `prefix` and the file's path in `output` (one line).
fn message_after(output: &str, prefix: &str, path: &Path) -> Option<String> {
    let head = format!("{prefix}{}: ", path.display());
    output
        .lines()
        .find_map(|l| l.trim_start().strip_prefix(&head))
        .map(str::to_owned)
}

fn firmware_build(model: &Path) -> Result<(bool, String)> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Command::new(cargo)
        .current_dir(root())
        .env("CATMODEL_MODEL", model)
        .args([
            "build",
            "--profile",
            crate::FIRMWARE_PROFILE,
            "-p",
            "catmodel-firmware",
            "--features",
            "qemu",
        ])
        .args(["--bin", "catmodel-qemu", "--target", TARGET])
        .output()
        .context("running cargo build")?;
    Ok((
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    ))
}

fn replay(model: &Path) -> Result<(bool, String)> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Command::new(cargo)
        .current_dir(root())
        .args(["run", "--quiet", "--release", "-p", "catmodel-host", "--"])
        .args([
            "replay",
            "data/bundled.can.log",
            "--out",
            "/dev/null",
            "--model",
        ])
        .arg(model)
        .output()
        .context("running catmodel replay")?;
    Ok((
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    ))
}

fn toml_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("reading {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    Ok(files)
}

pub fn model_corpus() -> Result<()> {
    let bad = toml_files(&root().join("models/bad"))?;
    let good = toml_files(&root().join("models/good"))?;
    let mut failures = Vec::new();
    for path in &bad {
        let text = std::fs::read_to_string(path)?;
        let expect = text
            .lines()
            .next()
            .and_then(|l| l.strip_prefix("# expect: "))
            .with_context(|| format!("{}: no `# expect:` first line", path.display()))?;
        let (built, build_err) = firmware_build(path)?;
        let (replayed, replay_err) = replay(path)?;
        let from_build = message_after(&build_err, "catmodel-model-file: error: ", path);
        let from_replay = message_after(&replay_err, "catmodel: error: ", path);
        let name = path
            .file_name()
            .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
        match (built, replayed, &from_build, &from_replay) {
            (false, false, Some(b), Some(r)) if b == r && b.contains(expect) => {
                println!("ok   {name}: {b}");
            }
            _ => {
                println!(
                    "FAIL {name}: firmware build {} ({from_build:?}), replay {} ({from_replay:?}), expected {expect:?}",
                    if built { "succeeded" } else { "failed" },
                    if replayed { "succeeded" } else { "failed" },
                );
                failures.push(name);
            }
        }
    }
    for path in &good {
        let name = path
            .file_name()
            .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
        let (built, err) = firmware_build(path)?;
        let (replayed, _) = replay(path)?;
        if built && replayed {
            println!("ok   {name}: accepted by both");
        } else {
            println!("FAIL {name}: a good file was refused:\n{err}");
            failures.push(name);
        }
    }
    // Leave the build as the default model for whatever runs next.
    let _ = firmware_build(&root().join("models/paper.toml"));
    if !failures.is_empty() {
        bail!(
            "model corpus: {} file(s) not handled identically: {failures:?}",
            failures.len()
        );
    }
    println!(
        "model corpus: {} bad files refused by the firmware build and by replay with the same message, {} good files accepted by both",
        bad.len(),
        good.len()
    );
    Ok(())
}
