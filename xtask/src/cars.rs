//! Model files drawn at random over the reader's ranges: cars no one has measured, for the
//! checks that must hold for any file the reader takes (the stage drives reach every stage the
//! bound counts, `drives::tests`; `cargo xtask random-cars --out DIR` writes them for
//! `CATMODEL_MODEL=FILE cargo qemu`).
//!
//! A draw starts from one of the repository's files (its identified models and comments) and
//! sets every key [`catmodel_model_file::KEY_RANGES`] lists, and the `[dynamics]` section,
//! somewhere in its range: the geometry consistent (overhangs from the body's length, the
//! antenna on the body or its mount, the centre of gravity on the wheelbase, the yaw inertia
//! and the cornering stiffnesses from the mass and size), the receiver's rate often a common
//! one, the speed model's input delay anywhere the delay line holds, the pure pursuit on some
//! cars and a lateral weight of their own on others. The reader decides: a draw
//! it refuses (an oversteering model unstable below the top speed, say) is drawn again, and
//! [`draw`] says how many were.
use std::path::Path;

use anyhow::{bail, Result};
use catmodel_model_file::{
    ModelFile, GNSS_RATE_RANGE_HZ, MPC_LATERAL_WEIGHT_RANGE, STEER_LAG_RANGE_S,
};

use crate::drives::Rng;

/// The files a draw starts from: their models, sections and comments.
const BASES: [&str; 3] = [
    "models/paper.toml",
    "models/hatchback.toml",
    "models/stress/dearest-found.toml",
];

/// The speed model's longest input delay the node's delay line holds, s (64 ticks).
const SPEED_DELAY_MAX_S: f64 = 1.28;

/// Receivers' common fix rates, Hz: half of the draws take one of these.
const COMMON_RATES_HZ: [f64; 7] = [1.0, 5.0, 10.0, 20.0, 25.0, 50.0, 100.0];

/// Standard gravity, m/s^2.
const G: f64 = 9.80665;

/// Log-uniform in [lo, hi].
fn log_range(rng: &mut Rng, lo: f64, hi: f64) -> f64 {
    (lo.ln() + (hi.ln() - lo.ln()) * rng.uniform()).exp()
}

/// `text` with `key` of `[section]` set to `value` (the line replaced, or added after the
/// section's header). The first header named `[section]` is the section.
fn set(text: &str, section: &str, key: &str, value: &str) -> String {
    set_under(text, &format!("[{section}]"), key, value)
}

/// [`set`] under the first header line `header` (`[[speed.blocks]]`: the first block).
fn set_under(text: &str, header: &str, key: &str, value: &str) -> String {
    let mut out = Vec::new();
    let mut inside = false;
    let mut done = false;
    let mut header_at = None;
    for line in text.lines() {
        let trimmed = line.trim_start();
        if trimmed.starts_with('[') {
            if inside && !done {
                // The key is not in the section: it goes after the header.
                if let Some(at) = header_at {
                    out.insert(at + 1, format!("{key} = {value}"));
                }
                done = true;
            }
            inside = !done && trimmed.trim_end() == header;
            if inside {
                header_at = Some(out.len());
            }
        } else if inside && !done {
            let name = trimmed.split('=').next().unwrap_or("").trim();
            if name == key && trimmed.contains('=') {
                out.push(format!("{key} = {value}"));
                done = true;
                continue;
            }
        }
        out.push(line.to_string());
    }
    if inside && !done {
        if let Some(at) = header_at {
            out.insert(at + 1, format!("{key} = {value}"));
        }
    }
    let mut s = out.join("\n");
    s.push('\n');
    s
}

/// One draw's text (not yet read).
fn draw_text(rng: &mut Rng, root: &Path) -> Result<String> {
    let base = BASES[rng.below(BASES.len() as u64) as usize];
    let mut t = std::fs::read_to_string(root.join(base))?;
    let put = |t: &mut String, section: &str, key: &str, value: f64| {
        *t = set(t, section, key, &format!("{value}"));
    };

    // Geometry: a wheelbase, overhangs from it, a body no longer than 25 m.
    let wheelbase = log_range(rng, 1.0, 10.0);
    let rear_overhang = rng.range(0.0, (0.6 * wheelbase).min(6.0));
    let front_overhang = rng.range(0.1, (0.6 * wheelbase).min(6.0));
    let length = (wheelbase + rear_overhang + front_overhang).min(25.0);
    let width = rng.range(0.8, 3.0);
    let track = rng.range(0.5, width.min(3.0));
    put(&mut t, "vehicle", "wheelbase_m", wheelbase);
    put(&mut t, "vehicle", "rear_overhang_m", rear_overhang);
    put(&mut t, "vehicle", "length_m", length);
    put(&mut t, "vehicle", "width_m", width);
    put(&mut t, "vehicle", "track_m", track);
    put(&mut t, "vehicle", "max_steer_deg", rng.range(10.0, 65.0));
    // The antenna anywhere on the body, its mount's reach past it included.
    let mount = catmodel_model_file::ANTENNA_MOUNT_M;
    let ahead = rng.range(-rear_overhang - mount, length - rear_overhang + mount);
    let left = rng.range(-0.5 * width - mount, 0.5 * width + mount);
    put(&mut t, "vehicle", "antenna_ahead_m", ahead);
    put(&mut t, "vehicle", "antenna_left_m", left);
    let rate = if rng.uniform() < 0.5 {
        COMMON_RATES_HZ[rng.below(COMMON_RATES_HZ.len() as u64) as usize]
    } else {
        log_range(rng, GNSS_RATE_RANGE_HZ.0, GNSS_RATE_RANGE_HZ.1)
    };
    put(&mut t, "vehicle", "gnss_rate_hz", rate);
    let max_speed = rng.range(5.0, 80.0);
    put(&mut t, "vehicle", "max_speed_mps", max_speed);
    put(
        &mut t,
        "vehicle",
        "max_steer_rate_pct_per_s",
        log_range(rng, 5.0, 500.0),
    );
    put(
        &mut t,
        "vehicle",
        "steer_lag_s",
        rng.range(STEER_LAG_RANGE_S.0, STEER_LAG_RANGE_S.1),
    );

    // The single-track model, from the mass and the size.
    let mass = log_range(rng, 200.0, 50_000.0);
    let gyration = rng.range(0.2, 0.45) * length;
    let front_share = rng.range(0.3, 0.7);
    let cg_front = front_share * wheelbase;
    let cg_rear = wheelbase - cg_front;
    let front_load = mass * G * cg_rear / wheelbase;
    let rear_load = mass * G * cg_front / wheelbase;
    put(&mut t, "dynamics", "mass_kg", mass);
    put(
        &mut t,
        "dynamics",
        "yaw_inertia_kg_m2",
        mass * gyration * gyration,
    );
    put(&mut t, "dynamics", "cg_to_front_m", cg_front);
    put(&mut t, "dynamics", "cg_to_rear_m", cg_rear);
    // Per unit of load: the rear's above the front's makes an understeering car (most cars; the
    // rest oversteer, which the reader takes if the model is stable to the top speed).
    let rear_per_load = rng.range(6.0, 20.0);
    let front_per_load = if rng.uniform() < 0.85 {
        rng.range(6.0, rear_per_load)
    } else {
        rng.range(6.0, 20.0)
    };
    let c_front = front_load * front_per_load;
    let c_rear = rear_load * rear_per_load;
    put(&mut t, "dynamics", "cornering_front_n_per_rad", c_front);
    put(&mut t, "dynamics", "cornering_rear_n_per_rad", c_rear);
    // The kinematic model's understeer is the same car's (the reader compares the two): eq 2's
    // K of the stiffnesses, within its range (an oversteering pair is stable to the top speed
    // or refused).
    let k =
        mass * (c_rear * cg_rear - c_front * cg_front) / (c_front * c_rear * wheelbase * wheelbase);
    put(
        &mut t,
        "vehicle",
        "understeer_s2_per_m2",
        k.clamp(0.0, 0.01),
    );

    // Inputs: timeouts, the gate, the outage bridged.
    for key in ["steer_timeout_s", "speed_timeout_s", "pedal_timeout_s"] {
        put(&mut t, "inputs", key, log_range(rng, 0.02, 2.0));
    }
    put(&mut t, "inputs", "gnss_gate_m", log_range(rng, 1.0, 100.0));
    // Longer than the GNSS timeout: 2.5 fix periods, 0.2 s at least (the reader's rule).
    let timeout_s = (2.5 / rate).max(0.2);
    put(
        &mut t,
        "inputs",
        "gnss_lost_s",
        log_range(rng, 1.01 * timeout_s, 30.0),
    );
    put(
        &mut t,
        "control",
        "position_uncertainty_m",
        rng.range(0.0, 20.0),
    );
    // The controller: the pure pursuit on a fifth of the cars (the MPC's stages are then
    // unreachable, `bound::unreachable`), a lateral weight of the car's own on a third.
    let controller = if rng.uniform() < 0.2 {
        "pure-pursuit"
    } else {
        "mpc"
    };
    t = set(&t, "control", "controller", &format!("\"{controller}\""));
    if rng.uniform() < 0.3 {
        put(
            &mut t,
            "control",
            "mpc_lateral_weight_per_m2",
            log_range(rng, MPC_LATERAL_WEIGHT_RANGE.0, MPC_LATERAL_WEIGHT_RANGE.1),
        );
    }

    // The hybrid switch: exit at or below enter.
    let enter_speed = log_range(rng, 1.0, 80.0);
    let enter_accel = log_range(rng, 0.1, 15.0);
    put(&mut t, "hybrid", "enter_dynamic_speed_mps", enter_speed);
    put(
        &mut t,
        "hybrid",
        "exit_dynamic_speed_mps",
        rng.range(1.0, enter_speed),
    );
    put(
        &mut t,
        "hybrid",
        "enter_dynamic_lat_accel_mps2",
        enter_accel,
    );
    put(
        &mut t,
        "hybrid",
        "exit_dynamic_lat_accel_mps2",
        rng.range(0.1, enter_accel),
    );
    t = set(
        &t,
        "hybrid",
        "min_dwell_ticks",
        &format!("{}", rng.below(501)),
    );

    // The speed model's input delay, whole ticks.
    let ticks = rng.below((SPEED_DELAY_MAX_S / catmodel::SAMPLE_PERIOD_S_F64) as u64 + 1);
    let delay_s = ticks as f64 * catmodel::SAMPLE_PERIOD_S_F64;
    Ok(set_under(
        &t,
        "[[speed.blocks]]",
        "delay_s",
        &format!("{delay_s:.2}"),
    ))
}

/// One model file the reader takes, drawn at random, its text, and how many draws the reader
/// refused before it.
pub fn draw(rng: &mut Rng, root: &Path) -> Result<(ModelFile, String, usize)> {
    let mut refused = 0;
    loop {
        let text = draw_text(rng, root)?;
        match catmodel_model_file::parse(&text, Path::new("random.toml")) {
            Ok(file) => return Ok((file, text, refused)),
            Err(_) => refused += 1,
        }
        if refused >= 200 {
            bail!("200 draws in a row refused by the reader: the draw is wrong");
        }
    }
}

/// `cargo xtask random-cars --out DIR [--count N] [--seed S] [--qemu]`: writes `N` model files
/// drawn at random (`DIR/car-K.toml`), each for `CATMODEL_MODEL=FILE cargo qemu`; with
/// `--qemu` it runs that for each (about 4 minutes a file), prints each file's two bounds and
/// their largest, and fails if one run fails (a tick or a bound over its budget, a stage no
/// drive reached).
pub fn random_cars(args: &[String]) -> Result<()> {
    let mut out = None;
    let mut count = 10usize;
    let mut seed = 1u64;
    let mut qemu = false;
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut value = || {
            it.next()
                .ok_or_else(|| anyhow::anyhow!("{a} needs a value"))
        };
        match a.as_str() {
            "--out" => out = Some(std::path::PathBuf::from(value()?)),
            "--count" => count = value()?.parse()?,
            "--seed" => seed = value()?.parse()?,
            "--qemu" => qemu = true,
            other => bail!("random-cars: unknown argument {other}"),
        }
    }
    let Some(out) = out else {
        bail!("usage: cargo xtask random-cars --out DIR [--count N] [--seed S]")
    };
    std::fs::create_dir_all(&out)?;
    let mut rng = Rng::new(seed);
    let root = crate::root();
    let mut refused = 0;
    for k in 0..count {
        let (_, text, r) = draw(&mut rng, &root)?;
        refused += r;
        let path = out.join(format!("car-{k}.toml"));
        let header = format!(
            "# Drawn at random over the reader's ranges: cargo xtask random-cars --seed {seed} (car {k})\n"
        );
        std::fs::write(&path, header + &text)?;
        println!("{}", path.display());
    }
    eprintln!("{count} model files written, {refused} draws refused by the reader on the way");
    if qemu {
        measure_each(&out, count)?;
    }
    Ok(())
}

/// `CATMODEL_MODEL=DIR/car-K.toml cargo qemu` for each file written, and the bounds.
fn measure_each(dir: &Path, count: usize) -> Result<()> {
    let root = crate::root();
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let mut failed = Vec::new();
    let mut largest = (0u64, 0u64);
    for k in 0..count {
        let path = std::fs::canonicalize(dir.join(format!("car-{k}.toml")))?;
        let status = std::process::Command::new(&cargo)
            .args(["xtask", "qemu"])
            .env("CATMODEL_MODEL", &path)
            .current_dir(&root)
            .stdout(std::process::Stdio::null())
            .status()?;
        if !status.success() {
            println!("car-{k}: cargo qemu FAILED ({})", path.display());
            failed.push(k);
            continue;
        }
        let timing: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(
            root.join("target/qemu/timing.json"),
        )?)?;
        let bound = |key: &str| timing.get(key).and_then(serde_json::Value::as_u64);
        let (Some(b), Some(c)) = (
            bound("worst_case_bound_instructions"),
            bound("worst_case_bound_controller_instructions"),
        ) else {
            bail!("target/qemu/timing.json after car-{k}: no bounds");
        };
        println!("car-{k}: bound {b}, controller bound {c}");
        largest = (largest.0.max(b), largest.1.max(c));
    }
    println!(
        "{} of {count} measured: largest bound {}, largest controller bound {}",
        count - failed.len(),
        largest.0,
        largest.1
    );
    if !failed.is_empty() {
        bail!("cargo qemu failed for cars {failed:?}");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_key_is_set_in_its_section_or_added_to_it() {
        let text = "a = 1\n[x]\nk = 1 # c\nm = 2\n[y]\nk = 3\n";
        for (section, key, value, want) in [
            ("x", "k", "5", "a = 1\n[x]\nk = 5\nm = 2\n[y]\nk = 3\n"),
            ("y", "k", "5", "a = 1\n[x]\nk = 1 # c\nm = 2\n[y]\nk = 5\n"),
            (
                "x",
                "n",
                "7",
                "a = 1\n[x]\nn = 7\nk = 1 # c\nm = 2\n[y]\nk = 3\n",
            ),
            (
                "y",
                "n",
                "7",
                "a = 1\n[x]\nk = 1 # c\nm = 2\n[y]\nn = 7\nk = 3\n",
            ),
        ] {
            assert_eq!(set(text, section, key, value), want, "{section}.{key}");
        }
    }

    /// The draws are files the reader takes, most at the first try, and they differ where it
    /// matters: the receiver's rate, the delay, the size.
    #[test]
    fn the_reader_takes_most_draws_and_they_spread_over_the_ranges() {
        let mut rng = Rng::new(7);
        let root = crate::root();
        let mut refused = 0;
        let mut rates = Vec::new();
        let mut lengths = Vec::new();
        for _ in 0..60 {
            let (file, _, r) = draw(&mut rng, &root).unwrap();
            refused += r;
            let car = file.node_config();
            rates.push(car.estimator.declared_gnss_rate_hz());
            lengths.push(f64::from(car.body.length_m));
        }
        assert!(refused < 60, "{refused} of {} draws refused", 60 + refused);
        let spread = |v: &[f64]| {
            let lo = v.iter().cloned().fold(f64::INFINITY, f64::min);
            let hi = v.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
            hi / lo
        };
        assert!(spread(&rates) > 20.0, "rates {rates:?}");
        assert!(spread(&lengths) > 4.0, "lengths {lengths:?}");
    }
}
