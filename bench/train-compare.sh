#!/usr/bin/env bash
# Training iterations/s of the relighting network: Burn (this project) vs the same network in
# PyTorch (bench/train_torch.py), measured in the same run on the same machine.
# Usage: bench/train-compare.sh [BATCH] [SIZE] [WIDTHS] [ITERS]   (defaults: 2 256 32,64,128,256,512 3)
# Env: DEVICE=cpu|gpu (Burn) and TORCH_DEVICE=cpu|cuda; VENV = a venv with torch
# (default ~/.cache/lightfarm-bench-venv, made with `python3 -m venv` + `pip install torch numpy`).
set -euo pipefail
cd "$(dirname "$0")/.."
BATCH=${1:-2}; SIZE=${2:-256}; WIDTHS=${3:-32,64,128,256,512}; ITERS=${4:-3}
DEVICE=${DEVICE:-cpu}; TORCH_DEVICE=${TORCH_DEVICE:-cpu}
VENV=${VENV:-$HOME/.cache/lightfarm-bench-venv}
THREADS=${THREADS:-$(nproc)}
export CARGO_TARGET_DIR=${CARGO_TARGET_DIR:-$HOME/.cache/lightfarm-target}
FEATURES=()
if [ "$DEVICE" = gpu ]; then FEATURES=(--features gpu); fi
if [ ! -x "$VENV/bin/python" ]; then
  echo "no PyTorch venv at $VENV: python3 -m venv $VENV && $VENV/bin/pip install torch numpy" >&2
  exit 1
fi
cargo build --release --locked -p lightfarm-trainer --example bench_train "${FEATURES[@]}" >&2
common=(--batch "$BATCH" --size "$SIZE" --widths "$WIDTHS" --iters "$ITERS" --warmup 1)
burn=$("$CARGO_TARGET_DIR/release/examples/bench_train" "${common[@]}" --device "$DEVICE")
torch=$("$VENV/bin/python" bench/train_torch.py "${common[@]}" --threads "$THREADS" --device "$TORCH_DEVICE")
echo "$burn"
echo "$torch"
python3 - "$burn" "$torch" <<'PY'
import json, sys
b, t = json.loads(sys.argv[1]), json.loads(sys.argv[2])
assert b["params"] == t["params"], f"parameter counts differ: burn {b['params']} vs torch {t['params']}"
print(f"batch {b['batch']} x {b['size']}², widths {b['widths']}, {b['params']:,} generator parameters")
print(f"burn ({b['device']}):    {b['iters_per_s']:.4f} it/s  (median {b['seconds_per_iter_median']:.3f} s)")
print(f"pytorch ({t['device']}): {t['iters_per_s']:.4f} it/s  (median {t['seconds_per_iter_median']:.3f} s, torch {t['torch']})")
print(f"ratio burn/pytorch: {b['iters_per_s'] / t['iters_per_s']:.2f}x")
PY
