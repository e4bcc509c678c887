#!/usr/bin/env bash
# CI's benchmark smoke stage: every scripts/bench_*.py at its smallest size (--smoke), peers
# skipped when not installed, every table written into ONE temporary folder (never over
# scripts/results/: published tables come from full runs only). Fails if any benchmark fails;
# prints each one's time and the total.
#
#   bash scripts/bench_smoke.sh              # all
#   bash scripts/bench_smoke.sh friction     # some (names without bench_ / .py)
#
# A benchmark added as scripts/bench_NAME.py is run here automatically: it must take --smoke.
set -uo pipefail
cd "$(dirname "$0")/.."
PY="${PY:-.venv/bin/python}"
TMP="$(mktemp -d "${TMPDIR:-/tmp}/parsolve-bench-smoke.XXXXXX")"
trap 'rm -rf "$TMP"' EXIT
export PARSOLVE_BENCH_SMOKE=1 PARSOLVE_BENCH_TMP="$TMP"
# the smoke runs of the harness's files and folders only: nothing outside $TMP
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1

if [ $# -gt 0 ]; then
    names=("$@")
else
    names=()
    for f in scripts/bench_*.py; do
        n="$(basename "$f" .py)"; n="${n#bench_}"
        case "$n" in harness|scenes) continue ;; esac   # modules, not benchmarks
        names+=("$n")
    done
fi

failed=()
touch "$TMP/.start"
t_all=$(date +%s.%N)
for n in "${names[@]}"; do
    t0=$(date +%s.%N)
    if "$PY" "scripts/bench_$n.py" --smoke >"$TMP/$n.log" 2>&1; then
        status=ok
    else
        status=FAILED
        failed+=("$n")
    fi
    printf '[bench_smoke] %-12s %6.1f s  %s\n' "$n" "$(echo "$(date +%s.%N) - $t0" | bc)" "$status"
    if [ "$status" = FAILED ]; then
        tail -n 30 "$TMP/$n.log" | sed "s/^/[bench_smoke]   $n: /"
    fi
done
printf '[bench_smoke] total %.1f s for %d benchmarks\n' "$(echo "$(date +%s.%N) - $t_all" | bc)" "${#names[@]}"
# the published tables must be untouched (a benchmark that ignored the harness's folders)
touched="$(find scripts/results -newer "$TMP/.start" -type f 2>/dev/null)"
if [ -n "$touched" ]; then
    echo "[bench_smoke] FAILED: smoke runs wrote into scripts/results/: $touched"
    failed+=("scripts/results")
fi
if [ ${#failed[@]} -gt 0 ]; then
    echo "[bench_smoke] FAILED: ${failed[*]}"
    exit 1
fi
echo "[bench_smoke] all passed"
