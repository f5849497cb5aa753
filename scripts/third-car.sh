#!/usr/bin/env bash
# The probe's roadster (host/vehicles/roadster.toml, 5 Hz receiver; roadster.car.toml is what its
# owner tells `identify`): what its model file is worth to the MPC on the double lane change
# (docs/controller.md, "How much the car's single-track model matters").
#
#   scripts/third-car.sh [DIR]      # default DIR: target/third-car; about 1.5 minutes
#
# 1. simulates the paper-sized training set (11 one-minute drives, the car's standard receiver),
#    the 5-minute validation drive, and two runs of `steps-at-speed` with a survey-grade one;
# 2. identifies a model file from the paper-sized set alone (the cornering stiffnesses are not
#    determined: the owner's guess stays) and one from the set with the step steers;
# 3. prints the highest clean lane-change speed (3 seeds, RTK) of the MPC with each file, with
#    a file of the plant's own values (`dlc-limits` without `--model`), and of pure pursuit.
# Uses the release CLI (cargo build --release -p catmodel-host).
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/paper-set.sh
D="${1:-target/third-car}"
V=host/vehicles/roadster.toml
CAR=host/vehicles/roadster.car.toml

cargo build --quiet --release -p catmodel-host
B=target/release/catmodel
rm -rf "$D"
mkdir -p "$D/steps1" "$D/steps2"

simulate_paper_set "$B" "$V" "$D"
for s in 1 2; do
  "$B" simulate-drive --scenario steps-at-speed --seed $s --receiver rtk --vehicle "$V" \
    --out "$D/steps$s" 2>/dev/null
done

set=("$D"/seed1/*[0-9t].csv "$D"/seed2/*[0-9].csv)
"$B" identify "${set[@]}" --validate "$D/validation.csv" --vehicle "$CAR" \
  --out "$D/guess.toml" 2>&1 | grep -E '^note: \[dynamics\]'
"$B" identify "${set[@]}" "$D"/steps1/steps-at-speed.csv "$D"/steps2/steps-at-speed.csv \
  --validate "$D/validation.csv" --vehicle "$CAR" --out "$D/identified.toml" 2>&1 |
  grep -E '^note: \[dynamics\]'

limit() { # CONTROLLER [--model FILE]: the highest clean speed, m/s
  "$B" dlc-limits --controllers "$@" --vehicle "$V" |
    python3 -c 'import json, sys; print(json.load(sys.stdin)["controllers"][0]["target_mps"])'
}
echo "MPC, the owner's guess of the stiffnesses: $(limit mpc --model "$D/guess.toml") m/s"
echo "MPC, the identified stiffnesses: $(limit mpc --model "$D/identified.toml") m/s"
echo "MPC, the plant's own values: $(limit mpc) m/s"
echo "pure pursuit: $(limit pure-pursuit --model "$D/identified.toml") m/s"
