#!/usr/bin/env python3
"""The replay work of `catmodel replay`, written the way a NumPy/SciPy user would write it.

The peer of `catmodel replay` in `scripts/compare-peers.sh` (issue 7). It does, per 20 ms tick
of a candump log, the work the node does (src/node/), with scipy.signal for the filters and
models and NumPy for the rest:

  parse the candump; decode per catmodel.dbc (CRC-8/SAE-J1850 over id + bytes 0..6, rolling
  counter, steering 0x100, speed 0x101, GNSS PGN 129025 from source 0x1C), all vectorised;
  GNSS to local metres (WGS-84, exact geodetic -> ECEF -> ENU, vectorised);
  then per tick (the streaming part, a Python loop over ticks):
    dead reckoning; GNSS fixes of the tick through the paper's lowpass, streaming:
      scipy.signal.firwin(21, 2 Hz, fs=100) then a 10-sample moving average, both
      scipy.signal.lfilter with carried state (zi); group delay (14.5 fixes) compensated by
      dead reckoning, lever arm 1.478 m; heading from the filtered track's course (64 fixes)
      with the node's complementary filter;
    eq 5 (internal controller, commanded -> actual speed) as a discrete state space
      (scipy.signal.tf2ss + cont2discrete, ZOH, Ts 0.02 s) with its 21-sample input delay
      as 21 extra states, stepped once per tick; eq 7 (dx/dt, 4 inputs) likewise;
    the 2 s horizon: 100 steps of the eq 5 speed model + kinematic model (eq 8 with eq 2's
      understeer), 10 points out (every 0.2 s);
  writes the predictions CSV `t,step,horizon_s,x,y,heading,speed,mode` (catmodel's format).

Roll-out variants (--rollout):
  vector (default, the fastest honest version): the speed model's 100-step response is one
    precomputed 100x23 matrix times the state plus the step response times the command (exact
    for a constant command, which is what the node holds over the horizon); the kinematic
    model is integrated with cumulative sums (same midpoint-heading chord as the node).
  loop: a plain Python loop of 100 steps (state-space step with NumPy, kinematic with math).

Differences from the node (not the same numbers, the same work or less): kinematic model only
(the node switches to a dynamic bicycle model at high lateral acceleration); no plausibility gate
on GNSS; no output frames encoded (the node encodes 14 CAN frames per tick and decodes them
again for its CSV). Times are printed to stderr and, with --timing-json, written as JSON.
"""
import argparse
import json
import math
import sys
import time

T_IMPORT0 = time.perf_counter()
import numpy as np  # noqa: E402
from scipy import signal  # noqa: E402

T_IMPORTED = time.perf_counter()

TICK_US = 20_000
TS = 0.02
GNSS_HZ = 100.0
WHEELBASE_M = 2.62
MAX_STEER_RAD = 35.5 * math.pi / 180.0
UNDERSTEER = 0.0015
ANTENNA_AHEAD_M = 1.478
MAX_SPEED = 60.0
STEER_TIMEOUT_US = 100_000
SPEED_TIMEOUT_US = 100_000
GNSS_LOST_US = 2_000_000
COURSE_GAIN = 0.05
COURSE_MIN_SPEED = 1.5
COURSE_MIN_BASELINE = 1.5
TRACK_LEN = 64
HORIZON_STEPS = 100
OUTPUT_EVERY = 10
N2K_SOURCE = 0x1C
PGN_POSITION_RAPID = 129025

# eq 5 and eq 7 (src/model/paper.rs)
EQ5 = ([0.03679, -0.1981, 0.7647], [1.0, 1.629, 0.7522], 21)
EQ7 = [
    ([-4.122, 49.61, -4.098], [1.0, 6.211, 26.79]),
    ([20.55, -110.4, 12.08], [1.0, 37.03, 111.7]),
    ([-0.06946, -0.06244, 0.0002256], [1.0, 1.416, 0.5473]),
    ([-22.3, 371.5, -26.08], [1.0, 6.59, 18.78]),
]


def crc_table():
    t = np.zeros(256, dtype=np.uint8)
    for i in range(256):
        c = i
        for _ in range(8):
            c = ((c << 1) ^ 0x1D) & 0xFF if c & 0x80 else (c << 1) & 0xFF
        t[i] = c
    return t


def parse_candump(path):
    """Timestamps (us, int64), identifiers (int64), DLC and data (N x 8 uint8)."""
    t_us, ids, dlc, payload = [], [], [], []
    with open(path) as f:
        for line in f:
            if not line.strip():
                continue
            stamp, _iface, frame = line.split()
            ident, data = frame.split("#")
            secs, micros = stamp[1:-1].split(".")
            t_us.append(int(secs) * 1_000_000 + int(micros))
            ids.append(int(ident, 16))
            raw = bytes.fromhex(data)
            dlc.append(len(raw))
            payload.append(raw.ljust(8, b"\0"))
    data = np.frombuffer(b"".join(payload), dtype=np.uint8).reshape(-1, 8)
    return np.array(t_us, dtype=np.int64), np.array(ids, dtype=np.int64), np.array(dlc), data


def u16(data, byte):
    return data[:, byte].astype(np.int64) | (data[:, byte + 1].astype(np.int64) << 8)


def decode(t_us, ids, dlc, data):
    """Vectorised DBC decode: the accepted steering, speed and GNSS samples."""
    table = crc_table()
    crc = np.full(len(ids), 0xFF, dtype=np.uint8)
    for b in [(ids >> 8) & 0xFF, ids & 0xFF] + [data[:, i] for i in range(7)]:
        crc = table[crc ^ b.astype(np.uint8)]
    crc_ok = (crc ^ 0xFF) == data[:, 7]
    counter = (data[:, 6] >> 4) & 0x0F

    def dbw(ident):
        sel = np.flatnonzero((ids == ident) & (dlc == 8) & crc_ok)
        c = counter[sel]
        # a stuck counter (the same as the previous accepted frame's) is rejected
        keep = np.ones(len(sel), dtype=bool)
        keep[1:] = c[1:] != c[:-1]
        return sel[keep]

    out = {}
    s = dbw(0x100)
    raw = u16(data[s], 0)
    raw = np.where(raw >= 0x8000, raw - 0x10000, raw)
    ok = (raw >= -10_000) & (raw <= 10_000)
    out["steer"] = (t_us[s][ok], raw[ok] * 0.01)

    s = dbw(0x101)
    v, cmd = u16(data[s], 0), u16(data[s], 2)
    ok = v != 0xFFFF
    cmd = np.where(cmd == 0xFFFF, v, cmd)
    out["speed"] = (t_us[s][ok], v[ok] * 0.01, cmd[ok] * 0.01)

    pf = (ids >> 16) & 0xFF
    pgn = np.where(pf < 240, (ids >> 8) & 0x3FF00, (ids >> 8) & 0x3FFFF)
    s = np.flatnonzero((ids > 0x7FF) & (pgn == PGN_POSITION_RAPID) & ((ids & 0xFF) == N2K_SOURCE) & (dlc == 8))
    ll = data[s].copy().view("<i4").reshape(-1, 2)
    ok = (ll[:, 0] != 0x7FFFFFFF) & (ll[:, 1] != 0x7FFFFFFF)
    ok &= (np.abs(ll[:, 0]) <= 900_000_000) & (np.abs(ll[:, 1]) <= 1_800_000_000)
    out["gnss"] = (t_us[s][ok], ll[ok, 0] * 1e-7, ll[ok, 1] * 1e-7)
    return out


def geodetic_to_enu(lat_deg, lon_deg, lat0_deg, lon0_deg):
    """WGS-84 geodetic -> ECEF -> local east/north (m) at the origin, vectorised, f64."""
    a, f = 6378137.0, 1.0 / 298.257223563
    e2 = f * (2.0 - f)

    def ecef(lat, lon):
        lat, lon = np.radians(lat), np.radians(lon)
        n = a / np.sqrt(1.0 - e2 * np.sin(lat) ** 2)
        return n * np.cos(lat) * np.cos(lon), n * np.cos(lat) * np.sin(lon), n * (1 - e2) * np.sin(lat)

    x, y, z = ecef(lat_deg, lon_deg)
    x0, y0, z0 = ecef(np.array(lat0_deg), np.array(lon0_deg))
    dx, dy, dz = x - x0, y - y0, z - z0
    la, lo = math.radians(lat0_deg), math.radians(lon0_deg)
    east = -math.sin(lo) * dx + math.cos(lo) * dy
    north = -math.sin(la) * math.cos(lo) * dx - math.sin(la) * math.sin(lo) * dy + math.cos(la) * dz
    return east, north


def discrete_ss(num, den, delay_samples=0):
    """ZOH discretisation (Ts 0.02) of num/den, the input delay as extra states."""
    a, b, c, d = signal.tf2ss(num, den)
    ad, bd, cd, dd, _ = signal.cont2discrete((a, b, c, d), TS, method="zoh")
    n = ad.shape[0]
    if delay_samples == 0:
        return ad, bd[:, 0], cd[0], float(dd[0, 0])
    # state [x (n), z_1 .. z_D]; z_D is the input D samples ago, what the plant sees now
    m = n + delay_samples
    A = np.zeros((m, m))
    A[:n, :n] = ad
    A[:n, m - 1] = bd[:, 0]
    for i in range(1, delay_samples):
        A[n + i, n + i - 1] = 1.0
    B = np.zeros(m)
    B[n] = 1.0
    C = np.zeros(m)
    C[:n] = cd[0]
    C[m - 1] = dd[0, 0]
    return A, B, C, 0.0


def wrap_pi(a):
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def held(times, values, at, timeout_us):
    """The latest value at or before each time in `at`, NaN when older than the timeout."""
    i = np.searchsorted(times, at, side="right") - 1
    v = np.where(i >= 0, values[np.maximum(i, 0)], np.nan)
    age = at - np.where(i >= 0, times[np.maximum(i, 0)], at[0] - 10 * timeout_us)
    return np.where(age <= timeout_us, v, np.nan)


def run(path, out_path, origin, rollout):
    t0 = time.perf_counter()
    t_us, ids, dlc, data = parse_candump(path)
    msgs = decode(t_us, ids, dlc, data)
    g_t, g_lat, g_lon = msgs["gnss"]
    if origin is None:
        origin = (float(g_lat[0]), float(g_lon[0]))
    g_x, g_y = geodetic_to_enu(g_lat, g_lon, *origin)
    g_xy = np.vstack([g_x, g_y])

    first = -(-int(t_us[0]) // TICK_US) * TICK_US
    last = -(-int(t_us[-1]) // TICK_US) * TICK_US
    ticks = np.arange(first, last + 1, TICK_US, dtype=np.int64)
    steer = held(msgs["steer"][0], msgs["steer"][1], ticks, STEER_TIMEOUT_US)
    speed_t, speed_v, speed_c = msgs["speed"]
    speed = held(speed_t, speed_v, ticks, SPEED_TIMEOUT_US)
    cmd = held(speed_t, speed_c, ticks, SPEED_TIMEOUT_US)
    g_end = np.searchsorted(g_t, ticks, side="right")
    # per-tick values as Python floats/ints for the loop
    steer_l = np.nan_to_num(steer).tolist()
    speed_l, cmd_l, g_end_l, g_t_l = speed.tolist(), cmd.tolist(), g_end.tolist(), g_t.tolist()
    t_decoded = time.perf_counter()

    # filters and models
    fir = signal.firwin(21, 2.0, fs=GNSS_HZ)
    ma = np.full(10, 0.1)
    fir_zi1, ma_zi1 = signal.lfilter_zi(fir, 1.0), signal.lfilter_zi(ma, 1.0)
    group_delay = (21 - 1) / 2 + (10 - 1) / 2
    k0 = int(group_delay)
    w = group_delay - k0
    A5, B5, C5, _ = discrete_ss(*EQ5)
    n5 = A5.shape[0]
    dc5 = float(C5 @ np.linalg.solve(np.eye(n5) - A5, B5))
    x_eq5 = np.linalg.solve(np.eye(n5) - A5, B5)  # state per unit input at equilibrium
    blocks = [discrete_ss(num, den) for num, den in EQ7]
    A7 = np.zeros((8, 8))
    B7 = np.zeros((8, 4))
    C7 = np.zeros(8)
    D7 = np.zeros(4)
    for i, (a, b, c, d) in enumerate(blocks):
        A7[2 * i:2 * i + 2, 2 * i:2 * i + 2] = a
        B7[2 * i:2 * i + 2, i] = b
        C7[2 * i:2 * i + 2] = c
        D7[i] = d
    s7 = np.zeros(8)
    # horizon: v_model at steps 1..100 = O @ s + G * u (the output before each update)
    O = np.empty((HORIZON_STEPS, n5))
    G = np.empty(HORIZON_STEPS)
    Ak = np.eye(n5)
    acc = np.zeros(n5)
    for k in range(HORIZON_STEPS):
        O[k] = C5 @ Ak
        G[k] = C5 @ acc
        acc = A5 @ acc + B5
        Ak = A5 @ Ak
    out_idx = np.arange(OUTPUT_EVERY - 1, HORIZON_STEPS, OUTPUT_EVERY)
    horizons = [(i + 1) * TS for i in out_idx]

    rows = ["t,step,horizon_s,x,y,heading,speed,mode\n"]
    fir_z = ma_z = None
    fixes = 0
    odo = [0.0, 0.0]
    odo_hist = []  # dead-reckoned antenna position at each fix
    track = []  # filtered antenna positions
    filtered = None
    heading = None
    yaw = 0.0
    v_now = 0.0
    s5 = None
    g_start = 0
    last_fix_us = None
    for step, now in enumerate(ticks.tolist()):
        # dead reckoning of the antenna over the last 20 ms
        h = heading if heading is not None else 0.0
        mid = h + 0.5 * yaw * TS
        sn, cs = math.sin(mid), math.cos(mid)
        along, across = v_now * TS, ANTENNA_AHEAD_M * yaw * TS
        odo[0] += along * sn + across * cs
        odo[1] += along * cs - across * sn
        if heading is not None:
            heading = wrap_pi(heading + yaw * TS)

        # this tick's GNSS fixes through the streaming lowpass
        g_stop = g_end_l[step]
        if g_stop > g_start:
            if last_fix_us is not None and g_t_l[g_start] - last_fix_us > GNSS_LOST_US:
                fixes, odo_hist, track, fir_z = 0, [], [], None
            xy = g_xy[:, g_start:g_stop]
            if fir_z is None:
                fir_z = fir_zi1[None, :] * xy[:, :1]
                ma_z = ma_zi1[None, :] * xy[:, :1]
            f, fir_z = signal.lfilter(fir, 1.0, xy, axis=1, zi=fir_z)
            m, ma_z = signal.lfilter(ma, 1.0, f, axis=1, zi=ma_z)
            for j in range(g_stop - g_start):
                back = v_now * (now - g_t_l[g_start + j]) * 1e-6
                odo_hist.append((odo[0] - back * sn, odo[1] - back * cs))
                track.append((m[0, j], m[1, j]))
            del odo_hist[:-32], track[:-TRACK_LEN]
            fixes += g_stop - g_start
            filtered = (m[0, -1], m[1, -1])
            last_fix_us = g_t_l[g_stop - 1]
            g_start = g_stop

        # speed, eq 5, yaw rate (kinematic, eq 2 with understeer)
        v_meas, u = speed_l[step], cmd_l[step]
        if s5 is None and not math.isnan(v_meas):
            u0 = v_meas / dc5
            s5 = x_eq5 * u0
        if math.isnan(u):
            u = v_meas if not math.isnan(v_meas) else v_now
        v_model = None
        if s5 is not None:
            v_model = float(C5 @ s5)
            s5 = A5 @ s5 + B5 * u
        v = v_meas if not math.isnan(v_meas) else (v_model if v_model is not None else 0.0)
        v_now = min(max(v, 0.0), MAX_SPEED)
        delta = steer_l[step] / 100.0 * MAX_STEER_RAD
        kappa = math.tan(delta / (1.0 + UNDERSTEER * v_now * v_now)) / WHEELBASE_M
        yaw = v_now * kappa

        # heading from the filtered track's course
        if v_now >= COURSE_MIN_SPEED and fixes >= TRACK_LEN - 1 + 2 * k0 and len(track) >= TRACK_LEN:
            dx, dy = track[-1][0] - track[0][0], track[-1][1] - track[0][1]
            if dx * dx + dy * dy >= COURSE_MIN_BASELINE ** 2:
                age_s = ((TRACK_LEN - 1) * 0.5 + group_delay) / GNSS_HZ
                lead = math.atan(ANTENNA_AHEAD_M * yaw / v_now)
                course = wrap_pi(math.atan2(dx, dy) - lead + yaw * age_s)
                heading = course if heading is None else wrap_pi(heading + COURSE_GAIN * wrap_pi(course - heading))

        # position: filtered + dead reckoning since the delayed fix, back to the rear axle
        if filtered is None or heading is None or fixes < 2 * group_delay or len(odo_hist) < k0 + 2:
            continue
        a, b = odo_hist[-1 - k0], odo_hist[-2 - k0]
        ax = filtered[0] + odo[0] - (a[0] + (b[0] - a[0]) * w)
        ay = filtered[1] + odo[1] - (a[1] + (b[1] - a[1]) * w)
        sh, ch = math.sin(heading), math.cos(heading)
        x0, y0 = ax - ANTENNA_AHEAD_M * sh, ay - ANTENNA_AHEAD_M * ch
        # eq 7, dx/dt model, inputs [v, x, y, phi]
        u7 = np.array([v_now, x0, y0, delta])
        _dxdt = float(C7 @ s7 + D7 @ u7)
        s7 = A7 @ s7 + B7 @ u7
        if s5 is None:
            continue
        bias = v_now - v_model
        t = now * 1e-6
        rows.append(f"{t:.6f},{step},0.00,{x0:.2f},{y0:.2f},{wrap_pi(heading):.3f},{v_now:.2f},kinematic\n")
        kappa0 = kappa
        if rollout == "vector":
            vs = np.clip(O @ s5 + G * u + bias, 0.0, MAX_SPEED)
            dth = vs * (kappa0 * TS)
            th = heading + np.cumsum(dth)
            half = 0.5 * dth
            chord = vs * TS * (1.0 - half * half / 6.0)
            th_mid = th - half
            xs = x0 + np.cumsum(chord * np.sin(th_mid))
            ys = y0 + np.cumsum(chord * np.cos(th_mid))
            px, py, ph, pv = xs[out_idx].tolist(), ys[out_idx].tolist(), th[out_idx].tolist(), vs[out_idx].tolist()
        else:
            px, py, ph, pv = [], [], [], []
            s, x, y, th = s5.copy(), x0, y0, heading
            for k in range(1, HORIZON_STEPS + 1):
                vk = min(max(float(C5 @ s) + bias, 0.0), MAX_SPEED)
                s = A5 @ s + B5 * u
                d = vk * kappa0 * TS
                half = 0.5 * d
                chord = vk * TS * (1.0 - half * half / 6.0)
                x += chord * math.sin(th + half)
                y += chord * math.cos(th + half)
                th += d
                if k % OUTPUT_EVERY == 0:
                    px.append(x)
                    py.append(y)
                    ph.append(th)
                    pv.append(vk)
        for hz, qx, qy, qh, qv in zip(horizons, px, py, ph, pv):
            rows.append(f"{t:.6f},{step},{hz:.2f},{qx:.2f},{qy:.2f},{wrap_pi(qh):.3f},{qv:.2f},kinematic\n")
    t_looped = time.perf_counter()
    with open(out_path, "w") as f:
        f.writelines(rows)
    t_written = time.perf_counter()
    return {
        "rollout": rollout,
        "frames": int(len(t_us)),
        "ticks": int(len(ticks)),
        "import_s": T_IMPORTED - T_IMPORT0,
        "parse_decode_s": t_decoded - t0,
        "tick_loop_s": t_looped - t_decoded,
        "write_s": t_written - t_looped,
        "total_in_process_s": t_written - t0,
    }


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("log", help="candump log")
    p.add_argument("--out", required=True, help="predictions CSV")
    p.add_argument("--origin", help="LAT,LON of the local frame (default: the first fix)")
    p.add_argument("--rollout", choices=["vector", "loop"], default="vector")
    p.add_argument("--timing-json", help="write the phase times here")
    a = p.parse_args()
    origin = tuple(float(v) for v in a.origin.split(",")) if a.origin else None
    timing = run(a.log, a.out, origin, a.rollout)
    print(
        "replay_scipy: {frames} frames, {ticks} ticks, rollout {rollout}: parse+decode {parse_decode_s:.3f} s, "
        "tick loop {tick_loop_s:.3f} s, write {write_s:.3f} s (imports {import_s:.3f} s)".format(**timing),
        file=sys.stderr,
    )
    if a.timing_json:
        with open(a.timing_json, "w") as f:
            json.dump(timing, f, indent=1)


if __name__ == "__main__":
    main()
