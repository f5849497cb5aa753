//! Logs as real recorders write them, through the built `catmodel` binary (issue "Real logs,
//! real receivers, another car", items 1 and 2):
//! - a recorder that writes four decimals (so two sensors share a timestamp), one line per
//!   report, CRLF, a byte-order mark and its own columns: identified as the clean log is, and
//!   replayed (equal candump timestamps);
//! - one impossible sample (1e30 m/s) is refused with its file, line and column;
//! - a model below the fit floor is not written, names its cause and line; `--force` writes it
//!   with the warning in the file, unless the reader refuses it (an absurd gain).
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use catmodel_host::logcsv::{self, LogRow};
use catmodel_host::model_file;

const BIN: &str = env!("CARGO_BIN_EXE_catmodel");

fn tmp_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("real_logs_{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn run(args: &[&str]) -> Output {
    Command::new(BIN).args(args).output().unwrap()
}

/// Runs, requires the exit status `code`, returns stderr.
fn status(code: i32, args: &[&str]) -> String {
    let out = run(args);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(
        out.status.code(),
        Some(code),
        "catmodel {args:?}:\n{stderr}"
    );
    stderr
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// `straight-5` with seed 1 (one minute, a speed step up and down), its CSV path.
fn straight_5(dir: &Path) -> PathBuf {
    status(
        0,
        &[
            "simulate-drive",
            "--scenario",
            "straight-5",
            "--seed",
            "1",
            "--out",
            s(dir),
        ],
    );
    dir.join("straight-5.csv")
}

/// The rows as a recorder with a 0.1 ms clock writes them: `t` with four decimals, one line per
/// report (a fix's latitude and longitude on two lines), CRLF, a byte-order mark, and two
/// columns of its own (`gear`, and a free-text `comment` whose quoted cells hold commas).
fn as_recorded(rows: &[LogRow]) -> String {
    let mut text =
        String::from("\u{feff}t,gear,vel,input_vel,accel,steer,brake,lat,lon,comment\r\n");
    for r in rows {
        let t = format!("{:.4}", r.t);
        let cell = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v}"));
        let mut line = |cells: [Option<f64>; 7]| {
            let body: Vec<String> = cells.iter().map(|c| cell(*c)).collect();
            text.push_str(&format!("{t},3,{},\"drive, no notes\"\r\n", body.join(",")));
        };
        if r.vel.is_some() || r.input_vel.is_some() {
            line([r.vel, r.input_vel, None, None, None, None, None]);
        }
        if r.accel.is_some() || r.brake.is_some() {
            line([None, None, r.accel, None, r.brake, None, None]);
        }
        if r.steer.is_some() {
            line([None, None, None, r.steer, None, None, None]);
        }
        if r.lat.is_some() {
            line([None, None, None, None, None, r.lat, None]);
            line([None, None, None, None, None, None, r.lon]);
        }
    }
    text
}

fn speed_training_fit(model: &Path) -> f64 {
    model_file::load(model)
        .unwrap()
        .speed
        .fit
        .training_fit_percent
        .unwrap()
}

#[test]
fn a_recorders_log_is_identified_and_replayed_like_the_clean_one() {
    let dir = tmp_dir("recorder");
    let clean = straight_5(&dir);
    let rows = logcsv::read_log(&clean).unwrap().rows;
    let recorded = dir.join("recorded.csv");
    std::fs::write(&recorded, as_recorded(&rows)).unwrap();

    // The recorder's file really has equal timestamps from different sensors: the reader
    // makes one row of each instant, no conflict.
    let equal_t = rows
        .windows(2)
        .filter(|w| format!("{:.4}", w[0].t) == format!("{:.4}", w[1].t))
        .count();
    assert!(equal_t > 0, "no two reports within the same 0.1 ms");
    let read = logcsv::read_log(&recorded).unwrap();
    assert_eq!(read.rows.len(), rows.len() - equal_t);
    assert_eq!(read.notes.conflicts, 0);

    let model_clean = dir.join("clean.toml");
    let model_rec = dir.join("recorded.toml");
    status(0, &["identify", s(&clean), "--out", s(&model_clean)]);
    let stderr = status(0, &["identify", s(&recorded), "--out", s(&model_rec)]);
    // The extra columns are named once, in one note.
    assert_eq!(
        stderr
            .matches("columns `gear`, `comment` are not in the log schema")
            .count(),
        1,
        "{stderr}"
    );
    // Rounding the time to 0.1 ms moves each report by at most 50 us: the same model.
    let (a, b) = (
        speed_training_fit(&model_clean),
        speed_training_fit(&model_rec),
    );
    assert!((a - b).abs() < 0.5, "fit {a} % clean vs {b} % recorded");

    // csv2can and replay take it too; the candump has frames sharing a timestamp.
    let can = dir.join("recorded.can.log");
    status(0, &["csv2can", s(&recorded), "--out", s(&can)]);
    let text = std::fs::read_to_string(&can).unwrap();
    let stamps: Vec<&str> = text.lines().map(|l| &l[..19]).collect();
    assert!(stamps.windows(2).any(|w| w[0] == w[1]));
    let pred = dir.join("pred.csv");
    status(
        0,
        &[
            "replay",
            s(&can),
            "--origin",
            "32.2319,-110.9501",
            "--out",
            s(&pred),
        ],
    );
    assert!(std::fs::metadata(&pred).unwrap().len() > 100_000);
}

#[test]
fn an_impossible_sample_is_refused_with_its_line() {
    let dir = tmp_dir("impossible");
    let clean = straight_5(&dir);
    let text = std::fs::read_to_string(&clean).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    // The first speed report after 20 s (line numbers are 1-based; the header is line 1).
    let index = lines
        .iter()
        .position(|l| {
            let c: Vec<&str> = l.split(',').collect();
            c[0].parse::<f64>().is_ok_and(|t| t > 20.0) && !c[1].is_empty()
        })
        .unwrap();
    let mut cells: Vec<String> = lines[index].split(',').map(str::to_string).collect();
    let column = cells[0].chars().count() + 2;
    cells[1] = "1e30".into();
    lines[index] = cells.join(",");
    let bad = dir.join("bad.csv");
    std::fs::write(&bad, lines.join("\n")).unwrap();
    let model = dir.join("bad.toml");
    let stderr = status(1, &["identify", s(&bad), "--out", s(&model)]);
    let expected = format!(
        "catmodel: error: {}:{}:{column}: column `vel`: 1e30 m/s is outside -10..80 m/s",
        bad.display(),
        index + 1
    );
    assert!(
        stderr.starts_with(&expected),
        "{stderr}\nexpected {expected}"
    );
    assert!(!model.exists());
}

#[test]
fn a_model_below_the_fit_floor_is_written_only_when_forced() {
    let dir = tmp_dir("floor");
    let clean = straight_5(&dir);
    // 1.2 s of speed reports at 79 m/s (inside the range check, far outside this drive).
    let text = std::fs::read_to_string(&clean).unwrap();
    let mut first_bad = None;
    let mut n = 0;
    let lines: Vec<String> = text
        .lines()
        .enumerate()
        .map(|(i, l)| {
            let mut c: Vec<String> = l.split(',').map(str::to_string).collect();
            let late = c[0].parse::<f64>().is_ok_and(|t| t > 30.0);
            if late && n < 60 && !c[1].is_empty() {
                c[1] = "79".into();
                n += 1;
                first_bad.get_or_insert(i + 1);
            }
            c.join(",")
        })
        .collect();
    let bad = dir.join("spiked.csv");
    std::fs::write(&bad, lines.join("\n")).unwrap();
    let model = dir.join("spiked.toml");
    let stderr = status(1, &["identify", s(&bad), "--out", s(&model)]);
    assert!(
        stderr.contains("catmodel: warning: [speed] training fit")
            && stderr.contains("< 50 %: one sample stands far outside the rest: `vel` in spiked"),
        "{stderr}"
    );
    assert!(
        stderr.contains(&format!(
            "{}:{}: this line's value 79 stands out",
            bad.display(),
            first_bad.unwrap()
        )),
        "{stderr}"
    );
    assert!(
        stderr.contains("not written: 1 fit(s) below the 50 % floor"),
        "{stderr}"
    );
    assert!(!model.exists());

    // --force writes a model below the floor, not one the reader refuses: the spike also
    // bent the eq 7 block's steering gain past what any car can have (a straight drive does
    // not excite the steering; the clean drive's is 50 m/s per rad).
    let stderr = status(1, &["identify", s(&bad), "--out", s(&model), "--force"]);
    assert!(
        stderr.contains("not written: the identified model is refused: dx_dt.blocks[phi]: DC gain"),
        "{stderr}"
    );
    assert!(!model.exists());

    // A turn at one speed: the lateral model's fit is below the floor (too little steering),
    // nothing is absurd, and --force writes it with the warning in the file.
    status(
        0,
        &[
            "simulate-drive",
            "--scenario",
            "turn-left",
            "--seed",
            "1",
            "--out",
            s(&dir),
        ],
    );
    let turn = dir.join("turn-left.csv");
    let stderr = status(1, &["identify", s(&turn), "--out", s(&model)]);
    assert!(
        stderr.contains("warning: [lateral] training fit")
            && stderr.contains("not written: 1 fit(s) below the 50 % floor"),
        "{stderr}"
    );
    assert!(!model.exists());
    status(0, &["identify", s(&turn), "--out", s(&model), "--force"]);
    let file = model_file::load(&model).unwrap();
    assert!(file
        .description
        .starts_with("WARNING: written with --force"));
    let lateral = file.lateral.expect("a lateral model");
    assert!(lateral
        .model
        .fit
        .note
        .starts_with("WARNING (--force): [lateral] training fit"));
    assert!(lateral.model.fit.training_fit_percent.unwrap() < 50.0);
}

/// A validation drive faster than anything in training (the 5-minute drive, up to 10 m/s,
/// after straight lines at 2.5 m/s): the dx/dt model (speed and absolute positions as inputs)
/// falls below the floor on it, and the cause names both ranges.
#[test]
fn a_validation_drive_outside_the_training_range_is_named() {
    let dir = tmp_dir("range");
    for (scenario, seed) in [("straight-2.5", "1"), ("validation", "3")] {
        status(
            0,
            &[
                "simulate-drive",
                "--scenario",
                scenario,
                "--seed",
                seed,
                "--out",
                s(&dir),
            ],
        );
    }
    let model = dir.join("m.toml");
    let stderr = status(
        1,
        &[
            "identify",
            s(&dir.join("straight-2.5.csv")),
            "--validate",
            s(&dir.join("validation.csv")),
            "--out",
            s(&model),
        ],
    );
    assert!(
        stderr.contains("[dx_dt] validation fit")
            && stderr.contains("the validation drive leaves the training range (speeds up to 10."),
        "{stderr}"
    );
    assert!(stderr.contains("trained up to 2."), "{stderr}");
    assert!(!model.exists());
}

/// A parked car's log (the receiver measured, the car never moving): replay says why the node
/// had no position, instead of suspecting the receiver's rate (a review; the rate was right).
#[test]
fn a_parked_cars_replay_says_the_car_never_moved() {
    let dir = tmp_dir("parked");
    status(
        0,
        &[
            "simulate-drive",
            "--scenario",
            "standstill",
            "--out",
            s(&dir),
        ],
    );
    let stderr = status(
        0,
        &[
            "replay",
            s(&dir.join("standstill.can.log")),
            "--out",
            s(&dir.join("p.csv")),
        ],
    );
    assert!(
        stderr.contains("no valid position") && stderr.contains("the car never moved"),
        "{stderr}"
    );
    assert!(!stderr.contains("gnss_rate_hz"), "{stderr}");
}
