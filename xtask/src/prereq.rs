//! What the firmware commands need before they build: the `thumbv7em-none-eabihf` standard
//! library (rustup installs a target listed in rust-toolchain.toml only together with the
//! toolchain, so a machine that already had Rust 1.95.0 lacks it and the build fails with
//! "can't find crate for `core`"), and `qemu-system-arm` for the QEMU runs. Checked first, so
//! a missing piece is said (and installed where that is safe) before minutes of building.
use std::path::PathBuf;
use std::process::Command;

use anyhow::{bail, Context, Result};

use super::TARGET;

/// Debian's package and the command that installs it.
const QEMU_PACKAGE: &str = "qemu-system-arm";

/// What to do about one prerequisite.
#[derive(Clone, Debug, PartialEq, Eq)]
enum Action {
    /// It is there.
    Ready,
    /// Say `why`, then run `commands` in order.
    Install {
        why: String,
        commands: Vec<Vec<String>>,
    },
    /// Cannot be fixed from here: stop with this message (it holds the exact command).
    Stop(String),
}

fn words(text: &str) -> Vec<String> {
    text.split_whitespace().map(str::to_string).collect()
}

/// The target: installed, or added with rustup, or the command to run.
fn target_action(installed: bool, rustup: bool) -> Action {
    if installed {
        Action::Ready
    } else if rustup {
        Action::Install {
            why: format!("the {TARGET} target (the MCU's standard library) is missing; adding it"),
            commands: vec![words(&format!("rustup target add {TARGET}"))],
        }
    } else {
        Action::Stop(format!(
            "the {TARGET} target (the MCU's standard library) is missing and rustup is not \
             installed; install rustup (https://rustup.rs), then run:\n    rustup target add {TARGET}"
        ))
    }
}

/// QEMU: found, or installed with apt-get as root, or the command to run.
fn qemu_action(found: bool, root: bool, apt: bool) -> Action {
    if found {
        Action::Ready
    } else if root && apt {
        Action::Install {
            why: format!("{QEMU_PACKAGE} is missing; installing it with apt-get"),
            commands: vec![
                words("apt-get update -qq"),
                words(&format!("apt-get install -y -qq {QEMU_PACKAGE}")),
            ],
        }
    } else if apt {
        Action::Stop(format!(
            "{QEMU_PACKAGE} is missing; install it with:\n    sudo apt-get update && sudo apt-get install -y {QEMU_PACKAGE}"
        ))
    } else {
        Action::Stop(format!(
            "{QEMU_PACKAGE} is missing; install QEMU's Arm system emulator (7.2 or later) with your \
             package manager (Debian, Ubuntu: apt-get install {QEMU_PACKAGE})"
        ))
    }
}

/// Carries out `action`; `check` says afterwards whether it worked.
fn apply(action: Action, check: impl Fn() -> bool, what: &str) -> Result<()> {
    match action {
        Action::Ready => Ok(()),
        Action::Stop(message) => bail!("{message}"),
        Action::Install { why, commands } => {
            eprintln!("xtask: {why}");
            for command in &commands {
                eprintln!("xtask: running `{}`", command.join(" "));
                let status = Command::new(&command[0])
                    .args(&command[1..])
                    .env("DEBIAN_FRONTEND", "noninteractive")
                    .status()
                    .with_context(|| format!("running {}", command[0]))?;
                if !status.success() {
                    bail!("`{}` failed ({status})", command.join(" "));
                }
            }
            if !check() {
                bail!("{what} is still missing after installing it");
            }
            Ok(())
        }
    }
}

fn runs(program: &str, args: &[&str]) -> bool {
    Command::new(program)
        .args(args)
        .output()
        .is_ok_and(|o| o.status.success())
}

/// The sysroot of the toolchain cargo builds with (rust-toolchain.toml's, via rustup).
fn sysroot() -> Result<PathBuf> {
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".into());
    let out = Command::new(&rustc)
        .current_dir(super::root())
        .args(["--print", "sysroot"])
        .output()
        .with_context(|| format!("running {rustc} --print sysroot"))?;
    Ok(PathBuf::from(String::from_utf8_lossy(&out.stdout).trim()))
}

/// Whether the toolchain has the target's standard library (what `rustup target list
/// --installed` lists, read from the sysroot so that it works without rustup too).
fn target_installed() -> bool {
    sysroot().is_ok_and(|s| {
        s.join("lib")
            .join("rustlib")
            .join(TARGET)
            .join("lib")
            .is_dir()
    })
}

/// The MCU target is installed (adding it with rustup if needed).
pub fn ensure_target() -> Result<()> {
    let action = target_action(target_installed(), runs("rustup", &["--version"]));
    apply(action, target_installed, TARGET)
}

fn qemu_found() -> bool {
    runs(QEMU_PACKAGE, &["--version"])
}

/// `qemu-system-arm` is installed (with apt-get when run as root).
pub fn ensure_qemu() -> Result<()> {
    let root = Command::new("id")
        .arg("-u")
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0");
    let action = qemu_action(qemu_found(), root, runs("apt-get", &["--version"]));
    apply(action, qemu_found, QEMU_PACKAGE)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_target_is_added_with_rustup_or_the_command_is_given() {
        assert_eq!(target_action(true, false), Action::Ready);
        let Action::Install { commands, .. } = target_action(false, true) else {
            panic!("rustup present: expected an install");
        };
        assert_eq!(
            commands,
            vec![words("rustup target add thumbv7em-none-eabihf")]
        );
        let Action::Stop(message) = target_action(false, false) else {
            panic!("no rustup: expected a stop");
        };
        assert!(
            message.ends_with("rustup target add thumbv7em-none-eabihf"),
            "{message}"
        );
    }

    #[test]
    fn qemu_is_installed_as_root_or_the_command_is_given() {
        assert_eq!(qemu_action(true, false, false), Action::Ready);
        let Action::Install { commands, .. } = qemu_action(false, true, true) else {
            panic!("root with apt: expected an install");
        };
        assert_eq!(commands[1], words("apt-get install -y -qq qemu-system-arm"));
        let Action::Stop(message) = qemu_action(false, false, true) else {
            panic!("not root: expected a stop");
        };
        assert!(
            message.contains("sudo apt-get update && sudo apt-get install -y qemu-system-arm"),
            "{message}"
        );
        assert!(matches!(qemu_action(false, true, false), Action::Stop(_)));
    }

    /// The sysroot check agrees with rustup's own list.
    #[test]
    fn the_sysroot_check_agrees_with_rustup() {
        let Ok(out) = Command::new("rustup")
            .current_dir(super::super::root())
            .args(["target", "list", "--installed"])
            .output()
        else {
            return; // no rustup: nothing to compare with
        };
        let listed = String::from_utf8_lossy(&out.stdout)
            .lines()
            .any(|l| l.trim() == TARGET);
        assert_eq!(target_installed(), listed);
    }
}
