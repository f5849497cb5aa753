//! The bus codecs against independent references: CRC check values, hand-packed frames, a
// The COG round trips use raw values next to pi and 2 pi on purpose (the field's range ends).
#![allow(clippy::approx_constant)]
//! published NMEA 2000 frame (canboatjs README), round trips of every message at its limits,
//! every error kind, the counter checker, freshness, the bus-load budget and candump text.
use catmodel::can::candump::{format_line, parse_line, CandumpError};
use catmodel::can::counter::{CounterCheck, CounterChecker};
use catmodel::can::crc::frame_crc;
use catmodel::can::freshness::{
    age_10ms, is_recent, is_timed_out, Freshness, FreshnessConfig, Input, AGE_MAX, AGE_NEVER,
};
use catmodel::can::spec::{self, sig, MessageSpec, NODE_CATMODEL};
use catmodel::can::*;
use proptest::prelude::*;

// ------------------------------------------------------------------------------------------
// CRC

#[test]
fn crc8_sae_j1850_check_values() {
    // CRC-8/SAE-J1850 (poly 0x1D, init 0xFF, xorout 0xFF) catalogue check value, and two short
    // vectors consistent with the static_asserts of Dataspeed's ds_dbw CAN driver.
    assert_eq!(crc8_sae_j1850(b"123456789"), 0x4B);
    assert_eq!(crc8_sae_j1850(b"0"), 0x71);
    assert_eq!(crc8_sae_j1850(b"01"), 0x28);
    // Empty input: init 0xFF xor 0xFF.
    assert_eq!(crc8_sae_j1850(b""), 0x00);
}

/// Bitwise CRC written independently of the crate's, for the frame-level property.
fn reference_crc(bytes: &[u8]) -> u8 {
    let mut crc: u32 = 0xFF;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc <<= 1;
            if crc & 0x100 != 0 {
                crc ^= 0x11D;
            }
        }
    }
    (crc as u8) ^ 0xFF
}

proptest! {
    #[test]
    fn frame_crc_covers_id_high_low_then_seven_bytes(id in 0u16..=0x7FF, data in any::<[u8; 8]>()) {
        let mut bytes = vec![(id >> 8) as u8, id as u8];
        bytes.extend_from_slice(&data[..7]);
        prop_assert_eq!(frame_crc(CanId::Standard(id), &data), reference_crc(&bytes));
        prop_assert_eq!(crc8_sae_j1850(&bytes), reference_crc(&bytes));
    }
}

// ------------------------------------------------------------------------------------------
// Hand-packed frames (independent of the descriptor table)

#[test]
fn steering_report_hand_packed() {
    // 12.34 % -> raw 1234 = 0x04D2 little-endian in bytes 0-1; counter 5 in bits 52..55 =
    // high nibble of byte 6; CRC over 0x01 0x00 then bytes 0..6.
    let frame = SteeringReport {
        steer_pct: Some(12.34),
    }
    .encode(5);
    let body = [0xD2, 0x04, 0, 0, 0, 0, 0x50];
    let crc = reference_crc(&[0x01, 0x00, 0xD2, 0x04, 0, 0, 0, 0, 0x50]);
    assert_eq!(frame.id, CanId::Standard(0x100));
    assert_eq!(frame.len, 8);
    assert_eq!(&frame.data[..7], &body);
    assert_eq!(frame.data[7], crc);
    // Negative: -100 % -> raw -10000 = 0xD8F0.
    let frame = SteeringReport {
        steer_pct: Some(-100.0),
    }
    .encode(15);
    assert_eq!(&frame.data[..7], &[0xF0, 0xD8, 0, 0, 0, 0, 0xF0]);
}

#[test]
fn prediction_hand_packed() {
    // counter 3 bits 0..3; dx = -0.01 m (raw -1 = 0x3FFF, 14 bits) at bits 4..17;
    // dy = +0.02 (raw 2) at 18..31; dheading = 0.001 (raw 1) at 32..43; speed = 0.05 (raw 5)
    // at 44..55.
    let p = Prediction {
        point: PredictionPoint::new(4).unwrap(),
        dx_m: Some(-0.01),
        dy_m: Some(0.02),
        dheading_rad: Some(0.001),
        speed_mps: Some(0.05),
    };
    let frame = p.encode(3);
    let word: u64 = 3 | (0x3FFF << 4) | (2 << 18) | (1 << 32) | (5 << 44);
    let bytes = word.to_le_bytes();
    assert_eq!(frame.id, CanId::Standard(0x313));
    assert_eq!(&frame.data[..7], &bytes[..7]);
    assert_eq!(
        frame.data[7],
        reference_crc(&[
            0x03, 0x13, bytes[0], bytes[1], bytes[2], bytes[3], bytes[4], bytes[5], bytes[6]
        ])
    );
    let (back, counter) = Prediction::decode(&frame).unwrap();
    assert_eq!(counter, 3);
    assert_eq!(back.point.k(), 4);
}

#[test]
fn nmea2000_position_published_frame() {
    // canboatjs README (YDWG-02 example): "09F8017F 50 C3 B8 13 47 D8 2B C6" decodes to
    // prio 2, PGN 129025, src 127, Latitude 33.0875728, Longitude -97.0205113.
    let frame = CanFrame::new(
        CanId::Extended(0x09F8_017F),
        &[0x50, 0xC3, 0xB8, 0x13, 0x47, 0xD8, 0x2B, 0xC6],
    )
    .unwrap();
    assert_eq!(spec::n2k_pgn_source(0x09F8_017F), (129_025, 127));
    let fix = GnssPosition::decode(&frame, 127).unwrap();
    assert_eq!(fix.lat_e7, 330_875_728);
    assert_eq!(fix.lon_e7, -970_205_113);
    assert_eq!(
        GnssPosition::decode(&frame, spec::N2K_DEFAULT_SOURCE),
        Err(DecodeError::WrongSource { got: 127 })
    );
    // Encoding the same fix from source 127 gives the same bytes and identifier.
    assert_eq!(fix.encode(127), frame);
    // Another priority is accepted (the PGN and source decide).
    let mut other = frame;
    other.id = CanId::Extended(0x1DF8_017F);
    assert_eq!(GnssPosition::decode(&other, 127), Ok(fix));
}

#[test]
fn nmea2000_cog_sog_layout() {
    // canboat PGN 129026: SID u8, COG reference 2 bits, 6 reserved bits, COG u16 1e-4 rad,
    // SOG u16 0.01 m/s, 2 reserved bytes (0xFF).
    let m = GnssCogSog {
        sid: 0x2A,
        cog_reference: 0,
        cog_rad: Some(1.2345),
        sog_mps: Some(12.34),
    };
    let frame = m.encode(spec::N2K_DEFAULT_SOURCE);
    assert_eq!(frame.id, CanId::Extended(0x09F8_021C));
    assert_eq!(
        frame.data,
        [0x2A, 0xFC, 0x39, 0x30, 0xD2, 0x04, 0xFF, 0xFF] // 12345 = 0x3039, 1234 = 0x04D2
    );
    let back = GnssCogSog::decode(&frame, 0x1C).unwrap();
    assert_eq!(back.sid, 0x2A);
    assert!((back.cog_rad.unwrap() - 1.2345).abs() < 0.5e-4);
    assert!((back.sog_mps.unwrap() - 12.34).abs() < 0.005);
}

// ------------------------------------------------------------------------------------------
// Round trips at min / max / invalid

/// |a - b| <= half a quantisation step (plus f32 rounding).
fn close(a: Option<f32>, b: Option<f32>, scale: f32) -> bool {
    match (a, b) {
        (None, None) => true,
        (Some(a), Some(b)) => (a - b).abs() <= 0.5 * scale + 1e-6 * b.abs(),
        _ => false,
    }
}

fn phys_min(s: &spec::SignalSpec) -> f32 {
    s.to_physical(s.raw_min)
}
fn phys_max(s: &spec::SignalSpec) -> f32 {
    s.to_physical(s.raw_max)
}

/// SPEED_REPORT `direction` (bits 32..33, byte 4): each of its four values packed by hand and
/// round-tripped; "not reported" (0) leaves the frame as it was before the signal existed, so
/// every recorded log decodes as it did.
#[test]
fn speed_report_direction_round_trips_and_zero_is_the_old_frame() {
    let old = |speed: f32, counter: u8| {
        // speed 1.00 m/s = raw 100 (0..15), command the same (16..31), counter in 52..55.
        let mut data = [100, 0, 100, 0, 0, 0, counter << 4, 0];
        data[7] = frame_crc(CanId::Standard(0x101), &data);
        assert_eq!(speed, 1.0);
        CanFrame::new(CanId::Standard(0x101), &data).unwrap()
    };
    let not_reported = SpeedReport {
        speed_mps: Some(1.0),
        speed_cmd_mps: Some(1.0),
        direction: Direction::NotReported,
    };
    assert_eq!(not_reported.encode(5), old(1.0, 5));
    assert_eq!(
        SpeedReport::decode(&old(1.0, 5)).unwrap(),
        (not_reported, 5)
    );
    for (raw, direction) in [
        (0u8, Direction::NotReported),
        (1, Direction::Forward),
        (2, Direction::Reverse),
        (3, Direction::Invalid),
    ] {
        let m = SpeedReport {
            direction,
            ..not_reported
        };
        let frame = m.encode(9);
        assert_eq!(frame.data[4], raw, "{direction:?}");
        assert_eq!(sig::DIRECTION.read_raw(&frame.data), i64::from(raw));
        let mut by_hand = old(1.0, 9);
        by_hand.data[4] = raw;
        by_hand.data[7] = frame_crc(by_hand.id, &by_hand.data);
        assert_eq!(frame, by_hand, "{direction:?}");
        assert_eq!(SpeedReport::decode(&frame).unwrap(), (m, 9));
    }
}

#[test]
fn inputs_round_trip_at_limits_and_invalid() {
    for counter in [0u8, 7, 15] {
        for v in [
            Some(phys_min(&sig::STEER_PCT)),
            Some(phys_max(&sig::STEER_PCT)),
            Some(0.0),
            None,
        ] {
            let m = SteeringReport { steer_pct: v };
            let (back, c) = SteeringReport::decode(&m.encode(counter)).unwrap();
            assert_eq!(c, counter);
            assert!(close(back.steer_pct, v, 0.01), "{v:?} -> {back:?}");
        }
        for (i, (a, b)) in [
            (Some(0.0), Some(655.34)),
            (Some(655.34), None),
            (None, Some(0.0)),
        ]
        .into_iter()
        .enumerate()
        {
            let direction = [
                Direction::Reverse,
                Direction::NotReported,
                Direction::Forward,
            ][i];
            let m = SpeedReport {
                speed_mps: a,
                speed_cmd_mps: b,
                direction,
            };
            let (back, c) = SpeedReport::decode(&m.encode(counter)).unwrap();
            assert_eq!(c, counter);
            assert!(close(back.speed_mps, a, 0.01) && close(back.speed_cmd_mps, b, 0.01));
            assert_eq!(back.direction, direction);
        }
        for (a, b) in [
            (Some(0.0), Some(100.0)),
            (Some(100.0), None),
            (None, Some(0.0)),
        ] {
            let m = PedalReport {
                accel_pct: a,
                brake_pct: b,
            };
            let (back, c) = PedalReport::decode(&m.encode(counter)).unwrap();
            assert_eq!(c, counter);
            assert!(close(back.accel_pct, a, 0.01) && close(back.brake_pct, b, 0.01));
        }
    }
    for (lat, lon) in [
        (-900_000_000, -1_800_000_000),
        (900_000_000, 1_800_000_000),
        (0, 0),
    ] {
        let m = GnssPosition {
            lat_e7: lat,
            lon_e7: lon,
        };
        assert_eq!(GnssPosition::decode(&m.encode(0x1C), 0x1C), Ok(m));
    }
    for (cog, sog) in [
        (Some(0.0), Some(0.0)),
        (Some(phys_max(&sig::COG_RAD)), Some(655.32)),
        (None, None),
    ] {
        let m = GnssCogSog {
            sid: 255,
            cog_reference: 3,
            cog_rad: cog,
            sog_mps: sog,
        };
        let back = GnssCogSog::decode(&m.encode(0x1C), 0x1C).unwrap();
        assert_eq!((back.sid, back.cog_reference), (255, 3));
        assert!(close(back.cog_rad, cog, 1e-4) && close(back.sog_mps, sog, 0.01));
    }
}

#[test]
fn state_messages_round_trip_at_limits_and_invalid() {
    let lim = |s: &spec::SignalSpec| [Some(phys_min(s)), Some(phys_max(s)), None];
    for counter in [0u8, 9, 15] {
        for (i, (e, n)) in lim(&sig::EAST_M)
            .into_iter()
            .zip(lim(&sig::NORTH_M).into_iter().rev())
            .enumerate()
        {
            let m = StatePosition {
                position_valid: i % 2 == 0,
                gnss_fresh: i == 1,
                gnss_rejected: i == 2,
                east_m: e,
                north_m: n,
            };
            let (back, c) = StatePosition::decode(&m.encode(counter)).unwrap();
            assert_eq!(c, counter);
            assert_eq!(
                (back.position_valid, back.gnss_fresh, back.gnss_rejected),
                (m.position_valid, m.gnss_fresh, m.gnss_rejected)
            );
            assert!(
                close(back.east_m, e, 0.01) && close(back.north_m, n, 0.01),
                "{m:?} -> {back:?}"
            );
        }
        for i in 0..3 {
            let m = StateMotion {
                mode: if i == 1 {
                    ModelMode::Dynamic
                } else {
                    ModelMode::Kinematic
                },
                heading_uncertain: i == 2,
                heading_rad: lim(&sig::HEADING_RAD)[i],
                speed_mps: lim(&sig::STATE_SPEED_MPS)[2 - i],
                yaw_rate_radps: lim(&sig::YAW_RATE_RADPS)[i],
            };
            let (back, c) = StateMotion::decode(&m.encode(counter)).unwrap();
            assert_eq!(
                (c, back.mode, back.heading_uncertain),
                (counter, m.mode, m.heading_uncertain)
            );
            assert!(close(back.heading_rad, m.heading_rad, 0.001));
            assert!(close(back.speed_mps, m.speed_mps, 0.01));
            assert!(close(back.yaw_rate_radps, m.yaw_rate_radps, 0.001));

            let m = ModelOutputs {
                speed_model_mps: lim(&sig::SPEED_MODEL_MPS)[i],
                dxdt_model_mps: lim(&sig::DXDT_MODEL_MPS)[2 - i],
                lat_accel_mps2: lim(&sig::LAT_ACCEL_MPS2)[(i + 1) % 3],
            };
            let (back, c) = NodeStatus::decode(&NodeStatus::Model(m).encode(counter)).unwrap();
            assert_eq!(c, counter);
            let NodeStatus::Model(back) = back else {
                panic!("page 5 decoded as {back:?}")
            };
            assert!(close(back.speed_model_mps, m.speed_model_mps, 0.01));
            assert!(close(back.dxdt_model_mps, m.dxdt_model_mps, 0.01));
            assert!(close(back.lat_accel_mps2, m.lat_accel_mps2, 0.01));

            for point in PredictionPoint::all() {
                let m = Prediction {
                    point,
                    dx_m: lim(&sig::DX_M)[i],
                    dy_m: lim(&sig::DY_M)[2 - i],
                    dheading_rad: lim(&sig::DHEADING_RAD)[(i + 1) % 3],
                    speed_mps: lim(&sig::PRED_SPEED_MPS)[(i + 2) % 3],
                };
                let frame = m.encode(counter);
                assert_eq!(frame.id, CanId::Standard(0x30F + u16::from(point.k())));
                let (back, c) = Prediction::decode(&frame).unwrap();
                assert_eq!((c, back.point), (counter, point));
                assert!(close(back.dx_m, m.dx_m, 0.01) && close(back.dy_m, m.dy_m, 0.01));
                assert!(close(back.dheading_rad, m.dheading_rad, 0.001));
                assert!(close(back.speed_mps, m.speed_mps, 0.01));
            }
        }
    }
    // Heading at +-pi fits (the DBC range is +-3.142).
    for h in [core::f32::consts::PI, -core::f32::consts::PI] {
        let (frame, report) = StateMotion {
            heading_rad: Some(h),
            ..Default::default()
        }
        .encode_with_report(0);
        assert!(!report.any_substituted());
        assert!(close(
            StateMotion::decode(&frame).unwrap().0.heading_rad,
            Some(h),
            0.001
        ));
    }
}

#[test]
fn node_status_pages_round_trip_and_saturate() {
    let all_health = HealthFlags {
        steer_stale: true,
        speed_stale: false,
        pedal_stale: true,
        gnss_stale: false,
        gnss_rejected_recently: true,
        position_invalid: false,
        prediction_saturated: true,
        nonfinite_guard: false,
        watchdog_reset: true,
        overrun_recently: false,
        input_invalid: true,
        planner_refused_recently: false,
        gnss_rate_mismatch: true,
        steering_mismatch: false,
        outside_corridor: true,
    };
    let pages = [
        NodeStatus::Health {
            mode: ModelMode::Dynamic,
            health: all_health,
            overrun_count: 65_535,
            last_step_us: Some(65_534),
        },
        NodeStatus::Health {
            mode: ModelMode::Kinematic,
            health: HealthFlags::default(),
            overrun_count: 0,
            last_step_us: None,
        },
        NodeStatus::RxErrors {
            crc_errors: 0,
            counter_errors: 1,
            dlc_errors: 65_535,
        },
        NodeStatus::RxRejects {
            range_errors: 65_535,
            gnss_gate_rejects: 2,
            unknown_ids: 0,
        },
        NodeStatus::Platform {
            tick_count: u32::MAX,
            rx_queue_drops: 65_535,
        },
        NodeStatus::Ages {
            ages_10ms: [0, 1, AGE_MAX, AGE_NEVER],
            stack_high_water_bytes: Some(65_534),
        },
        NodeStatus::Ages {
            ages_10ms: [AGE_NEVER; 4],
            stack_high_water_bytes: None,
        },
        NodeStatus::Model(ModelOutputs {
            speed_model_mps: Some(12.5),
            dxdt_model_mps: Some(-3.25),
            lat_accel_mps2: None,
        }),
    ];
    for (i, page) in pages.iter().enumerate() {
        let counter = (i % 16) as u8;
        let (frame, report) = page.encode_with_report(counter);
        assert!(!report.any_substituted(), "{page:?}");
        assert_eq!(NodeStatus::decode(&frame), Ok((*page, counter)));
        assert_eq!(
            spec::sig::PAGE.read_raw(&frame.data),
            i64::from(page.page())
        );
    }
    // Counters saturate at the field maximum (never wrap); measurements at max - 1 (max = n/a).
    let (frame, report) = NodeStatus::Health {
        mode: ModelMode::Kinematic,
        health: HealthFlags::default(),
        overrun_count: 70_000,
        last_step_us: Some(1_000_000),
    }
    .encode_with_report(0);
    assert_eq!(report.saturated, 2);
    assert_eq!(
        NodeStatus::decode(&frame).unwrap().0,
        NodeStatus::Health {
            mode: ModelMode::Kinematic,
            health: HealthFlags::default(),
            overrun_count: 65_535,
            last_step_us: Some(65_534)
        }
    );
    let (frame, _) = NodeStatus::RxErrors {
        crc_errors: u32::MAX,
        counter_errors: 65_536,
        dlc_errors: 3,
    }
    .encode_with_report(1);
    assert_eq!(
        NodeStatus::decode(&frame).unwrap().0,
        NodeStatus::RxErrors {
            crc_errors: 65_535,
            counter_errors: 65_535,
            dlc_errors: 3
        }
    );
}

#[test]
fn encoders_replace_non_finite_and_out_of_range_by_not_available() {
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -f32::NAN] {
        let (frame, report) = Prediction {
            point: PredictionPoint::new(1).unwrap(),
            dx_m: Some(bad),
            dy_m: Some(1.0),
            dheading_rad: Some(bad),
            speed_mps: Some(bad),
        }
        .encode_with_report(0);
        assert_eq!(report.non_finite, 3);
        assert!(report.any_substituted());
        assert_eq!(sig::DX_M.read_raw(&frame.data), -8192);
        assert_eq!(sig::DHEADING_RAD.read_raw(&frame.data), -2048);
        assert_eq!(sig::PRED_SPEED_MPS.read_raw(&frame.data), 0xFFF);
        let (back, _) = Prediction::decode(&frame).unwrap();
        assert_eq!(
            (back.dx_m, back.dheading_rad, back.speed_mps),
            (None, None, None)
        );
        assert_eq!(back.dy_m, Some(1.0));
    }
    // Out of range: 81.92 m > 81.91 m, -0.01 m/s, 100.01 %.
    let (frame, report) = Prediction {
        point: PredictionPoint::new(10).unwrap(),
        dx_m: Some(81.92),
        dy_m: Some(-81.91),
        dheading_rad: Some(2.047),
        speed_mps: Some(-0.01),
    }
    .encode_with_report(0);
    assert_eq!(
        (report.out_of_range, report.non_finite, report.absent),
        (2, 0, 0)
    );
    let (back, _) = Prediction::decode(&frame).unwrap();
    assert_eq!(back.dx_m, None);
    assert_eq!(back.speed_mps, None);
    assert!(close(back.dy_m, Some(-81.91), 0.01));
    let (_, report) = SteeringReport {
        steer_pct: Some(100.01),
    }
    .encode_with_report(0);
    assert_eq!(report.out_of_range, 1);
    let (frame, report) = GnssPosition {
        lat_e7: 900_000_001,
        lon_e7: 0,
    }
    .encode_with_report(0x1C);
    assert_eq!(report.out_of_range, 1);
    assert_eq!(
        GnssPosition::decode(&frame, 0x1C),
        Err(DecodeError::Invalid {
            signal: "latitude_deg"
        })
    );
    let (_, report) = NodeStatus::Model(ModelOutputs::default()).encode_with_report(0);
    assert_eq!(report.absent, 3);
    assert!(!report.any_substituted());
}

proptest! {
    /// Whatever f32 bits the model produces, the frame decodes, and every value is either
    /// "not available" or within the DBC range and within half a step of the input.
    #[test]
    fn prediction_encoding_never_emits_garbage(
        k in 1u8..=10, counter in 0u8..16,
        dx in any::<u32>(), dy in -90.0f32..90.0, dh in any::<u32>(), v in -1.0f32..50.0,
    ) {
        let m = Prediction {
            point: PredictionPoint::new(k).unwrap(),
            dx_m: Some(f32::from_bits(dx)),
            dy_m: Some(dy),
            dheading_rad: Some(f32::from_bits(dh)),
            speed_mps: Some(v),
        };
        let (back, c) = Prediction::decode(&m.encode(counter)).unwrap();
        prop_assert_eq!(c, counter);
        for (sent, got, s) in [
            (m.dx_m, back.dx_m, &sig::DX_M),
            (m.dy_m, back.dy_m, &sig::DY_M),
            (m.dheading_rad, back.dheading_rad, &sig::DHEADING_RAD),
            (m.speed_mps, back.speed_mps, &sig::PRED_SPEED_MPS),
        ] {
            if let Some(got) = got {
                prop_assert!(got >= phys_min(s) - 1e-4 && got <= phys_max(s) + 1e-4);
                prop_assert!(close(Some(got), sent, s.scale));
            } else {
                let sent = sent.unwrap();
                let in_range = sent.is_finite() && s.to_raw(sent).is_some();
                prop_assert!(!in_range, "{} = {} sent as n/a", s.name, sent);
            }
        }
    }
}

// ------------------------------------------------------------------------------------------
// The controller's messages: planner inputs and CONTROL_COMMAND

/// The 8 bytes of a little-endian 64-bit word with `crc` in byte 7 computed independently.
fn hand_frame(id: u16, word: u64) -> [u8; 8] {
    let mut bytes = word.to_le_bytes();
    let mut covered = vec![(id >> 8) as u8, id as u8];
    covered.extend_from_slice(&bytes[..7]);
    bytes[7] = reference_crc(&covered);
    bytes
}

#[test]
fn path_point_hand_packed() {
    // counter 7 (bits 0..3), path_id 3 (4..7), index 200 (8..15); east -0.02 m = raw -1 as 20
    // bits (16..35); north 10 485.74 m = raw 524 287 (36..55).
    let p = PathPoint {
        path_id: 3,
        index: 200,
        east_m: -0.02,
        north_m: 10_485.74,
    };
    let word: u64 = 7 | (3 << 4) | (200 << 8) | (0xF_FFFF << 16) | (524_287 << 36);
    let frame = p.encode(7);
    assert_eq!(frame.id, CanId::Standard(0x201));
    assert_eq!(frame.data, hand_frame(0x201, word));
    let (back, c) = PathPoint::decode(&frame).unwrap();
    assert_eq!((c, back.path_id, back.index), (7, 3, 200));
    assert!((back.east_m + 0.02).abs() < 1e-6 && (back.north_m - 10_485.74).abs() < 1e-3);
}

#[test]
fn path_limits_header_obstacle_origin_hand_packed() {
    // PATH_LIMITS: speed 12.34 m/s = 1234 (16..27), left 1.5 m = 150 (28..41), right 163.82 m
    // = 16 382 (42..55).
    let l = PathLimits {
        path_id: 15,
        index: 0,
        speed_mps: 12.34,
        left_m: 1.5,
        right_m: 163.82,
    };
    let word: u64 = 1 | (15 << 4) | (1234 << 16) | (150 << 28) | (16_382 << 42);
    assert_eq!(l.encode(1).data, hand_frame(0x202, word));
    // PATH_HEADER: count 256 in bits 8..16.
    let h = PathHeader {
        path_id: 9,
        count: 256,
    };
    assert_eq!(h.encode(0).data, hand_frame(0x200, (9 << 4) | (256 << 8)));
    // OBSTACLE: slot 2 (4..5), active (6), east 1 m = 50 (8..27), north -1 m = -50 as 20 bits
    // (28..47), radius 0.75 m = 15 (48..55).
    let o = Obstacle {
        obstacle_id: 2,
        circle: Some(ObstacleCircle {
            east_m: 1.0,
            north_m: -1.0,
            radius_m: 0.75,
        }),
    };
    let north_raw = (1u64 << 20) - 50;
    let word = 4 | (2 << 4) | (1 << 6) | (50 << 8) | (north_raw << 28) | (15 << 48);
    assert_eq!(o.encode(4).data, hand_frame(0x203, word));
    // LOCAL_ORIGIN: page bit 4; latitude 32.2319 deg = 322 319 000 in bits 8..39.
    let lat = LocalOrigin::Latitude {
        lat_e7: 322_319_000,
    };
    assert_eq!(
        lat.encode(5).data,
        hand_frame(0x204, 5 | (322_319_000 << 8))
    );
    let lon = LocalOrigin::Longitude {
        lon_e7: -1_109_501_000,
    };
    let lon_raw = u64::from((-1_109_501_000i32) as u32);
    assert_eq!(
        lon.encode(6).data,
        hand_frame(0x204, 6 | (1 << 4) | (lon_raw << 8))
    );
    assert_eq!(LocalOrigin::decode(&lon.encode(6)), Ok((lon, 6)));
}

#[test]
fn control_command_hand_packed() {
    // counter 11; status 3 (bits 4..5); steer -12.34 % = raw -1234 = 0xFB2E (8..23); speed
    // 10 m/s = 1000 (24..39); fallback reason 7, no passage (40..43).
    let m = ControlCommand {
        status: ControlStatus::Fallback,
        fallback: FallbackCause::NoPassage,
        steer_cmd_pct: Some(-12.34),
        speed_cmd_mps: Some(10.0),
    };
    let word: u64 = 11 | (3 << 4) | (0xFB2E << 8) | (1000 << 24) | (7 << 40);
    let frame = m.encode(11);
    assert_eq!(frame.id, CanId::Standard(0x320));
    assert_eq!(frame.data, hand_frame(0x320, word));
    let (back, c) = ControlCommand::decode(&frame).unwrap();
    assert_eq!(
        (c, back.status, back.fallback),
        (11, ControlStatus::Fallback, FallbackCause::NoPassage)
    );
    assert!(close(back.steer_cmd_pct, m.steer_cmd_pct, 0.01));
    assert!(close(back.speed_cmd_mps, m.speed_cmd_mps, 0.01));
}

#[test]
fn controller_messages_round_trip_at_limits() {
    let lim = |s: &spec::SignalSpec| [phys_min(s), phys_max(s), 0.0];
    for counter in [0u8, 8, 15] {
        for i in 0..3 {
            let p = PathPoint {
                path_id: counter,
                index: [0, 255, 17][i],
                east_m: lim(&sig::PATH_EAST_M)[i],
                north_m: lim(&sig::PATH_NORTH_M)[2 - i],
            };
            let (back, c) = PathPoint::decode(&p.encode(counter)).unwrap();
            assert_eq!((c, back.path_id, back.index), (counter, p.path_id, p.index));
            assert!(close(Some(back.east_m), Some(p.east_m), 0.02));
            assert!(close(Some(back.north_m), Some(p.north_m), 0.02));
            let l = PathLimits {
                path_id: counter ^ 0x0F,
                index: p.index,
                speed_mps: lim(&sig::PATH_SPEED_MPS)[i],
                left_m: lim(&sig::PATH_LEFT_M)[(i + 1) % 3],
                right_m: lim(&sig::PATH_RIGHT_M)[(i + 2) % 3],
            };
            let (back, c) = PathLimits::decode(&l.encode(counter)).unwrap();
            assert_eq!((c, back.path_id, back.index), (counter, l.path_id, l.index));
            for (a, b) in [
                (back.speed_mps, l.speed_mps),
                (back.left_m, l.left_m),
                (back.right_m, l.right_m),
            ] {
                assert!(close(Some(a), Some(b), 0.01), "{l:?} -> {back:?}");
            }
            let h = PathHeader {
                path_id: counter,
                count: [2, 256, 128][i],
            };
            assert_eq!(PathHeader::decode(&h.encode(counter)), Ok((h, counter)));
            let o = Obstacle {
                obstacle_id: (i % 4) as u8,
                circle: (i != 2).then_some(ObstacleCircle {
                    east_m: lim(&sig::OBSTACLE_EAST_M)[i],
                    north_m: lim(&sig::OBSTACLE_NORTH_M)[(i + 1) % 3],
                    radius_m: lim(&sig::OBSTACLE_RADIUS_M)[i],
                }),
            };
            let (back, c) = Obstacle::decode(&o.encode(counter)).unwrap();
            assert_eq!((c, back.obstacle_id), (counter, o.obstacle_id));
            match (back.circle, o.circle) {
                (None, None) => {}
                (Some(a), Some(b)) => {
                    assert!(close(Some(a.east_m), Some(b.east_m), 0.02));
                    assert!(close(Some(a.north_m), Some(b.north_m), 0.02));
                    assert!(close(Some(a.radius_m), Some(b.radius_m), 0.05));
                }
                other => panic!("{other:?}"),
            }
            for origin in [
                LocalOrigin::Latitude {
                    lat_e7: [-900_000_000, 900_000_000, 0][i],
                },
                LocalOrigin::Longitude {
                    lon_e7: [-1_800_000_000, 1_800_000_000, 0][i],
                },
            ] {
                assert_eq!(
                    LocalOrigin::decode(&origin.encode(counter)),
                    Ok((origin, counter))
                );
            }
            for status in [
                ControlStatus::NoPath,
                ControlStatus::Tracking,
                ControlStatus::Avoiding,
                ControlStatus::Fallback,
            ] {
                let fallback =
                    FallbackCause::ALL[(i + 4 * counter as usize) % FallbackCause::ALL.len()];
                let m = ControlCommand {
                    status,
                    fallback,
                    steer_cmd_pct: [Some(-100.0), Some(100.0), None][i],
                    speed_cmd_mps: [Some(655.34), None, Some(0.0)][i],
                };
                let (back, c) = ControlCommand::decode(&m.encode(counter)).unwrap();
                assert_eq!((c, back.status, back.fallback), (counter, status, fallback));
                assert!(close(back.steer_cmd_pct, m.steer_cmd_pct, 0.01));
                assert!(close(back.speed_cmd_mps, m.speed_cmd_mps, 0.01));
            }
        }
    }
}

#[test]
fn controller_messages_reject_bad_values() {
    // Out-of-range or non-finite values go out as "not available" (counted), and a receiver
    // rejects the frame: the path module never sees a value that is not a real one.
    for bad in [f32::NAN, f32::INFINITY, 10_486.0, -10_486.0] {
        let (frame, report) = PathPoint {
            path_id: 1,
            index: 0,
            east_m: bad,
            north_m: 0.0,
        }
        .encode_with_report(0);
        assert_eq!(report.non_finite + report.out_of_range, 1, "{bad}");
        assert_eq!(
            PathPoint::decode(&frame),
            Err(DecodeError::Invalid { signal: "east_m" })
        );
    }
    for (speed, left, signal) in [
        (-0.1, 1.0, "speed_mps"),
        (41.0, 1.0, "speed_mps"),
        (5.0, f32::NAN, "left_m"),
        (5.0, 200.0, "left_m"),
    ] {
        let (frame, report) = PathLimits {
            path_id: 1,
            index: 0,
            speed_mps: speed,
            left_m: left,
            right_m: 1.0,
        }
        .encode_with_report(0);
        assert!(report.any_substituted());
        assert_eq!(
            PathLimits::decode(&frame),
            Err(DecodeError::Invalid { signal })
        );
    }
    for count in [0u16, 1, 257, 1000] {
        let (frame, report) = PathHeader { path_id: 0, count }.encode_with_report(0);
        assert_eq!(report.out_of_range, 1, "{count}");
        assert_eq!(
            PathHeader::decode(&frame),
            Err(DecodeError::OutOfRange { signal: "count" })
        );
    }
    let (frame, report) = Obstacle {
        obstacle_id: 0,
        circle: Some(ObstacleCircle {
            east_m: 0.0,
            north_m: 0.0,
            radius_m: 12.8,
        }),
    }
    .encode_with_report(0);
    assert_eq!(report.out_of_range, 1);
    assert_eq!(
        Obstacle::decode(&frame),
        Err(DecodeError::Invalid { signal: "radius_m" })
    );
    let (frame, report) = LocalOrigin::Latitude {
        lat_e7: 900_000_001,
    }
    .encode_with_report(0);
    assert_eq!(report.out_of_range, 1);
    assert_eq!(
        LocalOrigin::decode(&frame),
        Err(DecodeError::Invalid {
            signal: "latitude_deg"
        })
    );
    // A CRC error and a wrong DLC are caught like on every frame of ours.
    let mut f = PathHeader {
        path_id: 0,
        count: 10,
    }
    .encode(0);
    f.data[1] ^= 0x01;
    assert!(matches!(
        PathHeader::decode(&f),
        Err(DecodeError::Crc { .. })
    ));
    let short = CanFrame::new(CanId::Standard(0x201), &[0; 7]).unwrap();
    assert_eq!(
        decode_planner(&short),
        Err(DecodeError::Dlc {
            expected: 8,
            got: 7
        })
    );
}

#[test]
fn decode_planner_dispatch_and_decode_input_unchanged() {
    let h = PathHeader {
        path_id: 4,
        count: 10,
    };
    let p = PathPoint {
        path_id: 4,
        index: 1,
        east_m: 1.0,
        north_m: 2.0,
    };
    let o = Obstacle {
        obstacle_id: 3,
        circle: None,
    };
    assert_eq!(
        decode_planner(&h.encode(1)),
        Ok(PlannerMessage::PathHeader(h, 1))
    );
    assert!(matches!(
        decode_planner(&p.encode(2)),
        Ok(PlannerMessage::PathPoint(_, 2))
    ));
    assert_eq!(
        decode_planner(&o.encode(3)),
        Ok(PlannerMessage::Obstacle(o, 3))
    );
    // The planner's frames are not vehicle inputs, and the vehicle's are not the planner's.
    for frame in [h.encode(1), p.encode(2), o.encode(3)] {
        assert_eq!(
            decode_input(&frame, spec::N2K_DEFAULT_SOURCE),
            Err(DecodeError::UnknownId)
        );
    }
    let steer = SteeringReport {
        steer_pct: Some(1.0),
    }
    .encode(0);
    assert_eq!(decode_planner(&steer), Err(DecodeError::UnknownId));
    let command = ControlCommand::default().encode(0);
    assert_eq!(decode_planner(&command), Err(DecodeError::UnknownId));
}

// ------------------------------------------------------------------------------------------
// Error kinds

/// Re-seals a frame whose payload was edited (so only the edited field is wrong).
fn reseal(mut frame: CanFrame) -> CanFrame {
    frame.data[7] = frame_crc(frame.id, &frame.data);
    frame
}

#[test]
fn decode_error_kinds() {
    let good = SteeringReport {
        steer_pct: Some(1.0),
    }
    .encode(1);
    // Wrong id.
    let mut f = good;
    f.id = CanId::Standard(0x101);
    assert_eq!(SteeringReport::decode(&f), Err(DecodeError::WrongId));
    f.id = CanId::Extended(0x100);
    assert_eq!(SteeringReport::decode(&f), Err(DecodeError::WrongId));
    // DLC.
    let mut f = good;
    f.len = 7;
    assert_eq!(
        SteeringReport::decode(&f),
        Err(DecodeError::Dlc {
            expected: 8,
            got: 7
        })
    );
    // CRC: every single-bit flip of bytes 0..=7 is caught.
    for bit in 0..64 {
        let mut f = good;
        f.data[bit / 8] ^= 1 << (bit % 8);
        assert!(
            matches!(SteeringReport::decode(&f), Err(DecodeError::Crc { .. })),
            "bit {bit}"
        );
    }
    // The CRC covers the id: the same payload under another id fails.
    let mut f = SpeedReport {
        speed_mps: Some(1.0),
        speed_cmd_mps: Some(1.0),
        direction: Direction::NotReported,
    }
    .encode(0);
    f.id = CanId::Standard(0x102);
    assert!(matches!(
        PedalReport::decode(&f),
        Err(DecodeError::Crc { .. })
    ));
    // Out of range: steer raw 10001 (100.01 %), with a valid CRC.
    let mut f = good;
    sig::STEER_PCT.write_raw(&mut f.data, 10_001);
    assert_eq!(
        SteeringReport::decode(&reseal(f)),
        Err(DecodeError::OutOfRange {
            signal: "steer_pct"
        })
    );
    // Invalid sentinel -> None for reports, Invalid for a position without latitude.
    let mut f = good;
    sig::STEER_PCT.write_raw(&mut f.data, -32_768);
    assert_eq!(
        SteeringReport::decode(&reseal(f)),
        Ok((SteeringReport { steer_pct: None }, 1))
    );
    let mut f = GnssPosition {
        lat_e7: 1,
        lon_e7: 2,
    }
    .encode(0x1C);
    sig::LONGITUDE_DEG.write_raw(&mut f.data, 0x7FFF_FFFF);
    assert_eq!(
        GnssPosition::decode(&f, 0x1C),
        Err(DecodeError::Invalid {
            signal: "longitude_deg"
        })
    );
    sig::LONGITUDE_DEG.write_raw(&mut f.data, 1_800_000_001);
    assert_eq!(
        GnssPosition::decode(&f, 0x1C),
        Err(DecodeError::OutOfRange {
            signal: "longitude_deg"
        })
    );
    // COG 0xFFFE (N2K "out of range") is out of range.
    let mut f = GnssCogSog {
        sid: 0,
        cog_reference: 0,
        cog_rad: Some(1.0),
        sog_mps: Some(1.0),
    }
    .encode(0x1C);
    sig::COG_RAD.write_raw(&mut f.data, 0xFFFE);
    assert_eq!(
        GnssCogSog::decode(&f, 0x1C),
        Err(DecodeError::OutOfRange { signal: "cog_rad" })
    );
    // NODE_STATUS page 6..15 does not exist.
    let mut f = NodeStatus::RxErrors {
        crc_errors: 0,
        counter_errors: 0,
        dlc_errors: 0,
    }
    .encode(0);
    sig::PAGE.write_raw(&mut f.data, 6);
    assert_eq!(
        NodeStatus::decode(&reseal(f)),
        Err(DecodeError::OutOfRange { signal: "page" })
    );
    // Prediction ids outside 0x310..=0x319.
    let mut f = Prediction {
        point: PredictionPoint::new(1).unwrap(),
        dx_m: None,
        dy_m: None,
        dheading_rad: None,
        speed_mps: None,
    }
    .encode(0);
    f.id = CanId::Standard(0x31A);
    assert_eq!(Prediction::decode(&f), Err(DecodeError::WrongId));
    f.id = CanId::Standard(0x30F);
    assert_eq!(Prediction::decode(&f), Err(DecodeError::WrongId));
    assert_eq!(PredictionPoint::new(0), None);
    assert_eq!(PredictionPoint::new(11), None);
}

#[test]
fn decode_input_dispatch() {
    let src = spec::N2K_DEFAULT_SOURCE;
    let s = SteeringReport {
        steer_pct: Some(-3.0),
    };
    assert_eq!(
        decode_input(&s.encode(2), src),
        Ok(InputMessage::Steering(s, 2))
    );
    let v = SpeedReport {
        speed_mps: Some(3.0),
        speed_cmd_mps: None,
        direction: Direction::Reverse,
    };
    assert_eq!(
        decode_input(&v.encode(3), src),
        Ok(InputMessage::Speed(v, 3))
    );
    let p = PedalReport {
        accel_pct: Some(50.0),
        brake_pct: Some(0.0),
    };
    assert_eq!(
        decode_input(&p.encode(4), src),
        Ok(InputMessage::Pedal(p, 4))
    );
    let g = GnssPosition {
        lat_e7: 322_316_000,
        lon_e7: -1_109_531_000,
    };
    assert_eq!(
        decode_input(&g.encode(src), src),
        Ok(InputMessage::GnssPosition(g))
    );
    assert_eq!(
        decode_input(&g.encode(0x22), src),
        Err(DecodeError::WrongSource { got: 0x22 })
    );
    let c = GnssCogSog {
        sid: 1,
        cog_reference: 0,
        cog_rad: Some(1.0),
        sog_mps: Some(2.0),
    };
    assert!(matches!(
        decode_input(&c.encode(src), src),
        Ok(InputMessage::GnssCogSog(_))
    ));
    // Our own outputs and strangers are not inputs.
    let out = StateMotion::default().encode(0);
    assert_eq!(decode_input(&out, src), Err(DecodeError::UnknownId));
    let stranger = CanFrame::new(CanId::Extended(spec::n2k_id(2, 127_250, src)), &[0; 8]).unwrap();
    assert_eq!(decode_input(&stranger, src), Err(DecodeError::UnknownId));
}

// ------------------------------------------------------------------------------------------
// Rolling counter

#[test]
fn counter_checker_sequence_stuck_jump_wrap_reset() {
    let mut c = CounterChecker::new();
    assert_eq!(c.check(14), CounterCheck::First);
    assert_eq!(c.check(15), CounterCheck::InSequence);
    assert_eq!(c.check(0), CounterCheck::InSequence); // wraps mod 16
    assert_eq!(c.check(0), CounterCheck::Stuck);
    assert!(!CounterCheck::Stuck.accepted());
    assert_eq!(c.check(0), CounterCheck::Stuck);
    assert_eq!(c.check(1), CounterCheck::InSequence); // stuck does not move the reference
    assert_eq!(c.check(4), CounterCheck::Jump { missed: 2 });
    assert!(
        CounterCheck::Jump { missed: 2 }.accepted() && CounterCheck::Jump { missed: 2 }.is_error()
    );
    assert_eq!(c.check(3), CounterCheck::Jump { missed: 14 }); // one step back = 14 lost
    assert_eq!(c.check(0x14), CounterCheck::InSequence); // only the low 4 bits count
    assert_eq!((c.stuck_count, c.jump_count, c.missed_frames), (2, 2, 16));
    c.reset();
    assert_eq!(c.check(9), CounterCheck::First);
    assert_eq!(c.stuck_count, 2);
    let mut c = CounterChecker::new();
    c.stuck_count = u32::MAX;
    c.check(1);
    c.check(1);
    assert_eq!(c.stuck_count, u32::MAX); // saturates
}

proptest! {
    #[test]
    fn counter_checker_accepts_every_in_sequence_stream(start in 0u8..16, n in 1usize..100) {
        let mut c = CounterChecker::new();
        for i in 0..n {
            let v = c.check(((start as usize + i) % 16) as u8);
            prop_assert!(v == CounterCheck::First || v == CounterCheck::InSequence);
        }
        prop_assert_eq!((c.stuck_count, c.jump_count), (0, 0));
    }
}

// ------------------------------------------------------------------------------------------
// Freshness

#[test]
fn freshness_timeouts_and_ages() {
    assert!(!is_timed_out(1_100_000, 1_000_000, 100_000)); // exactly the timeout: fresh
    assert!(is_timed_out(1_100_001, 1_000_000, 100_000));
    assert!(!is_timed_out(900_000, 1_000_000, 100_000)); // future sample: not timed out
    assert!(is_recent(1_050_000, 1_000_000, 100_000));
    assert_eq!(age_10ms(1_000_000, None), AGE_NEVER);
    assert_eq!(age_10ms(1_000_000, Some(1_000_000)), 0);
    assert_eq!(age_10ms(1_019_999, Some(1_000_000)), 1);
    assert_eq!(age_10ms(1_000_000 + 2_540_000, Some(1_000_000)), 254);
    assert_eq!(age_10ms(u64::MAX, Some(0)), AGE_MAX);

    let cfg = FreshnessConfig::default();
    assert_eq!(cfg.timeout_us(Input::Steer), 100_000);
    assert_eq!(cfg.timeout_us(Input::Gnss), 200_000);
    let mut f = Freshness::new();
    assert!(!f.is_fresh(&cfg, Input::Steer, 0));
    f.mark(Input::Steer, 1_000_000);
    f.mark(Input::Gnss, 1_000_000);
    f.mark(Input::Steer, 900_000); // older sample does not move the clock back
    assert_eq!(f.last_us(Input::Steer), Some(1_000_000));
    assert!(f.is_fresh(&cfg, Input::Steer, 1_100_000));
    assert!(!f.is_fresh(&cfg, Input::Steer, 1_100_001));
    assert!(f.is_fresh(&cfg, Input::Gnss, 1_150_000));
    assert_eq!(f.ages_10ms(1_150_000), [15, AGE_NEVER, AGE_NEVER, 15]);
}

// ------------------------------------------------------------------------------------------
// Bus load

#[test]
fn worst_case_frame_lengths_match_the_literature() {
    // Davis, Burns, Bril, Lukkien 2007, eq (5): 135 bits (11-bit, 8 bytes), 160 (29-bit, 8).
    assert_eq!(spec::worst_case_frame_bits(false, 8), 135);
    assert_eq!(spec::worst_case_frame_bits(true, 8), 160);
    assert_eq!(spec::nominal_frame_bits(false, 8), 111);
    assert_eq!(spec::worst_case_frame_bits(false, 0), 55);
}

#[test]
fn our_traffic_stays_under_20_percent_of_500_kbit() {
    let load = |pick: &dyn Fn(&MessageSpec) -> bool, worst: bool| -> f64 {
        spec::MESSAGES
            .iter()
            .filter(|m| pick(m))
            .map(|m| {
                let ext = matches!(m.id, CanId::Extended(_));
                let bits = if worst {
                    spec::worst_case_frame_bits(ext, m.dlc)
                } else {
                    spec::nominal_frame_bits(ext, m.dlc)
                };
                f64::from(bits) * 1000.0 / f64::from(m.cycle_ms)
            })
            .sum::<f64>()
            / 500_000.0
    };
    let ours = |m: &MessageSpec| m.transmitter == NODE_CATMODEL;
    // The planner's messages are events (cycle 0): see `a_full_path_transfer_at_the_paced_rate`.
    let all = |m: &MessageSpec| m.cycle_ms > 0;
    let (worst, nominal) = (load(&ours, true), load(&ours, false));
    println!(
        "node traffic: {:.2} % worst case, {:.2} % nominal; whole bus worst case {:.2} %",
        100.0 * worst,
        100.0 * nominal,
        100.0 * load(&all, true)
    );
    assert_eq!(spec::MESSAGES.iter().filter(|m| ours(m)).count(), 14);
    assert!(worst < 0.20, "worst-case node load {worst}");
    assert!((worst - 14.0 * 135.0 * 50.0 / 500_000.0).abs() < 1e-12);
    assert!(
        spec::MESSAGES
            .iter()
            .all(|m| m.cycle_ms > 0 || m.transmitter == spec::NODE_PLANNER),
        "only the planner's messages are event-driven"
    );
}

#[test]
fn a_full_path_transfer_at_the_paced_rate() {
    // A full path: PATH_HEADER, then PATH_POINT and PATH_LIMITS for each of the 256 points.
    let frames = 1 + 2 * spec::MAX_PATH_POINTS;
    let bits = |m: &MessageSpec| spec::worst_case_frame_bits(false, m.dlc);
    let path_bits = bits(&spec::PATH_HEADER) as usize
        + spec::MAX_PATH_POINTS * (bits(&spec::PATH_POINT) + bits(&spec::PATH_LIMITS)) as usize;
    assert_eq!((frames, path_bits), (513, 513 * 135));
    // Back to back it would hold the bus for 139 ms; paced at the simulated planner's rate
    // (catmodel_host::closed_loop::planner::PATH_FRAMES_PER_TICK per 20 ms) it takes ticks:
    let per_tick = catmodel_host::closed_loop::planner::PATH_FRAMES_PER_TICK;
    let ticks = frames.div_ceil(per_tick);
    let share = (per_tick * 135) as f64 / (0.020 * 500_000.0);
    println!(
        "256-point path: {frames} frames, {:.1} ms back to back; paced at {per_tick} frames per \
         20 ms: {:.2} s at {:.1} % of the bus",
        path_bits as f64 / 500.0,
        ticks as f64 * 0.020,
        100.0 * share
    );
    assert_eq!(ticks, 129);
    assert!(share < 0.06, "{share}");
    // The node's rule for a conforming planner: with the vehicle's inputs at their highest
    // rates (3 reports at 50 Hz, GNSS position and COG/SOG at 100 Hz: 7 a tick) it stays under
    // the frames one tick takes, so no backlog grows in the receive queue.
    assert_eq!(per_tick, catmodel::node::PLANNER_FRAMES_PER_TICK);
    assert!(7 + per_tick < catmodel::node::MAX_RX_FRAMES_PER_TICK);
}

// ------------------------------------------------------------------------------------------
// candump

#[test]
fn candump_formats_exactly() {
    let frame = TimedFrame {
        t_us: 1_700_000_000_123_456,
        frame: CanFrame::new(CanId::Standard(0x123), &[0xDE, 0xAD, 0xBE, 0xEF]).unwrap(),
    };
    let mut s = String::new();
    format_line(&frame, "can0", &mut s).unwrap();
    assert_eq!(s, "(1700000000.123456) can0 123#DEADBEEF");

    let frame = TimedFrame {
        t_us: 20_000,
        frame: CanFrame::new(CanId::Extended(0x09F8_011C), &[]).unwrap(),
    };
    let mut s = String::new();
    format_line(&frame, "vcan1", &mut s).unwrap();
    assert_eq!(s, "(0000000000.020000) vcan1 09F8011C#");

    let frame = TimedFrame {
        t_us: 5,
        frame: CanFrame::new(CanId::Standard(0x7), &[0x0A, 0xB0]).unwrap(),
    };
    let mut s = String::new();
    format_line(&frame, "can0", &mut s).unwrap();
    assert_eq!(s, "(0000000000.000005) can0 007#0AB0");
}

#[test]
fn candump_parses_valid_variants() {
    let f = parse_line("(1700000000.123456) can0 123#DEADBEEF\n").unwrap();
    assert_eq!(f.t_us, 1_700_000_000_123_456);
    assert_eq!(
        f.frame,
        CanFrame::new(CanId::Standard(0x123), &[0xDE, 0xAD, 0xBE, 0xEF]).unwrap()
    );
    // CRLF, lower-case hex, short seconds, empty payload, 8 bytes, extended id.
    let f = parse_line("(0.000001) can0 7ff#\r\n").unwrap();
    assert_eq!(
        (f.t_us, f.frame.id, f.frame.len),
        (1, CanId::Standard(0x7FF), 0)
    );
    let f = parse_line("(12.500000) slcan0 1FFFFFFF#0102030405060708").unwrap();
    assert_eq!(f.t_us, 12_500_000);
    assert_eq!(f.frame.id, CanId::Extended(0x1FFF_FFFF));
    assert_eq!(f.frame.payload(), &[1, 2, 3, 4, 5, 6, 7, 8]);
    let f = parse_line("(1.000000) can0 00000123#aB").unwrap();
    assert_eq!(
        (f.frame.id, f.frame.payload()),
        (CanId::Extended(0x123), &[0xAB][..])
    );
    // Largest timestamp that fits u64 microseconds.
    let f = parse_line("(18446744073709.551615) can0 000#").unwrap();
    assert_eq!(f.t_us, u64::MAX);
}

#[test]
fn candump_rejects_with_reasons() {
    use CandumpError::*;
    let cases: &[(&str, CandumpError)] = &[
        ("", Empty),
        ("   \n", Empty),
        ("1700000000.123456 can0 123#00", MissingTimestamp),
        ("can0 123#00", MissingTimestamp),
        ("(1700000000.123456 can0 123#00", BadTimestamp),
        ("() can0 123#00", BadTimestamp),
        ("(1700000000) can0 123#00", BadTimestamp),
        ("(1700000000.12345) can0 123#00", BadTimestamp),
        ("(1700000000.1234567) can0 123#00", BadTimestamp),
        ("(.123456) can0 123#00", BadTimestamp),
        ("(17000x0000.123456) can0 123#00", BadTimestamp),
        ("(-1.000000) can0 123#00", BadTimestamp),
        ("(1.-23456) can0 123#00", BadTimestamp),
        ("(18446744073709.551616) can0 123#00", BadTimestamp),
        ("(99999999999999999999.000000) can0 123#00", BadTimestamp),
        ("(1.000000)", MissingInterface),
        ("(1.000000)can0 123#00", MissingInterface),
        ("(1.000000) can0", MissingInterface),
        ("(1.000000)\tcan0 123#00", MissingInterface),
        ("(1.000000) averyveryverylongname 123#00", BadInterface),
        ("(1.000000) can0 12300", MissingSeparator),
        ("(1.000000) can0 #00", BadId),
        ("(1.000000) can0 12#00", BadId),
        ("(1.000000) can0 1234#00", BadId),
        ("(1.000000) can0 12G#00", BadId),
        ("(1.000000) can0 +12#00", BadId),
        ("(1.000000) can0 800#00", IdOutOfRange),
        ("(1.000000) can0 FFF#00", IdOutOfRange),
        ("(1.000000) can0 40000000#00", IdOutOfRange),
        ("(1.000000) can0 80000000#00", IdOutOfRange),
        // candump -e: CAN_ERR_FLAG with the error class (here a bus-off, 0x40).
        ("(1.000000) can0 20000040#0000000000000000", ErrorFrame),
        ("(1.000000) can0 20000000#00", ErrorFrame),
        ("(1.000000) can0 123#R", RemoteFrame),
        ("(1.000000) can0 123#R4", RemoteFrame),
        ("(1.000000) can0 123##100112233", FdFrame),
        ("(1.000000) can0 123#0", OddHex),
        ("(1.000000) can0 123#DEADBEE", OddHex),
        ("(1.000000) can0 123#DEADBEEG", BadHex),
        ("(1.000000) can0 123#DE.AD", BadHex),
        ("(1.000000) can0 123#010203040506070809", TooLong),
        ("(1.000000) can0 123#DEAD BEEF", TrailingGarbage),
        ("(1.000000) can0 123#DEAD X", TrailingGarbage),
        ("(1.000000) can0 123#DEAD r", TrailingGarbage),
        ("(1.000000) can0 123#DEAD R T", TrailingGarbage),
        ("(1.000000) can0 123#DEAD  R", TrailingGarbage),
        // candump -d: the socket's drop counter, not a frame.
        (
            "DROPCOUNT: dropped 3 CAN frames on 'can0' socket (total drops 3)",
            DropCount,
        ),
        // candump's screen format (`candump -ta`).
        ("(1.000000)  can0  123   [2]  DE", LengthMismatch),
        ("(1.000000)  can0  123   [1]  DE AD", TrailingGarbage),
        ("(1.000000)  can0  123   [1]  DEA", BadHex),
        ("(1.000000)  can0  123   [1]  ZZ", BadHex),
        ("(1.000000)  can0  123   [x]  00", BadHex),
        ("(1.000000)  can0  123   [0]  remote request", RemoteFrame),
        (
            "(1.000000)  can0  123  [12]  00 11 22 33 44 55 66 77 88 99 AA BB",
            FdFrame,
        ),
        (
            "(1.000000)  can0  20000080   [8]  00 00 00 00 00 00 00 00   ERRORFRAME",
            ErrorFrame,
        ),
        ("(1.000000)  can0  800   [1]  00", IdOutOfRange),
        // `-x` in the screen format: `RX` or `TX`, then two flag columns.
        ("(1.000000)  can0  RX -  123   [1]  00", MissingSeparator),
        ("(1.000000)  can0  RX x -  123   [1]  00", MissingSeparator),
        ("(1.000000)  can0  RX - -  123   [2]  00", LengthMismatch),
    ];
    for (line, want) in cases {
        assert_eq!(parse_line(line), Err(*want), "{line:?}");
        // Frames the node has no use for are skipped and counted by every reader; the rest
        // refuse the log.
        assert_eq!(
            want.is_unsupported_frame(),
            matches!(want, RemoteFrame | FdFrame | ErrorFrame),
            "{want:?}"
        );
    }
}

/// candump's screen format with a timestamp (`candump -ta`, what `candump -t a can0 > file`
/// records; spacing as can-utils prints it, and any other whitespace) reads as the log format's
/// line of the same frame.
#[test]
fn candump_screen_format_reads_as_the_log_format() {
    for (screen, log) in [
        (
            "(1700000000.123456)  can0  123   [4]  DE AD BE EF",
            "(1700000000.123456) can0 123#DEADBEEF",
        ),
        (
            "(0000000012.500000)  vcan0  09F80102   [8]  01 02 03 04 05 06 07 08",
            "(0000000012.500000) vcan0 09F80102#0102030405060708",
        ),
        ("(0.020000)\tcan1 7FF [0]", "(0.020000) can1 7FF#"),
        (
            "(0.020000)  can0  100   [2]  0a ff  \r",
            "(0.020000) can0 100#0AFF",
        ),
    ] {
        assert_eq!(parse_line(screen), parse_line(log), "{screen:?}");
        assert!(parse_line(screen).is_ok(), "{screen:?}");
    }
}

/// What can-utils' candump.c writes, line for line (its `printf`s quoted): each reads as the
/// plain log line of the same frame.
#[test]
fn candump_lines_as_can_utils_writes_them() {
    for (written, log) in [
        // Screen format: `printf(" %s", ...)` before the timestamp, `-ta` and `-tz`.
        (
            " (1700000000.003296)  can0  09F8011C   [8]  7F 32 36 13 F6 5B DE BD",
            "(1700000000.003296) can0 09F8011C#7F323613F65BDEBD",
        ),
        (
            " (014.945398)  can0       101   [2]  9B 00",
            "(014.945398) can0 101#9B00",
        ),
        // `-l` with names of different lengths: `%*s` right-aligns them.
        (
            "(0000000000.003296)  can0 100#ECFF",
            "(0000000000.003296) can0 100#ECFF",
        ),
        (
            "(0000000000.003296)     can0 100#ECFF",
            "(0000000000.003296) can0 100#ECFF",
        ),
        // `-l -x`: ` R` received, ` T` sent by this host.
        (
            "(1700000000.003745) can0 100#ECFF0000000000BB R",
            "(1700000000.003745) can0 100#ECFF0000000000BB",
        ),
        (
            "(1700000000.003745) can0 100#ECFF0000000000BB T\r\n",
            "(1700000000.003745) can0 100#ECFF0000000000BB",
        ),
        ("(1.000000) can0 123# R", "(1.000000) can0 123#"),
        // `-N`: nanoseconds (`%010llu.%09llu`), in the log and the screen format; candump
        // without `-N` writes `tv_nsec / 1000`, so the same frame reads the same either way.
        (
            "(1700000000.003296999) can0 09F8011C#7F323613F65BDEBD",
            "(1700000000.003296) can0 09F8011C#7F323613F65BDEBD",
        ),
        (
            " (1700000000.003296001)  can0  09F8011C   [8]  7F 32 36 13 F6 5B DE BD",
            "(1700000000.003296) can0 09F8011C#7F323613F65BDEBD",
        ),
        // `-t A`: the date (`strftime("%Y-%m-%d %H:%M:%S")`, local time, read as UTC), with
        // microseconds or, with `-N`, nanoseconds.
        (
            " (2023-11-14 22:13:20.003296)  can0  09F8011C   [8]  7F 32 36 13 F6 5B DE BD",
            "(1700000000.003296) can0 09F8011C#7F323613F65BDEBD",
        ),
        (
            " (2023-11-14 22:13:20.003296999)  can0       101   [2]  9B 00",
            "(1700000000.003296) can0 101#9B00",
        ),
        // `-x` in the screen format: `  RX` / `  TX` and the CAN FD flags (`- -` for a
        // classic frame) after the name.
        (
            " (1700000000.003296)  can0  RX - -  09F8011C   [8]  7F 32 36 13 F6 5B DE BD",
            "(1700000000.003296) can0 09F8011C#7F323613F65BDEBD",
        ),
        (
            " (2023-11-14 22:13:20.003296)  can0  TX - -       101   [2]  9B 00",
            "(1700000000.003296) can0 101#9B00",
        ),
    ] {
        assert_eq!(parse_line(written), parse_line(log), "{written:?}");
        assert!(parse_line(written).is_ok(), "{written:?}");
        assert_eq!(
            catmodel::can::candump::interface_of(written),
            Some("can0"),
            "{written:?}"
        );
    }
    // A remote frame stays a remote frame with `-x`.
    assert_eq!(
        parse_line("(1.000000) can0 123#R R"),
        Err(CandumpError::RemoteFrame)
    );
}

/// `candump -t A`'s dates against seconds since 1970 computed by Python
/// (`calendar.timegm(time.strptime(DATE, "%Y-%m-%d %H:%M:%S"))`), across the Gregorian
/// calendar's leap-year rules; every day from 1970 to 2400 one day after the one before; and
/// what is no date refused.
#[test]
fn candump_dates_are_seconds_since_1970() {
    let t_s = |date: &str| {
        parse_line(&format!("({date}.000000) can0 123#00")).map(|f| f.t_us / 1_000_000)
    };
    for (date, want) in [
        ("1970-01-01 00:00:00", 0),
        ("1972-02-29 12:00:00", 68_212_800),
        ("1999-12-31 23:59:59", 946_684_799),
        ("2000-02-29 00:00:00", 951_782_400),
        ("2000-03-01 00:00:00", 951_868_800),
        ("2023-11-14 22:13:20", 1_700_000_000),
        ("2024-12-31 23:59:59", 1_735_689_599),
        ("2038-01-19 03:14:08", 2_147_483_648),
        ("2100-02-28 00:00:00", 4_107_456_000),
        ("2100-03-01 00:00:00", 4_107_542_400),
        ("2400-02-29 00:00:00", 13_574_563_200),
        ("9999-12-31 23:59:59", 253_402_300_799),
    ] {
        assert_eq!(t_s(date), Ok(want), "{date}");
    }
    // Every date that parses is the day after the last one that did, and a year has 365 days
    // or, by the Gregorian rule, 366.
    let mut last = None;
    for year in 1970..=2400u64 {
        let mut days = 0;
        for month in 1..=12 {
            for day in 1..=31 {
                if let Ok(t) = t_s(&format!("{year}-{month:02}-{day:02} 00:00:00")) {
                    if let Some(last) = last {
                        assert_eq!(t, last + 86_400, "{year}-{month:02}-{day:02}");
                    }
                    last = Some(t);
                    days += 1;
                }
            }
        }
        let leap =
            year.is_multiple_of(4) && (!year.is_multiple_of(100) || year.is_multiple_of(400));
        assert_eq!(days, if leap { 366 } else { 365 }, "{year}");
    }
    // A leap second (`:60`, as a `right/` time zone writes it) is the next minute's first.
    assert_eq!(t_s("2016-12-31 23:59:60"), t_s("2017-01-01 00:00:00"));
    for date in [
        "1969-12-31 23:59:59",
        "2023-02-29 00:00:00",
        "1900-02-29 00:00:00",
        "2023-13-01 00:00:00",
        "2023-00-10 00:00:00",
        "2023-04-31 00:00:00",
        "2023-01-00 00:00:00",
        "2023-01-01 24:00:00",
        "2023-01-01 12:60:00",
        "2023-01-01 12:00:61",
        "23-01-01 12:00:00",
        "2023-1-01 12:00:00",
        "2023-01-01 12:00",
        "2023-01-01T12:00:00",
        "2023-01-01  12:00:00",
        "2023-01-01 12:00:00:00",
        "2023/01/01 12:00:00",
    ] {
        assert_eq!(t_s(date), Err(CandumpError::BadTimestamp), "{date}");
    }
    // Six or nine decimals, nothing between.
    for stamp in [
        "2023-11-14 22:13:20.12345",
        "2023-11-14 22:13:20.1234567",
        "1.12345678",
    ] {
        assert_eq!(
            parse_line(&format!("({stamp}) can0 123#00")),
            Err(CandumpError::BadTimestamp),
            "{stamp}"
        );
    }
}

/// `candump -d`: `DROPCOUNT: dropped %u CAN frame%s on '%s' socket (total drops %u)`.
#[test]
fn candump_dropcount_lines_give_their_count() {
    use catmodel::can::candump::dropped_frames;
    assert_eq!(
        dropped_frames("DROPCOUNT: dropped 3 CAN frames on 'can0' socket (total drops 3)"),
        Some(3)
    );
    assert_eq!(
        dropped_frames("DROPCOUNT: dropped 1 CAN frame on 'any' socket (total drops 17)\r"),
        Some(1)
    );
    for not in [
        "DROPCOUNT: dropped x CAN frames on 'can0' socket (total drops 3)",
        "DROPCOUNT: dropped 3 CAN frames on 'can0' socket",
        "DROPCOUNT: dropped 99999999999 CAN frames on 'can0' socket (total drops 3)",
        "(1.000000) can0 123#00",
    ] {
        assert_eq!(dropped_frames(not), None, "{not:?}");
    }
}

fn arb_frame() -> impl Strategy<Value = TimedFrame> {
    let id = prop_oneof![
        (0u16..=0x7FF).prop_map(CanId::Standard),
        (0u32..=0x1FFF_FFFF).prop_map(CanId::Extended),
    ];
    (
        any::<u64>(),
        id,
        proptest::collection::vec(any::<u8>(), 0..=8),
    )
        .prop_map(|(t_us, id, data)| TimedFrame {
            t_us,
            frame: CanFrame::new(id, &data).unwrap(),
        })
}

proptest! {
    #[test]
    fn candump_parse_of_format_is_identity(frame in arb_frame(), iface in "[a-z][a-z0-9_]{0,14}") {
        let mut line = String::new();
        format_line(&frame, &iface, &mut line).unwrap();
        prop_assert_eq!(parse_line(&line), Ok(frame));
        // And the canonical text survives a second round.
        let mut again = String::new();
        format_line(&parse_line(&line).unwrap(), &iface, &mut again).unwrap();
        prop_assert_eq!(again, line);
    }

    #[test]
    fn candump_parse_never_panics(line in "\\PC{0,60}") {
        let _ = parse_line(&line);
    }
}

proptest! {
    /// No decoder panics on any frame, whatever its id, DLC (even > 8) or bytes; a decoded
    /// message re-encodes to a frame that decodes to the same message and counter.
    #[test]
    fn decoders_never_panic_on_arbitrary_frames(
        std_id in 0u16..=0x7FF, ext_id in 0u32..=0x1FFF_FFFF, use_ext in any::<bool>(),
        len in 0u8..=15, data in any::<[u8; 8]>(), near in 0u16..0x10,
    ) {
        let ids = [
            if use_ext { CanId::Extended(ext_id) } else { CanId::Standard(std_id) },
            CanId::Standard(0x100 + near % 3),
            CanId::Standard(0x300 + near % 2),
            CanId::Standard(0x200 + near % 5),
            CanId::Standard(0x320),
            CanId::Standard(0x310 + near),
            CanId::Standard(0x3F0),
            CanId::Extended(spec::n2k_id(2, 129_025 + u32::from(near % 2), 0x1C)),
        ];
        for id in ids {
            let frame = CanFrame { id, len, data };
            let _ = decode_input(&frame, 0x1C);
            let _ = GnssPosition::decode(&frame, 0x1C);
            let _ = GnssCogSog::decode(&frame, 0x1C);
            if let Ok((m, c)) = StatePosition::decode(&frame) { let _ = m.encode(c); }
            if let Ok((m, c)) = StateMotion::decode(&frame) { let _ = m.encode(c); }
            if let Ok((m, c)) = ControlCommand::decode(&frame) { let _ = m.encode(c); }
            if let Ok(m) = decode_planner(&frame) {
                // Every planner message that decodes re-encodes to a frame that decodes to it.
                let again = match m {
                    PlannerMessage::PathHeader(m, c) => m.encode(c),
                    PlannerMessage::PathPoint(m, c) => m.encode(c),
                    PlannerMessage::PathLimits(m, c) => m.encode(c),
                    PlannerMessage::Obstacle(m, c) => m.encode(c),
                    PlannerMessage::LocalOrigin(m, c) => m.encode(c),
                };
                prop_assert_eq!(decode_planner(&again), Ok(m));
            }
            if let Ok((m, c)) = NodeStatus::decode(&frame) { let _ = m.encode(c); }
            if let Ok((m, c)) = Prediction::decode(&frame) { let _ = m.encode(c); }
            if let Ok((m, c)) = SteeringReport::decode(&frame) {
                // Only the signal bits, counter and CRC are defined; reserved bits re-encode as 0.
                let again = m.encode(c);
                prop_assert_eq!(SteeringReport::decode(&again), Ok((m, c)));
            }
        }
    }
}

/// The screen format's length field as can-utils' lib.c writes it: `[%d]` classic, `[%02d]`
/// CAN FD (skipped, as `##` is), `candump -8`'s `{%X}` raw DLC (9..F: 8 bytes), and `-a`'s
/// ASCII column after the data; `-e`'s explanation lines start with a tab.
#[test]
fn candump_screen_lengths_raw_dlcs_and_ascii() {
    use catmodel::can::candump::{is_error_detail, parse_line_and_dlc};
    let classic = parse_line("(1.000000)  can0  100   [2]  0A FF").unwrap();
    assert_eq!(classic, parse_line("(1.000000) can0 100#0AFF").unwrap());
    for fd in [
        "(1.000000)  can0  100  [02]  0A FF",
        "(1.000000)  can0  100  [08]  01 02 03 04 05 06 07 08",
        "(1.000000)  can0  100  [12]  01 02 03 04 05 06 07 08 09 0A 0B 0C",
        "(1.000000)  can0  RX B -  100  [00]",
    ] {
        assert_eq!(parse_line(fd), Err(CandumpError::FdFrame), "{fd}");
    }
    let (f, dlc) = parse_line_and_dlc("(1.000000)  can0  100   {2}  0A FF").unwrap();
    assert_eq!((f, dlc), (classic, None));
    let (f, dlc) =
        parse_line_and_dlc("(1.000000)  can0  100   {B}  01 02 03 04 05 06 07 08").unwrap();
    assert_eq!(dlc, Some(11));
    assert_eq!(f.frame.len, 8);
    for bad in ["{}", "{10}", "{G}"] {
        let line = format!("(1.000000)  can0  100   {bad}  0A FF");
        assert_eq!(parse_line(&line), Err(CandumpError::BadRawDlc), "{line}");
    }
    for ascii in [
        "(1.000000)  can0  100   [2]  0A FF   '..'",
        "(1.000000)  can0  100   [2]  20 41   ' A'",
        "(1.000000)  can0  100   [2]  41 20   'A '",
    ] {
        assert_eq!(
            parse_line(ascii).map(|f| f.frame.id),
            Ok(classic.frame.id),
            "{ascii}"
        );
    }
    for bad in [
        "(1.000000)  can0  100   [2]  0A FF   '..",
        "(1.000000)  can0  100   [2]  0A FF   '",
        "(1.000000)  can0  100   [2]  0A FF   x",
    ] {
        assert_eq!(parse_line(bad), Err(CandumpError::TrailingGarbage), "{bad}");
    }
    assert!(is_error_detail("\tbus-error"));
    assert!(is_error_detail(
        "\tcontroller-problem{rx-error-warning}\r\n"
    ));
    for not in [
        "",
        "\t",
        "bus-error",
        "\t(1.000000) can0 100#00",
        " (1.000000)  can0  100   [0]",
    ] {
        assert!(!is_error_detail(not), "{not:?}");
    }
}
