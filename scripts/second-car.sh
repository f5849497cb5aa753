#!/usr/bin/env bash
# The second car end to end (README, "A second car"): a Volkswagen Polo Mk6 with a 10 Hz GNSS
# receiver (host/vehicles/vw-polo.toml for the simulator, vw-polo.car.toml for identify).
#
#   scripts/second-car.sh [DIR]      # default DIR: target/second-car
#
# 1. simulates its experiments: the paper-sized training set (11 one-minute drives) and the
#    5-minute validation drive with seed 3;
# 2. identifies its models with `identify --vehicle` (fails if a fit is below the floor);
# 3. replays the node with that model file on a drive identification did not see (the
#    validation drive with seed 0) and evaluates it against truth (the goals: within 20 % of
#    the bias floor, below raw GNSS; printed);
# 4. bakes the model file into the QEMU firmware and requires its frames on that drive to be
#    byte-identical to host replay's (`cargo xtask tx-compare`).
# Uses the release CLI (cargo build --release -p catmodel-host).
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/paper-set.sh
D="${1:-target/second-car}"
V=host/vehicles/vw-polo.toml
ORIGIN=32.2319,-110.9501

cargo build --quiet --release -p catmodel-host
B=target/release/catmodel
rm -rf "$D"
mkdir -p "$D/drive"

simulate_paper_set "$B" "$V" "$D"

"$B" identify "$D"/seed1/*[0-9t].csv "$D"/seed2/*[0-9].csv --validate "$D/validation.csv" \
  --vehicle host/vehicles/vw-polo.car.toml --out "$D/vw-polo.toml"

"$B" simulate-drive --scenario validation --seed 0 --vehicle "$V" --out "$D/drive" 2>/dev/null
# Against truth: the node's local frame on the simulator's origin (--origin).
"$B" replay "$D/drive/validation.can.log" --model "$D/vw-polo.toml" --origin "$ORIGIN" \
  --out "$D/pred.csv"
"$B" evaluate "$D/pred.csv" --truth "$D/drive/validation.truth.csv" --model "$D/vw-polo.toml" \
  --json "$D/eval.json"

# Against the firmware: as QEMU runs it, the local frame on the first fix (no options).
"$B" replay "$D/drive/validation.can.log" --model "$D/vw-polo.toml" \
  --out "$D/pred-first-fix.csv" --tx-out "$D/replay-tx.log"
# CATMODEL_MODEL: absolute, whether DIR was given relative or absolute.
CATMODEL_MODEL="$(cd "$D" && pwd)/vw-polo.toml" cargo qemu -- "$D/drive/validation.can.log"
cargo xtask tx-compare target/qemu/tx.log "$D/replay-tx.log"
