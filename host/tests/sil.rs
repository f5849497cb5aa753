//! `catmodel sil --stdio` through a pipe, as a simulator drives it: lockstep (each TICK's
//! answer is read before the next line is written), the frames of a tick equal to what
//! `catmodel replay` makes of the same input (plus the controller's CONTROL_COMMAND), stamps and
//! END lines, and the protocol's errors with their line numbers.
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

const BIN: &str = env!("CARGO_BIN_EXE_catmodel");
const ORIGIN: &str = "32.2319,-110.9501";

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("data")
        .join(name)
}

fn tmp_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("sil_{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// `(SECONDS.UUUUUU)` of a candump line, in microseconds.
fn stamp_us(line: &str) -> u64 {
    let inner = &line[1..line.find(')').unwrap()];
    let (s, us) = inner.split_once('.').unwrap();
    s.parse::<u64>().unwrap() * 1_000_000 + us.parse::<u64>().unwrap()
}

fn seconds(t_us: u64) -> String {
    format!("{}.{:06}", t_us / 1_000_000, t_us % 1_000_000)
}

#[test]
fn lockstep_session_matches_replay_tick_by_tick() {
    let input = std::fs::read_to_string(data("bundled.can.log")).unwrap();
    let lines: Vec<&str> = input.lines().collect();
    let mut child = Command::new(BIN)
        .args(["sil", "--stdio", "--origin", ORIGIN])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let mut stdout = BufReader::new(child.stdout.take().unwrap());
    // The replay's schedule: first tick at the first frame's 20 ms slot, every 20 ms after, a
    // tick gets every frame stamped since the previous one. Run the first 3 s.
    let first = stamp_us(lines[0]).div_ceil(20_000) * 20_000;
    let mut next = 0;
    let mut answers = Vec::new();
    for k in 0..150u64 {
        let t = first + k * 20_000;
        while next < lines.len() && stamp_us(lines[next]) <= t {
            writeln!(stdin, "{}", lines[next]).unwrap();
            next += 1;
        }
        writeln!(stdin, "TICK {}", seconds(t)).unwrap();
        stdin.flush().unwrap();
        // Lockstep: the answer arrives before any further input is written.
        let mut tick_lines = Vec::new();
        loop {
            let mut line = String::new();
            assert!(stdout.read_line(&mut line).unwrap() > 0, "EOF before END");
            let line = line.trim_end().to_string();
            if let Some(end) = line.strip_prefix("END ") {
                assert_eq!(end, format!("{:010}.{:06}", t / 1_000_000, t % 1_000_000));
                break;
            }
            assert_eq!(stamp_us(&line), t, "{line}");
            tick_lines.push(line);
        }
        // 13 frames of the node and the controller's command, in that order.
        assert_eq!(tick_lines.len(), 14, "{tick_lines:?}");
        assert!(tick_lines[13].contains(" 320#"));
        answers.extend(tick_lines);
    }
    drop(stdin);
    let status = child.wait().unwrap();
    assert!(status.success());

    // The same input through replay gives the same frames, byte for byte.
    let dir = tmp_dir("replay");
    let cut: String = lines[..next].iter().map(|l| format!("{l}\n")).collect();
    let log = dir.join("cut.can.log");
    std::fs::write(&log, cut).unwrap();
    let tx = dir.join("tx.log");
    let out = Command::new(BIN)
        .args(["replay", log.to_str().unwrap(), "--origin", ORIGIN])
        .args(["--out", dir.join("p.csv").to_str().unwrap()])
        .args(["--tx-out", tx.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(out.status.success());
    let replayed = std::fs::read_to_string(&tx).unwrap();
    let replayed: Vec<&str> = replayed.lines().collect();
    // Replay stops at the tick of the last frame; the session's ticks cover the same span. The
    // node sends CONTROL_COMMAND itself: replay has it too.
    assert_eq!(answers.len(), replayed.len());
    for (a, b) in answers.iter().zip(&replayed) {
        assert_eq!(a.as_str(), *b);
    }
}

/// Runs a whole session from `input`; returns (exit code, stdout, stderr).
fn session(args: &[&str], input: &str) -> (Option<i32>, String, String) {
    let mut child = Command::new(BIN)
        .args(["sil", "--stdio"])
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(input.as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    (
        out.status.code(),
        String::from_utf8(out.stdout).unwrap(),
        String::from_utf8(out.stderr).unwrap(),
    )
}

#[test]
fn end_of_input_ends_the_session_and_blank_lines_are_skipped() {
    let (code, out, err) = session(&[], "\nTICK 0.020000\n\nTICK 0.040000\n");
    assert_eq!(code, Some(0), "{err}");
    let ends: Vec<&str> = out.lines().filter(|l| l.starts_with("END ")).collect();
    assert_eq!(ends, ["END 0000000000.020000", "END 0000000000.040000"]);
    // No input frames: the node still publishes its tick (position not valid, no path).
    assert_eq!(out.lines().count(), 2 * 15);
    let (code, out, _) = session(&[], "");
    assert_eq!((code, out.as_str()), (Some(0), ""));
}

/// The first tick's NODE_STATUS page 0 `steer_stale` bit of a session.
fn steer_stale_at_first_tick(input: &str) -> bool {
    use catmodel::can::{candump, NodeStatus};
    let (code, out, err) = session(&[], input);
    assert_eq!(code, Some(0), "{err}");
    let status = out
        .lines()
        .filter_map(|l| candump::parse_line(l).ok())
        .find_map(|f| NodeStatus::decode(&f.frame).ok())
        .expect("a status page")
        .0;
    match status {
        NodeStatus::Health { health, .. } => health.steer_stale,
        other => panic!("the first tick sends page 0, got {other:?}"),
    }
}

#[test]
fn a_frame_stamped_after_its_tick_is_the_nodes_to_reject() {
    // A valid steering report (12.34 %, counter 0, its CRC) given before TICK 0.02: stamped at
    // 0.01 the node takes it (steering fresh); stamped at 0.03, after the tick, the node
    // rejects it as the firmware would (steering stale).
    let frame = catmodel::can::SteeringReport {
        steer_pct: Some(12.34),
    }
    .encode(0);
    let line = |t_us| catmodel_host::replay::candump_line(t_us, &frame);
    assert!(!steer_stale_at_first_tick(&format!(
        "{}\nTICK 0.020000\n",
        line(10_000)
    )));
    assert!(steer_stale_at_first_tick(&format!(
        "{}\nTICK 0.020000\n",
        line(30_000)
    )));
}

#[test]
fn malformed_lines_are_errors_naming_their_line() {
    for (input, line, needle) in [
        (
            "TICK 0.020000\nhello\n",
            2,
            "neither a candump line nor `TICK",
        ),
        ("TICK 0.02\n", 1, "expected `TICK SECONDS.UUUUUU`"),
        ("TICK\n", 1, "expected `TICK SECONDS.UUUUUU`"),
        (
            "TICK 0.040000\nTICK 0.040000\n",
            2,
            "is not later than the previous TICK",
        ),
        (
            "TICK 0.040000\nTICK 0.020000\n",
            2,
            "is not later than the previous TICK",
        ),
        ("(0000000000.010000) can0 100#ZZ\n", 1, "data is not hex"),
    ] {
        let (code, out, err) = session(&[], input);
        assert_eq!(code, Some(1), "{input:?}: {err}");
        assert!(
            err.contains(&format!("stdin:{line}: ")) && err.contains(needle),
            "{input:?}: {err}"
        );
        // Ticks before the bad line were answered in full.
        let ticks_before = input
            .lines()
            .take(line - 1)
            .filter(|l| l.starts_with("TICK"))
            .count();
        assert_eq!(
            out.lines().filter(|l| l.starts_with("END")).count(),
            ticks_before
        );
    }
    let out = Command::new(BIN).args(["sil"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2), "--stdio is required");
}
