//! The log and truth CSV readers/writers: round trips, logs as recorders write them (column
//! order, extra columns, empty cells, equal timestamps, CRLF, a byte-order mark), physical
//! ranges, and every rejection with its `file:line:column` message.
use catmodel_host::logcsv::{
    self, Conflict, LogErrorKind, LogRow, TruthRow, LOG_COLUMNS, LOG_RANGES,
};
use proptest::prelude::*;
use std::path::Path;

const FILE: &str = "drive.csv";

fn parse(text: &str) -> Result<Vec<LogRow>, logcsv::LogError> {
    logcsv::parse_log(text, Path::new(FILE)).map(|log| log.rows)
}

fn notes(text: &str) -> Vec<String> {
    logcsv::parse_log(text, Path::new(FILE))
        .expect("valid")
        .notes
        .messages()
}

fn error_message(text: &str) -> String {
    match parse(text) {
        Ok(rows) => panic!("accepted: {rows:?}"),
        Err(e) => e.to_string(),
    }
}

const HEADER: &str = "t,vel,input_vel,accel,steer,brake,lat,lon";

#[test]
fn reads_columns_in_any_order_ignores_extras_and_empty_cells_are_missing() {
    let text = "\u{feff}lon,extra,t,steer,vel,input_vel,accel,brake,lat\r\n\
                -110.95,junk,0.5,-12.5,,,,,32.23\r\n\
                ,x,0.52,,3.25,4,10,0,\r\n";
    let rows = parse(text).expect("valid");
    assert_eq!(
        rows,
        vec![
            LogRow {
                t: 0.5,
                steer: Some(-12.5),
                lat: Some(32.23),
                lon: Some(-110.95),
                ..LogRow::empty(0.0)
            },
            LogRow {
                t: 0.52,
                vel: Some(3.25),
                input_vel: Some(4.0),
                accel: Some(10.0),
                brake: Some(0.0),
                ..LogRow::empty(0.0)
            },
        ]
    );
    // Quoted cells and surrounding spaces are accepted; trailing blank lines end the file.
    let rows = parse("\"t\", vel ,input_vel,accel,steer,brake,lat,lon\n\"1.5\", 2 ,,,,,,\n\n\n")
        .expect("valid");
    assert_eq!(
        rows,
        vec![LogRow {
            t: 1.5,
            vel: Some(2.0),
            ..LogRow::empty(0.0)
        }]
    );
}

/// A `steer` a few tenths of a per cent past full lock is a sensor calibrated a little past
/// it (a black-box probe's 100.9 % refused the whole log): read as the lock, what the steering
/// report on the bus carries, and counted in a note naming the largest and its line; past
/// 105 % it is still refused, naming the line.
#[test]
fn a_steer_a_little_past_the_lock_is_read_as_the_lock_and_counted() {
    let text =
        format!("{HEADER}\n0.1,,,,100.9,,,\n0.2,,,,-100.4,,,\n0.3,,,,-101.2,,,\n0.4,,,,99.5,,,\n");
    let steer: Vec<Option<f64>> = parse(&text)
        .expect("read")
        .iter()
        .map(|r| r.steer)
        .collect();
    assert_eq!(steer, [Some(100.0), Some(-100.0), Some(-100.0), Some(99.5)]);
    assert_eq!(
        notes(&text),
        ["drive.csv:4: column `steer`: 3 sample(s) past full lock, the largest -101.2 % on this \
          line: a steering sensor calibrated a little past its lock (up to 105 % is taken so); \
          read as the lock, -100 % (the steering report on the bus carries no more, so the node \
          reads the lock there too)"]
    );
    assert_eq!(
        notes(&format!("{HEADER}\n0.1,,,,100,,,\n0.2,,,,-100,,,\n")),
        [] as [String; 0]
    );
    let e = parse(&format!("{HEADER}\n0.1,,,,100.9,,,\n0.2,,,,105.01,,,\n")).expect_err("refused");
    assert_eq!(e.line, 3, "{e}");
    assert!(
        matches!(e.kind, LogErrorKind::OutOfRange { value, .. } if value == 105.01),
        "{e}"
    );
}

#[test]
fn every_malformed_file_is_rejected_with_file_line_and_column() {
    let cases: &[(&str, &str)] = &[
        ("", "drive.csv:1: missing header row"),
        ("1,2,3,4,5,6,7,8\n", "drive.csv:1:1: missing header row"),
        (
            "t,vel,\"input_vel,accel\n",
            "drive.csv:1:7: the quote that opens this cell is never closed (RFC 4180: a quoted \
             cell ends at the next lone `\"`; `\"\"` is a quote inside it)",
        ),
        ("t,vel,t\n", "drive.csv:1:7: column `t`: column `t` appears twice in the header"),
        ("t,vel,input_vel,accel,steer,brake,lat\n", "drive.csv:1: column `lon`: missing required column `lon` (the header found: `t,vel,input_vel,accel,steer,brake,lat`)"),
        (
            "t,vel,input_vel,accel,steer,brake,lat,lon\n0.1,abc,,,,,,\n",
            "drive.csv:2:5: column `vel`: not a number: `abc`",
        ),
        (
            "t,vel,input_vel,accel,steer,brake,lat,lon\n0.1,,,,,,,\n0.2,1,NaN,,,,,\n",
            "drive.csv:3:7: column `input_vel`: non-finite value: `NaN`",
        ),
        (
            "t,vel,input_vel,accel,steer,brake,lat,lon\n0.1,inf,,,,,,\n",
            "drive.csv:2:5: column `vel`: non-finite value: `inf`",
        ),
        (
            "t,vel,input_vel,accel,steer,brake,lat,lon\n0.2,,,,,,,\n0.1,,,,,,,\n",
            "drive.csv:3:1: column `t`: time goes backwards: 0.1 after 0.2",
        ),
        (
            "t,vel,input_vel,accel,steer,brake,lat,lon\n0.2,,,,,,,\n0.2,,,,,,,\n0.1999,,,,,,,\n",
            "drive.csv:4:1: column `t`: time goes backwards: 0.1999 after 0.2",
        ),
        (
            "t,vel,input_vel,accel,steer,brake,lat,lon\n,1,,,,,,\n",
            "drive.csv:2:1: column `t`: empty cell where a value is required",
        ),
        (
            "t,vel,input_vel,accel,steer,brake,lat,lon\n0.1,1,,,,\n",
            "drive.csv:2: expected 8 cells as in the header, found 6",
        ),
        (
            "t,vel,input_vel,accel,steer,brake,lat,lon\n0.1,1,,,,,,,\n",
            "drive.csv:2: expected 8 cells as in the header, found 9",
        ),
        (
            "t,vel,input_vel,accel,steer,brake,lat,lon\n0.1,,,,,,,\n\n0.2,,,,,,,\n",
            "drive.csv:3: blank line inside the data",
        ),
        (
            "t,vel,input_vel,accel,steer,brake,lat,lon\n0.1,,,,-105.5,,,\n",
            "drive.csv:2:8: column `steer`: -105.5 % is outside -105..105 % (100 % is full \
             lock; up to 105 % is a sensor calibrated a little past it, read as the lock)",
        ),
        (
            "t,vel,input_vel,accel,steer,brake,lat,lon\n0.1,,,101,,,,\n",
            "drive.csv:2:7: column `accel`: 101 % is outside 0..100 % (a pedal travels 0..100 %)",
        ),
        (
            "t,vel,input_vel,accel,steer,brake,lat,lon\n0.1,,,,,-1,,\n",
            "drive.csv:2:9: column `brake`: -1 % is outside 0..100 % (a pedal travels 0..100 %)",
        ),
        (
            "t,vel,input_vel,accel,steer,brake,lat,lon\n0.1,,,,,,91,0\n",
            "drive.csv:2:10: column `lat`: 91 deg is outside -90..90 deg (WGS-84 latitude)",
        ),
        (
            "t,vel,input_vel,accel,steer,brake,lat,lon\n0.1,,,,,,32.2,\n",
            "drive.csv:2:10: column `lat`: `lat` and `lon` must be both present or both empty",
        ),
        // The issue's impossible sample: one speed of 1e30 m/s.
        (
            "t,vel,input_vel,accel,steer,brake,lat,lon\n0.1,4.2,,,,,,\n0.12,1e30,,,,,,\n",
            "drive.csv:3:6: column `vel`: 1e30 m/s is outside -10..80 m/s \
             (no car drives this: 80 m/s = 288 km/h is above the 250 km/h most cars are limited to, \
             -10 m/s = 36 km/h in reverse; a speed in km/h or mph?)",
        ),
        (
            "t,vel,input_vel,accel,steer,brake,lat,lon\n0.1,,-12,,,,,\n",
            "drive.csv:2:6: column `input_vel`: -12 m/s is outside -10..80 m/s \
             (no car drives this: 80 m/s = 288 km/h is above the 250 km/h most cars are limited to, \
             -10 m/s = 36 km/h in reverse; a speed in km/h or mph?)",
        ),
        (
            "t,vel,input_vel,accel,steer,brake,lat,lon\n1700000000123,,,,,,,\n",
            "drive.csv:2:1: column `t`: 1.700000000123e12 s is outside -1e10..1e10 s \
             (1e10 s is 317 years: a time in milliseconds or microseconds?)",
        ),
        (
            "t,vel,input_vel,accel,steer,brake,lat,lon\n0.1,,,,,,0,0\n",
            "drive.csv:2:10: column `lat`: fix at latitude 0, longitude 0: the placeholder receivers write without a fix; leave `lat` and `lon` empty instead",
        ),
        // Half a fix stays half a fix when nothing else arrives at that instant.
        (
            "t,vel,input_vel,accel,steer,brake,lat,lon\n0.1,,,,,,,-110.9\n0.1,3,,,,,,\n0.2,,,,,,,\n",
            "drive.csv:2:11: column `lon`: `lat` and `lon` must be both present or both empty",
        ),
        // The character column counts characters (not bytes) and names the column.
        (
            "t,vel,input_vel,accel,steer,brake,lat,lon,note\n0.1,,,,,,,,é\n0.2,,,,,,,,é\n0.3,ö,,,,,,,\n",
            "drive.csv:4:5: column `vel`: not a number: `ö`",
        ),
    ];
    for (text, expected) in cases {
        assert_eq!(&error_message(text), expected, "input {text:?}");
    }
}

/// A recorder that writes four decimals: the speed and the GNSS reports of one instant land on
/// two lines with the same `t` (the issue's `3.6626 after 3.6626`). They are one instant.
#[test]
fn lines_with_equal_time_are_one_instant() {
    let text = format!(
        "{HEADER}\r\n3.6624,4.01,4.5,,,,,\r\n3.6626,4.02,4.5,,,,,\r\n3.6626,,,,,,32.2319,-110.9501\r\n\
         3.6626,,,,-3.5,,,\r\n3.6628,,,,,,,\r\n"
    );
    let log = logcsv::parse_log(&text, Path::new(FILE)).expect("valid");
    assert_eq!(
        log.rows,
        vec![
            LogRow {
                vel: Some(4.01),
                input_vel: Some(4.5),
                ..LogRow::empty(3.6624)
            },
            LogRow {
                vel: Some(4.02),
                input_vel: Some(4.5),
                steer: Some(-3.5),
                lat: Some(32.2319),
                lon: Some(-110.9501),
                ..LogRow::empty(3.6626)
            },
            LogRow::empty(3.6628),
        ]
    );
    assert_eq!(log.notes.merged_lines, 2);
    assert_eq!(log.notes.conflicts, 0);
    // Merging without a conflict is normal: no note.
    assert!(log.notes.messages().is_empty());

    // A recorder writing one line per signal: latitude and longitude of one fix on two lines.
    let rows = parse(&format!("{HEADER}\n1.5,,,,,,32.5,\n1.5,,,,,,,-110.5\n")).expect("valid");
    assert_eq!(
        rows,
        vec![LogRow {
            lat: Some(32.5),
            lon: Some(-110.5),
            ..LogRow::empty(1.5)
        }]
    );
    // An exact repeat of a line (some loggers write a line twice) is no conflict.
    let text = format!("{HEADER}\n1.5,3,,,,,,\n1.5,3,,,,,,\n");
    let log = logcsv::parse_log(&text, Path::new(FILE)).expect("valid");
    assert_eq!((log.rows.len(), log.notes.conflicts), (1, 0));
}

/// One sensor with two different values at one instant: the later line wins, counted, and the
/// note names both lines and values.
#[test]
fn two_values_of_one_sensor_at_one_instant_keep_the_later_and_say_so() {
    let text = format!("{HEADER}\n2.0,5.5,,,,,,\n2.0,5.75,,,10,,,\n2.0,,,,12,,,\n2.02,1,,,,,,\n");
    let log = logcsv::parse_log(&text, Path::new(FILE)).expect("valid");
    assert_eq!(log.rows[0].vel, Some(5.75));
    assert_eq!(log.rows[0].steer, Some(12.0));
    assert_eq!(log.notes.conflicts, 2);
    assert_eq!(
        log.notes.first_conflict,
        Some(Conflict {
            column: "vel",
            t: 2.0,
            first: (5.5, 2),
            kept: (5.75, 3),
        })
    );
    assert_eq!(
        log.notes.messages(),
        vec!["drive.csv:3: column `vel`: two values at t = 2 s (5.5 on line 2, 5.75 on line 3): the later one is kept (2 such cell(s) in the file)".to_string()]
    );
}

/// Extra columns (a recorder's own, with quoted free text holding commas) are read past and
/// named once, in one note.
#[test]
fn extra_columns_are_named_once() {
    let text = "\u{feff}t,gear,vel,input_vel,accel,steer,brake,lat,lon,comment\r\n\
                0.5,3,2.5,,,,,,,\"stop, then go\"\r\n\
                0.52,3,2.6,,,,,,,\"say \"\"hi\"\", twice\"\r\n";
    let log = logcsv::parse_log(text, Path::new(FILE)).expect("valid");
    assert_eq!(log.rows.len(), 2);
    assert_eq!(log.rows[1].vel, Some(2.6));
    assert_eq!(log.notes.extra_columns, vec!["gear", "comment"]);
    assert_eq!(
        log.notes.messages(),
        vec!["drive.csv: columns `gear`, `comment` are not in the log schema: ignored".to_string()]
    );
    assert_eq!(
        notes("t,vel,input_vel,accel,steer,brake,lat,lon,x\n0,,,,,,,,1\n"),
        vec!["drive.csv: column `x` is not in the log schema: ignored".to_string()]
    );
}

/// Three recorder habits the schema's "extra columns are ignored" covers (review finding 09):
/// a trailing comma on every line (an unnamed, empty column), a quoted comment holding a line
/// break (RFC 4180), and a comment in another encoding than UTF-8 (a cp1252 `ß`). Each reads
/// as the same log without it; a named column twice, a foreign byte in the header or in a
/// column that is read stay errors with their line and column.
#[test]
fn recorder_habits_in_extra_columns_are_read_past() {
    let plain = format!("{HEADER}\n0.5,2.5,3,,,,,\n0.52,2.6,3,,,,,\n");
    let want = parse(&plain).expect("valid");

    // (a) A trailing comma on every line, header included; with CRLF too.
    let trailing: String = plain.lines().map(|l| format!("{l},\r\n")).collect();
    assert_eq!(parse(&trailing).expect("trailing comma"), want);
    assert_eq!(
        notes(&trailing),
        vec![
            "drive.csv: 1 unnamed column (an empty header cell, as a trailing comma on every \
              line makes) is not in the log schema: ignored"
                .to_string()
        ]
    );
    let two = "t,gear,vel,input_vel,accel,steer,brake,lat,lon,,\n0.5,3,2.5,3,,,,,,,\n";
    assert_eq!(
        notes(two),
        vec![
            "drive.csv: column `gear` and 2 unnamed columns (empty header cells, as trailing \
              commas on every line make) are not in the log schema: ignored"
                .to_string()
        ]
    );
    // A known column twice is still ambiguous, unnamed ones beside it or not.
    assert_eq!(
        error_message("t,vel,input_vel,accel,steer,brake,lat,lon,vel,\n"),
        "drive.csv:1:43: column `vel`: column `vel` appears twice in the header"
    );
    // A header-less file with a trailing comma is still a file without a header.
    assert_eq!(
        error_message("1,2,3,4,5,6,7,8,\n"),
        "drive.csv:1:1: missing header row"
    );

    // (b) A quoted cell holding a line break (LF or CRLF): one record over two lines; the
    // lines after it keep their physical numbers in errors.
    for eol in ["\n", "\r\n"] {
        let text = format!(
            "{HEADER},comment{eol}0.5,2.5,3,,,,,,\"stop,{eol}then go\"{eol}0.52,2.6,3,,,,,,{eol}"
        );
        let log = logcsv::parse_log(&text, Path::new(FILE)).expect("quoted line break");
        assert_eq!(log.rows, want, "{eol:?}");
        assert_eq!(log.lines, vec![2, 4], "{eol:?}");
        let bad = format!(
            "{HEADER},comment{eol}0.5,2.5,3,,,,,,\"stop,{eol}then go\"{eol}0.52,x,3,,,,,,{eol}"
        );
        assert_eq!(
            error_message(&bad),
            "drive.csv:4:6: column `vel`: not a number: `x`",
            "{eol:?}"
        );
    }
    // A cell of a read column that starts on a later physical line is named by that line.
    let text = "t,comment,vel,input_vel,accel,steer,brake,lat,lon\n0.5,\"a\nb\",abc,,,,,,\n";
    assert_eq!(
        error_message(text),
        "drive.csv:3:4: column `vel`: not a number: `abc`"
    );
    // A quote inside a cell is text: it opens nothing (`5" screen`).
    let text = format!("{HEADER},comment\n0.5,2.5,3,,,,,,5\" screen\n0.52,2.6,3,,,,,,ok\n");
    assert_eq!(parse(&text).expect("inch mark"), want);
    // A quote that opens a cell and never closes is named where it opens.
    let text =
        format!("{HEADER},comment\n0.5,2.5,3,,,,,,ok\n0.52,2.6,3,,,,,,\"stop\n0.54,,,,,,,,\n");
    let message = error_message(&text);
    assert!(
        message.starts_with("drive.csv:3:17: the quote that opens this cell is never closed"),
        "{message}"
    );
}

/// (c) A byte that is not UTF-8 in an ignored column is never read; in the header or in a read
/// column it is an error with its line and column.
#[test]
fn a_foreign_encoding_is_refused_only_where_it_is_read() {
    let dir = std::env::temp_dir().join(format!("catmodel-logcsv-cp1252-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let write = |name: &str, bytes: &[u8]| {
        let p = dir.join(name);
        std::fs::write(&p, bytes).expect("write");
        p
    };
    // cp1252 `Straße`: 0xDF is not UTF-8.
    let ok = write(
        "comment.csv",
        b"t,vel,input_vel,accel,steer,brake,lat,lon,comment\n0.5,2.5,3,,,,,,Stra\xdfe\n0.52,2.6,3,,,,,,\n",
    );
    let log = logcsv::read_log(&ok).expect("a foreign byte in an ignored column");
    assert_eq!(log.rows.len(), 2);
    assert_eq!(log.rows[1].vel, Some(2.6));
    assert_eq!(log.notes.extra_columns, vec!["comment"]);
    let header = write(
        "header.csv",
        b"t,vel,input_vel,accel,steer,brake,lat,lon,Stra\xdfe\n0.5,2.5,3,,,,,,\n",
    );
    let e = logcsv::read_log(&header).expect_err("a foreign byte in the header");
    assert!(
        e.to_string()
            .starts_with(&format!("{}:1:43: not UTF-8 text", header.display())),
        "{e}"
    );
    let truth = write(
        "t.truth.csv",
        b"t,x,y,heading,yaw_rate,speed,note\n0,1,2,0.5,0,5,\xe9t\xe9\n0.01,1\xb2,2,0.5,0,5,\n",
    );
    let e = logcsv::read_truth(&truth).expect_err("a foreign byte in a truth column");
    assert!(
        e.to_string().starts_with(&format!(
            "{}:3:6: column `x`: not UTF-8 text",
            truth.display()
        )),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// The truth reader has physical ranges like the log reader's (review finding 08: a truth
/// `x = 1e300` made `evaluate` print `inf` and `NaN`), with `file:line:column`.
#[test]
fn truth_values_no_car_can_have_are_refused() {
    let head = "t,x,y,heading,yaw_rate,speed\n0,1,2,0.5,0.1,5\n";
    let cases = [
        (
            "0.01,1e300,2,0.5,0.1,5",
            "t.csv:3:6: column `x`: 1e300 m is outside -1e7..1e7 m",
        ),
        (
            "0.01,1,-2e7,0.5,0.1,5",
            "t.csv:3:8: column `y`: -2e7 m is outside -1e7..1e7 m",
        ),
        (
            "0.01,1,2,90,0.1,5",
            "t.csv:3:10: column `heading`: 90 rad is outside -6.3..6.3 rad",
        ),
        (
            "0.01,1,2,0.5,57,5",
            "t.csv:3:14: column `yaw_rate`: 57 rad/s is outside -10..10 rad/s",
        ),
        ("0.01,1,2,0.5,0.1,36", ""),
        (
            "0.01,1,2,0.5,0.1,130",
            "t.csv:3:18: column `speed`: 130 m/s is outside -10..80 m/s",
        ),
        (
            "1e12,1,2,0.5,0.1,5",
            "t.csv:3:1: column `t`: 1e12 s is outside -1e10..1e10 s",
        ),
    ];
    for (row, want) in cases {
        let text = format!("{head}{row}\n");
        match logcsv::parse_truth(&text, Path::new("t.csv")) {
            Ok(rows) => assert!(want.is_empty(), "{row}: accepted {rows:?}"),
            Err(e) => assert!(
                !want.is_empty() && e.to_string().starts_with(want),
                "{row}: {e}"
            ),
        }
    }
    for (range, column) in logcsv::TRUTH_RANGES.iter().zip(logcsv::TRUTH_COLUMNS) {
        assert_eq!(range.column, column);
    }
}

/// Every range bound is accepted and the next double beyond it is refused, for every column.
#[test]
fn ranges_are_inclusive_and_end_exactly_at_their_bounds() {
    assert_eq!(
        LOG_RANGES.iter().map(|r| r.column).collect::<Vec<_>>(),
        LOG_COLUMNS
    );
    for (i, range) in LOG_RANGES.iter().enumerate() {
        let line = |v: f64| {
            let mut cells = vec![String::new(); 8];
            cells[0] = "1".into();
            cells[i] = format!("{v:?}");
            // A fix needs both halves; the other half is a valid non-zero value.
            match i {
                6 => cells[7] = "1".into(),
                7 => cells[6] = "1".into(),
                _ => {}
            }
            format!("{HEADER}\n{}\n", cells.join(","))
        };
        for v in [range.min, range.max] {
            parse(&line(v)).unwrap_or_else(|e| panic!("{}: {v} refused: {e}", range.column));
        }
        for v in [range.min.next_down(), range.max.next_up()] {
            let e = parse(&line(v)).expect_err(range.column);
            assert!(
                matches!(e.kind, LogErrorKind::OutOfRange { value, .. } if value == v),
                "{}: {e}",
                range.column
            );
            assert_eq!(e.column.as_deref(), Some(range.column));
        }
    }
}

#[test]
fn file_errors_name_the_file() {
    let dir = std::env::temp_dir().join(format!("catmodel-logcsv-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let missing = dir.join("missing.csv");
    let e = logcsv::read_log(&missing).expect_err("no such file");
    assert!(matches!(e.kind, LogErrorKind::Io(_)));
    assert!(
        e.to_string()
            .starts_with(&format!("{}: ", missing.display())),
        "{e}"
    );

    let latin1 = dir.join("latin1.csv");
    std::fs::write(
        &latin1,
        b"t,vel,input_vel,accel,steer,brake,lat,lon\n0.1,,,,,,,\n0.2,\xe9,,,,,,\n",
    )
    .expect("write");
    let e = logcsv::read_log(&latin1).expect_err("not UTF-8");
    assert_eq!(
        e.to_string(),
        format!(
            "{}:3:5: column `vel`: not UTF-8 text (the header and the schema's columns must be \
             UTF-8; bytes of another encoding are accepted only in columns that are ignored)",
            latin1.display()
        )
    );

    let truth = dir.join("bad.truth.csv");
    std::fs::write(
        &truth,
        "t,x,y,heading,yaw_rate,speed\n0,1,2,3,4,5\n0.01,1,2,,4,5\n",
    )
    .expect("write");
    let e = logcsv::read_truth(&truth).expect_err("empty truth cell");
    assert_eq!(
        e.to_string(),
        format!(
            "{}:3:10: column `heading`: empty cell where a value is required",
            truth.display()
        )
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn writers_refuse_what_the_readers_would_reject() {
    let mut out = Vec::new();
    let rows = [
        LogRow::empty(1.0),
        LogRow {
            vel: Some(f64::NAN),
            ..LogRow::empty(2.0)
        },
    ];
    let (line, column, kind) = logcsv::write_log_to(&mut out, &rows).expect_err("NaN");
    assert_eq!((line, column), (3, Some("vel")));
    assert!(matches!(kind, LogErrorKind::NonFinite(_)));
    let rows = [
        TruthRow {
            t: 1.0,
            ..Default::default()
        },
        TruthRow {
            t: 1.0,
            ..Default::default()
        },
    ];
    let (line, column, kind) = logcsv::write_truth_to(&mut Vec::new(), &rows).expect_err("same t");
    assert_eq!((line, column), (3, Some("t")));
    assert!(matches!(kind, LogErrorKind::TimeNotIncreasing { .. }));
}

fn speed() -> impl Strategy<Value = f64> {
    prop_oneof![
        -10.0..=80.0,
        Just(0.0),
        Just(-0.0),
        Just(80.0),
        Just(-10.0),
        Just(1e-300)
    ]
}

fn finite() -> impl Strategy<Value = f64> {
    prop_oneof![
        -1e6..1e6,
        Just(0.0),
        Just(-0.0),
        Just(1e-300),
        Just(123456.789e-10)
    ]
}

fn cell(range: std::ops::RangeInclusive<f64>) -> impl Strategy<Value = Option<f64>> {
    proptest::option::of(range)
}

prop_compose! {
    fn log_rows()(deltas in proptest::collection::vec(1e-6..1.0f64, 0..40),
                  cells in proptest::collection::vec((speed(), speed(), cell(0.0..=100.0), cell(-100.0..=100.0),
                      cell(0.0..=100.0), proptest::option::of((-90.0..=90.0f64, 1e-9..=180.0f64).prop_map(outside_radians_box)), any::<(bool, bool)>()), 40))
                 -> Vec<LogRow> {
        let mut t = -3.0;
        deltas.iter().zip(&cells).map(|(d, (v, iv, a, s, b, fix, (has_v, has_iv)))| {
            t += d;
            LogRow { t, vel: has_v.then_some(*v), input_vel: has_iv.then_some(*iv), accel: *a, steer: *s, brake: *b,
                     lat: fix.map(|f| f.0), lon: fix.map(|f| f.1) }
        }).collect()
    }
}

/// A fix moved out of the box a latitude and longitude in radians fill when read as degrees
/// (`logcsv::radians_likely`: open sea, where the reader takes a log whose fixes all lie for
/// one in radians and refuses it): 4 degrees east when it is in it.
fn outside_radians_box((lat, lon): (f64, f64)) -> (f64, f64) {
    use std::f64::consts::{FRAC_PI_2, PI};
    match lat.abs() <= FRAC_PI_2 && lon.abs() <= PI {
        true => (lat, lon + 4.0),
        false => (lat, lon),
    }
}

proptest! {
    #[test]
    fn log_round_trip_is_exact(rows in log_rows()) {
        let mut bytes = Vec::new();
        logcsv::write_log_to(&mut bytes, &rows).expect("valid rows");
        let text = String::from_utf8(bytes).expect("utf-8");
        let back = parse(&text).expect("reads back");
        prop_assert_eq!(back.len(), rows.len());
        for (a, b) in back.iter().zip(&rows) {
            // Bit-exact (-0.0 stays -0.0).
            prop_assert_eq!(format!("{a:?}"), format!("{b:?}"));
        }
    }

    /// A recorder that writes each report on its own line (several lines per instant, in any
    /// order, some repeated) gives back the same rows as one line per instant.
    #[test]
    fn one_line_per_report_reads_as_one_row_per_instant(rows in log_rows(), order in proptest::collection::vec(any::<u32>(), 8 * 40), repeat in any::<u64>()) {
        let mut text = format!("{HEADER}\r\n");
        let mut k = 0;
        for (n, r) in rows.iter().enumerate() {
            let cells = [r.vel, r.input_vel, r.accel, r.steer, r.brake];
            let mut lines: Vec<String> = cells.iter().enumerate().filter_map(|(i, c)| {
                c.map(|v| {
                    let mut out = vec![String::new(); 7];
                    out[i] = format!("{v:?}");
                    format!("{:?},{}", r.t, out.join(","))
                })
            }).collect();
            if let (Some(lat), Some(lon)) = (r.lat, r.lon) {
                lines.push(format!("{:?},,,,,,{lat:?},{lon:?}", r.t));
            }
            if lines.is_empty() {
                lines.push(format!("{:?},,,,,,,", r.t));
            }
            if repeat >> (n % 64) & 1 == 1 {
                let again = lines[0].clone();
                lines.push(again);
            }
            // Shuffle the lines of this instant.
            for i in (1..lines.len()).rev() {
                let j = order[k % order.len()] as usize % (i + 1);
                k += 1;
                lines.swap(i, j);
            }
            for l in lines {
                text.push_str(&l);
                text.push_str("\r\n");
            }
        }
        let log = logcsv::parse_log(&text, Path::new(FILE)).expect("reads");
        prop_assert_eq!(log.notes.conflicts, 0);
        prop_assert_eq!(log.rows.len(), rows.len());
        for (a, b) in log.rows.iter().zip(&rows) {
            prop_assert_eq!(format!("{a:?}"), format!("{b:?}"));
        }
    }

    #[test]
    fn truth_round_trip_is_exact(values in proptest::collection::vec((finite(), finite(), -3.2..3.2f64, -10.0..10.0f64, 0.0..30.0f64), 0..30)) {
        let rows: Vec<TruthRow> = values.iter().enumerate().map(|(i, (x, y, h, r, v))| TruthRow {
            t: i as f64 * 0.01, x: *x, y: *y, heading: *h, yaw_rate: *r, speed: *v }).collect();
        let mut bytes = Vec::new();
        logcsv::write_truth_to(&mut bytes, &rows).expect("valid rows");
        let back = logcsv::parse_truth(std::str::from_utf8(&bytes).expect("utf-8"), Path::new("t.csv")).expect("reads back");
        prop_assert_eq!(back, rows);
    }

    /// Arbitrary text never panics the reader: it is either rows or an error with a position.
    #[test]
    fn garbage_never_panics(body in "[0-9a-z.,\\-\" \\n\\r]{0,200}") {
        let text = format!("{HEADER}\n{body}");
        if let Err(e) = parse(&text) {
            prop_assert!(e.line >= 1);
            prop_assert!(e.to_string().starts_with("drive.csv:"));
        }
    }
}

/// A header that lacks a required column is shown, with the likely cause: units in the names,
/// `;` separators, upper case (review: csv/units.csv, semi.csv, upper.csv), a comment line
/// above it.
#[test]
fn a_missing_column_shows_the_header_found_and_its_likely_cause() {
    for (header, cause) in [
        (
            "t [s],vel [m/s],input_vel [m/s],accel [%],steer [%],brake [%],lat [deg],lon [deg]",
            "carries a unit",
        ),
        (
            "t;vel;input_vel;accel;steer;brake;lat;lon",
            "separated by `;`",
        ),
        ("T,VEL,INPUT_VEL,ACCEL,STEER,BRAKE,LAT,LON", "lower case"),
        // A black-box probe's logger banner above the header.
        ("# logger v2.1, 2026-12-04", "the first line is a comment"),
    ] {
        let message = error_message(&format!("{header}\n0.02,,,,1,,,\n"));
        assert!(
            message.starts_with(&format!(
                "drive.csv:1: column `t`: missing required column `t` (the header found: `{header}`): "
            )),
            "{message}"
        );
        assert!(message.contains(cause), "{message}");
    }
    // No guess when there is nothing to see.
    assert_eq!(
        error_message("vel,input_vel,steer,lat,lon\n"),
        "drive.csv:1: column `t`: missing required column `t` (the header found: `vel,input_vel,steer,lat,lon`)"
    );
}

/// The pedals are optional columns (docs/logs.md): a log without `accel` and `brake` reads as
/// one whose pedal sensors never reported (review: csv/noped.csv was refused).
#[test]
fn the_pedal_columns_may_be_left_out() {
    let rows = parse("t,vel,input_vel,steer,lat,lon\n0.00,3,3.5,-1,,\n0.02,3.1,,,32.23,-110.95\n")
        .expect("valid");
    assert_eq!(rows.len(), 2);
    assert_eq!((rows[0].accel, rows[0].brake), (None, None));
    assert_eq!(rows[0].steer, Some(-1.0));
    assert_eq!(rows[1].lat, Some(32.23));
    // The other columns stay required.
    assert!(error_message("t,vel,input_vel,accel,brake,lat,lon\n")
        .contains("missing required column `steer`"));
}

/// A `t` in milliseconds (20 ms samples 20 "s" apart) is refused by its median interval
/// instead of making identify run for minutes on a log 1000 times too long (review:
/// csv/msint.csv); a receiver's 1 s and a drive's 20 ms pass.
#[test]
fn a_time_in_milliseconds_is_refused_by_its_median_interval() {
    let log = |step: f64| {
        let mut text = format!("{HEADER}\n");
        for i in 0..50 {
            text += &format!("{},{},,,,,,\n", 12.0 + step * f64::from(i), 3.0);
        }
        text
    };
    let message = error_message(&log(20.0));
    assert_eq!(
        message,
        "drive.csv: column `t`: the median interval between samples is 20.000 (in the unit of `t`), \
         far from the 20 ms of the log schema (`t` in seconds, sensors every 20 ms or faster): \
         `t` looks like milliseconds; divide it by 1000"
    );
    assert!(
        error_message(&log(20_000.0)).ends_with("`t` looks like microseconds; divide it by 1e6")
    );
    assert!(error_message(&log(1.5)).contains("looks like milliseconds"));
    for ok in [0.02, 0.2, 1.0] {
        assert_eq!(parse(&log(ok)).expect("valid").len(), 50, "{ok}");
    }
    // The median, not a pause: a long stop in a 20 ms log passes this check.
    let mut text = log(0.02);
    text += "100,3,,,,,,\n";
    assert!(parse(&text).is_ok());
}

/// A latitude and longitude in radians read as degrees put every fix in the open sea of the
/// Gulf of Guinea: refused, naming radians, at the first fix's line. A single fix there among
/// fixes elsewhere is not a unit (and the Tucson drive's are far outside the box); integers of
/// 1e-7 deg are named in the range error.
#[test]
fn a_track_in_radians_or_in_1e7_degrees_is_named() {
    let (lat, lon) = (32.2319_f64.to_radians(), (-110.9501_f64).to_radians());
    let text = format!(
        "{HEADER}\n0,1,,,,,,\n0.02,1,,,,,{lat},{lon}\n0.04,1,,,,,{},{lon}\n",
        lat + 1e-7
    );
    let e = error_message(&text);
    assert!(
        e.starts_with("drive.csv:3: column `lat`: all 2 fixes lie within 1.5708 deg")
            && e.contains("look like radians"),
        "{e}"
    );
    assert!(e.contains("multiply both columns by 57.29578"), "{e}");
    // The same drive in degrees, and one fix in the box among others.
    let degrees = format!("{HEADER}\n0,1,,,,,32.2319,-110.9501\n0.02,1,,,,,32.2320,-110.9501\n");
    parse(&degrees).expect("degrees");
    let mixed = format!("{HEADER}\n0,1,,,,,0.5,0.5\n0.02,1,,,,,5.5,0.5\n");
    parse(&mixed).expect("a fix outside the box");
    // u-blox style integers.
    let e = error_message(&format!("{HEADER}\n0,1,,,,,322319000,-1109501000\n"));
    assert!(
        e.ends_with("integers of 1e-7 deg (as u-blox writes them) need dividing by 1e7"),
        "{e}"
    );
}

#[test]
fn a_fix_in_nmea_minutes_is_named() {
    let e = error_message(&format!("{HEADER}\n0,1,,,,,3213.914,-11057.006\n"));
    assert!(e.contains("NMEA's ddmm.mmmm"), "{e}");
    let e = error_message(&format!("{HEADER}\n0,1,,,,,32.2,-11057.006\n"));
    assert!(
        e.contains("column `lon`") && e.contains("NMEA's ddmm.mmmm"),
        "{e}"
    );
    // Past a latitude's range, but neither format.
    let e = error_message(&format!("{HEADER}\n0,1,,,,,91,0\n"));
    assert!(e.ends_with("(WGS-84 latitude)"), "{e}");
}

/// A last line without a line end (a recorder that lost power mid-line) gets a warning, as the
/// candump reader gives one: kept when it reads (a number cut short that reads as another, a
/// longitude `-11` for `-110.95`, is left to the check of each sample against its neighbours),
/// left out when it does not (too few cells, half a fix, a `t` cut to before the line above).
/// A line end after it, or blanks after that, give none; a bad line that is not the last is an
/// error as before.
#[test]
fn a_last_line_without_a_line_end_is_warned_of() {
    let read = |text: &str| logcsv::parse_log(text, Path::new(FILE)).expect("valid");
    let first = format!("{HEADER}\n0.1,1,1,,0,,32.2,-110.9\n");
    let kept = read(&format!("{first}0.2,1,1,,0,,32.2,-11"));
    assert_eq!(kept.rows.len(), 2);
    assert_eq!(kept.rows[1].lon, Some(-11.0));
    let w = kept.notes.warnings();
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(
        w[0].starts_with("drive.csv:3: the last line has no line end")
            && w[0].contains("its values are kept"),
        "{}",
        w[0]
    );
    for cut in [
        "0.2,1,1,,0,,32.2",
        "0.2,1,1,,0,,32.2,",
        "0.",
        "0.2,1,1,,0,,32.2,-1-",
    ] {
        let log = read(&format!("{first}{cut}"));
        assert_eq!(log.rows.len(), 1, "{cut}");
        let w = log.notes.warnings();
        assert_eq!(w.len(), 1, "{cut}: {w:?}");
        assert!(
            w[0].starts_with("drive.csv:3: the last line has no line end")
                && w[0].ends_with("it does not read as a row: left out"),
            "{cut}: {}",
            w[0]
        );
    }
    for ended in ["\n", "\r\n", "\n\n", "\n  "] {
        let log = read(&format!("{first}0.2,1,1,,0,,32.2,-11{ended}"));
        assert_eq!(log.rows.len(), 2, "{ended:?}");
        assert!(log.notes.warnings().is_empty(), "{ended:?}");
    }
    assert!(read(HEADER).notes.warnings().is_empty());
    assert_eq!(
        error_message(&format!("{HEADER}\n0.1,abc,,,,,,\n0.2,1,1,,0,,32.2")),
        "drive.csv:2:5: column `vel`: not a number: `abc`"
    );
}

#[test]
fn line_ends_of_a_bare_cr_are_named() {
    // A black-box probe's log with classic Mac OS line ends (`\r` alone) was refused as
    // "c11-cr.csv:1:116: column `0`: column `0` appears twice in the header": the whole file
    // was one header line.
    let cr = format!("{HEADER}\r0.1,1,1,,0,,32.2,-110.9\r0.2,1,1,,0,,32.2,-110.9\r");
    let e = error_message(&cr);
    assert!(
        e.starts_with(
            "drive.csv:1:42: a line ends here with a bare CR (`\\r` without `\\n`), and 2 more \
             after it: the line ends of classic Mac OS"
        ),
        "{e}"
    );
    let rows = |text: &str| parse(text).map(|r| r.len()).map_err(|e| e.to_string());
    // From the second data line on (a file that was appended to by another tool).
    let mixed =
        format!("{HEADER}\n0.1,1,1,,0,,32.2,-110.9\n0.2,1,1,,0,,32.2,-110.9\r0.3,1,,,,,,\n");
    let e = rows(&mixed).expect_err("mixed");
    assert!(
        e.starts_with("drive.csv:3:24: a line ends here with a bare CR (`\\r` without `\\n`):"),
        "{e}"
    );
    // CRLF, a CRLF file cut before its last LF, and a CR inside a quoted cell still read.
    for ok in [
        format!("{HEADER}\r\n0.1,1,1,,0,,32.2,-110.9\r\n"),
        format!("{HEADER}\r\n0.1,1,1,,0,,32.2,-110.9\r"),
        format!("{HEADER},note\n0.1,1,1,,0,,32.2,-110.9,\"a\rb\"\n"),
    ] {
        assert_eq!(rows(&ok), Ok(1), "{ok:?}");
    }
}
