#!/usr/bin/env bash
# Runs every cargo-fuzz target of fuzz/ for a bounded time (CI) or a number of executions
# (the long run recorded in fuzz/README.md).
#
#   scripts/fuzz.sh                 # 30 s per target (what .ci/run does)
#   scripts/fuzz.sh 120             # 120 s per target
#   scripts/fuzz.sh --runs 10000000 # 10 million executions per target
#   scripts/fuzz.sh --runs 10000000 node_step   # one target
#
# cargo-fuzz needs nightly-only rustc flags (sanitizers, coverage); the machine has only the
# pinned stable toolchain, so RUSTC_BOOTSTRAP=1 enables them on it. cargo-fuzz itself is
# installed from crates.io if missing (saying so).
set -euo pipefail
cd "$(dirname "$0")/.."

limit=(-max_total_time=30)
case "${1:-}" in
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
mkdir -p ../target/fuzz-logs
for t in "${targets[@]}"; do
  mkdir -p "corpus/$t"
  log="../target/fuzz-logs/$t.log"
  echo "==> fuzz $t (${limit[*]}), log: target/fuzz-logs/$t.log"
  # corpus/<t> grows (git-ignored); seeds/<t> are committed starting points and regressions.
  status=0
  cargo fuzz run -O "$t" "corpus/$t" "seeds/$t" -- "${limit[@]}" -print_final_stats=1 \
    >"$log" 2>&1 || status=$?
  grep -E '^(stat::number_of_executed_units|stat::average_exec_per_sec|stat::peak_rss_mb)' "$log" || true
  if [ "$status" != 0 ]; then
    grep -E -A12 'panicked|ERROR|SUMMARY' "$log" | head -40 >&2 || tail -20 "$log" >&2
    echo "fuzz target $t failed (exit $status); failing input in fuzz/artifacts/$t/ (reproduce: cd fuzz && RUSTC_BOOTSTRAP=1 cargo fuzz run $t artifacts/$t/<file>)" >&2
    exit 1
  fi
done
