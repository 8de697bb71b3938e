#!/usr/bin/env bash
# The renderer benchmark: lightfarm and Mitsuba 3 (llvm_ad_rgb) on the same two scenes in the same
# run, printing samples/s, rays/s and lightfarm/Mitsuba ratios, plus both images' means as a
# cross-check. Usage: bench/compare.sh [SIZE] [SPP]   (defaults 256 256)
# Needs bench/setup_mitsuba.sh once. LIGHTFARM_DEVICE picks the Vulkan device (default: auto);
# LIGHTFARM_BIN a prebuilt lightfarm binary.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup-system.sh
size="${1:-256}"
spp="${2:-256}"
bench_dir="${LIGHTFARM_BENCH_DIR:-$HOME/.cache/lightfarm-bench}"
if [ ! -f "$bench_dir/env.sh" ]; then
    echo "Mitsuba is not set up: run bash bench/setup_mitsuba.sh first" >&2
    exit 1
fi
source "$bench_dir/env.sh"
# LIGHTFARM_BIN: an already built `lightfarm` (e.g. the test suite's debug build: the render time
# is the device's, so the Rust profile does not change it) instead of a release build here.
if [ -n "${LIGHTFARM_BIN:-}" ]; then
    lf="$LIGHTFARM_BIN"
    profile=()
else
    cargo build --release --locked -p lightfarm >&2
    lf="$CARGO_TARGET_DIR/release/lightfarm"
    profile=(--release)
fi
cargo run "${profile[@]}" --locked -q -p lightfarm-render --example bench_scene -- "$bench_dir/diffuse_sphere.glb" >&2
out="$bench_dir/run"
mkdir -p "$out"

# Same cameras as bench/mitsuba_ref.py: the sphere from (0,0,3), the head framed from +Z (default).
"$lf" render --scene "$bench_dir/diffuse_sphere.glb" --hdri assets/hdri/rooitou_park_1k.hdr \
    --camera 0,0,3:0,0,0:30 --size "${size}x${size}" --spp "$spp" --max-depth 8 \
    --out "$out/sphere.exr" --stats "$out/sphere.lf.json" >&2
python bench/mitsuba_ref.py --scene sphere --sphere-mesh "$bench_dir/diffuse_sphere.glb" \
    --width "$size" --height "$size" --spp "$spp" > "$out/sphere.mi.json"
"$lf" render --scene assets/heads/LeePerrySmith_textured.glb --hdri assets/hdri/studio_small_03_1k.hdr \
    --size "${size}x${size}" --spp "$spp" --max-depth 8 \
    --out "$out/head.exr" --stats "$out/head.lf.json" >&2
python bench/mitsuba_ref.py --scene head --width "$size" --height "$size" --spp "$spp" > "$out/head.mi.json"

python - "$out" <<'PY'
import json, sys
import numpy as np
out = sys.argv[1]
try:
    import OpenEXR  # noqa: F401
except ImportError:
    OpenEXR = None
import mitsuba as mi
mi.set_variant("scalar_rgb")
def lit_mean(path):
    bmp = mi.Bitmap(path)
    layers = dict(bmp.split())
    for name, b in layers.items():
        if name == "lit0":
            return np.array(b, dtype=np.float64).reshape(-1, 3).mean(axis=0)
    raise SystemExit(f"no lit0 layer in {path}: {list(layers)}")
print(f"| scene | lightfarm device | lightfarm M samples/s | lightfarm M rays/s | Mitsuba M samples/s | ratio | lightfarm mean RGB | Mitsuba mean RGB |")
print("|---|---|---|---|---|---|---|---|")
for scene in ["sphere", "head"]:
    lf = json.load(open(f"{out}/{scene}.lf.json"))
    mi_ = json.loads(open(f"{out}/{scene}.mi.json").read().strip().splitlines()[-1])
    ratio = lf["samples_per_second"] / mi_["samples_per_second"]
    m = lit_mean(f"{out}/{scene}.exr")
    print(f"| {scene} | {lf['device']} | {lf['samples_per_second']/1e6:.3f} | {lf['rays_per_second']/1e6:.2f} | "
          f"{mi_['samples_per_second']/1e6:.3f} ({mi_['variant']}) | {ratio:.2f}x | "
          f"{m[0]:.4f} {m[1]:.4f} {m[2]:.4f} | {' '.join(f'{x:.4f}' for x in mi_['mean'])} |")
PY
