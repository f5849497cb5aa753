//! Local east/north metres -> WGS-84 latitude/longitude for the simulated GNSS (f64, exact to
//! well under a millimetre near the origin; checked against pymap3d in `host-tests/tests/sim.rs`).
//! This is the one function to swap for `catmodel::geodesy::enu_to_geodetic` once the core's
//! geodesy lands; it uses only `libm` so that the output is the same on every platform.

/// Origin of the simulated drives: the Tucson test area (University of Arizona).
pub const ORIGIN_LAT_DEG: f64 = 32.2319;
/// See [`ORIGIN_LAT_DEG`].
pub const ORIGIN_LON_DEG: f64 = -110.9501;

const WGS84_A_M: f64 = 6_378_137.0;
const WGS84_F: f64 = 1.0 / 298.257_223_563;

/// Latitude and longitude (degrees) of the point `east_m`, `north_m` from the origin
/// (`origin_lat_deg`, `origin_lon_deg`, ellipsoid height 0), on the origin's tangent plane (up = 0).
pub fn enu_to_lat_lon(
    origin_lat_deg: f64,
    origin_lon_deg: f64,
    east_m: f64,
    north_m: f64,
) -> (f64, f64) {
    let e2 = WGS84_F * (2.0 - WGS84_F);
    let lat0 = origin_lat_deg.to_radians();
    let lon0 = origin_lon_deg.to_radians();
    let (s_lat0, c_lat0) = (libm::sin(lat0), libm::cos(lat0));
    let (s_lon0, c_lon0) = (libm::sin(lon0), libm::cos(lon0));
    let n0 = WGS84_A_M / libm::sqrt(1.0 - e2 * s_lat0 * s_lat0);
    // Origin in ECEF, then the ENU offset rotated into ECEF.
    let x = n0 * c_lat0 * c_lon0 - s_lon0 * east_m - s_lat0 * c_lon0 * north_m;
    let y = n0 * c_lat0 * s_lon0 + c_lon0 * east_m - s_lat0 * s_lon0 * north_m;
    let z = n0 * (1.0 - e2) * s_lat0 + c_lat0 * north_m;
    // ECEF -> geodetic: fixed-point iteration on latitude (converges to < 1e-12 rad in a few
    // rounds at the surface; a fixed count keeps the result reproducible).
    let p = libm::sqrt(x * x + y * y);
    let lon = libm::atan2(y, x);
    let mut lat = libm::atan2(z, p * (1.0 - e2));
    for _ in 0..6 {
        let s = libm::sin(lat);
        let n = WGS84_A_M / libm::sqrt(1.0 - e2 * s * s);
        let h = p / libm::cos(lat) - n;
        lat = libm::atan2(z, p * (1.0 - e2 * n / (n + h)));
    }
    (lat.to_degrees(), lon.to_degrees())
}
