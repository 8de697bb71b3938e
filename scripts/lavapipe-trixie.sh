#!/usr/bin/env bash
# Runs programs built on this Debian 12 host against Debian 13's newest lavapipe (Mesa 26 from
# trixie-backports, LLVM 19), in a Debian 13 root made with debootstrap. That driver needs
# glibc >= 2.39, so a Debian 12 process cannot load it; the root supplies its libraries.
#
# Why keep it at hand (BENCHMARKS.md, "Newer lavapipe"):
# - It renders 1.45-1.55x faster than bookworm-backports' Mesa 25 on the same box, and it is the
#   driver of the cluster image (scripts/docker-base.sh).
# - It handles floats the way NVIDIA does where Mesa 25 does not (denormals flushed to zero; min
#   and max return the other operand for a NaN), so the GPU-only bugs show up on a CPU box: the
#   ICT heads' NaN shading frames did, and the traversal counters test caught them here.
#
# Usage (as root: debootstrap, mount and chroot need it):
#   scripts/lavapipe-trixie.sh run PROGRAM [ARGS...]  a host program in the root, same cwd and paths
#   scripts/lavapipe-trixie.sh test [FILTER]          build the tests here, run the render, cli and
#                                                     light crates' tests there
#   LIGHTFARM_BIN=$(scripts/lavapipe-trixie.sh bin) bench/compare.sh 256 256
#                                                     the renderer benchmark on this driver
# The root is kept in $LIGHTFARM_TRIXIE_ROOT (default ~/.cache/lightfarm-trixie); the first call
# builds it (~30 s and ~700 MB here). Host paths are bind-mounted in a private mount namespace, so
# nothing stays mounted afterwards.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(dirname "$here")"
root="${LIGHTFARM_TRIXIE_ROOT:-$HOME/.cache/lightfarm-trixie}"

die() { echo "lavapipe-trixie: $*" >&2; exit 1; }
case "$root" in "" | / | "$HOME" | "$HOME/") die "LIGHTFARM_TRIXIE_ROOT=$root: name a folder of its own" ;; esac

ensure_root() {
    [ -f "$root/.ready" ] && return 0
    rm -rf "$root"
    bash "$here/trixie-root.sh" "$root" || die "could not make the Debian 13 root; rerun to retry"
    touch "$root/.ready"
}

# Runs "$@" (a host path and its arguments) inside the root.
run_in_root() {
    ensure_root
    local pass=() kv
    while IFS= read -r kv; do pass+=("$kv"); done < <(env | grep -E \
        '^(LIGHTFARM_[A-Z0-9_]*|LP_[A-Z_]*|MESA_[A-Z_]*|GALLIVM_[A-Z_]*|RUST_LOG|RUST_BACKTRACE|CARGO_TARGET_DIR)=' |
        grep -v -E '^LIGHTFARM_(BIN|TRIXIE_ROOT)=' || true)
    # The host's home (caches, the target dir), the repository and /tmp, at the same paths.
    local binds=("$HOME" "$repo" /tmp)
    unshare --mount --propagation private /bin/bash -c '
        set -e
        root=$1; shift
        n=$1; shift
        for d in proc sys dev; do mount --bind /$d "$root/$d"; done
        for ((i = 0; i < n; i++)); do mkdir -p "$root$1"; mount --bind "$1" "$root$1"; shift; done
        exec chroot "$root" "$@"' _ "$root" "${#binds[@]}" "${binds[@]}" \
        /usr/bin/env -i PATH=/usr/local/bin:/usr/bin:/bin HOME="$HOME" XDG_RUNTIME_DIR=/tmp "${pass[@]}" \
        /bin/bash -c 'cd "$1" && shift && exec "$@"' _ "$PWD" "$@"
}

cmd="${1:-}"
[ $# -gt 0 ] && shift
case "$cmd" in
run)
    [ $# -gt 0 ] || die "usage: $0 run PROGRAM [ARGS...]"
    run_in_root "$@"
    ;;
bin)
    ensure_root
    # A `lightfarm` for LIGHTFARM_BIN: the debug build unless LIGHTFARM_REAL_BIN names another.
    wrapper="$root/host-lightfarm"
    real="${LIGHTFARM_REAL_BIN:-${CARGO_TARGET_DIR:-$repo/target}/debug/lightfarm}"
    [ -x "$real" ] || die "$real is not built: cargo build --locked -p lightfarm (or set LIGHTFARM_REAL_BIN)"
    printf '#!/bin/sh\nexec %q run %q "$@"\n' "$here/lavapipe-trixie.sh" "$real" >"$wrapper"
    chmod +x "$wrapper"
    echo "$wrapper"
    ;;
test)
    cd "$repo"
    # Only the crates whose tests need nothing beyond Vulkan (the Python cross-checks and the
    # services are not in the root).
    list=$(cargo test --workspace --no-run --locked --message-format=json 2>/dev/null | python3 -c '
import json, sys
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m.get("executable") and m["profile"]["test"]:
        d = m["manifest_path"].rsplit("/", 1)[0]
        if d.endswith(("/crates/render", "/crates/cli", "/crates/light")):
            print(d, m["executable"])')
    [ -n "$list" ] || die "no test executables: does 'cargo test --workspace --no-run --locked' build?"
    failed=0
    while read -r dir exe; do
        echo "== $(basename "$exe")"
        (cd "$dir" && run_in_root "$exe" "$@") || failed=$((failed + 1))
    done <<<"$list"
    [ "$failed" = 0 ] || die "$failed test executables failed on $(chroot "$root" dpkg-query -W -f '${Version}' mesa-vulkan-drivers)"
    echo "lavapipe-trixie: every test passed"
    ;;
*)
    die "usage: $0 run PROGRAM [ARGS...] | bin | test [FILTER]"
    ;;
esac
