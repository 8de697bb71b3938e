#!/usr/bin/env bash
# Frees what earlier builds left in a reused target dir before the suite builds again, and
# says how much disk there is. Usage: scripts/prune-target.sh [TARGET_DIR]
#
# Why: CI reuses one target dir across commits. Every change to a crate links its test binaries
# anew under a new hash, and the old ones stay; incremental caches grow the same way. A CI run
# once died linking (`ld` killed by SIGBUS, then "No space left on device"). Only files that no
# build can use again go: the incremental caches (the suite builds with CARGO_INCREMENTAL=0)
# and, per test or binary target, every executable but the newest. A target is its name and its
# root source file (from the executable's dep-info): a crate's lib and bin tests, or two
# packages' tests/device.rs, share a name. Libraries stay, since one crate can be built twice on
# purpose (for build scripts and for the target).
# A change to Cargo.toml's [profile.*] sections gives every artifact a new hash, so the whole
# old build is garbage that would sit beside the new one: the profiles' hash is kept in the
# target dir, and when it differs (or was never written) the debug build goes whole.
set -euo pipefail
dir="${1:-${CARGO_TARGET_DIR:-$HOME/.cache/lightfarm-target}}"
# A cold build of the suite filled 4.9 GB (`du -sh` of a fresh target dir, 2026-12-05), plus
# room for the tests' own files and the next change.
need_gib=8
mkdir -p "$dir"

freed_kib=0
remove() {
    local kib
    kib=$(du -sk "$1" | cut -f1)
    rm -rf -- "$1"
    freed_kib=$((freed_kib + kib))
}

manifest="$(dirname "${BASH_SOURCE[0]}")/../Cargo.toml"
profiles=$(awk '/^\[/ { p = /^\[profile/ } p && NF && !/^[[:space:]]*#/' "$manifest" | sha256sum | cut -d' ' -f1)
stamp="$dir/.lightfarm-profiles"
if [ -d "$dir/debug" ] && [ "$(cat "$stamp" 2>/dev/null)" != "$profiles" ]; then
    echo "prune-target: Cargo.toml's profiles changed since $dir was built: removing its debug build"
    remove "$dir/debug"
fi
echo "$profiles" > "$stamp"

for profile in debug release; do
    [ -d "$dir/$profile/incremental" ] && remove "$dir/$profile/incremental"
    deps="$dir/$profile/deps"
    [ -d "$deps" ] || continue
    # Executables are named STEM-HASH (16 hex digits); newest first, so the first of a stem stays.
    declare -A seen=()
    while IFS= read -r path; do
        name=$(basename "$path")
        stem="${name%-*}"
        hash="${name##*-}"
        [[ "$hash" =~ ^[0-9a-f]{16}$ ]] || continue
        # The dep-info's first line is "EXE: ROOT OTHER..."; the root's last three components
        # name the target the same way in any clone of the repository.
        if [ -f "$path.d" ]; then
            root=$(head -n 1 "$path.d" | awk '{ print $2 }' | awk -F/ '{ print $(NF-2) "/" $(NF-1) "/" $NF }')
            stem="$stem:$root"
        fi
        if [ -n "${seen[$stem]:-}" ]; then
            remove "$path"
            rm -f -- "$path.d"
        else
            seen[$stem]=1
        fi
    done < <(find "$deps" -maxdepth 1 -type f -perm -u+x ! -name '*.so' ! -name '*.rlib' \
        ! -name '*.rmeta' ! -name '*.d' -printf '%T@ %p\n' | sort -rn | cut -d' ' -f2-)
    unset seen
done

avail_kib=$(df -Pk "$dir" | awk 'NR == 2 { print $4 }')
echo "prune-target: freed $((freed_kib / 1024)) MiB in $dir; $((avail_kib / 1048576)) GiB free there"
if [ "$avail_kib" -lt $((need_gib * 1048576)) ]; then
    echo "warning: the suite's build and tests can need ~${need_gib} GiB; only" \
        "$((avail_kib / 1048576)) GiB are free under $dir." >&2
    echo "  free disk there, or point CARGO_TARGET_DIR at a larger disk; 'rm -rf $dir' starts" \
        "a cold build (~30 min on 2 cores)." >&2
fi
