//! `replay --model`: the published model file reproduces the firmware's default byte for byte,
//! a model identified from simulated drives runs, and a model the node cannot run is refused
//! with the reason.
use std::path::Path;
use std::process::{Command, Output};

const BIN: &str = env!("CARGO_BIN_EXE_catmodel");

fn repo(p: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(p)
        .to_str()
        .unwrap()
        .to_owned()
}

fn run(args: &[&str]) -> Output {
    Command::new(BIN).args(args).output().unwrap()
}

fn ok(args: &[&str]) {
    let out = run(args);
    assert!(
        out.status.success(),
        "catmodel {args:?}:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn published_model_file_identified_model_and_refusals() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("replay_model");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let d = dir.to_str().unwrap();
    let bundled = repo("data/bundled.can.log");

    // models/paper.toml == the compiled-in published models: the golden frames, byte for byte.
    let tx = format!("{d}/paper.tx.log");
    ok(&[
        "replay",
        &bundled,
        "--model",
        &repo("models/paper.toml"),
        "--out",
        &format!("{d}/paper.csv"),
        "--tx-out",
        &tx,
    ]);
    assert!(
        std::fs::read(&tx).unwrap() == std::fs::read(repo("data/bundled.tx.golden.log")).unwrap(),
        "replay --model models/paper.toml differs from the golden frames"
    );

    // A model identified from the straight-line experiments runs, and changes the output.
    for s in ["straight-2.5", "straight-5", "straight-7.5", "straight-10"] {
        ok(&["simulate-drive", "--scenario", s, "--out", d, "--seed", "1"]);
    }
    let logs: Vec<String> = ["straight-2.5", "straight-5", "straight-7.5", "straight-10"]
        .iter()
        .map(|s| format!("{d}/{s}.csv"))
        .collect();
    let model = format!("{d}/identified.toml");
    let mut args = vec!["identify"];
    args.extend(logs.iter().map(String::as_str));
    args.extend(["--out", &model]);
    ok(&args);
    let tx2 = format!("{d}/identified.tx.log");
    ok(&[
        "replay",
        &bundled,
        "--model",
        &model,
        "--out",
        &format!("{d}/identified.csv"),
        "--tx-out",
        &tx2,
    ]);
    let a = std::fs::read_to_string(&tx).unwrap();
    let b = std::fs::read_to_string(&tx2).unwrap();
    assert_eq!(
        a.lines().count(),
        b.lines().count(),
        "same ticks, same frames"
    );
    assert_ne!(a, b, "an identified model changes the predictions");
}

/// Every file of the bad corpus (`models/bad/`) is refused by `replay --model` with exit status
/// 1 and exactly the reader's message (the firmware build prints the same message: `cargo
/// xtask model-corpus`).
#[test]
fn replay_refuses_the_bad_corpus_with_the_readers_message() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/bad");
    let mut checked = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        let message = catmodel_host::model_file::load(&path).unwrap_err().message;
        let out = run(&[
            "replay",
            &repo("data/bundled.can.log"),
            "--model",
            path.to_str().unwrap(),
            "--out",
            "/dev/null",
        ]);
        assert_eq!(out.status.code(), Some(1), "{}", path.display());
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(
            err.trim_end(),
            format!("catmodel: error: {}: {message}", path.display()),
            "{}",
            path.display()
        );
        checked += 1;
    }
    assert!(checked >= 20);
}
