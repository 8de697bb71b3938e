#!/usr/bin/env bash
# The paper's Table 4 on real photos, end to end: a base model trained on a rendered dataset
# (and its "w/o improved render net" twin), adapted on a folder of real portraits with the full
# method and each ablation, then one `lightfarm eval --real` row per model, and the astronaut
# relit under three HDRIs by the base and the adapted model (with the paper's light-ball inset).
#
#   bench/syn2real.sh DATASET PHOTOS OUT [TRAIN_STEPS] [ADAPT_STEPS] [SIZE]
#
# DATASET: a folder export of a rendered job (`lightfarm export JOB --format folder`);
# PHOTOS: a folder of real portraits (the paper: FFHQ; the three public-domain photos under
# assets/photos/ work for a smoke run). Defaults: 20000 training steps, 2000 adaptation steps,
# 256² — hours on a GPU node (build with --features gpu), far longer on a CPU. A smoke run:
#   bench/syn2real.sh out/demo/dataset assets/photos out/table4 20 6 64
# Writes OUT/table4.txt, OUT/table4.json and OUT/figure/{base,adapted}_<hdri>.png.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
if [ $# -lt 3 ]; then
    sed -n '2,15p' "$0" >&2
    exit 2
fi
dataset="$(realpath "$1")"; photos="$(realpath "$2")"; out="$(realpath -m "$3")"
train_steps="${4:-20000}"; adapt_steps="${5:-2000}"; size="${6:-256}"
lf="${LIGHTFARM_BIN:-lightfarm}"
command -v "$lf" >/dev/null || { echo "syn2real: $lf not found; cargo build --release and set LIGHTFARM_BIN" >&2; exit 1; }
[ -d "$dataset" ] || { echo "syn2real: dataset $dataset is not a folder export" >&2; exit 1; }
[ -d "$photos" ] || { echo "syn2real: photos $photos is not a folder" >&2; exit 1; }
mkdir -p "$out/figure"
# The smoke-run sizes need small networks; the paper's widths otherwise.
if [ "$size" -lt 128 ]; then widths="[8, 16, 32]"; adapter="base = 4\nblocks = 2"; else widths="[32, 64, 128, 256, 512]"; adapter="base = 32\nblocks = 9"; fi

train() { # NAME RENDER_NET
    cat > "$out/$1.toml" <<TOML
dataset = "$dataset"
out = "$out/$1"
split = "all"
steps = $train_steps
batch = 8
crop = $size
checkpoint_every = $(( train_steps < 500 ? train_steps : 500 ))
[net]
widths = $widths
render_net = "$2"
TOML
    "$lf" train "$out/$1.toml"
}

adapt() { # NAME BASE EXTRA_TOP [WEIGHTS]
    printf 'base = "%s"\nphotos = "%s"\nout = "%s"\nsteps = %s\nsize = %s\ncheckpoint_every = %s\n%b\n[adapter]\n%b\n[weights]\n%b\n' \
        "$out/$2" "$photos" "$out/$1" "$adapt_steps" "$size" "$(( adapt_steps < 100 ? adapt_steps : 100 ))" \
        "$3" "$adapter" "${4:-}" > "$out/$1.toml"
    "$lf" adapt "$out/$1.toml"
}

train base decomposed
train base_blackbox blackbox
adapt full base ""
adapt blackbox base_blackbox ""             # w/o improved render net (adapted like the rest)
adapt finetune base "finetune = true"       # finetune only
adapt direct base 'target = "relit"'        # direct syn2real
adapt no_relative base "" "relative = 0"    # w/o relative consistency
adapt no_olat base "" "olat = 0"            # w/o OLAT consistency

models=()
for m in base full blackbox finetune direct no_relative no_olat; do models+=(--model "$out/$m"); done
"$lf" eval "${models[@]}" --real "$photos" --size "$size" --json "$out/table4.json" | tee "$out/table4.txt"

astronaut="$root/assets/photos/astronaut.png"
for hdri in venice_sunset studio_small_03 rooitou_park; do
    for m in base full; do
        name=$([ "$m" = full ] && echo adapted || echo base)
        "$lf" relight --model "$out/$m" --image "$astronaut" --hdri "$hdri" --out "$out/figure/${name}_$hdri.png"
    done
done
echo "syn2real: $out/table4.txt, $out/figure/"
