#!/usr/bin/env bash
# Builds the local base image `lightfarm-base:bookworm` without pulling from a registry:
# debootstrap a minimal Debian 12 with the Vulkan loader and Mesa's lavapipe (the CPU Vulkan
# driver; GPU nodes bring their own driver through the NVIDIA container runtime), then
# `docker import` it. Users with a registry can skip this and build deploy/Dockerfile from the
# public debian:bookworm-slim image (--build-arg BASE=debian:bookworm-slim).
set -euo pipefail
cd "$(dirname "$0")/.."
IMAGE=${LIGHTFARM_BASE_IMAGE:-lightfarm-base:bookworm}
if docker image inspect "$IMAGE" >/dev/null 2>&1; then
    echo "$IMAGE exists (docker rmi it to rebuild)"
    exit 0
fi
if ! command -v debootstrap >/dev/null; then
    if [ "$(id -u)" = 0 ]; then
        apt-get update -qq && apt-get install -y -qq debootstrap >/dev/null
    else
        echo "error: debootstrap is missing; run: sudo apt-get install -y debootstrap" >&2
        exit 1
    fi
fi
MIRROR=$(scripts/debian-mirror.sh 2>/dev/null || echo "http://deb.debian.org/debian")
ROOT=$(mktemp -d /tmp/lightfarm-base.XXXXXX)
trap 'rm -rf "$ROOT"' EXIT
echo "debootstrap bookworm from $MIRROR into $ROOT ..."
debootstrap --variant=minbase --include=ca-certificates,libvulkan1,mesa-vulkan-drivers,tini \
    bookworm "$ROOT" "$MIRROR" >/dev/null
# Keep the image small: no apt lists, caches or docs.
chroot "$ROOT" apt-get clean
rm -rf "$ROOT"/var/lib/apt/lists/* "$ROOT"/usr/share/doc/* "$ROOT"/usr/share/man/* "$ROOT"/var/cache/*
tar -C "$ROOT" -c . | docker import - "$IMAGE" >/dev/null
echo "built $IMAGE ($(docker image inspect "$IMAGE" --format '{{.Size}}' | awk '{printf "%.0f MB", $1/1e6}'))"
