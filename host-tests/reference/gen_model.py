#!/usr/bin/env python3
"""Reference values for the model tests (host-tests/tests/model_lti.rs).

Computes, once and with a fixed seed, ZOH discretizations with scipy.signal.cont2discrete and
simulations with scipy.signal.dlsim of:
  - the paper's eq 5 (internal controller, 0.42 s delay) and eq 7 (h1..h4) at Ts = 0.02 s;
  - random stable 1st..3rd order transfer functions (proper and strictly proper, real and
    complex poles, non-monic denominators, whole-sample delays) at several sample periods.
Writes host-tests/reference/model_zoh.json.

Run (with numpy and scipy, e.g. from a venv: pip install numpy scipy): python3 host-tests/reference/gen_model.py
"""
import json
import pathlib

import numpy as np
import scipy
import scipy.signal as sig

SEED = 20240521
N_SAMPLES = 150
OUT = pathlib.Path(__file__).with_name("model_zoh.json")


def case(name, num, den, ts, delay_samples, rng, n_samples=N_SAMPLES):
    num = [float(c) for c in num]
    den = [float(c) for c in den]
    delay_s = delay_samples * ts
    dnum, dden, _ = sig.cont2discrete((num, den), ts, method="zoh")
    a, b, c, d = sig.tf2ss(num, den)
    ad, bd, cd, dd, _ = sig.cont2discrete((a, b, c, d), ts, method="zoh")
    u_rand = rng.uniform(-1.0, 1.0, n_samples)
    u_step = np.ones(n_samples)
    out = {}
    for label, u in (("step", u_step), ("random", u_rand)):
        # The delay is a pure shift of the input (zero before it arrives).
        u_del = np.concatenate([np.zeros(delay_samples), u])[:n_samples]
        _, y, _ = sig.dlsim((ad, bd, cd, dd, ts), u_del)
        out[label] = y[:, 0].tolist()
    return {
        "name": name,
        "num": num,
        "den": den,
        "ts": ts,
        "delay_s": delay_s,
        "delay_samples": delay_samples,
        "dnum": np.atleast_2d(dnum)[0].tolist(),
        "dden": np.asarray(dden).tolist(),
        "ad": np.asarray(ad).tolist(),
        "bd": np.asarray(bd)[:, 0].tolist(),
        "cd": np.asarray(cd)[0].tolist(),
        "dd": float(np.asarray(dd).ravel()[0]),
        "u_random": u_rand.tolist(),
        "y_step": out["step"],
        "y_random": out["random"],
    }


def random_stable_tf(rng, order, strictly_proper):
    poles = []
    while len(poles) < order:
        if order - len(poles) >= 2 and rng.random() < 0.5:
            re = -rng.uniform(0.3, 10.0)
            im = rng.uniform(0.5, 15.0)
            poles += [complex(re, im), complex(re, -im)]
        else:
            poles.append(-rng.uniform(0.5, 20.0))
    den = np.real(np.poly(poles)) * rng.uniform(0.5, 3.0)  # non-monic on purpose
    num_len = order if strictly_proper else order + 1
    num = rng.uniform(-5.0, 5.0, num_len)
    return num.tolist(), den.tolist()


def main():
    rng = np.random.default_rng(SEED)
    cases = []
    cases.append(case("eq5", [0.03679, -0.1981, 0.7647], [1.0, 1.629, 0.7522], 0.02, 21, rng, 400))
    eq7 = {
        "eq7_h1": ([-4.122, 49.61, -4.098], [1.0, 6.211, 26.79]),
        "eq7_h2": ([20.55, -110.4, 12.08], [1.0, 37.03, 111.7]),
        "eq7_h3": ([-0.06946, -0.06244, 0.0002256], [1.0, 1.416, 0.5473]),
        "eq7_h4": ([-22.3, 371.5, -26.08], [1.0, 6.59, 18.78]),
    }
    for name, (num, den) in eq7.items():
        cases.append(case(name, num, den, 0.02, 0, rng))
    periods = [0.02, 0.05, 0.1, 0.25]
    k = 0
    for order in (1, 2, 3):
        for strictly_proper in (False, True):
            for ts in periods:
                num, den = random_stable_tf(rng, order, strictly_proper)
                delay = int(rng.integers(0, 6))
                kind = "strict" if strictly_proper else "proper"
                cases.append(case(f"rand{k}_n{order}_{kind}_ts{ts}", num, den, ts, delay, rng))
                k += 1
    meta = {
        "generator": "host-tests/reference/gen_model.py",
        "seed": SEED,
        "scipy": scipy.__version__,
        "numpy": np.__version__,
        "method": "scipy.signal.cont2discrete(method='zoh') on the tf and on tf2ss; dlsim",
    }
    OUT.write_text(json.dumps({"meta": meta, "cases": cases}, indent=1) + "\n")
    print(f"wrote {OUT} ({len(cases)} cases)")


if __name__ == "__main__":
    main()
