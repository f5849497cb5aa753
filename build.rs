//! Puts `memory.x` on the linker's search path for the embedded target (cortex-m-rt's `link.x`
//! includes it), and, for the QEMU firmware, provides the drive it replays by default:
//! `data/bundled.can.log`, or a small synthetic placeholder while that file does not exist.
//!
//! Every build also bakes a model file into the crate as constants (`OUT_DIR/baked_model.rs`,
//! included by `node::baked`): `models/paper.toml` by default, or the file named by the
//! environment variable `CATMODEL_MODEL` (e.g. one `catmodel identify` wrote). The numbers are
//! written exactly (shortest round-trip literals); `catmodel replay --model` reads the same file
//! the same way, so the firmware and the replay run identical models.
use std::{env, fs, path::PathBuf};

const BUNDLED: &str = "data/bundled.can.log";

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    bake_model();
    println!("cargo:rerun-if-changed=memory.x");
    // Watch the drive, or the folder it will appear in (a path that does not exist would
    // re-run this script on every build).
    if std::path::Path::new(BUNDLED).exists() {
        println!("cargo:rerun-if-changed={BUNDLED}");
    } else if std::path::Path::new("data").exists() {
        println!("cargo:rerun-if-changed=data");
    }
    if env::var("CARGO_CFG_TARGET_OS").as_deref() != Ok("none") {
        return;
    }
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    fs::copy("memory.x", out.join("memory.x")).expect("memory.x is at the package root");
    println!("cargo:rustc-link-search={}", out.display());

    if env::var_os("CARGO_FEATURE_QEMU").is_some() {
        let drive = fs::read(BUNDLED).unwrap_or_else(|_| placeholder_drive().into_bytes());
        fs::write(out.join("bundled.can.log"), drive).expect("OUT_DIR is writable");
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

/// Model file -> `OUT_DIR/baked_model.rs`. A malformed file stops the build with the reason.
fn bake_model() {
    println!("cargo:rerun-if-env-changed=CATMODEL_MODEL");
    let path = env::var("CATMODEL_MODEL").unwrap_or_else(|_| "models/paper.toml".to_owned());
    println!("cargo:rerun-if-changed={path}");
    let text = fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("CATMODEL_MODEL: cannot read {path}: {e}"));
    let doc: toml::Table = text
        .parse()
        .unwrap_or_else(|e| panic!("{path}: not TOML: {e}"));
    let get = |keys: &[&str]| -> &toml::Value {
        let mut v = doc.get(keys[0]);
        for k in &keys[1..] {
            v = v.and_then(|t| t.get(*k));
        }
        v.unwrap_or_else(|| panic!("{path}: missing {}", keys.join(".")))
    };
    let num = |v: &toml::Value, what: &str| -> f64 {
        v.as_float()
            .or_else(|| v.as_integer().map(|i| i as f64))
            .unwrap_or_else(|| panic!("{path}: {what} is not a number"))
    };
    let f = |keys: &[&str]| num(get(keys), &keys.join("."));
    let coeffs = |v: &toml::Value, what: &str| -> String {
        let a = v
            .as_array()
            .unwrap_or_else(|| panic!("{path}: {what} is not an array"));
        let items: Vec<String> = a.iter().map(|x| format!("{:?}", num(x, what))).collect();
        format!("&[{}]", items.join(", "))
    };
    let blocks = |model: &str| -> Vec<String> {
        get(&[model, "blocks"])
            .as_array()
            .unwrap_or_else(|| panic!("{path}: {model}.blocks is not an array"))
            .iter()
            .map(|b| {
                let field = |k: &str| {
                    b.get(k)
                        .unwrap_or_else(|| panic!("{path}: a {model} block lacks {k}"))
                };
                format!(
                    "TransferFunction::new({}, {}, {:?})?",
                    coeffs(field("num"), "num"),
                    coeffs(field("den"), "den"),
                    num(field("delay_s"), "delay_s")
                )
            })
            .collect()
    };
    let speed = blocks("speed");
    let dxdt = blocks("dx_dt");
    assert!(
        speed.len() == 1,
        "{path}: the node runs a single-input speed model"
    );
    assert!(
        dxdt.len() == 4,
        "{path}: the node runs dx/dt with 4 inputs [v_m, x, y, phi]"
    );
    // As `catmodel_host::node_config`: a lateral section's steering gain scales the angle at
    // 100 % and its understeer term replaces the vehicle's.
    let (gain, understeer) = match doc.get("lateral") {
        Some(_) => (
            f(&["lateral", "steer_gain"]),
            f(&["lateral", "understeer_s2_per_m2"]),
        ),
        None => (1.0, f(&["vehicle", "understeer_s2_per_m2"])),
    };
    let max_steer_rad = if doc.get("lateral").is_some() {
        (f(&["vehicle", "max_steer_deg"]).to_radians() * gain) as f32
    } else {
        f(&["vehicle", "max_steer_deg"]).to_radians() as f32
    };
    let dwell = get(&["hybrid", "min_dwell_ticks"])
        .as_integer()
        .unwrap_or_else(|| panic!("{path}: hybrid.min_dwell_ticks is not an integer"));
    let code = format!(
        "// Generated by build.rs from {path}. Do not edit.\n\
         /// The models baked into this build (`{path}`).\n\
         pub fn baked_models() -> Result<NodeModels, ModelError> {{\n\
         Ok(NodeModels {{\n\
         vehicle: VehicleParams {{ wheelbase_m: {:?}, track_m: {:?}, max_steer_rad: {:?}, understeer_s2_per_m2: {:?} }},\n\
         hybrid: HybridConfig {{ enter_dynamic_speed_mps: {:?}, enter_dynamic_lat_accel_mps2: {:?}, exit_dynamic_speed_mps: {:?}, exit_dynamic_lat_accel_mps2: {:?}, min_dwell_ticks: {} }},\n\
         velocity: {},\n\
         dxdt: [{}],\n\
         ts_s: {:?},\n\
         }})\n}}\n\
         /// The model file this build baked.\n\
         pub const BAKED_MODEL_PATH: &str = {:?};\n",
        f(&["vehicle", "wheelbase_m"]) as f32,
        f(&["vehicle", "track_m"]) as f32,
        max_steer_rad,
        understeer as f32,
        f(&["hybrid", "enter_dynamic_speed_mps"]) as f32,
        f(&["hybrid", "enter_dynamic_lat_accel_mps2"]) as f32,
        f(&["hybrid", "exit_dynamic_speed_mps"]) as f32,
        f(&["hybrid", "exit_dynamic_lat_accel_mps2"]) as f32,
        dwell,
        speed[0],
        dxdt.join(", "),
        f(&["sample_time_s"]),
        path,
    );
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    fs::write(out.join("baked_model.rs"), code).expect("OUT_DIR is writable");
}
