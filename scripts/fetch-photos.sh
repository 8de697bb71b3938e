#!/usr/bin/env bash
# Installs three public-domain portrait photographs for the real-photo tests, the demo and the
# README: assets/photos/{astronaut.png,camera.png,grace_hopper.jpg}. They come from Debian's
# python3-skimage (skimage/data/astronaut.png: Eileen Collins, NASA, public domain;
# camera.png: CC0) and python-matplotlib-data (sample_data/grace_hopper.jpg: US Navy photo,
# public domain), downloaded with `apt-get download` (no root, nothing installed) and unpacked;
# each photo is checked by hash, so a newer package with the same photos also does. Idempotent.
# Run by scripts/fetch-models.sh.
#
# Offline: put the two .deb files into $LIGHTFARM_CACHE/debs/ first, or copy assets/photos/.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
cache="${LIGHTFARM_CACHE:-$HOME/.cache/lightfarm}/debs"
dest="$root/assets/photos"
source "$root/scripts/pypi-cache.sh"

# name  sha256  package  path inside the package
photos=(
    "astronaut.png 88431cd9653ccd539741b555fb0a46b61558b301d4110412b5bc28b5e3ea6cb5 python3-skimage usr/lib/python3/dist-packages/skimage/data/astronaut.png"
    "camera.png b0793d2adda0fa6ae899c03989482bff9a42d3d5690fc7e3648f2795d730c23a python3-skimage usr/lib/python3/dist-packages/skimage/data/camera.png"
    "grace_hopper.jpg a8ca6d734765703b09728ab47fe59f473d93ae3967fc24c7c0288c3c7adb7130 python-matplotlib-data usr/share/matplotlib/mpl-data/sample_data/grace_hopper.jpg"
)

missing=0
for p in "${photos[@]}"; do
    read -r name sha _ _ <<<"$p"
    has_sha256 "$sha" "$dest/$name" || missing=1
done
if [ "$missing" = 0 ]; then
    echo "fetch-photos: $dest is installed"
    exit 0
fi
mkdir -p "$dest" "$cache"
tmp="$(mktemp -d)"; trap 'rm -rf "$tmp"' EXIT
for pkg in python3-skimage python-matplotlib-data; do
    deb="$(ls "$cache/${pkg}"_*_all.deb 2>/dev/null | tail -n1 || true)"
    if [ -z "$deb" ]; then
        command -v apt-get >/dev/null || { echo "fetch-photos: apt-get is needed to download $pkg; or put its .deb into $cache" >&2; exit 1; }
        echo "fetch-photos: downloading $pkg (Debian package, not installed)"
        # A fresh container has no package lists: refresh them once (as root) and retry.
        (cd "$cache" && apt-get download "$pkg" >/dev/null 2>"$tmp/apt.log") ||
        { [ "$(id -u)" = 0 ] && apt-get update -qq >/dev/null 2>&1 &&
          (cd "$cache" && apt-get download "$pkg" >/dev/null 2>"$tmp/apt.log"); } || {
            echo "fetch-photos: 'apt-get download $pkg' failed ($(tail -n1 "$tmp/apt.log")); run 'apt-get update' as root, or put ${pkg}_*_all.deb into $cache" >&2
            exit 1; }
        deb="$(ls "$cache/${pkg}"_*_all.deb | tail -n1)"
    fi
    mkdir -p "$tmp/$pkg"
    dpkg-deb -x "$deb" "$tmp/$pkg"
done
for p in "${photos[@]}"; do
    read -r name sha pkg path <<<"$p"
    if ! has_sha256 "$sha" "$tmp/$pkg/$path"; then
        echo "fetch-photos: $path in $pkg is missing or changed (expected sha256 $sha); delete $cache/${pkg}_*.deb and rerun" >&2
        exit 1
    fi
    cp "$tmp/$pkg/$path" "$dest/$name"
done
cat > "$dest/LICENSES.md" <<'TXT'
# Photographs (fetched by scripts/fetch-photos.sh)

| file | subject | source | licence |
|---|---|---|---|
| astronaut.png | Eileen Collins, NASA astronaut portrait | scikit-image `skimage/data` (Debian python3-skimage) | public domain (NASA) |
| camera.png | a man with a camera, in profile (grayscale) | scikit-image `skimage/data` | CC0 (scikit-image's data README) |
| grace_hopper.jpg | Rear Admiral Grace Hopper | matplotlib `mpl-data/sample_data` (Debian python-matplotlib-data) | public domain (US Navy photograph) |
TXT
echo "fetch-photos: installed $dest"
