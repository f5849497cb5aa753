#!/usr/bin/env bash
# Receivers the node was not tuned on, through scripts/sil-drive.py (a black-box review's own
# plant, planner and DBC reader): four drives (S-curves at 8 and 14 m/s, a 7 m U-turn at 4 m/s,
# a 20 m/s straight) x receivers at 1, 5, 10, 20 and 100 Hz with 0.02 or 0.5 m of white noise
# and a 0.3 m bias, the course over ground from the carrier's Doppler (exact) or differenced
# from the receiver's own fixes (--cog-from-fixes). One line per drive:
#   drive|rate|noise|course|seed|lateral RMS, largest lateral error, largest excess outside
#   the corridor (m), fixes the gates rejected, statuses
# Usage: scripts/receiver-sweep.sh [CATMODEL] > OUT   (about 10 minutes; docs/findings.md)
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${1:-target/release/catmodel}
for sc in "scurve --speed 8" "scurve --speed 14" "uturn --speed 4 --radius 7" "straight --speed 20 --length 400"; do
  for hz in 1 5 10 20 100; do
    for w in 0.02 0.5; do
      for cog in "" "--cog-from-fixes"; do
        # shellcheck disable=SC2086
        r=$(python3 scripts/sil-drive.py $sc --gnss-hz "$hz" --gnss-white "$w" --gnss-bias 0.3 $cog \
          --seed 0 --catmodel "$BIN" 2>&1 | tail -1 | python3 -c '
import json, sys
try:
    d = json.loads(sys.stdin.read())
    gate = d["stderr_tail"][0].split("gnss gate ")[1].split(",")[0]
    print(d["lat_rms"], d["lat_max"], d["corr_excess"], gate, d["statuses"])
except (KeyError, ValueError, IndexError):
    print("the controller never drove")')
        echo "$sc|$hz|$w|$cog|0|$r"
      done
    done
  done
done
