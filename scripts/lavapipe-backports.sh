#!/usr/bin/env bash
# Source me: puts the newest lavapipe Debian packages for this release (Mesa 25 from
# bookworm-backports on Debian 12, Mesa 26 from trixie-backports on Debian 13) in front of the
# system's, for this shell, without touching the system: the packages are fetched with a private
# apt configuration and unpacked under $LIGHTFARM_MESA_DIR/<suite> (default
# ~/.cache/lightfarm-mesa). Measured on the 2-core box (BENCHMARKS.md): Mesa 25.0.7 renders
# 3.4-3.5x faster than Debian 12's Mesa 22.3.6, and Mesa 26.1 (LLVM 19) 1.45-1.55x faster than
# Mesa 25.0.7 (LLVM 15). Anything that fails leaves the system lavapipe in place, with a message.
# Opt out with LIGHTFARM_LAVAPIPE=system.

lf_mesa_setup() {
    local base="${LIGHTFARM_MESA_DIR:-$HOME/.cache/lightfarm-mesa}"
    local here release suite extra
    here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
    [ "${LIGHTFARM_LAVAPIPE:-backports}" = system ] && return 0
    release="$(sed -n 's/^VERSION_CODENAME=//p' /etc/os-release 2>/dev/null)"
    case "$release" in
        # libdrm2 and libdisplay-info2: the backported driver needs newer ones than the
        # release ships (bookworm) or than a minimal install has (trixie).
        bookworm) extra="libdrm2/bookworm-backports" ;;
        trixie) extra="libdisplay-info2" ;;
        *) release="" ;;
    esac
    if [ -z "$release" ] || [ "$(uname -m)" != x86_64 ]; then
        echo "lavapipe: not Debian 12 or 13 on x86_64, keeping the system's driver" >&2
        return 0
    fi
    suite="$release-backports"
    local dir="$base/$suite"
    # Before one folder per suite, the bookworm driver sat in $base itself.
    [ -f "$base/lvp_icd.json" ] && rm -rf "$base/lvp_icd.json" "$base/root" "$base/debs" "$base/apt"
    if [ ! -f "$dir/lvp_icd.json" ]; then
        local mirror apt
        mirror="$(bash "$here/debian-mirror.sh")" || return 0
        mkdir -p "$dir/apt/lists/partial" "$dir/apt/cache/archives/partial" "$dir/debs" "$dir/root"
        printf 'deb %s %s main\ndeb %s %s main\n' "$mirror" "$release" "$mirror" "$suite" >"$dir/apt/sources.list"
        apt=(-o Dir::Etc::SourceList="$dir/apt/sources.list" -o Dir::Etc::SourceParts=/dev/null
             -o Dir::State::Lists="$dir/apt/lists" -o Dir::Cache="$dir/apt/cache" -o Debug::NoLocking=1)
        echo "lavapipe: fetching Mesa's lavapipe from $suite into $dir ..." >&2
        if ! apt-get "${apt[@]}" update -qq >/dev/null 2>&1 ||
            ! (cd "$dir/debs" && apt-get "${apt[@]}" download -qq "mesa-vulkan-drivers/$suite" \
                "$extra" >/dev/null 2>&1); then
            echo "lavapipe: could not fetch the backports driver, keeping the system's" >&2
            return 0
        fi
        local deb
        for deb in "$dir"/debs/*.deb; do dpkg-deb -x "$deb" "$dir/root" || return 0; done
        local lib="$dir/root/usr/lib/x86_64-linux-gnu/libvulkan_lvp.so"
        [ -f "$lib" ] || { echo "lavapipe: unexpected package layout, keeping the system's driver" >&2; return 0; }
        sed "s#\"library_path\": \"[^\"]*\"#\"library_path\": \"$lib\"#" \
            "$dir/root/usr/share/vulkan/icd.d/lvp_icd.json" >"$dir/lvp_icd.json.tmp" && mv "$dir/lvp_icd.json.tmp" "$dir/lvp_icd.json"
    fi
    # Replace only the system's lavapipe: other drivers (an NVIDIA GPU) stay visible.
    local icds="$dir/lvp_icd.json" f
    for f in /usr/share/vulkan/icd.d/*.json /etc/vulkan/icd.d/*.json; do
        [ -f "$f" ] || continue
        case "$(basename "$f")" in lvp_icd*) ;; *) icds="$icds:$f" ;; esac
    done
    # A driver whose libraries do not resolve would leave no device at all: keep the system's.
    if LD_LIBRARY_PATH="$dir/root/usr/lib/x86_64-linux-gnu${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}" \
        ldd "$dir/root/usr/lib/x86_64-linux-gnu/libvulkan_lvp.so" 2>/dev/null | grep -q 'not found'; then
        echo "lavapipe: the backports driver misses libraries here, keeping the system's" >&2
        return 0
    fi
    export VK_ICD_FILENAMES="$icds"
    export LD_LIBRARY_PATH="$dir/root/usr/lib/x86_64-linux-gnu${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
    lf_mesa_backports=1
}
lf_mesa_backports=0
lf_mesa_setup
# Debian 12's own Mesa 22.3.6 ends every loop of a shader invocation once its loops have turned
# 65,535 times in all (gallivm's LP_MAX_TGSI_LOOP_ITERATIONS); the renderer finds that at start
# and renders one sample per dispatch there, slower still. Say so wherever a Debian 12 shell is
# left with it.
if [ "$lf_mesa_backports" = 0 ] && grep -q '^VERSION_CODENAME=bookworm' /etc/os-release 2>/dev/null; then
    echo "lavapipe: WARNING: Debian 12's own Mesa 22 renders 6-7x slower than Mesa 25 and ends" \
        "shader loops after 65,535 turns (the renderer then takes one sample per dispatch);" \
        "unset LIGHTFARM_LAVAPIPE or fix the fetch above to use Mesa 25 from bookworm-backports" >&2
fi
unset lf_mesa_backports
