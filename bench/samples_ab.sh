#!/usr/bin/env bash
# A/B of two lightfarm binaries on dataset samples (head, hair, garment, glasses): each sample of
# a spec is written once as a .glb (`lightfarm spec glb`), then rendered by both binaries in turns
# for ROUNDS rounds, so a slow minute of the machine hits both. Prints per sample and binary the
# M samples/s median (min-max), the BVH build seconds and the geometry on the device, then the
# total render time of all samples per binary (what a dataset of such samples costs).
# Usage: bench/samples_ab.sh BIN_A BIN_B [FIRST] [COUNT] [ROUNDS] [SIZE] [SPP]
#        (defaults 0 6 2 128 16; spec examples/dataset.toml, HDRI studio_small_03)
# Env: RUN = a prefix for both binaries, e.g. RUN="scripts/lavapipe-trixie.sh run" (Mesa 26);
#      SPEC = another dataset spec.
set -euo pipefail
cd "$(dirname "$0")/.."
[ $# -ge 2 ] || { sed -n 2,10p "$0" >&2; exit 2; }
a=$(realpath "$1") b=$(realpath "$2")
first=${3:-0} count=${4:-6} rounds=${5:-2} size=${6:-128} spp=${7:-16}
spec=${SPEC:-examples/dataset.toml}
read -r -a run <<< "${RUN:-}"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
for i in $(seq "$first" $((first + count - 1))); do
    "$a" spec glb "$spec" --index "$i" --out "$work/s$i.glb" >&2
done
for r in $(seq "$rounds"); do
    for i in $(seq "$first" $((first + count - 1))); do
        for v in a b; do
            bin=$a
            [ "$v" = b ] && bin=$b
            "${run[@]}" "$bin" render --scene "$work/s$i.glb" --hdri assets/hdri/studio_small_03_1k.hdr \
                --size "${size}x${size}" --spp "$spp" --max-depth 8 --out "$work/out.exr" \
                --stats "$work/$v.$i.$r.json" > /dev/null 2>&1 ||
                { echo "samples_ab: $bin failed on sample $i" >&2; exit 1; }
        done
    done
done
python3 - "$work" "$first" "$count" "$1" "$2" <<'PY'
import glob, json, statistics, sys
work, first, count, name_a, name_b = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], sys.argv[5]
print("| sample | binary | M samples/s | BVH build s | geometry MiB |")
print("|---|---|---|---|---|")
total = {"a": 0.0, "b": 0.0}
for i in range(first, first + count):
    for v, name in (("a", name_a), ("b", name_b)):
        runs = [json.load(open(f)) for f in sorted(glob.glob(f"{work}/{v}.{i}.*.json"))]
        rates = [s["samples_per_second"] / 1e6 for s in runs]
        med = statistics.median(rates)
        total[v] += 1.0 / med  # every sample has the same pixels × spp: seconds per M samples
        build = statistics.median(s.get("bvh_build_seconds", 0.0) for s in runs)
        geo = runs[0].get("geometry_bytes", 0) / 2**20
        print(f"| {i} | {name} | {med:.4f} ({min(rates):.4f}-{max(rates):.4f}) | {build:.2f} | {geo:.1f} |")
print(f"\nseconds per M samples, summed over the samples (medians): {name_a} {total['a']:.2f}, "
      f"{name_b} {total['b']:.2f} ({total['b'] / total['a']:.3f}x)")
PY
