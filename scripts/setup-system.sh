#!/usr/bin/env bash
# Makes sure the system packages lightfarm needs are present: the Vulkan loader and Mesa's
# lavapipe CPU driver (so rendering works on machines with no GPU), and with
# LIGHTFARM_NEED_CHROMIUM=1 (scripts/test.sh) Debian's chromium for the dashboard's browser
# tests. Installs them when run as root; otherwise prints the exact command. Sourced by scripts/test.sh and scripts/demo.sh.
set -euo pipefail

missing=()
# grep without -q reads all of ldconfig's output: with -q it exits early, ldconfig dies of
# SIGPIPE and pipefail would report the library missing.
ldconfig -p 2>/dev/null | grep 'libvulkan.so.1' >/dev/null || missing+=(libvulkan1)
ls /usr/share/vulkan/icd.d/lvp_icd*.json >/dev/null 2>&1 || missing+=(mesa-vulkan-drivers)
# The dashboard's browser tests (scripts/test.sh asks for them) drive headless Chromium.
if [ -n "${LIGHTFARM_NEED_CHROMIUM:-}" ]; then
    command -v chromium >/dev/null 2>&1 || missing+=(chromium)
fi
if ! command -v cargo >/dev/null 2>&1; then
    echo "error: cargo not found: install Rust from https://rustup.rs (stable, 1.85 or newer)" >&2
    exit 1
fi
if [ ${#missing[@]} -gt 0 ]; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
        echo "installing ${missing[*]} (Vulkan loader + lavapipe CPU driver, Chromium for the tests)..." >&2
        export DEBIAN_FRONTEND=noninteractive
        apt-get update -qq
        apt-get install -y -qq "${missing[@]}" >/dev/null
    else
        echo "error: missing system packages: ${missing[*]}" >&2
        echo "run: sudo apt-get install -y ${missing[*]}" >&2
        exit 1
    fi
fi
# The Vulkan loader and Mesa want a runtime dir; CI and containers often have none.
if [ -z "${XDG_RUNTIME_DIR:-}" ]; then
    export XDG_RUNTIME_DIR="${TMPDIR:-/tmp}/lightfarm-runtime-$(id -u)"
    mkdir -p "$XDG_RUNTIME_DIR" && chmod 700 "$XDG_RUNTIME_DIR"
fi
# A persistent target dir outside the clone: rebuilds in a fresh clone stay incremental.
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/lightfarm-target}"
# A 3.5x faster lavapipe on Debian 12 (backports, private copy, system untouched); falls back
# to the system driver on any problem. LIGHTFARM_LAVAPIPE=system keeps Debian's Mesa 22.
source "$(dirname "${BASH_SOURCE[0]}")/lavapipe-backports.sh"
