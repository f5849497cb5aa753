#!/usr/bin/env python3
"""A simulator that is not ours, driving the node over `catmodel sil --stdio`.

Everything the node is told and everything it answers goes through the bus as the DBC
(`catmodel.dbc`) describes it, encoded and decoded here by a DBC reader of this script's own
(Python standard library only: no cantools, nothing of the Rust side). The car is this script's
own too: a kinematic single-track model at the rear axle with the understeer gradient, a steering
actuator (rate limit, first-order lag) and a speed loop (dead time, first-order lag), integrated
at 1 ms, none of it the built-in plant of `catmodel closed-loop`. What it checks is the contract
of docs/bus.md and the README's "Software in the loop" from the outside:

- lockstep: the frames of each 20 ms step, then `TICK T`; the node's frames of that tick, then
  `END T`;
- the DBW reports (rolling counter in bits 52..55, CRC-8/SAE-J1850 over the identifier and bytes
  0..6), NMEA 2000 position and COG/SOG at the model file's receiver rate (29-bit identifiers),
  the planner's LOCAL_ORIGIN and path paced at 4 frames a tick;
- a "safety driver" launch (3 m/s, or the course's speed if lower but at least 2 m/s, wheels
  straight) until the node reports a valid position for a second and status 1 (tracking),
  then the node's CONTROL_COMMAND drives the car.

The course: 40 m east, a left half circle of 20 m radius, 40 m back west, at 5 m/s, stopping at
the end. The car's rear axle is scored against the path (the node's reference point). Exit
status 0 when the node drove the course within the bounds given, 1 otherwise, 2 on a broken
session (a frame that does not decode, a CRC error, a missing END).

    python3 scripts/sil-sim.py --catmodel target/release/catmodel [--speed 5] [--seed 0]
"""

import argparse
import math
import random
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
TICK_S = 0.02
# The stretch before the path's end over which the commands are watched, m.
STOP_WINDOW_M = 5.0
# The speed's swing is measured where the path's limit holds the course's speed this far ahead
# (one path point a metre), m.
SWING_AHEAD_M = 40
SUBSTEP_S = 0.001

# ---------------------------------------------------------------------------------- the DBC


class Signal:
    def __init__(self, name, mux, start, length, signed, scale, offset, lo, hi):
        self.name, self.mux = name, mux
        self.start, self.length, self.signed = start, length, signed
        self.scale, self.offset, self.lo, self.hi = scale, offset, lo, hi


class Message:
    def __init__(self, dbc_id, name, dlc):
        self.extended = bool(dbc_id & 0x80000000)
        self.can_id = dbc_id & 0x1FFFFFFF
        self.name, self.dlc = name, dlc
        self.signals = {}


def read_dbc(path):
    """Messages by name and by identifier; little-endian signals only (docs/bus.md)."""
    by_name, by_id = {}, {}
    msg = None
    for lineno, raw in enumerate(Path(path).read_text().splitlines(), 1):
        words = raw.split()
        if not words:
            continue
        if words[0] == "BO_":
            msg = Message(int(words[1]), words[2].rstrip(":"), int(words[3]))
            by_name[msg.name] = msg
            by_id[(msg.extended, msg.can_id)] = msg
        elif words[0] == "SG_" and msg is not None:
            head, _, rest = raw.partition(":")
            name_mux = head.split()[1:]
            mux = name_mux[1] if len(name_mux) > 1 else None
            layout, factor, limits = rest.split()[:3]
            bits, fmt = layout.split("@")
            if fmt[0] != "1":
                sys.exit(f"{path}:{lineno}: big-endian signal, not in this bus")
            start, length = (int(x) for x in bits.split("|"))
            scale, offset = (float(x) for x in factor.strip("()").split(","))
            lo, hi = (float(x) for x in limits.strip("[]").split("|"))
            msg.signals[name_mux[0]] = Signal(
                name_mux[0], mux, start, length, fmt[1] == "-", scale, offset, lo, hi
            )
    return by_name, by_id


def crc8_sae_j1850(data):
    crc = 0xFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1D) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc ^ 0xFF


def encode(msg, values, fill=0):
    """Payload bytes of `msg` with the physical `values` (raw for counter/CRC); CRC last."""
    word = int.from_bytes(bytes([fill]) * msg.dlc, "little")
    for name, value in values.items():
        sig = msg.signals[name]
        raw = round((value - sig.offset) / sig.scale)
        lo_raw = -(1 << (sig.length - 1)) if sig.signed else 0
        hi_raw = (1 << (sig.length - 1)) - 1 if sig.signed else (1 << sig.length) - 1
        if not lo_raw <= raw <= hi_raw:
            raise ValueError(f"{msg.name}.{name} = {value}: outside {sig.length} bits")
        mask = (1 << sig.length) - 1
        word &= ~(mask << sig.start)
        word |= (raw & mask) << sig.start
    data = bytearray(word.to_bytes(msg.dlc, "little"))
    if "crc" in msg.signals:
        data[7] = crc8_sae_j1850(bytes([msg.can_id >> 8, msg.can_id & 0xFF]) + bytes(data[:7]))
    return bytes(data)


def decode(msg, data):
    """Physical values of every signal (None for a raw all-ones / minimum sentinel)."""
    if "crc" in msg.signals:
        crc = crc8_sae_j1850(bytes([msg.can_id >> 8, msg.can_id & 0xFF]) + data[:7])
        if crc != data[7]:
            raise ValueError(f"{msg.name}: CRC {data[7]:#04x}, computed {crc:#04x}")
    word = int.from_bytes(data, "little")
    out = {}
    for name, sig in msg.signals.items():
        raw = (word >> sig.start) & ((1 << sig.length) - 1)
        if sig.signed and raw >= 1 << (sig.length - 1):
            raw -= 1 << sig.length
        value = raw * sig.scale + sig.offset
        out[name] = value if sig.lo - sig.scale <= value <= sig.hi + sig.scale else None
    return out


def candump(t, msg, data):
    ident = f"{msg.can_id:08X}" if msg.extended else f"{msg.can_id:03X}"
    return f"({t:017.6f}) can0 {ident}#{data.hex().upper()}"


# -------------------------------------------------------------------------------- the course


def course(speed):
    """(east, north, speed limit) every metre: 40 m east, a left half circle of 20 m, 40 m west,
    stopping at the end."""
    pts = [(float(x), 0.0) for x in range(0, 40)]
    radius, n_arc = 20.0, 63
    for i in range(n_arc):
        a = math.pi * i / n_arc
        pts.append((40.0 + radius * math.sin(a), radius - radius * math.cos(a)))
    pts += [(40.0 - x, 2 * radius) for x in range(0, 41)]
    # The speed limit tapers to a stop at the end at 1 m/s^2: sqrt(2 a d), d metres to go.
    return [(e, n, min(speed, math.sqrt(2.0 * (len(pts) - 1 - i)))) for i, (e, n) in enumerate(pts)]


def lateral_error(path, e, n):
    """Distance of (e, n) from the polyline, m, or None beyond its ends (the distance there is
    along the path, not across it)."""
    best = (float("inf"), 0.0, 0)
    for i in range(len(path) - 1):
        (e0, n0, _), (e1, n1, _) = path[i], path[i + 1]
        de, dn = e1 - e0, n1 - n0
        u = ((e - e0) * de + (n - n0) * dn) / (de * de + dn * dn)
        uc = max(0.0, min(1.0, u))
        best = min(best, (math.hypot(e - e0 - uc * de, n - n0 - uc * dn), u, i))
    d, u, i = best
    if (i == 0 and u < 0.0) or (i == len(path) - 2 and u > 1.0):
        return None
    return d


# -------------------------------------------------------------------------------- the car


class Car:
    """Kinematic single-track at the rear axle, heading clockwise from north."""

    def __init__(self, args):
        self.L, self.max_steer = 2.62, math.radians(35.5)
        self.understeer = 0.0015
        self.antenna_ahead = 1.478
        self.steer_rate = args.steer_rate  # % per s
        self.steer_lag = args.steer_lag
        self.speed_dead = args.speed_dead_time
        self.speed_lag = args.speed_lag
        self.e = self.n = 0.0
        self.heading = math.pi / 2  # east
        self.v = 0.0
        self.steer_cmd = self.steer_ramp = self.steer = 0.0  # %
        self.speed_queue = []  # (time it acts, command)
        self.speed_target = 0.0
        # --speed-loop eq5: the paper's eq 5 (the CAT Vehicle's internal speed controller,
        # identified: (0.03679 s^2 - 0.1981 s + 0.7647) / (s^2 + 1.629 s + 0.7522) after the
        # dead time), as a state space of this script's own (controllable canonical form).
        self.eq5 = args.speed_loop == "eq5"
        self.eq5_x = (0.0, 0.0)

    def step(self, t, steer_cmd, speed_cmd):
        self.speed_queue.append((t + self.speed_dead, speed_cmd))
        while self.speed_queue and self.speed_queue[0][0] <= t:
            self.speed_target = self.speed_queue.pop(0)[1]
        dstep = self.steer_rate * SUBSTEP_S
        self.steer_ramp += max(-dstep, min(dstep, steer_cmd - self.steer_ramp))
        self.steer += (self.steer_ramp - self.steer) * SUBSTEP_S / self.steer_lag
        if self.eq5:
            (b0, b1, b2), (a1, a2) = (0.03679, -0.1981, 0.7647), (1.629, 0.7522)
            x1, x2 = self.eq5_x
            u = self.speed_target
            x1, x2 = x1 + x2 * SUBSTEP_S, x2 + (u - a2 * x1 - a1 * x2) * SUBSTEP_S
            self.eq5_x = (x1, x2)
            self.v = (b2 - b0 * a2) * x1 + (b1 - b0 * a1) * x2 + b0 * u
        else:
            self.v += (self.speed_target - self.v) * SUBSTEP_S / self.speed_lag
        self.v = max(self.v, 0.0)
        delta = self.steer / 100.0 * self.max_steer
        yaw_rate = self.v * math.tan(delta) / (self.L * (1.0 + self.understeer * self.v**2))
        self.e += self.v * math.sin(self.heading) * SUBSTEP_S
        self.n += self.v * math.cos(self.heading) * SUBSTEP_S
        self.heading += yaw_rate * SUBSTEP_S
        return yaw_rate

    def antenna(self):
        return (
            self.e + self.antenna_ahead * math.sin(self.heading),
            self.n + self.antenna_ahead * math.cos(self.heading),
        )


# --------------------------------------------------------------------------------- geodesy

ORIGIN = (32.2319, -110.9501)  # a parking lot in Tucson, AZ (the CAT Vehicle's home)
WGS84_A, WGS84_F = 6378137.0, 1 / 298.257223563


def to_geodetic(e, n):
    """Local east/north (m) to latitude/longitude (deg) about ORIGIN: the WGS84 radii of
    curvature at the origin (an error under a millimetre within a few hundred metres)."""
    lat0 = math.radians(ORIGIN[0])
    e2 = WGS84_F * (2 - WGS84_F)
    w = math.sqrt(1 - e2 * math.sin(lat0) ** 2)
    meridian = WGS84_A * (1 - e2) / w**3
    normal = WGS84_A / w
    return (
        ORIGIN[0] + math.degrees(n / meridian),
        ORIGIN[1] + math.degrees(e / (normal * math.cos(lat0))),
    )


# ------------------------------------------------------------------------------ the session


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--catmodel", default=str(ROOT / "target/release/catmodel"))
    ap.add_argument("--dbc", default=str(ROOT / "catmodel.dbc"))
    ap.add_argument("--speed", type=float, default=5.0, help="course speed, m/s")
    ap.add_argument("--seed", type=int, default=0, help="the receiver noise's seed")
    ap.add_argument("--gnss-hz", type=float, default=100.0, help="receiver rate (the model file's)")
    ap.add_argument("--gnss-noise-m", type=float, default=0.02, help="1 sigma per axis (RTK)")
    ap.add_argument("--steer-rate", type=float, default=60.0, help="actuator rate limit, %%/s")
    ap.add_argument("--steer-lag", type=float, default=0.05, help="actuator lag, s")
    ap.add_argument("--speed-dead-time", type=float, default=0.3, help="speed loop dead time, s")
    ap.add_argument("--speed-lag", type=float, default=0.6, help="speed loop lag, s")
    ap.add_argument(
        "--speed-loop",
        choices=("lag", "eq5"),
        default="lag",
        help="the speed loop after its dead time: a first-order lag (--speed-lag), or the paper's"
        " eq 5 (with --speed-dead-time 0.42: the car the model file describes)",
    )
    ap.add_argument("--max-rms-m", type=float, default=0.15, help="bound on the lateral RMS")
    ap.add_argument("--max-lateral-m", type=float, default=0.5, help="bound on |lateral error|")
    ap.add_argument(
        "--max-over-limit-mps", type=float, default=0.5, help="bound on the speed over the path's"
    )
    ap.add_argument(
        "--max-swing-mps",
        type=float,
        default=2.0,
        help="bound on the speed's fall from its highest where the path's limit holds",
    )
    ap.add_argument(
        "--max-past-end-m", type=float, default=1.25, help="bound on the stop past the path's end"
    )
    ap.add_argument(
        "--max-stop-rise-mps",
        type=float,
        default=1.0,
        help="bound on a rise of the speed command over the path's last metres (the node creeps"
        " at up to 1 m/s in the stop)",
    )
    ap.add_argument(
        "--out",
        help="CSV of the run (t, east, north, heading, speed, steering, speed command, status)",
    )
    ap.add_argument("model_args", nargs="*", help="passed to `catmodel sil` (e.g. --model F)")
    args = ap.parse_args()

    msgs, by_id = read_dbc(args.dbc)
    rng = random.Random(args.seed)
    car = Car(args)
    path = course(args.speed)
    try:
        node = subprocess.Popen(
            [args.catmodel, "sil", "--stdio", *args.model_args],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            bufsize=1,
        )
    except OSError as e:
        print(
            f"sil-sim: cannot run {args.catmodel}: {e.strerror} "
            "(build it: cargo build --release -p catmodel-host)",
            file=sys.stderr,
        )
        return 2

    # The planner's frames, paced at 4 a tick: LOCAL_ORIGIN (latitude page, then longitude
    # page with the next counter), PATH_HEADER, then each point's PATH_POINT and PATH_LIMITS.
    counters = {}

    def planner(name, values):
        c = counters.get(name, 0)
        counters[name] = (c + 1) % 16
        return msgs[name], encode(msgs[name], {"counter": c, **values})

    lat_o, lon_o = ORIGIN
    outbox = [
        planner("LOCAL_ORIGIN", {"page": 0, "latitude_deg": lat_o}),
        planner("LOCAL_ORIGIN", {"page": 1, "longitude_deg": lon_o}),
        planner("PATH_HEADER", {"path_id": 1, "count": len(path)}),
    ]
    for i, (e, n, v) in enumerate(path):
        outbox.append(planner("PATH_POINT", {"path_id": 1, "index": i, "east_m": e, "north_m": n}))
        outbox.append(
            planner(
                "PATH_LIMITS",
                {"path_id": 1, "index": i, "speed_mps": v, "left_m": 1.75, "right_m": 1.75},
            )
        )

    dbw_counter = 0
    gnss_period = 1.0 / args.gnss_hz
    next_fix = gnss_period
    sid = 0
    t = 0.0
    tick = 0
    status = 0
    valid_since = None
    engaged_at = None
    # The launch: 3 m/s, or the course's speed if lower, but at least 2 m/s (the node settles
    # its heading from the course over the ground above 1.5 m/s, docs/controller.md).
    steer_cmd, speed_cmd = 0.0, min(3.0, max(args.speed, 2.0))
    errors = []
    over_limit = 0.0
    low, stop_rise = math.inf, 0.0
    # The speed's largest fall from its highest since the launch while the path's limit holds
    # the course's speed for SWING_AHEAD_M ahead: a car whose speed loop the node's model does
    # not describe swung between a stop and the course's speed (docs/findings.md).
    peak, swing = None, 0.0
    statuses = {}
    # The fallback's ticks by CONTROL_COMMAND fallback_reason (raw; catmodel.dbc names them).
    reasons = {}
    rows = []
    prev = car.antenna()
    # Time enough for the course at its speed, twice over, and the launch.
    length = sum(math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in zip(path, path[1:]))
    end_t = max(90.0, 2.0 * length / args.speed + 30.0)

    def fail(reason, code=2):
        node.kill()
        print(f"sil-sim: {reason}", file=sys.stderr)
        sys.exit(code)

    while t < end_t:
        tick += 1
        t_tick = round(tick * TICK_S, 6)
        lines = []
        # 20 one-millisecond substeps; fixes at the receiver's rate, reports once a tick.
        while t < t_tick - 1e-9:
            t = round(t + SUBSTEP_S, 6)
            yaw_rate = car.step(t, steer_cmd, speed_cmd)
            if t >= next_fix - 1e-9:
                next_fix += gnss_period
                ae, an = car.antenna()
                ne = ae + rng.gauss(0.0, args.gnss_noise_m)
                nn = an + rng.gauss(0.0, args.gnss_noise_m)
                lat, lon = to_geodetic(ne, nn)
                pos = msgs["GNSS_POSITION_RAPID"]
                fix = encode(pos, {"latitude_deg": lat, "longitude_deg": lon})
                lines.append(candump(t, pos, fix))
                de, dn = ae - prev[0], an - prev[1]
                prev = (ae, an)
                cog = math.atan2(de, dn) % (2 * math.pi)
                sog = math.hypot(de, dn) / gnss_period
                cs = msgs["GNSS_COG_SOG_RAPID"]
                values = {
                    "sid": sid,
                    "cog_reference": 0,
                    "cog_rad": min(cog, 6.2831),
                    "sog_mps": sog,
                }
                lines.append(candump(t, cs, encode(cs, values, fill=0xFF)))
                sid = (sid + 1) % 253
        t_rep = round(t_tick - 0.005, 6)
        for name, values in (
            ("STEERING_REPORT", {"steer_pct": car.steer}),
            ("SPEED_REPORT", {"speed_mps": car.v, "speed_cmd_mps": max(speed_cmd, 0.0)}),
            ("PEDAL_REPORT", {"accel_pct": 0.0, "brake_pct": 0.0}),
        ):
            m = msgs[name]
            lines.append(candump(t_rep, m, encode(m, {"counter": dbw_counter, **values})))
        dbw_counter = (dbw_counter + 1) % 16
        for m, data in outbox[:4]:
            lines.append(candump(round(t_tick - 0.003, 6), m, data))
        del outbox[:4]
        lines.sort(key=lambda s: s[1:18])
        node.stdin.write("\n".join(lines) + f"\nTICK {t_tick:.6f}\n")
        node.stdin.flush()

        # The node's frames of this tick, up to END.
        command = None
        valid = False
        while True:
            line = node.stdout.readline()
            if not line:
                fail(f"the node's output ended before END {t_tick:.6f}")
            if line.startswith("END"):
                break
            ident, _, data = line.split()[2].partition("#")
            key = (len(ident) > 3, int(ident, 16))
            if key not in by_id:
                fail(f"an output frame not in the DBC: {line.strip()}")
            m = by_id[key]
            try:
                values = decode(m, bytes.fromhex(data))
            except ValueError as e:
                fail(f"{e}: {line.strip()}")
            if m.name == "CONTROL_COMMAND":
                command = values
            elif m.name == "STATE_POSITION":
                valid = values["position_valid"] == 1
        if command is None:
            fail(f"no CONTROL_COMMAND at {t_tick:.6f}")
        status = int(command["status"])
        if valid and valid_since is None:
            valid_since = t_tick
        settled = valid_since is not None and t_tick - valid_since >= 1.0
        if engaged_at is None and status == 1 and settled:
            engaged_at = t_tick
            print(f"sil-sim: engaged at {t_tick:.2f} s", file=sys.stderr)
        if engaged_at is not None:
            statuses[status] = statuses.get(status, 0) + 1
            if status == 3:
                reason = int(command["fallback_reason"])
                reasons[reason] = reasons.get(reason, 0) + 1
            if command["steer_cmd_pct"] is None or command["speed_cmd_mps"] is None:
                fail(f"status {status} without a command at {t_tick:.6f}", 1)
            steer_cmd, speed_cmd = command["steer_cmd_pct"], command["speed_cmd_mps"]
            d = lateral_error(path, car.e, car.n)
            if d is not None:
                errors.append(d)
            # The path's speed limit where the car is (the highest of the nearest points').
            near = min(
                range(len(path)),
                key=lambda i: (path[i][0] - car.e) ** 2 + (path[i][1] - car.n) ** 2,
            )
            limit = max(p[2] for p in path[max(near - 2, 0) : near + 3])
            over_limit = max(over_limit, car.v - limit)
            ahead = min(p[2] for p in path[near : near + SWING_AHEAD_M + 1])
            if ahead >= args.speed - 1e-6:
                peak = car.v if peak is None else max(peak, car.v)
                swing = max(swing, peak - car.v)
            to_end = math.hypot(car.e - path[-1][0], car.n - path[-1][1])
            if to_end < STOP_WINDOW_M:
                # The commands in the stop: their largest rise over a lower one before.
                low = min(low, speed_cmd)
                stop_rise = max(stop_rise, speed_cmd - low)
            if to_end < 5.0 and car.v < 0.05:
                break
        rows.append((t_tick, car.e, car.n, car.heading, car.v, car.steer, speed_cmd, status))
    node.stdin.close()
    node.wait(timeout=10)

    if args.out:
        with open(args.out, "w") as f:
            f.write("t_s,east_m,north_m,heading_rad,speed_mps,steer_pct,speed_cmd_mps,status\n")
            for r in rows:
                f.write(",".join(f"{x:.4f}" for x in r[:-1]) + f",{r[-1]}\n")
    if engaged_at is None:
        print(
            "sil-sim: FAIL: the node never reported tracking with a valid position",
            file=sys.stderr,
        )
        return 1
    rms = math.sqrt(sum(e * e for e in errors) / len(errors))
    worst = max(errors)
    # Along the last segment: positive short of the end, negative past it.
    (e1, n1, _), (e2, n2, _) = path[-2], path[-1]
    seg = math.hypot(e2 - e1, n2 - n1)
    short = ((e2 - car.e) * (e2 - e1) + (n2 - car.n) * (n2 - n1)) / seg
    where = f"{abs(short):.2f} m {'short of' if short >= 0 else 'past'}"
    print(
        f"sil-sim: {tick} ticks, engaged {t - engaged_at:.1f} s, "
        f"statuses {dict(sorted(statuses.items()))}"
        + (f" (fallback reasons {dict(sorted(reasons.items()))})" if reasons else "")
        + "; "
        f"rear axle from the path: RMS {rms:.3f} m, largest {worst:.3f} m; "
        f"speed over the path's limit by {max(over_limit, 0.0):.2f} m/s at most, "
        f"fell by {swing:.2f} m/s at most where the limit holds; "
        f"stopped {where} the path's end at {car.v:.2f} m/s; "
        f"over its last {STOP_WINDOW_M:.0f} m the speed command rose by {stop_rise:.2f} m/s at most"
    )
    ok = rms <= args.max_rms_m and worst <= args.max_lateral_m and car.v < 0.05
    ok = ok and -args.max_past_end_m <= short <= 3.0 and stop_rise <= args.max_stop_rise_mps
    ok = ok and over_limit <= args.max_over_limit_mps and swing <= args.max_swing_mps
    ok = ok and statuses.get(3, 0) == 0
    print(f"sil-sim: {'PASS' if ok else 'FAIL'}", file=sys.stderr)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
