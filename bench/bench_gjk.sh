#!/usr/bin/env bash
# GJK+EPA benchmark against libccd (bench-only dependency). Run from anywhere:
#   bash bench/bench_gjk.sh
# Installs libccd-dev with apt-get when missing, links the core's static library (make lib,
# the project's C flags), prints a Markdown table on stdout.
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
make -s lib >&2
${CC:-cc} $(cat native/cflags.txt) -O2 -Inative/include -Inative/src \
    bench/bench_gjk.c build/c/libgraspcore.a $CCD_FLAGS -lm -lpthread -o build/bench/bench_gjk
exec build/bench/bench_gjk
