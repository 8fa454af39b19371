#!/usr/bin/env bash
# Runs one test (or any pytest selection) N times, each in a fresh pytest process, and says how
# many runs failed; the log of each failed run is kept. No retries: a run that fails is counted.
#   tests/load/flake_hunt.sh N LOGDIR PYTHON PYTEST_ARGS...
# `make flake-hunt TEST=... N=20` runs it under tests/load/under_load.sh (docs/testing.md).
set -u
n=$1 logdir=$2 python=$3
shift 3
logdir="$logdir/$(date -u +%Y%m%d-%H%M%S)-$$"   # one folder a hunt: hunts side by side do not mix
mkdir -p "$logdir"
failed=0
start=$SECONDS
for i in $(seq "$n"); do
    log="$logdir/run-$i.log"
    if "$python" -m pytest -q -p no:cacheprovider "$@" >"$log" 2>&1; then
        echo "flake-hunt: run $i/$n passed"
        rm -f "$log"
    else
        failed=$((failed + 1))
        echo "flake-hunt: run $i/$n FAILED (log: $log): $(grep -E '^(FAILED|ERROR)|[0-9]+ (failed|error)' "$log" | tail -1)"
    fi
done
echo "flake-hunt: $failed of $n runs failed in $((SECONDS - start)) s: $*"
[ "$failed" -eq 0 ]
