#!/usr/bin/env bash
# Regenerates the simulated drives in data/ (deterministic: same bytes on every run and machine).
#
#   scripts/gen-data.sh            # rewrite data/smoke.* and data/turn-left-30s.*; check bundled
#   scripts/gen-data.sh --bundled  # also copy smoke.can.log over data/bundled.can.log
#   scripts/gen-data.sh --check    # write nothing; fail if any file in data/ would change
#
# data/ holds:
#   smoke.{csv,can.log,truth.csv}          `simulate-drive --scenario smoke` (15 s), seed 0
#   bundled.can.log                        = smoke.can.log: the drive `cargo qemu` runs
#   turn-left-30s.{csv,can.log,truth.csv}  the first 30 s of `--scenario turn-left`, seed 0
#                                          (log and truth cut at t <= 30 s, candump by csv2can)
#   bundled.tx.golden.log                  the node's frames over bundled.can.log; NOT written
#                                          here (review, then `catmodel replay
#                                          data/bundled.can.log --tx-out` into it; .ci/run checks
#                                          that cargo qemu's frames equal it, stack field aside)
#
# Uses $CATMODEL if set, else builds the CLI with `cargo build --release -p catmodel-host` (the
# build CI's tests made; the simulator's f64 arithmetic gives the same bytes in every profile).
set -euo pipefail
cd "$(dirname "$0")/.."

mode=write
case "${1:-}" in
  "") ;;
  --bundled) mode=bundled ;;
  --check) mode=check ;;
  *) echo "usage: $0 [--bundled | --check]" >&2; exit 2 ;;
esac

if [[ -z "${CATMODEL:-}" ]]; then
  cargo build --quiet --release -p catmodel-host
  CATMODEL="${CARGO_TARGET_DIR:-target}/release/catmodel"
fi

tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT

# 1. The smoke drive.
"$CATMODEL" simulate-drive --scenario smoke --seed 0 --out "$tmp" 2>/dev/null

# 2. The second drive: 30 s of the left turn.
"$CATMODEL" simulate-drive --scenario turn-left --seed 0 --out "$tmp/full" 2>/dev/null
cut_at_30s() { awk -F, 'NR == 1 || $1 + 0 <= 30 { print }' "$1"; }
cut_at_30s "$tmp/full/turn-left.csv" > "$tmp/turn-left-30s.csv"
cut_at_30s "$tmp/full/turn-left.truth.csv" > "$tmp/turn-left-30s.truth.csv"
"$CATMODEL" csv2can "$tmp/turn-left-30s.csv" --out "$tmp/turn-left-30s.can.log" 2>/dev/null

files=(smoke.csv smoke.can.log smoke.truth.csv
       turn-left-30s.csv turn-left-30s.can.log turn-left-30s.truth.csv)
status=0
for f in "${files[@]}"; do
  if [[ $mode == check ]]; then
    cmp -s "$tmp/$f" "data/$f" || { echo "data/$f would change" >&2; status=1; }
  else
    cp "$tmp/$f" "data/$f"
  fi
done

if ! cmp -s "$tmp/smoke.can.log" data/bundled.can.log; then
  if [[ $mode == bundled ]]; then
    cp "$tmp/smoke.can.log" data/bundled.can.log
    echo "data/bundled.can.log updated: replay it with catmodel replay --tx-out into" \
         "data/bundled.tx.golden.log, review, and check cargo qemu against it" >&2
  else
    echo "data/bundled.can.log differs from the smoke drive; left as is" \
         "(rerun with --bundled to replace it, then regenerate the golden frames)" >&2
    status=1
  fi
fi
[[ $mode == check && $status == 0 ]] && echo "data/ is up to date" >&2
exit $status
