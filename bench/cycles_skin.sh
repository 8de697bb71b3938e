#!/usr/bin/env bash
# Skin cross-check against Blender Cycles (BENCHMARKS.md, "Skin against Blender Cycles"):
# a Python 3.11 venv with bpy 5.0.1 (374 MB wheel) and OpenEXR, then bench/cycles_skin.py.
# Usage: bash bench/cycles_skin.sh [extra cycles_skin.py flags, e.g. --method RANDOM_WALK_SKIN]
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup-system.sh
venv="${LIGHTFARM_BENCH_DIR:-$HOME/.cache/lightfarm-bench}/bpy311"
py="${PYTHON311:-python3.11}"
if ! command -v "$py" >/dev/null; then
    echo "error: bpy 5.0.1 needs Python 3.11: install it or set PYTHON311=/path/to/python3.11" >&2
    exit 1
fi
if [ ! -x "$venv/bin/python" ] || ! "$venv/bin/python" -c "import bpy, OpenEXR" 2>/dev/null; then
    "$py" -m venv "$venv"
    "$venv/bin/pip" install -q bpy==5.0.1 OpenEXR
fi
cargo build --locked -p lightfarm >&2
"$venv/bin/python" bench/cycles_skin.py --lightfarm "$CARGO_TARGET_DIR/debug/lightfarm" \
    --size 96 --spp 128 "$@"
