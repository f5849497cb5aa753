#!/usr/bin/env python3
"""Reference values for the model-predictive controller (host-tests/tests/mpc_reference.rs).

1. `tustin`: trapezoidal discretisation of the lateral error-state model (the matrices of
   src/control/mpc/lateral.rs, written out here from the same equations) by
   scipy.signal.cont2discrete(method='bilinear') at h = 0.1 s, for the dynamic model at 5, 15
   and 30 m/s and the kinematic model at 3 m/s, with and without path curvature.
2. `ltv_qp`: random time-varying LQ problems with the solver's structure (5 states, one input,
   20 stages, hard input bounds, hard and soft (exact-penalty) rows on two states each), built
   from the lateral model at random speeds, solved to high accuracy by an interior-point method
   (cvxpy + Clarabel). The Rust ADMM must reach the same plan.
3. `speed_qp`: the speed plan's QP (src/control/mpc/longitudinal.rs) for the published eq 5
   model: its response at 0.1 s to a command held over one 0.2 s knot, from scipy (ZOH at
   20 ms with the 21-sample delay, simulated with scipy.signal.dlsim), and the condensed QP
   (10 knots, 20 steps) solved by cvxpy + Clarabel for a start at steady state and a few target
   profiles.

Writes host-tests/reference/mpc.json.

Run: python3 -m venv /tmp/venv && /tmp/venv/bin/pip install numpy scipy cvxpy
     /tmp/venv/bin/python host-tests/reference/gen_mpc.py
"""
import json
import pathlib

import cvxpy as cp
import numpy as np
import scipy.signal as sig

OUT = pathlib.Path(__file__).with_name("mpc.json")
H = 0.1
N = 20
NX = 5
EY, EPSI, VY, R, DELTA = range(5)

# CAT Vehicle figures (catmodel::model::dynamic::CAT_VEHICLE_DYNAMICS, vehicle::CAT_VEHICLE).
M, IZ, LF, LR, CF, CR = 1741.0, 2500.0, 1.142, 1.478, 80000.0, 91000.0
L, K_KIN = 2.62, 0.0015
MIN_SPEED = 1.0


def continuous(mode, v, kappa, e0, d0):
    """F, e of lateral.rs `continuous` (G is the unit vector of delta)."""
    f = np.zeros((NX, NX))
    e = np.zeros(NX)
    s0, c0 = np.sin(e0), np.cos(e0)
    f[EY, EPSI] = v * c0
    e[EY] = v * (s0 - c0 * e0)
    f[EPSI, EY] = -v * kappa * kappa
    if mode == "dynamic":
        vx = max(v, MIN_SPEED, 0.1)
        f[EY, VY] = c0
        f[EY, R] = -LR * c0
        f[EPSI, R] = 1.0
        e[EPSI] = -v * kappa
        f[VY, VY] = -(CF + CR) / (M * vx)
        f[VY, R] = -vx - (CF * LF - CR * LR) / (M * vx)
        f[VY, DELTA] = CF / M
        f[R, VY] = -(CF * LF - CR * LR) / (IZ * vx)
        f[R, R] = -(CF * LF**2 + CR * LR**2) / (IZ * vx)
        f[R, DELTA] = CF * LF / IZ
    else:
        scale = 1.0 / (1.0 + K_KIN * v * v)
        t = np.tan(d0 * scale)
        c = t / L
        dc = scale * (1.0 + t * t) / L
        f[EPSI, DELTA] = v * dc
        e[EPSI] = v * (c - dc * d0) - v * kappa
    return f, e


def bilinear(f, e, h):
    g = np.zeros((NX, 2))
    g[DELTA, 0] = 1.0
    g[:, 1] = e
    ad, bd, _, _, _ = sig.cont2discrete((f, g, np.eye(NX), np.zeros((NX, 2))), h, method="bilinear")
    return ad, bd[:, 0], bd[:, 1]


def tustin_cases():
    cases = []
    for mode, v, kappa, e0, d0 in [
        ("dynamic", 5.0, 0.0, 0.0, 0.0),
        ("dynamic", 15.0, 0.02, 0.05, 0.03),
        ("dynamic", 30.0, -0.01, -0.1, -0.02),
        ("kinematic", 3.0, 0.1, 0.2, 0.3),
        ("kinematic", 8.0, -0.05, -0.05, -0.2),
    ]:
        f, e = continuous(mode, v, kappa, e0, d0)
        ad, bd, cd = bilinear(f, e, H)
        cases.append(
            {
                "mode": mode,
                "v": v,
                "kappa": kappa,
                "e0": e0,
                "d0": d0,
                "f": f.tolist(),
                "e": e.tolist(),
                "a": ad.tolist(),
                "b": bd.tolist(),
                "c": cd.tolist(),
            }
        )
    return cases


def random_ltv(rng, mode, soft_rows):
    """A problem shaped like the controller's: lateral model at random speeds, rows on
    (e_y, e_psi) and the steering range."""
    v0 = rng.uniform(6.0, 25.0) if mode == "dynamic" else rng.uniform(1.0, 6.0)
    stages = []
    for k in range(N):
        v = max(0.5, v0 + 0.1 * k * rng.uniform(-1.0, 1.0))
        kappa = rng.uniform(-0.05, 0.05)
        f, e = continuous(mode, v, kappa, rng.uniform(-0.1, 0.1), rng.uniform(-0.2, 0.2))
        a, b, c = bilinear(f, e, H)
        stages.append((a, b, c))
    q = np.array([rng.uniform(1, 20), rng.uniform(1, 20), rng.uniform(0, 1), rng.uniform(0, 1), rng.uniform(0.1, 5)])
    q_lin = [rng.normal(0, 0.2, NX) for _ in range(N)]
    r = rng.uniform(0.5, 3.0)
    r_lin = rng.normal(0, 0.1, N)
    umax = rng.uniform(0.2, 0.5)
    x0 = np.array([rng.uniform(-1.0, 1.0), rng.uniform(-0.2, 0.2), 0.0, 0.0, rng.uniform(-0.3, 0.3)])
    if mode == "dynamic":
        x0[VY] = rng.uniform(-0.3, 0.3)
        x0[R] = rng.uniform(-0.2, 0.2)
    rows = []
    for k in range(N):
        stage_rows = [
            # Steering range: hard.
            {"idx": [DELTA, DELTA], "coef": [1.0, 0.0], "lower": -0.6, "upper": 0.6, "soft": None, "rho": 300.0},
        ]
        for _ in range(4):
            s = rng.uniform(-1.0, 4.0)
            bound = rng.uniform(0.1, 1.0) if soft_rows else rng.uniform(1.0, 2.5)
            if rng.uniform() < 0.5:
                lower, upper = -bound, None
            else:
                lower, upper = None, bound
            stage_rows.append(
                {
                    "idx": [EY, EPSI],
                    "coef": [1.0, s],
                    "lower": lower,
                    "upper": upper,
                    "soft": float(rng.uniform(20.0, 200.0)) if soft_rows else None,
                    "rho": 50.0,
                }
            )
        rows.append(stage_rows)
    return {
        "mode": mode,
        "a": [s[0].tolist() for s in stages],
        "b": [s[1].tolist() for s in stages],
        "c": [s[2].tolist() for s in stages],
        "q_diag": [(q * (5.0 if k == N - 1 else 1.0)).tolist() for k in range(N)],
        "q_lin": [v.tolist() for v in q_lin],
        "r": r,
        "r_lin": r_lin.tolist(),
        "u_lower": [-umax] * N,
        "u_upper": [umax] * N,
        "x0": x0.tolist(),
        "rows": rows,
    }


def solve_ltv(p):
    x = cp.Variable((N + 1, NX))
    u = cp.Variable(N)
    cons = [x[0] == np.array(p["x0"])]
    cost = 0
    for k in range(N):
        a, b, c = np.array(p["a"][k]), np.array(p["b"][k]), np.array(p["c"][k])
        cons.append(x[k + 1] == a @ x[k] + b * u[k] + c)
        cons += [u[k] >= p["u_lower"][k], u[k] <= p["u_upper"][k]]
        qd = np.array(p["q_diag"][k])
        cost += 0.5 * cp.sum(cp.multiply(qd, cp.square(x[k + 1]))) + np.array(p["q_lin"][k]) @ x[k + 1]
        cost += 0.5 * p["r"] * cp.square(u[k]) + p["r_lin"][k] * u[k]
        for row in p["rows"][k]:
            g = row["coef"][0] * x[k + 1, row["idx"][0]] + row["coef"][1] * x[k + 1, row["idx"][1]]
            if row["soft"] is None:
                if row["lower"] is not None:
                    cons.append(g >= row["lower"])
                if row["upper"] is not None:
                    cons.append(g <= row["upper"])
            else:
                if row["lower"] is not None:
                    cost += row["soft"] * cp.pos(row["lower"] - g)
                if row["upper"] is not None:
                    cost += row["soft"] * cp.pos(g - row["upper"])
    prob = cp.Problem(cp.Minimize(cost), cons)
    prob.solve(solver=cp.CLARABEL, tol_gap_abs=1e-10, tol_gap_rel=1e-10, tol_feas=1e-10)
    assert prob.status == "optimal", prob.status
    return {"u": u.value.tolist(), "x": x.value[1:].tolist(), "objective": prob.value}


def ltv_cases():
    rng = np.random.default_rng(20240611)
    cases = []
    while len(cases) < 8:
        # Two of each: dynamic / kinematic, hard / soft rows.
        soft = len(cases) % 2 == 1
        mode = "dynamic" if len(cases) % 4 < 2 else "kinematic"
        p = random_ltv(rng, mode, soft)
        try:
            sol = solve_ltv(p)
        except (AssertionError, cp.error.SolverError):
            # A hard-row draw without a feasible plan: draw again.
            continue
        cases.append({"problem": p, "solution": sol})
    return cases


# Published eq 5 (paper): e^{-0.42 s} (0.03679 s^2 - 0.1981 s + 0.7647) / (s^2 + 1.629 s + 0.7522).
EQ5_NUM = [0.03679, -0.1981, 0.7647]
EQ5_DEN = [1.0, 1.629, 0.7522]
TS = 0.02
DELAY = 21
TICKS = 5


def eq5_discrete():
    a, b, c, d = sig.tf2ss(EQ5_NUM, EQ5_DEN)
    return sig.cont2discrete((a, b, c, d), TS, method="zoh")


PLAN = 20  # steps of 0.1 s in the speed plan
KNOT = 2  # steps per command knot
KNOTS = PLAN // KNOT


def eq5_step_at_steps():
    """Step response (input 1 from sample 0) at samples 0, 5, 10, ... 100."""
    ad, bd, cd, dd, _ = eq5_discrete()
    n = TICKS * PLAN + 1
    u = np.ones(n)
    u_delayed = np.concatenate([np.zeros(DELAY), u])[:n]
    _, y, _ = sig.dlsim((ad, bd, cd, dd, TS), u_delayed)
    return y[:, 0][::TICKS][: PLAN + 1]


def speed_cases():
    step = eq5_step_at_steps()
    # A command held over one knot: the step minus the step KNOT steps later.
    pulse = step - np.concatenate([np.zeros(KNOT), step[:-KNOT]])
    # P[i, j] = pulse[i + 1 - KNOT j] (step k = i + 1, knot j), 0 before the knot.
    pm = np.zeros((PLAN, KNOTS))
    for i in range(PLAN):
        for j in range(KNOTS):
            m = i + 1 - KNOT * j
            if 0 <= m <= PLAN:
                pm[i, j] = pulse[m]
    dc = sum(EQ5_NUM[-1:]) / EQ5_DEN[-1]
    cases = []
    tuning = {"speed_weight": 1.0, "command_change_weight": 0.5, "max_speed_mps": 30.0, "accel_mps2": 1.5, "decel_mps2": 3.0}
    for v0, targets in [
        (5.0, [10.0] * (PLAN + 1)),
        (12.0, [12.0] * 8 + [6.0] * (PLAN + 1 - 8)),
        (0.0, [4.0] * (PLAN + 1)),
        (28.0, [35.0] * (PLAN + 1)),
    ]:
        last = v0 / dc
        f = np.full(PLAN, v0)  # at steady state the free response is flat
        ref = []
        prev = v0
        for t in targets[1:]:
            goal = min(max(t, 0.0), tuning["max_speed_mps"])
            prev = min(max(goal, prev - tuning["decel_mps2"] * H), prev + tuning["accel_mps2"] * H)
            ref.append(prev)
        ref = np.array(ref)
        du = cp.Variable(KNOTS)
        v = f + pm @ du
        diff = cp.hstack([du[0], du[1:] - du[:-1]])
        cost = 0.5 * tuning["speed_weight"] * cp.sum_squares(v - ref) + 0.5 * tuning["command_change_weight"] * cp.sum_squares(diff)
        # The path's target is a limit as well: v_k <= min(target_{k+1} + 0.2, max_speed).
        limits = np.minimum(np.maximum(np.array(targets[1:]), 0.0) + 0.2, tuning["max_speed_mps"])
        cost += 100.0 * cp.sum(cp.pos(v - limits))
        cons = [last + du >= 0.0, last + du <= tuning["max_speed_mps"]]
        prob = cp.Problem(cp.Minimize(cost), cons)
        prob.solve(solver=cp.CLARABEL, tol_gap_abs=1e-10, tol_gap_rel=1e-10, tol_feas=1e-10)
        assert prob.status == "optimal"
        cases.append(
            {
                "v0": v0,
                "last_command": last,
                "targets": targets,
                "commands": (last + du.value).tolist(),
                "speeds": (f + pm @ du.value).tolist(),
            }
        )
    return {"step_at_steps": step.tolist(), "pulse": pulse.tolist(), "dc_gain": dc, "tuning": tuning, "cases": cases}


def rounded(v):
    """Floats to 12 significant digits (far below every tolerance; keeps the file small)."""
    if isinstance(v, float):
        return float(f"{v:.12g}")
    if isinstance(v, list):
        return [rounded(x) for x in v]
    if isinstance(v, dict):
        return {k: rounded(x) for k, x in v.items()}
    return v


def main():
    out = {"h": H, "tustin": tustin_cases(), "ltv_qp": ltv_cases(), "speed_qp": speed_cases()}
    OUT.write_text(json.dumps(rounded(out)) + "\n")
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
