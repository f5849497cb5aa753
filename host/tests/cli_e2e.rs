//! End to end: the built `catmodel` binary on the smoke drive (15 s).
//! simulate-drive -> csv2can (equal to the written .can.log) -> replay -> evaluate (JSON, plots),
//! determinism for a seed, the bundled data's reproducibility, and bad input (file:line, exit
//! status).
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const BIN: &str = env!("CARGO_BIN_EXE_catmodel");
const ORIGIN: &str = "32.2319,-110.9501";

/// A fresh directory under cargo's per-test tmp dir.
fn tmp_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("cli_e2e_{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("data")
        .join(name)
}

fn run(args: &[&str]) -> Output {
    Command::new(BIN).args(args).output().unwrap()
}

/// Runs and requires success; returns stderr.
fn ok(args: &[&str]) -> String {
    let out = run(args);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "catmodel {args:?} failed:\n{stderr}");
    stderr
}

/// Runs and requires failure; returns stderr.
fn fails(args: &[&str]) -> String {
    let out = run(args);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(
        out.status.code(),
        Some(1),
        "catmodel {args:?} should fail:\n{stderr}"
    );
    assert!(stderr.starts_with("catmodel: error: "), "{stderr}");
    stderr
}

/// `catmodel replay LOG --origin ORIGIN --out OUT`, which must succeed; its stderr.
fn replay_at_origin(log: &Path, out: &Path) -> String {
    ok(&["replay", s(log), "--origin", ORIGIN, "--out", s(out)])
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn read(p: &Path) -> Vec<u8> {
    std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Well-formed XML as plotters writes it: balanced tags, one `<svg>` root.
fn assert_well_formed_svg(text: &str, path: &Path) {
    assert!(
        text.starts_with("<svg"),
        "{}: no <svg> root",
        path.display()
    );
    let mut stack: Vec<&str> = Vec::new();
    let mut rest = text;
    let mut elements = 0;
    while let Some(open) = rest.find('<') {
        let close = rest[open..]
            .find('>')
            .unwrap_or_else(|| panic!("{}: unterminated tag", path.display()))
            + open;
        let tag = &rest[open + 1..close];
        if tag.starts_with('?') || tag.starts_with('!') {
        } else if let Some(name) = tag.strip_prefix('/') {
            assert_eq!(stack.pop(), Some(name.trim()), "{}", path.display());
        } else {
            elements += 1;
            let name = tag.split_whitespace().next().unwrap_or("");
            assert!(!name.is_empty(), "{}: empty tag", path.display());
            if !tag.ends_with('/') {
                stack.push(name);
            }
        }
        // Text between tags must not hold a raw '<' (checked by the find above) or '&' that
        // does not start an entity.
        rest = &rest[close + 1..];
        let text_end = rest.find('<').unwrap_or(rest.len());
        for (i, _) in rest[..text_end].match_indices('&') {
            let ent = &rest[i..text_end];
            assert!(
                ["&amp;", "&lt;", "&gt;", "&quot;", "&apos;", "&#"]
                    .iter()
                    .any(|e| ent.starts_with(e)),
                "{}: bare & in text",
                path.display()
            );
        }
        if stack.is_empty() {
            assert!(
                rest.trim().is_empty(),
                "{}: content after </svg>",
                path.display()
            );
            break;
        }
    }
    assert!(stack.is_empty(), "{}: unclosed {stack:?}", path.display());
    assert!(
        elements > 20,
        "{}: only {elements} elements",
        path.display()
    );
}

#[test]
fn smoke_drive_through_every_command() {
    let dir = tmp_dir("pipeline");
    let (sim_a, sim_b) = (dir.join("a"), dir.join("b"));

    // simulate-drive, twice with the same seed: identical bytes.
    let msg = ok(&["simulate-drive", "--scenario", "smoke", "--out", s(&sim_a)]);
    assert!(msg.contains("smoke.can.log"), "{msg}");
    ok(&[
        "simulate-drive",
        "--scenario",
        "smoke",
        "--seed",
        "0",
        "--out",
        s(&sim_b),
    ]);
    for f in ["smoke.csv", "smoke.can.log", "smoke.truth.csv"] {
        assert_eq!(read(&sim_a.join(f)), read(&sim_b.join(f)), "{f} differs");
    }
    // Another seed is another repetition.
    ok(&[
        "simulate-drive",
        "--scenario",
        "smoke",
        "--seed",
        "3",
        "--out",
        s(&dir.join("c")),
    ]);
    assert_ne!(
        read(&sim_a.join("smoke.csv")),
        read(&dir.join("c").join("smoke.csv"))
    );

    // csv2can of the log equals the candump simulate-drive wrote.
    let can = dir.join("csv2can.can.log");
    let msg = ok(&["csv2can", s(&sim_a.join("smoke.csv")), "--out", s(&can)]);
    assert!(msg.contains("frames"), "{msg}");
    assert_eq!(read(&can), read(&sim_a.join("smoke.can.log")));

    // replay: predictions for every tick, the node's frames, nothing rejected.
    let pred = dir.join("pred.csv");
    let tx = dir.join("tx.log");
    let msg = ok(&[
        "replay",
        s(&sim_a.join("smoke.can.log")),
        "--origin",
        ORIGIN,
        "--out",
        s(&pred),
        "--tx-out",
        s(&tx),
    ]);
    assert!(
        msg.contains(
            "crc 0, counter 0, dlc 0, range 0, gnss gate 0, gnss rate 0, unknown id 0, time 0"
        ),
        "{msg}"
    );
    let pred_text = String::from_utf8(read(&pred)).unwrap();
    assert!(pred_text.starts_with("t,step,horizon_s,x,y,heading,speed,mode\n"));
    let horizon0 = pred_text
        .lines()
        .filter(|l| l.split(',').nth(2) == Some("0.00"))
        .count();
    // 15 s at 50 Hz = 750 ticks, minus those before the node knows its heading (it needs the
    // car to move: about 4 s in this drive).
    assert!((500..=751).contains(&horizon0), "{horizon0} ticks");
    // Every tx line is a valid candump line of one of our IDs.
    let tx_text = String::from_utf8(read(&tx)).unwrap();
    assert!(tx_text.lines().count() > 10 * horizon0);
    for l in tx_text.lines().take(200) {
        let f = catmodel::can::candump::parse_line(l).unwrap();
        let catmodel::can::CanId::Standard(id) = f.frame.id else {
            panic!("{l}")
        };
        assert!((0x300..=0x3F0).contains(&id), "{l}");
    }

    // evaluate: table, JSON and plots (inputs found beside the truth file).
    let json = dir.join("eval.json");
    let plots = dir.join("plots");
    let out = run(&[
        "evaluate",
        s(&pred),
        "--truth",
        s(&sim_a.join("smoke.truth.csv")),
        "--json",
        s(&json),
        "--plots",
        s(&plots),
    ]);
    assert!(out.status.success(), "{:?}", out);
    let table = String::from_utf8(out.stdout).unwrap();
    assert!(table.starts_with("raw GNSS position error"), "{table}");
    // Raw GNSS, raw GNSS at the axle, the bias floor, the header, 11 horizons.
    assert_eq!(table.lines().count(), 4 + 11, "{table}");

    let e: serde_json::Value = serde_json::from_slice(&read(&json)).unwrap();
    let horizons = e["horizons"].as_array().unwrap();
    assert_eq!(horizons.len(), 11);
    let at = |h: f64| {
        horizons
            .iter()
            .find(|r| (r["horizon_s"].as_f64().unwrap() - h).abs() < 1e-9)
            .unwrap_or_else(|| panic!("no horizon {h}"))
    };
    // Every tick compared, but for the last one or two past the end of the truth record.
    let compared = e["ticks"].as_u64().unwrap() as usize;
    assert!(
        compared <= horizon0 && compared + 3 >= horizon0,
        "{compared}"
    );
    let raw = e["raw_gnss"]["pos_rms_m"].as_f64().unwrap();
    // 100 Hz GNSS over 15 s, its error in the receiver's range (about 1.2 m plus bias).
    assert!(e["raw_gnss"]["count"].as_u64().unwrap() > 1400);
    assert!((0.5..5.0).contains(&raw), "raw GNSS RMS {raw}");
    // 1 s ahead, the node beats the kinematic baseline fed with raw GNSS.
    let node_1s = at(1.0)["node"]["pos_rms_m"].as_f64().unwrap();
    let base_1s = at(1.0)["baseline"]["pos_rms_m"].as_f64().unwrap();
    assert!(
        node_1s < base_1s,
        "1 s: node {node_1s} m vs baseline {base_1s} m"
    );
    // And its heading is far better than the raw-track heading.
    let node_h = at(1.0)["node"]["heading_rms_rad"].as_f64().unwrap();
    let base_h = at(1.0)["baseline"]["heading_rms_rad"].as_f64().unwrap();
    assert!(node_h < base_h, "heading {node_h} vs {base_h}");
    // Errors grow with the horizon for both (2 s worse than 0.2 s).
    for who in ["node", "baseline"] {
        let e02 = at(0.2)[who]["pos_rms_m"].as_f64().unwrap();
        let e2 = at(2.0)[who]["pos_rms_m"].as_f64().unwrap();
        assert!(e2 > e02, "{who}: {e02} at 0.2 s, {e2} at 2 s");
    }

    // The plots: four well-formed SVG files with their titles and legends as text.
    let stderr = String::from_utf8(out.stderr).unwrap();
    for (file, must_contain) in [
        ("path.svg", "truth"),
        ("error_vs_horizon.svg", "kinematic baseline"),
        ("gnss_window.svg", "raw GNSS"),
        ("position_error_time.svg", "filtered"),
    ] {
        let p = plots.join(file);
        assert!(stderr.contains(file), "{stderr}");
        let text = String::from_utf8(read(&p)).unwrap();
        assert_well_formed_svg(&text, &p);
        assert!(text.contains(must_contain), "{file}");
        assert!(text.contains("<text"), "{file}: no text elements");
        assert!(text.len() < 1_000_000, "{file}: {} bytes", text.len());
    }

    // Replaying again gives the same bytes.
    let pred2 = dir.join("pred2.csv");
    replay_at_origin(&sim_a.join("smoke.can.log"), &pred2);
    assert_eq!(read(&pred), read(&pred2));
}

/// data/ is what `scripts/gen-data.sh` writes: the smoke drive and its bundled copy.
#[test]
fn bundled_smoke_drive_is_reproducible() {
    let dir = tmp_dir("bundled");
    ok(&["simulate-drive", "--scenario", "smoke", "--out", s(&dir)]);
    for f in ["smoke.csv", "smoke.can.log", "smoke.truth.csv"] {
        assert!(read(&dir.join(f)) == read(&data(f)), "data/{f} is stale");
    }
    assert!(read(&data("bundled.can.log")) == read(&data("smoke.can.log")));
    // The second drive: the first 30 s of turn-left (the header and rows with t <= 30, as
    // scripts/gen-data.sh cuts them with awk).
    ok(&[
        "simulate-drive",
        "--scenario",
        "turn-left",
        "--out",
        s(&dir),
    ]);
    for (full, cut) in [
        ("turn-left.csv", "turn-left-30s.csv"),
        ("turn-left.truth.csv", "turn-left-30s.truth.csv"),
    ] {
        let text = String::from_utf8(read(&dir.join(full))).unwrap();
        let mut kept = String::new();
        for (i, l) in text.lines().enumerate() {
            let t: f64 = l.split(',').next().unwrap().parse().unwrap_or(0.0);
            if i == 0 || t <= 30.0 {
                kept.push_str(l);
                kept.push('\n');
            }
        }
        assert!(kept.as_bytes() == read(&data(cut)), "data/{cut} is stale");
    }
    // Its candump is csv2can of its log.
    let can = dir.join("turn.can.log");
    ok(&["csv2can", s(&data("turn-left-30s.csv")), "--out", s(&can)]);
    assert!(read(&can) == read(&data("turn-left-30s.can.log")));
}

/// Writes `lines` of the smoke candump with line `n` (1-based) replaced.
fn edited_candump(dir: &Path, name: &str, n: usize, replacement: &str) -> PathBuf {
    let text = String::from_utf8(read(&data("smoke.can.log"))).unwrap();
    let mut lines: Vec<&str> = text.lines().collect();
    lines[n - 1] = replacement;
    let path = dir.join(name);
    std::fs::write(&path, lines.join("\n") + "\n").unwrap();
    path
}

#[test]
fn bad_input_is_reported_with_file_and_line() {
    let dir = tmp_dir("bad");
    let pred = dir.join("p.csv");
    let smoke = String::from_utf8(read(&data("smoke.can.log"))).unwrap();
    let line = |n: usize| smoke.lines().nth(n - 1).unwrap().to_string();

    // A malformed candump line: file:line and the reason.
    let bad = edited_candump(&dir, "bad_hex.log", 7, "(0000000000.100000) can0 100#0G");
    let err = fails(&["replay", s(&bad), "--out", s(&pred)]);
    assert!(err.contains(&format!("{}:7: ", bad.display())), "{err}");
    assert!(err.contains("data is not hex"), "{err}");
    assert!(!pred.exists(), "no output on error");

    let bad = edited_candump(&dir, "no_ts.log", 3, "can0 100#00");
    let err = fails(&["replay", s(&bad), "--out", s(&pred)]);
    assert!(err.contains(":3: malformed candump line"), "{err}");

    // Time going backwards: an error naming the line.
    // Line 10 stamped at t = 0, before line 9.
    let backwards = format!("(0000000000.000000){}", line(10).split_once(')').unwrap().1);
    let bad = edited_candump(&dir, "backwards.log", 10, &backwards);
    let err = fails(&["replay", s(&bad), "--out", s(&pred)]);
    assert!(err.contains(":10: time goes backwards"), "{err}");
    // evaluate reads the same candump (for the baseline) and says the same.
    let truth = dir.join("x.truth.csv");
    std::fs::copy(data("smoke.truth.csv"), &truth).unwrap();
    replay_at_origin(&data("smoke.can.log"), &pred);
    let err = fails(&[
        "evaluate",
        s(&pred),
        "--truth",
        s(&truth),
        "--inputs",
        s(&bad),
    ]);
    assert!(err.contains(":10: time goes backwards"), "{err}");

    // Unknown identifiers are counted and ignored.
    let t = line(20).split_once(')').unwrap().0.to_string() + ")";
    let mut with_unknown = String::new();
    for (i, l) in smoke.lines().enumerate() {
        with_unknown.push_str(l);
        with_unknown.push('\n');
        if i == 19 {
            with_unknown.push_str(&format!("{t} can0 555#0102\n{t} can0 18FEF100#00\n"));
        }
    }
    let unknown = dir.join("unknown.log");
    std::fs::write(&unknown, with_unknown).unwrap();
    let msg = ok(&["replay", s(&unknown), "--out", s(&pred)]);
    assert!(msg.contains("unknown id 2,"), "{msg}");

    // A malformed log CSV: file:line:column, the column's name and the reason.
    let csv = String::from_utf8(read(&data("smoke.csv"))).unwrap();
    let mut lines: Vec<String> = csv.lines().map(str::to_string).collect();
    lines[4] = lines[4].replacen(',', ",abc", 1);
    let bad_csv = dir.join("bad.csv");
    std::fs::write(&bad_csv, lines.join("\n")).unwrap();
    let err = fails(&["csv2can", s(&bad_csv), "--out", s(&dir.join("o.log"))]);
    assert!(
        err.contains(&format!("{}:5:", bad_csv.display())) && err.contains("`vel`"),
        "{err}"
    );
    assert!(err.contains("not a number"), "{err}");
    // Time going backwards in a CSV.
    let mut lines: Vec<String> = csv.lines().map(str::to_string).collect();
    lines.swap(6, 7);
    std::fs::write(&bad_csv, lines.join("\n")).unwrap();
    let err = fails(&["csv2can", s(&bad_csv), "--out", s(&dir.join("o.log"))]);
    assert!(
        err.contains(":8:") && err.contains("time goes backwards"),
        "{err}"
    );

    // A malformed predictions CSV.
    let ptext = String::from_utf8(read(&pred)).unwrap();
    let mut plines: Vec<&str> = ptext.lines().collect();
    plines[3] = "oops";
    let bad_pred = dir.join("bad_pred.csv");
    std::fs::write(&bad_pred, plines.join("\n")).unwrap();
    let err = fails(&[
        "evaluate",
        s(&bad_pred),
        "--truth",
        s(&truth),
        "--inputs",
        s(&data("smoke.can.log")),
    ]);
    assert!(err.contains(&format!("{}:4:", bad_pred.display())), "{err}");

    // evaluate without --inputs needs NAME.truth.csv beside NAME.can.log.
    let odd = dir.join("truth_without_suffix.csv");
    std::fs::copy(data("smoke.truth.csv"), &odd).unwrap();
    let err = fails(&["evaluate", s(&pred), "--truth", s(&odd)]);
    assert!(err.contains("--inputs"), "{err}");

    // A missing file names the file.
    let err = fails(&["replay", s(&dir.join("nope.log")), "--out", s(&pred)]);
    assert!(err.contains("nope.log"), "{err}");
}

/// `evaluate` with a truth sampled at 1 Hz (a reference receiver at 1 Hz, a black-box probe)
/// failed with "the node had no valid position at any tick ... a receiver slower than the
/// model file's gnss_rate_hz", blaming the node; the truth's samples, 1 s apart, left every
/// prediction in a gap. Now the gap warning comes first and the error names the truth's
/// spacing; a 2 Hz truth is still scored.
#[test]
fn evaluate_names_a_truth_sampled_too_slowly_not_the_node() {
    let dir = tmp_dir("slow-truth");
    let pred = dir.join("pred.csv");
    replay_at_origin(&data("smoke.can.log"), &pred);
    let text = String::from_utf8(read(&data("smoke.truth.csv"))).unwrap();
    let every = |n: usize, name: &str| {
        let path = dir.join(name);
        let rows: Vec<&str> = text
            .lines()
            .enumerate()
            .filter(|(i, _)| *i == 0 || (i - 1) % n == 0)
            .map(|(_, l)| l)
            .collect();
        std::fs::write(&path, rows.join("\n") + "\n").unwrap();
        path
    };
    let (hz1, hz2) = (every(100, "truth-1hz.csv"), every(50, "truth-2hz.csv"));
    let inputs = data("smoke.can.log");
    let out = run(&[
        "evaluate",
        s(&pred),
        "--truth",
        s(&hz1),
        "--inputs",
        s(&inputs),
    ]);
    assert_eq!(out.status.code(), Some(1), "refused");
    let err = String::from_utf8_lossy(&out.stderr);
    let gap = err
        .find("gap(s) longer than 0.5 s")
        .unwrap_or_else(|| panic!("{err}"));
    let error = err
        .find("catmodel: error: ")
        .unwrap_or_else(|| panic!("{err}"));
    assert!(gap < error, "the gap warning first: {err}");
    assert!(
        err.contains("the truth's samples are 1.000 s apart"),
        "{err}"
    );
    assert!(!err.contains("a receiver slower than"), "{err}");
    ok(&[
        "evaluate",
        s(&pred),
        "--truth",
        s(&hz2),
        "--inputs",
        s(&inputs),
    ]);
}

/// A log with no rows is not a drive: `csv2can` of a header alone and `replay` of an empty
/// candump (or one of blank lines only) are errors naming the file, and write nothing (they
/// used to write an empty candump, and replay 0 ticks, with exit status 0).
#[test]
fn a_log_with_no_rows_is_not_a_drive() {
    let dir = tmp_dir("no-rows");
    let header_only = dir.join("header.csv");
    std::fs::write(
        &header_only,
        "t,vel,input_vel,accel,steer,brake,lat,lon\r\n",
    )
    .unwrap();
    let can = dir.join("header.can.log");
    let err = fails(&["csv2can", s(&header_only), "--out", s(&can)]);
    assert!(
        err.contains(&format!("{}: no data rows", header_only.display())),
        "{err}"
    );
    assert!(!can.exists(), "nothing written");

    let pred = dir.join("p.csv");
    for (name, text) in [("empty.can.log", ""), ("blank.can.log", "\n  \n\n")] {
        let log = dir.join(name);
        std::fs::write(&log, text).unwrap();
        let err = fails(&["replay", s(&log), "--out", s(&pred)]);
        assert!(
            err.contains(&format!("{}: no CAN frame to replay", log.display())),
            "{err}"
        );
        assert!(!pred.exists(), "{name}: no output");
    }
}

/// Simulates `scenario` (seed 1) into `dir` and writes a copy of its log as `{scenario}-{tag}.csv`
/// with every non-empty cell of `columns` mapped by `f`: a log as another recorder's habit
/// writes it. Returns the copy's path.
fn simulated_log_with(
    dir: &Path,
    scenario: &str,
    tag: &str,
    columns: &[&str],
    f: impl Fn(f64) -> f64,
) -> PathBuf {
    ok(&[
        "simulate-drive",
        "--scenario",
        scenario,
        "--seed",
        "1",
        "--out",
        s(dir),
    ]);
    let text = String::from_utf8(read(&dir.join(format!("{scenario}.csv")))).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let picked: Vec<usize> = columns
        .iter()
        .map(|c| header.iter().position(|h| h == c).unwrap())
        .collect();
    let mut out = String::new();
    for (i, l) in text.lines().enumerate() {
        let mut cells: Vec<String> = l.split(',').map(str::to_string).collect();
        for &k in picked.iter().filter(|_| i > 0) {
            if !cells[k].is_empty() {
                cells[k] = format!("{}", f(cells[k].parse::<f64>().unwrap()));
            }
        }
        out += &(cells.join(",") + "\n");
    }
    let path = dir.join(format!("{scenario}-{tag}.csv"));
    std::fs::write(&path, out).unwrap();
    path
}

/// `identify` refuses logs whose wheel speed their GNSS track says is not in m/s (review
/// finding 04: a training set in km/h was identified with exit 0 and a steering gain of 0.34),
/// naming each file, the ratio and the likely unit; `--force` identifies anyway, with the
/// warning; `compare` warns.
#[test]
fn identify_refuses_a_wheel_speed_in_another_unit() {
    let dir = tmp_dir("speed-unit");
    let logs: Vec<PathBuf> = ["straight-5", "turn-left"]
        .iter()
        .map(|scenario| {
            simulated_log_with(&dir, scenario, "kmh", &["vel", "input_vel"], |v| v * 3.6)
        })
        .collect();
    let model = dir.join("model.toml");
    let mut args = vec!["identify", s(&logs[0]), s(&logs[1]), "--out", s(&model)];
    let err = fails(&args);
    for log in &logs {
        assert!(
            err.contains(&format!("{}: the wheel speed `vel` is 3.", log.display())),
            "{err}"
        );
    }
    assert!(err.contains("`vel` looks like km/h"), "{err}");
    assert!(err.contains("--force"), "{err}");
    assert!(!model.exists(), "not written");
    args.push("--force");
    let warnings = ok(&args);
    assert!(
        warnings.contains("looks like km/h") && warnings.contains("identified anyway"),
        "{warnings}"
    );
    assert!(model.exists());
    let warning = ok(&["compare", s(&logs[0]), "--model", s(&model)]);
    assert!(warning.contains("looks like km/h"), "{warning}");
}

/// `identify` with the command `input_vel` in km/h and the wheel speed `vel` in m/s (a
/// black-box probe): refused only as "DC gain 0.2769 is outside 0.5..2", without the unit the
/// gain points to (1/3.6 = 0.278), as a wheel speed in km/h is named. Now the refusal names it
/// and the fix, by the rule that names the wheel speed's: before any fit, by the speed the car
/// settles to (and nothing else: every log's command was also named as not followed before),
/// and with `--force` after it, by the speed model's gain.
#[test]
fn identify_names_a_command_in_km_h_by_the_speed_models_gain() {
    let dir = tmp_dir("command-unit");
    let logs: Vec<PathBuf> = ["straight-5", "straight-10"]
        .iter()
        .map(|scenario| simulated_log_with(&dir, scenario, "kmh", &["input_vel"], |v| v * 3.6))
        .collect();
    let model = dir.join("model.toml");
    let mut args = vec!["identify"];
    args.extend(logs.iter().map(|p| s(p)));
    args.extend(["--out", s(&model)]);
    let out = run(&args);
    assert_eq!(out.status.code(), Some(1), "refused");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.starts_with("catmodel: error: ")
            && stderr.contains("the speed settles at 0.2")
            && stderr.matches("`input_vel` looks like km/h").count() == 2
            && stderr.contains("divide `input_vel` by 3.6")
            && stderr.contains("the command is not in m/s")
            && !stderr.contains("did not follow"),
        "{stderr}"
    );
    assert!(!model.exists(), "not written");
    args.push("--force");
    let out = run(&args);
    assert_eq!(out.status.code(), Some(1), "refused");
    let stderr = String::from_utf8_lossy(&out.stderr);
    let err = stderr.lines().last().unwrap();
    assert!(err.starts_with("catmodel: error: "), "{stderr}");
    assert!(err.contains("DC gain 0.2"), "{err}");
    assert!(
        err.contains("`input_vel` looks like km/h") && err.contains("divide `input_vel` by 3.6"),
        "{err}"
    );
    assert!(!model.exists(), "not written");
}

/// `identify --validate` with a log of the car parked (a black-box probe): the undefined speed
/// fit was counted "below the 50 % floor" and blamed on "another car, another speed-loop
/// setting, or a validation log with a fault". Now the validation log is named as not moving
/// (no speed to score), and the refusal counts the fit as undefined.
#[test]
fn identify_says_a_parked_validation_log_does_not_move() {
    let dir = tmp_dir("validate-parked");
    for scenario in ["straight-5", "standstill"] {
        ok(&[
            "simulate-drive",
            "--scenario",
            scenario,
            "--seed",
            "1",
            "--out",
            s(&dir),
        ]);
    }
    let model = dir.join("model.toml");
    let out = run(&[
        "identify",
        s(&dir.join("straight-5.csv")),
        "--validate",
        s(&dir.join("standstill.csv")),
        "--out",
        s(&model),
    ]);
    assert_eq!(out.status.code(), Some(1), "refused");
    let err = String::from_utf8_lossy(&out.stderr);
    let speed = err
        .lines()
        .find(|l| l.contains("[speed] validation fit"))
        .unwrap_or_else(|| panic!("{err}"));
    assert!(
        speed.contains("the validation log does not move") && speed.contains("no speed to score"),
        "{speed}"
    );
    assert!(!err.contains("another speed-loop setting"), "{err}");
    assert!(
        err.contains("1 undefined") || err.contains("1 fit(s) undefined"),
        "{err}"
    );
    assert!(!model.exists(), "not written");
}

/// A copy of the log `src` with `vel` and `input_vel` times `unit`, at `dst`.
fn with_speed_times(src: &Path, dst: &Path, unit: f64) {
    let text = String::from_utf8(read(src)).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let picked: Vec<usize> = ["vel", "input_vel"]
        .iter()
        .map(|c| header.iter().position(|h| h == c).unwrap())
        .collect();
    let mut out = String::new();
    for (i, l) in text.lines().enumerate() {
        let mut cells: Vec<String> = l.split(',').map(str::to_string).collect();
        for &k in picked.iter().filter(|_| i > 0) {
            if !cells[k].is_empty() {
                cells[k] = format!("{}", unit * cells[k].parse::<f64>().unwrap());
            }
        }
        out += &(cells.join(",") + "\n");
    }
    std::fs::write(dst, out).unwrap();
}

/// `identify --vehicle` and `compare` move the wheel speed (the rear axle's) to the antenna
/// the car file declares before judging its unit against the GNSS track (third probe, finding
/// 01): a 12 m bus with its antenna 6.5 m ahead of the rear axle ran its full-lock circle in
/// m/s at 0.68 times the speed along the track, and `identify` refused it ("check the unit of
/// `vel`"), `compare` warned. Now both accept it, and the same log in km/h is still refused.
/// The same for the antenna 3.45 m behind the rear axle and 1.75 m left of the centre line
/// (the ends of the documented ranges) on a right-hand circle (0.70 before).
#[test]
fn identify_judges_the_wheel_speed_at_the_antenna_the_car_file_declares() {
    let dir = tmp_dir("speed-unit-antenna");
    let plant = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/bus-12m-20hz.toml");
    let car = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/bus-12m.car.toml");
    let plant_text = String::from_utf8(read(&plant)).unwrap();
    let car_text = String::from_utf8(read(&car)).unwrap();
    let behind_left = (
        plant_text.replace(
            "antenna_ahead_of_rear_axle_m = 6.5",
            "antenna_ahead_of_rear_axle_m = -3.45\nantenna_left_of_centre_line_m = 1.75",
        ),
        car_text
            .replace("antenna_ahead_m = 6.5", "antenna_ahead_m = -3.45")
            .replace("antenna_left_m = 0.0", "antenna_left_m = 1.75"),
    );
    assert_ne!(behind_left.0, plant_text);
    assert_ne!(behind_left.1, car_text);
    for (tag, (plant_text, car_text), circle, antenna) in [
        (
            "ahead",
            (plant_text.clone(), car_text.clone()),
            "circle-left",
            "6.5 m ahead of and 0 m left",
        ),
        (
            "behind-left",
            behind_left,
            "circle-right",
            "-3.45 m ahead of and 1.75 m left",
        ),
    ] {
        let dir = dir.join(tag);
        std::fs::create_dir_all(&dir).unwrap();
        let plant = dir.join("bus.toml");
        let car = dir.join("bus.car.toml");
        std::fs::write(&plant, plant_text).unwrap();
        std::fs::write(&car, car_text).unwrap();
        for scenario in [circle, "straight-5"] {
            ok(&[
                "simulate-drive",
                "--scenario",
                scenario,
                "--seed",
                "1",
                "--vehicle",
                s(&plant),
                "--out",
                s(&dir),
            ]);
        }
        let logs = [
            dir.join(format!("{circle}.csv")),
            dir.join("straight-5.csv"),
        ];
        let model = dir.join("model.toml");
        let said = ok(&[
            "identify",
            s(&logs[0]),
            s(&logs[1]),
            "--vehicle",
            s(&car),
            "--out",
            s(&model),
        ]);
        assert!(!said.contains("wheel speed `vel`"), "{tag}: {said}");
        assert!(model.exists(), "{tag}");
        let said = ok(&["compare", s(&logs[0]), "--model", s(&model)]);
        assert!(!said.contains("wheel speed `vel`"), "{tag}: {said}");

        // The same drive in km/h: refused, by the speed moved to the antenna.
        let kmh: Vec<PathBuf> = logs
            .iter()
            .map(|l| {
                let k = l.with_extension("kmh.csv");
                with_speed_times(l, &k, 3.6);
                k
            })
            .collect();
        let kmh_model = dir.join("kmh-model.toml");
        let err = fails(&[
            "identify",
            s(&kmh[0]),
            s(&kmh[1]),
            "--vehicle",
            s(&car),
            "--out",
            s(&kmh_model),
        ]);
        for log in &kmh {
            assert!(
                err.contains(&format!("{}: the wheel speed `vel` is 3.", log.display())),
                "{tag}: {err}"
            );
        }
        assert!(err.contains("`vel` looks like km/h"), "{tag}: {err}");
        assert!(
            err.contains(&format!(
                "the wheel speed moved to the antenna, {antenna} of the rear axle"
            )),
            "{tag}: {err}"
        );
        assert!(!kmh_model.exists(), "{tag}");
        let warning = ok(&["compare", s(&kmh[0]), "--model", s(&model)]);
        assert!(warning.contains("looks like km/h"), "{tag}: {warning}");
    }
}

/// `evaluate` refuses, with what to do, what would score nonsense (review findings 07, 08 and
/// the lead's frame mismatch): predictions on another clock than the truth (both ranges
/// named, not "no valid position"); a truth value no car can have (FILE:LINE:COL, not `inf`
/// and `NaN` in the report); predictions in the node's own frame (replay without `--origin`,
/// origin at the first fix) scored against the truth's frame. The same run with `--origin`
/// scores.
#[test]
fn evaluate_refuses_what_would_mislead() {
    let dir = tmp_dir("evaluate-refuses");
    let truth = data("smoke.truth.csv");
    let can = data("smoke.can.log");

    // Predictions stamped at an epoch (the log's `t` + 1.7e9 s), truth from 0.
    let csv = String::from_utf8(read(&data("smoke.csv"))).unwrap();
    let mut epoch = String::new();
    for (i, l) in csv.lines().enumerate() {
        if i == 0 {
            epoch += l;
        } else {
            let (t, rest) = l.split_once(',').unwrap();
            epoch += &format!("{:.6},{rest}", t.parse::<f64>().unwrap() + 1.7e9);
        }
        epoch += "\n";
    }
    let epoch_csv = dir.join("epoch.csv");
    std::fs::write(&epoch_csv, epoch).unwrap();
    let epoch_can = dir.join("epoch.can.log");
    ok(&["csv2can", s(&epoch_csv), "--out", s(&epoch_can)]);
    let epoch_pred = dir.join("epoch_pred.csv");
    replay_at_origin(&epoch_can, &epoch_pred);
    let err = fails(&[
        "evaluate",
        s(&epoch_pred),
        "--truth",
        s(&truth),
        "--inputs",
        s(&epoch_can),
    ]);
    assert!(err.contains("do not overlap in time"), "{err}");
    assert!(
        err.contains("(t = 1700000003.86 .. 1700000014.96 s)"),
        "{err}"
    );
    assert!(err.contains("(t = 0 .. 14.95 s)"), "{err}");
    assert!(!err.contains("no valid position"), "{err}");

    // A truth cell no car can have: its file, line and column.
    let pred = dir.join("pred.csv");
    ok(&["replay", s(&can), "--origin", ORIGIN, "--out", s(&pred)]);
    let truth_text = String::from_utf8(read(&truth)).unwrap();
    let mut lines: Vec<String> = truth_text.lines().map(str::to_string).collect();
    let cells: Vec<String> = lines[1000].split(',').map(str::to_string).collect();
    lines[1000] = format!("{},1e300,{}", cells[0], cells[2..].join(","));
    let bad_truth = dir.join("bad.truth.csv");
    std::fs::write(&bad_truth, lines.join("\n") + "\n").unwrap();
    let json = dir.join("eval.json");
    let err = fails(&[
        "evaluate",
        s(&pred),
        "--truth",
        s(&bad_truth),
        "--inputs",
        s(&can),
        "--json",
        s(&json),
    ]);
    let col = cells[0].chars().count() + 2;
    assert!(
        err.contains(&format!(
            "{}:1001:{col}: column `x`: 1e300 m is outside -1e7..1e7 m",
            bad_truth.display()
        )),
        "{err}"
    );
    assert!(!json.exists(), "no report on error");

    // Replay without --origin: the node's frame at its first fix, 1.5 m from the truth's.
    let first_fix = dir.join("first_fix.csv");
    ok(&["replay", s(&can), "--out", s(&first_fix)]);
    let err = fails(&[
        "evaluate",
        s(&first_fix),
        "--truth",
        s(&truth),
        "--inputs",
        s(&can),
    ]);
    assert!(
        err.contains("the predictions are not in the truth's frame"),
        "{err}"
    );
    assert!(err.contains("the first GNSS fix"), "{err}");
    assert!(err.contains(&format!("--origin {ORIGIN}")), "{err}");
    // The same drive replayed in the truth's frame is scored.
    let out = ok(&[
        "evaluate",
        s(&pred),
        "--truth",
        s(&truth),
        "--inputs",
        s(&can),
    ]);
    assert!(!out.contains("error"), "{out}");
}

/// A truth file with no sample, empty (0 bytes) or a header alone, is named as such, whatever
/// the file is called and whether `--inputs` is given (a black-box probe: an empty `X.csv` was
/// "cannot guess the candump of this truth file; pass --inputs FILE.can.log", an empty
/// `X.truth.csv` "missing header row", a header alone in `X.truth.csv` "opening X.can.log: No
/// such file"). A truth with samples but a name the candump cannot be guessed from is still
/// told to pass `--inputs`.
#[test]
fn evaluate_names_a_truth_with_no_sample() {
    let dir = tmp_dir("evaluate-empty-truth");
    let can = data("smoke.can.log");
    let pred = dir.join("pred.csv");
    ok(&["replay", s(&can), "--origin", ORIGIN, "--out", s(&pred)]);
    let header = "t,x,y,heading,yaw_rate,speed\n";
    let cases = [
        ("X.truth.csv", "", "empty file (0 bytes)"),
        ("Y.csv", "", "empty file (0 bytes)"),
        ("H.truth.csv", header, "a header row and no sample"),
        ("K.csv", header, "a header row and no sample"),
        (
            "B.truth.csv",
            "t,x,y,heading,yaw_rate,speed\r\n\r\n\n",
            "a header row and no sample",
        ),
    ];
    for (name, text, said) in cases {
        let truth = dir.join(name);
        std::fs::write(&truth, text).unwrap();
        for inputs in [None, Some(&can)] {
            let mut args = vec!["evaluate", s(&pred), "--truth", s(&truth)];
            if let Some(c) = inputs {
                args.extend(["--inputs", s(c)]);
            }
            let err = fails(&args);
            assert!(
                err.contains(&format!(
                    "{}: {said}: the truth has no sample to score the predictions against",
                    truth.display()
                )),
                "{name}, --inputs {inputs:?}: {err}"
            );
            assert!(
                !err.contains("cannot guess") && !err.contains("can.log"),
                "{name}: {err}"
            );
        }
    }
    // Samples, but no candump to guess from the name.
    let named_otherwise = dir.join("smoke-truth.csv");
    std::fs::copy(data("smoke.truth.csv"), &named_otherwise).unwrap();
    let err = fails(&["evaluate", s(&pred), "--truth", s(&named_otherwise)]);
    assert!(
        err.contains("cannot guess the candump of this truth file")
            && err.contains("pass --inputs FILE.can.log"),
        "{err}"
    );
}

/// `evaluate` on predictions that cover part of the drive says how much, and gives raw GNSS
/// over their span beside the figures over the whole drive (black-box probe: the first 30 s
/// of the 5-minute drive put raw GNSS at "0.784 x the floor", the floor over 30 s and raw GNSS
/// over 300, without a word); it refuses inputs whose fixes lie 100 m or more from the truth
/// (another drive's candump scored a baseline 227 m off, exit 0) and inputs whose fixes do not
/// overlap the predictions in time. The whole drive gets no warning.
#[test]
fn evaluate_names_partial_predictions_and_refuses_another_drives_inputs() {
    let dir = tmp_dir("evaluate-inputs");
    let truth = data("smoke.truth.csv");
    let can = data("smoke.can.log");
    let pred = dir.join("pred.csv");
    ok(&["replay", s(&can), "--origin", ORIGIN, "--out", s(&pred)]);
    let evaluate = |pred: &Path, inputs: &Path, succeeds: bool| -> String {
        let args = [
            "evaluate",
            s(pred),
            "--truth",
            s(&truth),
            "--inputs",
            s(inputs),
        ];
        if succeeds {
            ok(&args)
        } else {
            fails(&args)
        }
    };
    let whole = evaluate(&pred, &can, true);
    assert!(!whole.contains("warning"), "{whole}");

    // The predictions up to t = 6 s of the 15 s.
    let text = String::from_utf8(read(&pred)).unwrap();
    let part: String = text
        .lines()
        .filter(|l| {
            l.starts_with('t') || l.split(',').next().unwrap().parse::<f64>().unwrap() <= 6.0
        })
        .map(|l| format!("{l}\n"))
        .collect();
    let part_csv = dir.join("part.csv");
    std::fs::write(&part_csv, part).unwrap();
    let warned = evaluate(&part_csv, &can, true);
    assert!(
        warned.contains(&format!(
            "catmodel: warning: {}: the predictions cover t = 3.86 .. 6 s of the drive",
            part_csv.display()
        )) && warned.contains("over it raw GNSS at the rear axle is"),
        "{warned}"
    );

    // The log's fixes moved 0.01 deg north (1.1 km), or cut to its first 3 s.
    let csv = String::from_utf8(read(&data("smoke.csv"))).unwrap();
    let edited = |name: &str, edit: &dyn Fn(&str) -> Option<String>| -> PathBuf {
        let mut out = String::new();
        for (i, l) in csv.lines().enumerate() {
            if i == 0 {
                out += l;
                out += "\n";
            } else if let Some(l) = edit(l) {
                out += &l;
                out += "\n";
            }
        }
        let log = dir.join(format!("{name}.csv"));
        std::fs::write(&log, out).unwrap();
        let can = dir.join(format!("{name}.can.log"));
        ok(&["csv2can", s(&log), "--out", s(&can)]);
        can
    };
    let far = edited("far", &|l| {
        let mut cells: Vec<String> = l.split(',').map(str::to_string).collect();
        if let Ok(lat) = cells[6].parse::<f64>() {
            cells[6] = format!("{:.9}", lat + 0.01);
        }
        Some(cells.join(","))
    });
    let err = evaluate(&pred, &far, false);
    assert!(
        err.contains(&format!(
            "the inputs {}: their GNSS fixes lie 110",
            far.display()
        )) && err.contains("m from the truth")
            && err.contains("another drive's candump?"),
        "{err}"
    );
    let early = edited("early", &|l| {
        (l.split(',').next().unwrap().parse::<f64>().unwrap() < 3.0).then(|| l.to_string())
    });
    let err = evaluate(&pred, &early, false);
    assert!(
        err.contains("do not overlap in time: the baseline has no input at the predictions' ticks"),
        "{err}"
    );
}

/// `receiver-error` on the simulator's receiver parked for an hour gives the bound the built-in
/// files declare (the simulator's bias, 0.8 m per axis: 2.0 m, 2.5 standard deviations; seeds
/// 1 and 2 give 2.1 and 2.0 m); a 20 s standstill is too short and says how long is enough; a
/// drive is refused.
#[test]
fn receiver_error_from_a_parked_car() {
    let dir = tmp_dir("receiver-error");
    ok(&[
        "simulate-drive",
        "--scenario",
        "parked-1h",
        "--out",
        s(&dir),
    ]);
    let stdout = |args: &[&str]| {
        let out = run(args);
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let text = stdout(&["receiver-error", s(&dir.join("parked-1h.can.log"))]);
    let bound: f64 = text
        .split("position_uncertainty_m = ")
        .nth(1)
        .and_then(|t| t.trim().parse().ok())
        .unwrap_or_else(|| panic!("{text}"));
    assert!((1.8..=2.2).contains(&bound), "{text}");
    ok(&[
        "simulate-drive",
        "--scenario",
        "standstill",
        "--out",
        s(&dir),
    ]);
    let short = stdout(&["receiver-error", s(&dir.join("standstill.can.log"))]);
    assert!(
        short.contains("not determined") && short.contains("at least 10 minutes"),
        "{short}"
    );
    assert!(!short.contains("position_uncertainty_m ="), "{short}");
    ok(&[
        "simulate-drive",
        "--scenario",
        "straight-5",
        "--out",
        s(&dir),
    ]);
    let moved = fails(&["receiver-error", s(&dir.join("straight-5.can.log"))]);
    assert!(moved.contains("the car moved"), "{moved}");
    // The same drive without its speed reports (a recording that kept the receiver's frames
    // alone): the fixes' spread tells that it moved (a black-box probe's such log was taken to
    // be parked, and 410.7 m advised, which the model file refuses).
    let drive = std::fs::read_to_string(dir.join("straight-5.can.log")).unwrap();
    let gnss_only: String = drive
        .lines()
        .filter(|l| !l.contains(" 101#"))
        .map(|l| format!("{l}\n"))
        .collect();
    let gnss_only_path = dir.join("gnss-only.can.log");
    std::fs::write(&gnss_only_path, gnss_only).unwrap();
    let moved = fails(&["receiver-error", s(&gnss_only_path)]);
    assert!(
        moved.contains("the car moved (the logs have no speed report to tell"),
        "{moved}"
    );
    // Every fix stamped alike (a recorder that lost its clock): refused with the reason.
    let stamped = std::fs::read_to_string(dir.join("standstill.can.log")).unwrap();
    let same: String = stamped
        .lines()
        .filter_map(|l| {
            l.split_once(' ')
                .map(|(_, rest)| format!("(1700000000.000000) {rest}\n"))
        })
        .collect();
    let same_path = dir.join("same-stamp.can.log");
    std::fs::write(&same_path, same).unwrap();
    let e = fails(&["receiver-error", s(&same_path)]);
    assert!(e.contains("fixes span 0.000 s"), "{e}");
}

/// A copy of a candump log with `shift_s` added to the timestamps of the lines from `from`
/// on (a pause of the recording there, or with `from` 0 the whole log recorded later).
fn shifted_candump(src: &Path, dst: &Path, from: usize, shift_s: u64) {
    let text = std::fs::read_to_string(src).unwrap();
    let out: String = text
        .lines()
        .enumerate()
        .map(|(i, l)| {
            let (stamp, rest) = l.split_once(' ').unwrap();
            let (sec, us) = stamp
                .trim_start_matches('(')
                .trim_end_matches(')')
                .split_once('.')
                .unwrap();
            let sec: u64 = sec.parse().unwrap();
            let sec = if i >= from { sec + shift_s } else { sec };
            format!("({sec:010}.{us}) {rest}\n")
        })
        .collect();
    std::fs::write(dst, out).unwrap();
}

/// The east and north deviations averaged over 1 s that `receiver-error` prints.
fn averaged_deviations(text: &str) -> [f64; 2] {
    let mut v = text.lines().filter_map(|l| {
        l.split("averaged over 1 s ")
            .nth(1)
            .and_then(|r| r.split(" m").next())
            .and_then(|x| x.parse().ok())
    });
    let (Some(e), Some(n)) = (v.next(), v.next()) else {
        panic!("{text}");
    };
    [e, n]
}

/// `receiver-error` over several logs, or a log with a pause, measures each log and each
/// stretch between pauses apart. It took the receiver's rate as the logs' whole span over
/// their fix count, and averaged over "a second" of that rate: a black-box probe's 20 Hz
/// receiver with 3 m of white noise (1.7-1.8 m declared from each hour alone) declared 5.4 m
/// from two hours a day apart, 1.2 m (too small: obstacles are inflated by it) from two logs
/// both stamped from 0, whose fixes it interleaved, and 2.5 m from one hour with an hour's
/// pause. Here on such a receiver parked for an hour: the averaged deviations of the log
/// paused for an hour halfway are those of the log to 2 % (0.96 m for 0.67 m before, two fixes
/// to a "second"), and those of two logs stamped from 0 or a day apart lie within those of
/// each alone (0.47 m and 2.1 m before).
#[test]
fn receiver_error_measures_each_log_and_each_stretch_between_pauses_apart() {
    let dir = tmp_dir("receiver-error-stretches");
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    let car = String::from_utf8(read(&manifest.join("vehicles/cat-vehicle.toml"))).unwrap();
    let white = [
        (
            "period_s = 0.01             # paper",
            "period_s = 0.05 # paper",
        ),
        ("white_noise_m = 0.3 ", "white_noise_m = 3.0 "),
        ("bias_sigma_m = 0.8 ", "bias_sigma_m = 0.01 "),
        ("bias_correlation_s = 60.0", "bias_correlation_s = 10.0"),
    ]
    .iter()
    .fold(car, |c, (from, to)| {
        assert_eq!(c.matches(from).count(), 1, "{from}");
        c.replace(from, to)
    });
    let vehicle = dir.join("white.toml");
    std::fs::write(&vehicle, white).unwrap();
    for seed in ["0", "1"] {
        let out = dir.join(format!("s{seed}"));
        ok(&[
            "simulate-drive",
            "--scenario",
            "parked-1h",
            "--vehicle",
            s(&vehicle),
            "--seed",
            seed,
            "--out",
            s(&out),
        ]);
    }
    let (log0, log1) = (
        dir.join("s0/parked-1h.can.log"),
        dir.join("s1/parked-1h.can.log"),
    );
    let run_ok = |logs: &[&Path]| -> (String, String) {
        let mut args = vec!["receiver-error"];
        args.extend(logs.iter().map(|p| s(p)));
        let out = run(&args);
        let (stdout, stderr) = (
            String::from_utf8_lossy(&out.stdout).into_owned(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        );
        assert!(out.status.success(), "{args:?}: {stderr}");
        (stdout, stderr)
    };
    let alone0 = averaged_deviations(&run_ok(&[&log0]).0);
    let alone1 = averaged_deviations(&run_ok(&[&log1]).0);
    // 3 m of white noise, 20 fixes a second: 0.67 m averaged.
    for a in alone0.iter().chain(&alone1) {
        assert!((a / 0.671 - 1.0).abs() < 0.05, "{alone0:?} {alone1:?}");
    }
    // The first log paused for an hour halfway.
    let lines = std::fs::read_to_string(&log0).unwrap().lines().count();
    let paused = dir.join("paused.can.log");
    shifted_candump(&log0, &paused, lines / 2, 3600);
    let (text, notes) = run_ok(&[&paused]);
    let got = averaged_deviations(&text);
    for (g, a) in got.iter().zip(&alone0) {
        assert!(
            (g / a - 1.0).abs() < 0.02,
            "{got:?} against {alone0:?}: {text}"
        );
    }
    assert!(
        text.contains("in 2 stretches (one every 0.050 s)"),
        "{text}"
    );
    assert!(
        notes.contains("measured in 2 stretches") && notes.contains("longest 3600."),
        "{notes}"
    );
    assert!(!notes.contains("the node ticked"), "{notes}");
    // Both logs stamped from 0, and the second a day later: the same, between the two alone.
    let later = dir.join("next-day.can.log");
    shifted_candump(&log1, &later, 0, 86_400);
    let (both, _) = run_ok(&[&log0, &log1]);
    let (apart, _) = run_ok(&[&log0, &later]);
    assert_eq!(both, apart);
    let got = averaged_deviations(&both);
    for ((g, a), b) in got.iter().zip(&alone0).zip(&alone1) {
        assert!(
            *g >= a.min(*b) - 1e-3 && *g <= a.max(*b) + 1e-3,
            "{got:?} against {alone0:?} and {alone1:?}: {both}"
        );
    }
    assert!(
        both.contains("in 2 stretches (one every 0.050 s)"),
        "{both}"
    );
}

/// `receiver-error` on a receiver at another NMEA 2000 source address names the addresses
/// that did send PGN 129025 and the key to set, as `replay` does; it said "0 GNSS fixes (PGN
/// 129025 from source address 28)" alone.
#[test]
fn receiver_error_names_the_source_address_the_fixes_came_from() {
    let dir = tmp_dir("receiver-error-source");
    ok(&[
        "simulate-drive",
        "--scenario",
        "standstill",
        "--out",
        s(&dir),
    ]);
    let text = std::fs::read_to_string(dir.join("standstill.can.log")).unwrap();
    assert!(text.contains(" 09F8011C#"));
    let moved = dir.join("sa128.can.log");
    std::fs::write(&moved, text.replace(" 09F8011C#", " 09F80180#")).unwrap();
    let e = fails(&["receiver-error", s(&moved)]);
    assert!(
        e.contains("from 128 (0x80) did send PGN 129025")
            && e.contains("set gnss_source_address = 128"),
        "{e}"
    );
}

#[test]
fn replay_says_when_fixes_lie_beyond_the_local_frame() {
    // An origin 20.5 km north of the bundled drive: every fix lies beyond the frame's 20 km
    // reach, and a configured origin is not the node's to move. Before, replay blamed the
    // receiver's rate.
    let dir = tmp_dir("beyond-frame");
    let stderr = ok(&[
        "replay",
        s(&data("bundled.can.log")),
        "--origin",
        "32.4169,-110.9501",
        "--out",
        s(&dir.join("pred.csv")),
    ]);
    assert!(
        stderr.contains("more than 20 km from the local frame's origin")
            && stderr.contains("too far from the drive")
            && !stderr.contains("gnss_rate_hz"),
        "{stderr}"
    );
    // The drive's own origin: not a word about the frame.
    let stderr = ok(&[
        "replay",
        s(&data("bundled.can.log")),
        "--origin",
        "32.2319,-110.9501",
        "--out",
        s(&dir.join("pred.csv")),
    ]);
    assert!(!stderr.contains("local frame"), "{stderr}");
}

/// The median interval between the receiver's position frames (PGN 129025 from source 0x1C,
/// identifier 09F8011C) of a candump, s: the reference the replay's rate warning must name.
fn median_fix_interval_s(candump: &Path) -> (f64, usize) {
    let text = String::from_utf8(read(candump)).unwrap();
    let t: Vec<f64> = text
        .lines()
        .filter(|l| l.contains(" 09F8011C#"))
        .map(|l| l[1..l.find(')').unwrap()].parse().unwrap())
        .collect();
    let mut d: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    d.sort_by(f64::total_cmp);
    (d[d.len() / 2], t.len())
}

/// Review finding 04: a 100 Hz receiver replayed with a model file declaring 10 Hz. The
/// warning named the node's latest off-period interval ("132.7 Hz (every 8 ms)") and told the
/// user to declare it, which the model-file reader refuses (1..100 Hz). It now names the median
/// interval over every fix of the log, and the rate it advises is one the reader takes: replayed
/// with it, no fix is refused for its rate.
#[test]
fn replay_names_the_receivers_rate_from_the_whole_log() {
    let dir = tmp_dir("rate-mismatch");
    let can = data("smoke.can.log");
    let (median_s, fixes) = median_fix_interval_s(&can);
    let paper = String::from_utf8(read(&data("../models/paper.toml"))).unwrap();
    let with_rate = |hz: &str, name: &str| -> PathBuf {
        let text: String = paper
            .lines()
            .map(|l| {
                if l.starts_with("gnss_rate_hz =") {
                    format!("gnss_rate_hz = {hz}")
                } else if l.starts_with("gnss_lost_s =") {
                    // Outlasts the 0.25 s GNSS timeout at 10 Hz, so the file is valid.
                    "gnss_lost_s = 10.0".into()
                } else {
                    l.into()
                }
            })
            .collect::<Vec<_>>()
            .join("\n");
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    let ten = with_rate("10.0", "m10.toml");
    let out = dir.join("pred.csv");
    let stderr = ok(&["replay", s(&can), "--model", s(&ten), "--out", s(&out)]);
    // The rate and the count exactly; the interval to its printed 0.01 ms (the reference
    // subtracts decimal seconds, the replay integer microseconds).
    let expected = format!(
        "the receiver's fixes came at {:.1} Hz (the median interval between its {fixes} fixes: ",
        1.0 / median_s
    );
    let ms: f64 = stderr
        .split(&expected)
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|ms| ms.parse().ok())
        .unwrap_or_else(|| panic!("{expected}\n{stderr}"));
    assert!(
        (ms - median_s * 1e3).abs() <= 0.006,
        "{ms} ms vs {median_s} s"
    );
    let advised = stderr
        .split("set [vehicle] gnss_rate_hz = ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .unwrap_or_else(|| panic!("no rate advised:\n{stderr}"));
    let hz: f64 = advised.parse().unwrap();
    assert!((hz - 1.0 / median_s).abs() <= 0.05, "{hz} vs {median_s} s");
    // Following the advice: the file loads and the fixes are used.
    let fixed = with_rate(advised, "advised.toml");
    let stderr = ok(&["replay", s(&can), "--model", s(&fixed), "--out", s(&out)]);
    assert!(
        stderr.contains("gnss rate 0,") && !stderr.contains("gnss_rate_hz"),
        "{stderr}"
    );
}

/// A copy of the log `src` with only every `k`-th fix kept (the other rows' `lat`, `lon`
/// emptied): a receiver at a `k`-th of the rate.
fn with_every_nth_fix(src: &Path, dst: &Path, k: usize) {
    let text = String::from_utf8(read(src)).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let lat = header.iter().position(|h| *h == "lat").unwrap();
    let lon = header.iter().position(|h| *h == "lon").unwrap();
    let mut fixes = 0;
    let mut out = String::new();
    for (i, l) in text.lines().enumerate() {
        let mut cells: Vec<String> = l.split(',').map(str::to_string).collect();
        if i > 0 && !cells[lat].is_empty() {
            if fixes % k != 0 {
                cells[lat].clear();
                cells[lon].clear();
            }
            fixes += 1;
        }
        out += &(cells.join(",") + "\n");
    }
    std::fs::write(dst, out).unwrap();
}

/// A receiver slower than the 1 Hz a model file may declare is named with its rate, not the
/// wheel speed (a black-box probe's 0.5 Hz receiver: `identify` refused its drive for "the
/// wheel speed `vel` disagrees with the GNSS track ...: a wheel speed that sticks at its last
/// value", 153.0 m by the wheel speed and 18.6 m along the track on the circles; on a straight
/// drive it noted "the wheel speed `vel` is 0.62 s +- 0.13 late"). The simulator's 1 Hz
/// receiver on the circles, thinned to 0.5 and 0.2 Hz: refused naming the rate, identified
/// with `--force` and a warning, `compare` warns; the 1 Hz drive is identified as before.
#[test]
fn identify_names_a_receiver_slower_than_1_hz() {
    let dir = tmp_dir("slow-receiver");
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    let car = String::from_utf8(read(&manifest.join("vehicles/cat-vehicle.toml"))).unwrap();
    let (before, gnss) = car.split_once("[sensors.gnss]").unwrap();
    let (period, rest) = gnss.split_once("period_s = 0.01").unwrap();
    let vehicle = dir.join("cat-1hz.toml");
    std::fs::write(
        &vehicle,
        format!("{before}[sensors.gnss]{period}period_s = 1.0{rest}"),
    )
    .unwrap();
    ok(&[
        "simulate-drive",
        "--scenario",
        "circle-left",
        "--vehicle",
        s(&vehicle),
        "--out",
        s(&dir),
    ]);
    let one_hz = dir.join("circle-left.csv");
    let model = dir.join("m.toml");
    let err = ok(&["identify", s(&one_hz), "--out", s(&model)]);
    assert!(!err.contains("slower than"), "{err}");

    for (k, said) in [(2, "every 2.00 s (0.50 Hz"), (5, "every 5.00 s (0.20 Hz")] {
        let log = dir.join(format!("circle-left-{k}.csv"));
        with_every_nth_fix(&one_hz, &log, k);
        let _ = std::fs::remove_file(&model);
        let err = fails(&["identify", s(&log), "--out", s(&model)]);
        assert!(
            err.contains(&format!(
                "{}: the GNSS fixes come {said}, the median interval): below the 1 Hz a model \
                 file may declare",
                log.display()
            )) && err.contains("not written: 1 log(s) from a receiver slower than 1 Hz"),
            "{err}"
        );
        assert!(!err.contains("wheel speed `vel`"), "{err}");
        assert!(!model.exists(), "nothing written");
        let err = ok(&["identify", s(&log), "--out", s(&model), "--force"]);
        assert!(
            err.contains(said) && err.contains("(identified anyway: --force)"),
            "{err}"
        );
        assert!(!err.contains("wheel speed `vel`"), "{err}");
        let paper = manifest.join("../models/paper.toml");
        let err = ok(&["compare", s(&log), "--model", s(&paper)]);
        assert!(err.contains(said), "{err}");
        assert!(!err.contains("wheel speed `vel`"), "{err}");
    }
}

/// Review finding 01: drives whose `steer` has the other sign (positive = left) gave a steering
/// gain of -0.987 that `identify` only noted, leaving `[lateral]` out, writing the file and
/// exiting 0. It is now refused with the cause and the fix, as a wheel speed in km/h is;
/// `--force` writes the file without `[lateral]`, with the warning; `compare` warns.
#[test]
fn identify_refuses_a_steering_of_the_other_sign() {
    let dir = tmp_dir("steer-sign");
    let logs: Vec<PathBuf> = ["turn-left", "circle-right"]
        .iter()
        .map(|scenario| simulated_log_with(&dir, scenario, "flipped", &["steer"], |v| -v))
        .collect();
    let model = dir.join("model.toml");
    let mut args = vec!["identify", s(&logs[0]), s(&logs[1]), "--out", s(&model)];
    let err = fails(&args);
    let gain: f64 = err
        .split("from `steer`) is ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|g| g.parse().ok())
        .unwrap_or_else(|| panic!("{err}"));
    // The car's gain, 0.987 unflipped (README), with the other sign.
    assert!((gain + 0.987).abs() < 0.02, "{gain}\n{err}");
    assert!(
        err.contains("turn-left-flipped ") && err.contains("circle-right-flipped "),
        "each log's gain: {err}"
    );
    assert!(
        err.contains("`steer` turns the car the other way") && err.contains("negate the column"),
        "{err}"
    );
    assert!(
        err.contains("not written") && err.contains("--force"),
        "{err}"
    );
    assert!(!model.exists(), "not written");
    args.push("--force");
    let warnings = ok(&args);
    assert!(
        warnings.contains("negate the column") && warnings.contains("without [lateral]: --force"),
        "{warnings}"
    );
    let written = String::from_utf8(read(&model)).unwrap();
    assert!(!written.contains("[lateral]"), "{written}");
    let warning = ok(&["compare", s(&logs[1]), "--model", s(&model)]);
    assert!(
        warning.contains("catmodel: warning: ") && warning.contains("negate the column"),
        "{warning}"
    );
}

/// No command writes over its own input (outside review, finding 07: `replay in.can.log --out
/// in.can.log` replaced the drive with its predictions, exit 0; so did `--tx-out`, `csv2can`,
/// `evaluate --json`, `identify --out` and `compare --out` given an input's path). Each is
/// refused before anything is read, naming the path and both arguments, and the input keeps
/// its bytes, however the path is spelled; so are two outputs given one path, an output in a
/// directory that does not exist (it was created, with its parents), and an existing file as
/// `identify --report DIR` (it failed after the whole identification with `File exists (os
/// error 17)`, naming no path).
#[test]
fn outputs_never_overwrite_inputs() {
    let dir = tmp_dir("aliases");
    let copy = |name: &str, as_name: &str| {
        let p = dir.join(as_name);
        std::fs::copy(data(name), &p).unwrap();
        p
    };
    let can = copy("smoke.can.log", "in.can.log");
    let log = copy("smoke.csv", "in.csv");
    let turn = copy("turn-left-30s.csv", "turn.csv");
    let truth = copy("smoke.truth.csv", "truth.csv");
    let pred = dir.join("p.csv");
    ok(&["replay", s(&can), "--origin", ORIGIN, "--out", s(&pred)]);
    let paper = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/paper.toml");
    let fresh = dir.join("fresh.csv");
    let respelled = dir.join(".").join("in.can.log");
    let cases: Vec<(Vec<&str>, &Path, &str)> = vec![
        (
            vec!["replay", s(&can), "--out", s(&can)],
            &can,
            "--out and LOG",
        ),
        (
            vec!["replay", s(&can), "--out", s(&fresh), "--tx-out", s(&can)],
            &can,
            "--tx-out and LOG",
        ),
        (
            vec!["replay", s(&can), "--out", s(&respelled)],
            &respelled,
            "--out and LOG",
        ),
        (
            vec!["csv2can", s(&log), "--out", s(&log)],
            &log,
            "--out and LOG",
        ),
        (
            vec![
                "evaluate",
                s(&pred),
                "--truth",
                s(&truth),
                "--inputs",
                s(&can),
                "--json",
                s(&truth),
            ],
            &truth,
            "--json and --truth",
        ),
        (
            vec![
                "evaluate",
                s(&pred),
                "--truth",
                s(&truth),
                "--inputs",
                s(&can),
                "--json",
                s(&pred),
            ],
            &pred,
            "--json and PREDICTIONS",
        ),
        (
            vec!["identify", s(&log), s(&turn), "--out", s(&turn)],
            &turn,
            "--out and LOGS",
        ),
        (
            vec!["compare", s(&log), "--model", s(&paper), "--out", s(&log)],
            &log,
            "--out and LOG",
        ),
    ];
    for (args, input, what) in cases {
        let before = read(input);
        let err = fails(&args);
        assert!(
            err.contains(&format!("{}: is also an input ({what})", input.display())),
            "{args:?}: {err}"
        );
        assert_eq!(read(input), before, "{args:?} changed {}", input.display());
        assert!(!fresh.exists(), "{args:?} wrote {}", fresh.display());
    }
    // Two outputs, one path.
    let err = fails(&["replay", s(&can), "--out", s(&fresh), "--tx-out", s(&fresh)]);
    assert!(
        err.contains(&format!(
            "{}: given as two outputs (--out and --tx-out)",
            fresh.display()
        )),
        "{err}"
    );
    assert!(!fresh.exists());
    // A directory that does not exist is named, not created.
    let typo = dir.join("no/such/p.csv");
    let err = fails(&["replay", s(&can), "--out", s(&typo)]);
    assert!(
        err.contains(&format!(
            "the directory {} does not exist",
            dir.join("no/such").display()
        )),
        "{err}"
    );
    assert!(!dir.join("no").exists(), "created the missing directories");
    // An existing file as the report directory: refused before the identification (nothing on
    // stdout, where its summary goes), naming the file.
    let afile = dir.join("afile");
    std::fs::write(&afile, "").unwrap();
    let model = dir.join("m.toml");
    let out = run(&[
        "identify",
        s(&log),
        s(&turn),
        "--out",
        s(&model),
        "--report",
        s(&afile),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains(&format!(
            "{}: exists and is not a directory (--report",
            afile.display()
        )),
        "{err}"
    );
    assert!(
        out.stdout.is_empty(),
        "identified first: {}",
        String::from_utf8_lossy(&out.stdout)
    );
    assert!(!model.exists());
}

/// Command-line values that would mislead are refused by name (a black-box probe): a sample
/// time that is not a number was blamed on the model file, one of 1e-12 s gave a delay of
/// 1 048 577 samples where it is 4.2e11; `--from=-inf` printed "from -inf s"; `--messages ''`
/// showed no frame with exit 0, as if the log held none.
#[test]
fn command_line_values_that_would_mislead_are_refused() {
    // A value the argument parser refuses: exit 2 and clap's "invalid value" with the reason.
    let refused = |args: &[&str], why: &str| {
        let out = run(args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(
            stderr.contains("invalid value") && stderr.contains(why),
            "{args:?}: {stderr}"
        );
    };
    let paper = data("../models/paper.toml");
    for ts in ["NaN", "1e-12", "inf", "0", "-0.02", "100"] {
        refused(
            &["discretize", s(&paper), &format!("--ts={ts}")],
            "a sample time from 0.0001 to 10 s",
        );
    }
    let fine = run(&["discretize", s(&paper), "--ts", "0.001"]);
    assert!(fine.status.success());
    assert!(String::from_utf8_lossy(&fine.stdout).contains("\"ts\": 0.001"));
    let log = data("smoke.can.log");
    for from in ["-inf", "NaN", "inf"] {
        refused(
            &["identify-steering", s(&log), &format!("--from={from}")],
            "not a finite number of seconds",
        );
    }
    for messages in ["", ","] {
        let err = fails(&["decode", s(&log), "--messages", messages]);
        assert!(
            err.contains("--messages: no message named"),
            "{messages:?}: {err}"
        );
    }
}

/// A truth in another convention is refused by name: the heading counter-clockwise from east
/// (ROS, ENU) with the yaw rate negated, or x and y swapped (NED). A black-box probe's
/// ENU truth scored the heading 1.65 rad RMS and the filtered position "0.812 x the floor",
/// its swapped one the position 43 m RMS and "1.005 x the floor", both with exit 0.
#[test]
fn evaluate_refuses_a_truth_in_another_convention() {
    let dir = tmp_dir("evaluate-truth-convention");
    let can = data("smoke.can.log");
    let pred = dir.join("pred.csv");
    ok(&["replay", s(&can), "--origin", ORIGIN, "--out", s(&pred)]);
    let truth = std::fs::read_to_string(data("smoke.truth.csv")).unwrap();
    let (header, rows) = truth.split_once('\n').unwrap();
    let rewrite = |f: &dyn Fn(&[f64]) -> [f64; 6]| -> String {
        let mut out = format!("{header}\n");
        for line in rows.lines() {
            let v: Vec<f64> = line.split(',').map(|c| c.parse().unwrap()).collect();
            let w = f(&v).map(|x| x.to_string()).join(",");
            out.push_str(&w);
            out.push('\n');
        }
        out
    };
    let wrap = |a: f64| {
        (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
    };
    let enu = rewrite(&|v| {
        [
            v[0],
            v[1],
            v[2],
            wrap(std::f64::consts::FRAC_PI_2 - v[3]),
            -v[4],
            v[5],
        ]
    });
    let ned = rewrite(&|v| [v[0], v[2], v[1], v[3], v[4], v[5]]);
    for (name, text) in [("enu.truth.csv", enu), ("ned.truth.csv", ned)] {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        let err = fails(&[
            "evaluate",
            s(&pred),
            "--truth",
            s(&path),
            "--inputs",
            s(&can),
        ]);
        assert!(
            err.contains("the truth's heading is")
                && err.contains("from the direction its own x, y move"),
            "{name}: {err}"
        );
    }
    // The truth as written: scored.
    ok(&[
        "evaluate",
        s(&pred),
        "--truth",
        s(&data("smoke.truth.csv")),
        "--inputs",
        s(&can),
    ]);
}

/// `catmodel ... | head`: a reader that closes the pipe early ends the tool as it ends any Unix
/// tool, quietly and with status 0 (as `decode` does). Rust's runtime ignores SIGPIPE, and the
/// next `println!` (`identify-steering`'s lines, among others) panicked with "failed printing
/// to stdout" and exit status 101.
#[test]
fn a_closed_pipe_ends_the_tool_quietly() {
    use std::process::Stdio;
    let dir = tmp_dir("closed_pipe");
    let d = dir.to_str().unwrap();
    ok(&[
        "closed-loop",
        "--scenario",
        "dlc",
        "--speed",
        "8",
        "--out",
        d,
    ]);
    let (rx, tx) = (dir.join("session.can.log"), dir.join("session.tx.log"));
    let mut child = Command::new(BIN)
        .args([
            "identify-steering",
            rx.to_str().unwrap(),
            tx.to_str().unwrap(),
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The read end closed before the tool writes (it reads and fits the session first).
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    // Status 0, as `decode` ends: 141 (SIGPIPE) fails a `set -o pipefail` script.
    assert_eq!(out.status.code(), Some(0), "{stderr}");
}

/// A negative number after an option is its value, not a flag: a black-box probe's southern
/// origin, `--origin -33.86,151.21`, was refused by `replay`, `evaluate` and `sil` ("unexpected
/// argument '-3' found", and clap's tip, `-- -33.86,151.21`, did not work either); only
/// `--origin=-33.86,151.21` did. The other numeric options (`--speed`, `--seed`,
/// `--replan-every`, `--from`, `--ts`) now reach their own checks with a negative value too.
#[test]
fn a_negative_number_is_an_options_value() {
    let dir = tmp_dir("negative-values");
    let can = data("smoke.can.log");
    let pred = dir.join("p.csv");
    let sydney = "-33.86,151.21";
    // The origin is taken: the drive's fixes lie beyond its 20 km, and replay says so.
    let err = ok(&["replay", s(&can), "--origin", sydney, "--out", s(&pred)]);
    assert!(
        err.contains("from the local frame's origin (now -33.8600000,151.2100000)"),
        "{err}"
    );
    // evaluate parses it and checks the position (a latitude beyond 90 degrees is not one).
    ok(&["replay", s(&can), "--origin", ORIGIN, "--out", s(&pred)]);
    let truth = data("smoke.truth.csv");
    let out = run(&[
        "evaluate",
        s(&pred),
        "--truth",
        s(&truth),
        "--origin",
        "-91,151.21",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("origin -91,151.21 is not a WGS-84 position"),
        "{stderr}"
    );
    let out = run(&[
        "evaluate",
        s(&pred),
        "--truth",
        s(&truth),
        "--origin",
        sydney,
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.code() != Some(2) && !stderr.contains("unexpected argument"),
        "{stderr}"
    );
    // sil over one tick.
    let mut child = Command::new(BIN)
        .args(["sil", "--stdio", "--origin", sydney])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    {
        use std::io::Write;
        let mut stdin = child.stdin.take().unwrap();
        stdin.write_all(b"TICK 0.020000\n").unwrap();
    }
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout)
        .lines()
        .any(|l| l.starts_with("END ")));
    // The numeric options' own checks answer a negative value.
    let cl_out = dir.join("cl");
    for (option, why) in [
        ("--speed", "--speed -3: a target speed is in (0, 40] m/s"),
        (
            "--replan-every",
            "--replan-every -3: a period of at least 0.02 s",
        ),
    ] {
        let err = fails(&[
            "closed-loop",
            "--scenario",
            "loop",
            option,
            "-3",
            "--out",
            s(&cl_out),
        ]);
        assert!(err.contains(why), "{option}: {err}");
    }
    for args in [
        &[
            "closed-loop",
            "--scenario",
            "loop",
            "--seed",
            "-3",
            "--out",
            s(&cl_out),
        ][..],
        &[
            "simulate-drive",
            "--scenario",
            "smoke",
            "--seed",
            "-3",
            "--out",
            s(&cl_out),
        ][..],
    ] {
        let out = run(args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            stderr.contains("invalid value '-3' for '--seed <SEED>'"),
            "{args:?}: {stderr}"
        );
    }
    let paper = data("../models/paper.toml");
    let out = run(&["discretize", s(&paper), "--ts", "-0.02"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("-0.02: a sample time from 0.0001 to 10 s"),
        "{stderr}"
    );
    // A negative start of the fit's window is a time like any other: the smoke drive has no
    // CONTROL_COMMAND to fit.
    let err = fails(&["identify-steering", s(&can), "--from", "-5"]);
    assert!(err.contains("no CONTROL_COMMAND"), "{err}");
}

/// `csv2can` of a log whose speed and steering were recorded at 5 Hz (slower than the node's
/// 0.1 s input timeouts; a black-box probe) said nothing of their rate: only `replay` of its
/// candump did. Now `csv2can` notes each sensor's median interval against its timeout, worded
/// as `replay`'s; the log as recorded (50 Hz) gets no such note.
#[test]
fn csv2can_names_sensors_logged_slower_than_their_timeouts() {
    let dir = tmp_dir("csv2can_slow");
    let csv = std::fs::read_to_string(data("smoke.csv")).unwrap();
    let out = every_tenth_report(&csv);
    let slow = dir.join("slow.csv");
    std::fs::write(&slow, out).unwrap();
    let stderr = ok(&["csv2can", s(&slow), "--out", s(&dir.join("slow.can.log"))]);
    assert!(
        stderr.contains("STEERING_REPORT every 0.200 s (median), longer than its 0.100 s timeout")
            && stderr
                .contains("SPEED_REPORT every 0.200 s (median), longer than its 0.100 s timeout")
            && stderr.contains("come further apart than the node's timeouts"),
        "{stderr}"
    );
    let stderr = ok(&[
        "csv2can",
        s(&data("smoke.csv")),
        "--out",
        s(&dir.join("as.can.log")),
    ]);
    assert!(!stderr.contains("further apart"), "{stderr}");
}

/// A log whose `vel` is negative (a signed wheel speed: the car reversing) goes on the bus as
/// its magnitude with SPEED_REPORT `direction` = reverse, and says so: `csv2can` counts and
/// notes them, `decode` names the direction, `replay` counts the reports that carried one.
/// Before, they went out as 0 m/s (a documented note). A log without a negative speed gives
/// the same frames as before (`bundled_smoke_drive_is_reproducible`) and no note.
#[test]
fn csv2can_sends_a_negative_speed_as_reversing_and_decode_and_replay_show_it() {
    let dir = tmp_dir("csv2can_reverse");
    let csv = std::fs::read_to_string(data("smoke.csv")).unwrap();
    let mut lines = csv.lines();
    let header = lines.next().unwrap();
    assert_eq!(header, "t,vel,input_vel,accel,steer,brake,lat,lon");
    let mut out = format!("{header}\n");
    let mut reversed = 0;
    for line in lines {
        let mut cells: Vec<String> = line.split(',').map(str::to_string).collect();
        let t: f64 = cells[0].parse().unwrap();
        if (8.0..9.0).contains(&t) && !cells[1].is_empty() {
            let v: f64 = cells[1].parse().unwrap();
            if v > 0.0 {
                cells[1] = format!("{}", -v);
                reversed += 1;
            }
        }
        out.push_str(&cells.join(","));
        out.push('\n');
    }
    assert!(reversed > 40, "{reversed}");
    let log_csv = dir.join("reverse.csv");
    std::fs::write(&log_csv, out).unwrap();
    let log = dir.join("reverse.can.log");
    let stderr = ok(&["csv2can", s(&log_csv), "--out", s(&log)]);
    assert!(
        stderr.contains(&format!(
            "{reversed} measured speed(s) `vel` below 0 m/s sent as reversing: SPEED_REPORT \
             carries the magnitude with direction = 2 (reverse)"
        )),
        "{stderr}"
    );
    let decoded = run(&["decode", s(&log), "--csv", "--messages", "SPEED_REPORT"]);
    let text = String::from_utf8(decoded.stdout).unwrap();
    let direction_rows: Vec<&str> = text.lines().filter(|l| l.contains(",direction,")).collect();
    let reverse_rows = direction_rows
        .iter()
        .filter(|l| l.contains(",direction,2,2,,reverse,"))
        .count();
    assert_eq!(reverse_rows, reversed, "{:?}", &direction_rows[..3]);
    let stderr = replay_at_origin(&log, &dir.join("pred.csv"));
    assert!(
        stderr.contains(&format!(
            "SPEED_REPORT direction: 0 report(s) forward, {reversed} reverse (the first at t = 8."
        )),
        "{stderr}"
    );
    // The drive as recorded: no note from either.
    let plain = dir.join("plain.can.log");
    let stderr = ok(&["csv2can", s(&data("smoke.csv")), "--out", s(&plain)]);
    assert!(!stderr.contains("reversing"), "{stderr}");
    let stderr = replay_at_origin(&plain, &dir.join("plain.csv"));
    assert!(!stderr.contains("direction"), "{stderr}");
}

/// A log whose steering and speed were recorded at 5 Hz (a telemetry logger's rate, not the
/// bus's 50 Hz): `replay` names the reports' interval against their timeouts, and the node's
/// steering check does not read the ticks between reports, when the models steer straight on,
/// as a stronger steering. A black-box probe's 5-minute drive so decimated replayed with "the
/// car turned 1.733 times the yaw rate the model file's steering gives ... Scale the model
/// file's steering by it" and no word of the rate.
#[test]
fn reports_slower_than_their_timeouts_are_named_not_taken_for_a_steering_gain() {
    let dir = tmp_dir("slow_reports");
    let d = dir.to_str().unwrap();
    ok(&[
        "simulate-drive",
        "--scenario",
        "validation",
        "--seed",
        "3",
        "--out",
        d,
    ]);
    let csv = std::fs::read_to_string(dir.join("validation.csv")).unwrap();
    let out = every_tenth_report(&csv);
    let slow = dir.join("slow.csv");
    std::fs::write(&slow, out).unwrap();
    let log = dir.join("slow.can.log");
    ok(&[
        "csv2can",
        slow.to_str().unwrap(),
        "--out",
        log.to_str().unwrap(),
    ]);
    let pred = dir.join("pred.csv");
    let stderr = replay_at_origin(&log, &pred);
    assert!(
        stderr.contains("STEERING_REPORT every 0.200 s (median), longer than its 0.100 s timeout")
            && stderr.contains("SPEED_REPORT every 0.200 s"),
        "{stderr}"
    );
    assert!(!stderr.contains("times the yaw rate"), "{stderr}");
    // As recorded: neither.
    let full = dir.join("validation.can.log");
    let stderr = replay_at_origin(&full, &pred);
    assert!(
        !stderr.contains("further apart than the node's timeouts")
            && !stderr.contains("times the yaw rate"),
        "{stderr}"
    );
}

/// A log CSV (the simulator's schema) with every 10th report of the five bus sensors kept and
/// the fixes as they are: the bus sampled at 5 Hz by a telemetry logger.
fn every_tenth_report(csv: &str) -> String {
    let mut lines = csv.lines();
    let header = lines.next().unwrap();
    assert_eq!(header, "t,vel,input_vel,accel,steer,brake,lat,lon");
    let mut out = format!("{header}\n");
    let mut reports = 0;
    for line in lines {
        let mut cells: Vec<&str> = line.split(',').collect();
        if cells[1..6].iter().any(|c| !c.is_empty()) {
            reports += 1;
            if reports % 10 != 0 {
                cells[1..6].fill("");
            }
        }
        if cells[1..].iter().any(|c| !c.is_empty()) {
            out.push_str(&cells.join(","));
            out.push('\n');
        }
    }
    out
}

/// `identify` on the 15 s smoke drive alone (a black-box probe): refused by the model file's
/// reader for the speed model's DC gain (0.23), nothing said of how little the log holds. The
/// refusal now names the training logs' length and speed steps.
#[test]
fn identify_on_too_little_data_says_how_little() {
    let dir = tmp_dir("too-little");
    let smoke = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/smoke.csv");
    let err = fails(&["identify", s(&smoke), "--out", s(&dir.join("m.toml"))]);
    assert!(
        err.contains("the training logs hold 15 s and")
            && err.contains("too little to determine the models?"),
        "{err}"
    );
}
