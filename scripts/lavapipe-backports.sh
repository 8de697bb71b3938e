#!/usr/bin/env bash
# Source me: puts Mesa 25's lavapipe (Debian 12 bookworm-backports) in front of the system's
# Mesa 22 for this shell, without touching the system: the packages are fetched with a private
# apt configuration and unpacked under $LIGHTFARM_MESA_DIR (default ~/.cache/lightfarm-mesa).
# Measured here: 3.4-3.5x faster renders than Mesa 22.3.6 with bit-compatible images
# (BENCHMARKS.md). Anything that fails leaves the system lavapipe in place, with a message.
# Opt out with LIGHTFARM_LAVAPIPE=system.

lf_mesa_setup() {
    local dir="${LIGHTFARM_MESA_DIR:-$HOME/.cache/lightfarm-mesa}"
    local here
    here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
    [ "${LIGHTFARM_LAVAPIPE:-backports}" = system ] && return 0
    if ! grep -q '^VERSION_CODENAME=bookworm' /etc/os-release 2>/dev/null || [ "$(uname -m)" != x86_64 ]; then
        echo "lavapipe: not Debian 12 on x86_64, keeping the system's driver" >&2
        return 0
    fi
    if [ ! -f "$dir/lvp_icd.json" ]; then
        local mirror apt
        mirror="$(bash "$here/debian-mirror.sh")" || return 0
        mkdir -p "$dir/apt/lists/partial" "$dir/apt/cache/archives/partial" "$dir/debs" "$dir/root"
        printf 'deb %s bookworm main\ndeb %s bookworm-backports main\n' "$mirror" "$mirror" >"$dir/apt/sources.list"
        apt=(-o Dir::Etc::SourceList="$dir/apt/sources.list" -o Dir::Etc::SourceParts=/dev/null
             -o Dir::State::Lists="$dir/apt/lists" -o Dir::Cache="$dir/apt/cache" -o Debug::NoLocking=1)
        echo "lavapipe: fetching Mesa 25 lavapipe from bookworm-backports into $dir ..." >&2
        if ! apt-get "${apt[@]}" update -qq >/dev/null 2>&1 ||
            ! (cd "$dir/debs" && apt-get "${apt[@]}" download -qq mesa-vulkan-drivers/bookworm-backports \
                libdrm2/bookworm-backports >/dev/null 2>&1); then
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
}
lf_mesa_setup
