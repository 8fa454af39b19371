#!/usr/bin/env bash
# Runs a command with every core kept busy by plain CPU hogs at normal priority (nice 0), as a
# shared CI machine or a developer's busy laptop would be; the hogs are stopped when the command
# ends, fails or is interrupted. `make test-under-load`, `make flake-hunt` (docs/testing.md).
#   tests/load/under_load.sh COMMAND [ARGS...]      HOGS=N overrides the count (default: nproc)
set -u
hogs=${HOGS:-$(nproc)}
pids=()
stop_hogs() {
    if ((${#pids[@]})); then
        kill "${pids[@]}" 2>/dev/null
        wait "${pids[@]}" 2>/dev/null
        pids=()
    fi
}
trap stop_hogs EXIT
trap 'stop_hogs; exit 130' INT
trap 'stop_hogs; exit 143' TERM
for _ in $(seq "$hogs"); do
    # A busy loop in its own shell: pure CPU, no memory, killed by its pid (never by name).
    bash -c 'while :; do :; done' &
    pids+=($!)
done
echo "under_load: $hogs CPU hogs at normal priority (pids ${pids[*]})" >&2
"$@"
status=$?
stop_hogs
echo "under_load: hogs stopped; the command exited with $status" >&2
exit $status
