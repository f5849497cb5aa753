//! Puts `memory.x` on the linker's search path for the embedded target (cortex-m-rt's `link.x`
//! includes it). Host builds are untouched.
use std::{env, fs, path::PathBuf};

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed=memory.x");
    if env::var("CARGO_CFG_TARGET_OS").as_deref() != Ok("none") {
        return;
    }
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    fs::copy("memory.x", out.join("memory.x")).expect("memory.x is at the package root");
    println!("cargo:rustc-link-search={}", out.display());
}
