#!/usr/bin/env bash
# One stage of `make test` (docs/testing.md): runs the command with its output in LOGDIR/STAGE.log,
# and writes the stage's result and wall time to LOGDIR/STAGE.result. It exits 0 either way, so
# the stages beside it run on; tests/load/stage_summary.sh reports them all and fails for them.
#   tests/load/run_stage.sh STAGE LOGDIR COMMAND [ARGS...]
set -u
stage=$1 logdir=$2
shift 2
mkdir -p "$logdir"
start=$(date +%s)
echo "== $stage: started (output in $logdir/$stage.log)"
if "$@" >"$logdir/$stage.log" 2>&1; then result=passed; else result=FAILED; fi
seconds=$(($(date +%s) - start))
echo "$stage $result $seconds" >"$logdir/$stage.result"
echo "== $stage: $result in $seconds s"
