#!/usr/bin/env bash
# The main job, for now: renders the built-in head under two lightings (studio, sun+sky) with all
# passes into out/demo/. Later issues extend it with the farm, the dataset and the trainer.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup-system.sh
cargo build --release --locked -p lightfarm
mkdir -p out/demo
"$CARGO_TARGET_DIR/release/lightfarm" render \
    --scene assets/heads/LeePerrySmith_textured.glb \
    --hdri assets/hdri/studio_small_03_1k.hdr --hdri assets/hdri/rooitou_park_1k.hdr \
    --hdri-rotation 0 --hdri-rotation 120 \
    --size "${LIGHTFARM_DEMO_SIZE:-256x256}" --spp "${LIGHTFARM_DEMO_SPP:-64}" \
    --out out/demo/head.exr --stats out/demo/head.json --preview out/demo/head.png
echo "wrote out/demo/head.exr (lit0, lit1, albedo, normal, normal_lens, mask), head.png, head.json"
