#!/usr/bin/env python3
"""Independent SIL driver for `catmodel sil --stdio` (reviewer's own; plant, DBC reader, planner).

Plant: dynamic single-track with saturating (tanh) tyres above 3 m/s, kinematic below; steering
actuator: dead time + rate limit + first-order lag, road-wheel gain factor (real vs model);
speed loop: first-order-plus-dead-time with accel/decel limits; GNSS: white noise + Gauss-Markov
bias at a chosen rate. Planner: LOCAL_ORIGIN, paths (4 frames/tick), obstacles, replacement.

Usage: scripts/sil-drive.py SCENARIO [options]; prints one JSON line of metrics. Written for a
black-box review (docs/findings.md: "A lower target speed beyond the controller's 2 s horizon",
e.g. `python3 scripts/sil-drive.py speedstep --speed 20 --speed2 5 --step-at 300 --length 500`,
`straight --speed 20 --length 600 --max-decel 3.5`); CI runs one of its drives (the truck's S-curve at 10 m/s, .ci/run); scripts/sil-sim.py is the CI's simulator.
"""
import argparse, json, math, random, re, subprocess, sys, os
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = Path(__file__).resolve().parent.parent
DBC = str(REPO / "catmodel.dbc")
BASE_MODEL = str(REPO / "models" / "paper.toml")
LAT_GAIN = None
TICK = 0.02
SUB = 0.002

# ------------------------------------------------------------------ DBC (own reader)
class Sig:
    pass

def read_dbc(path):
    msgs, byid = {}, {}
    cur = None
    for line in open(path):
        line = line.strip()
        m = re.match(r"BO_ (\d+) (\w+): (\d+)", line)
        if m:
            rid = int(m.group(1))
            cur = dict(name=m.group(2), ext=bool(rid & 0x80000000), id=rid & 0x1FFFFFFF,
                       dlc=int(m.group(3)), sigs={})
            msgs[cur["name"]] = cur
            byid[(cur["ext"], cur["id"])] = cur
            continue
        m = re.match(r"SG_ (\w+)\s*(M|m\d+)?\s*: (\d+)\|(\d+)@1([+-]) \(([^,]+),([^)]+)\) \[([^|]+)\|([^\]]+)\]", line)
        if m and cur:
            s = Sig()
            s.name, s.mux = m.group(1), m.group(2)
            s.start, s.len = int(m.group(3)), int(m.group(4))
            s.signed = m.group(5) == "-"
            s.scale, s.off = float(m.group(6)), float(m.group(7))
            s.lo, s.hi = float(m.group(8)), float(m.group(9))
            cur["sigs"][s.name] = s
    return msgs, byid

def crc8(data):
    c = 0xFF
    for b in data:
        c ^= b
        for _ in range(8):
            c = ((c << 1) ^ 0x1D) & 0xFF if c & 0x80 else (c << 1) & 0xFF
    return c ^ 0xFF

def enc(msg, vals, fill=0):
    w = int.from_bytes(bytes([fill]) * msg["dlc"], "little")
    for k, v in vals.items():
        s = msg["sigs"][k]
        raw = int(round((v - s.off) / s.scale))
        lo = -(1 << (s.len - 1)) if s.signed else 0
        hi = (1 << (s.len - 1)) - 1 if s.signed else (1 << s.len) - 1
        raw = max(lo, min(hi, raw))
        mask = (1 << s.len) - 1
        w = (w & ~(mask << s.start)) | ((raw & mask) << s.start)
    d = bytearray(w.to_bytes(msg["dlc"], "little"))
    if "crc" in msg["sigs"]:
        d[7] = crc8(bytes([(msg["id"] >> 8) & 0xFF, msg["id"] & 0xFF]) + bytes(d[:7]))
    return bytes(d)

def dec(msg, d):
    """returns (values with raw too), crc_ok"""
    ok = True
    if "crc" in msg["sigs"]:
        ok = crc8(bytes([(msg["id"] >> 8) & 0xFF, msg["id"] & 0xFF]) + d[:7]) == d[7]
    w = int.from_bytes(d, "little")
    out, raws = {}, {}
    for k, s in msg["sigs"].items():
        raw = (w >> s.start) & ((1 << s.len) - 1)
        if s.signed and raw >= 1 << (s.len - 1):
            raw -= 1 << s.len
        raws[k] = raw
        out[k] = raw * s.scale + s.off
    return out, raws, ok

def line(t, msg, data):
    ident = f"{msg['id']:08X}" if msg["ext"] else f"{msg['id']:03X}"
    return f"({t:.6f}) can0 {ident}#{data.hex().upper()}"

# ------------------------------------------------------------------ geodesy (exact ECEF/ENU)
A, F = 6378137.0, 1 / 298.257223563
E2 = F * (2 - F)
ORIGIN = (48.1372, 11.5756)  # Munich, not the project's Tucson

def geo2ecef(lat, lon, h=0.0):
    la, lo = math.radians(lat), math.radians(lon)
    N = A / math.sqrt(1 - E2 * math.sin(la) ** 2)
    return ((N + h) * math.cos(la) * math.cos(lo), (N + h) * math.cos(la) * math.sin(lo),
            (N * (1 - E2) + h) * math.sin(la))

def ecef2geo(x, y, z):
    lon = math.atan2(y, x)
    p = math.hypot(x, y)
    lat = math.atan2(z, p * (1 - E2))
    for _ in range(6):
        N = A / math.sqrt(1 - E2 * math.sin(lat) ** 2)
        h = p / math.cos(lat) - N
        lat = math.atan2(z, p * (1 - E2 * N / (N + h)))
    return math.degrees(lat), math.degrees(lon)

O_ECEF = geo2ecef(*ORIGIN)

def enu2geo(e, n):
    la, lo = math.radians(ORIGIN[0]), math.radians(ORIGIN[1])
    sl, cl, so, co = math.sin(la), math.cos(la), math.sin(lo), math.cos(lo)
    u = 0.0
    dx = -so * e - sl * co * n + cl * co * u
    dy = co * e - sl * so * n + cl * so * u
    dz = cl * n + sl * u
    return ecef2geo(O_ECEF[0] + dx, O_ECEF[1] + dy, O_ECEF[2] + dz)

# ------------------------------------------------------------------ cars
CARS = {
    # L, width, length, rear_overhang, max_steer_deg, steer_rate %/s, antenna_ahead, mass, Iz, lf frac, Cf, Cr
    "default": dict(L=2.62, W=1.806, Len=4.437, ro=0.909, maxdeg=35.5, rate=60.0, ant=1.478,
                    m=1741.0, Iz=2500.0, lf=1.142, Cf=80000.0, Cr=91000.0, mu=0.9),
    "small": dict(L=2.30, W=1.60, Len=3.55, ro=0.55, maxdeg=34.0, rate=90.0, ant=1.0,
                  m=1050.0, Iz=1300.0, lf=0.95, Cf=55000.0, Cr=60000.0, mu=0.9),
    "truck": dict(L=4.80, W=2.30, Len=7.6, ro=1.4, maxdeg=32.0, rate=40.0, ant=3.0,
                  m=5500.0, Iz=28000.0, lf=2.0, Cf=160000.0, Cr=240000.0, mu=0.8),
}

def make_model(car, gnss_hz, pos_unc, out, steer_lag=None, dynamics=True):
    t = open(BASE_MODEL).read()
    def sub(key, val):
        nonlocal t
        t, n = re.subn(rf"^{key} = [^\n#]*", f"{key} = {val}", t, flags=re.M)
        assert n == 1, key
    sub("wheelbase_m", car["L"]); sub("max_steer_deg", car["maxdeg"])
    sub("antenna_ahead_m", car["ant"]); sub("gnss_rate_hz", float(gnss_hz))
    sub("width_m", car["W"]); sub("length_m", car["Len"]); sub("rear_overhang_m", car["ro"])
    sub("max_steer_rate_pct_per_s", car["rate"]); sub("position_uncertainty_m", pos_unc)
    # understeer of the plant's linear tyres: K = m (Cr lr - Cf lf)/(Cf Cr L^2)
    lr = car["L"] - car["lf"]
    K = car["m"] * (car["Cr"] * lr - car["Cf"] * car["lf"]) / (car["Cf"] * car["Cr"] * car["L"] ** 2)
    sub("understeer_s2_per_m2", round(K, 6))
    sub("mass_kg", car["m"]); sub("yaw_inertia_kg_m2", car["Iz"])
    sub("cg_to_front_m", car["lf"]); sub("cg_to_rear_m", round(lr, 4))
    sub("cornering_front_n_per_rad", car["Cf"]); sub("cornering_rear_n_per_rad", car["Cr"])
    if gnss_hz < 10:
        sub("gnss_lost_s", max(2.0, 3.0 / gnss_hz))
    if steer_lag is not None:
        t = t.replace("max_steer_rate_pct_per_s =", f"steer_lag_s = {steer_lag}\nmax_steer_rate_pct_per_s =", 1)
    if LAT_GAIN is not None:
        t += f"""
[lateral]
steer_gain = {LAT_GAIN}
understeer_s2_per_m2 = {round(K, 6)}
equation = "yaw rate = G(s) v tan(g delta / (1 + K v^2)) / L, G first order"
output = "yaw_rate"
output_unit = "rad/s"

[[lateral.blocks]]
input = "yaw_rate_kinematic"
input_unit = "rad/s"
num = [0.0, 25.0]
den = [1.0, 25.0]
delay_s = 0.0
"""
    if not dynamics:
        t = re.sub(r"\[dynamics\].*?(?=\n\[inputs\])", "", t, flags=re.S)
    open(out, "w").write(t)

class Plant:
    def __init__(s, car, a):
        s.c = car; s.a = a
        s.L = car["L"]; s.lf = car["lf"]; s.lr = car["L"] - car["lf"]
        s.x = s.y = 0.0  # rear axle east/north
        s.h = a.start_heading
        s.v = 0.0; s.vy = 0.0; s.r = 0.0
        s.steer = 0.0; s.ramp = 0.0; s.steer_q = []; s.speed_q = []; s.vt = 0.0
        s.sq_cmd = 0.0
    def wheel(s):
        return s.steer / 100.0 * math.radians(s.c["maxdeg"]) * s.a.steer_gain
    def step(s, t, steer_cmd, speed_cmd):
        a = s.a
        s.steer_q.append((t + a.steer_dead, steer_cmd))
        while s.steer_q and s.steer_q[0][0] <= t + 1e-9:
            s.sq_cmd = s.steer_q.pop(0)[1]
        d = s.c["rate"] * a.rate_factor * SUB
        s.ramp += max(-d, min(d, s.sq_cmd - s.ramp))
        s.steer += (s.ramp - s.steer) * SUB / a.steer_lag
        s.speed_q.append((t + a.speed_dead, speed_cmd))
        while s.speed_q and s.speed_q[0][0] <= t + 1e-9:
            s.vt = s.speed_q.pop(0)[1]
        acc = (s.vt - s.v) / a.speed_lag
        acc = max(-a.max_decel, min(a.max_accel, acc))
        s.v = max(0.0, s.v + acc * SUB)
        delta = s.wheel()
        c = s.c
        if s.v < 3.0:
            s.r = s.v * math.tan(delta) / s.L
            s.vy = s.lr * s.r  # CG lateral velocity: rear axle has none
            beta_rear = 0.0
        else:
            vx = s.v
            af = math.atan2(s.vy + s.lf * s.r, vx) - delta
            ar = math.atan2(s.vy - s.lr * s.r, vx)
            g = 9.81
            Fzf = c["m"] * g * s.lr / s.L; Fzr = c["m"] * g * s.lf / s.L
            Ff = -c["mu"] * Fzf * math.tanh(c["Cf"] * af / (c["mu"] * Fzf))
            Fr = -c["mu"] * Fzr * math.tanh(c["Cr"] * ar / (c["mu"] * Fzr))
            dvy = (Ff * math.cos(delta) + Fr) / c["m"] - vx * s.r
            dr = (s.lf * Ff * math.cos(delta) - s.lr * Fr) / c["Iz"]
            s.vy += dvy * SUB; s.r += dr * SUB
        # rear axle velocity in body frame: (v, vy - lr r); heading clockwise from north, + r = right turn
        side = s.vy - s.lr * s.r  # + = right
        s.x += (s.v * math.sin(s.h) + side * math.cos(s.h)) * SUB
        s.y += (s.v * math.cos(s.h) - side * math.sin(s.h)) * SUB
        s.h += s.r * SUB
    def corners(s):
        fwd = (math.sin(s.h), math.cos(s.h)); rgt = (math.cos(s.h), -math.sin(s.h))
        W = s.c["W"] / 2; fr = s.c["Len"] - s.c["ro"]; re_ = -s.c["ro"]
        return [(s.x + fwd[0] * l + rgt[0] * w, s.y + fwd[1] * l + rgt[1] * w)
                for l in (fr, re_) for w in (-W, W)]
    def antenna(s):
        return s.x + s.c["ant"] * math.sin(s.h), s.y + s.c["ant"] * math.cos(s.h)

# ------------------------------------------------------------------ paths
def straight(p0, h, length, step):
    out = []
    n = int(round(length / step))
    for i in range(1, n + 1):
        out.append((p0[0] + i * step * math.sin(h), p0[1] + i * step * math.cos(h)))
    return out

def arc(p0, h, radius, angle, step):
    """angle>0 turns right (clockwise)"""
    out = []
    n = max(1, int(round(abs(angle) * radius / step)))
    x, y, hh = p0[0], p0[1], h
    for i in range(1, n + 1):
        dh = angle / n
        chord = 2 * radius * math.sin(abs(dh) / 2)
        hm = hh + dh / 2
        x += chord * math.sin(hm); y += chord * math.cos(hm); hh += dh
        out.append((x, y))
    return out, hh

class Path:
    def __init__(s, pts, v, left, right):
        s.pts = pts
        s.v = v if isinstance(v, list) else [v] * len(pts)
        s.l = left if isinstance(left, list) else [left] * len(pts)
        s.r = right if isinstance(right, list) else [right] * len(pts)
        s.s = [0.0]
        for a, b in zip(pts, pts[1:]):
            s.s.append(s.s[-1] + math.hypot(b[0] - a[0], b[1] - a[1]))
    def project(s, x, y):
        best = None
        for i in range(len(s.pts) - 1):
            (x0, y0), (x1, y1) = s.pts[i], s.pts[i + 1]
            dx, dy = x1 - x0, y1 - y0
            L2 = dx * dx + dy * dy
            u = ((x - x0) * dx + (y - y0) * dy) / L2
            uc = max(0.0, min(1.0, u))
            px, py = x0 + uc * dx, y0 + uc * dy
            dist = math.hypot(x - px, y - py)
            if best is None or dist < best[0]:
                Ls = math.sqrt(L2)
                # signed: + = right of path direction
                cross = (dx * (y - y0) - dy * (x - x0)) / Ls  # + = left
                best = (dist, i, u, uc, -cross)
        dist, i, u, uc, off = best
        st = s.s[i] + uc * (s.s[i + 1] - s.s[i])
        beyond = (i == 0 and u < 0) or (i == len(s.pts) - 2 and u > 1)
        lim = max(s.v[i], s.v[i + 1])
        left = s.l[i] + uc * (s.l[i + 1] - s.l[i]); right = s.r[i] + uc * (s.r[i + 1] - s.r[i])
        along_end = None
        if i == len(s.pts) - 2:
            along_end = (u - 1) * math.sqrt((s.pts[-1][0] - s.pts[-2][0]) ** 2 + (s.pts[-1][1] - s.pts[-2][1]) ** 2)
        return dict(dist=dist, off=off, st=st, beyond=beyond, lim=lim, left=left, right=right,
                    i=i, along_end=along_end, vmin_ahead=None)

def build(pieces, p0=(0.0, 0.0), h=math.pi / 2, step=1.0):
    pts = [p0]
    for kind, *args in pieces:
        if kind == "S":
            pts += straight(pts[-1], h, args[0], step)
        else:
            seg, h = arc(pts[-1], h, args[0], args[1], step)
            pts += seg
    return pts

def scenario(name, a):
    """returns list of (send_time, path_id, Path), obstacles [(slot, t_on, t_off, e, n, r)], t_max, extra"""
    V = a.speed
    obs = []
    paths = []
    lw, rw = a.left, a.right
    if name == "scurve":
        pts = build([("S", 40), ("A", 25, -math.pi / 3), ("A", 25, 2 * math.pi / 3), ("A", 25, -math.pi / 3), ("S", 40)])
        paths.append((0.0, 1, Path(pts, V, lw, rw)))
    elif name == "uturn":
        pts = build([("S", 35), ("A", a.radius, -math.pi), ("S", 35)], step=0.5)
        v = [V] * len(pts)
        paths.append((0.0, 1, Path(pts, v, lw, rw)))
    elif name == "straight":
        pts = build([("S", a.length)], step=5.0)
        paths.append((0.0, 1, Path(pts, V, lw, rw)))
    elif name == "speedstep":
        pts = build([("S", a.length)], step=2.0)
        v = [V if (s * 2.0) < a.step_at else a.speed2 for s in range(len(pts))]
        paths.append((0.0, 1, Path(pts, v, lw, rw)))
    elif name == "curve":
        p1 = build([("S", a.length)], step=2.0)
        p2 = build([("A", a.radius, math.pi / 2), ("S", 60)], p0=p1[-1], step=2.0)[1:]
        pts = p1 + p2
        v = [V] * len(p1) + [a.speed2] * len(p2)
        paths.append((0.0, 1, Path(pts, v, lw, rw)))
    elif name == "replace":
        pts = build([("S", 300)], step=2.0)
        paths.append((0.0, 1, Path(pts, V, lw, rw)))
        # at t_replace: a path from ahead of the car, shifted left by a.shift, then a right curve
        extra = dict(replace_at=a.replace_at)
        paths.append(("replace", 2, None))
    elif name == "obstacle":
        pts = build([("S", a.length)], step=1.0)
        paths.append((0.0, 1, Path(pts, V, lw, rw)))
        for k, spec in enumerate(a.obs):
            # spec: along,offset(+right),radius[,t_on]
            f = [float(x) for x in spec.split(",")]
            t_on = f[3] if len(f) > 3 else 0.0
            obs.append((k, t_on, 1e9, f[0], -f[1], f[2]))  # path runs east from (0,0): north = -offset
    else:
        sys.exit("unknown scenario " + name)
    return paths, obs

# ------------------------------------------------------------------ main
def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("scenario")
    ap.add_argument("--car", default="default")
    ap.add_argument("--speed", type=float, default=8.0)
    ap.add_argument("--speed2", type=float, default=5.0)
    ap.add_argument("--step-at", type=float, default=150.0)
    ap.add_argument("--length", type=float, default=200.0)
    ap.add_argument("--radius", type=float, default=7.0)
    ap.add_argument("--left", type=float, default=1.75)
    ap.add_argument("--right", type=float, default=1.75)
    ap.add_argument("--obs", action="append", default=[], help="along,offset_right,radius[,t_on]")
    ap.add_argument("--replace-at", type=float, default=15.0)
    ap.add_argument("--shift", type=float, default=2.0)
    ap.add_argument("--start-offset", type=float, default=0.0, help="car start, m right of path start")
    ap.add_argument("--start-back", type=float, default=0.0, help="car start, m behind path start")
    ap.add_argument("--start-heading-deg", type=float, default=0.0, help="relative to path, + right")
    ap.add_argument("--gnss-hz", type=float, default=10.0)
    ap.add_argument("--gnss-white", type=float, default=0.02)
    ap.add_argument("--gnss-bias", type=float, default=0.0, help="bias sigma per axis (tau 60 s)")
    ap.add_argument("--pos-unc", type=float, default=0.5)
    ap.add_argument("--glitch-at", type=float, default=None, help="s after engagement: fixes moved sideways")
    ap.add_argument("--glitch-m", type=float, default=1.0, help="the glitch's step to the right, m")
    ap.add_argument("--glitch-fixes", type=int, default=2, help="how many fixes the glitch moves")
    ap.add_argument("--cog-from-fixes", action="store_true",
                    help="COG and SOG differenced from the reported fixes (as some receivers do), not Doppler")
    ap.add_argument("--no-cog", action="store_true",
                    help="the receiver sends no COG and SOG at all: positions only")
    ap.add_argument("--steer-gain", type=float, default=1.0)
    ap.add_argument("--rate-factor", type=float, default=1.0)
    ap.add_argument("--steer-lag", type=float, default=0.06)
    ap.add_argument("--steer-dead", type=float, default=0.02)
    ap.add_argument("--declare-lag", type=float, default=None)
    ap.add_argument("--speed-dead", type=float, default=0.25)
    ap.add_argument("--speed-lag", type=float, default=0.8)
    ap.add_argument("--max-accel", type=float, default=2.0)
    ap.add_argument("--max-decel", type=float, default=5.0)
    ap.add_argument("--launch", type=float, default=3.0)
    ap.add_argument("--no-dynamics", action="store_true")
    ap.add_argument("--lateral-gain", type=float, default=None, help="declare [lateral] steer_gain")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--push-at", type=float, default=None)
    ap.add_argument("--push-steer", type=float, default=60.0)
    ap.add_argument("--push-dur", type=float, default=2.0)
    ap.add_argument("--replan-after", type=float, default=None, help="s after status 3/lost_path: send a new path from the car")
    ap.add_argument("--tmax", type=float, default=0.0)
    ap.add_argument("--out", default=None)
    ap.add_argument("--catmodel", default=str(REPO / "target" / "release" / "catmodel"))
    a = ap.parse_args()
    a.start_heading = math.pi / 2 + math.radians(a.start_heading_deg)

    global LAT_GAIN
    LAT_GAIN = a.lateral_gain
    msgs, byid = read_dbc(DBC)
    car = CARS[a.car]
    model = HERE / f"model_{os.getpid()}.toml"
    make_model(car, a.gnss_hz, a.pos_unc, model, a.declare_lag, not a.no_dynamics)
    rng = random.Random(a.seed)
    paths, obs = scenario(a.scenario, a)
    P = Plant(car, a)
    P.x = -a.start_back; P.y = -a.start_offset
    node = subprocess.Popen([a.catmodel, "sil", "--stdio", "--model", str(model)],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, bufsize=1)
    cnt = {}
    def pl(name, vals):
        c = cnt.get(name, 0); cnt[name] = (c + 1) % 16
        return line_later(name, {"counter": c, **vals})
    def line_later(name, vals):
        return (msgs[name], enc(msgs[name], vals))
    outbox = [pl("LOCAL_ORIGIN", {"page": 0, "latitude_deg": ORIGIN[0]}),
              pl("LOCAL_ORIGIN", {"page": 1, "longitude_deg": ORIGIN[1]})]
    def send_path(pid, path):
        frames = [pl("PATH_HEADER", {"path_id": pid, "count": len(path.pts)})]
        for i, (e, n) in enumerate(path.pts):
            frames.append(pl("PATH_POINT", {"path_id": pid, "index": i, "east_m": e, "north_m": n}))
            frames.append(pl("PATH_LIMITS", {"path_id": pid, "index": i, "speed_mps": path.v[i],
                                              "left_m": path.l[i], "right_m": path.r[i]}))
        return frames
    active = None  # path we score against
    pending = []   # (time_when_fully_sent_approx, path)
    t_max = a.tmax or 0.0
    for (ts, pid, path) in paths:
        if ts == 0.0:
            outbox += send_path(pid, path)
            active = path
            if not t_max:
                t_max = 12.0 + path.s[-1] / max(min(path.v), 1.0) * 1.5 + 10
    if not t_max:
        t_max = 60
    a.launch = min(a.launch, max(2.0, active.v[0]))
    obs_state = {}  # slot -> on?
    bias = [0.0, 0.0]; tau = 60.0
    gper = 1.0 / a.gnss_hz; next_fix = gper
    glitched = 0; prev_fix = None
    dbw_c = 0
    t = 0.0; tick = 0
    steer_cmd = 0.0; speed_cmd = 0.0
    engaged = None; valid_since = None
    M = dict(lat=[], corr_excess=0.0, corr_excess_t=None, obs_clear=1e9, obs_clear_t=None,
             over_limit=0.0, over_t=None, statuses={}, reasons={}, bad_frames=0, crc_err=0,
             na_cmd=0, frame_counts={}, counter_err=0, end_missing=0, max_speed=0.0,
             steer_abs_mean=0.0, steer_changes=0.0, steer_step_max=0.0, steer_step_t=None, status_log=[], max_lat=0.0, max_lat_t=None,
             pred_bad=0)
    rows = []
    replaced = False
    stop_t = None
    last_status = None
    try:
        while t < t_max - 1e-9:
            tick += 1
            tt = round(tick * TICK, 6)
            lines = []
            while t < tt - 1e-9:
                t = round(t + SUB, 6)
                pushing = a.push_at is not None and engaged is not None and a.push_at <= t - engaged < a.push_at + a.push_dur
                P.step(t, a.push_steer if pushing else steer_cmd, speed_cmd)
                if t >= next_fix - 1e-9:
                    next_fix += gper
                    k = math.exp(-gper / tau)
                    for j in range(2):
                        bias[j] = k * bias[j] + math.sqrt(1 - k * k) * a.gnss_bias * rng.gauss(0, 1)
                    ae, an = P.antenna()
                    fe = ae + bias[0] + rng.gauss(0, a.gnss_white)
                    fn = an + bias[1] + rng.gauss(0, a.gnss_white)
                    if a.glitch_at is not None and engaged is not None and t - engaged >= a.glitch_at \
                            and glitched < a.glitch_fixes:
                        glitched += 1
                        fe += a.glitch_m * math.cos(P.h); fn -= a.glitch_m * math.sin(P.h)
                    lat, lon = enu2geo(fe, fn)
                    lines.append(line(t, msgs["GNSS_POSITION_RAPID"],
                                      enc(msgs["GNSS_POSITION_RAPID"], {"latitude_deg": lat, "longitude_deg": lon})))
                    side = P.vy - P.lr * P.r
                    ve = P.v * math.sin(P.h) + side * math.cos(P.h) + P.c["ant"] * P.r * math.cos(P.h)
                    vn = P.v * math.cos(P.h) - side * math.sin(P.h) - P.c["ant"] * P.r * math.sin(P.h)
                    if a.cog_from_fixes and prev_fix is not None:
                        ve, vn = (fe - prev_fix[0]) / gper, (fn - prev_fix[1]) / gper
                    prev_fix = (fe, fn)
                    cog = math.atan2(ve, vn) % (2 * math.pi)
                    sog = math.hypot(ve, vn)
                    if not a.no_cog:
                        lines.append(line(t, msgs["GNSS_COG_SOG_RAPID"], enc(msgs["GNSS_COG_SOG_RAPID"],
                                     {"sid": tick % 250, "cog_reference": 0, "cog_rad": min(cog, 6.2831), "sog_mps": sog}, fill=0xFF)))
            tr = round(tt - 0.004, 6)
            for nm, vals in (("STEERING_REPORT", {"steer_pct": max(-100, min(100, P.steer))}),
                             ("SPEED_REPORT", {"speed_mps": P.v, "speed_cmd_mps": speed_cmd}),
                             ("PEDAL_REPORT", {"accel_pct": 0.0, "brake_pct": 0.0})):
                lines.append(line(tr, msgs[nm], enc(msgs[nm], {"counter": dbw_c, **vals})))
            dbw_c = (dbw_c + 1) % 16
            # path replacement
            for (ts, pid, path) in paths:
                if ts == "replace" and not replaced and engaged is not None and t >= engaged + a.replace_at:
                    replaced = True
                    pr = active.project(P.x, P.y)
                    x0 = pr["st"] + 10.0
                    pts = build([("S", 30), ("A", 30.0, math.pi / 3), ("S", 80)], p0=(x0, a.shift), step=2.0)
                    newp = Path(pts, a.speed, a.left, a.right)
                    outbox += send_path(pid, newp)
                    pending.append((tt + (1 + 2 * len(pts)) / 4 * TICK + 0.1, newp))
            if a.replan_after is not None and M.get("lost_at") is not None and not M.get("replanned") and tt - M["lost_at"] >= a.replan_after:
                M["replanned"] = round(tt - engaged, 2)
                pts = build([("S", 120)], p0=(P.x, P.y), h=P.h, step=2.0)
                newp = Path(pts, a.speed, a.left, a.right)
                outbox += send_path(7, newp)
                pending.append((tt + (1 + 2 * len(pts)) / 4 * TICK + 0.1, newp))
            for p_ in list(pending):
                if tt >= p_[0]:
                    active = p_[1]; pending.remove(p_)
            # obstacles
            for (slot, ton, toff, e, n, r) in obs:
                if ton < 0:
                    on = obs_state.get(slot, False) or (engaged is not None and e - P.x <= -ton)
                else:
                    on = ton <= (t - (engaged or 1e9)) < toff if ton > 0 else True
                if obs_state.get(slot) != on:
                    obs_state[slot] = on
                    if on and engaged is not None:
                        M.setdefault("obs_on_at", []).append((slot, round(tt - engaged, 2), round(e - P.x, 2), round(P.v, 2)))
                    outbox.insert(0, pl("OBSTACLE", {"obstacle_id": slot, "active": int(on), "east_m": e, "north_m": n, "radius_m": r}))
            for m_, d_ in outbox[:4]:
                lines.append(line(round(tt - 0.002, 6), m_, d_))
            del outbox[:4]
            lines.sort(key=lambda s: float(s[1:s.index(")")]))
            node.stdin.write("\n".join(lines) + f"\nTICK {tt:.6f}\n")
            node.stdin.flush()
            cmd = None; valid = False; nfr = 0; est = None; est_h = 0.0; est_r = 0.0
            while True:
                ln = node.stdout.readline()
                if not ln:
                    M["end_missing"] += 1
                    raise RuntimeError(f"node output ended at {tt}: {node.stderr.read()[:500]}")
                if ln.startswith("END"):
                    if abs(float(ln.split()[1]) - tt) > 1e-6:
                        M["bad_frames"] += 1
                    break
                nfr += 1
                parts = ln.split()
                ident, _, data = parts[2].partition("#")
                key = (len(ident) > 3, int(ident, 16))
                if key not in byid:
                    M["bad_frames"] += 1; continue
                m_ = byid[key]
                vals, raws, ok = dec(m_, bytes.fromhex(data))
                if not ok:
                    M["crc_err"] += 1
                if "counter" in raws and raws["counter"] != (tick - 1) % 16:
                    M["counter_err"] += 1
                if m_["name"] == "CONTROL_COMMAND":
                    cmd = (vals, raws)
                elif m_["name"] == "STATE_POSITION":
                    valid = raws["position_valid"] == 1
                    est = [vals["east_m"], vals["north_m"], est[2] if est else 0.0]
                elif m_["name"] == "STATE_MOTION":
                    est_h = vals["heading_rad"]; est_r = vals["yaw_rate_radps"]
            M["frame_counts"][nfr] = M["frame_counts"].get(nfr, 0) + 1
            if cmd is None:
                M["bad_frames"] += 1
                continue
            vals, raws = cmd
            st = raws["status"]
            if valid and valid_since is None:
                valid_since = tt
            if engaged is None and st in (1, 2) and valid_since is not None and tt - valid_since >= 1.0:
                engaged = tt
                # The node's heading when it takes the car over, against the truth.
                M["takeover_heading_err"] = abs((est_h - P.h + math.pi) % (2 * math.pi) - math.pi)
            if engaged is None:
                # safety driver: straight at launch speed (after 0.5 s)
                steer_cmd = 0.0
                speed_cmd = a.launch if tt > 0.5 else 0.0
            else:
                M["statuses"][st] = M["statuses"].get(st, 0) + 1
                if st == 3 and raws["fallback_reason"] == 5 and M.get("lost_at") is None:
                    M["lost_at"] = tt
                if st == 3:
                    M["reasons"][raws["fallback_reason"]] = M["reasons"].get(raws["fallback_reason"], 0) + 1
                if st != last_status:
                    M["status_log"].append((round(tt - engaged, 2), st, raws["fallback_reason"]))
                    last_status = st
                if raws["steer_cmd_pct"] == -32768 or raws["speed_cmd_mps"] == 0xFFFF:
                    M["na_cmd"] += 1
                    # DBW holds last command? we brake
                    speed_cmd = 0.0
                else:
                    ns = vals["steer_cmd_pct"]
                    M["steer_changes"] += abs(ns - steer_cmd)
                    if engaged is not None and abs(ns - steer_cmd) > M["steer_step_max"]:
                        M["steer_step_max"] = abs(ns - steer_cmd)
                        M["steer_step_t"] = round(tt - engaged, 2)
                    steer_cmd = ns; speed_cmd = vals["speed_cmd_mps"]
                # metrics
                pr = active.project(P.x, P.y)
                if not pr["beyond"]:
                    M["lat"].append(pr["off"])
                    if abs(pr["off"]) > M["max_lat"]:
                        M["max_lat"] = abs(pr["off"]); M["max_lat_t"] = round(tt - engaged, 2)
                # corridor: each corner
                for cx, cy in P.corners():
                    pc = active.project(cx, cy)
                    if pc["beyond"]:
                        continue
                    ex = max(pc["off"] - pc["right"], -pc["off"] - pc["left"])
                    if ex > M["corr_excess"]:
                        M["corr_excess"] = ex; M["corr_excess_t"] = round(tt - engaged, 2)
                # obstacles (only active ones)
                for (slot, ton, toff, e, n, r) in obs:
                    if not obs_state.get(slot):
                        continue
                    # distance circle centre to body rectangle
                    fwd = (math.sin(P.h), math.cos(P.h)); rgt = (math.cos(P.h), -math.sin(P.h))
                    dx, dy = e - P.x, n - P.y
                    lon_ = dx * fwd[0] + dy * fwd[1]; lat_ = dx * rgt[0] + dy * rgt[1]
                    lo = min(max(lon_, -car["ro"]), car["Len"] - car["ro"])
                    la = min(max(lat_, -car["W"] / 2), car["W"] / 2)
                    dcl = math.hypot(lon_ - lo, lat_ - la) - r
                    if dcl < M["obs_clear"]:
                        M["obs_clear"] = dcl; M["obs_clear_t"] = round(tt - engaged, 2)
                if not pr["beyond"] and P.v - pr["lim"] > M["over_limit"]:
                    M["over_limit"] = P.v - pr["lim"]; M["over_t"] = round(tt - engaged, 2)
                M["max_speed"] = max(M["max_speed"], P.v)
                endp = active
                if pending == [] and P.v < 0.02 and engaged is not None and tt - engaged > 3 and speed_cmd == 0.0:
                    if stop_t is None:
                        stop_t = tt
                    elif tt - stop_t > 3.0:
                        break
                else:
                    stop_t = None
            rows.append((tt, P.x, P.y, P.h, P.v, P.steer, steer_cmd, speed_cmd, st, raws["fallback_reason"], P.vt, est[0] if est else 0.0, est[1] if est else 0.0, est_h, est_r, P.r))
    except RuntimeError as e:
        M["error"] = str(e)
    node.stdin.close()
    try:
        err = node.stderr.read()
        node.wait(timeout=10)
    except Exception:
        err = ""
    M["rc"] = node.returncode
    M["stderr_tail"] = err.strip().splitlines()[-int(os.environ.get("TAIL","3")):] if err else []
    try:
        model.unlink()
    except Exception:
        pass
    res = {"scenario": a.scenario, "args": " ".join(sys.argv[1:])}
    res["engaged_s"] = engaged
    lat = M.pop("lat")
    if lat:
        res["lat_rms"] = round(math.sqrt(sum(x * x for x in lat) / len(lat)), 3)
        res["lat_max"] = round(M["max_lat"], 3)
    # final position
    pr = active.project(P.x, P.y)
    res["final_v"] = round(P.v, 3)
    res["final_along_end"] = round(pr["along_end"], 2) if pr["along_end"] is not None else None
    res["final_station"] = round(pr["st"], 2); res["path_len"] = round(active.s[-1], 2)
    res["final_off"] = round(pr["off"], 2)
    res["t_end"] = round(t, 2)
    res["steer_act_pct_s"] = round(M.pop("steer_changes") / max(1e-9, (t - (engaged or t)) or 1), 1)
    for k, v in M.items():
        if isinstance(v, float):
            v = round(v, 3)
        res[k] = v
    if len(res["status_log"]) > 30:
        res["status_log"] = res["status_log"][:30] + ["..."]
    print(json.dumps(res))
    if a.out:
        with open(a.out, "w") as f:
            f.write("t,x,y,h,v,steer,steer_cmd,speed_cmd,status,reason,v_target,est_x,est_y,est_h,est_r,r\n")
            for r in rows:
                f.write(",".join(f"{x:.4f}" if isinstance(x, float) else str(x) for x in r) + "\n")

if __name__ == "__main__":
    main()
