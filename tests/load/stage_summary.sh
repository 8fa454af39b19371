#!/usr/bin/env bash
# The end of `make test`: each stage's result and wall time, the end of every failed stage's log,
# the total; exits 1 if any stage failed or did not finish.
#   tests/load/stage_summary.sh LOGDIR STAGE...
set -u
logdir=$1
shift
failed=()
echo
echo "== make test: stages (side by side; each one's output in $logdir/STAGE.log)"
for stage in "$@"; do
    if [ -f "$logdir/$stage.result" ]; then
        read -r _ result seconds <"$logdir/$stage.result"
    else
        result="DID-NOT-FINISH" seconds="-"
    fi
    printf '   %-18s %-14s %5s s\n' "$stage" "$result" "$seconds"
    [ "$result" = passed ] || failed+=("$stage")
done
if [ -f "$logdir/.start" ]; then
    echo "   total (wall)                     $(($(date +%s) - $(cat "$logdir/.start"))) s"
fi
for stage in "${failed[@]}"; do
    echo
    echo "== $stage: FAILED; the end of $logdir/$stage.log:"
    tail -n 40 "$logdir/$stage.log" 2>/dev/null
done
if ((${#failed[@]})); then
    echo "== make test: FAILED: ${failed[*]}"
    exit 1
fi
echo "== make test: every stage passed"
