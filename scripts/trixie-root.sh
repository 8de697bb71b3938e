#!/usr/bin/env bash
# Makes a minimal Debian 13 root in DIR with the Vulkan loader and trixie-backports' lavapipe
# (Mesa 26, LLVM 19), plus any PACKAGES from trixie: the one recipe behind the cluster's base
# image (scripts/docker-base.sh) and the Mesa 26 test root (scripts/lavapipe-trixie.sh).
# Usage (as root): scripts/trixie-root.sh DIR [PACKAGES...]
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
[ $# -ge 1 ] || { echo "usage: $0 DIR [PACKAGES...]" >&2; exit 2; }
root=$1
shift
if [ "$(id -u)" != 0 ]; then
    echo "error: making a Debian 13 root needs root (debootstrap, chroot)" >&2
    exit 1
fi
if ! command -v debootstrap >/dev/null; then
    apt-get update -qq && apt-get install -y -qq debootstrap >/dev/null
fi
mirror="$(bash "$here/debian-mirror.sh" 2>/dev/null || echo http://deb.debian.org/debian)"
include="ca-certificates,libvulkan1"
for p in "$@"; do include="$include,$p"; done
echo "debootstrap trixie from $mirror into $root ..." >&2
if ! debootstrap --variant=minbase --include="$include" trixie "$root" "$mirror" >/dev/null; then
    echo "error: debootstrap failed (network? mirror $mirror); $root is incomplete" >&2
    exit 1
fi
echo "deb $mirror trixie-backports main" >"$root/etc/apt/sources.list.d/backports.list"
cp /etc/resolv.conf "$root/etc/resolv.conf"
chroot "$root" apt-get update -qq
chroot "$root" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
    -t trixie-backports mesa-vulkan-drivers >/dev/null
echo "lavapipe in $root: Mesa $(chroot "$root" dpkg-query -W -f '${Version}' mesa-vulkan-drivers)" >&2
