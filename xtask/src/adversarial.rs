//! `cargo xtask adversarial [--runs N] [--seed S]`: tries to break the tick's worst-case bound
//! in QEMU (docs/firmware.md, "Worst-case tick").
//!
//! It computes the bound ([`crate::bound::measure`]), then runs the QEMU firmware (the very
//! build `cargo qemu` runs) over drives made to maximise the node's work
//! ([`crate::drives`]): the dedicated drives of the stage measurement, targeted combinations
//! of every load and fault at once, then a search over drive parameters: `N` drives, the first
//! half random, the second half mutations of the heaviest drive found so far (a (1+1)
//! evolution strategy on the slowest tick). Every tick of every drive is measured; the command
//! fails if one exceeds the bound (or the bound exceeds the budget). On every drive whose
//! frames all fit the firmware's receive queue (no drops), host replay must also send
//! byte-identical frames (`cargo xtask tx-compare`): the per-tick cap and the frames it holds
//! back work the same in both. Drives go to `target/adversarial/NAME.log` (candump), a summary
//! to `target/adversarial/summary.json`.
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{anyhow, bail, Context, Result};
use catmodel::node::NodeConfig;
use catmodel_app::budget::{CONTROL_TICK_BUDGET_INSTRUCTIONS, TICK_BUDGET_INSTRUCTIONS};

use super::drives::{self, Periodic, Profile, Rng, Spec};
use super::{bound, cargo_build, root, run_qemu, txcompare};
use catmodel::can::spec::MAX_PATH_POINTS;

/// One drive's result.
struct Outcome {
    spec: Spec,
    ticks: usize,
    /// Slowest tick in which no controller planned (and no path completed).
    max_tick: u32,
    max_slot: u64,
    /// Slowest controller tick, if any.
    max_control_tick: Option<u32>,
    rx_queue_drops: u32,
    overruns: u32,
    /// Frames compared with host replay (drives without receive-queue drops).
    replay_frames: Option<usize>,
}

/// Every load and fault at once, and the heaviest combinations of two.
fn targeted(car: &NodeConfig) -> Vec<Spec> {
    let top = f64::from(car.max_speed_mps) + 5.0;
    let enter = f64::from(car.hybrid.enter_dynamic_speed_mps);
    let exit = f64::from(car.hybrid.exit_dynamic_speed_mps);
    let dwell_s = f64::from(car.hybrid.min_dwell_ticks) * catmodel::SAMPLE_PERIOD_S_F64;
    let mut specs = drives::stage_corpus(car);
    for spec in &mut specs {
        spec.name = spec.name.replacen("stages-", "corpus-", 1);
    }
    specs.push(Spec {
        seconds: 10.0,
        speed: Profile::Square {
            lo: (exit - 1.0).max(0.5),
            hi: top,
            period_s: 2.0 * dwell_s + 0.04,
        },
        steer: Profile::Square {
            lo: -100.0,
            hi: 100.0,
            period_s: 0.3,
        },
        // As fast as the node still takes the receiver (faster is `gnss_rate_mismatch`).
        gnss_hz: drives::TAKEN_FASTER * car.estimator.declared_gnss_rate_hz(),
        cog_hz: 200.0,
        gnss_dropout: Some(Periodic {
            first_s: 2.0,
            every_s: 0.53,
            len_s: 0.07,
        }),
        gnss_jump: Some(Periodic {
            first_s: 5.0,
            every_s: 3.0,
            len_s: 0.8,
        }),
        gnss_jump_m: 30.0,
        burst: Some(Periodic {
            first_s: 1.0,
            every_s: 0.31,
            len_s: 0.06,
        }),
        corrupt_per_tick: 8,
        unknown_per_tick: 30,
        path_points: MAX_PATH_POINTS,
        ..Spec::plain("everything-at-once")
    });
    // Bursts the cap holds back and the receive queue still holds: QEMU and host replay must
    // hand the same frames to the same ticks.
    specs.push(Spec {
        burst: Some(Periodic {
            first_s: 1.0,
            every_s: 0.9,
            len_s: 0.05,
        }),
        ..Spec::plain("bursts-held-back")
    });
    specs.push(Spec {
        speed: Profile::Sine {
            mean: enter,
            amp: enter,
            period_s: 1.7,
        },
        steer: Profile::Sine {
            mean: 0.0,
            amp: 100.0,
            period_s: 0.9,
        },
        gnss_hz: 150.0,
        cog_hz: 150.0,
        corrupt_per_tick: 12,
        burst: Some(Periodic {
            first_s: 0.5,
            every_s: 0.2,
            len_s: 0.08,
        }),
        ..Spec::plain("floods-in-bursts")
    });
    specs
}

/// A random drive.
fn random(rng: &mut Rng, car: &NodeConfig, name: String) -> Spec {
    let top = f64::from(car.max_speed_mps) + 10.0;
    let profile = |rng: &mut Rng, lo: f64, hi: f64| match rng.below(4) {
        0 => Profile::Const(rng.range(lo, hi)),
        1 => Profile::Sine {
            mean: rng.range(lo, hi),
            amp: rng.range(0.0, hi - lo),
            period_s: rng.range(0.2, 6.0),
        },
        2 => Profile::Square {
            lo: rng.range(lo, hi),
            hi: rng.range(lo, hi),
            period_s: rng.range(0.1, 3.0),
        },
        _ => Profile::Ramp {
            from: rng.range(lo, hi),
            to: rng.range(lo, hi),
            seconds: rng.range(0.5, 8.0),
        },
    };
    let window = |rng: &mut Rng, len_max: f64| {
        (rng.below(2) == 0).then(|| Periodic {
            first_s: rng.range(0.5, 4.0),
            every_s: rng.range(0.1, 4.0),
            len_s: rng.range(0.005, len_max),
        })
    };
    let rates = [1.0, 5.0, 10.0, 20.0, 50.0, 100.0, 130.0, 150.0, 200.0];
    let cog_rates = [0.0, 1.0, 10.0, 50.0, 100.0, 200.0];
    Spec {
        name,
        seed: rng.next_u64(),
        seconds: rng.range(5.0, 9.0),
        origin_deg: (rng.range(-79.0, 79.0), rng.range(-180.0, 179.99)),
        speed: profile(rng, 0.0, top),
        steer: profile(rng, -130.0, 130.0),
        gnss_hz: rates[rng.below(rates.len() as u64) as usize],
        cog_hz: cog_rates[rng.below(cog_rates.len() as u64) as usize],
        gnss_noise_m: rng.range(0.0, 3.0),
        // Not drawn: `stages-cog-scattered` scatters them for every car, and the search's
        // draws stay those of the figures it found.
        cog_noise_rad: 0.0,
        gnss_dropout: window(rng, 1.5),
        gnss_gap_exact: rng.below(2) == 0,
        gnss_jump: window(rng, 2.0),
        gnss_jump_m: rng.range(2.0, 80.0),
        gnss_jump_back_s: [0.0, 0.0, 2.0, 6.0][rng.below(4) as usize],
        burst: window(rng, 0.25),
        corrupt_per_tick: rng.below(16) as u32,
        unknown_per_tick: rng.below(60) as u32,
        path_points: [0, 0, 2, 5, 40, 256][rng.below(6) as usize],
        path_spacing_m: [1.0, 0.5, 0.08][rng.below(3) as usize],
        path_once: rng.below(2) == 0,
        obstacles: rng.below(5) as usize,
        obstacles_at_centre: rng.below(2) == 0,
        // Not drawn: `stages-path-far` places them so for every car, and the search's draws
        // stay those of the figures it found.
        obstacles_far_m: 0.0,
        heading_rad: 0.3,
        obstacles_moving_mps: [0.0, 1.5, 30.0][rng.below(3) as usize],
        corridor_widening_m: [0.0, 0.002, -0.002][rng.below(3) as usize],
        path_offset_m: 0.0,
    }
}

/// `spec` with one or two of its parameters drawn again.
fn mutate(rng: &mut Rng, car: &NodeConfig, spec: &Spec, name: String) -> Spec {
    let fresh = random(rng, car, name.clone());
    let mut out = Spec {
        name,
        seed: rng.next_u64(),
        ..spec.clone()
    };
    for _ in 0..1 + rng.below(2) {
        match rng.below(10) {
            0 => out.speed = fresh.speed,
            1 => out.steer = fresh.steer,
            2 => out.gnss_hz = fresh.gnss_hz,
            3 => out.cog_hz = fresh.cog_hz,
            4 => {
                out.gnss_dropout = fresh.gnss_dropout;
                out.gnss_gap_exact = fresh.gnss_gap_exact;
            }
            5 => {
                out.gnss_jump = fresh.gnss_jump;
                out.gnss_jump_m = fresh.gnss_jump_m;
                out.gnss_jump_back_s = fresh.gnss_jump_back_s;
            }
            6 => out.burst = fresh.burst,
            7 => out.corrupt_per_tick = fresh.corrupt_per_tick,
            8 => {
                out.path_points = fresh.path_points;
                out.path_spacing_m = fresh.path_spacing_m;
                out.path_once = fresh.path_once;
                out.obstacles = fresh.obstacles;
                out.obstacles_at_centre = fresh.obstacles_at_centre;
                out.obstacles_moving_mps = fresh.obstacles_moving_mps;
                out.corridor_widening_m = fresh.corridor_widening_m;
            }
            _ => out.unknown_per_tick = fresh.unknown_per_tick,
        }
    }
    out
}

/// Runs one drive in QEMU (and, without receive-queue drops, host replay beside it).
fn run(elf: &Path, host: &Path, car: &NodeConfig, spec: Spec) -> Result<Outcome> {
    let dir = root().join("target").join("adversarial");
    let path = dir.join(format!("{}.log", spec.name));
    drives::write_candump(&path, &drives::generate(&spec, car))?;
    // Each drive its own output directory: drives run side by side (`main`).
    let out = dir.join("run").join(&spec.name);
    let run = run_qemu(elf, &out, Some(&path), &[])?;
    let replay_frames = if run.trailer.rx_queue_drops == 0 {
        let replay_tx = out.join("replay-tx.log");
        let status = Command::new(host)
            .arg("replay")
            .arg(&path)
            .arg("--out")
            .arg(out.join("replay-pred.csv"))
            .arg("--tx-out")
            .arg(&replay_tx)
            .output()
            .context("running catmodel replay")?;
        if !status.status.success() {
            bail!(
                "catmodel replay failed on {}: {}",
                path.display(),
                String::from_utf8_lossy(&status.stderr)
            );
        }
        let compared = txcompare::compare_files(&out.join("tx.log"), &replay_tx)
            .with_context(|| format!("QEMU and host replay differ on {}", path.display()))?;
        Some(compared.frames)
    } else {
        None
    };
    let (max_slot, max_tick) = run
        .records
        .iter()
        .filter(|r| !r.controller())
        .map(|r| (r.slot, r.tick))
        .max_by_key(|(_, tick)| *tick)
        .unwrap_or((0, 0));
    let max_control_tick = run
        .records
        .iter()
        .filter(|r| r.controller())
        .map(|r| r.tick)
        .max();
    Ok(Outcome {
        spec,
        ticks: run.records.len(),
        max_tick,
        max_slot,
        max_control_tick,
        rx_queue_drops: run.trailer.rx_queue_drops,
        overruns: run.trailer.overruns,
        replay_frames,
    })
}

pub fn adversarial(args: &[String]) -> Result<()> {
    let mut runs = 16usize;
    let mut seed = 1u64;
    let mut it = args.iter();
    while let Some(arg) = it.next() {
        match (arg.as_str(), it.next()) {
            ("--runs", Some(n)) => runs = n.parse()?,
            ("--seed", Some(n)) => seed = n.parse()?,
            _ => bail!("usage: cargo xtask adversarial [--runs N] [--seed S]"),
        }
    }
    let bound = bound::measure()?;
    print!("{}", bound.table());
    let total = bound.total();
    let car = bound::baked_car()?;
    let elf = cargo_build("qemu", "catmodel-qemu")?;
    let host = bound::host_binary()?;
    let mut rng = Rng::new(seed);
    // The targeted drives two at a time: a QEMU run and its host replay take one core each.
    let mut outcomes: Vec<Outcome> = Vec::new();
    let mut specs = targeted(&car).into_iter();
    loop {
        let pair: Vec<Spec> = specs.by_ref().take(2).collect();
        if pair.is_empty() {
            break;
        }
        let done: Vec<Result<Outcome>> = std::thread::scope(|s| {
            let handles: Vec<_> = pair
                .into_iter()
                .map(|spec| {
                    let (elf, host, car) = (&elf, &host, &car);
                    s.spawn(move || run(elf, host, car, spec))
                })
                .collect();
            handles
                .into_iter()
                .map(|h| {
                    h.join()
                        .unwrap_or_else(|_| Err(anyhow!("a drive's thread panicked")))
                })
                .collect()
        });
        for outcome in done {
            outcomes.push(outcome?);
        }
    }
    let mut best: Option<Spec> = None;
    let mut best_tick = 0;
    for i in 0..runs {
        let name = format!("search-{seed}-{i:02}");
        let spec = match (&best, i < runs / 2) {
            (Some(b), false) => mutate(&mut rng, &car, b, name),
            _ => random(&mut rng, &car, name),
        };
        let outcome = run(&elf, &host, &car, spec)?;
        if outcome.max_tick > best_tick {
            best_tick = outcome.max_tick;
            best = Some(outcome.spec.clone());
        }
        outcomes.push(outcome);
    }

    outcomes.sort_by_key(|o| std::cmp::Reverse(o.max_tick));
    println!(
        "\n{:<34}{:>7}{:>10}{:>9}{:>8}{:>12}{:>10}  QEMU == replay",
        "drive", "ticks", "max tick", "of bound", "slot", "max ctl tick", "rx drops"
    );
    for o in &outcomes {
        println!(
            "{:<34}{:>7}{:>10}{:>8.1}%{:>8}{:>12}{:>10}  {}",
            o.spec.name,
            o.ticks,
            o.max_tick,
            f64::from(o.max_tick) / total as f64 * 100.0,
            o.max_slot,
            o.max_control_tick
                .map_or_else(|| "-".to_string(), |t| t.to_string()),
            o.rx_queue_drops,
            match o.replay_frames {
                Some(n) => format!("{n} frames identical"),
                None => "not compared (queue drops)".to_string(),
            }
        );
    }
    let worst = outcomes.first().map_or(0, |o| o.max_tick);
    println!(
        "{} drives, {} ticks: slowest tick {worst} instructions = {:.1} % of the bound {total} (budget {TICK_BUDGET_INSTRUCTIONS})",
        outcomes.len(),
        outcomes.iter().map(|o| o.ticks).sum::<usize>(),
        f64::from(worst) / total as f64 * 100.0
    );
    let summary = serde_json::json!({
        "worst_case_bound_instructions": total,
        "budget_instructions": TICK_BUDGET_INSTRUCTIONS,
        "seed": seed,
        "drives": outcomes.iter().map(|o| serde_json::json!({
            "name": o.spec.name,
            "spec": format!("{:?}", o.spec),
            "ticks": o.ticks,
            "max_tick_instructions": o.max_tick,
            "max_tick_slot": o.max_slot,
            "max_controller_tick_instructions": o.max_control_tick,
            "rx_queue_drops": o.rx_queue_drops,
            "overruns": o.overruns,
            "replay_identical_frames": o.replay_frames,
        })).collect::<Vec<_>>(),
    });
    let path: PathBuf = root()
        .join("target")
        .join("adversarial")
        .join("summary.json");
    std::fs::write(&path, serde_json::to_string_pretty(&summary)? + "\n")?;
    println!("wrote target/adversarial/summary.json and the drives (candump) beside it");
    if let Some(o) = outcomes.iter().find(|o| u64::from(o.max_tick) > total) {
        bail!(
            "drive {} had a tick of {} instructions, over the worst-case bound of {total}: the bound is wrong (target/adversarial/{}.log reproduces it)",
            o.spec.name,
            o.max_tick,
            o.spec.name
        );
    }
    let total_control = bound.total_control();
    if let Some(o) = outcomes.iter().find(|o| {
        o.max_control_tick
            .is_some_and(|t| u64::from(t) > total_control)
    }) {
        bail!(
            "drive {} had a controller tick of {:?} instructions, over the controller's worst-case bound of {total_control}: the bound is wrong (target/adversarial/{}.log reproduces it)",
            o.spec.name,
            o.max_control_tick,
            o.spec.name
        );
    }
    if total_control > u64::from(CONTROL_TICK_BUDGET_INSTRUCTIONS) {
        bail!("the controller's worst-case bound {total_control} exceeds its budget {CONTROL_TICK_BUDGET_INSTRUCTIONS}");
    }
    if let Some(o) = outcomes.iter().find(|o| o.overruns > 0) {
        bail!("drive {} overran its 20 ms slots", o.spec.name);
    }
    if total > u64::from(TICK_BUDGET_INSTRUCTIONS) {
        bail!("the worst-case bound {total} exceeds the budget {TICK_BUDGET_INSTRUCTIONS}");
    }
    Ok(())
}
