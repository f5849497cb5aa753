"""Reference values for host-tests/tests/sim.rs: local ENU -> WGS-84 lat/lon at the Tucson
origin of the simulator, computed with pymap3d (independent of the Rust code).
Run (with numpy and scipy, e.g. from a venv: pip install numpy scipy): python3 host-tests/reference/gen_sim_reference.py"""
import json
import pathlib

import pymap3d

ORIGIN = (32.2319, -110.9501, 0.0)
POINTS = [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (123.456, -78.9), (-1500.0, 2000.0), (2500.0, 2500.0), (-0.3, -4000.0)]

cases = []
for east, north in POINTS:
    lat, lon, _h = pymap3d.enu2geodetic(east, north, 0.0, *ORIGIN, deg=True)
    cases.append({"east_m": east, "north_m": north, "lat_deg": float(lat), "lon_deg": float(lon)})

out = pathlib.Path(__file__).with_name("sim_geodesy.json")
out.write_text(json.dumps({"origin": {"lat_deg": ORIGIN[0], "lon_deg": ORIGIN[1], "h_m": ORIGIN[2]},
                           "source": "pymap3d.enu2geodetic, WGS-84", "cases": cases}, indent=1) + "\n")
print(out)
