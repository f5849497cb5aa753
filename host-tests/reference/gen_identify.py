#!/usr/bin/env python3
"""Reference values for `catmodel discretize` (host-tests/tests/discretize.rs).

For every block of models/paper.toml (eq 5 and eq 7 h1..h4) and a few extra transfer functions
(1st and 3rd order, strictly proper and proper, with delays), at Ts = 0.02 s and 0.01 s:
the controllable canonical realization (scipy.signal.tf2ss, the one catmodel uses) discretized
with python-control, control.c2d(sys, ts, 'zoh'), and the delay in samples.
Writes host-tests/reference/discretize_c2d.json.

Run (with numpy and scipy, e.g. from a venv: pip install numpy scipy): python3 host-tests/reference/gen_identify.py
"""
import json
import pathlib

import control
import numpy as np
import scipy.signal as sig

OUT = pathlib.Path(__file__).with_name("discretize_c2d.json")

PAPER = {
    "speed.input_vel": ([0.03679, -0.1981, 0.7647], [1.0, 1.629, 0.7522], 0.42),
    "dx_dt.v_m": ([-4.122, 49.61, -4.098], [1.0, 6.211, 26.79], 0.0),
    "dx_dt.x": ([20.55, -110.4, 12.08], [1.0, 37.03, 111.7], 0.0),
    "dx_dt.y": ([-0.06946, -0.06244, 0.0002256], [1.0, 1.416, 0.5473], 0.0),
    "dx_dt.phi": ([-22.3, 371.5, -26.08], [1.0, 6.59, 18.78], 0.0),
}
EXTRA = {
    "first_order": ([2.0], [0.5, 1.0], 0.1),
    "third_order_proper": ([0.5, 1.0, 2.0, 3.0], [1.0, 3.0, 3.5, 1.5], 0.2),
    "third_order_strict": ([1.0, 0.25], [2.0, 5.0, 6.0, 4.0], 0.0),
}


def c2d(num, den, ts, delay_s):
    a, b, c, d = sig.tf2ss(num, den)
    sysd = control.c2d(control.ss(a, b, c, d), ts, "zoh")
    return {
        "num": num,
        "den": den,
        "delay_s": delay_s,
        "A": np.asarray(sysd.A).tolist(),
        "B": np.asarray(sysd.B).tolist(),
        "C": np.asarray(sysd.C).tolist(),
        "D": np.asarray(sysd.D).tolist(),
        "delay_samples": int(round(delay_s / ts)),
    }


def main():
    out = {"control_version": control.__version__, "cases": []}
    for ts in (0.02, 0.01):
        for group, models in (("paper", PAPER), ("extra", EXTRA)):
            for name, (num, den, delay) in models.items():
                entry = c2d(num, den, ts, delay)
                entry.update({"name": name, "group": group, "ts": ts})
                out["cases"].append(entry)
    OUT.write_text(json.dumps(out, indent=1) + "\n")
    print(f"wrote {OUT} ({len(out['cases'])} cases)")


if __name__ == "__main__":
    main()
