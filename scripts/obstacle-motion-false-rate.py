#!/usr/bin/env python3
"""How often the node's motion test (src/control/planner.rs, ObstacleMotion) calls a standing
object moving, and how soon it sees a slow walk, by simulation: circles once a tick (20 ms) with
Gaussian scatter per axis, rounded to the bus's 0.02 m; a least-squares line over a span of 0.5
s, grown to 1 s while it is no motion and tested at each frame; motion when the speed is at
least 0.3 m/s and at least C standard errors (from the span's own residuals).

usage: obstacle-motion-false-rate.py [--scatter 0.2] [--sigmas 5.5] [--spans 20000] [--walk 0]
Prints the share of spans called moving (for --walk 0 a false rate; for a walk, the detection
rate) and, for a walk, the mean time to the call.
"""
import argparse

import numpy as np

ap = argparse.ArgumentParser()
ap.add_argument("--scatter", type=float, default=0.2)
ap.add_argument("--sigmas", type=float, default=5.5)
ap.add_argument("--spans", type=int, default=20000)
ap.add_argument("--walk", type=float, default=0.0, help="the object's speed, m/s (north)")
ap.add_argument("--seed", type=int, default=1)
a = ap.parse_args()

rng = np.random.default_rng(a.seed)
t = np.arange(51) * 0.02
called, when = 0, []
for _ in range(a.spans):
    e = np.round(rng.normal(0, a.scatter, 51) / 0.02) * 0.02
    n = np.round((a.walk * t + rng.normal(0, a.scatter, 51)) / 0.02) * 0.02
    for k in range(26, 52):
        tt, ee, nn = t[:k], e[:k], n[:k]
        dt = tt - tt.mean()
        stt = (dt * dt).sum()
        ve, vn = (dt * (ee - ee.mean())).sum() / stt, (dt * (nn - nn.mean())).sum() / stt
        rss = ((ee - ee.mean()) ** 2).sum() + ((nn - nn.mean()) ** 2).sum() - (ve * ve + vn * vn) * stt
        var = rss / (2 * (k - 2)) / stt
        speed2 = ve * ve + vn * vn
        if speed2 >= 0.3 ** 2 and speed2 >= a.sigmas ** 2 * var:
            called += 1
            when.append(tt[-1])
            break
print(f"scatter {a.scatter} m, {a.sigmas} sigmas, walk {a.walk} m/s: called moving in "
      f"{called} of {a.spans} spans ({called / a.spans:.2e})"
      + (f", after {np.mean(when):.2f} s on average" if when and a.walk > 0 else ""))
