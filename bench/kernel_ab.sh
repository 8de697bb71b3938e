#!/usr/bin/env bash
# A/B of two integrator kernels on the scenes of bench/compare.sh, in the same binary and the same
# run: the shaders/ tree of each git revision (or "work" for the working tree) compiled with the
# renderer's naga options (examples/compile_kernel.rs), loaded through LIGHTFARM_INTEGRATOR_SPV.
# The variants take turns for ROUNDS rounds, so a slow minute of the machine hits both; prints
# M samples/s median (min-max) per kernel and scene.
# Usage: bench/kernel_ab.sh REV_A REV_B [ROUNDS] [SIZE] [SPP]   (defaults 3 256 256)
# A revision suffixed with +guards keeps naga's loop bounding and integer-division checks
# (e.g. b3212ca+guards is the kernel as it was before they were turned off).
# Env: LIGHTFARM_BIN = a prebuilt lightfarm (default: the debug build, made here).
# Both kernels must bind what that binary binds: since the BVH nodes became a storage image
# (binding 1), kernels of revisions before that change need a binary of their own revision
# (time those with two LIGHTFARM_BIN runs of bench/compare.sh instead).
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup-system.sh
[ $# -ge 2 ] || { sed -n 2,10p "$0" >&2; exit 2; }
rounds=${3:-3} size=${4:-256} spp=${5:-256}
bench_dir="${LIGHTFARM_BENCH_DIR:-$HOME/.cache/lightfarm-bench}"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
if [ -z "${LIGHTFARM_BIN:-}" ]; then
    cargo build --locked -q -p lightfarm >&2
    LIGHTFARM_BIN="$CARGO_TARGET_DIR/debug/lightfarm"
fi
sphere="$bench_dir/diffuse_sphere.glb"
mkdir -p "$bench_dir"
[ -f "$sphere" ] || cargo run --locked -q -p lightfarm-render --example bench_scene -- "$sphere" >&2
names=()
for spec in "$1" "$2"; do
    rev=${spec%+guards}
    name=$(printf %s "$spec" | tr -c 'A-Za-z0-9+_-' _)
    mkdir -p "$work/$name"
    if [ "$rev" = work ]; then
        cp -r shaders "$work/$name/"
    else
        git archive "$rev" shaders | tar -x -C "$work/$name"
    fi
    flags=()
    [ "$spec" != "$rev" ] && flags=(--naga-guards)
    cargo run --locked -q -p lightfarm-render --example compile_kernel -- \
        "$work/$name/shaders" "$work/$name.spv" "${flags[@]}" >&2
    names+=("$name")
done
for r in $(seq "$rounds"); do
    for name in "${names[@]}"; do
        LIGHTFARM_INTEGRATOR_SPV="$work/$name.spv" "$LIGHTFARM_BIN" render --scene "$sphere" \
            --hdri assets/hdri/rooitou_park_1k.hdr --camera 0,0,3:0,0,0:30 --size "${size}x${size}" \
            --spp "$spp" --max-depth 8 --out "$work/sphere.$name.exr" --stats "$work/sphere.$name.$r.json" >&2
        LIGHTFARM_INTEGRATOR_SPV="$work/$name.spv" "$LIGHTFARM_BIN" render \
            --scene assets/heads/LeePerrySmith_textured.glb --hdri assets/hdri/studio_small_03_1k.hdr \
            --size "${size}x${size}" --spp "$spp" --max-depth 8 --out "$work/head.$name.exr" \
            --stats "$work/head.$name.$r.json" >&2
    done
done
python3 - "$work" "${names[@]}" <<'PY'
import glob, json, statistics, sys
work, names = sys.argv[1], sys.argv[2:]
print(f"| kernel | sphere M samples/s | head M samples/s |")
print("|---|---|---|")
for n in names:
    row = [n]
    for scene in ["sphere", "head"]:
        v = [json.load(open(f))["samples_per_second"] / 1e6 for f in sorted(glob.glob(f"{work}/{scene}.{n}.*.json"))]
        row.append(f"{statistics.median(v):.3f} ({min(v):.3f}-{max(v):.3f})")
    print("| " + " | ".join(row) + " |")
PY
