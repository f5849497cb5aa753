#!/usr/bin/env python3
"""RMS difference between two predictions CSVs (`t,step,horizon_s,x,y,heading,speed,mode`) at
the same tick and horizon: catmodel's and the NumPy/SciPy peer's (scripts/compare-peers.sh).

Usage: compare_predictions.py CATMODEL.csv PEER.csv [--max-rms-1s M]
Exits 1 if the 1 s-ahead RMS position difference exceeds --max-rms-1s (default 1.0 m).
"""
import argparse
import sys

import numpy as np


def load(path):
    d = np.genfromtxt(path, delimiter=",", names=True, usecols=(1, 2, 3, 4, 5, 6))
    return {(int(s), round(float(h), 2)): (x, y, hd, v) for s, h, x, y, hd, v in d}


def main():
    p = argparse.ArgumentParser()
    p.add_argument("catmodel")
    p.add_argument("peer")
    p.add_argument("--max-rms-1s", type=float, default=1.0)
    a = p.parse_args()
    ours, peer = load(a.catmodel), load(a.peer)
    rms_1s = None
    for horizon in (0.0, 1.0, 2.0):
        keys = [k for k in ours if k[1] == horizon and k in peer]
        if not keys:
            print(f"horizon {horizon:.1f} s: no common ticks", file=sys.stderr)
            sys.exit(1)
        o = np.array([ours[k] for k in keys])
        q = np.array([peer[k] for k in keys])
        dpos = np.hypot(o[:, 0] - q[:, 0], o[:, 1] - q[:, 1])
        rms = float(np.sqrt(np.mean(dpos**2)))
        dv = float(np.sqrt(np.mean((o[:, 3] - q[:, 3]) ** 2)))
        print(f"horizon {horizon:.1f} s: {len(keys)} common ticks, RMS position difference {rms:.3f} m, "
              f"speed {dv:.3f} m/s")
        if horizon == 1.0:
            rms_1s = rms
    if rms_1s > a.max_rms_1s:
        print(f"1 s-ahead predictions disagree: {rms_1s:.3f} m > {a.max_rms_1s} m", file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
