#!/usr/bin/env bash
# GJK+EPA benchmark against libccd (bench-only dependency). Run from anywhere:
#   bash bench/bench_gjk.sh
# Installs libccd-dev with apt-get when missing, builds with the project's C flags,
# prints a Markdown table on stdout.
set -euo pipefail
cd "$(dirname "$0")/.."

if ! { [ -f /usr/include/ccd/ccd.h ] && ldconfig -p 2>/dev/null | grep -q libccd; }; then
    SUDO=""
    if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
    echo "bench_gjk: installing libccd-dev" >&2
    $SUDO apt-get update >&2
    $SUDO apt-get install -y libccd-dev >&2
fi

CCD_FLAGS="$(pkg-config --cflags --libs ccd 2>/dev/null || echo -lccd)"
mkdir -p build/bench
${CC:-cc} -std=c11 -O2 -ffp-contract=off -Wall -Wextra -Inative/include -Inative/src \
    bench/bench_gjk.c native/src/geometry.c native/src/hull.c $CCD_FLAGS -lm -o build/bench/bench_gjk
exec build/bench/bench_gjk
