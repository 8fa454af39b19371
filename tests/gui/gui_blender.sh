#!/usr/bin/env bash
# A real GUI Blender for the GUI tests (docs/gui-tests.md).
#
#   gui_blender.sh setup          build the cached Debian 13 chroot with Blender 4.3 + Xvfb
#                                 (root and debootstrap needed; reused while its stamp is valid)
#   gui_blender.sh check          exit 0 when a GUI Blender can be run, else say why (exit 3)
#   gui_blender.sh blender ARGS... run the GUI Blender with ARGS under Xvfb: inside the chroot with
#                                 /tmp and the repository visible at their own paths (a private
#                                 mount namespace, so nothing stays mounted when it exits), and
#                                 the BLENDER_USER_* and GRASP_LAB_* variables passed in
#   gui_blender.sh run CMD...     the same for any command (CMD is looked up in the chroot)
#
# BLENDER=/path/to/blender uses a user's own Blender (an official 4.5 LTS / 5.x build) instead
# of the chroot: then xvfb-run, xdotool and ImageMagick must be installed on the host.
set -euo pipefail

ROOT=${GRASP_LAB_GUI_ROOT:-${XDG_CACHE_HOME:-$HOME/.cache}/grasp-lab/gui-blender-trixie}
STAMP_VERSION=2
STAMP="$ROOT/.grasp-lab-gui-v$STAMP_VERSION"
REPO=$(cd "$(dirname "$0")/../.." && pwd)
PACKAGES="blender python3-numpy xvfb xauth imagemagick xdotool libgl1-mesa-dri libegl1 libegl-mesa0 libglx-mesa0 procps"
SCREEN=${GRASP_LAB_GUI_SCREEN:-1600x900x24}

why_not() {
    if [[ -n "${BLENDER:-}" ]]; then
        [[ -x "$BLENDER" ]] || { echo "BLENDER=$BLENDER is not an executable"; return; }
        command -v xvfb-run >/dev/null || { echo "BLENDER is set but xvfb-run is missing on this host (apt-get install xvfb xauth xdotool imagemagick)"; return; }
        command -v xdotool >/dev/null || { echo "BLENDER is set but xdotool is missing on this host"; return; }
        return
    fi
    [[ -f "$STAMP" ]] && return
    [[ $(id -u) == 0 ]] || { echo "the GUI Blender chroot needs root to build (or set BLENDER=/path/to/blender with xvfb-run, xdotool and ImageMagick installed)"; return; }
    [[ -f /etc/debian_version ]] || { echo "the GUI Blender chroot is built with Debian's debootstrap (or set BLENDER=/path/to/blender)"; return; }
}

mirror() {
    local uri
    uri=$(sed -n 's/^URIs: *\([^ ]*\).*/\1/p' /etc/apt/sources.list.d/debian.sources 2>/dev/null | grep -v security | head -1 || true)
    [[ -n "$uri" ]] || uri=$(awk '$1=="deb" && $2 !~ /security/ {print $2; exit}' /etc/apt/sources.list 2>/dev/null || true)
    echo "${uri:-http://deb.debian.org/debian}"
}

in_chroot() {  # in_chroot CMD...: bind the host's kernel filesystems, /tmp and the repo; run; unmount by exiting
    local cd_exec='cd "$0" 2>/dev/null || cd /; exec "$@"'
    # shellcheck disable=SC2046 # the passed variables are one word each
    unshare --mount --propagation private -- bash -c '
        set -e
        root=$1; repo=$2; shift 2
        for d in /proc /sys /dev /dev/pts /dev/shm /tmp; do mkdir -p "$root$d"; mount --rbind "$d" "$root$d"; done
        mkdir -p "$root$repo"; mount --bind "$repo" "$root$repo"
        cp /etc/resolv.conf "$root/etc/resolv.conf" 2>/dev/null || true
        exec chroot "$root" /usr/bin/env -i PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin \
            HOME=/root LANG=C.UTF-8 TERM=dumb "$@"' _ "$ROOT" "$REPO" \
        $(env | grep -E '^(BLENDER_USER_[A-Z_]*|GRASP_LAB_[A-Z_]*)=' || true) \
        /bin/sh -c "$cd_exec" "$PWD" "$@"
}

setup() {
    if [[ -n "${BLENDER:-}" ]]; then echo "BLENDER=$BLENDER: using it, no chroot"; return; fi
    local reason; reason=$(why_not)
    [[ -z "$reason" ]] || { echo "gui_blender: cannot set up: $reason" >&2; exit 3; }
    if [[ -f "$STAMP" ]]; then
        if in_chroot blender --version 2>/dev/null | grep -q '^Blender [4-9]'; then
            echo "GUI Blender: cached in $ROOT"; return
        fi
        echo "GUI Blender: the cached chroot in $ROOT does not run Blender: building it again"
        rm -f "$STAMP"
    fi
    local t0=$SECONDS
    command -v debootstrap >/dev/null || { apt-get update -qq; DEBIAN_FRONTEND=noninteractive apt-get install -y -qq debootstrap >/dev/null; }
    local tmp="$ROOT.partial"
    rm -rf "$tmp"; mkdir -p "$tmp"
    echo "GUI Blender: debootstrap trixie into $tmp ($(mirror))"
    debootstrap --variant=minbase trixie "$tmp" "$(mirror)" > "$tmp.log" 2>&1 || { tail -20 "$tmp.log" >&2; exit 1; }
    ROOT=$tmp in_chroot bash -c "apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $PACKAGES" >> "$tmp.log" 2>&1 \
        || { tail -20 "$tmp.log" >&2; exit 1; }
    ROOT=$tmp in_chroot blender --version | head -1
    rm -rf "$ROOT"; mv "$tmp" "$ROOT"; mv "$tmp.log" "$ROOT/setup.log"
    touch "$STAMP"
    echo "$((SECONDS - t0))" > "$ROOT/setup-seconds"
    echo "GUI Blender: set up in $((SECONDS - t0)) s"
}

case "${1:-}" in
    setup) setup ;;
    check) reason=$(why_not); if [[ -n "$reason" ]]; then echo "$reason"; exit 3; fi ;;
    run|blender)
        cmd=$1; shift
        if [[ -n "${BLENDER:-}" ]]; then
            [[ $cmd == blender ]] && set -- "$BLENDER" "$@"
            exec xvfb-run -a -s "-screen 0 $SCREEN" "$@"
        fi
        [[ -f "$STAMP" ]] || { echo "gui_blender: not set up (run: $0 setup)" >&2; exit 3; }
        [[ $cmd == blender ]] && set -- /usr/bin/blender "$@"
        in_chroot xvfb-run -a -s "-screen 0 $SCREEN" "$@" ;;
    *) echo "usage: $0 setup | check | blender ARGS... | run CMD..." >&2; exit 2 ;;
esac
