#!/usr/bin/env bash
# Builds the cluster image `lightfarm:local` offline: the release binary compiled on this host,
# the local base image (scripts/docker-base.sh), then `docker compose build`.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup-system.sh
cargo build --release --locked -p lightfarm
mkdir -p deploy/bin
cp "$CARGO_TARGET_DIR/release/lightfarm" deploy/bin/lightfarm
bash scripts/docker-base.sh
[ -f deploy/.env ] || cp deploy/env.example deploy/.env
source scripts/compose.sh
compose build
