#!/usr/bin/env python3
"""A receding-horizon planner and a moving obstacle over `catmodel sil --stdio` (docs/bus.md,
"Obstacles that move"). Reuses the DBC codec, car model and geodesy of scripts/sil-sim.py.

usage: sil-moving.py --scenario {pedestrian,slowcar,cutin,oncoming,standing,none} [--road {straight,wave}]
                     [--replan S] [--speed V] [--model FILE] [--gnss-noise-m 0.02] [--sweep S]
                     [--obstacle-noise-m 0] [--ped-speed 1.5] [--ped-from right] [--ped-stop-at T] [--lead-speed 4]
                     [--lead-brake-at T] [--lead-decel 6] [--cutin-gap 15] [--cutin-at 4] [--cutin-s 3]
                     [--out CSV]
pedestrian: crosses the road 45 m ahead at --ped-speed from t = 2 s, from 6 m to the right
(--ped-from right) or left (with --ped-stop-at T, stops at t = T s where it is, and stays);
slowcar: a car 30 m ahead in the lane at --lead-speed (with --lead-brake-at T, braking from
t = T s at --lead-decel m/s^2, default 6, to a stop where it stays); cutin: a car --cutin-gap m
ahead of the car's start in the left-hand lane (3.5 m left) at --lead-speed that changes into
the car's lane at t = --cutin-at s, taking --cutin-s s (a half-cosine sideways: it turns in,
then straightens, which the node's straight-on prediction does not know); oncoming: a car in the left lane
(3.5 m left) coming towards the car at --lead-speed from 150 m; standing: an object standing
in the lane 45 m ahead. --obstacle-noise-m adds Gaussian noise to each circle sent (a detector's).
--sweep S sends, every tick, the circle that covers the object from now to S seconds ahead (its
radius grown by half the distance it moves) instead of its position.
Prints a JSON summary: NaNs, command ranges, lateral error to the road, min clearance body<->obstacle
(and the same over the ticks the car moves, above 0.5 m/s: an object that runs into a car that
has stopped, e.g. the slower car once the path has ended, is not one the car can avoid),
largest steering-command step per tick (all ticks, and ticks right after a new path is loaded), statuses.
"""
import argparse, importlib.util, json, math, random, subprocess, sys
import os
HERE = os.path.dirname(os.path.abspath(__file__))
spec = importlib.util.spec_from_file_location("silsim", os.path.join(HERE, "sil-sim.py"))
S = importlib.util.module_from_spec(spec); spec.loader.exec_module(S)

ap = argparse.ArgumentParser()
ap.add_argument("--catmodel", default=os.path.join(HERE, "..", "target", "release", "catmodel"))
ap.add_argument("--scenario", default="pedestrian")
ap.add_argument("--road", default="straight")
ap.add_argument("--replan", type=float, default=0.5)
ap.add_argument("--speed", type=float, default=8.0)
ap.add_argument("--model", default=None)
ap.add_argument("--gnss-hz", type=float, default=100.0)
ap.add_argument("--gnss-noise-m", type=float, default=0.02)
ap.add_argument("--points", type=int, default=40)
ap.add_argument("--spacing", type=float, default=1.0)
ap.add_argument("--left", type=float, default=1.75)
ap.add_argument("--right", type=float, default=1.75)
ap.add_argument("--ped-speed", type=float, default=1.5)
ap.add_argument("--ped-from", choices=["right", "left"], default="right")
ap.add_argument("--ped-stop-at", type=float, default=None)
ap.add_argument("--lead-speed", type=float, default=4.0)
ap.add_argument("--lead-brake-at", type=float, default=None)
ap.add_argument("--lead-decel", type=float, default=6.0)
ap.add_argument("--cutin-gap", type=float, default=15.0)
ap.add_argument("--cutin-at", type=float, default=4.0)
ap.add_argument("--cutin-s", type=float, default=3.0)
ap.add_argument("--duration", type=float, default=40.0)
ap.add_argument("--seed", type=int, default=0)
ap.add_argument("--sweep", type=float, default=0.0)
ap.add_argument("--obstacle-noise-m", type=float, default=0.0)
ap.add_argument("--out")
ap.add_argument("--dump-input")
a = ap.parse_args()

class CA: pass
ca = CA(); ca.steer_rate=60.0; ca.steer_lag=0.05; ca.speed_dead_time=float(__import__("os").environ.get("DEAD","0.3")); ca.speed_lag=0.6; ca.speed_loop=__import__("os").environ.get("LOOP","lag")
car = S.Car(ca)
W_HALF, L_FRONT, L_REAR = 1.806/2, 4.437-0.909, 0.909
msgs, by_id = S.read_dbc(os.path.join(HERE, "..", "catmodel.dbc"))
rng = random.Random(a.seed)

def road(s):  # centre line at arc parameter ~ east
    if a.road == "straight": return (s, 0.0)
    return (s, 4.0*math.sin(2*math.pi*s/80.0))
def road_dist(e, n):
    # lateral distance from the road centre: search east near e
    best = 1e9
    for k in range(-60, 61):
        s = e + k*0.05
        re_, rn = road(s); best = min(best, math.hypot(e-re_, n-rn))
    return best

counters = {}
def planner(name, values):
    c = counters.get(name, 0); counters[name] = (c+1) % 16
    return msgs[name], S.encode(msgs[name], {"counter": c, **values})

def make_path(pid, e_car):
    # points from the car's station (slightly behind) forward, evenly in arc length (approx)
    pts = []; s = e_car + float(__import__("os").environ.get("START_OFF","-1.0"))
    re_, rn = road(s); pts.append((re_, rn))
    while len(pts) < a.points:
        # step along until arc distance = spacing
        s2 = s
        while True:
            s2 += 0.01; x, y = road(s2)
            if math.hypot(x-pts[-1][0], y-pts[-1][1]) >= a.spacing: break
        s = s2; pts.append(road(s))
    out = [planner("PATH_HEADER", {"path_id": pid, "count": len(pts)})]
    for i, (e, n) in enumerate(pts):
        out.append(planner("PATH_POINT", {"path_id": pid, "index": i, "east_m": e, "north_m": n}))
        out.append(planner("PATH_LIMITS", {"path_id": pid, "index": i, "speed_mps": a.speed, "left_m": a.left, "right_m": a.right}))
    return out

def obstacle_at(t):
    if a.scenario == "pedestrian":
        # crosses the road 45 m ahead of the start from right to left, starting when t = 2 s at 6 m right
        t0 = 2.0
        side = 1.0 if a.ped_from == "right" else -1.0
        walked = max(0.0, (t if a.ped_stop_at is None else min(t, a.ped_stop_at)) - t0)
        return (45.0, road(45.0)[1] - side*(6.0 - a.ped_speed*walked), 0.4)
    if a.scenario == "slowcar":
        s = 30.0 + a.lead_speed*t
        if a.lead_brake_at is not None and t > a.lead_brake_at:
            tb = min(t - a.lead_brake_at, a.lead_speed/a.lead_decel)
            s = 30.0 + a.lead_speed*a.lead_brake_at + a.lead_speed*tb - a.lead_decel*tb*tb/2
        e, n = road(s); return (e, n, 1.5)
    if a.scenario == "cutin":
        e, n = road(a.cutin_gap + a.lead_speed*t)
        f = min(max((t - a.cutin_at)/a.cutin_s, 0.0), 1.0)
        return (e, n + 3.5*0.5*(1.0 + math.cos(math.pi*f)), 1.5)
    if a.scenario == "oncoming":
        s = 150.0 - a.lead_speed*t
        e, n = road(s); return (e, n + 3.5, 1.5)
    if a.scenario == "standing":
        e, n = road(45.0); return (e, n, 0.5)
    return None

def clearance(ob):
    # body rectangle at rear axle frame vs circle; and whether the circle is behind the body
    e, n, r = ob
    dx, dy = e - car.e, n - car.n
    h = car.heading
    fwd = dx*math.sin(h) + dy*math.cos(h)    # along heading (heading clockwise from north)
    left = -dx*math.cos(h) + dy*math.sin(h)
    cx = min(max(fwd, -L_REAR), L_FRONT); cy = min(max(left, -W_HALF), W_HALF)
    return math.hypot(fwd-cx, left-cy) - r

args_sil = [a.catmodel, "sil", "--stdio"] + (["--model", a.model] if a.model else [])
dumpf = open(a.dump_input, "w") if a.dump_input else None
node = subprocess.Popen(args_sil, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, bufsize=1)
lat_o, lon_o = S.ORIGIN
outbox = [planner("LOCAL_ORIGIN", {"page": 0, "latitude_deg": lat_o}), planner("LOCAL_ORIGIN", {"page": 1, "longitude_deg": lon_o})]
car.e, car.n = road(0.0); car.heading = math.pi/2
pid = 1; outbox += make_path(pid, car.e)
last_path_sent_tick = None
gp = 1.0/a.gnss_hz; next_fix = gp; sid = 0; t = 0.0; tick = 0; dbw = 0
steer_cmd, speed_cmd = 0.0, 3.0
prev = car.antenna(); engaged = None; valid_since = None
rows = []; stats = dict(nan=0, steer_out_of_range=0, speed_out_of_range=0, na_while_engaged=0)
statuses = {}; reasons = {}; min_clear = 1e9; min_clear_t = None; min_ahead = 1e9; min_ahead_t = None; max_lat = 0.0; lat_sq = []; steps = []
next_replan = a.replan; paths_sent = 1; prev_cmd = None
while t < a.duration:
    tick += 1; tt = round(tick*S.TICK_S, 6); lines = []
    while t < tt - 1e-9:
        t = round(t + S.SUBSTEP_S, 6)
        car.step(t, steer_cmd, speed_cmd)
        if t >= next_fix - 1e-9:
            next_fix += gp
            ae, an = car.antenna()
            la, lo = S.to_geodetic(ae + rng.gauss(0, a.gnss_noise_m), an + rng.gauss(0, a.gnss_noise_m))
            pos = msgs["GNSS_POSITION_RAPID"]; lines.append(S.candump(t, pos, S.encode(pos, {"latitude_deg": la, "longitude_deg": lo})))
            de, dn = ae-prev[0], an-prev[1]; prev = (ae, an)
            cs = msgs["GNSS_COG_SOG_RAPID"]
            lines.append(S.candump(t, cs, S.encode(cs, {"sid": sid, "cog_reference": 0, "cog_rad": min(math.atan2(de, dn) % (2*math.pi), 6.2831), "sog_mps": math.hypot(de, dn)/gp}, fill=0xFF)))
            sid = (sid+1) % 253
    trep = round(tt-0.005, 6)
    for name, vals in (("STEERING_REPORT", {"steer_pct": car.steer}), ("SPEED_REPORT", {"speed_mps": car.v, "speed_cmd_mps": max(speed_cmd, 0)}), ("PEDAL_REPORT", {"accel_pct": 0.0, "brake_pct": 0.0})):
        m = msgs[name]; lines.append(S.candump(trep, m, S.encode(m, {"counter": dbw, **vals})))
    dbw = (dbw+1) % 16
    # replanning once the previous transfer is out
    if engaged is not None and tt >= next_replan and not outbox:
        pid = pid % 15 + 1; outbox += make_path(pid, car.e); paths_sent += 1; next_replan = tt + a.replan
    ob = obstacle_at(tt)
    if ob is not None and a.obstacle_noise_m > 0:
        ob = (ob[0] + rng.gauss(0, a.obstacle_noise_m), ob[1] + rng.gauss(0, a.obstacle_noise_m), ob[2])
    if ob is not None and a.sweep > 0:
        ob2 = obstacle_at(tt + a.sweep) or ob
        ob = ((ob[0]+ob2[0])/2, (ob[1]+ob2[1])/2, ob[2] + math.hypot(ob2[0]-ob[0], ob2[1]-ob[1])/2)
    nplan = 4
    if ob is not None:
        m, d = planner("OBSTACLE", {"obstacle_id": 0, "active": 1, "east_m": ob[0], "north_m": ob[1], "radius_m": ob[2]})
        lines.append(S.candump(round(tt-0.003, 6), m, d)); nplan = 3
    for m, d in outbox[:nplan]:
        lines.append(S.candump(round(tt-0.003, 6), m, d))
    if outbox and len(outbox) <= nplan: last_path_sent_tick = tick
    del outbox[:nplan]
    lines.sort(key=lambda s: s[1:18])
    node.stdin.write("\n".join(lines) + f"\nTICK {tt:.6f}\n"); node.stdin.flush()
    if a.dump_input: dumpf.write("\n".join(lines) + "\n")
    cmd = None; valid = False
    while True:
        line = node.stdout.readline()
        if not line: print("node output ended", node.stderr.read()[-2000:], file=sys.stderr); sys.exit(2)
        if line.startswith("END"): break
        ident, _, data = line.split()[2].partition("#")
        m = by_id[(len(ident) > 3, int(ident, 16))]
        v = S.decode(m, bytes.fromhex(data))
        if m.name == "CONTROL_COMMAND": cmd = v
        elif m.name == "STATE_POSITION": valid = v["position_valid"] == 1
    st = int(cmd["status"])
    if valid and valid_since is None: valid_since = tt
    # The node drives once it tracks (status 1); a cut-in's car in the other lane may keep it
    # avoiding (status 2) from the start, which it drives too.
    engage_on = (1, 2) if a.scenario == "cutin" else (1,)
    if engaged is None and st in engage_on and valid_since is not None and tt - valid_since >= 1.0: engaged = tt
    sc, vc = cmd["steer_cmd_pct"], cmd["speed_cmd_mps"]
    for x in (sc, vc):
        if x is not None and (x != x): stats["nan"] += 1
    if engaged is not None:
        statuses[st] = statuses.get(st, 0) + 1
        if st == 3: reasons[int(cmd["fallback_reason"])] = reasons.get(int(cmd["fallback_reason"]), 0) + 1
        if sc is None or vc is None: stats["na_while_engaged"] += 1
        else:
            if abs(sc) > 100: stats["steer_out_of_range"] += 1
            if vc < 0 or vc > a.speed + 0.5: stats["speed_out_of_range"] += 1
            if prev_cmd is not None:
                steps.append((abs(sc - prev_cmd), tt, tick - (last_path_sent_tick or -99)))
            prev_cmd = sc
            steer_cmd, speed_cmd = sc, vc
        d = road_dist(car.e, car.n); max_lat = max(max_lat, d); lat_sq.append(d*d)
        if ob is not None:
            c = clearance(obstacle_at(tt))
            if c < min_clear: min_clear, min_clear_t = c, tt
            if car.v > 0.5 and c < min_ahead: min_ahead, min_ahead_t = c, tt
    rows.append((tt, car.e, car.n, car.heading, car.v, car.steer, steer_cmd, speed_cmd, st, int(cmd["fallback_reason"] or 0), *(ob or (0, 0, 0))))
node.stdin.close(); err = node.stderr.read(); node.wait()
if a.out:
    with open(a.out, "w") as f:
        f.write("t,e,n,heading,v,steer,steer_cmd,speed_cmd,status,reason,ob_e,ob_n,ob_r\n")
        for r in rows: f.write(",".join(f"{x:.4f}" if isinstance(x, float) else str(x) for x in r) + "\n")
steps.sort(reverse=True)
after_load = [s for s in steps if 0 <= s[2] <= 3]
print(json.dumps(dict(engaged_at=engaged, paths_sent=paths_sent, statuses=statuses, fallback_reasons=reasons, **stats,
    lateral_rms_m=round(math.sqrt(sum(lat_sq)/max(len(lat_sq), 1)), 3), lateral_max_m=round(max_lat, 3),
    min_clearance_m=round(min_clear, 3) if min_clear < 1e9 else None, min_clearance_t=min_clear_t,
    min_clearance_moving_m=round(min_ahead, 3) if min_ahead < 1e9 else None, min_clearance_moving_t=min_ahead_t,
    final_east=round(car.e, 1), final_speed=round(car.v, 2),
    steer_step_max=[(round(s[0], 2), s[1]) for s in steps[:5]],
    steer_step_max_near_load=[(round(s[0], 2), s[1], s[2]) for s in sorted(after_load, reverse=True)[:5]],
    sil_summary=err.strip().splitlines()[-6:])))
