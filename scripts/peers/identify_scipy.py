#!/usr/bin/env python3
"""The identification work of `catmodel identify`, written the way a NumPy/SciPy user would.

The peer of `catmodel identify` in `scripts/compare-peers.sh` (issue 7). Same CSV logs (the
simulator's, `simulate-drive`), same steps and settings as host/src/identify/:

  preprocess (every log): the columns onto the uniform 20 ms grid where all sensors overlap
    (numpy.interp), zero-phase FIR scipy.signal.filtfilt(firwin(21, 2 Hz, fs=50)) then MATLAB
    smooth(., 10) (a centred 9-sample mean shrinking at the ends, cumulative sums), GNSS to
    metres from each log's first fix (exact WGS-84 ECEF -> ENU), steering % -> centre angle,
    dx/dt and dy/dt by +-12-sample central differences, course (unwrapped, held below 1 m/s),
    yaw rate by a +-48-sample difference of the course;
  speed model (eq 5 form): ARX (eq 6) delay 0..60 at na = nb = 2 by least squares
    (numpy.linalg.lstsq), then na, nb in 1..3 by AIC; the ARX poles mapped to s as the
    first initial denominator (plus catmodel's three defaults); a 2nd-order proper continuous
    transfer function with input delay fitted by simulation error with
    scipy.optimize.least_squares (trf, all 5 TF coefficients, poles kept left of -0.1 1/s by
    bounds on the shifted denominator, experiments weighted 1/var(speed)), simulated with
    scipy.signal.cont2discrete (ZOH) + lfilter from the equilibrium of the first input; the
    delay searched over catmodel's grid (ARX delay +-20 samples: every third, then +-2 around
    the best two with 8-evaluation quick fits, then full fits at the best two delays from the
    first two initial denominators);
  dx/dt MISO (eq 7 form, inputs v, x, y, phi; proper 2nd-order blocks, no delay): started from
    the poles of a MISO ARX(2, 3, 0), 20 TF coefficients by least_squares (at most 40 iterations);
  lateral: steering gain and understeer by least_squares on yaw = v tan(g delta/(1+K v^2))/L
    (samples > 2 m/s, |delta| > 0.01 rad), then a first-order lag with delay 0..10 samples by
    simulation error (the same scan);
  validation: fit % as MATLAB compare, 100 (1 - ||y - yhat|| / ||y - mean y||), pure simulation
    from the inputs, over the concatenated training logs and the validation log.

Not done (catmodel does them too, they are reports, not estimation): the step-response table
(Fig 2), the 17-regressor correlation ranking, the kinematic baselines, MSE columns.
Differences in method: catmodel solves the numerator exactly for each trial denominator
(separable least squares) and runs Levenberg-Marquardt on the denominators only; here every
TF coefficient is a least_squares parameter (numerators started by one linear solve for the
initial denominators).

Prints the fits and times; --json FILE writes them (times in seconds, in-process).
"""
import argparse
import io
import json
import math
import os
import sys
import time
import tomllib
import warnings

T0 = time.perf_counter()
# One BLAS thread: the matrices are tiny (3x3 expm, 33 000 x 5 least squares), and OpenBLAS's
# worker threads cost 50x on expm when the cores are busy (measured: 5 ms vs 0.1 ms per call).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
import numpy as np  # noqa: E402
from scipy import signal  # noqa: E402
from scipy.optimize import least_squares  # noqa: E402

T_IMPORTED = time.perf_counter()
# cont2discrete warns about the unit numerators of the basis responses (leading zeros).
warnings.filterwarnings("ignore", category=signal.BadCoefficients)

TS = 0.02
FIR_TAPS = 21
CUTOFF_HZ = 2.0
SMOOTH_SPAN = 10
DIFF_HALF_WIDTH = 12
MAX_DELAY = 60
SIGMA = 0.1  # slowest accepted pole decay rate, 1/s (catmodel's MIN_DECAY_RATE_PER_S)
MAX_LATERAL_POLE = 25.0


# --- reading and preprocessing ----------------------------------------------------------
def read_log(path):
    """The log CSV (t,vel,input_vel,accel,steer,brake,lat,lon; empty = not reported) -> dict."""
    with open(path) as f:
        header = f.readline().strip().split(",")
        body = f.read()
    # Empty cells -> nan, so that numpy's C parser takes the file.
    body = body.replace(",,", ",nan,").replace(",,", ",nan,").replace(",\n", ",nan\n")
    if body.endswith(","):
        body += "nan"
    a = np.loadtxt(io.StringIO(body), delimiter=",", ndmin=2)
    return {h: a[:, i] for i, h in enumerate(header)}


def geodetic_to_enu(lat_deg, lon_deg, lat0, lon0):
    """WGS-84 geodetic -> ECEF -> east/north at the origin (height 0), m."""
    a, f = 6378137.0, 1.0 / 298.257223563
    e2 = f * (2.0 - f)

    def ecef(lat, lon):
        la, lo = np.radians(lat), np.radians(lon)
        n = a / np.sqrt(1.0 - e2 * np.sin(la) ** 2)
        return n * np.cos(la) * np.cos(lo), n * np.cos(la) * np.sin(lo), n * (1 - e2) * np.sin(la)

    x, y, z = ecef(lat_deg, lon_deg)
    x0, y0, z0 = ecef(lat0, lon0)
    dx, dy, dz = x - x0, y - y0, z - z0
    sp, cp = math.sin(math.radians(lat0)), math.cos(math.radians(lat0))
    sl, cl = math.sin(math.radians(lon0)), math.cos(math.radians(lon0))
    return -sl * dx + cl * dy, -sp * cl * dx - sp * sl * dy + cp * dz


def smooth(y, span):
    """MATLAB smooth(y, span), 'moving': centred mean, even span reduced by one, shrinking ends."""
    n = len(y)
    span = min(span, n)
    if span % 2 == 0:
        span -= 1
    if span <= 1:
        return y.copy()
    h = (span - 1) // 2
    k = np.arange(n)
    w = np.minimum(np.minimum(k, n - 1 - k), h)
    c = np.concatenate(([0.0], np.cumsum(y)))
    return (c[k + w + 1] - c[k - w]) / (2 * w + 1)


def derivative(x, h):
    n = len(x)
    k = np.arange(n)
    lo = np.maximum(k - h, 0)
    hi = np.minimum(k + h, n - 1)
    d = (hi - lo).astype(float)
    out = np.zeros(n)
    ok = d > 0
    out[ok] = (x[hi[ok]] - x[lo[ok]]) / (d[ok] * TS)
    return out


def course(dx, dy, min_speed=1.0):
    valid = np.hypot(dx, dy) >= min_speed
    out = np.zeros(len(dx))
    if not valid.any():
        return out
    idx = np.flatnonzero(valid)
    unwrapped = np.unwrap(np.arctan2(dx[idx], dy[idx]))
    # Hold the last valid value (the first valid one before it).
    pos = np.maximum.accumulate(np.where(valid, np.arange(len(dx)), -1))
    held = np.searchsorted(idx, np.maximum(pos, idx[0]))
    return unwrapped[held]


def preprocess(path, vehicle, taps):
    c = read_log(path)
    t = c["t"]
    cols = {}
    for name in ("vel", "input_vel", "steer"):
        m = ~np.isnan(c[name])
        cols[name] = (t[m], c[name][m])
    g = ~np.isnan(c["lat"]) & ~np.isnan(c["lon"])
    tg, lat, lon = t[g], c["lat"][g], c["lon"][g]
    t0 = max(cols["vel"][0][0], cols["input_vel"][0][0], cols["steer"][0][0], tg[0])
    t1 = min(cols["vel"][0][-1], cols["input_vel"][0][-1], cols["steer"][0][-1], tg[-1])
    n = int(math.floor((t1 - t0) / TS + 1e-9)) + 1
    grid = t0 + np.arange(n) * TS
    grid = grid[grid <= t1]
    xe, yn = geodetic_to_enu(lat, lon, lat[0], lon[0])

    def f(tt, v):
        return smooth(signal.filtfilt(taps, [1.0], np.interp(grid, tt, v)), SMOOTH_SPAN)

    e = {"name": path, "t": grid}
    e["vel"] = f(*cols["vel"])
    e["input_vel"] = f(*cols["input_vel"])
    steer = f(*cols["steer"])
    e["delta"] = np.clip(steer, -100, 100) / 100.0 * math.radians(vehicle["max_steer_deg"])
    e["x"] = f(tg, xe)
    e["y"] = f(tg, yn)
    e["dx"] = derivative(e["x"], DIFF_HALF_WIDTH)
    dy = derivative(e["y"], DIFF_HALF_WIDTH)
    e["heading"] = course(e["dx"], dy)
    yaw = derivative(e["heading"], 4 * DIFF_HALF_WIDTH)
    yaw[np.hypot(e["dx"], dy) < 1.0] = 0.0
    e["yaw"] = yaw
    return e


# --- simulation and transfer-function fits ------------------------------------------------
def fit_percent(y, yhat):
    return 100.0 * (1.0 - np.linalg.norm(y - yhat) / np.linalg.norm(y - np.mean(y)))


def delayed(u, d):
    if d == 0:
        return u
    return np.concatenate((np.full(d, u[0]), u[:-d]))


def discretize(num, den):
    """ZOH discretization (cont2discrete) and the unit-input steady state of lfilter."""
    numd, dend, _ = signal.cont2discrete((num, den), TS, method="zoh")
    b = np.ravel(numd)
    return b, dend, signal.lfilter_zi(b, dend)


def simulate(num, den, delay, u):
    """Pure simulation from the equilibrium of u[0], input delayed by whole samples."""
    b, a, zi = discretize(num, den)
    ud = delayed(u, delay)
    return signal.lfilter(b, a, ud, zi=zi * ud[0])[0]


def shifted(coeffs, s0):
    """Coefficients of p(s + s0) for p = [1, coeffs...] (Horner), without the leading 1."""
    out = np.array([1.0])
    for c in coeffs:
        out = np.polyadd(np.polymul(out, [1.0, s0]), [c])
    return out[1:]


class Miso:
    """Blocks (order, proper, delay); parameters per block: shifted-denominator coefficients
    (all > 0 <=> every pole left of -SIGMA, exact for orders 1 and 2), then the numerator."""

    def __init__(self, specs):
        self.specs = specs

    def split(self, p):
        out, at = [], 0
        for order, proper, _ in self.specs:
            q = p[at:at + order]
            at += order
            nn = order + 1 if proper else order
            num = p[at:at + nn]
            at += nn
            out.append((num, np.concatenate(([1.0], shifted(q, SIGMA)))))
        return out

    def bounds(self):
        lo, hi = [], []
        for order, proper, _ in self.specs:
            nn = order + 1 if proper else order
            lo += [0.0] * order + [-np.inf] * nn
            hi += [np.inf] * (order + nn)
        return np.array(lo), np.array(hi)

    def simulate(self, p, inputs_per_exp):
        blocks = [discretize(num, den) for num, den in self.split(p)]
        outs = []
        for inputs in inputs_per_exp:
            y = 0.0
            for (b, a, zi), (_, _, d), u in zip(blocks, self.specs, inputs):
                ud = delayed(u, d)
                y = y + signal.lfilter(b, a, ud, zi=zi * ud[0])[0]
            outs.append(y)
        return outs

    def initial(self, dens, inputs_per_exp, outputs, weights):
        """Parameters for the denominators `dens` with the numerators by linear least squares."""
        cols = []
        for (order, proper, d), den in zip(self.specs, dens):
            full = np.concatenate(([1.0], den))
            nn = order + 1 if proper else order
            for i in range(nn):
                num = np.zeros(nn)
                num[i] = 1.0
                cols.append(discretize(num, full))
        mats = []
        for inputs, w in zip(inputs_per_exp, weights):
            m = []
            j = 0
            for (order, proper, d), u in zip(self.specs, inputs):
                nn = order + 1 if proper else order
                ud = delayed(u, d)
                for _ in range(nn):
                    b, a, zi = cols[j]
                    m.append(signal.lfilter(b, a, ud, zi=zi * ud[0])[0])
                    j += 1
            mats.append(np.sqrt(w) * np.column_stack(m))
        phi = np.vstack(mats)
        y = np.concatenate([np.sqrt(w) * o for o, w in zip(outputs, weights)])
        theta = np.linalg.lstsq(phi, y, rcond=None)[0]
        p, at = [], 0
        for (order, proper, _), den in zip(self.specs, dens):
            nn = order + 1 if proper else order
            p += list(np.maximum(shifted(den, -SIGMA), 1e-6)) + list(theta[at:at + nn])
            at += nn
        return np.array(p)


def oe_fit(specs, dens, inputs_per_exp, outputs, weights, max_nfev):
    """Simulation-error fit from initial denominators; returns (params, cost, model)."""
    model = Miso(specs)
    sw = np.sqrt(np.asarray(weights))
    y = np.concatenate([w * o for o, w in zip(outputs, sw)])

    def residual(p):
        return np.concatenate([w * s for s, w in zip(model.simulate(p, inputs_per_exp), sw)]) - y

    p0 = model.initial(dens, inputs_per_exp, outputs, weights)
    lo, hi = model.bounds()
    r = least_squares(residual, p0, bounds=(lo, hi), method="trf", x_scale="jac",
                      max_nfev=max_nfev)
    return r.x, 2.0 * r.cost, model


def fit_siso_with_delay_scan(u, y, w, order, proper, candidates, inits, max_nfev):
    """catmodel's delay search: quick fits every third candidate, then +-2 around the best two,
    full fits at the best two delays from the first two initial denominators."""
    inputs = [[ui] for ui in u]

    def quick(d):
        try:
            return oe_fit([(order, proper, d)], [inits[0]], inputs, y, w, 8)[1]
        except (ValueError, np.linalg.LinAlgError):
            return math.inf

    scan = {d: quick(d) for d in candidates[::3]}
    for centre in sorted(scan, key=scan.get)[:2]:
        for d in candidates:
            if abs(d - centre) <= 2 and d not in scan:
                scan[d] = quick(d)
    best = None
    for d in sorted(scan, key=scan.get)[:2]:
        for init in inits[:2]:
            try:
                p, cost, model = oe_fit([(order, proper, d)], [init], inputs, y, w, max_nfev)
            except (ValueError, np.linalg.LinAlgError):
                continue
            if best is None or cost < best[1]:
                best = (p, cost, model, d)
    return best, scan


def arx(u_list, y_list, na, nb, nk):
    """Least-squares ARX (eq 6), rows inside each experiment; returns (a, b, mean sq error)."""
    lag = max([na] + [b + k for b, k in zip(nb, nk)])
    mats, ys = [], []
    for us, y in zip(u_list, y_list):
        n = len(y)
        cols = [-y[lag - i:n - i] for i in range(1, na + 1)]
        for u, b, k in zip(us, nb, nk):
            cols += [u[lag - k - i:n - k - i] for i in range(b)]
        mats.append(np.column_stack(cols))
        ys.append(y[lag:])
    phi, yy = np.vstack(mats), np.concatenate(ys)
    theta = np.linalg.lstsq(phi, yy, rcond=None)[0]
    loss = np.mean((yy - phi @ theta) ** 2)
    return np.concatenate(([1.0], theta[:na])), theta[na:], loss, len(yy)


def den_from_discrete(a):
    """Monic continuous denominator (no leading 1) from discrete poles, s = ln(z)/Ts."""
    z = np.roots(a)
    if np.any(np.abs(z) >= 1.0) or np.any((np.abs(z.imag) < 1e-12) & (z.real <= 0.0)):
        return None
    s = np.log(z.astype(complex)) / TS
    return np.real(np.poly(s))[1:]


def identify_speed(train):
    u = [e["input_vel"] for e in train]
    y = [e["vel"] for e in train]
    w = [1.0 / np.var(v) if np.var(v) > 1e-12 else 1.0 for v in y]
    us = [[x] for x in u]
    nk = min(range(MAX_DELAY + 1), key=lambda k: arx(us, y, 2, [2], [k])[2])
    best = None
    for na in range(1, 4):
        for nb in range(1, 4):
            a, _, loss, rows = arx(us, y, na, [nb], [nk])
            aic = rows * math.log(max(loss, 1e-300)) + 2 * (na + nb)
            if best is None or aic < best[0]:
                best = (aic, a)
    inits = []
    d = den_from_discrete(best[1])
    if d is not None and len(d) == 2:
        inits.append(d)
    elif d is not None and len(d) == 1:
        inits.append(np.array([d[0] + 5.0, d[0] * 5.0]))
    inits += [np.array(x) for x in ([2.0, 1.0], [1.0, 0.25], [4.0, 4.0])]
    candidates = list(range(max(nk - 20, 0), min(nk + 20, MAX_DELAY) + 1))
    (p, cost, model, delay), scan = fit_siso_with_delay_scan(u, y, w, 2, True, candidates, inits, 100)
    num, den = model.split(p)[0]
    return num, den, delay, nk


def identify_dx_dt(train, base_dx_dt):
    inputs = [[e["vel"], e["x"], e["y"], e["delta"]] for e in train]
    y = [e["dx"] for e in train]
    a, _, _, _ = arx(inputs, y, 2, [3] * 4, [0] * 4)
    d = den_from_discrete(a)
    if d is not None and len(d) == 2:
        dens = [d] * 4
    else:
        # As catmodel: without usable (stable, positive real or complex) ARX poles, start from
        # the base model's eq 7 poles.
        dens = [np.asarray(b["den"][1:]) / b["den"][0] for b in base_dx_dt["blocks"]]
    specs = [(2, True, 0)] * 4
    p, _, model = oe_fit(specs, dens, inputs, y, [1.0] * len(train), 40)
    return [(num, den) for num, den in model.split(p)]


def identify_lateral(train, vehicle):
    v = np.concatenate([e["vel"] for e in train])
    dl = np.concatenate([e["delta"] for e in train])
    r = np.concatenate([e["yaw"] for e in train])
    m = (v > 2.0) & (np.abs(dl) > 0.01)
    v, dl, r = v[m], dl[m], r[m]
    L = vehicle["wheelbase_m"]
    k0 = vehicle["understeer_s2_per_m2"]
    estimate_k = np.ptp(v) > 2.0

    def res(p):
        g, k = p if estimate_k else (p[0], k0)
        return r - v * np.tan(g * dl / (1.0 + k * v * v)) / L

    if estimate_k:
        sol = least_squares(res, [1.0, k0], bounds=([-np.inf, 0.0], [np.inf, np.inf]),
                            x_scale="jac")
        g, k = sol.x
    else:
        g, k = least_squares(res, [1.0]).x[0], k0
    r_kin = [e["vel"] * np.tan(g * e["delta"] / (1.0 + k * e["vel"] ** 2)) / L for e in train]
    yaw = [e["yaw"] for e in train]
    (p, _, model, delay), _ = fit_siso_with_delay_scan(
        r_kin, yaw, [1.0] * len(train), 1, False, list(range(11)),
        [np.array([1.0]), np.array([5.0])], 100)
    num, den = model.split(p)[0]
    if den[1] > MAX_LATERAL_POLE:
        dc = num[-1] / den[-1]
        num, den = np.array([dc * MAX_LATERAL_POLE]), np.array([1.0, MAX_LATERAL_POLE])
    return g, k, num, den, delay


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("logs", nargs="+", help="training log CSVs")
    ap.add_argument("--validate", required=True, help="validation log CSV")
    ap.add_argument("--base", default="models/paper.toml", help="model file with [vehicle]")
    ap.add_argument("--speed-only", action="store_true", help="only the speed model")
    ap.add_argument("--json", help="write fits and times here")
    args = ap.parse_args()

    t_start = time.perf_counter()
    with open(args.base, "rb") as f:
        base = tomllib.load(f)
    vehicle = base["vehicle"]
    taps = signal.firwin(FIR_TAPS, CUTOFF_HZ, fs=1.0 / TS)
    train = [preprocess(p, vehicle, taps) for p in args.logs]
    val = [preprocess(args.validate, vehicle, taps)]
    t_pre = time.perf_counter()

    num, den, delay, nk = identify_speed(train)
    out = {"speed": {"num": list(num), "den": list(den), "delay_s": delay * TS, "arx_nk": nk}}
    if not args.speed_only:
        dx = identify_dx_dt(train, base["dx_dt"])
        g, k, lnum, lden, ldelay = identify_lateral(train, vehicle)
        out["lateral"] = {"steer_gain": g, "understeer": k, "num": list(lnum),
                          "den": list(lden), "delay_s": ldelay * TS}
    t_fit = time.perf_counter()

    def speed_fit(es):
        y = np.concatenate([e["vel"] for e in es])
        yh = np.concatenate([simulate(num, den, delay, e["input_vel"]) for e in es])
        return fit_percent(y, yh)

    out["speed"]["training_fit_percent"] = speed_fit(train)
    out["speed"]["validation_fit_percent"] = speed_fit(val)
    if not args.speed_only:
        def dx_fit(es):
            y = np.concatenate([e["dx"] for e in es])
            yh = np.concatenate([
                sum(simulate(n_, d_, 0, e[c]) for (n_, d_), c in zip(dx, ("vel", "x", "y", "delta")))
                for e in es])
            return fit_percent(y, yh)

        def yaw_fit(es):
            y = np.concatenate([e["yaw"] for e in es])
            yh = np.concatenate([
                simulate(lnum, lden, ldelay, e["vel"] * np.tan(
                    g * e["delta"] / (1.0 + k * e["vel"] ** 2)) / vehicle["wheelbase_m"])
                for e in es])
            return fit_percent(y, yh)

        out["dx_dt"] = {"training_fit_percent": dx_fit(train), "validation_fit_percent": dx_fit(val)}
        out["lateral"]["training_fit_percent"] = yaw_fit(train)
        out["lateral"]["validation_fit_percent"] = yaw_fit(val)
    t_end = time.perf_counter()
    out["times_s"] = {
        "imports": T_IMPORTED - T0,
        "read_and_preprocess": t_pre - t_start,
        "identify": t_fit - t_pre,
        "validate": t_end - t_fit,
        "identify_and_validate": t_end - t_pre,
        "total_in_process": t_end - t_start,
    }
    s = out["speed"]
    print(f"speed model: delay {s['delay_s']:.2f} s, num {np.round(num, 5).tolist()}, "
          f"den {np.round(den, 5).tolist()} (ARX nk {nk})")
    print(f"speed fit: training {s['training_fit_percent']:.2f} %, "
          f"validation {s['validation_fit_percent']:.2f} %")
    if not args.speed_only:
        print(f"dx/dt fit: training {out['dx_dt']['training_fit_percent']:.2f} %, "
              f"validation {out['dx_dt']['validation_fit_percent']:.2f} %")
        la = out["lateral"]
        print(f"lateral: steer_gain {g:.4f}, understeer {k:.5f}, fit training "
              f"{la['training_fit_percent']:.2f} %, validation {la['validation_fit_percent']:.2f} %")
    ts = out["times_s"]
    print(f"time: read+preprocess {ts['read_and_preprocess']:.3f} s, identify "
          f"{ts['identify']:.3f} s, validate {ts['validate']:.3f} s, in-process total "
          f"{ts['total_in_process']:.3f} s (imports {ts['imports']:.3f} s)", file=sys.stderr)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
