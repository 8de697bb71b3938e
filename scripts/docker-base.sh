#!/usr/bin/env bash
# Builds the local base image `lightfarm-base:trixie` without pulling from a registry:
# debootstrap a minimal Debian 13 with the Vulkan loader and Mesa's lavapipe (the CPU Vulkan
# driver; GPU nodes bring their own driver through the NVIDIA container runtime), then
# `docker import` it. Mesa comes from trixie-backports (26.x, LLVM 19): on the same 2-core box
# it renders 1.45-1.55x faster than bookworm-backports' Mesa 25.0.7 (LLVM 15), and Debian 12's
# own Mesa 22 is 3.5x slower still (BENCHMARKS.md), so CPU render workers want the newest.
# Users with a registry can skip this and build deploy/Dockerfile from the public
# debian:trixie-slim image (--build-arg BASE=debian:trixie-slim, see the README).
set -euo pipefail
cd "$(dirname "$0")/.."
IMAGE=${LIGHTFARM_BASE_IMAGE:-lightfarm-base:trixie}
if docker image inspect "$IMAGE" >/dev/null 2>&1; then
    echo "$IMAGE exists (docker rmi it to rebuild)"
    exit 0
fi
if [ "$(id -u)" != 0 ]; then
    echo "error: building the base image needs root (debootstrap, chroot); run it as root" >&2
    exit 1
fi
ROOT=$(mktemp -d /tmp/lightfarm-base.XXXXXX)
trap 'rm -rf "$ROOT"' EXIT
bash scripts/trixie-root.sh "$ROOT" tini
# Keep the image small: no apt lists, caches or docs.
chroot "$ROOT" apt-get clean
rm -rf "$ROOT"/var/lib/apt/lists/* "$ROOT"/usr/share/doc/* "$ROOT"/usr/share/man/* "$ROOT"/var/cache/*
tar -C "$ROOT" -c . | docker import - "$IMAGE" >/dev/null
echo "built $IMAGE ($(docker image inspect "$IMAGE" --format '{{.Size}}' | awk '{printf "%.0f MB", $1/1e6}'))"
