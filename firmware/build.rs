//! Puts `memory.x` on the linker's search path for the embedded target (cortex-m-rt's `link.x`
//! includes it), and, for the QEMU firmware, provides the drive it replays by default:
//! `data/bundled.can.log`, or a small synthetic placeholder while that file does not exist.
//!
//! Every build also bakes the car into the crate (`OUT_DIR/baked.rs`, included by `baked`): the
//! model file `models/paper.toml` by default, or the file named by the environment variable
//! `CATMODEL_MODEL` (e.g. one `catmodel identify` wrote; absolute, or relative to the
//! repository root; `cargo qemu` makes a path relative to its own directory absolute first). It is read with the host's reader, discretized
//! and designed in f64 on the host, and written as the node's configuration image (f32 words):
//! `catmodel replay --model` builds the same configuration from the same file, so the firmware
//! and the replay run identical numbers.
use std::{env, fs, path::PathBuf};

const BUNDLED: &str = "../data/bundled.can.log";

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    bake_model();
    println!("cargo:rerun-if-changed=../memory.x");
    // Watch the drive, or the folder it will appear in (a path that does not exist would
    // re-run this script on every build).
    if std::path::Path::new(BUNDLED).exists() {
        println!("cargo:rerun-if-changed={BUNDLED}");
    } else if std::path::Path::new("../data").exists() {
        println!("cargo:rerun-if-changed=../data");
    }
    if env::var("CARGO_CFG_TARGET_OS").as_deref() != Ok("none") {
        return;
    }
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    refuse_the_hosts_profile(&out);
    fs::copy("../memory.x", out.join("memory.x")).expect("memory.x is at the repository root");
    println!("cargo:rustc-link-search={}", out.display());

    if env::var_os("CARGO_FEATURE_QEMU").is_some() {
        let drive = fs::read(BUNDLED).unwrap_or_else(|_| placeholder_drive().into_bytes());
        fs::write(out.join("bundled.can.log"), drive).expect("OUT_DIR is writable");
    }
}

/// The MCU's firmware is built with `--profile firmware` (fat LTO, one codegen unit: the profile
/// its instruction counts and flash and RAM budgets are measured with). `--release` is the host's
/// profile, without LTO; a board image built with it would differ from the one measured, so
/// the build stops and says what to type. The profile is the directory cargo builds in:
/// `OUT_DIR` is `<target dir>/<triple>/<profile>/build/<package>-<hash>/out`.
fn refuse_the_hosts_profile(out: &std::path::Path) {
    let profile = out.ancestors().nth(3).and_then(|p| p.file_name());
    if profile.and_then(|p| p.to_str()) == Some("release") {
        let message = "catmodel-firmware: build the MCU's firmware with `--profile firmware` \
                       (fat LTO, the profile its budgets are measured with), not `--release` \
                       (the host's profile): e.g. cargo build --profile firmware -p \
                       catmodel-firmware --features board --bin catmodel-board --target \
                       thumbv7em-none-eabihf";
        eprintln!("{message}");
        println!("cargo:warning={message}");
        std::process::exit(1);
    }
}

/// 10 s of the node's input IDs at their bus rates (standard 0x100-0x102 at 50 Hz, NMEA 2000
/// PGN 129025 at 10 Hz), with zero payloads and a little arrival jitter. It exercises the
/// replay and the tick timing, not the models.
fn placeholder_drive() -> String {
    let mut text = String::new();
    let start_us: u64 = 1_700_000_000_003_000;
    for k in 0..500u64 {
        let t = start_us + k * 20_000;
        for (i, id) in ["100", "101", "102"].iter().enumerate() {
            let t_us = t + i as u64 * 250 + (k * 37) % 400;
            text.push_str(&format!(
                "({}.{:06}) can0 {}#0000000000000000\n",
                t_us / 1_000_000,
                t_us % 1_000_000,
                id
            ));
        }
        if k % 5 == 0 {
            let t_us = t + 5_000;
            text.push_str(&format!(
                "({}.{:06}) can0 09F80100#0000000000000000\n",
                t_us / 1_000_000,
                t_us % 1_000_000
            ));
        }
    }
    text
}

/// Model file -> `OUT_DIR/baked.rs`: read and checked by the host's own reader
/// (`catmodel-model-file`), so a file `catmodel replay --model` refuses stops this build with
/// the same message, and one it accepts is baked as the very configuration replay runs.
fn bake_model() {
    println!("cargo:rerun-if-env-changed=CATMODEL_MODEL");
    let (path, shown) = match env::var("CATMODEL_MODEL") {
        // A relative path is taken from the repository root, where cargo is run.
        Ok(p) => (PathBuf::from("..").join(&p), p),
        Err(_) => (
            PathBuf::from("../models/paper.toml"),
            "models/paper.toml".to_owned(),
        ),
    };
    println!("cargo:rerun-if-changed={}", path.display());
    let file = match catmodel_model_file::load(&path) {
        Ok(file) => file,
        Err(e) => {
            // The reader's message, exactly as `catmodel replay --model` prints it.
            eprintln!("catmodel-model-file: error: {shown}: {}", e.message);
            println!(
                "cargo:warning=catmodel-model-file: error: {shown}: {}",
                e.message
            );
            std::process::exit(1);
        }
    };
    let code = catmodel_model_file::bake::rust_source(&file, &shown);
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    fs::write(out.join("baked.rs"), code).expect("OUT_DIR is writable");
}
