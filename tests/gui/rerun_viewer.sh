#!/bin/bash
# The Rerun viewer under Xvfb on this host (docs/viewers.md, tests/gui/test_rerun_viewer.py):
#   rerun_viewer.sh check    says whether Xvfb and Mesa's software Vulkan driver (lavapipe) are here
#   rerun_viewer.sh setup    installs them from Debian when missing (as root: CI; else says what to run)
# The viewer itself comes with the rerun-sdk wheel (requirements.txt).
set -u
PACKAGES="xvfb xauth mesa-vulkan-drivers"

missing() {
    command -v Xvfb >/dev/null || echo "Xvfb (package xvfb)"
    ls /usr/share/vulkan/icd.d/lvp_icd*.json >/dev/null 2>&1 || echo "Mesa's software Vulkan driver (package mesa-vulkan-drivers)"
}

case "${1:-check}" in
    check)
        m=$(missing)
        if [[ -z $m ]]; then echo "ready"; else echo "missing: $(echo "$m" | paste -sd, -)"; exit 1; fi ;;
    setup)
        [[ -z $(missing) ]] && exit 0
        if [[ $(id -u) != 0 ]]; then
            echo "the Rerun viewer tests need: apt-get install $PACKAGES (as root)"; exit 1
        fi
        export DEBIAN_FRONTEND=noninteractive
        apt-get update -qq && apt-get install -y -qq --no-install-recommends $PACKAGES >/dev/null
        [[ -z $(missing) ]] || { echo "still missing after apt-get: $(missing)"; exit 1; } ;;
    *)
        echo "usage: $0 check|setup" >&2; exit 2 ;;
esac
