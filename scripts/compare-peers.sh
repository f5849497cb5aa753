#!/usr/bin/env bash
# catmodel side by side with the tools a user would otherwise reach for (issue 7), on the same
# data in the same run:
#
#   replay    `catmodel replay` vs scripts/peers/replay_scipy.py (NumPy/SciPy: the same decode,
#             GNSS lowpass, eq 5 / eq 7 state space and 2 s kinematic roll-out every 20 ms tick)
#             over the 5-minute validation drive (`simulate-drive --scenario validation`)
#   identify  `catmodel identify` vs scripts/peers/identify_scipy.py (NumPy/SciPy: the same
#             preprocessing, ARX, delay-scanned simulation-error fit of the eq 5-form speed model
#             with scipy.optimize.least_squares + cont2discrete/lfilter, eq 7 MISO dx/dt, steering
#             gain and lateral lag, validation fit %) on the paper-sized experiment set (README
#             "Identify, compare, discretize": 11 one-minute drives + the validation drive)
#
#   scripts/compare-peers.sh              # RUNS=5 runs of each, median wall time
#   RUNS=9 scripts/compare-peers.sh
#   PEER_ROLLOUT=loop scripts/compare-peers.sh   # the plain Python loop roll-out instead
#
# Creates target/peers-venv (numpy, scipy, control from PyPI) unless it already has them
# (set PEERS_PYTHON to use another interpreter with them), builds `catmodel` (release), writes
# everything to target/peers/: the drives, both predictions CSVs, both identified models,
# results.md and results.json.
# Fails if the peer's 1 s-ahead predictions are more than 1 m RMS from catmodel's.
# Identify: wall time of each whole command (reading the CSVs included), each one's own timing of
# the identification + validation alone, and both validation fit % (MATLAB compare, pure
# simulation) of the speed model and of dx/dt on the validation drive.
# Runs alternate (catmodel, peer, catmodel, ...) so that load from other processes hits both.
set -euo pipefail
cd "$(dirname "$0")/.."

runs="${RUNS:-5}"
rollout="${PEER_ROLLOUT:-vector}"
out=target/peers
venv=target/peers-venv
origin=32.2319,-110.9501 # the simulator's origin (README, "The CLI")
mkdir -p "$out"

# --- Python peers' environment -------------------------------------------------------------
if [[ -n "${PEERS_PYTHON:-}" ]]; then
  py="$PEERS_PYTHON"
else
  py="$venv/bin/python"
  if ! "$py" -c 'import numpy, scipy, control' 2>/dev/null; then
    echo "compare-peers: creating $venv (numpy, scipy, control from PyPI)" >&2
    python3 -m venv "$venv"
    "$py" -m pip install --quiet --upgrade pip
    "$py" -m pip install --quiet numpy scipy control
  fi
fi
versions=$("$py" -c 'import sys, numpy, scipy, control; print(f"Python {sys.version.split()[0]}, NumPy {numpy.__version__}, SciPy {scipy.__version__}, python-control {control.__version__}")')

# --- catmodel and the drive ----------------------------------------------------------------
cargo build --quiet --release -p catmodel-host
catmodel=target/release/catmodel
"$catmodel" simulate-drive --scenario validation --out "$out" 2>/dev/null
log="$out/validation.can.log"

now() { date +%s.%N; }
median() { sort -g | awk '{a[NR]=$1} END {print (NR % 2) ? a[(NR+1)/2] : (a[NR/2] + a[NR/2+1]) / 2}'; }

: >"$out/catmodel.times"
: >"$out/peer.times"
: >"$out/peer.loop_times"
: >"$out/peer.inproc_times"
for i in $(seq "$runs"); do
  t0=$(now)
  "$catmodel" replay "$log" --origin "$origin" --out "$out/pred_catmodel.csv" 2>/dev/null
  t1=$(now)
  "$py" scripts/peers/replay_scipy.py "$log" --origin "$origin" --out "$out/pred_scipy.csv" \
    --rollout "$rollout" --timing-json "$out/peer_timing.json" 2>/dev/null
  t2=$(now)
  awk -v a="$t1" -v b="$t0" 'BEGIN { print a - b }' >>"$out/catmodel.times"
  awk -v a="$t2" -v b="$t1" 'BEGIN { print a - b }' >>"$out/peer.times"
  "$py" -c 'import json,sys; t=json.load(open(sys.argv[1])); print(t["tick_loop_s"]); print(t["total_in_process_s"], file=sys.stderr)' \
    "$out/peer_timing.json" >>"$out/peer.loop_times" 2>>"$out/peer.inproc_times"
  echo "compare-peers: run $i/$runs: catmodel $(tail -1 "$out/catmodel.times") s, scipy $(tail -1 "$out/peer.times") s" >&2
done

ours=$(median <"$out/catmodel.times")
peer=$(median <"$out/peer.times")
peer_inproc=$(median <"$out/peer.inproc_times")
peer_loop=$(median <"$out/peer.loop_times")
ticks=$("$py" -c 'import json,sys; print(json.load(open(sys.argv[1]))["ticks"])' "$out/peer_timing.json")
agreement=$("$py" scripts/peers/compare_predictions.py "$out/pred_catmodel.csv" "$out/pred_scipy.csv")
rms_1s=$(echo "$agreement" | awk '/^horizon 1.0/ {print $(NF-4)}')

# --- identify on the paper-sized experiment set ---------------------------------------------
idd="$out/identify"
mkdir -p "$idd/seed1" "$idd/seed2" "$idd/seed3"
for s in straight-2.5 straight-5 straight-7.5 straight-10 turn-left turn-right circle-left circle-right; do
  "$catmodel" simulate-drive --scenario "$s" --out "$idd/seed1" --seed 1 2>/dev/null
done
for s in straight-2.5 straight-5 straight-10; do
  "$catmodel" simulate-drive --scenario "$s" --out "$idd/seed2" --seed 2 2>/dev/null
done
"$catmodel" simulate-drive --scenario validation --out "$idd/seed3" --seed 3 2>/dev/null
id_logs=()
for s in straight-2.5 straight-5 straight-7.5 straight-10 turn-left turn-right circle-left circle-right; do
  id_logs+=("$idd/seed1/$s.csv")
done
for s in straight-2.5 straight-5 straight-10; do id_logs+=("$idd/seed2/$s.csv"); done
id_val="$idd/seed3/validation.csv"

: >"$out/id_catmodel.times"
: >"$out/id_peer.times"
: >"$out/id_catmodel.inproc_times"
: >"$out/id_peer.inproc_times"
for i in $(seq "$runs"); do
  t0=$(now)
  "$catmodel" identify "${id_logs[@]}" --validate "$id_val" --out "$out/identified_catmodel.toml" \
    >"$out/identify_catmodel.txt" 2>/dev/null
  t1=$(now)
  "$py" scripts/peers/identify_scipy.py "${id_logs[@]}" --validate "$id_val" \
    --json "$out/identified_scipy.json" >"$out/identify_scipy.txt" 2>/dev/null
  t2=$(now)
  awk -v a="$t1" -v b="$t0" 'BEGIN { print a - b }' >>"$out/id_catmodel.times"
  awk -v a="$t2" -v b="$t1" 'BEGIN { print a - b }' >>"$out/id_peer.times"
  awk '/^identified in/ { print $3 }' "$out/identify_catmodel.txt" >>"$out/id_catmodel.inproc_times"
  "$py" -c 'import json,sys; print(json.load(open(sys.argv[1]))["times_s"]["identify_and_validate"])' \
    "$out/identified_scipy.json" >>"$out/id_peer.inproc_times"
  echo "compare-peers: identify run $i/$runs: catmodel $(tail -1 "$out/id_catmodel.times") s, scipy $(tail -1 "$out/id_peer.times") s" >&2
done
id_ours=$(median <"$out/id_catmodel.times")
id_peer=$(median <"$out/id_peer.times")
id_ours_inproc=$(median <"$out/id_catmodel.inproc_times")
id_peer_inproc=$(median <"$out/id_peer.inproc_times")
read -r fit_ours fit_peer dx_ours dx_peer < <("$py" -c '
import json, sys, tomllib
m = tomllib.load(open(sys.argv[1], "rb"))
p = json.load(open(sys.argv[2]))
print(m["speed"]["fit"]["validation_fit_percent"], p["speed"]["validation_fit_percent"],
      m["dx_dt"]["fit"]["validation_fit_percent"], p["dx_dt"]["validation_fit_percent"])
' "$out/identified_catmodel.toml" "$out/identified_scipy.json")

fmt() { printf '%.3f' "$1"; }
fit2() { printf '%.2f' "$1"; }
ratio() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.0f", a / b }'; }
ratio1() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.1f", a / b }'; }
cores=$(nproc)
cpu=$(awk -F': ' '/model name/ {print $2; exit}' /proc/cpuinfo 2>/dev/null || echo unknown)

cat >"$out/results.md" <<EOF
| work (same data, same run) | catmodel | NumPy/SciPy peer | ratio |
|---|---|---|---|
| replay of the 5-minute validation drive ($ticks ticks), whole command, wall, median of $runs | $(fmt "$ours") s | $(fmt "$peer") s | $(ratio "$peer" "$ours")x |
| same, the peer without interpreter start and imports (its in-process time) | $(fmt "$ours") s | $(fmt "$peer_inproc") s | $(ratio "$peer_inproc" "$ours")x |
| the peer's per-tick loop alone ($rollout roll-out) vs the whole catmodel command | $(fmt "$ours") s | $(fmt "$peer_loop") s | $(ratio "$peer_loop" "$ours")x |
| identify on the paper-sized experiment set (11 logs + validation log), whole command, wall, median of $runs | $(fmt "$id_ours") s | $(fmt "$id_peer") s | $(ratio1 "$id_peer" "$id_ours")x |
| same, identification + validation only (each one's own timer, after reading and preprocessing) | $(fmt "$id_ours_inproc") s | $(fmt "$id_peer_inproc") s | $(ratio1 "$id_peer_inproc" "$id_ours_inproc")x |

1 s-ahead predictions, catmodel vs peer: RMS position difference $rms_1s m.
Identify, validation fit % (pure simulation on the validation drive), catmodel vs peer: speed
(eq 5 form) $(fit2 "$fit_ours") vs $(fit2 "$fit_peer"); dx/dt (eq 7 form) $(fit2 "$dx_ours") vs $(fit2 "$dx_peer").
Machine: $cores cores ($cpu), shared with other work; $versions.
EOF
cat >"$out/results.json" <<EOF
{"runs": $runs, "ticks": $ticks, "rollout": "$rollout", "catmodel_replay_s": $ours,
 "scipy_replay_s": $peer, "scipy_in_process_s": $peer_inproc, "scipy_tick_loop_s": $peer_loop,
 "rms_1s_m": $rms_1s, "cores": $cores,
 "catmodel_identify_s": $id_ours, "scipy_identify_s": $id_peer,
 "catmodel_identify_in_process_s": $id_ours_inproc, "scipy_identify_in_process_s": $id_peer_inproc,
 "catmodel_speed_validation_fit_percent": $fit_ours, "scipy_speed_validation_fit_percent": $fit_peer,
 "catmodel_dx_dt_validation_fit_percent": $dx_ours, "scipy_dx_dt_validation_fit_percent": $dx_peer}
EOF
echo "$agreement"
cat "$out/results.md"
