#!/usr/bin/env bash
# Set up the Mitsuba 3 reference renderer for lightfarm's benchmark.
#
# Idempotent. Creates, under ${LIGHTFARM_BENCH_DIR:-$HOME/.cache/lightfarm-bench}:
#   venv/         Python venv with mitsuba (3.9.1 if available, else latest 3.x) and numpy
#   llvm19/       libllvm19 unpacked from Debian's .deb (Dr.Jit's llvm_* variants need LLVM >= 19;
#                 Debian 12's default LLVM 14/15 crash Dr.Jit)
#   env.sh        `source` it to get DRJIT_LIBLLVM_PATH and the venv's python on PATH
#
# Needs only the Debian and PyPI registries. Never modifies the system's apt configuration:
# when `apt-get download libllvm19` cannot find the package with the system's sources (e.g. a
# machine without bookworm 12.x point-release lists), it falls back to a private apt state dir
# with bookworm + bookworm-backports, then to a direct pool URL.
set -euo pipefail

BENCH_DIR="${LIGHTFARM_BENCH_DIR:-$HOME/.cache/lightfarm-bench}"
VENV="$BENCH_DIR/venv"
LLVM_DIR="$BENCH_DIR/llvm19"
PY="${PYTHON:-python3}"
MITSUBA_PIN="3.9.1"
DEBIAN_MIRROR="${DEBIAN_MIRROR:-$(bash "$(dirname "${BASH_SOURCE[0]}")/../scripts/debian-mirror.sh")}"
# Last-resort direct URL (Debian 12 point release package).
LLVM_POOL_URL="$DEBIAN_MIRROR/pool/main/l/llvm-toolchain-19/libllvm19_19.1.7-3~deb12u1_amd64.deb"

mkdir -p "$BENCH_DIR"
log() { echo "[setup_mitsuba] $*" >&2; }

# ---------------------------------------------------------------- Python venv
VPY="$VENV/bin/python"
if ! "$VPY" -m pip --version >/dev/null 2>&1; then
    rm -rf "$VENV"  # absent, or left half-made by a venv without ensurepip
    log "creating venv at $VENV"
    if ! "$PY" -m venv "$VENV" 2>/dev/null; then
        rm -rf "$VENV"
        if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
            log "python3 -m venv failed; installing python3-venv"
            apt-get update -qq >/dev/null 2>&1 || true
            DEBIAN_FRONTEND=noninteractive apt-get install -y -qq python3-venv >/dev/null
            "$PY" -m venv "$VENV"
        else
            log "python3 -m venv failed; run as root: apt-get update && apt-get install -y python3-venv"
            exit 1
        fi
    fi
fi
"$VPY" -m pip install -q --upgrade pip >/dev/null 2>&1 || true

have_mitsuba_version() {
    "$VPY" -c 'import importlib.metadata as m; print(m.version("mitsuba"))' 2>/dev/null || true
}
cur="$(have_mitsuba_version)"
if [ "$cur" = "$MITSUBA_PIN" ] || { [ -n "$cur" ] && [ "${LIGHTFARM_ALLOW_UNPINNED:-0}" = 1 ]; }; then
    log "mitsuba $cur already installed"
else
    log "installing mitsuba==$MITSUBA_PIN (fallback: latest 3.x)"
    if ! "$VPY" -m pip install -q "mitsuba==$MITSUBA_PIN"; then
        log "mitsuba $MITSUBA_PIN not available; installing latest 3.x"
        "$VPY" -m pip install -q "mitsuba>=3,<4"
    fi
fi
"$VPY" -c 'import numpy' 2>/dev/null || "$VPY" -m pip install -q numpy

# ---------------------------------------------------------------- libLLVM 19
find_libllvm() { find "$LLVM_DIR" -name 'libLLVM.so.19*' -type f 2>/dev/null | sort | head -n1 || true; }

LIBLLVM="$(find_libllvm)"
if [ -z "$LIBLLVM" ]; then
    mkdir -p "$LLVM_DIR/deb"
    deb="$(ls "$LLVM_DIR"/deb/libllvm19_*.deb 2>/dev/null | head -n1 || true)"
    if [ -z "$deb" ]; then
        if [ "$(id -u)" != 0 ]; then
            cat >&2 <<EOF
[setup_mitsuba] not root: fetch libllvm19 yourself, then re-run this script:
    sudo apt-get update
    (cd "$LLVM_DIR/deb" && apt-get download libllvm19)
  or, if apt cannot find it (needs Debian 12.x lists, or bookworm-backports):
    (cd "$LLVM_DIR/deb" && curl -fLO '$LLVM_POOL_URL')
  the script then runs:
    dpkg-deb -x "$LLVM_DIR"/deb/libllvm19_*.deb "$LLVM_DIR/root"
EOF
            # apt-get download itself works unprivileged once lists exist: try it anyway.
            (cd "$LLVM_DIR/deb" && apt-get download libllvm19 >/dev/null 2>&1) || true
        else
            log "fetching libllvm19 with apt-get download"
            (cd "$LLVM_DIR/deb" && { apt-get download libllvm19 2>/dev/null || {
                apt-get update -qq >/dev/null 2>&1 || true; apt-get download libllvm19; }; }) || true
        fi
        deb="$(ls "$LLVM_DIR"/deb/libllvm19_*.deb 2>/dev/null | head -n1 || true)"
    fi
    if [ -z "$deb" ]; then
        # Private apt state: bookworm + bookworm-backports, without touching /etc/apt.
        log "system apt has no libllvm19; trying a private apt config with bookworm-backports"
        A="$LLVM_DIR/apt"
        mkdir -p "$A/lists/partial" "$A/cache/archives/partial"
        cat >"$A/sources.list" <<EOF
deb $DEBIAN_MIRROR bookworm main
deb $DEBIAN_MIRROR bookworm-backports main
EOF
        APTOPT=(-o Dir::Etc::SourceList="$A/sources.list" -o Dir::Etc::SourceParts=/dev/null
                -o Dir::State::Lists="$A/lists" -o Dir::Cache="$A/cache"
                -o Debug::NoLocking=1)
        if apt-get "${APTOPT[@]}" update -qq >/dev/null 2>&1; then
            (cd "$LLVM_DIR/deb" && apt-get "${APTOPT[@]}" download libllvm19) || true
        fi
        deb="$(ls "$LLVM_DIR"/deb/libllvm19_*.deb 2>/dev/null | head -n1 || true)"
    fi
    if [ -z "$deb" ]; then
        log "trying direct pool URL $LLVM_POOL_URL"
        fetch_ok=0
        if command -v curl >/dev/null; then
            (cd "$LLVM_DIR/deb" && curl -fsSLO "$LLVM_POOL_URL") && fetch_ok=1
        elif command -v wget >/dev/null; then
            (cd "$LLVM_DIR/deb" && wget -q "$LLVM_POOL_URL") && fetch_ok=1
        else
            "$VPY" - "$LLVM_POOL_URL" "$LLVM_DIR/deb" <<'EOF' && fetch_ok=1
import sys, os, urllib.request, urllib.parse
url, d = sys.argv[1], sys.argv[2]
name = urllib.parse.unquote(url.rsplit("/", 1)[1])
urllib.request.urlretrieve(url, os.path.join(d, name))
EOF
        fi
        deb="$(ls "$LLVM_DIR"/deb/libllvm19_*.deb 2>/dev/null | head -n1 || true)"
    fi
    if [ -z "$deb" ]; then
        log "could not obtain libllvm19; llvm_ad_rgb will be unavailable (scalar_rgb still works)"
    else
        log "unpacking $(basename "$deb")"
        dpkg-deb -x "$deb" "$LLVM_DIR/root"
    fi
    LIBLLVM="$(find_libllvm)"
fi

# ---------------------------------------------------------------- env + check
{
    echo "# generated by bench/setup_mitsuba.sh"
    echo "export LIGHTFARM_BENCH_DIR='$BENCH_DIR'"
    echo "export PATH='$VENV/bin':\"\$PATH\""
    [ -n "$LIBLLVM" ] && echo "export DRJIT_LIBLLVM_PATH='$LIBLLVM'"
} >"$BENCH_DIR/env.sh"

if [ -n "$LIBLLVM" ]; then
    if DRJIT_LIBLLVM_PATH="$LIBLLVM" "$VPY" -c \
        'import mitsuba as mi; mi.set_variant("llvm_ad_rgb"); print(mi.__version__)' >/dev/null 2>&1; then
        log "llvm_ad_rgb OK with $LIBLLVM"
    else
        log "WARNING: llvm_ad_rgb failed to initialise with $LIBLLVM"
    fi
fi
log "mitsuba $(have_mitsuba_version) in $VENV"
log "to use:  source $BENCH_DIR/env.sh"
if [ -n "$LIBLLVM" ]; then
    echo "DRJIT_LIBLLVM_PATH=$LIBLLVM"
else
    echo "DRJIT_LIBLLVM_PATH="
fi
