#!/usr/bin/env python3
"""Random robustness sweep of the node over `catmodel sil --stdio` (scripts/sil-drive.py).

Draws N drives at random (scenario, car, speed, corridor, obstacles, receiver rate and noise,
the steering and speed loops' mismatch with the model file), runs each with sil-drive.py on two
workers, prints one JSON line per drive, then the drives that look wrong:

- a fault: the node's exit status, an error, a CRC or counter error, a missing or bad frame, a
  "not available" command while engaged, a prediction out of range;
- never engaged (no status 1 or 2 after the position has been valid for 1 s; not flagged for
  a receiver whose courses the drive does not use, launched slower than the track's chords
  correct the heading at: the node waits there by design), or taken over with the heading
  more than 0.1 rad off the truth;
- the body over an obstacle's circle, outside the corridor by more than 0.3 m, over the path's
  speed by more than 1 m/s, lost path, bad input, solver or non-finite fallbacks, or a stop
  more than 1.5 m past or 3 m short of the path's end.

A flag is a lead to read, not a verdict: a planner's path that the car cannot follow (a
replacement shifted sideways a few metres ahead) leaves the corridor by design.

    python3 scripts/sil-sweep.py --seed 1 --count 120 [--cog-modes exact,fixes,none]
        [--catmodel target/release/catmodel]

Used for docs/findings.md (a sweep of 120 drives: no fault; the speed commands' swings while
slowing for a lower target, and a slow speed loop's stop beside an obstacle, under "Not fixed
yet"). About 3 s of CPU per drive.
"""
import argparse
import concurrent.futures as cf
import json
import random
import subprocess
import sys
from pathlib import Path

DRIVE = Path(__file__).resolve().parent / "sil-drive.py"
ROOT = Path(__file__).resolve().parent.parent


def draw(rng, cog_modes):
    """One drive's sil-drive.py arguments. The receiver's course over ground is drawn from
    `cog_modes` ("exact": the carrier's Doppler, "fixes": differenced from its own fixes,
    "none": positions only) by a generator of the drive's own, so that the other draws of a
    seed are the same whatever the modes."""
    car = rng.choice(["default", "small", "truck"])
    scenario = rng.choice(
        ["scurve", "uturn", "straight", "speedstep", "curve", "replace", "obstacle", "obstacle"])
    speed = {"scurve": (3, 12), "uturn": (2, 8), "straight": (3, 30), "speedstep": (5, 25),
             "curve": (5, 20), "replace": (3, 15), "obstacle": (3, 15)}[scenario]
    v = rng.uniform(*speed)
    if car == "truck" and scenario == "scurve":
        v = min(v, 9.0)  # its S-curve's limit (docs/controller.md)
    a = [scenario, "--car", car, "--seed", str(rng.randrange(1000)), "--speed", f"{v:.2f}"]
    if scenario == "speedstep":
        a += ["--speed2", f"{rng.uniform(2, v):.2f}", "--length", "400", "--step-at", "250"]
    if scenario == "curve":
        a += ["--speed2", f"{rng.uniform(2, 8):.2f}", "--radius", f"{rng.uniform(8, 40):.1f}",
              "--length", "120"]
    if scenario == "uturn":
        # sil-drive.py's U-turn has a point every 0.5 m: beyond 18 m it has more than the
        # 256 points a path may have, and the node refuses it (as it should).
        a += ["--radius", f"{rng.uniform(6, 18):.1f}"]
    if scenario == "replace":
        a += ["--shift", f"{rng.uniform(-3, 3):.2f}", "--replace-at", f"{rng.uniform(5, 15):.1f}"]
    w = rng.uniform(1.6, 4.0) if car == "truck" else rng.uniform(1.2, 3.5)
    a += ["--left", f"{w:.2f}", "--right", f"{w:.2f}"]
    if scenario == "obstacle":
        a += ["--length", "200"]
        for _ in range(rng.choice([1, 1, 2, 3])):
            a += ["--obs", f"{rng.uniform(50, 170):.1f},{rng.uniform(-w, w):.2f},"
                           f"{rng.uniform(0.3, 1.5):.2f}"]
    a += ["--gnss-hz", str(rng.choice([1, 5, 10, 10, 20, 50, 100])),
          "--gnss-white", f"{rng.choice([0.01, 0.02, 0.1, 0.3]):.2f}",
          "--gnss-bias", f"{rng.choice([0.0, 0.0, 0.2, 0.5]):.2f}",
          "--pos-unc", f"{rng.choice([0.1, 0.5, 1.0]):.1f}"]
    # The car against its model file: steering 10 % either way, its rate 20 %, the lags and
    # the speed loop's limits. The launch (the safety driver's speed before engaging) is above
    # the 1.5 m/s the heading needs (docs/bus.md, `not_ready`).
    a += ["--steer-gain", f"{rng.uniform(0.9, 1.1):.2f}",
          "--rate-factor", f"{rng.uniform(0.8, 1.2):.2f}",
          "--steer-lag", f"{rng.uniform(0.02, 0.15):.3f}",
          "--speed-dead", f"{rng.uniform(0.1, 0.5):.2f}",
          "--speed-lag", f"{rng.uniform(0.3, 1.5):.2f}",
          "--max-accel", f"{rng.uniform(1.5, 3.5):.1f}",
          "--max-decel", f"{rng.uniform(3, 8):.1f}",
          "--launch", f"{rng.uniform(1.6, 4):.1f}"]
    mode = random.Random(" ".join(a)).choice(cog_modes)
    a += {"exact": [], "fixes": ["--cog-from-fixes"], "none": ["--no-cog"]}[mode]
    return a


def chord_speed_mps(hz):
    """The speed below which the track's chords (the last 0.63 s of fixes, at least one) are
    shorter than the 1.5 m the node corrects its heading by (`course_min_baseline_m`): a car
    whose receiver's courses are not used waits there for its heading (`heading_settling`,
    docs/bus.md)."""
    return 1.5 / (max(1, round(0.63 * hz)) / hz)


def run(args, catmodel):
    try:
        out = subprocess.run([sys.executable, str(DRIVE), *args, "--catmodel", catmodel],
                             capture_output=True, text=True, timeout=900)
        lines = out.stdout.strip().splitlines()
        d = json.loads(lines[-1]) if lines else {"error": out.stderr.strip()[-300:]}
    except Exception as e:  # a hung or crashed driver is a finding too
        d = {"error": repr(e)}
    d["argv"] = " ".join(args)
    return d


def flags(d):
    f = []
    if d.get("error"):
        f.append("error: " + str(d["error"])[:150])
    if d.get("rc") not in (0, None):
        f.append(f"exit {d.get('rc')}")
    for k in ("crc_err", "bad_frames", "counter_err", "end_missing", "pred_bad", "na_cmd"):
        if d.get(k):
            f.append(f"{k} {d[k]}")
    argv = d.get("argv", "").split()
    courses = "--no-cog" not in argv and "--cog-from-fixes" not in argv
    waits = False
    if not courses and "--launch" in argv and "--gnss-hz" in argv:
        launch = float(argv[argv.index("--launch") + 1])
        waits = launch < 1.05 * chord_speed_mps(float(argv[argv.index("--gnss-hz") + 1]))
    if "error" not in d and d.get("engaged_s") is None:
        if waits:
            # The safety driver holds the car where the node waits for its heading, by
            # design: what it does then is the driver's.
            return f
        f.append("never engaged")
    if (d.get("takeover_heading_err") or 0) > 0.1:
        f.append(f"taken over with the heading {d['takeover_heading_err']} rad off")
    if (d.get("obs_clear") or 1e9) < 0.2:
        f.append(f"obstacle clearance {d['obs_clear']} m at {d.get('obs_clear_t')} s")
    if (d.get("corr_excess") or 0) > 0.3:
        f.append(f"outside the corridor by {d['corr_excess']} m at {d.get('corr_excess_t')} s")
    if (d.get("over_limit") or 0) > 1.0:
        f.append(f"over the path's speed by {d['over_limit']} m/s")
    # lost path, bad input, solver, non-finite command (docs/bus.md, fallback_reason)
    bad = {k: n for k, n in d.get("reasons", {}).items() if k in ("5", "6", "8", "10", "11")}
    if bad:
        f.append(f"fallback reasons {bad}")
    end = d.get("final_along_end")
    if end is not None and d.get("scenario") != "replace" and (end > 1.5 or end < -3.0):
        f.append(f"at rest {end} m from the path's end")
    return f


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--count", type=int, default=40)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--catmodel", default=str(ROOT / "target" / "release" / "catmodel"))
    ap.add_argument("--cog-modes", default="exact",
                    help="the receivers' courses to draw from, comma-separated: exact, fixes, "
                         "none (default exact)")
    a = ap.parse_args()
    if not Path(a.catmodel).exists():
        sys.exit(f"no {a.catmodel}: build it with `cargo build --release -p catmodel-host`")
    rng = random.Random(a.seed)
    modes = a.cog_modes.split(",")
    if not modes or any(m not in ("exact", "fixes", "none") for m in modes):
        sys.exit(f"--cog-modes: exact, fixes or none, not {a.cog_modes}")
    drives = [draw(rng, modes) for _ in range(a.count)]
    results = []
    with cf.ThreadPoolExecutor(a.workers) as ex:
        for d in ex.map(lambda args: run(args, a.catmodel), drives):
            print(json.dumps(d), flush=True)
            results.append(d)
    flagged = [(flags(d), d["argv"]) for d in results]
    flagged = [(f, argv) for f, argv in flagged if f]
    print(f"\n{len(results)} drives, {len(flagged)} flagged", file=sys.stderr)
    for f, argv in flagged:
        print(f"  {'; '.join(f)}\n    python3 scripts/sil-drive.py {argv}", file=sys.stderr)


if __name__ == "__main__":
    main()
