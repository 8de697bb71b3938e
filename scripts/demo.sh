#!/usr/bin/env bash
# The main job: an in-process coordinator and render worker render a small light-stage dataset
# from the built-in assets into out/demo/ (dataset/ = EXR + JSON per sample, sheet.png = contact
# sheet). Size and sample count: LIGHTFARM_DEMO_COUNT, LIGHTFARM_DEMO_SIZE, LIGHTFARM_DEMO_SPP.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup-system.sh
cargo build --release --locked -p lightfarm
"$CARGO_TARGET_DIR/release/lightfarm" demo --out out/demo \
    --count "${LIGHTFARM_DEMO_COUNT:-8}" --size "${LIGHTFARM_DEMO_SIZE:-128}" --spp "${LIGHTFARM_DEMO_SPP:-32}"
