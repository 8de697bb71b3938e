#!/usr/bin/env bash
# Installs MediaPipe's face mesh (Google, Apache-2.0), which gives the skin mask of the
# real-photo lighting metric (lightfarm eval --real): assets/models/mediapipe/face_landmark.tflite
# (1.2 MB, TensorFlow Lite, read by crates/face), taken from the mediapipe==0.10.14 wheel on
# PyPI (cp311 manylinux; later releases ship no models) and checked by hash, with the wheel's
# licence. Idempotent. Run by scripts/fetch-models.sh.
#
# Air-gapped cluster: put the wheel named below into $LIGHTFARM_CACHE/wheels/ first (it is
# then not downloaded), or copy assets/models/mediapipe/ from a connected machine.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
cache="${LIGHTFARM_CACHE:-$HOME/.cache/lightfarm}/wheels"
dest="$root/assets/models/mediapipe"
wheel="mediapipe-0.10.14-cp311-cp311-manylinux_2_17_x86_64.manylinux2014_x86_64.whl"
wheel_sha256="a807328339e7356fda0bb14df12fedbf1d33bdf81649c5f8666b0026b1cc30b4"
model="mediapipe/modules/face_landmark/face_landmark.tflite"
model_sha256="1055cb9d4a9ca8b8c688902a3a5194311138ba256bcc94e336d8373a5f30c814"

source "$root/scripts/pypi-cache.sh"

if has_sha256 "$model_sha256" "$dest/face_landmark.tflite" && [ -f "$dest/LICENSE" ]; then
    echo "fetch-facemesh: $dest is installed"
    exit 0
fi
pypi_cached fetch-facemesh "mediapipe==0.10.14" "$wheel" "$wheel_sha256" "$cache" "36 MB" \
    --only-binary=:all: --python-version 311 --platform manylinux_2_17_x86_64
mkdir -p "$dest"
tmp="$(mktemp -d)"; trap 'rm -rf "$tmp"' EXIT
python3 -c 'import sys, zipfile; zipfile.ZipFile(sys.argv[1]).extractall(sys.argv[2], sys.argv[3:])' \
    "$cache/$wheel" "$tmp" "$model" "mediapipe-0.10.14.dist-info/LICENSE"
if ! has_sha256 "$model_sha256" "$tmp/$model"; then
    echo "fetch-facemesh: $model inside the wheel has an unexpected hash" >&2; exit 1
fi
mv "$tmp/mediapipe-0.10.14.dist-info/LICENSE" "$dest/LICENSE"
mv "$tmp/$model" "$dest/face_landmark.tflite"
echo "fetch-facemesh: installed $dest"
