#!/usr/bin/env bash
# Installs the model data that is too large for the repository: the pretrained VGG16 + LPIPS
# weights (scripts/fetch-vgg16.sh, into assets/models/vgg16/), MODNet for matting photographs
# (scripts/fetch-modnet.sh, assets/models/modnet/), dlib's face-recognition ResNet for the
# identity loss and metric (scripts/fetch-face.sh, assets/models/dlib/), MediaPipe's face mesh
# for the skin mask (scripts/fetch-facemesh.sh, assets/models/mediapipe/), three public-domain portrait photos
# (scripts/fetch-photos.sh, assets/photos/) and MakeHuman's compiled target set
# (CC0), from the makehuman==1.3.2 wheel on PyPI. Idempotent; every file is checked by hash.
#
#   ./scripts/fetch-models.sh            # into assets/models/makehuman/
#   LIGHTFARM_CACHE=/path ./scripts/...  # where the wheel is cached (default ~/.cache/lightfarm)
#
# Air-gapped cluster: run it on a connected machine and copy assets/models/makehuman/, or put
# makehuman-1.3.2-py3-none-any.whl into $LIGHTFARM_CACHE/wheels/ first (it is then not
# downloaded). Nothing of MakeHuman's Python code is imported or kept.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
"$root/scripts/fetch-vgg16.sh"
"$root/scripts/fetch-modnet.sh"
"$root/scripts/fetch-face.sh"
"$root/scripts/fetch-facemesh.sh"
"$root/scripts/fetch-photos.sh"
source "$root/scripts/pypi-cache.sh"
cache="${LIGHTFARM_CACHE:-$HOME/.cache/lightfarm}/wheels"
dest="$root/assets/models/makehuman"
wheel="makehuman-1.3.2-py3-none-any.whl"
wheel_sha256="384f0553a66659be95ff05b7c2d2d837376062f1d525dbd8920b029c4c6fa85e"
npz_sha256="6929705536c11e06e6ba41cfeec7fd83d3d31ee6e4d65c8d165810f2db9e0029"

if has_sha256 "$npz_sha256" "$dest/targets.npz"; then
    echo "fetch-models: $dest/targets.npz is installed"
    exit 0
fi
mkdir -p "$dest"
pypi_cached fetch-models "makehuman==1.3.2" "$wheel" "$wheel_sha256" "$cache" "30 MB" --only-binary=:all:
tmp="$(mktemp -d)"; trap 'rm -rf "$tmp"' EXIT
python3 - "$cache/$wheel" "$tmp" <<'PY'
import sys, zipfile
z = zipfile.ZipFile(sys.argv[1])
with open(sys.argv[2] + '/targets.npz', 'wb') as fh:
    fh.write(z.read('makehuman/data/targets.npz'))
PY
if ! has_sha256 "$npz_sha256" "$tmp/targets.npz"; then
    echo "fetch-models: targets.npz inside the wheel has an unexpected hash" >&2; exit 1
fi
# The set's own licence record (a small pickled array, read here as bytes, never unpickled).
python3 - "$tmp/targets.npz" "$tmp/targets.license.txt" <<'PY'
import sys, zipfile
raw = zipfile.ZipFile(sys.argv[1]).read('targets/targets.license.npy')
if b'CC0' not in raw or b'MakeHuman Team' not in raw:
    sys.exit('fetch-models: the embedded targets.license no longer says CC0 / MakeHuman Team')
open(sys.argv[2], 'w').write(
    "targets.npz: MakeHuman 1.x compiled targets, from the makehuman==1.3.2 wheel on PyPI.\n"
    "Its embedded record targets/targets.license reads: author MakeHuman Team, license CC0,\n"
    "copyright (c) www.makehumancommunity.org 2001-2020.\n")
PY
mv "$tmp/targets.npz" "$dest/targets.npz"
mv "$tmp/targets.license.txt" "$dest/LICENSE.txt"
echo "fetch-models: installed $dest/targets.npz"
