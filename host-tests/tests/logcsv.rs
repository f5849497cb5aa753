//! The log and truth CSV readers/writers: round trips, schema freedom (column order, extra
//! columns, empty cells), and every rejection with its `file:line:column` message.
use catmodel_host::logcsv::{self, LogErrorKind, LogRow, TruthRow};
use proptest::prelude::*;
use std::path::Path;

const FILE: &str = "drive.csv";

fn parse(text: &str) -> Result<Vec<LogRow>, logcsv::LogError> {
    logcsv::parse_log(text, Path::new(FILE))
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

#[test]
fn every_malformed_file_is_rejected_with_file_line_and_column() {
    let cases: &[(&str, &str)] = &[
        ("", "drive.csv:1: missing header row"),
        ("1,2,3,4,5,6,7,8\n", "drive.csv:1:1: missing header row"),
        ("t,vel,,accel\n", "drive.csv:1:7: empty column name in the header"),
        ("t,vel,t\n", "drive.csv:1:7: column `t`: column `t` appears twice in the header"),
        ("t,vel,input_vel,accel,steer,brake,lat\n", "drive.csv:1: column `lon`: missing required column `lon`"),
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
            "t,vel,input_vel,accel,steer,brake,lat,lon\n0.2,,,,,,,\n0.2,,,,,,,\n",
            "drive.csv:3:1: column `t`: time not increasing: 0.2 after 0.2",
        ),
        (
            "t,vel,input_vel,accel,steer,brake,lat,lon\n0.2,,,,,,,\n0.1,,,,,,,\n",
            "drive.csv:3:1: column `t`: time not increasing: 0.1 after 0.2",
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
            "t,vel,input_vel,accel,steer,brake,lat,lon\n0.1,,,,-100.5,,,\n",
            "drive.csv:2:8: column `steer`: value -100.5 outside -100..100",
        ),
        (
            "t,vel,input_vel,accel,steer,brake,lat,lon\n0.1,,,101,,,,\n",
            "drive.csv:2:7: column `accel`: value 101 outside 0..100",
        ),
        (
            "t,vel,input_vel,accel,steer,brake,lat,lon\n0.1,,,,,-1,,\n",
            "drive.csv:2:9: column `brake`: value -1 outside 0..100",
        ),
        (
            "t,vel,input_vel,accel,steer,brake,lat,lon\n0.1,,,,,,91,0\n",
            "drive.csv:2:10: column `lat`: value 91 outside -90..90",
        ),
        (
            "t,vel,input_vel,accel,steer,brake,lat,lon\n0.1,,,,,,32.2,\n",
            "drive.csv:2:15: column `lon`: `lat` and `lon` must be both present or both empty",
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
        format!("{}:3: not UTF-8 text", latin1.display())
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
                  cells in proptest::collection::vec((finite(), finite(), cell(0.0..=100.0), cell(-100.0..=100.0),
                      cell(0.0..=100.0), proptest::option::of((-90.0..=90.0f64, -180.0..=180.0f64)), any::<(bool, bool)>()), 40))
                 -> Vec<LogRow> {
        let mut t = -3.0;
        deltas.iter().zip(&cells).map(|(d, (v, iv, a, s, b, fix, (has_v, has_iv)))| {
            t += d;
            LogRow { t, vel: has_v.then_some(*v), input_vel: has_iv.then_some(*iv), accel: *a, steer: *s, brake: *b,
                     lat: fix.map(|f| f.0), lon: fix.map(|f| f.1) }
        }).collect()
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

    #[test]
    fn truth_round_trip_is_exact(values in proptest::collection::vec((finite(), finite(), -3.2..3.2f64, finite(), 0.0..30.0f64), 0..30)) {
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
