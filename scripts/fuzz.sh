#!/usr/bin/env bash
# Runs every cargo-fuzz target of fuzz/ for a bounded time (CI) or a number of executions
# (the long run recorded in fuzz/README.md).
#
#   scripts/fuzz.sh                 # 30 s per target (what .ci/run does)
#   scripts/fuzz.sh 120             # 120 s per target
#   scripts/fuzz.sh --runs 10000000 # 10 million executions per target
#   scripts/fuzz.sh --runs 10000000 node_step   # one target
#   scripts/fuzz.sh --build         # install cargo-fuzz if missing and build the targets only
#
# cargo-fuzz needs nightly-only rustc flags (sanitizers, coverage); the machine has only the
# pinned stable toolchain, so RUSTC_BOOTSTRAP=1 enables them on it. cargo-fuzz itself is
# installed from crates.io if missing (saying so).
set -euo pipefail
cd "$(dirname "$0")/.."

limit=(-max_total_time=30)
build_only=0
case "${1:-}" in
  --build) build_only=1; shift ;;
  --runs) limit=(-runs="$2"); shift 2 ;;
  ''|*[!0-9]*) ;;
  *) limit=(-max_total_time="$1"); shift ;;
esac
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(candump log_csv decoders node_step)

if ! cargo fuzz --version >/dev/null 2>&1; then
  echo "scripts/fuzz.sh: installing cargo-fuzz (cargo install cargo-fuzz --locked)" >&2
  cargo install cargo-fuzz --locked --quiet
fi

export RUSTC_BOOTSTRAP=1
cd fuzz
cargo fuzz build -O
[ "$build_only" = 0 ] || exit 0
mkdir -p ../target/fuzz-logs
# The targets run side by side, as many at once as the machine has cores (each libFuzzer run is
# one process on one core); each one's exit status goes to a file beside its log.
run_target() {
  local t=$1 status=0
  mkdir -p "corpus/$t"
  # corpus/<t> grows (git-ignored); seeds/<t> are committed starting points and regressions.
  cargo fuzz run -O "$t" "corpus/$t" "seeds/$t" -- "${limit[@]}" -print_final_stats=1 \
    >"../target/fuzz-logs/$t.log" 2>&1 || status=$?
  echo "$status" >"../target/fuzz-logs/$t.status"
}
cores=$(nproc 2>/dev/null || echo 1)
for t in "${targets[@]}"; do
  while [ "$(jobs -rp | wc -l)" -ge "$cores" ]; do wait -n || true; done
  echo "==> fuzz $t (${limit[*]}), log: target/fuzz-logs/$t.log"
  rm -f "../target/fuzz-logs/$t.status"
  run_target "$t" &
done
wait
for t in "${targets[@]}"; do
  log="../target/fuzz-logs/$t.log"
  status=$(cat "../target/fuzz-logs/$t.status" 2>/dev/null || echo "no status")
  echo "--- $t"
  grep -E '^(stat::number_of_executed_units|stat::average_exec_per_sec|stat::peak_rss_mb)' "$log" || true
  if [ "$status" != 0 ]; then
    grep -E -A12 'panicked|ERROR|SUMMARY' "$log" | head -40 >&2 || tail -20 "$log" >&2
    echo "fuzz target $t failed (exit $status); failing input in fuzz/artifacts/$t/ (reproduce: cd fuzz && RUSTC_BOOTSTRAP=1 cargo fuzz run $t artifacts/$t/<file>)" >&2
    exit 1
  fi
done
