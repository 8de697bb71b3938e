#!/usr/bin/env bash
# Hair cross-check against Blender Cycles: a Python 3.11 venv with bpy 5.0.1 (374 MB wheel) and
# OpenEXR (the one bench/cycles_skin.sh makes), the lightfarm debug build, then
# bench/cycles_hair.py (a strand patch in lightfarm's fibre .glb, rendered by both from that file).
# Usage: bash bench/cycles_hair.sh [extra cycles_hair.py flags, e.g. --settings black@-8,black@8]
# (--cycles-only skips the lightfarm build and render.) Output: /tmp/lightfarm-bench/cycles_hair.
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
case " $* " in
    *" --cycles-only "*) ;;
    *) cargo build --locked -p lightfarm >&2 ;;
esac
"$venv/bin/python" bench/cycles_hair.py --lightfarm "$CARGO_TARGET_DIR/debug/lightfarm" \
    --size 128 --spp 128 "$@"
