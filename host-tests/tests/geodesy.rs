//! `catmodel::geodesy` against pymap3d (`reference/gen_signal.py`): the node's f32 expansion
//! over a 2 km x 2 km grid around Tucson and rings to 19.5 km, the exact f64 functions on
//! random points with heights.
use catmodel::geodesy::{
    ecef_to_geodetic, enu_to_geodetic, geodetic_to_ecef, geodetic_to_enu, Enu, EnuExact,
    GeodesyError, Geodetic, LocalFrame,
};
use catmodel_host_tests::load_reference;

#[test]
fn to_local_matches_pymap3d() {
    let r = load_reference("geodesy_local.json");
    let frame = LocalFrame::new(
        r["origin_lat_e7"].as_i64().unwrap() as i32,
        r["origin_lon_e7"].as_i64().unwrap() as i32,
    )
    .unwrap();
    // Worst horizontal error per tag (the 2 km x 2 km grid, then rings at 2, 5, 10, 19.5 km).
    let mut worst: Vec<(String, f64)> = Vec::new();
    for p in r["points"].as_array().unwrap() {
        let lat_e7 = p["lat_e7"].as_i64().unwrap() as i32;
        let lon_e7 = p["lon_e7"].as_i64().unwrap() as i32;
        let tag = p["tag"].as_str().unwrap().to_string();
        let enu = frame.to_local(lat_e7, lon_e7).unwrap();
        let de = enu.east_m as f64 - p["east_m"].as_f64().unwrap();
        let dn = enu.north_m as f64 - p["north_m"].as_f64().unwrap();
        let err = de.hypot(dn);
        match worst.iter_mut().find(|(t, _)| *t == tag) {
            Some((_, w)) => *w = w.max(err),
            None => worst.push((tag, err)),
        }
        // from_local inverts to_local to f32 rounding of the coordinates.
        let (lat, lon) = frame.from_local(enu);
        let back = geodetic_to_enu(
            lat_e7 as f64 / 1e7,
            lon_e7 as f64 / 1e7,
            0.0,
            &Geodetic {
                lat_deg: lat,
                lon_deg: lon,
                height_m: 0.0,
            },
        );
        let round_trip_m = back.east_m.hypot(back.north_m);
        assert!(
            round_trip_m < 2e-3,
            "round trip {round_trip_m} m at {lat_e7},{lon_e7}"
        );
    }
    println!("to_local worst error vs pymap3d: {worst:?}");
    let bound = |tag: &str| match tag {
        // The node needs 1 cm; within 2 km the expansion plus f32 rounding stay below 1 mm
        // (measured 0.10 mm on the grid, 0.19 mm at 2 km). Beyond, the third-order terms
        // grow as distance^3 (measured 1.0 mm at 5 km, 7.3 mm at 10 km, 5.4 cm at 19.5 km).
        "grid" | "ring2000" => 1e-3,
        "ring5000" => 2e-3,
        "ring10000" => 1.5e-2,
        "ring19500" => 0.1,
        other => panic!("unknown tag {other}"),
    };
    assert_eq!(worst.len(), 5);
    for (tag, w) in &worst {
        assert!(*w < bound(tag), "{tag}: worst {w} m");
    }
}

#[test]
fn to_local_rejections() {
    let frame = LocalFrame::new(322_319_000, -1_109_501_000).unwrap();
    assert_eq!(
        frame.to_local(0x7FFF_FFFF, -1_109_501_000),
        Err(GeodesyError::NotAvailable)
    );
    assert_eq!(
        frame.to_local(322_319_000, 0x7FFF_FFFF),
        Err(GeodesyError::NotAvailable)
    );
    assert_eq!(
        frame.to_local(-900_000_001, 0),
        Err(GeodesyError::LatitudeOutOfRange)
    );
    assert_eq!(
        frame.to_local(0, 1_800_000_001),
        Err(GeodesyError::LongitudeOutOfRange)
    );
    // 21 km east (0.2228 deg at 32.23 N is ~20.99 km): just beyond the radius.
    assert_eq!(
        frame.to_local(322_319_000, -1_109_501_000 + 2_230_000),
        Err(GeodesyError::BeyondValidityRadius)
    );
    // 19 km north is accepted.
    assert!(frame
        .to_local(322_319_000 + 1_713_000, -1_109_501_000)
        .is_ok());
    // Far away (other hemisphere) is rejected, not wrapped into range.
    assert_eq!(
        frame.to_local(-322_319_000, 691_000_000),
        Err(GeodesyError::BeyondValidityRadius)
    );
    assert_eq!(
        LocalFrame::new(0x7FFF_FFFF, 0),
        Err(GeodesyError::NotAvailable)
    );
    assert_eq!(
        LocalFrame::new(-810_000_000, 0),
        Err(GeodesyError::OriginTooCloseToPole)
    );
    assert_eq!(frame.from_local(Enu::default()), (32.2319, -110.9501));
}

#[test]
fn exact_functions_match_pymap3d() {
    let r = load_reference("geodesy_exact.json");
    let o = &r["origin"];
    let origin = Geodetic {
        lat_deg: o["lat_deg"].as_f64().unwrap(),
        lon_deg: o["lon_deg"].as_f64().unwrap(),
        height_m: o["h_m"].as_f64().unwrap(),
    };
    let mut worst_ecef: f64 = 0.0;
    let mut worst_enu: f64 = 0.0;
    for p in r["points"].as_array().unwrap() {
        let (lat, lon, h) = (
            p["lat_deg"].as_f64().unwrap(),
            p["lon_deg"].as_f64().unwrap(),
            p["h_m"].as_f64().unwrap(),
        );
        let ecef: Vec<f64> = p["ecef"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let enu_ref: Vec<f64> = p["enu"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let e = geodetic_to_ecef(lat, lon, h);
        let d = [e.x_m - ecef[0], e.y_m - ecef[1], e.z_m - ecef[2]];
        worst_ecef = worst_ecef.max(d.iter().map(|v| v.abs()).fold(0.0, f64::max));
        let enu = geodetic_to_enu(lat, lon, h, &origin);
        let d = [
            enu.east_m - enu_ref[0],
            enu.north_m - enu_ref[1],
            enu.up_m - enu_ref[2],
        ];
        worst_enu = worst_enu.max(d.iter().map(|v| v.abs()).fold(0.0, f64::max));

        // Round trips: ECEF -> geodetic, ENU -> geodetic.
        let g = ecef_to_geodetic(e);
        let back = geodetic_to_ecef(g.lat_deg, g.lon_deg, g.height_m);
        let rt = (back.x_m - e.x_m)
            .hypot(back.y_m - e.y_m)
            .hypot(back.z_m - e.z_m);
        assert!(rt < 1e-6, "ecef round trip {rt} m at {lat},{lon},{h}");
        assert!(
            (g.height_m - h).abs() < 1e-6,
            "height {} vs {h}",
            g.height_m
        );
        let g2 = enu_to_geodetic(
            &EnuExact {
                east_m: enu_ref[0],
                north_m: enu_ref[1],
                up_m: enu_ref[2],
            },
            &origin,
        );
        let again = geodetic_to_enu(g2.lat_deg, g2.lon_deg, g2.height_m, &origin);
        let rt = (again.east_m - enu_ref[0])
            .hypot(again.north_m - enu_ref[1])
            .hypot(again.up_m - enu_ref[2]);
        // ~1e-9 relative of distances up to 1.3e7 m for the far-away points.
        assert!(rt < 1e-3, "enu round trip {rt} m at {lat},{lon},{h}");
        if (lat - origin.lat_deg).abs() < 0.1 {
            assert!((g2.lat_deg - lat).abs() < 1e-11 && (g2.lon_deg - lon).abs() < 1e-11);
            assert!((g2.height_m - h).abs() < 1e-6);
        }
    }
    println!("worst |ECEF - pymap3d| {worst_ecef} m, worst |ENU - pymap3d| {worst_enu} m");
    assert!(worst_ecef < 1e-6, "{worst_ecef}");
    // The brief asks < 1 mm; measured 3e-9 m (both are the same closed forms in f64).
    assert!(worst_enu < 1e-6, "{worst_enu}");
}
