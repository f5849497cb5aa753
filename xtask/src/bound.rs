//! The tick's worst-case bound: the structure written down next to the code
//! (`catmodel::node::stage::TICK_STAGES`, each stage's runs per tick at most; the app's drain,
//! handoff and the step's return once each) times each stage's most expensive run, measured
//! in QEMU by `catmodel-qemu-stages --stages` over the dedicated drives of
//! [`crate::drives::stage_corpus`]:
//!
//! `bound = sum over the common rows of max_per_tick x max`
//! `      + max over the branches of the same sum over the branch's rows`
//!
//! (a tick runs the stages of one branch at most, `catmodel::node::stage::Branch`: a tick that
//! loads a long path does not also plan; the stage measurement fails if one does), where the
//! rows of one exclusive set (`catmodel::node::stage::Exclusive`: a tick that fills missing
//! GNSS fixes does not also restart the lowpass) count as the dearest of them.
//!
//! Two bounds: `worst_case_bound_instructions` over the ticks in which no controller plans
//! (each stage's maximum over such ticks; budget `TICK_BUDGET_INSTRUCTIONS`) and
//! `worst_case_bound_controller_instructions` over any tick (each stage's maximum over every
//! tick, and the controller's solve at its worst case, every row active and every iteration
//! run, measured apart by `catmodel-qemu-mpc-bench`; budget `CONTROL_TICK_BUDGET_INSTRUCTIONS`).
//! The second with the solve at its maximum on the stage drives instead is reported beside it
//! (`controller_bound_drives_instructions`): the drives' own ticks must stay under it.
//!
//! It holds for any input as far as (1) the counts are bounded by the code (a stage that runs
//! more often than its row says fails the measurement), (2) no stage's cost depends on the data
//! beyond the paths the dedicated drives take (every loop has a fixed count; the branches are
//! the ones the drives exercise), and (3) the probed build of the step costs what the plain
//! one does (the difference is a row of its own). `cargo xtask adversarial` then tries to break
//! it on whole ticks. The table is data: a new stage is a new row, nothing here changes.
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{anyhow, bail, Context, Result};
use catmodel::node::drive::Controller;
use catmodel::node::NodeConfig;
use catmodel_app::budget::{
    CONTROL_TICK_BUDGET_INSTRUCTIONS, CYCLES_PER_TICK, TICK_BUDGET_INSTRUCTIONS,
};

use super::bench::{self, MPC_BENCH};
use super::{cargo_build, drives, qemu_append, qemu_path, qemu_stderr_cached, root};

/// The stage row of the model-predictive controller's solve (`Stage::MpcSolve`).
const SOLVE_ROW: &str = "mpc_solve";
/// The branch of the rows that may run in any tick (`Branch::Common`).
const COMMON: &str = "common";

/// One row of the bound.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Row {
    /// Stage key.
    pub key: String,
    /// Runs per tick, at most.
    pub max_per_tick: u32,
    /// Runs measured.
    pub runs: u32,
    /// Most expensive run measured in a tick without a controller planning, instructions.
    pub max: u32,
    /// The drive that showed it.
    pub drive: String,
    /// Most expensive run measured in any tick, instructions.
    pub max_control: u32,
    /// The drive that showed it.
    pub drive_control: String,
    /// Which stages it may run beside: `common` (any), else only the rows of its own branch
    /// and the common ones.
    pub branch: String,
    /// The exclusive set it is in (a tick runs one of its rows at most), if any.
    pub exclusive: Option<String>,
    /// Why no more runs.
    pub because: String,
}

impl Row {
    /// This row's part of the bound.
    pub fn part(&self) -> u64 {
        u64::from(self.max_per_tick) * u64::from(self.max)
    }

    /// This row's part of the controller's bound over the drives' maxima.
    pub fn part_control(&self) -> u64 {
        u64::from(self.max_per_tick) * u64::from(self.max_control)
    }
}

/// The branches' composition of a bound: the common rows' sum plus the largest branch's.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Composition {
    /// Sum over the common rows.
    pub common: u64,
    /// Sum over each other branch's rows, in the order of the rows.
    pub branches: Vec<(String, u64)>,
}

impl Composition {
    /// The rows' parts summed by branch; the rows of one exclusive set count as the dearest.
    fn of<'a>(rows: impl Iterator<Item = (&'a Row, u64)>) -> Self {
        let mut c = Composition {
            common: 0,
            branches: Vec::new(),
        };
        // (branch, set, the dearest part so far)
        let mut sets: Vec<(&str, &str, u64)> = Vec::new();
        for (row, part) in rows {
            match row.exclusive.as_deref() {
                Some(set) => match sets
                    .iter_mut()
                    .find(|(b, s, _)| *b == row.branch && *s == set)
                {
                    Some((_, _, dearest)) => *dearest = (*dearest).max(part),
                    None => sets.push((&row.branch, set, part)),
                },
                None => c.add(&row.branch, part),
            }
        }
        for (branch, _, part) in sets {
            c.add(branch, part);
        }
        c
    }

    fn add(&mut self, branch: &str, part: u64) {
        if branch == COMMON {
            self.common += part;
        } else if let Some((_, sum)) = self.branches.iter_mut().find(|(b, _)| b == branch) {
            *sum += part;
        } else {
            self.branches.push((branch.to_string(), part));
        }
    }

    /// The bound: the common rows and the most expensive branch.
    pub fn total(&self) -> u64 {
        self.common + self.branches.iter().map(|(_, s)| *s).max().unwrap_or(0)
    }

    /// `common + max(branch a, branch b)`, for the printed lines.
    pub fn describe(&self) -> String {
        let branches: Vec<String> = self
            .branches
            .iter()
            .map(|(b, s)| format!("{b} {s}"))
            .collect();
        format!("common {} + max({})", self.common, branches.join(", "))
    }
}

/// The bound and what it was computed from.
#[derive(Clone, Debug)]
pub struct Bound {
    /// The rows, node stages first, in the order they run.
    pub rows: Vec<Row>,
    /// Ticks measured over the dedicated drives.
    pub ticks: u32,
    /// The largest whole tick among them (drain + plain step + handoff) without a controller
    /// planning, and its drive.
    pub max_tick: (u32, String),
    /// The largest whole tick among them, any tick, and its drive.
    pub max_tick_control: (u32, String),
    /// The drives.
    pub drives: Vec<String>,
    /// The controller's solve on its most expensive path (every row active, every iteration),
    /// measured apart, and where.
    pub solve_worst: Option<(u32, String)>,
}

impl Bound {
    /// Records the controller's solve on its most expensive path (measured apart): the stage
    /// drives reach the solve, not its worst case.
    pub fn compose_solve(&mut self, worst: u32, which: &str) {
        self.solve_worst = Some((worst, which.to_string()));
    }

    /// A row's most expensive run in the controller's bound: the drives' maximum, and for the
    /// solve the solver's worst case where the drives showed less.
    pub fn max_control_of(&self, row: &Row) -> u32 {
        match &self.solve_worst {
            Some((worst, _)) if row.key == SOLVE_ROW => (*worst).max(row.max_control),
            _ => row.max_control,
        }
    }

    /// A row's part of the controller's bound.
    pub fn part_control_of(&self, row: &Row) -> u64 {
        u64::from(row.max_per_tick) * u64::from(self.max_control_of(row))
    }

    /// The tick's bound (no controller planning), by branch.
    pub fn composition(&self) -> Composition {
        Composition::of(self.rows.iter().map(|r| (r, r.part())))
    }

    /// The controller's bound, by branch.
    pub fn composition_control(&self) -> Composition {
        Composition::of(self.rows.iter().map(|r| (r, self.part_control_of(r))))
    }

    /// The tick's bound, instructions.
    pub fn total(&self) -> u64 {
        self.composition().total()
    }

    /// The bound of a tick in which a controller plans, instructions: the solve at its worst
    /// case once [`Bound::compose_solve`] recorded it.
    pub fn total_control(&self) -> u64 {
        self.composition_control().total()
    }

    /// The controller's bound with every row at the stage drives' maximum (the solve too): the
    /// drives' own ticks are under it.
    pub fn total_control_drives(&self) -> u64 {
        Composition::of(self.rows.iter().map(|r| (r, r.part_control()))).total()
    }

    /// The failures of a run whose slowest ticks were `max_plain` (no controller planning) and
    /// `max_control`: a measured tick over its bound means the bound is wrong (a stage costs
    /// more than measured, or runs more often than its row says, or beside another branch).
    /// The dedicated drives' own largest ticks are checked too, the controller's against the
    /// bound over their own maxima.
    pub fn check(&self, max_plain: u32, max_control: Option<u32>) -> Vec<String> {
        let mut failures = Vec::new();
        let (bound, bound_control) = (self.total(), self.total_control());
        for (what, tick, limit) in [
            ("a tick", Some(max_plain), bound),
            ("a controller tick", max_control, bound_control),
            ("a dedicated drive's tick", Some(self.max_tick.0), bound),
            (
                "a dedicated drive's controller tick",
                Some(self.max_tick_control.0),
                self.total_control_drives(),
            ),
        ] {
            if let Some(t) = tick.filter(|&t| u64::from(t) > limit) {
                failures.push(format!(
                    "{what} took {t} instructions, over its worst-case bound of {limit}: the bound is wrong"
                ));
            }
        }
        failures
    }

    /// The rows no drive ran: a row measured at 0 would count nothing, and the bound would not
    /// be one. Only the rows no tick of this car can run may stay unmeasured ([`unreachable`]):
    /// the model-predictive controller's on a car whose model file chooses the pure pursuit,
    /// the restart on the track on a car whose position is lost before a gap can need one.
    pub fn unmeasured(&self, unreachable: &[&str]) -> Vec<&str> {
        self.rows
            .iter()
            .filter(|r| r.runs == 0)
            .filter(|r| !unreachable.contains(&r.key.as_str()))
            .map(|r| r.key.as_str())
            .collect()
    }

    /// The table printed by `cargo qemu` and `cargo xtask bench-target`.
    pub fn table(&self) -> String {
        let total = self.total();
        let total_control = self.total_control();
        let mut t = String::new();
        let _ = writeln!(
            t,
            "worst case per tick, from the code's structure and each stage's measured maximum \
             ({} ticks of {} dedicated drives; QEMU instruction counts, not cycles):",
            self.ticks,
            self.drives.len()
        );
        let _ = writeln!(
            t,
            "  {:<20}{:<10}{:<10}{:>9}{:>8}{:>9}{:>7}{:>9}{:>10}{:>7}  {:<26}bounded by",
            "stage",
            "branch",
            "one of",
            "max/tick",
            "max",
            "part",
            "share",
            "max ctl",
            "part ctl",
            "share",
            "max seen on (ctl)"
        );
        for r in &self.rows {
            let share = r.part() as f64 / total.max(1) as f64 * 100.0;
            let part_control = self.part_control_of(r);
            let share_control = part_control as f64 / total_control.max(1) as f64 * 100.0;
            let seen_control = match &self.solve_worst {
                Some((worst, which)) if r.key == SOLVE_ROW && *worst > r.max_control => {
                    format!("{which}; drives {} on {}", r.max_control, r.drive_control)
                }
                _ => r.drive_control.clone(),
            };
            let _ = writeln!(
                t,
                "  {:<20}{:<10}{:<10}{:>9}{:>8}{:>9}{:>6.1}%{:>9}{:>10}{:>6.1}%  {:<26}{}",
                r.key,
                r.branch,
                r.exclusive.as_deref().unwrap_or("-"),
                r.max_per_tick,
                r.max,
                r.part(),
                share,
                self.max_control_of(r),
                part_control,
                share_control,
                format!("{} ({seen_control})", r.drive),
                r.because
            );
        }
        let _ = writeln!(
            t,
            "  (a tick runs the common rows and the rows of one other branch at most, and one row of each 'one of' set, which counts as its dearest row; shares are of the bound)"
        );
        let _ = writeln!(
            t,
            "  bound {total} instructions = {} (budget {TICK_BUDGET_INSTRUCTIONS}; {:.3} % of a 20 ms tick at 168 MHz if one instruction took one cycle); largest tick of these drives {}",
            self.composition().describe(),
            total as f64 / CYCLES_PER_TICK as f64 * 100.0,
            self.max_tick.0
        );
        let solve = match &self.solve_worst {
            Some((worst, which)) => format!("the solve at its worst case {worst} ({which})"),
            None => "the solve at its maximum on the drives".to_string(),
        };
        let _ = writeln!(
            t,
            "  controller bound {total_control} instructions = {}, {solve} (budget {CONTROL_TICK_BUDGET_INSTRUCTIONS}, enforced; {:.3} % of the tick); largest controller tick of these drives {}",
            self.composition_control().describe(),
            total_control as f64 / CYCLES_PER_TICK as f64 * 100.0,
            self.max_tick_control.0
        );
        let _ = writeln!(
            t,
            "  controller bound over the drives' maxima (the solve's too) {} instructions",
            self.total_control_drives()
        );
        t
    }

    /// The markdown table of the README and docs/firmware.md.
    pub fn markdown(&self) -> String {
        let total = self.total();
        let total_control = self.total_control();
        let mut t = String::new();
        let _ = writeln!(
            t,
            "| stage | branch | one of | runs per tick, at most | bounded by | most expensive run | share of the bound | most expensive run, controller ticks | share of the controller bound |"
        );
        let _ = writeln!(t, "|---|---|---|---:|---|---:|---:|---:|---:|");
        for r in &self.rows {
            let _ = writeln!(
                t,
                "| {} | {} | {} | {} | {} | {} | {:.1} % | {} | {:.1} % |",
                r.key,
                r.branch,
                r.exclusive.as_deref().unwrap_or("-"),
                r.max_per_tick,
                r.because,
                r.max,
                r.part() as f64 / total.max(1) as f64 * 100.0,
                self.max_control_of(r),
                self.part_control_of(r) as f64 / total_control.max(1) as f64 * 100.0
            );
        }
        let _ = writeln!(
            t,
            "| **bound** ({}; {}) | | | | | **{total}** | | **{total_control}** | |",
            self.composition().describe(),
            self.composition_control().describe()
        );
        t
    }

    /// `worst_case` of `timing.json`.
    pub fn json(&self) -> serde_json::Value {
        let composition = |c: Composition| {
            serde_json::json!({
                "common_instructions": c.common,
                "branches": c.branches.iter().map(|(b, s)| serde_json::json!({"branch": b, "instructions": s})).collect::<Vec<_>>(),
                "total_instructions": c.total(),
            })
        };
        serde_json::json!({
            "method": "sum over the tick's common stages of (runs per tick at most, from catmodel::node::stage::TICK_STAGES and the app) x (most expensive run measured in QEMU on dedicated drives), plus the largest such sum over the stages of one branch (a tick runs one branch at most), the stages of one exclusive set (a tick runs one of them at most) counted as the dearest of them; in the controller's bound the solve at its worst case (catmodel-qemu-mpc-bench)",
            "drives": self.drives,
            "ticks_measured": self.ticks,
            "largest_tick_measured": self.max_tick.0,
            "largest_tick_drive": self.max_tick.1,
            "largest_controller_tick_measured": self.max_tick_control.0,
            "largest_controller_tick_drive": self.max_tick_control.1,
            "bound": composition(self.composition()),
            "controller_bound": composition(self.composition_control()),
            "controller_bound_drives_instructions": self.total_control_drives(),
            "solver_worst_case": self.solve_worst.as_ref().map(|(n, which)| serde_json::json!({"instructions": n, "measured_by": which})),
            "stages": self.rows.iter().map(|r| serde_json::json!({
                "stage": r.key,
                "branch": r.branch,
                "exclusive": r.exclusive,
                "max_per_tick": r.max_per_tick,
                "runs_measured": r.runs,
                "max_instructions": r.max,
                "max_on_drive": r.drive,
                "part_instructions": r.part(),
                "max_controller_on_drives_instructions": r.max_control,
                "max_controller_on_drive": r.drive_control,
                "max_controller_instructions": self.max_control_of(r),
                "part_controller_instructions": self.part_control_of(r),
                "bounded_by": r.because,
            })).collect::<Vec<_>>(),
        })
    }
}

/// The configuration the firmware bakes: `CATMODEL_MODEL` or `models/paper.toml` (the
/// firmware's build script reads the same file through the same reader).
pub fn baked_car() -> Result<NodeConfig> {
    let path = match std::env::var_os("CATMODEL_MODEL") {
        // Absolute, or relative to the repository root, as `firmware/build.rs` reads it.
        Some(p) => root().join(p),
        None => root().join("models").join("paper.toml"),
    };
    let file = catmodel_model_file::load(&path).map_err(|e| anyhow!("{e}"))?;
    Ok(file.node_config())
}

/// Writes the dedicated drives into `dir`; returns their paths relative to the repository.
pub fn write_stage_corpus(car: &NodeConfig, dir: &Path) -> Result<Vec<String>> {
    let mut paths = Vec::new();
    for spec in drives::stage_corpus(car) {
        let frames = drives::generate(&spec, car);
        let path = dir.join(format!("{}.log", spec.name));
        drives::write_candump(&path, &frames)?;
        let rel = path
            .strip_prefix(root())
            .unwrap_or(&path)
            .to_string_lossy()
            .into_owned();
        paths.push(rel);
    }
    Ok(paths)
}

/// Parses the `--stages` output of the bench firmware.
pub fn parse(stderr: &str, drives: Vec<String>) -> Result<Bound> {
    let name = |index: &str| -> Result<String> {
        let i: usize = index.parse()?;
        Ok(drives.get(i).cloned().unwrap_or_else(|| format!("#{i}")))
    };
    let mut rows = Vec::new();
    let mut ticks = None;
    let mut done = false;
    for line in stderr.lines() {
        let fields: Vec<&str> = line.split('\t').collect();
        match fields.as_slice() {
            ["stage", key, max_per_tick, runs, max, drive, max_control, drive_control, branch, exclusive, because] => {
                rows.push(Row {
                    key: key.to_string(),
                    max_per_tick: max_per_tick.parse()?,
                    runs: runs.parse()?,
                    max: max.parse()?,
                    drive: name(drive)?,
                    max_control: max_control.parse()?,
                    drive_control: name(drive_control)?,
                    branch: branch.to_string(),
                    exclusive: (*exclusive != "-").then(|| exclusive.to_string()),
                    because: because.to_string(),
                })
            }
            ["stage-ticks", n, max, drive, max_control, drive_control] => {
                ticks = Some((
                    n.parse()?,
                    (max.parse()?, name(drive)?),
                    (max_control.parse()?, name(drive_control)?),
                ))
            }
            ["stage-done"] => done = true,
            _ => {}
        }
    }
    if !done || rows.is_empty() {
        bail!("the stage measurement did not finish:\n{stderr}");
    }
    let (ticks, max_tick, max_tick_control) =
        ticks.ok_or_else(|| anyhow!("no stage-ticks line"))?;
    Ok(Bound {
        rows,
        ticks,
        max_tick,
        max_tick_control,
        drives,
        solve_worst: None,
    })
}

/// Closed-loop scenarios whose recorded bus input (the vehicle's sensors and the planner's path,
/// obstacles and origin, with the node's own controller driving) are stage drives: the drive
/// stage planning on a real path, with and without an obstacle.
const CLOSED_LOOP_SCENARIOS: [&str; 2] = ["dlc", "obstacle"];

/// The release host binary (`catmodel`), built if needed.
pub fn host_binary() -> Result<PathBuf> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let status = Command::new(cargo)
        .current_dir(root())
        .args(["build", "--release", "--quiet", "-p", "catmodel-host"])
        .status()
        .context("running cargo build")?;
    if !status.success() {
        bail!("building catmodel-host failed");
    }
    Ok(root().join("target").join("release").join("catmodel"))
}

/// Records the closed-loop sessions into `dir` (`catmodel closed-loop --scenario S --out
/// DIR/closed-loop-S`); returns their bus inputs' paths relative to the repository.
pub fn write_closed_loop_sessions(dir: &Path, host: &Path) -> Result<Vec<String>> {
    let mut paths = Vec::new();
    for scenario in CLOSED_LOOP_SCENARIOS {
        let out = dir.join(format!("closed-loop-{scenario}"));
        let mut command = Command::new(host);
        command
            .current_dir(root())
            .args(["closed-loop", "--scenario", scenario, "--out"])
            .arg(&out);
        // The node as the firmware bakes it (the plant's receiver then at the file's rate).
        if let Some(model) = std::env::var_os("CATMODEL_MODEL") {
            command.arg("--model").arg(root().join(model));
        }
        let output = command.output().context("running catmodel closed-loop")?;
        if !output.status.success() {
            bail!(
                "catmodel closed-loop --scenario {scenario} failed:\n{}",
                String::from_utf8_lossy(&output.stderr)
            );
        }
        let log = out.join("session.can.log");
        paths.push(
            log.strip_prefix(root())
                .unwrap_or(&log)
                .to_string_lossy()
                .into_owned(),
        );
    }
    Ok(paths)
}

/// Generates the dedicated drives and records the closed-loop sessions, builds the stage
/// firmware and measures every stage in QEMU; the controller's solve row is composed with its
/// worst case ([`mpc_worst_solve`]).
pub fn measure() -> Result<Bound> {
    // Side by side: the stages' QEMU runs take one core, the controller benchmark's build (a
    // fat-LTO link of one codegen unit) and its QEMU run another.
    // Cargo is called here before, and by the benchmark's thread only after: a build waits for
    // another's lock on the target directory.
    let host = host_binary()?;
    let elf = cargo_build("qemu", "catmodel-qemu-stages")?;
    let (stages, solve) = std::thread::scope(|s| {
        let solve = s.spawn(mpc_worst_solve);
        let stages = measure_stages_built(&host, &elf);
        let solve = solve
            .join()
            .unwrap_or_else(|_| Err(anyhow!("the controller benchmark's thread panicked")));
        (stages, solve)
    });
    let mut bound = stages?;
    let (worst, which) = solve?;
    bound.compose_solve(worst, &which);
    Ok(bound)
}

/// [`measure`] without the controller's worst-case solve (the caller composes it).
pub fn measure_stages() -> Result<Bound> {
    let host = host_binary()?;
    let elf = cargo_build("qemu", "catmodel-qemu-stages")?;
    measure_stages_built(&host, &elf)
}

/// [`measure_stages`] with the host binary and the stage firmware built (no cargo call).
fn measure_stages_built(host: &Path, elf: &Path) -> Result<Bound> {
    let car = baked_car()?;
    let dir = root().join("target").join("qemu").join("stages");
    let mut drives = write_stage_corpus(&car, &dir)?;
    drives.extend(write_closed_loop_sessions(&dir, host)?);
    // The drives go in a list file: a command line of their paths outgrows the firmware's
    // buffer as drives are added or the checkout's path grows.
    let list = dir.join("drives.list");
    let mut text = drives.join("\n");
    text.push('\n');
    std::fs::write(&list, text).with_context(|| format!("writing {}", list.display()))?;
    let append = qemu_append(
        elf,
        &[
            "catmodel-qemu-stages".into(),
            "--stages".into(),
            qemu_path(&list)?,
        ],
    )?;
    let mut inputs = vec![list.clone()];
    inputs.extend(drives.iter().map(|d| root().join(d)));
    let stderr =
        qemu_stderr_cached(elf, &append, &inputs).context("the stage measurement failed")?;
    // A drive's name: its file's stem, or its directory's for a closed-loop session.
    let names = drives
        .iter()
        .map(|p| {
            let path = Path::new(p);
            let named = if p.ends_with("session.can.log") {
                path.parent().and_then(Path::file_name)
            } else {
                path.file_stem()
            };
            named.map_or_else(|| p.clone(), |s| s.to_string_lossy().into_owned())
        })
        .collect();
    let mut bound = parse(&stderr, names)?;
    let unreachable = unreachable(&car);
    for r in bound.rows.iter_mut().filter(|r| r.runs == 0) {
        if unreachable.contains(&r.key.as_str()) {
            r.because = format!("unreachable for this model file ({})", r.because);
        }
    }
    let unmeasured = bound.unmeasured(&unreachable);
    if !unmeasured.is_empty() {
        bail!(
            "the dedicated drives never ran {} with this model file: the bound would count \
             nothing for {}; the drives (xtask/src/drives.rs, stage_corpus) must reach every stage",
            unmeasured.join(", "),
            if unmeasured.len() == 1 { "it" } else { "them" }
        );
    }
    Ok(bound)
}

/// The stages no tick of `car` can run, by the code's rules, so that no drive has to reach them
/// (their rows count 0):
/// - the model-predictive controller's (`drive_reference`, the solve, `drive_coast`) on a car
///   whose model file chooses the pure pursuit;
/// - `gnss_restart` where the position is lost before a gap can need a restart: a restart
///   takes `GAP_FILL_PER_TICK + 1` missing fixes (`src/node/gnss.rs`: a gap of
///   `GAP_FILL_PER_TICK + 1.5` receiver periods at least, [`crate::drives::restart_gap_s`]),
///   and the first tick that finds the receiver silent for longer than `gnss_lost_us` resets
///   the position. A tick takes its frames before it looks: the fix after a gap of `g` is
///   taken in time if no tick falls between `lost` and `g` after the fix before it, which the
///   ticks' phase allows while `g < lost + 20 ms` (the stage drive `stages-gnss-gaps-exact`
///   places it so) and nothing allows past that. A 1 Hz car with `gnss_lost_s = 3`: a restart
///   needs 3.5 s of silence, the position is gone after 3; a 10 Hz car with `gnss_lost_s =
///   0.32`: 0.35 s against 0.34 (two ticks were allowed here before, and such a car's
///   measurement stopped for want of a restart no drive could make).
pub fn unreachable(car: &NodeConfig) -> Vec<&'static str> {
    let mut out = Vec::new();
    if car.controller == Controller::PurePursuit {
        out.extend(["drive_reference", SOLVE_ROW, "drive_coast"]);
    }
    let lost_s = car.gnss_lost_us as f64 * 1e-6;
    if crate::drives::restart_gap_s(car) > lost_s + catmodel::SAMPLE_PERIOD_S_F64 {
        out.push("gnss_restart");
    }
    out
}

/// The model-predictive controller's solve on its most expensive path: every row of every
/// stage active and every ADMM iteration run (no early exit), in both lateral modes, on the
/// baked car (`catmodel-qemu-mpc-bench`, rows `mpc_worst_dynamic`, `mpc_worst_kinematic` and
/// `mpc_worst_standing`), ended in the dearer fallback (`mpc_part_fallback_end`: a whole solve
/// whose plans did not clear an obstacle, or were not finite; docs/mpc.md). The solve's
/// iterations are capped, so this is its cost for any input.
fn mpc_worst_solve() -> Result<(u32, String)> {
    let (features, bin) = MPC_BENCH;
    let stderr = bench::run_bench(features, bin)?;
    let (rows, _) = bench::parse(&stderr)?;
    worst_solve(&rows, bin)
}

/// The benchmark's row of a solve's end in the fallback, beyond the end a plan takes.
const FALLBACK_END_ROW: &str = "mpc_part_fallback_end";

/// The largest `mpc_worst_*` row of the controller's benchmark plus its fallback's end
/// ([`FALLBACK_END_ROW`]): a worst-case row may end either way, so the sum covers both.
pub fn worst_solve(rows: &[bench::Row], bin: &str) -> Result<(u32, String)> {
    let worst = rows
        .iter()
        .filter(|r| r.key.starts_with("mpc_worst_"))
        .max_by_key(|r| r.max)
        .ok_or_else(|| anyhow!("{bin} printed no mpc_worst_* row"))?;
    let end = rows
        .iter()
        .find(|r| r.key == FALLBACK_END_ROW)
        .ok_or_else(|| anyhow!("{bin} printed no {FALLBACK_END_ROW} row"))?;
    Ok((
        worst.max.saturating_add(end.max),
        format!(
            "{bin} {} {} + {FALLBACK_END_ROW} {}",
            worst.key, worst.max, end.max
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bound_is_the_sum_of_runs_times_maxima() {
        let text = "noise\nstage\tframe\t16\t100\t200\t0\t300\t1\tcommon\t-\tMAX\n\
                    stage\tpredict\t1\t9\t5000\t1\t90000\t0\tcommon\t-\tonce\n\
                    stage-ticks\t9\t7000\t1\t80000\t0\nstage-done\n";
        let b = parse(text, vec!["a".into(), "b".into()]).unwrap();
        assert_eq!(b.total(), 16 * 200 + 5000);
        assert_eq!(b.total_control(), 16 * 300 + 90_000);
        assert_eq!(
            (b.ticks, b.max_tick.0, b.max_tick.1.as_str()),
            (9, 7000, "b")
        );
        assert_eq!(b.max_tick_control, (80_000, "a".to_string()));
        assert_eq!(
            (b.rows[1].drive.as_str(), b.rows[0].drive_control.as_str()),
            ("b", "b")
        );
        assert!(b.table().contains("bound 8200 instructions"));
        assert!(b.table().contains("controller bound 94800 instructions"));
        assert!(b.check(8200, Some(94_800)).is_empty());
        assert_eq!(b.check(8201, Some(94_801)).len(), 2);
        // A line without its branch is not a row.
        assert!(parse(
            "stage\tx\t1\t1\t1\t0\t1\t0\twhy\nstage-done\n",
            vec!["a".into()]
        )
        .is_err());
    }

    #[test]
    fn a_row_no_drive_ran_is_refused_but_the_mpcs_on_a_pure_pursuit_car() {
        let text = "stage\tgnss_fill\t2\t0\t0\t0\t0\t0\tcommon\tgnss_gap\tcap\n\
                    stage\tpredict\t1\t9\t5000\t1\t5000\t0\tcommon\t-\tonce\n\
                    stage\tdrive_reference\t1\t0\t0\t0\t0\t1\tplan\t-\tonce\n\
                    stage-ticks\t9\t7000\t1\t80000\t0\nstage-done\n";
        let b = parse(text, vec!["a".into(), "b".into()]).unwrap();
        assert_eq!(b.unmeasured(&[]), vec!["gnss_fill", "drive_reference"]);
        let pursuit = ["drive_reference", SOLVE_ROW, "drive_coast"];
        assert_eq!(b.unmeasured(&pursuit), vec!["gnss_fill"]);
    }

    #[test]
    fn branches_count_once_the_most_expensive() {
        // A tick runs the common rows and one branch: loading a path (two rows) or planning
        // (two rows, one of them the solve), never both.
        let text = "stage\tframe\t12\t9\t10\t0\t20\t0\tcommon\t-\tcap\n\
                    stage\tpath_complete\t1\t4\t0\t0\t90000\t1\tpath_load\t-\tone\n\
                    stage\tdrive_reference\t1\t5\t0\t0\t100000\t1\tplan\t-\tonce\n\
                    stage\tmpc_solve\t1\t5\t0\t0\t300000\t1\tplan\t-\tcap\n\
                    stage\tdrive_coast\t1\t2\t0\t0\t2000\t1\tpath_load\t-\tonce\n\
                    stage-ticks\t9\t100\t0\t400240\t1\nstage-done\n";
        let mut b = parse(text, vec!["a".into(), "b".into()]).unwrap();
        let c = b.composition_control();
        assert_eq!(c.common, 12 * 20);
        assert_eq!(
            c.branches,
            vec![
                ("path_load".to_string(), 92_000),
                ("plan".to_string(), 400_000)
            ]
        );
        assert_eq!(b.total_control(), 240 + 400_000);
        assert_eq!(b.total(), 12 * 10);
        assert!(b
            .table()
            .contains("= common 240 + max(path_load 92000, plan 400000)"));
        // The solve at its worst case lifts the plan branch only.
        b.compose_solve(450_000, "bench mpc_worst_dynamic");
        assert_eq!(b.total_control(), 240 + 100_000 + 450_000);
        assert_eq!(b.total_control_drives(), 240 + 400_000);
        // A loading branch dearer than the plan is the one counted.
        b.rows[1].max_control = 600_000;
        assert_eq!(b.total_control(), 240 + 602_000);
        // The drives' own controller ticks are checked against the drives' bound.
        b.rows[1].max_control = 90_000;
        b.max_tick_control.0 = 400_241;
        assert_eq!(b.check(0, Some(0)).len(), 1);
    }

    #[test]
    fn an_exclusive_set_counts_its_dearest_row() {
        // Filling two missing fixes (2 x 500) or one restart (1 x 2000): a tick does one or
        // the other, so the bound takes 2000, not 3000; rows outside the set still add up.
        let text = "stage\tframe\t12\t9\t10\t0\t10\t0\tcommon\t-\tcap\n\
                    stage\tgnss_fill\t2\t9\t500\t0\t500\t0\tcommon\tgnss_gap\tcap\n\
                    stage\tgnss_restart\t1\t9\t2000\t0\t2000\t0\tcommon\tgnss_gap\tonce\n\
                    stage\tmpc_solve\t1\t5\t0\t0\t9000\t1\tplan\t-\tcap\n\
                    stage-ticks\t9\t100\t0\t9000\t1\nstage-done\n";
        let mut b = parse(text, vec!["a".into(), "b".into()]).unwrap();
        assert_eq!(b.rows[1].exclusive.as_deref(), Some("gnss_gap"));
        assert_eq!(b.rows[0].exclusive, None);
        assert_eq!(b.total(), 120 + 2000);
        assert_eq!(b.total_control(), 120 + 2000 + 9000);
        // The dearer member decides: fills dearer than the restart.
        b.rows[1].max = 1500;
        assert_eq!(b.total(), 120 + 3000);
        assert!(b.table().contains("gnss_gap"));
        assert!(b
            .markdown()
            .contains("| gnss_fill | common | gnss_gap | 2 |"));
    }

    #[test]
    fn the_solve_row_takes_the_worst_case_where_the_drives_showed_less() {
        let text = "stage\tmpc_solve\t1\t5\t0\t0\t200000\t1\tplan\t-\tcap\n\
                    stage\tdrive\t1\t9\t70\t0\t3000\t1\tcommon\t-\tonce\n\
                    stage-ticks\t9\t70\t0\t203000\t1\nstage-done\n";
        let mut b = parse(text, vec!["a".into(), "b".into()]).unwrap();
        assert_eq!(b.total_control(), 203_000);
        b.compose_solve(419_144, "bench mpc_worst_dynamic");
        // The enforced bound takes the worst case; the drives' figure stays beside it; without
        // a controller the solve never runs: that bound is unchanged.
        assert_eq!(b.total_control(), 419_144 + 3000);
        assert_eq!(b.total_control_drives(), 200_000 + 3000);
        assert_eq!(b.total(), 70);
        assert!(b.table().contains("controller bound 422144 instructions"));
        assert!(b.check(0, Some(422_144)).is_empty());
        assert_eq!(b.check(0, Some(422_145)).len(), 1);
        // A drive that showed more than the bench keeps its figure.
        b.compose_solve(100_000, "smaller");
        assert_eq!(b.total_control(), 203_000);
    }

    #[test]
    fn the_solve_worst_case_is_the_dearest_row_ended_in_the_fallback() {
        let line = |key: &str, max: u32| format!("bench\t{key}\tname\t1\t1\t1\t{max}\twhat\n");
        let mut text = line("mpc_worst_dynamic", 420_000)
            + &line("mpc_worst_kinematic", 425_000)
            + &line("mpc_dlc", 500_000)
            + "bench-overhead\t4\nbench-done\n";
        let (rows, _) = bench::parse(&text).unwrap();
        // Without the fallback's end the bound would miss a path: refused.
        assert!(worst_solve(&rows, "b").is_err());
        text = line("mpc_part_fallback_end", 5_000) + &text;
        let (rows, _) = bench::parse(&text).unwrap();
        let (worst, which) = worst_solve(&rows, "b").unwrap();
        // The dearest worst-case row, not another scenario's, plus the end.
        assert_eq!(worst, 430_000);
        assert!(which.contains("mpc_worst_kinematic 425000"), "{which}");
    }
}
