#!/usr/bin/env python3
"""Writes the model-file corpus from models/paper.toml: files the node must refuse
(models/bad/*.toml), each starting with `# expect: TEXT`, the text the one reader's error
message must contain, and files it must accept as the published car (models/good/*.toml).

Run from anywhere: `python3 models/bad/generate.py`. The files are committed; this script is
how they were made, so that a reader can see each one is the published file with one change.
"""
import pathlib
import re

HERE = pathlib.Path(__file__).resolve().parent
MODELS = HERE.parent
PAPER = (MODELS / "paper.toml").read_text()


def block(text, model, name):
    """The `[[model.blocks]]` table whose input is `name`, with its start and end."""
    for m in re.finditer(r"\[\[%s\.blocks\]\]\n" % re.escape(model), text):
        start = m.start()
        nxt = text.find("\n[", m.end())
        end = len(text) if nxt < 0 else nxt + 1
        if 'input = "%s"' % name in text[start:end]:
            return start, end
    raise SystemExit(f"no {model} block for {name}")


def replace(text, old, new):
    assert old in text, old
    return text.replace(old, new, 1)


def drop_block(text, model, name):
    s, e = block(text, model, name)
    return text[:s] + text[e:]


def duplicate_x(text):
    s, e = block(text, "dx_dt", "phi")
    return text[:s] + text[s:e].replace('input = "phi"', 'input = "x"') + text[e:]


def reorder(text):
    """dx/dt blocks in the order phi, y, x, v_m (the node must match them by name)."""
    spans = [block(text, "dx_dt", n) for n in ("v_m", "x", "y", "phi")]
    first, last = spans[0][0], spans[-1][1]
    parts = [text[s:e] for s, e in spans]
    return text[:first] + "".join(reversed(parts)) + text[last:]


def with_lateral(text, steer_gain="1.0", den="[1.0, 25.0]", delay_s="0.0"):
    """The published file with a lateral section as `catmodel identify` writes one."""
    return text + f"""
[lateral]
steer_gain = {steer_gain}
understeer_s2_per_m2 = 0.0015
equation = "yaw rate = G(s) v tan(g delta / (1 + K v^2)) / L, G first order"
output = "yaw_rate"
output_unit = "rad/s"

[[lateral.blocks]]
input = "yaw_rate_kinematic"
input_unit = "rad/s"
num = [0.0, 25.0]
den = {den}
delay_s = {delay_s}
"""


BAD = {
    "misnamed-input": (
        lambda t: replace(t, 'input = "phi"', 'input = "psi"'),
        'dx_dt.blocks[3].input = "psi": not an input of this model',
    ),
    "duplicate-input": (duplicate_x, 'input = "x": a second block for this input'),
    "missing-block": (
        lambda t: drop_block(t, "dx_dt", "phi"),
        'dx_dt.blocks: no block for input "phi"',
    ),
    "speed-order-3": (
        lambda t: replace(t, "den = [1.0, 1.629, 0.7522]", "den = [1.0, 2.0, 1.629, 0.7522]"),
        "speed.blocks[0]: order 3 is above the 2 the node runs",
    ),
    "speed-delay-beyond-line": (
        lambda t: replace(t, "delay_s = 0.42", "delay_s = 1.5"),
        "speed.blocks[input_vel]: delay of 75 samples is beyond the 64 samples",
    ),
    "dxdt-delay-beyond-line": (
        lambda t: replace(
            t, "num = [-4.122, 49.61, -4.098]\nden = [1.0, 6.211, 26.79]\ndelay_s = 0.0",
            "num = [-4.122, 49.61, -4.098]\nden = [1.0, 6.211, 26.79]\ndelay_s = 0.1"),
        "dx_dt.blocks[v_m]: delay of 5 samples is beyond the 1 samples",
    ),
    "fractional-delay": (
        lambda t: replace(t, "delay_s = 0.42", "delay_s = 0.43"),
        "speed.blocks[0].delay_s: delay 0.43 s is not a whole number of samples",
    ),
    "improper": (
        lambda t: replace(t, "den = [1.0, 1.629, 0.7522]", "den = [1.629, 0.7522]"),
        "speed.blocks[0]: improper",
    ),
    "integrating-speed-model": (
        lambda t: replace(t, "den = [1.0, 1.629, 0.7522]", "den = [1.0, 1.629, 0.0]"),
        "speed.blocks[input_vel]: the model has a pole at s = 0",
    ),
    # Stability and gains (docs/findings.md, "unstable, near-integrating and absurd models").
    "unstable-speed-model": (
        lambda t: replace(t, "den = [1.0, 1.629, 0.7522]", "den = [1.0, -0.5, 0.2]"),
        "speed.blocks[input_vel]: pole at s = 0.25 +/- 0.3708j in the right half-plane",
    ),
    "undamped-speed-model": (
        lambda t: replace(t, "den = [1.0, 1.629, 0.7522]", "den = [1.0, 0.0, 0.7522]"),
        "speed.blocks[input_vel]: pole at s = 0 +/- 0.8673j on the imaginary axis",
    ),
    "slow-speed-model": (
        lambda t: replace(t, "den = [1.0, 1.629, 0.7522]", "den = [1.0, 1e-6, 1e-12]"),
        "speed.blocks[input_vel]: pole at s = -5e-7 +/- 8.66e-7j decays slower than 0.1 1/s",
    ),
    "huge-speed-gain": (
        lambda t: replace(t, "num = [0.03679, -0.1981, 0.7647]", "num = [0.0, 1e30, 1e30]"),
        "speed.blocks[input_vel]: DC gain 1.329e30 is outside 0.5..2",
    ),
    "unstable-dxdt-model": (
        lambda t: replace(t, "den = [1.0, 6.211, 26.79]", "den = [1.0, -2.0, 1.0]"),
        "dx_dt.blocks[v_m]: pole at s = 1 in the right half-plane",
    ),
    "dxdt-steering-gain": (
        lambda t: replace(t, "num = [-22.3, 371.5, -26.08]", "num = [-22.3, 371.5, -26080.0]"),
        "dx_dt.blocks[phi]: DC gain -1389 is outside -193.7..193.7",
    ),
    "dxdt-position-gain": (
        lambda t: replace(t, "num = [20.55, -110.4, 12.08]", "num = [20.55, -110.4, 1208.0]"),
        "dx_dt.blocks[x]: DC gain 10.81 is outside -1..1",
    ),
    "unstable-lateral-model": (
        lambda t: with_lateral(t, den="[1.0, -25.0]"),
        "lateral.blocks[yaw_rate_kinematic]: pole at s = 25 in the right half-plane",
    ),
    "steer-gain-lock": (
        lambda t: with_lateral(t, steer_gain="50.98"),
        "lateral.steer_gain = 50.98: the lock would be max_steer_deg 35.5 x 50.98 = 1810 deg",
    ),
    "negative-wheelbase": (
        lambda t: replace(t, "wheelbase_m = 2.62 ", "wheelbase_m = -2.62"),
        "vehicle.wheelbase_m = -2.62: must be within 1..10 m",
    ),
    "zero-timeout": (
        lambda t: replace(t, "steer_timeout_s = 0.1", "steer_timeout_s = 0.0"),
        "inputs.steer_timeout_s = 0: must be within 0.02..2 s",
    ),
    "nan-understeer": (
        lambda t: replace(t, "understeer_s2_per_m2 = 0.0015 ", "understeer_s2_per_m2 = nan"),
        "vehicle.understeer_s2_per_m2 = NaN: must be within 0..0.01 s^2/m^2",
    ),
    "infinite-gate": (
        lambda t: replace(t, "gnss_gate_m = 10.0", "gnss_gate_m = inf"),
        "inputs.gnss_gate_m = inf: must be within 1..100 m",
    ),
    "nan-coefficient": (
        lambda t: replace(t, "num = [0.03679, -0.1981, 0.7647]", "num = [0.03679, nan, 0.7647]"),
        "speed.blocks[0]: a coefficient or the delay is not a finite number",
    ),
    "gnss-rate-zero": (
        lambda t: replace(t, "gnss_rate_hz = 100.0", "gnss_rate_hz = 0.0"),
        "vehicle.gnss_rate_hz = 0: must be within 1..100 Hz",
    ),
    "gnss-rate-too-high": (
        lambda t: replace(t, "gnss_rate_hz = 100.0", "gnss_rate_hz = 200.0"),
        "vehicle.gnss_rate_hz = 200: must be within 1..100 Hz",
    ),
    "cg-not-on-wheelbase": (
        lambda t: replace(t, "cg_to_rear_m = 1.478", "cg_to_rear_m = 1.6"),
        "dynamics: cg_to_front_m + cg_to_rear_m",
    ),
    "no-hysteresis": (
        lambda t: replace(t, "exit_dynamic_speed_mps = 4.0", "exit_dynamic_speed_mps = 8.0"),
        "hybrid: exit thresholds must not exceed enter thresholds",
    ),
    "lateral-weight-zero": (
        lambda t: replace(t, "position_uncertainty_m = 2.0", "position_uncertainty_m = 2.0\nmpc_lateral_weight_per_m2 = 0.0"),
        "control.mpc_lateral_weight_per_m2 = 0: must be within 0.1..100",
    ),
    "lateral-weight-nan": (
        lambda t: replace(t, "position_uncertainty_m = 2.0", "position_uncertainty_m = 2.0\nmpc_lateral_weight_per_m2 = nan"),
        "control.mpc_lateral_weight_per_m2 = NaN: must be within 0.1..100",
    ),
    "lateral-accel-in-g": (
        lambda t: replace(t, "max_lateral_accel_mps2 = 5.9", "max_lateral_accel_mps2 = 0.6"),
        "control.max_lateral_accel_mps2 = 0.6: must be within 1..15 m/s^2",
    ),
    "lateral-accel-nan": (
        lambda t: replace(t, "max_lateral_accel_mps2 = 5.9", "max_lateral_accel_mps2 = nan"),
        "control.max_lateral_accel_mps2 = NaN: must be within 1..15 m/s^2",
    ),
    "steer-lag-negative": (
        lambda t: replace(t, "\n\n[dynamics]", "\nsteer_lag_s = -0.05\n\n[dynamics]"),
        "vehicle.steer_lag_s = -0.05: must be within 0..0.25 s",
    ),
    "steer-lag-too-long": (
        lambda t: replace(t, "\n\n[dynamics]", "\nsteer_lag_s = 0.5\n\n[dynamics]"),
        "vehicle.steer_lag_s = 0.5: must be within 0..0.25 s",
    ),
    # What no car has (the reader's physical ranges, README "Model file"), units and outputs
    # the node does not use, and gains that pass at once: each the published file with one
    # change.
    "oversteer-dynamics": (
        lambda t: replace(t, "cornering_rear_n_per_rad = 91000.0", "cornering_rear_n_per_rad = 10000.0"),
        "dynamics: the single-track model oversteers (cornering_front_n_per_rad x cg_to_front_m = 91360 N m/rad "
        "above cornering_rear_n_per_rad x cg_to_rear_m = 14780 N m/rad) and is unstable above its critical speed "
        "sqrt(C_f C_r L^2 / (m (C_f l_f - C_r l_r))) = 6.418 m/s, within vehicle.max_speed_mps = 60",
    ),
    # The range's top, 0.01, against the stiffnesses' 0.0015: radii 29 % apart at 6 m/s.
    "understeer-disagrees": (
        lambda t: replace(t, "understeer_s2_per_m2 = 0.0015  #", "understeer_s2_per_m2 = 0.01    #"),
        "vehicle.understeer_s2_per_m2 = 0.01 and [dynamics] describe different cars: at "
        "hybrid.enter_dynamic_speed_mps = 6, where the node switches from the kinematic model to the dynamic one, "
        "one steering turns the car on radii 29 % apart",
    ),
    "speed-feedthrough": (
        lambda t: replace(t, "num = [0.03679, -0.1981, 0.7647]", "num = [1e6, 1e6, 0.7647]"),
        "speed.blocks[input_vel]: high-frequency gain 1e6 (num[0] / den[0], what passes at once) is outside -2..2",
    ),
    # Was refused with a pole at s = 0 that is not there (the poles are -0.45 +/- 0.19j).
    "speed-huge-feedthrough": (
        lambda t: replace(
            replace(t, "num = [0.03679, -0.1981, 0.7647]", "num = [1e27, 0.0, 0.19]"),
            "den = [1.0, 1.629, 0.7522]", "den = [1.0, 0.9, 0.19]"),
        "speed.blocks[input_vel]: high-frequency gain 1e27 (num[0] / den[0], what passes at once) is outside -2..2",
    ),
    "speed-overshoot": (
        lambda t: replace(t, "num = [0.03679, -0.1981, 0.7647]", "num = [0.0, 1e6, 0.7647]"),
        "speed.blocks[input_vel]: the step response reaches",
    ),
    "dxdt-position-feedthrough": (
        lambda t: replace(t, "num = [20.55, -110.4, 12.08]", "num = [1e6, -110.4, 12.08]"),
        "dx_dt.blocks[x]: high-frequency gain 1e6 (num[0] / den[0], what passes at once) is outside -5000..5000",
    ),
    "dxdt-steady-state-lost": (
        lambda t: replace(t, "num = [-22.3, 371.5, -26.08]", "num = [0.0, 1e27, -26.08]"),
        "dx_dt.blocks[phi]: its discretization's steady-state gain is",
    ),
    "antenna-far-ahead": (
        lambda t: replace(t, "antenna_ahead_m = 1.478 ", "antenna_ahead_m = 1e30 "),
        "vehicle.antenna_ahead_m = 1e30: must be within -1.409..4.028 m",
    ),
    "car-too-wide": (
        lambda t: replace(t, "width_m = 1.806 ", "width_m = 1e30 "),
        "vehicle.width_m = 1e30: must be within 0.8..3 m",
    ),
    "lock-too-small": (
        lambda t: replace(t, "max_steer_deg = 35.5 ", "max_steer_deg = 1e-30 "),
        "vehicle.max_steer_deg = 1e-30: must be within 10..65 deg",
    ),
    "max-speed-absurd": (
        lambda t: replace(t, "max_speed_mps = 60.0 ", "max_speed_mps = 1e30 "),
        "vehicle.max_speed_mps = 1e30: must be within 5..80 m/s",
    ),
    "wheelbase-in-mm": (
        lambda t: replace(t, "wheelbase_m = 2.62 ", "wheelbase_m = 2620.0"),
        "vehicle.wheelbase_m = 2620: must be within 1..10 m",
    ),
    "track-wider-than-car": (
        lambda t: replace(t, "track_m = 1.55 ", "track_m = 1.9 "),
        "vehicle.track_m = 1.9: wider than width_m = 1.806",
    ),
    "mass-in-tonnes": (
        lambda t: replace(t, "mass_kg = 1741.0", "mass_kg = 1.741"),
        "dynamics.mass_kg = 1.741: must be within 200..50000 kg",
    ),
    "yaw-inertia-absurd": (
        lambda t: replace(t, "yaw_inertia_kg_m2 = 2500.0", "yaw_inertia_kg_m2 = 1e9"),
        "dynamics.yaw_inertia_kg_m2 = 1e9: must be within 342.8..34275 kg m^2",
    ),
    "cornering-in-n-per-deg": (
        lambda t: replace(t, "cornering_front_n_per_rad = 80000.0", "cornering_front_n_per_rad = 1396.0"),
        "dynamics.cornering_front_n_per_rad = 1396: must be within 19263..3.853e5 N/rad",
    ),
    "gnss-lost-an-hour": (
        lambda t: replace(t, "gnss_lost_s = 2.0 ", "gnss_lost_s = 3600.0 "),
        "inputs.gnss_lost_s = 3600: must be within 0.2..30 s",
    ),
    "phi-in-degrees": (
        lambda t: replace(t, 'input_unit = "rad"', 'input_unit = "deg"'),
        'dx_dt.blocks[phi].input_unit: expected "rad", found "deg"',
    ),
    "speed-in-kmh": (
        lambda t: replace(t, 'input = "input_vel"\ninput_unit = "m/s"', 'input = "input_vel"\ninput_unit = "km/h"'),
        'speed.blocks[input_vel].input_unit: expected "m/s", found "km/h"',
    ),
    "dxdt-output-dy-dt": (
        lambda t: replace(t, 'output = "dx_dt"', 'output = "dy_dt"'),
        'dx_dt.output: expected "dx_dt", found "dy_dt"',
    ),
    "fit-nan": (
        lambda t: replace(t, "training_fit_percent = 74.53", "training_fit_percent = nan"),
        "speed.fit.training_fit_percent = NaN: must be a finite number <= 100",
    ),
    "fit-above-100": (
        lambda t: replace(t, "training_fit_percent = 85.67", "training_fit_percent = 185.67"),
        "dx_dt.fit.training_fit_percent = 185.67: must be a finite number <= 100",
    ),
    "lateral-delay-too-long": (
        lambda t: with_lateral(t, delay_s="100.0"),
        "lateral.blocks[yaw_rate_kinematic].delay_s = 100: must be within 0..0.5 s",
    ),
    "unknown-key": (
        lambda t: replace(t, "wheelbase_m = 2.62 ", "wheelbase_mm = 2620"),
        "unknown field `wheelbase_mm`",
    ),
    "missing-key": (
        lambda t: re.sub(r"antenna_ahead_m = .*\n", "", t, count=1),
        "missing field `antenna_ahead_m`",
    ),
    "missing-table": (
        lambda t: t[: t.index("[inputs]")] + t[t.index("[hybrid]"):],
        "missing field `inputs`",
    ),
    "wrong-sample-time": (
        lambda t: replace(t, "sample_time_s = 0.02", "sample_time_s = 0.01"),
        "sample_time_s = 0.01: the node runs every 0.02 s",
    ),
    "old-format": (
        lambda t: replace(t, 'format = "catmodel-model-2"', 'format = "catmodel-model-1"'),
        'format = "catmodel-model-1": written by an older catmodel',
    ),
    "not-toml": (
        lambda t: replace(t, "[vehicle]", "[vehicle"),
        "not a valid model file: line 15, column 9: invalid table header",
    ),
}

GOOD = {
    # Blocks in another order: matched by name, the same node as the published file.
    "reordered-inputs": reorder,
    # A byte-order mark, as some editors write.
    "byte-order-mark": lambda t: "\ufeff" + t,
}


def main():
    for name, (edit, expect) in BAD.items():
        text = edit(PAPER)
        assert text != PAPER, name
        (HERE / f"{name}.toml").write_text(f"# expect: {expect}\n{text}")
    for name, edit in GOOD.items():
        text = edit(PAPER)
        assert text != PAPER, name
        (MODELS / "good" / f"{name}.toml").write_text(text)
    print(f"wrote {len(BAD)} bad and {len(GOOD)} good model files")


if __name__ == "__main__":
    main()
