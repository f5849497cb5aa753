#!/usr/bin/env python3
"""Reference values for host-tests/tests/{signal,geodesy}.rs, computed with scipy/numpy/pymap3d.

Run from the repository root (with numpy and scipy): python3 host-tests/reference/gen_signal.py
Writes host-tests/reference/signal_*.json and geodesy_*.json. Deterministic (fixed seeds).
"""
import json
import os

import numpy as np
import pymap3d
import scipy
import scipy.signal as sig

OUT = os.path.dirname(os.path.abspath(__file__))
VERSIONS = {"numpy": np.__version__, "scipy": scipy.__version__, "pymap3d": pymap3d.__version__}


def dump(name, obj):
    obj = {"generator": "gen_signal.py", "versions": VERSIONS, **obj}
    with open(os.path.join(OUT, name), "w") as f:
        json.dump(obj, f, indent=1)
        f.write("\n")


def test_signal(n, fs, seed):
    """Chirp + step + noise: broadband content, a discontinuity, a non-zero start value."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fs
    x = 3.0 + np.sin(2 * np.pi * (0.2 + 2.0 * t / t[-1]) * t) + 0.3 * rng.standard_normal(n)
    x[n // 2 :] += 1.5
    return x


# --- firwin: several (numtaps, cutoff, fs), odd and even, including the paper's 21 taps ---
fir_cases = []
for numtaps, cutoff, fs in [
    (21, 2.0, 50.0),  # paper: "20th order FIR", vehicle bus at 50 Hz
    (21, 5.0, 100.0),  # GNSS at 100 Hz
    (21, 0.5, 50.0),
    (20, 3.0, 50.0),  # even numtaps: firwin accepts it for a lowpass
    (1, 1.0, 10.0),
    (2, 1.0, 10.0),
    (7, 24.0, 50.0),  # near Nyquist
    (101, 0.7, 100.0),
]:
    taps = sig.firwin(numtaps, cutoff, fs=fs)
    fir_cases.append({"numtaps": numtaps, "cutoff_hz": cutoff, "fs_hz": fs, "taps": taps.tolist()})
dump("signal_firwin.json", {"call": "scipy.signal.firwin(numtaps, cutoff_hz, fs=fs_hz)", "cases": fir_cases})

# --- streaming FIR vs lfilter: zero initial state, and primed with x[0] (lfilter_zi * x[0]) ---
b = sig.firwin(21, 5.0, fs=100.0)
x = test_signal(400, 100.0, 1)
y_zero = sig.lfilter(b, [1.0], x)
y_primed, _ = sig.lfilter(b, [1.0], x, zi=sig.lfilter_zi(b, [1.0]) * x[0])
dump(
    "signal_lfilter.json",
    {
        "call": "scipy.signal.lfilter(b, [1.0], x) and with zi=lfilter_zi(b, 1)*x[0]; b = firwin(21, 5, fs=100)",
        "b": b.tolist(),
        "x": x.tolist(),
        "y_zero_state": y_zero.tolist(),
        "y_primed": y_primed.tolist(),
    },
)

# --- filtfilt with scipy defaults ---
ff_cases = []
for numtaps, cutoff, fs, n, seed in [(21, 2.0, 50.0, 300, 2), (21, 2.0, 50.0, 64, 3), (20, 3.0, 50.0, 200, 4), (3, 10.0, 50.0, 10, 5)]:
    b = sig.firwin(numtaps, cutoff, fs=fs)
    x = test_signal(n, fs, seed)
    y = sig.filtfilt(b, [1.0], x)
    ff_cases.append({"b": b.tolist(), "x": x.tolist(), "y": y.tolist()})
dump("signal_filtfilt.json", {"call": "scipy.signal.filtfilt(b, [1.0], x) (padtype='odd', padlen=3*len(b))", "cases": ff_cases})

# --- resampling: irregular multi-rate series with NaN gaps onto the 0.02 s grid; eq 1 grid ---
rng = np.random.default_rng(6)
t = np.cumsum(rng.uniform(0.004, 0.016, 600)) + 10.0  # ~100 Hz, jittered, starts at ~10 s
speed = 5.0 + np.sin(t)
steer = np.cos(3 * t)
steer[rng.random(600) < 0.5] = np.nan  # a slower sensor: half the rows empty
speed[[0, 1, 2]] = np.nan  # leading gap
steer_valid = ~np.isnan(steer)
speed_valid = ~np.isnan(speed)
lo = max(t[speed_valid][0], t[steer_valid][0])
hi = min(t[speed_valid][-1], t[steer_valid][-1])
grid = np.ceil(lo / 0.02) * 0.02 + 0.02 * np.arange(int((hi - np.ceil(lo / 0.02) * 0.02) / 0.02))
eq1_n = 3000
ts, te = 12.345, 71.002
k = np.arange(1, eq1_n + 1)
eq1 = (k - 1) * ((te - ts) / eq1_n) + ts
dump(
    "signal_interp.json",
    {
        "call": "numpy.interp(grid, t[valid], y[valid]) per signal; eq1 = (k-1)*((te-ts)/N)+ts",
        "t": t.tolist(),
        "speed": [None if np.isnan(v) else v for v in speed],
        "steer": [None if np.isnan(v) else v for v in steer],
        "grid": grid.tolist(),
        "speed_on_grid": np.interp(grid, t[speed_valid], speed[speed_valid]).tolist(),
        "steer_on_grid": np.interp(grid, t[steer_valid], steer[steer_valid]).tolist(),
        "eq1": {"n": eq1_n, "t_s": ts, "t_e": te, "grid": eq1.tolist()},
    },
)

# --- geodesy: pymap3d over a 2 km x 2 km grid around Tucson, plus farther rings ---
lat0_e7, lon0_e7 = 322_319_000, -1_109_501_000
lat0, lon0 = lat0_e7 / 1e7, lon0_e7 / 1e7
m_per_deg_lat = 110_900.0  # only to lay out the grid; the truth comes from pymap3d
m_per_deg_lon = 94_300.0
points = []
for i in range(-10, 11):
    for j in range(-10, 11):
        lat_e7 = lat0_e7 + round(i * 100.0 / m_per_deg_lat * 1e7)
        lon_e7 = lon0_e7 + round(j * 100.0 / m_per_deg_lon * 1e7)
        points.append((lat_e7, lon_e7, "grid"))
for r_m in [2_000.0, 5_000.0, 10_000.0, 19_500.0]:
    for ang in np.linspace(0, 2 * np.pi, 16, endpoint=False):
        lat_e7 = lat0_e7 + round(r_m * np.cos(ang) / m_per_deg_lat * 1e7)
        lon_e7 = lon0_e7 + round(r_m * np.sin(ang) / m_per_deg_lon * 1e7)
        points.append((lat_e7, lon_e7, f"ring{int(r_m)}"))
rows = []
for lat_e7, lon_e7, tag in points:
    e, n, u = pymap3d.geodetic2enu(lat_e7 / 1e7, lon_e7 / 1e7, 0.0, lat0, lon0, 0.0)
    rows.append({"lat_e7": lat_e7, "lon_e7": lon_e7, "tag": tag, "east_m": e, "north_m": n, "up_m": u})
dump(
    "geodesy_local.json",
    {
        "call": "pymap3d.geodetic2enu(lat_e7/1e7, lon_e7/1e7, 0, lat0, lon0, 0) (WGS-84)",
        "origin_lat_e7": lat0_e7,
        "origin_lon_e7": lon0_e7,
        "points": rows,
    },
)

# f64 functions: points with heights, ECEF and ENU with a non-zero origin height.
rng = np.random.default_rng(7)
origin = (lat0, lon0, 728.0)
rows = []
for _ in range(60):
    lat = lat0 + rng.uniform(-0.01, 0.01)
    lon = lon0 + rng.uniform(-0.012, 0.012)
    h = rng.uniform(600.0, 900.0)
    x, y, z = pymap3d.geodetic2ecef(lat, lon, h)
    e, n, u = pymap3d.geodetic2enu(lat, lon, h, *origin)
    rows.append({"lat_deg": lat, "lon_deg": lon, "h_m": h, "ecef": [x, y, z], "enu": [e, n, u]})
for lat, lon, h in [(0.0, 0.0, 0.0), (89.9, 45.0, 100.0), (-45.0, 179.99, 5000.0), (60.0, -120.0, -50.0)]:
    x, y, z = pymap3d.geodetic2ecef(lat, lon, h)
    e, n, u = pymap3d.geodetic2enu(lat, lon, h, *origin)
    rows.append({"lat_deg": lat, "lon_deg": lon, "h_m": h, "ecef": [x, y, z], "enu": [e, n, u]})
dump(
    "geodesy_exact.json",
    {
        "call": "pymap3d.geodetic2ecef(lat, lon, h); pymap3d.geodetic2enu(lat, lon, h, *origin)",
        "origin": {"lat_deg": origin[0], "lon_deg": origin[1], "h_m": origin[2]},
        "points": rows,
    },
)
print("wrote", sorted(f for f in os.listdir(OUT) if f.endswith(".json")))
