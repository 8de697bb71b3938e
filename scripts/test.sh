#!/usr/bin/env bash
# The whole default test suite (CPU-only machines render on lavapipe). Usage: scripts/test.sh
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup-system.sh
cargo test --workspace --locked -- --test-threads=2 "$@"
