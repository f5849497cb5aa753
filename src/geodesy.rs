//! WGS-84 latitude/longitude <-> local east/north metres.
//!
//! Two tiers:
//! - [`LocalFrame`], for the node: built once from the origin fix (f64 precomputation), then
//!   [`LocalFrame::to_local`] turns each NMEA 2000 fix (PGN 129025, 1e-7 deg integers) into
//!   east/north metres with a handful of `f32` operations on the integer differences. It is the
//!   second-order Taylor expansion, about the origin, of the exact tangent-plane (ENU) east and
//!   north of a point on the ellipsoid (height 0). Error against the exact ENU (pymap3d
//!   `geodetic2enu`, `host-tests/tests/geodesy.rs`, origin Tucson 32.2319 N 110.9501 W),
//!   expansion and `f32` rounding together: 0.10 mm worst on a 2 km x 2 km grid, 0.19 mm at
//!   2 km, 1.0 mm at 5 km, 7.3 mm at 10 km, 5.4 cm at 19.5 km (the third-order terms grow as
//!   distance^3, and with the latitude: at 20 km 0.15 m at 60 deg, 1.4 m at 80 deg, against
//!   this crate's exact f64 `geodetic_to_enu`). Fixes beyond [`VALIDITY_RADIUS_M`] are
//!   rejected (the node moves a frame of its own choosing with the car, `node::gnss`).
//! - Exact `f64` conversions for the host: [`geodetic_to_ecef`], [`ecef_to_geodetic`],
//!   [`geodetic_to_enu`], [`enu_to_geodetic`] (sub-micrometre round trips).
//!
//! Expansion used (phi latitude, lambda longitude, d = difference from the origin, in rad;
//! N prime-vertical and M meridian radius of curvature at the origin, M' = dM/dphi):
//! east  = N cos(phi0) dlambda - M sin(phi0) dphi dlambda
//! north = M dphi + M'/2 dphi^2 + N sin(phi0) cos(phi0) dlambda^2 / 2
//! (from d(N cos phi)/dphi = -M sin phi and d(N (1-e^2) sin phi)/dphi = M cos phi).

/// WGS-84 semi-major axis, m.
pub const WGS84_A_M: f64 = 6_378_137.0;
/// WGS-84 flattening.
pub const WGS84_F: f64 = 1.0 / 298.257_223_563;
/// WGS-84 first eccentricity squared, e^2 = f (2 - f).
pub const WGS84_E2: f64 = WGS84_F * (2.0 - WGS84_F);

/// [`LocalFrame::to_local`] rejects fixes farther than this from the origin, m: at 20 km the
/// expansion's error is about 6 cm at mid latitudes (0.15 m at 60 deg).
pub const VALIDITY_RADIUS_M: f32 = 20_000.0;
/// Origins closer to a pole than this latitude are refused: the expansion in longitude
/// differences degrades where meridians converge. Degrees.
pub const MAX_ORIGIN_LAT_DEG: f64 = 80.0;
/// NMEA 2000 "data not available" for a signed 32-bit field.
pub const NMEA2000_I32_NOT_AVAILABLE: i32 = i32::MAX;

const E7_PER_DEG: f64 = 1.0e7;
const RAD_PER_E7: f64 = core::f64::consts::PI / 180.0 / E7_PER_DEG;
/// Integer differences beyond 2^24 (1.68 deg) are not exact in `f32`; they lie beyond the
/// validity radius anyway for origins within [`MAX_ORIGIN_LAT_DEG`] (20 km is at most 1.04 deg
/// of longitude at 80 deg).
const MAX_EXACT_DIFF_E7: i64 = 1 << 24;

/// Why a position was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum GeodesyError {
    /// Latitude or longitude is the NMEA 2000 "not available" value 0x7FFFFFFF.
    NotAvailable,
    /// |latitude| > 90 deg.
    LatitudeOutOfRange,
    /// |longitude| > 180 deg.
    LongitudeOutOfRange,
    /// The origin is closer to a pole than [`MAX_ORIGIN_LAT_DEG`].
    OriginTooCloseToPole,
    /// The fix is farther than [`VALIDITY_RADIUS_M`] from the origin.
    BeyondValidityRadius,
}

/// Local horizontal position, metres east and north of the frame's origin (node, f32).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Enu {
    /// Metres east of the origin.
    pub east_m: f32,
    /// Metres north of the origin.
    pub north_m: f32,
}

/// A local tangent-plane frame at an origin fix, for converting fixes on the node.
/// Configuration: immutable once built.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LocalFrame {
    origin_lat_e7: i32,
    origin_lon_e7: i32,
    /// m per 1e-7 deg of longitude: N cos(phi0) k.
    east_per_dlon: f32,
    /// m per (1e-7 deg)^2 of dlat dlon: -M sin(phi0) k^2.
    east_per_dlat_dlon: f32,
    /// m per 1e-7 deg of latitude: M k.
    north_per_dlat: f32,
    /// m per (1e-7 deg)^2 of dlat^2: M'/2 k^2.
    north_per_dlat2: f32,
    /// m per (1e-7 deg)^2 of dlon^2: N sin(phi0) cos(phi0)/2 k^2.
    north_per_dlon2: f32,
}

/// The expansion's coefficients (k = rad per 1e-7 deg):
/// [east_per_dlon, east_per_dlat_dlon, north_per_dlat, north_per_dlat2, north_per_dlon2],
/// computed in f32 with a fixed amount of work (the node builds its frame at the first fix,
/// inside a tick: f64 on the Cortex-M4F is software, about 8 000 instructions for this). The
/// latitude goes in as whole degrees plus the rest, so that the conversion to radians keeps
/// f32's precision; `sin_cos` is within 1e-7 ([`crate::math::sin_cos`]); the radii of curvature
/// come from binomial series in `u = e^2 sin^2(phi0) <= 0.0067` (truncated below 1e-11), so no
/// square root. Each coefficient is within 3.5e-7 (relative) of the same expansion in f64
/// (measured at every 0.01 deg to +-80 deg: `coefficients_in_f32_match_f64`), a few f32
/// rounding steps; against pymap3d the frame's error is what it was with f64 coefficients
/// (module doc).
fn expansion_coefficients(origin_lat_e7: i32) -> [f32; 5] {
    let whole_deg = origin_lat_e7 / 10_000_000;
    let rest_e7 = origin_lat_e7 % 10_000_000;
    let k = RAD_PER_E7 as f32;
    let phi0 = whole_deg as f32 * (RAD_PER_E7 * 1e7) as f32 + rest_e7 as f32 * k;
    let (s, c) = crate::math::sin_cos(phi0);
    let e2 = WGS84_E2 as f32;
    let u = e2 * s * s;
    // (1 - u)^(-1/2), (1 - u)^(-3/2) and (1 - u)^(-1): the binomial series to u^5.
    let inv_w = 1.0 + u * (0.5 + u * (0.375 + u * (0.3125 + u * (0.273_437_5 + u * 0.246_093_75))));
    let inv_w3 =
        1.0 + u * (1.5 + u * (1.875 + u * (2.187_5 + u * (2.460_937_5 + u * 2.707_031_3))));
    let inv_w2 = 1.0 + u * (1.0 + u * (1.0 + u * (1.0 + u * (1.0 + u))));
    let a = WGS84_A_M as f32;
    let n = a * inv_w;
    let m = a * (1.0 - WGS84_E2) as f32 * inv_w3;
    let dm = 3.0 * m * e2 * s * c * inv_w2;
    [
        n * c * k,
        -m * s * k * k,
        m * k,
        0.5 * dm * k * k,
        0.5 * n * s * c * k * k,
    ]
}

fn check_fix(lat_e7: i32, lon_e7: i32) -> Result<(), GeodesyError> {
    if lat_e7 == NMEA2000_I32_NOT_AVAILABLE || lon_e7 == NMEA2000_I32_NOT_AVAILABLE {
        return Err(GeodesyError::NotAvailable);
    }
    if lat_e7.unsigned_abs() > 900_000_000 {
        return Err(GeodesyError::LatitudeOutOfRange);
    }
    if lon_e7.unsigned_abs() > 1_800_000_000 {
        return Err(GeodesyError::LongitudeOutOfRange);
    }
    Ok(())
}

/// Longitude difference in 1e-7 deg, wrapped across the antimeridian to [-180, 180) deg.
fn dlon_e7(lon_e7: i32, origin_lon_e7: i32) -> i64 {
    let mut d = lon_e7 as i64 - origin_lon_e7 as i64;
    if d >= 1_800_000_000 {
        d -= 3_600_000_000;
    } else if d < -1_800_000_000 {
        d += 3_600_000_000;
    }
    d
}

impl LocalFrame {
    /// A frame at the origin fix (1e-7 deg, as PGN 129025 carries it). Rejects invalid fixes
    /// (see [`GeodesyError`]) and origins beyond ±[`MAX_ORIGIN_LAT_DEG`].
    pub fn new(origin_lat_e7: i32, origin_lon_e7: i32) -> Result<Self, GeodesyError> {
        check_fix(origin_lat_e7, origin_lon_e7)?;
        if (origin_lat_e7.unsigned_abs() as f64) > MAX_ORIGIN_LAT_DEG * E7_PER_DEG {
            return Err(GeodesyError::OriginTooCloseToPole);
        }
        let [a, b, c, d, e] = expansion_coefficients(origin_lat_e7);
        Ok(Self {
            origin_lat_e7,
            origin_lon_e7,
            east_per_dlon: a,
            east_per_dlat_dlon: b,
            north_per_dlat: c,
            north_per_dlat2: d,
            north_per_dlon2: e,
        })
    }

    /// Origin latitude, 1e-7 deg.
    pub fn origin_lat_e7(&self) -> i32 {
        self.origin_lat_e7
    }

    /// Origin longitude, 1e-7 deg.
    pub fn origin_lon_e7(&self) -> i32 {
        self.origin_lon_e7
    }

    /// East/north metres of a fix (1e-7 deg) from the origin; `f32` arithmetic on the exact
    /// integer differences (about 12 flops, bit-identical on every target). Error against the
    /// exact ENU: < 1 mm within 2 km (see the module doc). Rejects invalid fixes and fixes
    /// beyond [`VALIDITY_RADIUS_M`]; crossing the antimeridian is handled.
    pub fn to_local(&self, lat_e7: i32, lon_e7: i32) -> Result<Enu, GeodesyError> {
        check_fix(lat_e7, lon_e7)?;
        let dlat_i = lat_e7 as i64 - self.origin_lat_e7 as i64;
        let dlon_i = dlon_e7(lon_e7, self.origin_lon_e7);
        if dlat_i.abs() > MAX_EXACT_DIFF_E7 || dlon_i.abs() > MAX_EXACT_DIFF_E7 {
            return Err(GeodesyError::BeyondValidityRadius);
        }
        // Exact conversions: |d| <= 2^24.
        let dlat = crate::math::i64_to_f32(dlat_i);
        let dlon = crate::math::i64_to_f32(dlon_i);
        let east_m = dlon * (self.east_per_dlon + self.east_per_dlat_dlon * dlat);
        let north_m = dlat * (self.north_per_dlat + self.north_per_dlat2 * dlat)
            + self.north_per_dlon2 * dlon * dlon;
        if east_m * east_m + north_m * north_m > VALIDITY_RADIUS_M * VALIDITY_RADIUS_M {
            return Err(GeodesyError::BeyondValidityRadius);
        }
        Ok(Enu { east_m, north_m })
    }

    /// Inverse of [`LocalFrame::to_local`], for the host: (latitude, longitude) in degrees of
    /// the point with these local coordinates, solving the same expansion in f64 by fixed-point
    /// iteration. Round trip with `to_local` is within its f32 rounding (< 1 mm within 2 km).
    pub fn from_local(&self, enu: Enu) -> (f64, f64) {
        // The frame's own coefficients, so that this is the inverse of `to_local`.
        let [a, b, c, d, e] = [
            self.east_per_dlon,
            self.east_per_dlat_dlon,
            self.north_per_dlat,
            self.north_per_dlat2,
            self.north_per_dlon2,
        ]
        .map(f64::from);
        let east = enu.east_m as f64;
        let north = enu.north_m as f64;
        let mut dlat = north / c;
        let mut dlon = east / a;
        // Contraction factor ~ distance / earth radius: 12 rounds reach f64 precision at 20 km.
        for _ in 0..12 {
            dlon = east / (a + b * dlat);
            dlat = (north - e * dlon * dlon) / (c + d * dlat);
        }
        let lat_deg = (self.origin_lat_e7 as f64 + dlat) / E7_PER_DEG;
        let mut lon_deg = (self.origin_lon_e7 as f64 + dlon) / E7_PER_DEG;
        if lon_deg >= 180.0 {
            lon_deg -= 360.0;
        } else if lon_deg < -180.0 {
            lon_deg += 360.0;
        }
        (lat_deg, lon_deg)
    }
}

/// A geodetic position on WGS-84 (host, f64).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Geodetic {
    /// Latitude, degrees north.
    pub lat_deg: f64,
    /// Longitude, degrees east.
    pub lon_deg: f64,
    /// Height above the ellipsoid, m.
    pub height_m: f64,
}

/// Earth-centred, earth-fixed coordinates, m (host, f64).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Ecef {
    /// m, towards (0 N, 0 E).
    pub x_m: f64,
    /// m, towards (0 N, 90 E).
    pub y_m: f64,
    /// m, towards the north pole.
    pub z_m: f64,
}

/// Exact local east/north/up, m, of the tangent plane at an origin (host, f64).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EnuExact {
    /// m east.
    pub east_m: f64,
    /// m north.
    pub north_m: f64,
    /// m up (along the origin's ellipsoid normal).
    pub up_m: f64,
}

/// WGS-84 geodetic (deg, deg, m) to ECEF (m), exact closed form.
pub fn geodetic_to_ecef(lat_deg: f64, lon_deg: f64, height_m: f64) -> Ecef {
    let (sp, cp) = libm::sincos(lat_deg.to_radians());
    let (sl, cl) = libm::sincos(lon_deg.to_radians());
    let n = WGS84_A_M / libm::sqrt(1.0 - WGS84_E2 * sp * sp);
    Ecef {
        x_m: (n + height_m) * cp * cl,
        y_m: (n + height_m) * cp * sl,
        z_m: (n * (1.0 - WGS84_E2) + height_m) * sp,
    }
}

/// ECEF (m) to WGS-84 geodetic, by fixed-point iteration on latitude (converges by a factor
/// ~e^2 per round near the surface; 10 rounds reach f64 precision for heights below 1000 km).
pub fn ecef_to_geodetic(ecef: Ecef) -> Geodetic {
    let p = libm::hypot(ecef.x_m, ecef.y_m);
    let lon = libm::atan2(ecef.y_m, ecef.x_m);
    let mut lat = libm::atan2(ecef.z_m, p * (1.0 - WGS84_E2));
    let mut h = 0.0;
    for _ in 0..10 {
        let (s, c) = libm::sincos(lat);
        let n = WGS84_A_M / libm::sqrt(1.0 - WGS84_E2 * s * s);
        h = p * c + ecef.z_m * s - WGS84_A_M * libm::sqrt(1.0 - WGS84_E2 * s * s);
        lat = libm::atan2(ecef.z_m, p * (1.0 - WGS84_E2 * n / (n + h)));
    }
    Geodetic {
        lat_deg: lat.to_degrees(),
        lon_deg: lon.to_degrees(),
        height_m: h,
    }
}

/// Exact ENU (m) of a geodetic point (deg, deg, m) in the tangent frame at `origin`:
/// ECEF difference rotated into east/north/up. Same as pymap3d `geodetic2enu`.
pub fn geodetic_to_enu(lat_deg: f64, lon_deg: f64, height_m: f64, origin: &Geodetic) -> EnuExact {
    let p = geodetic_to_ecef(lat_deg, lon_deg, height_m);
    let o = geodetic_to_ecef(origin.lat_deg, origin.lon_deg, origin.height_m);
    let (dx, dy, dz) = (p.x_m - o.x_m, p.y_m - o.y_m, p.z_m - o.z_m);
    let (sp, cp) = libm::sincos(origin.lat_deg.to_radians());
    let (sl, cl) = libm::sincos(origin.lon_deg.to_radians());
    EnuExact {
        east_m: -sl * dx + cl * dy,
        north_m: -sp * cl * dx - sp * sl * dy + cp * dz,
        up_m: cp * cl * dx + cp * sl * dy + sp * dz,
    }
}

/// Inverse of [`geodetic_to_enu`]: the geodetic point at `enu` in the frame at `origin`.
pub fn enu_to_geodetic(enu: &EnuExact, origin: &Geodetic) -> Geodetic {
    let o = geodetic_to_ecef(origin.lat_deg, origin.lon_deg, origin.height_m);
    let (sp, cp) = libm::sincos(origin.lat_deg.to_radians());
    let (sl, cl) = libm::sincos(origin.lon_deg.to_radians());
    let (e, n, u) = (enu.east_m, enu.north_m, enu.up_m);
    ecef_to_geodetic(Ecef {
        x_m: o.x_m - sl * e - sp * cl * n + cp * cl * u,
        y_m: o.y_m + cl * e - sp * sl * n + cp * sl * u,
        z_m: o.z_m + cp * n + sp * u,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_bad_fixes() {
        let f = LocalFrame::new(322_319_000, -1_109_501_000).unwrap();
        assert_eq!(f.to_local(i32::MAX, 0), Err(GeodesyError::NotAvailable));
        assert_eq!(
            f.to_local(900_000_001, 0),
            Err(GeodesyError::LatitudeOutOfRange)
        );
        assert_eq!(
            f.to_local(0, i32::MIN),
            Err(GeodesyError::LongitudeOutOfRange)
        );
        // 0.2 deg north = 22 km.
        assert_eq!(
            f.to_local(324_319_000, -1_109_501_000),
            Err(GeodesyError::BeyondValidityRadius)
        );
        assert_eq!(
            LocalFrame::new(850_000_000, 0),
            Err(GeodesyError::OriginTooCloseToPole)
        );
        assert_eq!(f.to_local(322_319_000, -1_109_501_000), Ok(Enu::default()));
    }

    /// The f32 coefficients against the same expansion in f64 (libm), at every 0.01 deg of
    /// latitude the node accepts.
    #[test]
    fn coefficients_in_f32_match_f64() {
        let f64_coefficients = |lat_e7: i32| {
            let phi0 = lat_e7 as f64 * RAD_PER_E7;
            let (s, c) = (phi0.sin(), phi0.cos());
            let w2 = 1.0 - WGS84_E2 * s * s;
            let n = WGS84_A_M / w2.sqrt();
            let m = WGS84_A_M * (1.0 - WGS84_E2) / (w2 * w2.sqrt());
            let dm = 3.0 * m * WGS84_E2 * s * c / w2;
            let k = RAD_PER_E7;
            [
                n * c * k,
                -m * s * k * k,
                m * k,
                0.5 * dm * k * k,
                0.5 * n * s * c * k * k,
            ]
        };
        let mut worst = [0.0f64; 5];
        for centi_deg in -8_000..=8_000 {
            let lat_e7 = centi_deg * 100_000;
            let reference = f64_coefficients(lat_e7);
            let ours = expansion_coefficients(lat_e7);
            for i in 0..5 {
                // Relative to the coefficient's scale at mid latitudes (the sine terms vanish
                // at the equator, where their absolute error is what matters).
                let scale = f64_coefficients(450_000_000)[i].abs();
                worst[i] = worst[i].max((f64::from(ours[i]) - reference[i]).abs() / scale);
            }
        }
        println!("worst relative error of the f32 coefficients: {worst:?}");
        for w in worst {
            assert!(w < 5e-7, "{worst:?}");
        }
    }

    #[test]
    fn antimeridian() {
        let f = LocalFrame::new(0, 1_799_999_000).unwrap();
        let p = f.to_local(0, -1_799_999_000).unwrap();
        // 0.0002 deg of longitude at the equator: 22.26 m east.
        assert!((p.east_m - 22.263_9).abs() < 1e-3, "{p:?}");
    }
}
