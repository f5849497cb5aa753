//! candump files as can-utils' candump.c writes them, through the built `catmodel` binary
//! (docs/logs.md, "candump"; docs/findings.md, "Fixed"): the screen format with its leading
//! space, `-l` with right-aligned interface names, `-l -x` flags, `-d` drop counts, a last line
//! cut short, delta timestamps, and logs of several interfaces. Each variant of the smoke drive
//! replays to the same predictions as the plain log.
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const BIN: &str = env!("CARGO_BIN_EXE_catmodel");

fn tmp_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("candump_variants_{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn smoke() -> String {
    std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/smoke.can.log"))
        .unwrap()
}

fn run(args: &[&str]) -> Output {
    Command::new(BIN).args(args).output().unwrap()
}

/// Replays `text` (written to DIR/NAME), with `extra` arguments: exit status, predictions,
/// stderr.
fn replay(dir: &Path, name: &str, text: &str, extra: &[&str]) -> (i32, String, String) {
    let log = dir.join(name);
    std::fs::write(&log, text).unwrap();
    let out = dir.join(format!("{name}.csv"));
    let _ = std::fs::remove_file(&out);
    let mut args = vec![
        "replay",
        log.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let o = run(&args);
    (
        o.status.code().unwrap(),
        std::fs::read_to_string(&out).unwrap_or_default(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// Rewrites each line of the plain log with `f`.
fn each_line(text: &str, mut f: impl FnMut(&str) -> String) -> String {
    text.lines().map(|l| f(l) + "\n").collect()
}

/// `(TS) can0 ID#DATA` as candump's screen format writes it: `printf(" %s", ...)`, the
/// timestamp, a space, the name, two spaces, the identifier right-aligned, `[LEN]`, the bytes.
fn screen(line: &str) -> String {
    let (stamp, rest) = line.split_once(' ').unwrap();
    let (iface, frame) = rest.split_once(' ').unwrap();
    let (id, data) = frame.split_once('#').unwrap();
    let bytes: Vec<&str> = (0..data.len() / 2)
        .map(|i| &data[2 * i..2 * i + 2])
        .collect();
    format!(
        " {stamp}  {iface}  {id:>8}   [{}]  {}",
        bytes.len(),
        bytes.join(" ")
    )
}

#[test]
fn the_screen_format_as_candump_prints_it_replays_like_the_log() {
    let dir = tmp_dir("screen");
    let plain = smoke();
    let (code, want, stderr) = replay(&dir, "plain.log", &plain, &[]);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        !stderr.contains("note:") && !stderr.contains("warning:"),
        "{stderr}"
    );
    // `candump -ta can0 > file`: every line starts with a space.
    let ta = each_line(&plain, screen);
    assert!(ta.starts_with(" (0000000000.003296)  can0  09F8011C   [8]  7F 32"));
    let (code, got, stderr) = replay(&dir, "ta.log", &ta, &[]);
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(got, want);
}

/// The seconds and microseconds of a log line's `(SSSSSSSSSS.UUUUUU)`, and the rest.
fn stamp(line: &str) -> (u64, &str, &str) {
    let close = line.find(')').unwrap();
    let (s, us) = line[1..close].split_once('.').unwrap();
    (s.parse().unwrap(), us, &line[close + 1..])
}

/// `candump -N` (nanoseconds) in the log format, and `candump -t A -N -x` (the date, local
/// time, nanoseconds, `RX - -`) in the screen format: the same predictions as the plain log;
/// and a date log whose clock goes back (daylight saving time ends) is refused with the cause.
#[test]
fn nanoseconds_dates_and_screen_flags_replay_like_the_log() {
    let dir = tmp_dir("dated");
    let plain = smoke();
    let (code, want, stderr) = replay(&dir, "plain.log", &plain, &[]);
    assert_eq!(code, 0, "{stderr}");
    let ns = each_line(&plain, |l| {
        let (s, us, rest) = stamp(l);
        format!("({s:010}.{us}789){rest}")
    });
    // The smoke drive starts at 0 s: 1970-01-01 at midnight, and lasts less than an hour.
    let date = |s: u64| format!("1970-01-01 00:{:02}:{:02}", s / 60, s % 60);
    let dated = each_line(&plain, |l| {
        let (s, us, _) = stamp(l);
        let written = screen(l).replacen("  can0  ", "  can0  RX - -  ", 1);
        let close = written.find(')').unwrap();
        format!(" ({}.{us}001{}", date(s), &written[close..])
    });
    assert!(
        dated.starts_with(" (1970-01-01 00:00:00.003296001)  can0  RX - -  09F8011C   [8]"),
        "{}",
        &dated[..80]
    );
    for (name, text) in [("ns.log", ns), ("dated.log", dated.clone())] {
        let (code, got, stderr) = replay(&dir, name, &text, &[]);
        assert_eq!(code, 0, "{name}: {stderr}");
        assert_eq!(got, want, "{name}");
    }
    // Local time goes back an hour where daylight saving time ends: the first half of the
    // drive stamped an hour later than the second.
    let at = dated.lines().count() / 2;
    let shifted: String = dated
        .lines()
        .enumerate()
        .map(|(i, l)| {
            let l = if i < at {
                l.replacen("(1970-01-01 00:", "(1970-01-01 01:", 1)
            } else {
                l.to_owned()
            };
            l + "\n"
        })
        .collect();
    let (code, _, stderr) = replay(&dir, "dst.log", &shifted, &[]);
    assert_eq!(code, 1, "{stderr}");
    assert!(
        stderr.contains(&format!("dst.log:{}: time goes backwards", at + 1)),
        "{stderr}"
    );
    assert!(
        stderr.contains("`candump -t A` writes the recorder's local time"),
        "{stderr}"
    );
}

#[test]
fn delta_timestamps_are_refused_by_name() {
    let dir = tmp_dir("delta");
    // `candump -td`: `(%03lu.%06lu)`, the time since the frame before.
    let mut last = None;
    let td = each_line(&smoke(), |l| {
        let close = l.find(')').unwrap();
        let (s, us) = l[1..close].split_once('.').unwrap();
        let t = s.parse::<u64>().unwrap() * 1_000_000 + us.parse::<u64>().unwrap();
        let d = t - last.replace(t).unwrap_or(t);
        screen(&format!(
            "({:03}.{:06}){}",
            d / 1_000_000,
            d % 1_000_000,
            &l[close + 1..]
        ))
    });
    let (code, _, stderr) = replay(&dir, "td.log", &td, &[]);
    assert_eq!(code, 1, "{stderr}");
    assert!(stderr.contains("td.log:"), "{stderr}");
    assert!(stderr.contains("time goes backwards"), "{stderr}");
    assert!(stderr.contains("look like `candump -td`'s"), "{stderr}");
}

#[test]
fn candump_l_variants_replay_like_the_plain_log() {
    let dir = tmp_dir("variants");
    let plain = smoke();
    let (_, want, _) = replay(&dir, "plain.log", &plain, &[]);
    // `-l` on can0 and vcan10: `%*s` right-aligns the names to the longest.
    let padded = plain.replace(") can0 ", ")   can0 ");
    // `-l -x`: ` R` received, ` T` sent by this host.
    let flagged = each_line(&plain, |l| format!("{l} R"));
    for (name, text) in [("padded.log", padded), ("xflag.log", flagged)] {
        let (code, got, stderr) = replay(&dir, name, &text, &[]);
        assert_eq!(code, 0, "{name}: {stderr}");
        assert_eq!(got, want, "{name}");
    }
    // `-d`: the socket's drop counter, skipped and reported with its line and count.
    let mut lines: Vec<&str> = plain.lines().collect();
    lines.insert(
        500,
        "DROPCOUNT: dropped 3 CAN frames on 'can0' socket (total drops 3)",
    );
    lines.insert(
        900,
        "DROPCOUNT: dropped 1 CAN frame on 'can0' socket (total drops 4)",
    );
    let (code, got, stderr) = replay(&dir, "drops.log", &(lines.join("\n") + "\n"), &[]);
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(got, want);
    assert!(
        stderr.contains(
            "catmodel: warning: ",
        ) && stderr.contains("drops.log:501: the recording lost 4 frame(s): candump -d reported drops on 2 line(s)"),
        "{stderr}"
    );
}

#[test]
fn a_last_line_cut_short_is_left_out_and_one_elsewhere_refused() {
    let dir = tmp_dir("trunc");
    let plain = smoke();
    let lines: Vec<&str> = plain.lines().collect();
    let n = lines.len();
    let all_but_last = lines[..n - 1].join("\n") + "\n";
    let (_, want, _) = replay(&dir, "shorter.log", &all_but_last, &[]);
    for cut in [10, 30] {
        // Power lost mid-line: no line end.
        let text = all_but_last.clone() + &lines[n - 1][..cut];
        let (code, got, stderr) = replay(&dir, "cut.log", &text, &[]);
        assert_eq!(code, 0, "{stderr}");
        assert_eq!(got, want);
        assert!(
            stderr.contains(&format!("cut.log:{n}: the last line is cut short")),
            "{stderr}"
        );
    }
    // The same line with its line end, or in the middle: an error.
    let ended = all_but_last.clone() + &lines[n - 1][..30] + "\n";
    let (code, _, stderr) = replay(&dir, "ended.log", &ended, &[]);
    assert_eq!(code, 1, "{stderr}");
    assert!(
        stderr.contains(&format!("ended.log:{n}: malformed candump line")),
        "{stderr}"
    );
    let middle = lines[..10].join("\n") + "\n" + &lines[10][..30] + "\n" + &lines[11..].join("\n");
    let (code, _, stderr) = replay(&dir, "middle.log", &middle, &[]);
    assert_eq!(code, 1, "{stderr}");
    assert!(
        stderr.contains("middle.log:11: malformed candump line"),
        "{stderr}"
    );
}

#[test]
fn frames_of_two_interfaces_are_named_and_one_is_kept_on_request() {
    let dir = tmp_dir("twoif");
    let plain = smoke();
    let (_, want, _) = replay(&dir, "plain.log", &plain, &[]);
    // A second bus with the same identifiers and other data, as a recorder on can0 and can1.
    let two = each_line(&plain, |l| {
        if let Some((head, data)) = l.split_once(" can0 101#") {
            format!("{l}\n{head} can1 101#{}", data.replace('0', "1"))
        } else {
            l.to_string()
        }
    });
    let (code, got, stderr) = replay(&dir, "two.log", &two, &[]);
    assert_eq!(code, 0, "{stderr}");
    // can1's frames reach the node (and fail its CRC check).
    assert!(got.len() > 1000);
    assert!(!stderr.contains("rejected: crc 0,"), "{stderr}");
    assert!(
        stderr.contains("two.log: frames of 2 interfaces, `can0` ("),
        "{stderr}"
    );
    assert!(stderr.contains("`--interface NAME` keeps one"), "{stderr}");
    let (code, got, stderr) = replay(&dir, "two.log", &two, &["--interface", "can0"]);
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(got, want);
    assert!(stderr.contains("only `can0`'s are read"), "{stderr}");
    let (code, _, stderr) = replay(&dir, "two.log", &two, &["--interface", "can9"]);
    assert_eq!(code, 1, "{stderr}");
    assert!(
        stderr.contains(
            "no frame on interface `can9` (--interface); the log's interfaces: `can0`, `can1`"
        ),
        "{stderr}"
    );
    // decode keeps the same frames.
    let decode = |log: &Path, extra: &[&str]| {
        let mut args = vec!["decode", log.to_str().unwrap()];
        args.extend_from_slice(extra);
        String::from_utf8(run(&args).stdout).unwrap()
    };
    assert_eq!(
        decode(&dir.join("two.log"), &["--interface", "can0"]),
        decode(&dir.join("plain.log"), &[])
    );
}

/// Stamps rounded up to the next multiple of `batch_us`, as a recorder that reads its queue in
/// batches and stamps each batch writes them (review finding 03's `batch.py`).
fn batched(text: &str, batch_us: u64) -> String {
    each_line(text, |l| {
        let (stamp, rest) = l.split_once(' ').unwrap();
        let (s, us) = stamp
            .trim_start_matches('(')
            .trim_end_matches(')')
            .split_once('.')
            .unwrap();
        let t = s.parse::<u64>().unwrap() * 1_000_000 + us.parse::<u64>().unwrap();
        let t = t.div_ceil(batch_us) * batch_us;
        format!("({:010}.{:06}) {rest}", t / 1_000_000, t % 1_000_000)
    })
}

/// A candump stamped in batches coarser than the node's 20 ms tick replays as given (exit 0),
/// with a warning saying what it is and what it does to the estimate (review finding 03: the
/// filtered position 9 m RMS off without a word); batches of one tick, the plain log and a
/// slow bus (one frame every 100 ms, no message twice at one timestamp) get no warning.
#[test]
fn timestamps_in_batches_coarser_than_a_tick_are_named() {
    let dir = tmp_dir("batched");
    let plain = smoke();
    let warned = |stderr: &str| stderr.contains("the timestamps come in batches");
    for batch_ms in [40, 50, 60] {
        let (code, pred, stderr) = replay(&dir, "b.log", &batched(&plain, batch_ms * 1000), &[]);
        assert_eq!(code, 0, "{stderr}");
        assert!(pred.starts_with("t,step,"), "{batch_ms} ms: replayed");
        assert!(warned(&stderr), "{batch_ms} ms: {stderr}");
        // No position at all (the smoke drive batched to 40 ms): the batches are named as
        // the cause, not the model file's receiver rate.
        assert!(!stderr.contains("gnss_rate_hz"), "{stderr}");
        assert!(stderr.contains("b.log: "), "{stderr}");
        assert!(
            stderr.contains(&format!("{batch_ms} ms apart on average")),
            "{stderr}"
        );
        assert!(stderr.contains("filtered position"), "{stderr}");
    }
    for (name, text) in [
        ("plain.log", plain.clone()),
        ("tick.log", batched(&plain, 20_000)),
        // A slow bus: every fifth line, stamped 100 ms apart.
        (
            "slow.log",
            plain
                .lines()
                .step_by(5)
                .enumerate()
                .map(|(i, l)| {
                    let t = i as u64 * 100_000;
                    let rest = l.split_once(' ').unwrap().1;
                    format!("({:010}.{:06}) {rest}\n", t / 1_000_000, t % 1_000_000)
                })
                .collect(),
        ),
    ] {
        let (code, _, stderr) = replay(&dir, name, &text, &[]);
        assert_eq!(code, 0, "{name}: {stderr}");
        assert!(!warned(&stderr), "{name}: {stderr}");
    }
}

/// The smoke drive's GNSS positions (PGN 129025, `09F8011C`: source address 0x1C) with another
/// source address, as from a receiver configured otherwise: `replay` names the address the
/// positions came from and the key to set (a black-box probe's 0x1D receiver had its fixes
/// counted as unknown ids and the model file's `gnss_rate_hz` blamed). With four more receivers
/// beside the car's, 14 frames a tick reach the 12 the node takes: the receive queue drops
/// frames, as the firmware's does, and the warning says so.
#[test]
fn gnss_positions_of_other_source_addresses_are_named() {
    let dir = tmp_dir("other-sources");
    let plain = smoke();
    assert!(plain.contains(" 09F8011C#"));
    let moved = plain.replace(" 09F8011C#", " 09F8011D#");
    let (code, _, stderr) = replay(&dir, "sa1d.log", &moved, &[]);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stderr.contains("no GNSS position came from source address 28")
            && stderr.contains("set gnss_source_address = 29"),
        "{stderr}"
    );
    assert!(!stderr.contains("gnss_rate_hz"), "{stderr}");
    let flooded = each_line(&plain, |l| {
        if l.contains(" 09F8011C#") {
            ["1C", "1D", "00", "01", "02"]
                .iter()
                .map(|sa| l.replace(" 09F8011C#", &format!(" 09F801{sa}#")))
                .collect::<Vec<_>>()
                .join("\n")
        } else {
            l.to_string()
        }
    });
    let (code, _, stderr) = replay(&dir, "flooded.log", &flooded, &[]);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stderr.contains("frames were dropped by the full receive queue (64 frames)"),
        "{stderr}"
    );
    assert!(
        stderr.contains("GNSS positions from other source addresses than the model file's 28"),
        "{stderr}"
    );
}

#[test]
fn a_raw_dlc_suffix_of_can_utils_is_read_and_a_wrong_one_named() {
    // can-utils' lib.c writes `_` and the DLC field 9..F after the data of a classic frame of
    // 8 bytes whose DLC said more (CAN_CTRLMODE_CC_LEN8_DLC). A black-box probe's log with it
    // on every frame was refused: "malformed candump line (data is not hex)".
    let dir = tmp_dir("raw-dlc");
    let plain = smoke();
    let (_, want, _) = replay(&dir, "plain.log", &plain, &[]);
    let mut k = 0;
    let suffixed = each_line(&plain, |l| {
        k += 1;
        format!("{l}_{:X}", 9 + k % 7)
    });
    let (code, got, stderr) = replay(&dir, "dlc.log", &suffixed, &[]);
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(got, want);
    assert!(
        stderr.contains("dlc.log:1: 3739 frame(s) carry can-utils' raw DLC suffix"),
        "{stderr}"
    );
    // With `candump -l -x`'s flag after it.
    let flagged = each_line(&plain, |l| format!("{l}_9 R"));
    let (code, got, stderr) = replay(&dir, "dlcx.log", &flagged, &[]);
    assert_eq!((code, got == want), (0, true), "{stderr}");
    // A suffix can-utils never writes is refused by name, not as "data is not hex" (the one
    // reader of the format, the core's, which the firmware's QEMU replay parses with too).
    let why = "`_` after the data, but not can-utils' raw DLC suffix";
    for line in [
        "(0000000000.003745) can0 100#ECFF0000000000BB_8",
        "(0000000000.003745) can0 100#ECFF_9",
    ] {
        let (first, rest) = plain.split_once('\n').unwrap();
        let text = format!("{first}\n{line}\n{rest}");
        let (code, _, stderr) = replay(&dir, "bad.log", &text, &[]);
        assert_eq!(code, 1, "{stderr}");
        assert!(
            stderr.contains(&format!("bad.log:2: malformed candump line ({why}")),
            "{stderr}"
        );
    }
}

#[test]
fn lines_written_twice_are_named_and_read_once() {
    // A black-box probe's log with every line twice replayed with "counter 2243" rejections,
    // the receiver blamed ("the receiver's fixes came at 200.1 Hz ... set the receiver to send
    // at 100 Hz or less") and no prediction, the repeat never named.
    let dir = tmp_dir("twice");
    let plain = smoke();
    let (_, want, _) = replay(&dir, "plain.log", &plain, &[]);
    let twice = each_line(&plain, |l| format!("{l}\n{l}"));
    let (code, got, stderr) = replay(&dir, "twice.log", &twice, &[]);
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(got, want);
    assert!(
        stderr.contains(
            "twice.log:2: 3739 frame line(s) repeat the line before them exactly (the same \
             timestamp to the microsecond, interface, identifier and data), every frame of the \
             log twice: a logger that wrote frames twice."
        ) && stderr.contains("counter 0,"),
        "{stderr}"
    );
    assert!(!stderr.contains("Hz"), "{stderr}");
    // Some lines twice: counted; the same frame on two interfaces is not a repeat.
    let mut k = 0;
    let some = each_line(&plain, |l| {
        k += 1;
        match k % 100 {
            0 => format!("{l}\n{l}"),
            1 => format!("{l}\n{}", l.replace(" can0 ", " can1 ")),
            _ => l.to_string(),
        }
    });
    let (code, _, stderr) = replay(&dir, "some.log", &some, &[]);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stderr.contains("some.log:102: 37 frame line(s) repeat the line before them exactly")
            && !stderr.contains("every frame"),
        "{stderr}"
    );
}

#[test]
fn an_input_that_came_as_can_fd_is_named() {
    // A black-box probe's log with every STEERING_REPORT as a CAN FD frame replayed with exit
    // 0 and 557 of 6117 prediction rows; the only sign was "skipped: 748 remote/FD/error
    // frames".
    let dir = tmp_dir("fd-input");
    let plain = smoke();
    let fd = plain.replace(" can0 100#", " can0 100##0");
    let (code, _, stderr) = replay(&dir, "fd.log", &fd, &[]);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stderr.contains(
            "fd.log: no STEERING_REPORT (0x100) arrived as classic CAN: its 748 frames came as \
             CAN FD frames (`##` in the log format, a two-digit `[LEN]` in the screen format), which the node does not read"
        ),
        "{stderr}"
    );
    let mut k = 0;
    let some = each_line(&plain, |l| {
        k += 1;
        if k % 2 == 0 {
            l.replace(" can0 101#", " can0 101##1")
        } else {
            l.to_string()
        }
    });
    let (code, _, stderr) = replay(&dir, "some.log", &some, &[]);
    assert_eq!(code, 0, "{stderr}");
    let n = some.matches("101##").count();
    assert!(n > 0);
    assert!(
        stderr.contains(&format!(
            "some.log: {n} SPEED_REPORT frames (0x101) came as CAN FD frames (`##` in the log format, a two-digit `[LEN]` in the screen format), \
             beside {} as classic CAN",
            748 - n
        )),
        "{stderr}"
    );
    // The plain log: no word of CAN FD.
    let (_, _, stderr) = replay(&dir, "plain.log", &plain, &[]);
    assert!(!stderr.contains("CAN FD"), "{stderr}");
}

#[test]
fn eleven_bit_identifiers_written_as_29_bit_are_named() {
    // A converter that writes every identifier with 8 hex digits turns STEERING_REPORT's
    // 0x100 into the 29-bit 0x00000100, a different frame on the bus: the node ran without
    // steering and nothing said why.
    let dir = tmp_dir("as-extended");
    let plain = smoke();
    let n = plain.matches(" can0 100#").count();
    assert!(n > 0);
    let wide = plain.replace(" can0 100#", " can0 00000100#");
    let (code, _, stderr) = replay(&dir, "wide.log", &wide, &[]);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stderr.contains(&format!(
            "wide.log: {n} frames with the 29-bit identifier 0x00000100 carry the number of \
             STEERING_REPORT (0x100, an 11-bit identifier in catmodel.dbc), and no \
             STEERING_REPORT came with the 11-bit one, so the node ran without it"
        )),
        "{stderr}"
    );
    assert!(
        stderr.contains("write the 11-bit ones with 3 (`100#...`)"),
        "{stderr}"
    );
    // The plain log: no word of it.
    let (_, _, stderr) = replay(&dir, "plain.log", &plain, &[]);
    assert!(!stderr.contains("29-bit"), "{stderr}");
}

#[test]
fn a_log_without_speed_reports_is_not_called_a_parked_car() {
    // With no SPEED_REPORT the node's speed is 0 throughout and it never has a position; the
    // replay said "the car never moved", blaming the drive for what the log lacks.
    let dir = tmp_dir("no-speed");
    let plain = smoke();
    let without: String = plain
        .lines()
        .filter(|l| !l.contains(" can0 101#"))
        .map(|l| format!("{l}\n"))
        .collect();
    let (code, _, stderr) = replay(&dir, "nospeed.log", &without, &[]);
    assert_eq!(code, 0, "{stderr}");
    assert!(!stderr.contains("never moved"), "{stderr}");
    assert!(
        stderr.contains("the log holds no SPEED_REPORT (0x101) the node could read"),
        "{stderr}"
    );
}

#[test]
fn a_pause_of_every_input_is_named() {
    // A black-box probe's log with every frame cut for three minutes replayed without a word
    // (docs/findings.md, silent inputs): the pause the node's heading came back from wrong.
    let dir = tmp_dir("pause");
    let plain = smoke();
    let stamp_s = |l: &str| -> f64 { l[1..l.find(')').unwrap()].parse().unwrap() };
    let cut: String = plain
        .lines()
        .filter(|l| !(5.0..8.0).contains(&stamp_s(l)))
        .map(|l| format!("{l}\n"))
        .collect();
    let line = cut.lines().position(|l| stamp_s(l) >= 8.0).unwrap() + 1;
    let (code, _, stderr) = replay(&dir, "pause.log", &cut, &[]);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stderr.contains(&format!(
            "pause.log:{line}: the log pauses 1 time(s) with no frame for more than 1 s, the \
             longest 3.0 s"
        )),
        "{stderr}"
    );
    let (_, _, stderr) = replay(&dir, "plain.log", &plain, &[]);
    assert!(!stderr.contains("the log pauses"), "{stderr}");
}

/// candump's screen format as its options change it (a black-box probe): a CAN FD frame's
/// two-digit `[08]` was read as classic CAN (the node took a CAN FD steering report), and
/// `-e`'s tab-indented explanation of an error frame, `-8`'s `{8}`, `-a`'s ASCII column and a
/// screen log without timestamps were refused as malformed lines, for the wrong reason. Now the
/// CAN FD frames are skipped and named, `-e`, `-8` and `-a` replay like the plain log, and a
/// log without timestamps is refused with how to record one.
#[test]
fn screen_format_options_are_read_or_named() {
    let dir = tmp_dir("screen-options");
    let plain = smoke();
    let (code, want, stderr) = replay(&dir, "plain.log", &plain, &[]);
    assert_eq!(code, 0, "{stderr}");
    let ta = each_line(&plain, screen);
    // CAN FD: lib.c writes `[%02d]`.
    let fd = ta.replace("  100   [8]", "  100  [08]");
    assert_ne!(fd, ta);
    let (code, _, stderr) = replay(&dir, "fd.log", &fd, &[]);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stderr.contains("no STEERING_REPORT (0x100) arrived as classic CAN: its 748 frames"),
        "{stderr}"
    );
    // `-e`: an error frame and its explanation, on lines that start with a tab.
    let mut lines: Vec<String> = ta.lines().map(str::to_string).collect();
    let t = &lines[100][..21];
    lines.insert(
        101,
        format!("{t}  can0  20000080   [8]  00 00 00 00 00 00 00 00   ERRORFRAME"),
    );
    lines.insert(102, "\tbus-error".to_string());
    lines.insert(103, "\tcontroller-problem{rx-error-warning}".to_string());
    let e = lines.join("\n") + "\n";
    let (code, got, stderr) = replay(&dir, "e.log", &e, &[]);
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(got, want);
    assert!(
        stderr.contains("skipped: 1 remote/FD/error frames"),
        "{stderr}"
    );
    // `-8`: the raw DLC in braces.
    let dlc = ta.replace("   [8]  ", "   {8}  ");
    let (code, got, stderr) = replay(&dir, "dlc.log", &dlc, &[]);
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(got, want);
    // `-a`: the data as ASCII in quotes (a space among them splits the column).
    let ascii = each_line(&ta, |l| format!("{l}   '.3 6..[..'"));
    let (code, got, stderr) = replay(&dir, "ascii.log", &ascii, &[]);
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(got, want);
    // No `-t`: no timestamp to replay by.
    let untimed = each_line(&ta, |l| l[21..].to_string());
    let (code, _, stderr) = replay(&dir, "untimed.log", &untimed, &[]);
    assert_eq!(code, 1);
    assert!(
        stderr.contains("untimed.log:1: a candump line without a timestamp")
            && stderr.contains("record with `candump -ta`"),
        "{stderr}"
    );
}

/// `candump -l can0 can1` reads its sockets in turn, so a frame of `can1` can be written
/// after a later frame of `can0` (a black-box probe's log: 428 us back, refused as "time goes
/// backwards"). Now frames of another interface up to 20 ms back are put in time order and
/// counted in a note; within one interface the time is checked as before, and more than 20 ms
/// across interfaces is refused naming `--interface`.
#[test]
fn frames_of_two_interfaces_slightly_out_of_order_are_put_in_order() {
    let dir = tmp_dir("reorder");
    let plain = smoke();
    let (_, want, _) = replay(&dir, "plain.log", &plain, &[]);
    // STEERING_REPORT on can1, each written after the frame that follows it.
    let swap = |text: &str, from: &str, to: &str| {
        let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
        let mut i = 0;
        let mut swapped = 0;
        while i + 1 < lines.len() {
            if lines[i].contains(from) && stamp(&lines[i]).1 != stamp(&lines[i + 1]).1 {
                lines[i] = lines[i].replace(from, to);
                lines.swap(i, i + 1);
                swapped += 1;
                i += 2;
            } else {
                i += 1;
            }
        }
        (lines.join("\n") + "\n", swapped)
    };
    let (two, swapped) = swap(&plain, " can0 100#", " can1 100#");
    assert!(swapped > 500);
    let (code, got, stderr) = replay(&dir, "two.log", &two, &[]);
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(got, want);
    assert!(
        stderr.contains(&format!(
            "{swapped} frame(s) were written after a later frame of another interface"
        )) && stderr.contains("put in time order"),
        "{stderr}"
    );
    // One interface: still refused.
    let (one, _) = swap(&plain, " can0 100#", " can0 100#");
    let (code, _, stderr) = replay(&dir, "one.log", &one, &[]);
    assert_eq!(code, 1);
    assert!(stderr.contains("time goes backwards"), "{stderr}");
    // Across interfaces by more than 20 ms: another clock.
    let late = each_line(&plain, |l| match l.split_once(" can0 100#") {
        Some((head, data)) => {
            let (s, us, _) = stamp(head);
            let t = s * 1_000_000 + us.parse::<u64>().unwrap() + 30_000;
            format!(
                "({:010}.{:06}) can1 100#{data}",
                t / 1_000_000,
                t % 1_000_000
            )
        }
        None => l.to_string(),
    });
    let (code, _, stderr) = replay(&dir, "late.log", &late, &[]);
    assert_eq!(code, 1);
    assert!(
        stderr.contains("time goes backwards") && stderr.contains("`--interface NAME`"),
        "{stderr}"
    );
}

/// One bus logged on two interfaces (a gateway mirrors every frame onto `can1` 200 us later):
/// a black-box probe's log replayed with exit 0 and no prediction, the copies refused by their
/// counters and the fixes blamed on a "5000 Hz" receiver. Now refused naming `--interface`;
/// with it, the plain log's predictions.
#[test]
fn one_bus_logged_on_two_interfaces_is_refused_naming_interface() {
    let dir = tmp_dir("mirror");
    let plain = smoke();
    let (_, want, _) = replay(&dir, "plain.log", &plain, &[]);
    let mirrored = each_line(&plain, |l| {
        let (s, us, rest) = stamp(l);
        let t = s * 1_000_000 + us.parse::<u64>().unwrap() + 200;
        let copy = rest.replacen(" can0 ", " can1 ", 1);
        format!("{l}\n({:010}.{:06}){copy}", t / 1_000_000, t % 1_000_000)
    });
    let (code, _, stderr) = replay(&dir, "gw.log", &mirrored, &[]);
    assert_eq!(code, 1, "{stderr}");
    let n = plain.lines().count();
    assert!(
        stderr.contains(&format!(
            "gw.log: {n} frames of `can1` repeat a frame of `can0` 0.200 ms later"
        )) && stderr.contains("replay one interface with `--interface can0`"),
        "{stderr}"
    );
    let (code, got, stderr) = replay(&dir, "gw.log", &mirrored, &["--interface", "can0"]);
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(got, want);
}
