//! `catmodel.dbc` is the single source of truth: read it with the project's DBC reader
//! (`catmodel_host::dbc`, the one `catmodel decode` uses) and compare every message and every
//! signal with the Rust descriptor table (`catmodel::can::spec`), which all typed codecs go
//! through. Then check the table's own invariants (no overlapping signals, every signal inside
//! its DLC) and round-trip every signal at its raw limits and its sentinel through the generic
//! bit packer.
use std::collections::{BTreeMap, BTreeSet};

use catmodel::can::spec::{self, Integrity, MessageSpec, Mux, SignalSpec};
use catmodel::can::CanId;
use catmodel_host::dbc::{ByteOrder, Dbc, Multiplex};
use catmodel_host_tests::isclose;

/// Relative tolerance for scale / offset / limits: the table stores scale as f32, the DBC as
/// decimal text; f32 has a relative resolution of 6e-8.
const RTOL: f64 = 1e-6;
const ATOL: f64 = 1e-12;

/// `catmodel.dbc` as it is on disk (the reader's built-in copy is the same file).
fn load_dbc() -> Dbc {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../catmodel.dbc");
    let text = std::fs::read_to_string(&path).expect("reading catmodel.dbc");
    let dbc = Dbc::parse(&text).unwrap_or_else(|e| panic!("catmodel.dbc: {e}"));
    assert_eq!(Dbc::catmodel().unwrap(), dbc, "the built-in copy is stale");
    dbc
}

fn by_id() -> BTreeMap<CanId, &'static MessageSpec> {
    spec::MESSAGES.iter().map(|m| (m.id, *m)).collect()
}

#[test]
fn the_same_messages_in_both() {
    let dbc = load_dbc();
    let dbc_ids: BTreeSet<CanId> = dbc.messages.iter().map(|m| m.id).collect();
    let rust_ids: BTreeSet<CanId> = by_id().keys().copied().collect();
    assert_eq!(
        dbc.messages.len(),
        dbc_ids.len(),
        "duplicate ids in the DBC"
    );
    assert_eq!(
        spec::MESSAGES.len(),
        rust_ids.len(),
        "duplicate ids in the table"
    );
    assert_eq!(dbc_ids, rust_ids);
    assert_eq!(dbc.messages.len(), 24);
}

#[test]
fn every_message_agrees() {
    let dbc = load_dbc();
    let table = by_id();
    for m in &dbc.messages {
        let r = table[&m.id];
        let what = &m.name;
        assert_eq!(m.name, r.name);
        assert_eq!(m.dlc, r.dlc, "{what}: DLC");
        assert_eq!(m.transmitter, r.transmitter, "{what}: transmitter");
        assert_eq!(
            m.cycle_ms,
            Some(u64::from(r.cycle_ms)),
            "{what}: cycle time"
        );
        let dbc_names: BTreeSet<&str> = m.signals.iter().map(|s| s.name.as_str()).collect();
        let rust_names: BTreeSet<&str> = r.signals.iter().map(|s| s.name).collect();
        assert_eq!(dbc_names, rust_names, "{what}: signal names");
        assert_eq!(
            m.signals.len(),
            r.signals.len(),
            "{what}: duplicate signal names"
        );
    }
}

#[test]
fn every_signal_agrees() {
    let dbc = load_dbc();
    let table = by_id();
    let mut checked = 0;
    for m in &dbc.messages {
        let r = table[&m.id];
        for s in &m.signals {
            let rs = r.signal(&s.name).unwrap();
            let what = format!("{}.{}", m.name, s.name);
            assert_eq!(s.start_bit, u16::from(rs.start_bit), "{what}: start bit");
            assert_eq!(s.len_bits, u16::from(rs.len_bits), "{what}: length");
            assert_eq!(s.byte_order, ByteOrder::LittleEndian, "{what}: byte order");
            assert_eq!(s.signed, rs.signed, "{what}: signedness");
            assert!(
                isclose(f64::from(rs.scale), s.factor, RTOL, ATOL),
                "{what}: scale {} vs {}",
                rs.scale,
                s.factor
            );
            assert!(
                isclose(f64::from(rs.offset), s.offset, RTOL, ATOL),
                "{what}: offset"
            );
            let min = rs.raw_min as f64 * s.factor + s.offset;
            let max = rs.raw_max as f64 * s.factor + s.offset;
            assert!(
                isclose(min, s.min, RTOL, ATOL),
                "{what}: min {min} vs {}",
                s.min
            );
            assert!(
                isclose(max, s.max, RTOL, ATOL),
                "{what}: max {max} vs {}",
                s.max
            );
            assert_eq!(s.unit, rs.unit, "{what}: unit");
            assert_eq!(s.receivers, r.receivers, "{what}: receivers");
            let mux = match s.multiplex {
                Multiplex::Plain => Mux::Plain,
                Multiplex::Switch => Mux::Switch,
                Multiplex::Page(p) => Mux::Page(u8::try_from(p).unwrap()),
            };
            assert_eq!(mux, rs.mux, "{what}: multiplexing");
            checked += 1;
        }
    }
    let total: usize = spec::MESSAGES.iter().map(|m| m.signals.len()).sum();
    assert_eq!(checked, total);
    println!("{checked} signals in {} messages agree", dbc.messages.len());
}

#[test]
fn sentinels_and_value_tables_agree() {
    let dbc = load_dbc();
    let table = by_id();
    // Every "not_available" VAL_ entry is the table's sentinel, and vice versa.
    let mut from_dbc = BTreeSet::new();
    for m in &dbc.messages {
        for s in &m.signals {
            let r = table[&m.id].signal(&s.name).unwrap();
            for (raw, description) in &s.values {
                if description == "not_available" {
                    from_dbc.insert((m.id, s.name.clone(), *raw));
                } else {
                    assert!(r.in_range(*raw), "{}: value {raw} outside range", s.name);
                }
            }
        }
    }
    let from_rust: BTreeSet<(CanId, String, i64)> = spec::MESSAGES
        .iter()
        .flat_map(|m| {
            m.signals
                .iter()
                .filter_map(|s| s.not_available_raw.map(|na| (m.id, s.name.to_string(), na)))
        })
        .collect();
    assert_eq!(from_dbc, from_rust);
    assert!(from_rust.len() >= 40, "{}", from_rust.len());
}

#[test]
fn bus_level_attributes() {
    let dbc = load_dbc();
    assert_eq!(dbc.baudrate, Some(500_000));
    let nodes: BTreeSet<&str> = dbc.nodes.iter().map(String::as_str).collect();
    let expected: BTreeSet<&str> = [
        spec::NODE_CATMODEL,
        spec::NODE_DBW,
        spec::NODE_GNSS,
        spec::NODE_PLANNER,
    ]
    .into();
    assert_eq!(nodes, expected);
    // The NMEA 2000 identifiers decode to their PGNs and the default source.
    for (m, pgn) in [
        (&spec::GNSS_POSITION_RAPID, spec::PGN_POSITION_RAPID),
        (&spec::GNSS_COG_SOG_RAPID, spec::PGN_COG_SOG_RAPID),
    ] {
        let CanId::Extended(id) = m.id else {
            panic!("{}: not extended", m.name)
        };
        assert_eq!(spec::n2k_pgn_source(id), (pgn, spec::N2K_DEFAULT_SOURCE));
        assert_eq!(id >> 26, 2, "priority");
        assert_eq!(dbc.message(m.name).and_then(|d| d.pgn()), Some(pgn));
    }
}

// ------------------------------------------------------------------------------------------
// The table's own invariants

/// Bit mask of a signal within the 64-bit payload.
fn bits(s: &SignalSpec) -> u64 {
    (((1u128 << s.len_bits) - 1) << s.start_bit) as u64
}

#[test]
fn signals_fit_and_never_overlap() {
    for m in spec::MESSAGES {
        let pages: Vec<Option<u8>> = {
            let mut p: Vec<Option<u8>> = m
                .signals
                .iter()
                .filter_map(|s| {
                    if let Mux::Page(p) = s.mux {
                        Some(Some(p))
                    } else {
                        None
                    }
                })
                .collect();
            p.sort();
            p.dedup();
            if p.is_empty() {
                vec![None]
            } else {
                p
            }
        };
        for page in pages {
            let mut used = 0u64;
            for s in m.signals.iter().filter(|s| match s.mux {
                Mux::Page(p) => Some(p) == page,
                _ => true,
            }) {
                assert!(s.len_bits >= 1 && s.len_bits <= 32, "{}.{}", m.name, s.name);
                assert!(
                    u32::from(s.start_bit) + u32::from(s.len_bits) <= u32::from(m.dlc) * 8,
                    "{}.{} beyond DLC",
                    m.name,
                    s.name
                );
                assert_eq!(
                    used & bits(s),
                    0,
                    "{}.{} overlaps (page {page:?})",
                    m.name,
                    s.name
                );
                used |= bits(s);
                // Limits inside the width, sentinel inside the width and outside the limits.
                let (lo, hi) = if s.signed {
                    (-(1i64 << (s.len_bits - 1)), (1i64 << (s.len_bits - 1)) - 1)
                } else {
                    (0, (1i64 << s.len_bits) - 1)
                };
                assert!(
                    lo <= s.raw_min && s.raw_min <= s.raw_max && s.raw_max <= hi,
                    "{}.{}",
                    m.name,
                    s.name
                );
                if let Some(na) = s.not_available_raw {
                    assert!(
                        lo <= na && na <= hi && !s.in_range(na),
                        "{}.{} sentinel",
                        m.name,
                        s.name
                    );
                }
            }
        }
        // Protected messages: counter as declared, CRC in byte 7, our ids 11-bit.
        if let Integrity::CounterCrc(counter) = m.integrity {
            assert_eq!(m.signal("counter"), Some(&counter), "{}", m.name);
            assert_eq!(
                m.signal("crc").map(|s| (s.start_bit, s.len_bits)),
                Some((56, 8)),
                "{}",
                m.name
            );
            assert_eq!(counter.len_bits, 4);
            assert!(matches!(m.id, CanId::Standard(_)), "{}", m.name);
        }
    }
}

#[test]
fn every_signal_round_trips_at_its_limits_without_touching_the_others() {
    let mut cases = 0;
    for m in spec::MESSAGES {
        for s in m.signals {
            let mut values = vec![s.raw_min, s.raw_max, (s.raw_min + s.raw_max) / 2];
            values.extend(s.not_available_raw);
            for background in [
                [0u8; 8],
                [0xFF; 8],
                [0xA5, 0x5A, 0x3C, 0xC3, 0x0F, 0xF0, 0x99, 0x66],
            ] {
                for &v in &values {
                    let mut data = background;
                    s.write_raw(&mut data, v);
                    assert_eq!(s.read_raw(&data), v, "{}.{} = {v}", m.name, s.name);
                    let changed = u64::from_le_bytes(data) ^ u64::from_le_bytes(background);
                    assert_eq!(
                        changed & !bits(s),
                        0,
                        "{}.{} wrote outside its bits",
                        m.name,
                        s.name
                    );
                    if s.in_range(v) && s.scale != 1.0 {
                        let phys = s.to_physical(v);
                        assert_eq!(
                            s.to_raw(phys),
                            Some(v),
                            "{}.{} physical round trip",
                            m.name,
                            s.name
                        );
                    }
                    cases += 1;
                }
            }
        }
    }
    println!("{cases} raw round trips");
}

/// Encoding is the exact inverse of decoding for every raw value of every scaled signal:
/// a stride through the whole range plus every value of the top 2^16 of each 24-bit range,
/// where f32 carries less than one raw step of slack (found by the `decoders` fuzz target).
#[test]
fn physical_round_trip_is_exact_over_the_whole_range() {
    let mut cases = 0u64;
    for m in spec::MESSAGES {
        // 32-bit signals (NMEA 2000 lat/lon) are carried as integers, never as f32.
        for s in m
            .signals
            .iter()
            .filter(|s| s.scale != 1.0 && s.raw_max - s.raw_min <= 1 << 24)
        {
            let span = s.raw_max - s.raw_min;
            let stride = (span / 100_000).max(1);
            let dense = (s.raw_max - 65_536).max(s.raw_min)..=s.raw_max;
            let low = s.raw_min..=(s.raw_min + 65_536).min(s.raw_max);
            for raw in (s.raw_min..=s.raw_max)
                .step_by(stride as usize)
                .chain(dense)
                .chain(low)
            {
                let phys = s.to_physical(raw);
                assert_eq!(s.to_raw(phys), Some(raw), "{}.{} raw {raw}", m.name, s.name);
                cases += 1;
            }
        }
    }
    assert!(cases > 1_000_000, "{cases}");
}
