//! `cargo xtask bench-target [--check]`: instructions per call of each node component on QEMU.
//!
//! Builds `catmodel-qemu-bench` (profile `firmware`: opt-level 3, fat LTO,
//! thumbv7em-none-eabihf), runs it on `-M netduinoplus2` under `-icount shift=0` (TIM2 counts
//! one per instruction, as in `cargo qemu`), and prints a markdown table (docs/firmware.md, "Per
//! component"). The firmware prints one tab-separated line per component: `bench KEY NAME CALLS
//! MIN MEDIAN MAX WHAT`.
//! `--check` fails if a component's max exceeds its budget in [`BUDGETS`], or the tick's
//! worst-case bound ([`bound`], printed after the table) exceeds the tick budget.
use std::fmt::Write as _;

use anyhow::{anyhow, bail, Result};

use catmodel_app::budget::{CONTROL_TICK_BUDGET_INSTRUCTIONS, TICK_BUDGET_INSTRUCTIONS};

use super::{bound, cargo_build, qemu_stderr_cached, root};

/// Max instructions per call allowed by `--check`: about 1.5x what was measured (README,
/// "Instructions per component on the target"), so a regression, not noise, trips it (QEMU
/// counts are exact and repeatable).
const BUDGETS: &[(&str, u32)] = &[
    ("gnss_fir", 160),
    ("moving_average", 80),
    ("velocity_eq5", 80),
    ("dxdt_eq7", 200),
    ("kinematic_eq8", 130),
    ("kinematic_eq2_eq8", 240),
    ("kinematic_textbook", 250),
    // 97 before the model's input was the wheel angle's tangent (a `math::tan` per call, 203).
    ("dynamic_step", 300),
    ("rollout_kinematic", 7_100),
    ("rollout_dynamic", 10_000),
    ("decode_steering", 280),
    ("decode_speed", 330),
    ("decode_pedal", 340),
    ("decode_gnss_position", 160),
    ("decode_gnss_cog_sog", 270),
    ("encode_state_position", 510),
    ("encode_state_motion", 680),
    ("encode_prediction", 830),
    ("encode_node_status", 1_050),
    ("encode_tick_set", 8_000),
    ("tick_running", TICK_BUDGET_INSTRUCTIONS),
    ("tick_all", TICK_BUDGET_INSTRUCTIONS),
    // The controller (catmodel-qemu-mpc-bench, docs/mpc.md): its whole budget is 450 000 per
    // solve; the worst case measures 418 724. The lateral problem's part grew from 61 530 to
    // 67 423 when a moving obstacle's row came to keep the body clear of the segment between
    // where it would have braked and where it goes on (`lateral::obstacle_row`).
    ("mpc_dlc", 450_000),
    ("mpc_obstacle", 450_000),
    ("mpc_blocked", 450_000),
    ("mpc_worst_dynamic", 450_000),
    ("mpc_worst_kinematic", 450_000),
    ("mpc_worst_standing", 450_000),
    // 68 078 before the dynamic stages linearised the wheel angle's tangent (a tangent per
    // stage: 69 916).
    ("mpc_part_build", 75_000),
    ("mpc_part_factor", 37_000),
    ("mpc_part_iteration", 21_000),
    ("mpc_part_iteration_checked", 28_000),
    ("mpc_part_speed", 60_000),
    // A whole solve's end in the fallback beyond the roll-out of a plan: the braking speed
    // plan, the lane's steering ramp or the workspace forgotten (bound.rs adds it to the solve).
    ("mpc_part_fallback_end", 15_000),
    ("tinympc_solve", u32::MAX),
    ("tinympc_cache", u32::MAX),
];

/// The benchmark firmwares: the node's components, and the controller (with TinyMPC on the
/// same model for comparison).
const BENCHES: &[(&str, &str)] = &[("qemu", "catmodel-qemu-bench"), MPC_BENCH];

/// The controller's benchmark firmware (features, binary): its worst-case solve is also a row
/// of the tick's bound (`bound::measure`).
pub const MPC_BENCH: (&str, &str) = ("qemu,tinympc", "catmodel-qemu-mpc-bench");

/// One component's line.
pub struct Row {
    /// Component key.
    pub key: String,
    name: String,
    calls: u32,
    min: u32,
    median: u32,
    /// Most instructions of one call.
    pub max: u32,
    what: String,
}

/// Builds benchmark firmware `bin` with `features` and runs it in QEMU; returns what it printed
/// on stderr (its rows).
pub fn run_bench(features: &str, bin: &str) -> Result<String> {
    let elf = cargo_build(features, bin)?;
    qemu_stderr_cached(&elf, bin, &[])
}

/// The rows and the timing overhead printed by a benchmark firmware.
pub fn parse(stderr: &str) -> Result<(Vec<Row>, u32)> {
    let mut rows = Vec::new();
    let mut overhead = None;
    let mut done = false;
    for line in stderr.lines() {
        let fields: Vec<&str> = line.split('\t').collect();
        match fields.as_slice() {
            ["bench", key, name, calls, min, median, max, what] => rows.push(Row {
                key: key.to_string(),
                name: name.to_string(),
                calls: calls.parse()?,
                min: min.parse()?,
                median: median.parse()?,
                max: max.parse()?,
                what: what.to_string(),
            }),
            ["bench-overhead", n] => overhead = Some(n.parse()?),
            ["bench-done"] => done = true,
            _ => {}
        }
    }
    if !done {
        bail!("the benchmark firmware did not finish:\n{stderr}");
    }
    let overhead = overhead.ok_or_else(|| anyhow!("no bench-overhead line"))?;
    Ok((rows, overhead))
}

pub fn bench_target(args: &[String]) -> Result<()> {
    let check = match args {
        [] => false,
        [flag] if flag == "--check" => true,
        _ => bail!("usage: cargo xtask bench-target [--check]"),
    };
    let mut rows = Vec::new();
    let mut overhead = 0;
    for &(features, bin) in BENCHES {
        let stderr = run_bench(features, bin)?;
        let (more, n) = parse(&stderr)?;
        rows.extend(more);
        overhead = n;
        for line in stderr.lines().filter(|l| l.starts_with("mpc-info\t")) {
            println!("{}", line.replace('\t', ": "));
        }
    }

    let mut table = String::new();
    let _ = writeln!(
        table,
        "| component | what one call does | calls | min | median | max |"
    );
    let _ = writeln!(table, "|---|---|---:|---:|---:|---:|");
    for r in &rows {
        let _ = writeln!(
            table,
            "| {} | {} | {} | {} | {} | {} |",
            r.name, r.what, r.calls, r.min, r.median, r.max
        );
    }
    let _ = writeln!(
        table,
        "\nInstructions per call (QEMU -icount shift=0, TIM2; not Cortex-M4 cycles), \
         profile firmware (opt-level 3, fat LTO), timing overhead of {overhead} instructions \
         subtracted."
    );
    // The tick's worst case from its structure and each stage's maximum (docs/firmware.md,
    // "Worst-case tick"), measured by the same firmware in its `--stages` mode.
    let mut bound = bound::measure_stages()?;
    let (worst, which) = bound::worst_solve(&rows, MPC_BENCH.1)?;
    bound.compose_solve(worst, &which);
    let _ = writeln!(
        table,
        "\nWorst case per tick (`worst_case_bound_instructions`), {} instructions; with a controller planning (`worst_case_bound_controller_instructions`), {}:\n\n{}",
        bound.total(),
        bound.total_control(),
        bound.markdown()
    );
    print!("{table}");
    print!("{}", bound.table());
    let out_dir = root().join("target").join("qemu");
    std::fs::create_dir_all(&out_dir)?;
    std::fs::write(out_dir.join("bench-target.md"), &table)?;
    println!("wrote target/qemu/bench-target.md");

    if check {
        let mut over = Vec::new();
        for r in &rows {
            match BUDGETS.iter().find(|(key, _)| *key == r.key) {
                Some((_, budget)) if r.max > *budget => {
                    over.push(format!("{}: max {} > budget {budget}", r.key, r.max))
                }
                Some(_) => {}
                None => over.push(format!("{}: no budget in xtask/src/bench.rs", r.key)),
            }
        }
        if bound.total() > u64::from(TICK_BUDGET_INSTRUCTIONS) {
            over.push(format!(
                "worst-case bound {} > tick budget {TICK_BUDGET_INSTRUCTIONS}",
                bound.total()
            ));
        }
        if bound.total_control() > u64::from(CONTROL_TICK_BUDGET_INSTRUCTIONS) {
            over.push(format!(
                "controller worst-case bound {} > controller tick budget {CONTROL_TICK_BUDGET_INSTRUCTIONS}",
                bound.total_control()
            ));
        }
        if !over.is_empty() {
            bail!("over budget:\n  {}", over.join("\n  "));
        }
        println!("every component within its budget (--check)");
    }
    Ok(())
}
