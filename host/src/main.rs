//! `catmodel`: the host command-line tool (see README, "The CLI").
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{bail, Result};
use catmodel_host::outputs::{Kind, Paths};
use catmodel_host::progress::Progress;
use catmodel_host::{csv2can, decode, evaluate, identify, logcsv, model_file, replay, sim};
use clap::{Args, Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "catmodel",
    version,
    about = "Identified vehicle models (CAT Vehicle paper) on a 20 ms CAN node: host tools"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the built-in plant simulator: writes DIR/NAME.csv, DIR/NAME.can.log, DIR/NAME.truth.csv.
    SimulateDrive(SimulateDriveArgs),
    /// Encode a log (CSV schema) as the node's input frames, candump format.
    Csv2can(Csv2canArgs),
    /// Run the very same Node as the firmware over a candump log.
    Replay(ReplayArgs),
    /// Score predictions against ground truth, beside a kinematic raw-GNSS baseline.
    Evaluate(EvaluateArgs),
    /// Identify the models (eq 5, eq 7, lateral) from driving logs; write a model file.
    Identify(IdentifyArgs),
    /// The steering actuator's lag (`[vehicle] steer_lag_s`) and, when the session shows it, its
    /// rate limit (`max_steer_rate_pct_per_s`) from candump logs of a session in which the
    /// controller drove: its CONTROL_COMMAND frames and the car's STEERING_REPORT.
    IdentifySteering(IdentifySteeringArgs),
    /// The GNSS receiver's error (`[control] position_uncertainty_m`) from candump logs of the
    /// car parked: each axis's deviation and correlation time, and the bound to declare.
    ReceiverError(ReceiverErrorArgs),
    /// Simulate each model of a model file over one log, beside the kinematic model.
    Compare(CompareArgs),
    /// Close the loop: the plant simulator, the node and its controller on one bus, over a
    /// scenario (dlc, obstacle, loop, crossing); writes DIR/session.can.log, session.tx.log,
    /// metrics.json and plots.
    ClosedLoop(ClosedLoopArgs),
    /// The ISO 3888-2 double lane change's speeds for one car: each controller's highest clean
    /// speed (3 seeds, RTK receiver) and the offline optimiser's limit (perfect plant
    /// knowledge); prints JSON.
    DlcLimits(DlcLimitsArgs),
    /// Software in the loop: the node (and its controller) in lockstep over stdin/stdout.
    /// Input lines: candump frames and `TICK SECONDS.UUUUUU`, every 20 ms on multiples of
    /// 0.020000 s; on each TICK the node runs and writes that tick's frames as candump lines,
    /// then `END SECONDS.UUUUUU`.
    Sil(SilArgs),
    /// Decode a candump log (e.g. target/qemu/tx.log) with catmodel.dbc: signals, CRC, counters.
    Decode(DecodeArgs),
    /// Print the discrete state-space matrices of every model block as JSON.
    Discretize(DiscretizeArgs),
}

#[derive(Args)]
struct SimulateDriveArgs {
    /// straight-2.5, straight-5, straight-7.5, straight-10, turn-left, turn-right,
    /// circle-left, circle-right, validation, smoke, standstill, parked-1h, suburb, steps-at-speed.
    #[arg(long)]
    scenario: String,
    /// Output directory.
    #[arg(long)]
    out: PathBuf,
    /// Repetition (noise and small command variations).
    #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
    seed: u64,
    /// Vehicle parameters (TOML); default: the CAT Vehicle.
    #[arg(long)]
    vehicle: Option<PathBuf>,
    /// GNSS receiver: standard (the vehicle file's) or rtk (survey grade: 1 cm, as
    /// `closed-loop --receiver rtk`).
    #[arg(long, default_value = "standard")]
    receiver: String,
    /// Inject sensor faults (GNSS dropouts and outliers, lost reports).
    #[arg(long)]
    faults: bool,
}

#[derive(Args)]
struct Csv2canArgs {
    /// Log CSV.
    log: PathBuf,
    /// candump file to write.
    #[arg(long)]
    out: PathBuf,
}

#[derive(Args)]
struct ReplayArgs {
    /// candump log of the node's input frames.
    log: PathBuf,
    /// Local frame origin `LAT,LON` in degrees, south and west negative (`--origin
    /// -33.86,151.21`; default: the first GNSS fix).
    #[arg(long, value_parser = parse_origin, allow_hyphen_values = true)]
    origin: Option<(f64, f64)>,
    /// Predictions CSV to write (`t,step,horizon_s,x,y,heading,speed,mode`).
    #[arg(long)]
    out: PathBuf,
    /// Also write the frames the node sends, candump, stamped with the tick time.
    #[arg(long)]
    tx_out: Option<PathBuf>,
    /// Model file (default: the published models, models/paper.toml, as in the firmware).
    #[arg(long)]
    model: Option<PathBuf>,
    /// Keep only the frames of this interface (candump's name, e.g. `can0`) of a log that
    /// holds several.
    #[arg(long, value_name = "NAME")]
    interface: Option<String>,
}

#[derive(Args)]
struct EvaluateArgs {
    /// Predictions CSV from `replay`.
    predictions: PathBuf,
    /// Ground truth CSV (`t,x,y,heading,yaw_rate,speed`).
    #[arg(long)]
    truth: PathBuf,
    /// The candump the predictions came from (for the baseline and raw GNSS); default:
    /// NAME.can.log beside NAME.truth.csv.
    #[arg(long)]
    inputs: Option<PathBuf>,
    /// Origin of the truth frame `LAT,LON` in degrees, south and west negative (default: the
    /// simulator's test site).
    #[arg(long, value_parser = parse_origin, allow_hyphen_values = true)]
    origin: Option<(f64, f64)>,
    /// The car's model file (its geometry for the kinematic baseline, its GNSS antenna and
    /// receiver address; default: models/paper.toml).
    #[arg(long)]
    model: Option<PathBuf>,
    /// Also write the evaluation as JSON.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Write figures (SVG) into this directory: path.svg, error_vs_horizon.svg,
    /// gnss_window.svg, position_error_time.svg.
    #[arg(long, value_name = "DIR")]
    plots: Option<PathBuf>,
}

#[derive(Args)]
struct IdentifyArgs {
    /// Training logs (CSV schema).
    #[arg(required = true)]
    logs: Vec<PathBuf>,
    /// Validation logs.
    #[arg(long, num_args = 1..)]
    validate: Vec<PathBuf>,
    /// Model file to write (TOML).
    #[arg(long)]
    out: PathBuf,
    /// Write a report (Markdown summary and SVG plots) into this directory.
    #[arg(long)]
    report: Option<PathBuf>,
    /// Vehicle, hybrid thresholds and fallback models from this model file
    /// (default: models/paper.toml as built in).
    #[arg(long)]
    base: Option<PathBuf>,
    /// The car the logs come from: a TOML file with the model file's [vehicle] table and
    /// optionally [dynamics] and [inputs] (README, "A second car"); replaces the base file's.
    #[arg(long)]
    vehicle: Option<PathBuf>,
    /// Write the model even if a fit is below the floor (the warning goes into the file),
    /// or a log's wheel speed is not in m/s by its GNSS track (km/h, mph).
    #[arg(long)]
    force: bool,
}

#[derive(Args)]
struct IdentifySteeringArgs {
    /// candump logs (e.g. a recorder's of the whole bus, or closed-loop's session.can.log
    /// and session.tx.log), merged by time.
    #[arg(required = true)]
    logs: Vec<PathBuf>,
    /// The car's model file: its steering rate limit is used when the session does not
    /// show the limit, and compared with it when it does.
    #[arg(long)]
    model: Option<PathBuf>,
    /// The fit's window starts here, s of the logs' clock (default: a second after the
    /// first tracking command).
    #[arg(long, value_parser = parse_finite_seconds, allow_negative_numbers = true)]
    from: Option<f64>,
    /// Keep only the frames of this interface (candump's name, e.g. `can0`) of a log that
    /// holds several.
    #[arg(long, value_name = "NAME")]
    interface: Option<String>,
}

#[derive(Args)]
struct ReceiverErrorArgs {
    /// candump logs, merged by time.
    #[arg(required = true)]
    logs: Vec<PathBuf>,
    /// The car's model file: the receiver's NMEA 2000 source address (default: the
    /// published car's).
    #[arg(long)]
    model: Option<PathBuf>,
    /// Keep only the frames of this interface (candump's name, e.g. `can0`) of a log that
    /// holds several.
    #[arg(long, value_name = "NAME")]
    interface: Option<String>,
}

#[derive(Args)]
struct CompareArgs {
    /// Log CSV.
    log: PathBuf,
    /// Model file.
    #[arg(long)]
    model: PathBuf,
    /// CSV to write: t,vel,vel_model,vel_kinematic,dx,dx_model,dx_kinematic.
    #[arg(long)]
    out: Option<PathBuf>,
}

#[derive(Args)]
struct ClosedLoopArgs {
    /// dlc (ISO 3888-2 double lane change), obstacle, loop, crossing (a pedestrian).
    #[arg(long)]
    scenario: String,
    /// mpc or pure-pursuit.
    #[arg(long, default_value = "mpc")]
    controller: String,
    /// Vehicle parameters of the plant (TOML); default: the CAT Vehicle.
    #[arg(long)]
    vehicle: Option<PathBuf>,
    /// Model file for the node (default: the published models). Without --vehicle the
    /// plant's GNSS receiver is the one the file declares (its rate and antenna).
    #[arg(long)]
    model: Option<PathBuf>,
    /// GNSS receiver: rtk (survey grade) or standard (the vehicle file's).
    #[arg(long, default_value = "rtk")]
    receiver: String,
    /// Target speed, m/s (default: the scenario's).
    #[arg(long, allow_negative_numbers = true)]
    speed: Option<f64>,
    /// Sensor noise seed.
    #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
    seed: u64,
    /// The planner replans: it sends the path (a new path id) and obstacles again every
    /// SECONDS (default: once).
    #[arg(long, value_name = "SECONDS", allow_negative_numbers = true)]
    replan_every: Option<f64>,
    /// The car starts this far to the right of the path's first point (negative: left), m:
    /// how the controller returns to a path it is not on.
    #[arg(
        long,
        value_name = "METRES",
        default_value_t = 0.0,
        allow_negative_numbers = true
    )]
    start_offset: f64,
    /// Inject the vehicle file's sensor faults (its [faults]: GNSS outages and outliers,
    /// lost bus reports), as simulate-drive does; off by default.
    #[arg(long)]
    faults: bool,
    /// Output directory.
    #[arg(long)]
    out: PathBuf,
}

#[derive(Args)]
struct DlcLimitsArgs {
    /// Controllers to measure (pure-pursuit, mpc), comma-separated.
    #[arg(long, default_value = "pure-pursuit", value_delimiter = ',')]
    controllers: Vec<String>,
    /// Also run the offline optimiser (minutes).
    #[arg(long)]
    optimal: bool,
    /// Vehicle parameters of the plant (TOML); default: the CAT Vehicle.
    #[arg(long)]
    vehicle: Option<PathBuf>,
    /// Model file for the node (default: the published models).
    #[arg(long)]
    model: Option<PathBuf>,
    /// Also write the result as JSON.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Write the optimiser's best run at its limit as figures into this directory.
    #[arg(long, value_name = "DIR")]
    plots: Option<PathBuf>,
}

#[derive(Args)]
struct SilArgs {
    /// Talk over stdin/stdout (the only transport).
    #[arg(long, required = true)]
    stdio: bool,
    /// Model file (default: the published models).
    #[arg(long)]
    model: Option<PathBuf>,
    /// Local frame origin `LAT,LON` in degrees, south and west negative (`--origin
    /// -33.86,151.21`; default: the first GNSS fix).
    #[arg(long, value_parser = parse_origin, allow_hyphen_values = true)]
    origin: Option<(f64, f64)>,
}

#[derive(Args)]
struct DecodeArgs {
    /// candump log.
    log: PathBuf,
    /// Only these messages: names, NAME* for a prefix, or hex ids; comma-separated.
    #[arg(long, value_delimiter = ',')]
    messages: Vec<String>,
    /// Long CSV, one row per signal: t_s,id,message,check,signal,raw,value,unit,label,data.
    #[arg(long)]
    csv: bool,
    /// Keep only the frames of this interface (candump's name, e.g. `can0`) of a log that
    /// holds several.
    #[arg(long, value_name = "NAME")]
    interface: Option<String>,
}

#[derive(Args)]
struct DiscretizeArgs {
    /// Model file.
    model: PathBuf,
    /// Sample time, s (default: the file's), 1e-4 to 10.
    #[arg(long, value_parser = parse_sample_time, allow_negative_numbers = true)]
    ts: Option<f64>,
}

/// The published model file, built into the binary.
const PAPER_MODEL_TOML: &str = include_str!("../../models/paper.toml");

fn load_base(base: Option<&Path>) -> Result<catmodel_host::model_file::ModelFile> {
    Ok(match base {
        Some(p) => model_file::load(p)?,
        None => model_file::parse(PAPER_MODEL_TOML, Path::new("models/paper.toml"))?,
    })
}

/// `--ts`: a finite sample time from 0.1 ms to 10 s (outside, a delay's count of samples
/// saturates or a model's poles leave the unit circle's useful part; NaN was blamed on the
/// model file).
fn parse_sample_time(s: &str) -> Result<f64, String> {
    let ts: f64 = s.trim().parse().map_err(|e| format!("{s:?}: {e}"))?;
    if !(1e-4..=10.0).contains(&ts) {
        return Err(format!("{s}: a sample time from 0.0001 to 10 s"));
    }
    Ok(ts)
}

/// A finite number of seconds (`--from`).
fn parse_finite_seconds(s: &str) -> Result<f64, String> {
    let v: f64 = s.trim().parse().map_err(|e| format!("{s:?}: {e}"))?;
    if !v.is_finite() {
        return Err(format!("{s}: not a finite number of seconds"));
    }
    Ok(v)
}

/// `--origin LAT,LON`, degrees. Its options take a value that starts with a hyphen
/// (`allow_hyphen_values`): a southern latitude was taken for a flag (as a negative number is
/// by every numeric option without `allow_negative_numbers`), and clap's tip, `-- -33.86,...`,
/// did not work either.
fn parse_origin(s: &str) -> Result<(f64, f64), String> {
    let (lat, lon) = s
        .split_once(',')
        .ok_or_else(|| format!("expected LAT,LON, got {s:?}"))?;
    let lat: f64 = lat
        .trim()
        .parse()
        .map_err(|e| format!("latitude {lat:?}: {e}"))?;
    let lon: f64 = lon
        .trim()
        .parse()
        .map_err(|e| format!("longitude {lon:?}: {e}"))?;
    if !(-90.0..=90.0).contains(&lat) || !(-180.0..=180.0).contains(&lon) {
        return Err(format!("origin {lat},{lon} is not a WGS-84 position"));
    }
    Ok((lat, lon))
}

fn to_e7((lat, lon): (f64, f64)) -> (i32, i32) {
    ((lat * 1e7).round() as i32, (lon * 1e7).round() as i32)
}

fn main() -> ExitCode {
    quiet_on_a_closed_pipe();
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("catmodel: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// A reader that stops early (`catmodel identify-steering ... | head -3`) closes the pipe: the
/// tool then ends quietly with status 0, as `decode` already did for its own output. Rust's
/// runtime ignores SIGPIPE, so the next `println!` met the closed pipe and panicked ("failed
/// printing to stdout: Broken pipe"), exit status 101; restoring SIGPIPE's default instead
/// ended the tool with status 141, which fails a `set -o pipefail` script such as the
/// README's blocks.
fn quiet_on_a_closed_pipe() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let payload = info.payload();
        let message = payload
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| payload.downcast_ref::<&str>().copied())
            .unwrap_or("");
        // EPIPE is 32 on Linux and the BSDs (macOS included).
        if message.starts_with("failed printing to stdout") && message.contains("(os error 32)") {
            std::process::exit(0);
        }
        default(info);
    }));
}

/// Runs the subcommand the command line names.
fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::SimulateDrive(args) => simulate_drive(args),
        Command::Csv2can(args) => csv2can(args),
        Command::Replay(args) => replay(args),
        Command::Evaluate(args) => evaluate(args),
        Command::Identify(args) => identify(args),
        Command::IdentifySteering(args) => identify_steering(args),
        Command::ReceiverError(args) => receiver_error(args),
        Command::Compare(args) => compare(args),
        Command::ClosedLoop(args) => closed_loop(args),
        Command::DlcLimits(args) => dlc_limits(args),
        Command::Sil(args) => sil(args),
        Command::Decode(args) => decode(args),
        Command::Discretize(args) => discretize(args),
    }
}

/// Simulates a scenario on the plant and writes its log, candump and ground truth.
fn simulate_drive(args: SimulateDriveArgs) -> Result<()> {
    let SimulateDriveArgs {
        scenario,
        out,
        seed,
        vehicle,
        receiver,
        faults,
    } = args;
    let mut paths = Paths::new()
        .input_opt(vehicle.as_deref(), "--vehicle")
        .output(&out, "--out", Kind::Dir);
    for ext in ["csv", "can.log", "truth.csv"] {
        paths = paths.output(&out.join(format!("{scenario}.{ext}")), "--out", Kind::File);
    }
    paths.check()?;
    let options = sim::SimOptions {
        seed,
        faults,
        ..sim::SimOptions::default()
    };
    let receiver = catmodel_host::closed_loop::Receiver::from_name(&receiver)
        .ok_or_else(|| anyhow::anyhow!("unknown receiver `{receiver}`; known: standard, rtk"))?;
    let mut cfg = sim::load_vehicle(vehicle.as_deref()).map_err(|e| anyhow::anyhow!("{e}"))?;
    receiver.apply(&mut cfg.sensors.gnss);
    let progress = Progress::spinner(&format!("simulating {scenario}"));
    let output =
        sim::run_named_on(&scenario, &cfg, &options).map_err(|e| anyhow::anyhow!("{e}"))?;
    progress.set_message("writing");
    let (log_path, truth_path) =
        sim::write_outputs(&out, &scenario, &output).map_err(|e| anyhow::anyhow!("{e}"))?;
    let can_path = out.join(format!("{scenario}.can.log"));
    let encoded = csv2can::encode_log(&output.log)?;
    replay::write_file(&can_path, &csv2can::to_candump(&encoded.frames))?;
    progress.finish();
    if let Some(warning) = sim::slide_warning(&scenario, &output.truth, &cfg) {
        eprintln!("catmodel: warning: {warning}");
    }
    eprintln!(
        "wrote {}, {}, {}",
        log_path.display(),
        can_path.display(),
        truth_path.display()
    );
    Ok(())
}

/// Encodes a CSV log as the node's input frames, candump.
fn csv2can(args: Csv2canArgs) -> Result<()> {
    let Csv2canArgs { log, out } = args;
    Paths::new()
        .input(&log, "LOG")
        .output(&out, "--out", Kind::File)
        .check()?;
    let read = logcsv::read_log(&log).map_err(|e| anyhow::anyhow!("{e}"))?;
    print_notes(&read.notes.messages());
    print_warnings(&read.notes.warnings());
    if read.rows.is_empty() {
        // An empty candump would replay to nothing, with success: not a drive.
        bail!(
            "{}: no data rows (a header alone): a log with no rows is not a drive; \
             nothing written to {}",
            log.display(),
            out.display()
        );
    }
    let encoded =
        csv2can::encode_log(&read.rows).map_err(|e| anyhow::anyhow!("{}: {e}", log.display()))?;
    if let Some(note) = encoded.note() {
        print_notes(&[format!("{}: {note}", log.display())]);
    }
    // Sensors logged slower than the node's input timeouts: named as replay names them.
    let mut intervals = replay::ReportIntervals::steering_and_speed(
        &model_file::load(&model_file::paper_path())?.node_config(),
    );
    for f in &encoded.frames {
        replay::ReportIntervals::observe_frame(&mut intervals, &f.frame, f.t_us);
    }
    if let Some(note) = replay::slow_log_reports_note(&intervals) {
        print_notes(&[format!("{}: {note}", log.display())]);
    }
    replay::write_file(&out, &csv2can::to_candump(&encoded.frames))?;
    eprintln!("wrote {} frames to {}", encoded.frames.len(), out.display());
    Ok(())
}

/// Runs the node over a candump log and writes its predictions.
fn replay(args: ReplayArgs) -> Result<()> {
    let ReplayArgs {
        log,
        origin,
        out,
        tx_out,
        model,
        interface,
    } = args;
    Paths::new()
        .input(&log, "LOG")
        .input_opt(model.as_deref(), "--model")
        .output(&out, "--out", Kind::File)
        .output_opt(tx_out.as_deref(), "--tx-out", Kind::File)
        .check()?;
    let reading = Progress::spinner(&format!("reading {}", log.display()));
    let text = replay::read_bytes(&log)?;
    reading.finish();
    let mut config = catmodel_host::node_config(model.as_deref())?;
    config.origin_e7 = origin.map(to_e7);
    let declared_hz = 1.0 / f64::from(config.estimator.gnss_period_s);
    let still = config.estimator.course_min_speed_mps;
    let gnss_source = config.gnss_source;
    let (result, report) = replay_with_progress(
        &log,
        &text,
        interface.as_deref(),
        config,
        &out,
        tx_out.as_deref(),
    )?;
    replay::print_report(&log, &report);
    print_replay_counts(&result);
    print_replay_warnings(&result, &report, (declared_hz, gnss_source), still);
    Ok(())
}

/// Replays a log's bytes through the node under a progress bar, writing `out` (and `tx_out`).
fn replay_with_progress(
    log: &Path,
    text: &[u8],
    interface: Option<&str>,
    config: catmodel::node::NodeConfig,
    out: &Path,
    tx_out: Option<&Path>,
) -> Result<(replay::ReplayStats, replay::LogReport)> {
    let progress = Progress::bar(replay::estimate_ticks(text), "replay");
    let mut done = 0;
    // The log is parsed while the node runs; the files are written only if it all
    // parses.
    let replayed = replay::replay_file(log, text, interface, config, out, tx_out, |ticks| {
        progress.inc(ticks - done);
        done = ticks;
    })?;
    progress.finish();
    Ok(replayed)
}

/// What the replay read and rejected, on stderr: frames, ticks, the node's counters, and
/// what it refused of a planner's messages.
fn print_replay_counts(result: &replay::ReplayStats) {
    let c = result.counters;
    eprintln!(
        "replayed {} frames in {} ticks; rejected: crc {}, counter {}, dlc {}, range {}, gnss gate {}, gnss rate {}, unknown id {}, time {}; skipped: {} remote/FD/error frames",
        result.frames + result.filtered, result.ticks, c.crc_errors, c.counter_errors, c.dlc_errors,
        c.range_errors, c.gnss_gate_rejects, c.gnss_rate_mismatch, result.filtered + u64::from(c.unknown_ids), c.time_errors,
        result.unsupported
    );
    if result.rx_queue_drops > 0 {
        eprintln!(
            "catmodel: warning: {} frames were dropped by the full receive queue ({} frames), as \
             the firmware drops them (NODE_STATUS rx_queue_drops): the bus carried more frames \
             the acceptance filter admits than the node takes ({} a tick), e.g. a second GNSS \
             receiver or a gateway repeating the drive-by-wire's reports",
            result.rx_queue_drops,
            catmodel::node::RX_QUEUE_LEN,
            catmodel::node::MAX_RX_FRAMES_PER_TICK
        );
    }
    // Logs with a planner on the bus: what it sent and the node refused (NODE_STATUS
    // carries only a bit of it).
    if result.planner.counters != Default::default() {
        eprintln!("catmodel: {}", result.planner);
    }
}

/// The replay's warnings on stderr: the receiver's rate, the steering, the local frame's
/// reach, and why the node never had a position if it did not.
fn print_replay_warnings(
    result: &replay::ReplayStats,
    report: &replay::LogReport,
    (declared_hz, gnss_source): (f64, u8),
    still: f32,
) {
    let c = result.counters;
    if let Some(note) = catmodel_host::gnss_rate_note(&c, result.gnss_rate, declared_hz) {
        eprintln!("catmodel: warning: {note}");
    }
    if let Some(note) =
        catmodel_host::steering_note(&result.steering, Some(result.steering_mismatch_ticks))
    {
        eprintln!("catmodel: warning: {note}");
    }
    if let Some(note) = replay::frame_note(result) {
        eprintln!("catmodel: warning: {note}");
    }
    if let Some(note) = replay::speed_note(result) {
        eprintln!("catmodel: warning: {note}");
    }
    if let Some(note) = replay::direction_note(result) {
        eprintln!("catmodel: note: {note}");
    }
    if let Some(note) = replay::slow_reports_note(result) {
        eprintln!("catmodel: warning: {note}");
    }
    // No position at any tick (the rate's mismatch and the frame's reach have their
    // own warnings above): why, as far as the replay can tell.
    let other_sources = replay::other_sources_note(result, gnss_source);
    if let Some(note) = &other_sources {
        eprintln!("catmodel: warning: {note}");
    }
    let no_position = result.ticks > 0
        && result.valid_ticks == 0
        && c.gnss_rate_mismatch == 0
        && result.fixes_beyond_frame == 0
        && !(result.fixes == 0 && other_sources.is_some());
    let speed = &catmodel::can::spec::SPEED_REPORT;
    let speed_reports =
        catmodel::can::spec::node_input_index(speed.id).map_or(0, |i| report.inputs.classic[i]);
    if no_position && speed_reports == 0 {
        // Without speed reports the node's speed is 0 throughout: "the car never moved"
        // would blame the drive for what the log lacks.
        eprintln!(
            "catmodel: warning: the node had no valid position at any of the {} ticks: the log holds no {} ({}) the node could read, \
             and without the car's speed it has no dead reckoning to carry a position between fixes nor a course to take a heading from",
            result.ticks,
            speed.name,
            replay::id_text(speed.id)
        );
    } else if no_position && result.max_speed_mps < still {
        eprintln!(
            "catmodel: warning: the node had no valid position at any of the {} ticks: the car never moved (its speed stayed below {still} m/s, {:.2} m/s at most), so there is no heading from its course and no position. \
             A parked car's log measures the receiver (`catmodel receiver-error`), not the node",
            result.ticks, result.max_speed_mps
        );
    } else if no_position && report.timestamps.batched() {
        eprintln!(
            "catmodel: warning: the node had no valid position at any of the {} ticks: every prediction is \"not available\" ({} GNSS fixes refused by the gate): \
             the log's timestamps come in batches (the warning above), which bunch the fixes in time",
            result.ticks, c.gnss_gate_rejects
        );
    } else if no_position {
        eprintln!(
            "catmodel: warning: the node had no valid position at any of the {} ticks: every prediction is \"not available\" ({} GNSS fixes refused by the gate). \
             Check the model file's vehicle.gnss_rate_hz against the receiver: a slower one times out between its fixes",
            result.ticks, c.gnss_gate_rejects
        );
    }
}

/// Scores predictions against ground truth and the kinematic baseline.
fn evaluate(args: EvaluateArgs) -> Result<()> {
    let EvaluateArgs {
        predictions,
        truth,
        inputs,
        origin,
        model,
        json,
        plots,
    } = args;
    let (inputs, inputs_arg) = match inputs {
        Some(p) => (p, "--inputs"),
        None => match sibling_candump(&truth) {
            Some(p) => (p, "--inputs (its default)"),
            None => {
                // A truth with no sample is the first thing to fix, whatever its name: said
                // before the candump it cannot name.
                catmodel_host::read_truth(&truth)?;
                bail!(
                    "{}: cannot guess the candump of this truth file (not NAME.truth.csv); \
                     pass --inputs FILE.can.log",
                    truth.display()
                );
            }
        },
    };
    Paths::new()
        .input(&predictions, "PREDICTIONS")
        .input(&truth, "--truth")
        .input(&inputs, inputs_arg)
        .input_opt(model.as_deref(), "--model")
        .output_opt(json.as_deref(), "--json", Kind::File)
        .output_opt(plots.as_deref(), "--plots", Kind::Dir)
        .check()?;
    let model = model_file::load(&model.unwrap_or_else(model_file::paper_path))?;
    let car = catmodel_host::Car::from_model(&model);
    let origin = origin.unwrap_or(catmodel_host::SIM_ORIGIN_DEG);
    let progress = Progress::spinner("reading");
    let data = catmodel_host::EvaluationData::read(&predictions, &truth, &inputs, origin, car)?;
    let gap_warning = match data.truth.gaps() {
        (gaps @ 1.., total_s, Some((from, to))) => Some(format!(
            "catmodel: warning: {}: the truth has {gaps} gap(s) longer than {} s ({total_s:.1} s \
             in all, the longest from t = {from} to {to} s): nothing is scored within them (a \
             straight line across them is not where the car was)",
            truth.display(),
            catmodel_host::evaluate::TRUTH_GAP_S
        )),
        _ => None,
    };
    progress.set_message("evaluating");
    let e = data.evaluate();
    let e = match e {
        Ok(e) => e,
        Err(err) => {
            progress.finish();
            // The gaps first: they may be why nothing could be scored.
            if let Some(w) = gap_warning {
                eprintln!("{w}");
            }
            return Err(err);
        }
    };
    let written = match &plots {
        Some(dir) => {
            progress.set_message("plotting");
            data.write_plots(dir, &e)?
        }
        None => Vec::new(),
    };
    progress.finish();
    if let Some(w) = gap_warning {
        eprintln!("{w}");
    }
    if let Some(w) = data.coverage_warning(&e) {
        eprintln!("catmodel: warning: {w}");
    }
    print!("{}", evaluate::format_table(&e));
    if let Some(path) = json {
        replay::write_file(&path, &serde_json::to_string_pretty(&e)?)?;
    }
    for p in written {
        eprintln!("wrote {}", p.display());
    }
    Ok(())
}

/// Identifies the models from driving logs and writes the model file.
fn identify(args: IdentifyArgs) -> Result<()> {
    let IdentifyArgs {
        logs,
        validate,
        out,
        report,
        base,
        vehicle,
        force,
    } = args;
    Paths::new()
        .inputs(&logs, "LOGS")
        .inputs(&validate, "--validate")
        .input_opt(base.as_deref(), "--base")
        .input_opt(vehicle.as_deref(), "--vehicle")
        .output(&out, "--out", Kind::File)
        .output_opt(report.as_deref(), "--report", Kind::Dir)
        .check()?;
    let base = load_base(base.as_deref())?;
    let base = match vehicle {
        Some(car) => {
            let applied = identify::car::apply(&base, &car)?;
            print_notes(&applied.notes);
            applied.file
        }
        None => base,
    };
    let opts = identify::IdentifyOptions::default();
    let [training, validation] = read_identify_logs(&logs, &validate, &base, &opts)?;
    for e in training.iter().chain(&validation) {
        print_notes(&e.log_notes);
        print_warnings(&e.log_warnings);
    }
    // A receiver slower than a model file may declare: its track cannot judge the wheel
    // speed, and what would blame the wheel speed names the receiver instead.
    let slow = slow_receiver_problems(
        logs.iter().chain(&validate),
        training.iter().chain(&validation),
    );
    refuse_slow_receivers(&slow, &out, force)?;
    // A wheel speed the GNSS track contradicts (km/h, mph) identifies without a
    // word and a wrong model (review finding 04): refused before the minutes of fitting.
    let units = speed_unit_problems(
        logs.iter().chain(&validate),
        training.iter().chain(&validation),
    );
    refuse_speed_units(&units, &out, force)?;
    let mut id = fit_models(training, validation, &base, &opts)?;
    print!("{}", identify::summary(&id));
    // The report first: it is what shows why a model falls below the floor.
    if let Some(dir) = report {
        let index = identify::report::write_report(&dir, &id)?;
        eprintln!("wrote {}", index.display());
    }
    refuse_steering_problem(&id, &out, force)?;
    refuse_slow_speed_sensor(&id, &out, force)?;
    let violations = check_fit_floor(&id, &logs, &out, force)?;
    identify::floor::mark_forced(&mut id.model, &violations);
    // A refusal on logs this short names how little they hold (a black-box probe's 15 s
    // smoke drive was refused for a DC gain of 0.23, nothing said of its length).
    let seconds: f64 = id.training.iter().map(|e| e.len() as f64 * e.ts_s).sum();
    let little = (seconds < SHORT_TRAINING_S).then(|| {
        format!(
            " (the training logs hold {seconds:.0} s and {} speed step(s): too little to \
             determine the models? The paper-sized training set is seven logs of a minute, \
             29 speed steps)",
            id.steps
                .iter()
                .filter(|s| id.training.iter().any(|e| e.name == s.experiment))
                .count()
        )
    });
    write_identified_model(&out, &id.model, little.as_deref().unwrap_or_default())
}

/// Training logs shorter than this in all, s, are named with a refused model's reason.
const SHORT_TRAINING_S: f64 = 120.0;

/// Reads and preprocesses the training and validation logs under a progress bar.
fn read_identify_logs(
    logs: &[PathBuf],
    validate: &[PathBuf],
    base: &model_file::ModelFile,
    opts: &identify::IdentifyOptions,
) -> Result<[Vec<identify::preprocess::Experiment>; 2]> {
    let progress = indicatif::ProgressBar::new((logs.len() + validate.len()) as u64)
        .with_message("reading logs");
    let sets = identify::load_sets([logs, validate], &base.vehicle, &opts.preprocess, || {
        progress.inc(1)
    })?;
    progress.finish_and_clear();
    Ok(sets)
}

/// Refuses logs from a receiver slower than a model file may declare
/// ([`slow_receiver_problems`]) before fitting; with `--force`, warns and goes on.
fn refuse_slow_receivers(slow: &[String], out: &Path, force: bool) -> Result<()> {
    if slow.is_empty() {
        return Ok(());
    }
    let (lo, _) = model_file::GNSS_RATE_RANGE_HZ;
    if !force {
        bail!(
            "{}\n{} not written: {} log(s) from a receiver slower than {lo} Hz (--force \
             identifies anyway: the speed model needs no fix)",
            slow.join("\n"),
            out.display(),
            slow.len()
        );
    }
    for s in slow {
        eprintln!("catmodel: warning: {s} (identified anyway: --force)");
    }
    Ok(())
}

/// `FILE: why` for each log whose receiver is too slow for its track to be measured
/// ([`identify::slow_receiver`]).
fn slow_receiver_problems<'a>(
    paths: impl IntoIterator<Item = &'a PathBuf>,
    experiments: impl IntoIterator<Item = &'a identify::preprocess::Experiment>,
) -> Vec<String> {
    paths
        .into_iter()
        .zip(experiments)
        .filter_map(|(p, e)| Some(format!("{}: {}", p.display(), identify::slow_receiver(e)?)))
        .collect()
}

/// Refuses logs whose wheel speed is not in m/s ([`speed_unit_problems`]) before fitting;
/// with `--force`, warns and goes on.
fn refuse_speed_units(units: &[String], out: &Path, force: bool) -> Result<()> {
    if !units.is_empty() {
        if !force {
            bail!(
                "{}\n{} not written: the wheel speed is not the log schema's (m/s by \
                 the GNSS track, negative in reverse) or does not follow the track, or the \
                 command is not in m/s, in {} case(s) (--force identifies anyway)",
                units.join("\n"),
                out.display(),
                units.len()
            );
        }
        for u in units {
            eprintln!("catmodel: warning: {u} (identified anyway: --force)");
        }
    }
    Ok(())
}

/// Fits the models to the logs under a spinner.
fn fit_models(
    training: Vec<identify::preprocess::Experiment>,
    validation: Vec<identify::preprocess::Experiment>,
    base: &model_file::ModelFile,
    opts: &identify::IdentifyOptions,
) -> Result<identify::Identification> {
    let spinner = indicatif::ProgressBar::new_spinner().with_message("identifying");
    spinner.enable_steady_tick(std::time::Duration::from_millis(120));
    let id = identify::identify(training, validation, base, opts)?;
    spinner.finish_and_clear();
    Ok(id)
}

/// Refuses a training steering the fit found wrong; with `--force`, warns and goes on.
fn refuse_steering_problem(id: &identify::Identification, out: &Path, force: bool) -> Result<()> {
    // A steering of the other sign or in degrees (review finding 01) is the log's:
    // refused as the wheel speed's unit is; --force writes the file without [lateral].
    if let Some(why) = &id.steering_problem {
        if !force {
            bail!(
                "{why}\n{} not written: the training logs' `steer` is not the log \
                 schema's (--force writes the file without [lateral])",
                out.display()
            );
        }
        eprintln!("catmodel: warning: {why} (identified anyway, without [lateral]: --force)");
    }
    Ok(())
}

/// Refuses a speed model whose delay the logs' speed rate cannot time
/// ([`identify::Identification::slow_sensor_problem`]); with `--force`, warns and goes on.
fn refuse_slow_speed_sensor(id: &identify::Identification, out: &Path, force: bool) -> Result<()> {
    if let Some(why) = &id.slow_sensor_problem {
        if !force {
            bail!(
                "{why}\n{} not written: the training logs' speed is logged too slowly for its \
                 delay (--force writes it anyway)",
                out.display()
            );
        }
        eprintln!("catmodel: warning: {why} (identified anyway: --force)");
    }
    Ok(())
}

/// Warns of each fit below the floor, with the training log's line that stands out if one
/// does; refuses them unless `--force`. Returns them for the file's warning.
fn check_fit_floor(
    id: &identify::Identification,
    logs: &[PathBuf],
    out: &Path,
    force: bool,
) -> Result<Vec<identify::floor::FloorViolation>> {
    let violations = identify::floor::check(id);
    for v in &violations {
        eprintln!("catmodel: warning: {v}");
        if let Some((path, line, value)) = v.suspect.as_ref().and_then(|s| locate_suspect(s, logs))
        {
            eprintln!(
                "catmodel: warning: {}:{line}: this line's value {value} stands out",
                path.display()
            );
        }
    }
    if !violations.is_empty() && !force {
        let undefined = violations
            .iter()
            .filter(|v| v.fit_percent.is_none())
            .count();
        let below = violations.len() - undefined;
        let counted = match (below, undefined) {
            (_, 0) => format!(
                "{below} fit(s) below the {} % floor",
                identify::floor::FIT_FLOOR_PERCENT
            ),
            (0, _) => format!("{undefined} fit(s) undefined"),
            _ => format!(
                "{below} fit(s) below the {} % floor and {undefined} undefined",
                identify::floor::FIT_FLOOR_PERCENT
            ),
        };
        bail!(
            "{} not written: {counted} (see the warnings above; --force writes it anyway, with the warning in the file)",
            out.display(),
        );
    }
    Ok(violations)
}

/// Writes the identified model file, if the model file's reader accepts it.
fn write_identified_model(out: &Path, model: &model_file::ModelFile, hint: &str) -> Result<()> {
    // Only a file every reader loads is written (the firmware build's too): a model
    // the reader refuses (an unstable pole, an absurd gain) is named, not saved.
    model_file::parse(&model_file::to_toml(model), out).map_err(|e| {
        // A command in km/h or mph is refused by the speed model's gain: named as the unit.
        let unit = model
            .speed
            .blocks
            .iter()
            .find(|b| b.input == "input_vel")
            .and_then(|b| b.tf.dc_gain().ok())
            .and_then(identify::units::command_unit_problem)
            .map(|why| format!(": {why}"))
            .unwrap_or_default();
        anyhow::anyhow!(
            "{} not written: the identified model is refused: {}{unit}{hint}",
            out.display(),
            e.message
        )
    })?;
    model_file::save(out, model).map_err(|e| anyhow::anyhow!("writing {}: {e}", out.display()))?;
    eprintln!("wrote {}", out.display());
    Ok(())
}

/// Fits the steering actuator's lag and rate limit from a session's candump logs.
fn identify_steering(args: IdentifySteeringArgs) -> Result<()> {
    use identify::steering::RateLimit;
    let IdentifySteeringArgs {
        logs,
        model,
        from,
        interface,
    } = args;
    Paths::new()
        .inputs(&logs, "LOGS")
        .input_opt(model.as_deref(), "--model")
        .check()?;
    let file_rate = match &model {
        Some(p) => Some(model_file::load(p)?.vehicle.max_steer_rate_pct_per_s),
        None => None,
    };
    let mut read = Vec::new();
    for log in &logs {
        let at = replay::AtPause::Split(
            "identify-steering fits the stretches between such gaps in the reports and commands, never across one",
        );
        let frames = replay::read_candump_reporting_at(log, interface.as_deref(), at)?.frames;
        read.push((log.display().to_string(), frames));
    }
    let named: Vec<(String, &[catmodel::can::frame::TimedFrame])> = read
        .iter()
        .map(|(name, frames)| (name.clone(), frames.as_slice()))
        .collect();
    let series = identify::steering::SteeringSeries::from_logs(&named)?;
    let f = identify::steering::fit(&series, file_rate, from)?;
    if let Some((gap_from, gap_to)) = f.longest_gap {
        eprintln!(
            "catmodel: note: the session was fitted in {} stretches, apart, never across a gap: \
             {} gap(s) in the reports or the commands (more than {} of their median intervals \
             and {} s), the longest {:.1} s (from t = {gap_from:.3} to {gap_to:.3} s); {:.1} s \
             of reports fitted",
            f.stretches,
            f.gaps,
            identify::steering::GAP_PERIODS,
            identify::steering::MIN_GAP_S,
            gap_to - gap_from,
            f.fitted_s
        );
    }
    println!(
        "steering actuator: {} reports and {} commands from {:.2} s to {:.2} s{} (commands over {:.1} %)",
        f.reports,
        f.commands,
        f.from_s,
        f.to_s,
        if f.stretches > 1 {
            format!(" in {} stretches, {:.1} s of them", f.stretches, f.fitted_s)
        } else {
            String::new()
        },
        f.span_pct
    );
    if series.rejected > 0 {
        println!(
            "  {} frames of the two messages rejected (CRC, range, length)",
            series.rejected
        );
    }
    match f.rate {
        RateLimit::Measured {
            pct_per_s,
            rms_unlimited_pct,
        } => {
            println!(
                "  rate limit {pct_per_s:.1} %/s (report error RMS {rms_unlimited_pct:.2} % without a limit)"
            );
            if let Some(r) = file_rate.filter(|r| (pct_per_s / r - 1.0).abs() > 0.1) {
                println!(
                    "  warning: the model file says {r} %/s: the steering does not move at that rate"
                );
            }
        }
        RateLimit::NotShown { at_least_pct_per_s } => {
            let used = match file_rate {
                Some(r) => format!("the model file's {r} %/s used"),
                None => "fitted with no limit".to_string(),
            };
            println!(
                "  rate limit not shown: the commands never asked for more than the steering gave (it moved at up to {at_least_pct_per_s:.1} %/s, so the limit is at least that); {used}"
            );
            if let Some(r) = file_rate.filter(|r| *r < at_least_pct_per_s) {
                println!("  warning: the model file says {r} %/s, slower than the steering moved");
            }
        }
    }
    println!(
        "  lag {:.3} s and delay {:.3} s: the steering trails a ramp by {:.3} s; report error RMS {:.2} % ({:.2} % with neither)",
        f.lag_s,
        f.delay_s,
        f.trail_s(),
        f.rms_pct,
        f.rms_without_pct
    );
    let trail = f.trail_s();
    if f.lag_s >= identify::steering::MAX_LAG_S - 1e-6
        || f.delay_s >= identify::steering::MAX_DELAY_S - 1e-6
    {
        println!(
            "  warning: the fit is at the edge of its search (a lag up to {} s, a delay up to {} \
             s): the steering trails a ramp by {trail:.3} s or more, and the rate limit fitted \
             beside it may stand in for the rest",
            identify::steering::MAX_LAG_S,
            identify::steering::MAX_DELAY_S
        );
    }
    if f.rms_pct > STEERING_FIT_EXPLAINS * f.rms_without_pct {
        println!(
            "  warning: the lag, delay and rate limit take only {:.0} % of the reports' error \
             away ({:.2} % of {:.2} %): this session does not determine them (another actuator \
             than a rate-limited lag, or reports that trail far behind)",
            100.0 * (1.0 - f.rms_pct / f.rms_without_pct),
            f.rms_pct,
            f.rms_without_pct
        );
    }
    println!("  for the car's model file, [vehicle]:");
    if let RateLimit::Measured { pct_per_s, .. } = f.rate {
        println!("  max_steer_rate_pct_per_s = {pct_per_s:.1}");
    }
    let max_lag = model_file::STEER_LAG_RANGE_S.1;
    if trail > max_lag {
        println!(
            "  steer_lag_s = {max_lag:.3}  # the most the model file takes: the steering trails \
             by {trail:.3} s, longer than the controller's command can lead its plan by; the \
             car will follow its plans late"
        );
    } else {
        println!("  steer_lag_s = {trail:.3}");
    }
    Ok(())
}

/// `identify-steering` warns when its fit leaves more than this share of the error it starts
/// from (neither lag nor delay): a good fit leaves the reports' noise (0.2 % RMS on the
/// built-in plant, a tenth of a ramp's error or less).
const STEERING_FIT_EXPLAINS: f64 = 0.5;

/// Measures the GNSS receiver's error from candump logs of the car parked.
fn receiver_error(args: ReceiverErrorArgs) -> Result<()> {
    use identify::receiver::{AVERAGE_S, MIN_INDEPENDENT, MIN_LOG_S, SIGMAS};
    let ReceiverErrorArgs {
        logs,
        model,
        interface,
    } = args;
    Paths::new()
        .inputs(&logs, "LOGS")
        .input_opt(model.as_deref(), "--model")
        .check()?;
    let file = load_base(model.as_deref())?;
    let source = file.inputs.gnss_source_address;
    let mut read = Vec::new();
    for log in &logs {
        let at = replay::AtPause::Split(
            "receiver-error measures the fixes in stretches between such gaps, never across one",
        );
        read.push(replay::read_candump_reporting_at(log, interface.as_deref(), at)?.frames);
    }
    let r =
        identify::receiver::measure(&read.iter().map(Vec::as_slice).collect::<Vec<_>>(), source)?;
    if r.stretches > 1 {
        let gaps = match r.longest_gap {
            Some((log, from, to)) => format!(
                "; {} gap(s) between fixes within a log (more than {} of the receiver's \
                 intervals and {} s), the longest {:.1} s in {} (from t = {from:.3} to \
                 {to:.3} s)",
                r.gaps,
                identify::receiver::GAP_PERIODS,
                identify::receiver::MIN_GAP_S,
                to - from,
                logs[log].display()
            ),
            None => String::new(),
        };
        eprintln!(
            "catmodel: note: the fixes were measured in {} stretches, apart: {} log(s){gaps}; \
             the receiver's rate is counted, the fixes averaged over {AVERAGE_S} s and their \
             correlation taken within each stretch, pooled over them, each log's fixes about \
             its own mean; {:.1} s of fixes (pauses and the time between logs not counted)",
            r.stretches, r.logs, r.duration_s
        );
    }
    let parked = match r.speed_reports {
        0 => "no speed reports: the car is taken to be parked".to_string(),
        n => format!("{n} speed reports, all parked"),
    };
    println!(
        "receiver at source address {source}: {} fixes over {:.1} s{} (one every {:.3} s); {parked}{}",
        r.fixes,
        r.duration_s,
        if r.stretches > 1 {
            format!(" in {} stretches", r.stretches)
        } else {
            String::new()
        },
        r.interval_s,
        if r.rejected > 0 {
            format!("; {} fixes rejected (not available, range)", r.rejected)
        } else {
            String::new()
        }
    );
    for (name, a) in [("east", r.east), ("north", r.north)] {
        let tau = a
            .correlation_s
            .map_or("not determined".to_string(), |t| format!("{t:.1} s"));
        println!(
            "  {name}: deviation {:.3} m, averaged over {AVERAGE_S} s {:.3} m, correlation time {tau}",
            a.sigma_m, a.slow_sigma_m
        );
    }
    match r.independent {
        Some(n) => println!("  the log holds about {n:.0} independent values of the bias"),
        None => println!("  the error did not forget itself within a quarter of the log"),
    }
    if r.long_enough() {
        println!(
            "  for the car's model file, [control] ({SIGMAS} standard deviations of the averaged error):"
        );
        println!("  position_uncertainty_m = {:.1}", r.uncertainty_m());
    } else {
        let need = r.log_needed_s().map_or("far longer".to_string(), |t| {
            format!(
                "at least {:.0} minutes ({MIN_INDEPENDENT} independent values of the bias, and {:.0} minutes at least)",
                (t / 60.0).ceil(),
                MIN_LOG_S / 60.0
            )
        });
        println!(
            "  not determined: too short a log to bound the bias ({SIGMAS} standard deviations would be {:.1} m now); record the car parked for {need}",
            r.uncertainty_m()
        );
    }
    Ok(())
}

/// Simulates a model file's models over one log beside the kinematic model.
fn compare(args: CompareArgs) -> Result<()> {
    let CompareArgs { log, model, out } = args;
    Paths::new()
        .input(&log, "LOG")
        .input(&model, "--model")
        .output_opt(out.as_deref(), "--out", Kind::File)
        .check()?;
    let file = model_file::load(&model)?;
    let opts = identify::preprocess::PreprocessOptions::default();
    let e = identify::preprocess::load_experiment(&log, &file.vehicle, &opts)?;
    print_notes(&e.log_notes);
    print_warnings(&e.log_warnings);
    for s in slow_receiver_problems([&log], [&e]) {
        eprintln!(
            "catmodel: warning: {s}: the scores below that the track measures (dx/dt, the yaw \
             rate) are the receiver's as much as the models'"
        );
    }
    for u in speed_unit_problems([&log], [&e]) {
        eprintln!("catmodel: warning: {u}: the scores below compare models in m/s with it");
    }
    if let Some(why) = identify::steering_problem(std::slice::from_ref(&e), &file.vehicle) {
        eprintln!(
            "catmodel: warning: {}: {why}: the yaw-rate scores below compare the model's \
             steering with it",
            log.display()
        );
    }
    let sim = identify::validate::simulate_all(&file, &e)?;
    let scores = identify::validate::scores(std::slice::from_ref(&e), std::slice::from_ref(&sim));
    print!(
        "{}",
        identify::validate::format_tables(
            &format!("{} with {}", log.display(), model.display()),
            &scores
        )
    );
    if let Some(path) = out {
        replay::write_file(&path, &identify::validate::compare_csv(&e, &sim))?;
    }
    Ok(())
}

/// Runs the plant, the node and its controller on one bus over a scenario.
fn closed_loop(args: ClosedLoopArgs) -> Result<()> {
    let ClosedLoopArgs {
        scenario,
        controller,
        vehicle,
        model,
        receiver,
        speed,
        seed,
        replan_every,
        start_offset,
        faults,
        out,
    } = args;
    let mut paths = Paths::new()
        .input_opt(vehicle.as_deref(), "--vehicle")
        .input_opt(model.as_deref(), "--model")
        .output(&out, "--out", Kind::Dir);
    for name in catmodel_host::closed_loop::SESSION_FILES {
        paths = paths.output(&out.join(name), "--out", Kind::File);
    }
    paths.check()?;
    let progress = Progress::spinner(&format!("closed loop: {scenario}"));
    let (metrics, written) =
        catmodel_host::closed_loop::command(&catmodel_host::closed_loop::ClosedLoopArgs {
            scenario,
            controller,
            vehicle,
            model,
            receiver,
            speed_mps: speed,
            seed,
            replan_s: replan_every,
            start_offset_m: start_offset,
            faults,
            out,
        })?;
    progress.finish();
    if metrics.driven_time_s == 0.0 {
        eprintln!(
            "catmodel: warning: the node never took the car over from the launch driver \
             (no CONTROL_COMMAND to drive: no position, speed model or settled heading; the \
             session's NODE_STATUS frames say which): nothing of this run is the \
             controller's, and it is not completed"
        );
    }
    println!("{}", serde_json::to_string_pretty(&metrics)?);
    for p in written {
        eprintln!("wrote {}", p.display());
    }
    Ok(())
}

/// Finds one car's double lane change speed limits and prints them as JSON.
fn dlc_limits(args: DlcLimitsArgs) -> Result<()> {
    let DlcLimitsArgs {
        controllers,
        optimal,
        vehicle,
        model,
        json,
        plots,
    } = args;
    Paths::new()
        .input_opt(vehicle.as_deref(), "--vehicle")
        .input_opt(model.as_deref(), "--model")
        .output_opt(json.as_deref(), "--json", Kind::File)
        .output_opt(plots.as_deref(), "--plots", Kind::Dir)
        .check()?;
    let progress = Progress::spinner("searching the double lane change's limits");
    let (cfg, node) = catmodel_host::closed_loop::load_setup(vehicle.as_deref(), model.as_deref())?;
    let limits =
        catmodel_host::closed_loop::limits::dlc_limits(&cfg, &node, &controllers, optimal)?;
    progress.finish();
    let text = serde_json::to_string_pretty(&limits)?;
    println!("{text}");
    // The figures' directory first: `--json` may name a file in it.
    if let Some(dir) = &plots {
        std::fs::create_dir_all(dir)
            .map_err(|e| anyhow::anyhow!("creating {}: {e}", dir.display()))?;
    }
    if let Some(path) = json {
        replay::write_file(&path, &text)?;
    }
    if let (Some(dir), Some(v)) = (plots, limits.optimal_mps) {
        use catmodel_host::closed_loop::{optimal, plots};
        let track = optimal::TrackAtSpeed::new(&cfg, v);
        let rows = track.record(&limits.optimal_profile_pct);
        for p in plots::write_optimal_plots(&dir, track.course(), &cfg.body, v, &rows)? {
            eprintln!("wrote {}", p.display());
        }
    }
    Ok(())
}

/// Runs the node in lockstep over stdin/stdout (software in the loop).
fn sil(args: SilArgs) -> Result<()> {
    let SilArgs {
        stdio: _,
        model,
        origin,
    } = args;
    let mut config = catmodel_host::node_config(model.as_deref())?;
    config.origin_e7 = origin.map(to_e7);
    // The node exactly as the model file configures it, controller included.
    let mut driver = catmodel_host::closed_loop::driver::NodeDriver::new(
        config,
        catmodel_host::closed_loop::driver::Controller::FromModel,
    );
    let stdin = std::io::stdin().lock();
    let stdout = std::io::BufWriter::new(std::io::stdout().lock());
    let summary = catmodel_host::sil::run(&mut driver, stdin, stdout)?;
    eprintln!("sil: {summary}");
    if let Some(w) = summary.timestamps.warning("stdin") {
        eprintln!("sil: warning: {w}");
    }
    if let Some(note) = catmodel_host::closed_loop::driver::Driver::gnss_rate_note(&driver) {
        eprintln!("sil: warning: {note}");
    }
    if let Some(note) = catmodel_host::closed_loop::driver::Driver::steering_note(&driver) {
        eprintln!("sil: warning: {note}");
    }
    Ok(())
}

/// Decodes a candump log with catmodel.dbc.
fn decode(args: DecodeArgs) -> Result<()> {
    let DecodeArgs {
        log,
        messages,
        csv,
        interface,
    } = args;
    let format = if csv {
        decode::Format::Csv
    } else {
        decode::Format::Table
    };
    decode::run(&log, interface.as_deref(), &messages, format)
}

/// Prints the discrete state-space matrices of a model file's blocks as JSON.
fn discretize(args: DiscretizeArgs) -> Result<()> {
    let DiscretizeArgs { model, ts } = args;
    let file = model_file::load(&model)?;
    let d = identify::discretize::discretize_file(&file, ts)?;
    println!("{}", serde_json::to_string_pretty(&d)?);
    Ok(())
}

/// `FILE: why` for each log whose wheel speed its GNSS track says is not in m/s
/// ([`identify::units::SpeedScale::problem`]), or that stays positive while the car is asked
/// to reverse ([`identify::units::unsigned_reverse`]).
fn speed_unit_problems<'a>(
    paths: impl IntoIterator<Item = &'a PathBuf>,
    experiments: impl IntoIterator<Item = &'a identify::preprocess::Experiment>,
) -> Vec<String> {
    paths
        .into_iter()
        .zip(experiments)
        .flat_map(|(p, e)| {
            let unit = e.speed_scale.and_then(|s| s.problem());
            // A wheel speed in another unit disagrees everywhere: named once, as the unit. A
            // receiver too slow for its track to judge the wheel speed by makes it disagree
            // on every turn: named as the receiver's ([`slow_receiver_problems`]).
            let stuck = e
                .speed_disagreement
                .filter(|_| unit.is_none() && identify::slow_receiver(e).is_none())
                .map(|d| d.problem());
            let sign = identify::units::unsigned_reverse(e);
            [unit, stuck, sign, e.command_unit.clone()]
                .into_iter()
                .flatten()
                .map(move |problem| format!("{}: {problem}", p.display()))
        })
        .collect()
}

/// The training log and line behind a suspect sample of the fit floor, with its value.
fn locate_suspect(
    suspect: &identify::floor::Suspect,
    logs: &[PathBuf],
) -> Option<(PathBuf, usize, f64)> {
    let path = logs.iter().find(|p| {
        p.file_name()
            .and_then(|n| n.to_str())
            .is_some_and(|n| n.trim_end_matches(".csv") == suspect.log)
    })?;
    let log = logcsv::read_log(path).ok()?;
    let (line, value) = identify::floor::locate(suspect, &log)?;
    Some((path.clone(), line, value))
}

/// What reading a file noticed without refusing it, on stderr: `catmodel: note: FILE[:LINE]: ...`.
fn print_notes(notes: &[String]) {
    for n in notes {
        eprintln!("catmodel: note: {n}");
    }
}

/// What reading a file found worth a warning, on stderr: `catmodel: warning: FILE:LINE: ...`.
fn print_warnings(warnings: &[String]) {
    for w in warnings {
        eprintln!("catmodel: warning: {w}");
    }
}

/// `NAME.truth.csv` -> `NAME.can.log`; `None` for a truth file named otherwise.
fn sibling_candump(truth: &Path) -> Option<PathBuf> {
    let name = truth.file_name().and_then(|n| n.to_str())?;
    let stem = name.strip_suffix(".truth.csv")?;
    Some(truth.with_file_name(format!("{stem}.can.log")))
}
