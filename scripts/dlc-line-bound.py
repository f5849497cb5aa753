#!/usr/bin/env python3
"""What a clearance to the cones costs in the ISO 3888-2 double lane change.

For each clearance c, the least peak curvature of any line (the rear axle's track) that keeps
the body c or more from every cone, and what that curvature allows:

  - the point-mass bound sqrt(mu g / kappa(c)): no car on tyres of friction mu passes the
    track with clearance c faster (the body's lateral acceleration on its line is v^2 kappa,
    and the tyres give at most mu g);
  - the optimiser's scaling v_opt sqrt(kappa(c_opt) / kappa(c)): the speed at the lateral
    acceleration the optimiser's own pass needed at least (its line is no less curved than the
    least-curved one at its clearance).

A linear program (scipy's HiGHS) over the line's lateral offset every 0.25 m: minimise t with
|y''| <= t, the body's sides (a rectangle along the line's slope, linearised) c from the cones;
the exact rectangle test then checks the result, and the program is re-solved with a larger
margin until the exact clearance is c. The track is built here from ISO 3888-2's rules (lane
widths from the car's width, cones 3 m apart with a 0.15 m radius), independently of
host/src/closed_loop/scenario.rs. docs/controller.md ("What the lane change's goal asks")
gives the figures for the CAT Vehicle and the hatchback.

  python3 scripts/dlc-line-bound.py [--vehicle host/vehicles/cat-vehicle.toml]
      [--clearances 0,0.017,0.05,0.1,0.15] [--optimal 16.94 --optimal-clearance 0.017]

Needs numpy and scipy (pip install numpy scipy).
"""
import argparse
import math
import tomllib

import numpy as np
from scipy.optimize import linprog

SECTIONS_M = (12.0, 13.5, 11.0, 12.5, 12.0)  # ISO 3888-2 sections 1-5
CONE_RADIUS_M = 0.15
CONE_SPACING_M = 3.0
EXIT_WIDTH_MAX_M = 3.0
G = 9.80665


def lanes(width):
    """(x_start, x_end, y_right, y_left) of sections 1, 3 and 5."""
    l1, l2, l3, l4, l5 = SECTIONS_M
    w1, w3, w5 = 1.1 * width + 0.25, width + 1.0, min(1.3 * width + 0.25, EXIT_WIDTH_MAX_M)
    y3 = w1 / 2 + 1.0
    x3, x5 = l1 + l2, l1 + l2 + l3 + l4
    return [(0.0, l1, -w1 / 2, w1 / 2), (x3, x3 + l3, y3, y3 + w3), (x5, x5 + l5, -w5 / 2, w5 / 2)]


def cones(width):
    """(x, centre y left, centre y right) of every pair of cones."""
    out = []
    for a, b, y_right, y_left in lanes(width):
        n = max(1, math.ceil((b - a) / CONE_SPACING_M))
        out += [(a + (b - a) * i / n, y_left + CONE_RADIUS_M, y_right - CONE_RADIUS_M)
                for i in range(n + 1)]
    return out


def body_distance(body, x, y, heading, cx, cy):
    """Distance from (cx, cy) to the body's rectangle, rear axle at (x, y)."""
    length, width, rear = body
    s, c = math.sin(heading), math.cos(heading)
    u = (cx - x) * c + (cy - y) * s
    v = -(cx - x) * s + (cy - y) * c
    du = max(-rear - u, u - (length - rear), 0.0)
    dv = max(abs(v) - width / 2, 0.0)
    return math.hypot(du, dv)


def exact_clearance(body, xs, ys):
    slope = np.gradient(ys, xs)
    worst = math.inf
    for x, y, k in zip(xs, ys, slope):
        for cx, y_left, y_right in cones(body[1]):
            if abs(cx - x) > body[0] + 1.0:
                continue
            for cy in (y_left, y_right):
                d = body_distance(body, x, y, math.atan(k), cx, cy) - CONE_RADIUS_M
                worst = min(worst, d)
    return worst


def least_curvature_line(body, margin, dx=0.25):
    """The least-peak-curvature line keeping the linearised body `margin` from the cones."""
    length, width, rear = body
    xs = np.arange(-20.0, sum(SECTIONS_M) + 20.0 + 1e-9, dx)
    n = len(xs)
    rows, bounds = [], []
    for i in range(1, n - 1):
        for sign in (1.0, -1.0):
            r = np.zeros(n + 1)
            r[i - 1:i + 2] = sign * np.array([1.0, -2.0, 1.0]) / dx**2
            r[n] = -1.0
            rows.append(r)
            bounds.append(0.0)
    for cx, y_left, y_right in cones(width):
        for i in range(1, n - 1):
            u = cx - xs[i]
            if u < -rear or u > length - rear:
                continue
            # The body's side beside the cone: y + u y' -+ width / 2.
            side = np.zeros(n + 1)
            side[i], side[i - 1], side[i + 1] = 1.0, -u / (2 * dx), u / (2 * dx)
            rows.append(side)
            bounds.append(y_left - CONE_RADIUS_M - margin - width / 2)
            rows.append(-side)
            bounds.append(-(y_right + CONE_RADIUS_M + margin + width / 2))
    equal = np.zeros((4, n + 1))
    for k, i in enumerate((0, 1, n - 2, n - 1)):  # straight and on the centre line at both ends
        equal[k, i] = 1.0
    cost = np.zeros(n + 1)
    cost[n] = 1.0
    res = linprog(cost, A_ub=np.array(rows), b_ub=np.array(bounds), A_eq=equal, b_eq=np.zeros(4),
                  bounds=[(None, None)] * n + [(0.0, None)], method="highs")
    if res.status != 0:
        raise SystemExit(f"no line keeps {margin} m: {res.message}")
    ys = res.x[:n]
    slope = np.gradient(ys, xs)
    curvature = np.abs(np.gradient(slope, xs)) / (1 + slope**2) ** 1.5
    return xs, ys, float(curvature.max())


def curvature_at(body, clearance):
    """Least peak curvature at an exact clearance (the linearised margin raised until met)."""
    margin = clearance
    for _ in range(8):
        xs, ys, kappa = least_curvature_line(body, margin)
        got = exact_clearance(body, xs, ys)
        if got >= clearance - 0.002:
            return kappa, got
        margin += clearance - got
    return kappa, got


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--vehicle", default="host/vehicles/cat-vehicle.toml")
    ap.add_argument("--clearances", default="0,0.017,0.03,0.05,0.07,0.1,0.15")
    ap.add_argument("--optimal", type=float, default=16.94,
                    help="the optimiser's limit for this car, m/s (catmodel dlc-limits --optimal)")
    ap.add_argument("--optimal-clearance", type=float, default=0.017,
                    help="the clearance the optimiser's pass kept at its limit, m")
    args = ap.parse_args()
    with open(args.vehicle, "rb") as f:
        car = tomllib.load(f)
    b = car["body"]
    body = (b["length_m"], b["width_m"], b["rear_overhang_m"])
    mu = min(car["tyre_front"]["friction_mu"], car["tyre_rear"]["friction_mu"])
    k_opt, _ = curvature_at(body, args.optimal_clearance)
    print(f"{args.vehicle}: body {body[0]} x {body[1]} m, friction {mu}; optimiser "
          f"{args.optimal} m/s at {args.optimal_clearance} m")
    print("| clearance m | least peak curvature 1/m | exact clearance m "
          "| point-mass bound m/s | at the optimiser's lateral acceleration m/s |")
    print("|---|---|---|---|---|")
    for c in (float(s) for s in args.clearances.split(",")):
        kappa, got = curvature_at(body, c)
        print(f"| {c:g} | {kappa:.4f} | {got:.3f} | {math.sqrt(mu * G / kappa):.2f} "
              f"| {args.optimal * math.sqrt(k_opt / kappa):.2f} |")


if __name__ == "__main__":
    main()
