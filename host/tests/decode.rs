//! `catmodel decode`: the DBC-driven decoder against the node's own codecs on the golden output
//! and the bundled input drive, hand-made frames (values, CRC and counters worked out by hand
//! and by an independent CRC-8 in Python), and bad input through the CLI.
use std::path::{Path, PathBuf};
use std::process::Command;

use catmodel::can::codec::ControlCommand;
use catmodel::can::codec::{decode_input, InputMessage, ModelMode, NodeStatus};
use catmodel::can::spec::N2K_DEFAULT_SOURCE;
use catmodel::can::{Prediction, StateMotion, StatePosition, TimedFrame};
use catmodel_host::dbc::{Dbc, SignalValue};
use catmodel_host::decode::{decode_frames, Check, DecodedFrame, Decoder, Format, Selection};

const BIN: &str = env!("CARGO_BIN_EXE_catmodel");

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../data")
        .join(name)
}

fn tmp(name: &str, text: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("decode");
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

/// The decoded value of `name`: `None` for the "not available" sentinel.
fn value(d: &DecodedFrame<'_>, name: &str) -> Option<f64> {
    let v: &SignalValue<'_> = d
        .signals
        .iter()
        .find(|v| v.signal.name == name)
        .unwrap_or_else(|| panic!("{name} missing"));
    if v.label == Some("not_available") {
        assert!(!v.in_range(), "{name}: sentinel inside the DBC range");
        None
    } else {
        Some(v.physical)
    }
}

/// The DBC value of `name` equals the codec's f32 (to f32 precision) or both are unavailable.
fn agree(d: &DecodedFrame<'_>, name: &str, codec: Option<f32>) {
    let dbc = value(d, name);
    match (dbc, codec) {
        (None, None) => {}
        (Some(a), Some(b)) => assert!(
            (a - f64::from(b)).abs() <= 1e-6 * a.abs().max(1.0),
            "{} t={} {name}: dbc {a} codec {b}",
            d.message.unwrap().name,
            d.frame.t_us
        ),
        _ => panic!("{name}: dbc {dbc:?} codec {codec:?}"),
    }
}

fn flag(d: &DecodedFrame<'_>, name: &str) -> bool {
    value(d, name).unwrap() == 1.0
}

fn label<'a>(d: &'a DecodedFrame<'_>, name: &str) -> Option<&'a str> {
    d.signals
        .iter()
        .find(|v| v.signal.name == name)
        .and_then(|v| v.label)
}

fn mode_label(mode: ModelMode) -> &'static str {
    match mode {
        ModelMode::Kinematic => "kinematic",
        ModelMode::Dynamic => "dynamic",
    }
}

fn ages(d: &DecodedFrame<'_>, name: &str, raw_10ms: u8) {
    let v = d.signals.iter().find(|v| v.signal.name == name).unwrap();
    assert_eq!(v.raw, i128::from(raw_10ms), "{name}");
}

#[test]
fn golden_output_decodes_as_the_node_codecs_decode_it() {
    let dbc = Dbc::catmodel().unwrap();
    let frames = catmodel_host::replay::read_candump(&data("bundled.tx.golden.log")).unwrap();
    let mut decoder = Decoder::new(&dbc);
    let mut per_name = std::collections::BTreeMap::<String, usize>::new();
    for tf in &frames {
        let d = decoder.decode(tf);
        let f = &tf.frame;
        let name = d
            .message
            .expect("every output frame is in the DBC")
            .name
            .clone();
        assert_eq!(d.check, Check::Ok, "{name} at {}", tf.t_us);
        *per_name.entry(name.clone()).or_default() += 1;
        let counter = value(&d, "counter").unwrap() as u8;
        match name.as_str() {
            "STATE_POSITION" => {
                let (m, c) = StatePosition::decode(f).unwrap();
                assert_eq!(c, counter);
                assert_eq!(flag(&d, "position_valid"), m.position_valid);
                assert_eq!(flag(&d, "gnss_fresh"), m.gnss_fresh);
                assert_eq!(flag(&d, "gnss_rejected"), m.gnss_rejected);
                agree(&d, "east_m", m.east_m);
                agree(&d, "north_m", m.north_m);
            }
            "STATE_MOTION" => {
                let (m, c) = StateMotion::decode(f).unwrap();
                assert_eq!(c, counter);
                assert_eq!(label(&d, "mode"), Some(mode_label(m.mode)));
                assert_eq!(flag(&d, "heading_uncertain"), m.heading_uncertain);
                agree(&d, "heading_rad", m.heading_rad);
                agree(&d, "speed_mps", m.speed_mps);
                agree(&d, "yaw_rate_radps", m.yaw_rate_radps);
            }
            "NODE_STATUS" => {
                let (m, c) = NodeStatus::decode(f).unwrap();
                assert_eq!(c, counter);
                assert_eq!(value(&d, "page").unwrap(), f64::from(m.page()));
                match m {
                    NodeStatus::Health {
                        mode,
                        health,
                        overrun_count,
                        last_step_us,
                    } => {
                        assert_eq!(label(&d, "mode"), Some(mode_label(mode)));
                        assert_eq!(flag(&d, "position_invalid"), health.position_invalid);
                        assert_eq!(flag(&d, "gnss_stale"), health.gnss_stale);
                        assert_eq!(flag(&d, "input_invalid"), health.input_invalid);
                        assert_eq!(
                            flag(&d, "planner_refused_recently"),
                            health.planner_refused_recently
                        );
                        assert_eq!(flag(&d, "gnss_rate_mismatch"), health.gnss_rate_mismatch);
                        assert_eq!(flag(&d, "steering_mismatch"), health.steering_mismatch);
                        assert_eq!(flag(&d, "outside_corridor"), health.outside_corridor);
                        agree(&d, "overrun_count", Some(overrun_count as f32));
                        agree(&d, "last_step_us", last_step_us.map(|v| v as f32));
                    }
                    NodeStatus::RxErrors {
                        crc_errors,
                        counter_errors,
                        dlc_errors,
                    } => {
                        agree(&d, "crc_errors", Some(crc_errors as f32));
                        agree(&d, "counter_errors", Some(counter_errors as f32));
                        agree(&d, "dlc_errors", Some(dlc_errors as f32));
                    }
                    NodeStatus::RxRejects {
                        range_errors,
                        gnss_gate_rejects,
                        unknown_ids,
                    } => {
                        agree(&d, "range_errors", Some(range_errors as f32));
                        agree(&d, "gnss_gate_rejects", Some(gnss_gate_rejects as f32));
                        agree(&d, "unknown_ids", Some(unknown_ids as f32));
                    }
                    NodeStatus::Platform {
                        tick_count,
                        rx_queue_drops,
                    } => {
                        agree(&d, "tick_count", Some(tick_count as f32));
                        agree(&d, "rx_queue_drops", Some(rx_queue_drops as f32));
                    }
                    NodeStatus::Ages {
                        ages_10ms,
                        stack_high_water_bytes,
                    } => {
                        for (name, raw) in ["steer_age", "speed_age", "pedal_age", "gnss_age"]
                            .iter()
                            .zip(ages_10ms)
                        {
                            ages(&d, name, raw);
                        }
                        agree(
                            &d,
                            "stack_high_water_bytes",
                            stack_high_water_bytes.map(|v| v as f32),
                        );
                    }
                    NodeStatus::Model(m) => {
                        agree(&d, "speed_model_mps", m.speed_model_mps);
                        agree(&d, "dxdt_model_mps", m.dxdt_model_mps);
                        agree(&d, "lat_accel_mps2", m.lat_accel_mps2);
                    }
                }
                // Only the page's own signals (+ counter, page, crc) are shown.
                let page_signals = d.signals.len() - 3;
                assert!(
                    (2..=18).contains(&page_signals),
                    "{page_signals} signals on page {}",
                    m.page()
                );
            }
            "CONTROL_COMMAND" => {
                let (m, c) = ControlCommand::decode(f).unwrap();
                assert_eq!(c, counter);
                agree(&d, "steer_cmd_pct", m.steer_cmd_pct);
                agree(&d, "speed_cmd_mps", m.speed_cmd_mps);
            }
            other => {
                let k: u8 = other.strip_prefix("PREDICTION_").unwrap().parse().unwrap();
                let (m, c) = Prediction::decode(f).unwrap();
                assert_eq!((c, m.point.k()), (counter, k));
                agree(&d, "dx_m", m.dx_m);
                agree(&d, "dy_m", m.dy_m);
                agree(&d, "dheading_rad", m.dheading_rad);
                agree(&d, "speed_mps", m.speed_mps);
            }
        }
    }
    // 748 ticks, 14 frames each; the drive has real positions, not only sentinels.
    assert_eq!(per_name.len(), 14);
    assert!(per_name.values().all(|&n| n == 748), "{per_name:?}");
}

#[test]
fn bundled_input_drive_decodes_as_the_node_reads_it() {
    let dbc = Dbc::catmodel().unwrap();
    let frames = catmodel_host::replay::read_candump(&data("bundled.can.log")).unwrap();
    let mut decoder = Decoder::new(&dbc);
    let mut positions = 0;
    for tf in &frames {
        let d = decoder.decode(tf);
        let raw = |name: &str| {
            d.signals
                .iter()
                .find(|v| v.signal.name == name)
                .unwrap()
                .raw
        };
        match decode_input(&tf.frame, N2K_DEFAULT_SOURCE).unwrap() {
            InputMessage::Steering(m, c) => {
                assert_eq!((d.check, raw("counter")), (Check::Ok, i128::from(c)));
                agree(&d, "steer_pct", m.steer_pct);
            }
            InputMessage::Speed(m, c) => {
                assert_eq!((d.check, raw("counter")), (Check::Ok, i128::from(c)));
                agree(&d, "speed_mps", m.speed_mps);
                agree(&d, "speed_cmd_mps", m.speed_cmd_mps);
            }
            InputMessage::Pedal(m, c) => {
                assert_eq!((d.check, raw("counter")), (Check::Ok, i128::from(c)));
                agree(&d, "accel_pct", m.accel_pct);
                agree(&d, "brake_pct", m.brake_pct);
            }
            InputMessage::GnssPosition(p) => {
                assert_eq!(d.check, Check::Unprotected);
                assert_eq!(raw("latitude_deg"), i128::from(p.lat_e7));
                assert_eq!(raw("longitude_deg"), i128::from(p.lon_e7));
                positions += 1;
            }
            InputMessage::GnssCogSog(_) => panic!("the bundled drive has no COG/SOG"),
        }
    }
    assert!(positions > 1000, "{positions}");
}

/// One STATE_POSITION worked out by hand: counter 3, position_valid and gnss_fresh set,
/// east 12.34 m (raw 1234 = 0x0004D2), north -5.00 m (raw -500 = 0xFFFE0C in 24 bits); CRC
/// from an independent CRC-8/SAE-J1850 in Python over 03 00 33 D2 04 00 0C FE FF = 0xFC.
/// Then the same payload with counter 4 (CRC 0x72), 4 again (stuck), 7 (two missed, CRC 0x95),
/// a broken CRC (counter 8: the right CRC is 0xC9), a short frame, an identifier the DBC lacks, and NMEA 2000 positions: the
/// canboatjs README's frame (priority 2, PGN 129025, source 127: 33.0875728, -97.0205113) and
/// ours from source 0x1C.
const HAND_MADE: &str = "\
(1.000000) can0 300#33D204000CFEFFFC
(1.020000) can0 300#34D204000CFEFF72
(1.040000) can0 300#34D204000CFEFF72
(1.060000) can0 300#37D204000CFEFF95
(1.080000) can0 300#38D204000CFEFF00
(1.100000) can0 300#38D20400
(1.120000) can0 123#DEADBEEF
(1.140000) can0 09F8017F#50C3B81347D82BC6
";

#[test]
fn hand_made_frames_decode_to_hand_derived_values_and_checks() {
    let dbc = Dbc::catmodel().unwrap();
    let frames: Vec<TimedFrame> =
        catmodel_host::replay::parse_candump(Path::new("hand"), HAND_MADE).unwrap();
    let mut out = Vec::new();
    let summary = decode_frames(&dbc, &frames, None, Format::Csv, &mut out).unwrap();
    let csv = String::from_utf8(out).unwrap();
    let rows: Vec<&str> = csv.lines().collect();
    assert_eq!(
        rows[0],
        "t_s,id,message,check,signal,raw,value,unit,label,data"
    );
    let has = |row: &str| assert!(rows.contains(&row), "missing {row:?} in\n{csv}");
    has("1.000000,300,STATE_POSITION,ok,counter,3,3,,,33D204000CFEFFFC");
    has("1.000000,300,STATE_POSITION,ok,position_valid,1,1,,,33D204000CFEFFFC");
    has("1.000000,300,STATE_POSITION,ok,gnss_rejected,0,0,,,33D204000CFEFFFC");
    has("1.000000,300,STATE_POSITION,ok,east_m,1234,12.34,m,,33D204000CFEFFFC");
    has("1.000000,300,STATE_POSITION,ok,north_m,-500,-5.00,m,,33D204000CFEFFFC");
    has("1.000000,300,STATE_POSITION,ok,crc,252,252,,,33D204000CFEFFFC");
    has("1.020000,300,STATE_POSITION,ok,counter,4,4,,,34D204000CFEFF72");
    has("1.040000,300,STATE_POSITION,stuck,counter,4,4,,,34D204000CFEFF72");
    has("1.060000,300,STATE_POSITION,jump+2,counter,7,7,,,37D204000CFEFF95");
    has("1.080000,300,STATE_POSITION,crc-error,crc,0,0,,,38D204000CFEFF00");
    // The short frame: the signals it holds, flagged.
    has("1.100000,300,STATE_POSITION,dlc-4,counter,8,8,,,38D20400");
    assert!(!csv.contains("1.100000,300,STATE_POSITION,dlc-4,north_m"));
    has("1.120000,123,,unknown-id,,,,,,DEADBEEF");
    has("1.140000,09F8017F,GNSS_POSITION_RAPID,sa=0x7F,latitude_deg,330875728,33.0875728,deg,,50C3B81347D82BC6");
    has("1.140000,09F8017F,GNSS_POSITION_RAPID,sa=0x7F,longitude_deg,-970205113,-97.0205113,deg,,50C3B81347D82BC6");
    assert_eq!(
        (
            summary.frames,
            summary.crc_errors,
            summary.counter_stuck,
            summary.counter_jumps,
            summary.missed_frames,
            summary.dlc_errors
        ),
        (8, 1, 1, 1, 2, 1)
    );
    assert_eq!(summary.unknown_ids.values().sum::<u64>(), 1);

    // The table shows the same, one line per frame, the wrong CRC with the right one.
    let mut out = Vec::new();
    decode_frames(&dbc, &frames, None, Format::Table, &mut out).unwrap();
    let table = String::from_utf8(out).unwrap();
    let lines: Vec<&str> = table.lines().collect();
    assert_eq!(lines.len(), 9, "{table}");
    assert!(lines[1].contains("east_m=    12.34 m") && lines[1].contains("north_m=    -5.00 m"));
    assert!(lines[5].contains("crc-error") && lines[5].contains("crc=0x00 (expected 0xC9)"));
    assert!(lines[7].contains("unknown") && lines[7].contains("data=DEADBEEF"));
    // Frames of one message line up: every `east_m=` at the same column.
    let col = |l: &str| l.find("east_m=");
    assert_eq!(col(lines[1]), col(lines[4]));
}

#[test]
fn selection_by_name_prefix_and_id() {
    let dbc = Dbc::catmodel().unwrap();
    let pick = |items: &[&str]| {
        let items: Vec<String> = items.iter().map(|s| s.to_string()).collect();
        Selection::parse(&dbc, &items)
    };
    assert_eq!(pick(&[]).unwrap(), None);
    let frames = catmodel_host::replay::read_candump(&data("bundled.tx.golden.log")).unwrap();
    let count = |items: &[&str]| {
        let sel = pick(items).unwrap();
        let mut out = Vec::new();
        let summary = decode_frames(&dbc, &frames, sel.as_ref(), Format::Table, &mut out).unwrap();
        assert_eq!(
            summary.frames, 10_472,
            "every frame is checked, shown or not"
        );
        assert_eq!(
            String::from_utf8(out).unwrap().lines().count() as u64,
            summary.shown + 1
        );
        summary.shown
    };
    assert_eq!(count(&["PREDICTION_*"]), 7_480);
    assert_eq!(count(&["node_status", "0x300"]), 2 * 748);
    assert_eq!(count(&["3F0", "301"]), 2 * 748);
    assert_eq!(count(&["7FF"]), 0);
    let e = pick(&["NOPE"]).unwrap_err().to_string();
    assert!(
        e.contains("\"NOPE\"") && e.contains("STATE_POSITION"),
        "{e}"
    );
}

#[test]
fn cli_decodes_and_names_bad_lines() {
    let out = Command::new(BIN)
        .args(["decode", "--messages", "STATE_MOTION"])
        .arg(data("bundled.tx.golden.log"))
        .output()
        .unwrap();
    assert!(out.status.success());
    let stdout = String::from_utf8(out.stdout).unwrap();
    assert_eq!(stdout.lines().count(), 749);
    assert!(stdout.lines().nth(1).unwrap().contains("STATE_MOTION"));
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert!(
        stderr.contains("decoded 10472 frames (748 shown)") && stderr.contains("0 crc errors"),
        "{stderr}"
    );

    let bad = tmp(
        "bad.log",
        "(1.000000) can0 300#33D204000CFEFFFC\n\n(1.020000) can0 300#33D2XX\n",
    );
    let out = Command::new(BIN).arg("decode").arg(&bad).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert!(
        stderr.contains(&format!(
            "{}:3: malformed candump line (data is not hex)",
            bad.display()
        )),
        "{stderr}"
    );
}
