#!/usr/bin/env bash
# Runs every ```sh block of README.md as pasted, so that the README's commands keep working.
#
# Each block runs on its own (a reader may paste any one of them), with bash and
# `set -euo pipefail`, from the repository root, with TMPDIR pointing at a fresh directory (the
# blocks write their outputs under `mktemp -d`). A block must not write into the repository:
# `git status` is compared before and after each one.
#
# A block may be preceded by directives in HTML comments (invisible on GitHub), each printed
# when it is applied, never silently:
#   <!-- readme-check: skip: REASON -->           the block is not run (e.g. it needs a board)
#   <!-- readme-check: shorten s/FROM/TO/ -->     a sed substitution applied before running it;
#                                                 it must change the block (else: failure)
#
# Usage: scripts/readme-check.sh [README.md]; exit status 1 if any block failed.
set -euo pipefail
cd "$(dirname "$0")/.."

readme=${1:-README.md}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# Split the README into blocks: work/N.sh, work/N.line (line of the fence), work/N.directives.
awk -v dir="$work" '
  /^<!-- readme-check:.*-->[[:space:]]*$/ {
    d = $0
    sub(/^<!-- readme-check:[[:space:]]*/, "", d)
    sub(/[[:space:]]*-->[[:space:]]*$/, "", d)
    pending = pending d "\n"
    next
  }
  /^```sh[[:space:]]*$/ && !inside {
    inside = 1; n++
    printf "%d\n", NR > (dir "/" n ".line")
    printf "%s", pending > (dir "/" n ".directives")
    printf "" > (dir "/" n ".sh")
    pending = ""
    next
  }
  /^```[[:space:]]*$/ && inside { inside = 0; next }
  inside { print > (dir "/" n ".sh"); next }
  /^[[:space:]]*$/ { next }
  { pending = "" }
  END { if (inside) { print "unclosed ```sh block" > "/dev/stderr"; exit 1 } }
' "$readme"

passed=0 failed=0 skipped=0
start_all=$SECONDS
for line_file in $(ls "$work"/*.line 2>/dev/null | sort -V); do
  n=$(basename "$line_file" .line)
  where="$readme:$(cat "$line_file")"
  script="$work/$n.sh"
  skip=""
  while IFS= read -r directive; do
    [ -z "$directive" ] && continue
    case "$directive" in
      skip:*)
        skip="${directive#skip:}"
        ;;
      shorten\ *)
        expr="${directive#shorten }"
        cp "$script" "$script.orig"
        sed -e "$expr" "$script.orig" > "$script"
        if cmp -s "$script" "$script.orig"; then
          echo "FAIL block $n ($where): shorten $expr changes nothing (stale directive)"
          failed=$((failed + 1))
          continue 2
        fi
        echo "     block $n ($where): shortened with $expr"
        ;;
      *)
        echo "FAIL block $n ($where): unknown directive: $directive"
        failed=$((failed + 1))
        continue 2
        ;;
    esac
  done < "$work/$n.directives"
  if [ -n "$skip" ]; then
    echo "SKIP block $n ($where):${skip}"
    skipped=$((skipped + 1))
    continue
  fi

  tmp="$work/tmp-$n"
  mkdir -p "$tmp"
  before=$(git status --porcelain --untracked-files=all)
  started=$SECONDS
  if TMPDIR="$tmp" bash -euo pipefail "$script" > "$work/$n.log" 2>&1 </dev/null; then
    status=ok
  else
    status="exit status $?"
  fi
  after=$(git status --porcelain --untracked-files=all)
  took=$((SECONDS - started))
  if [ "$status" = ok ] && [ "$before" != "$after" ]; then
    status="it wrote into the repository:
$(diff <(echo "$before") <(echo "$after") | grep '^>' || true)"
  fi
  if [ "$status" = ok ]; then
    echo "ok   block $n ($where) in ${took} s"
    passed=$((passed + 1))
  else
    echo "FAIL block $n ($where) after ${took} s: $status"
    echo "---- the block:"
    cat "$script"
    echo "---- its output (last 40 lines):"
    tail -n 40 "$work/$n.log"
    echo "----"
    failed=$((failed + 1))
  fi
  rm -rf "$tmp"
done

echo "README blocks took $((SECONDS - start_all)) s"
echo "readme-check: $passed passed, $failed failed, $skipped skipped"
[ "$failed" = 0 ]
