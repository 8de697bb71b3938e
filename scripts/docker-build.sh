#!/usr/bin/env bash
# Builds the cluster image `lightfarm:local` offline: the release binary compiled on this host,
# the local base image (scripts/docker-base.sh), then `docker compose build`; and
# lightfarm-prometheus:local (Debian's Prometheus) for the `metrics` profile.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup-system.sh
# --features gpu: the trainer can use Burn's wgpu backend (compose profile `gpu`).
cargo build --release --locked -p lightfarm --features gpu
mkdir -p deploy/bin
cp "$CARGO_TARGET_DIR/release/lightfarm" deploy/bin/lightfarm
bash scripts/docker-base.sh
[ -f deploy/.env ] || cp deploy/env.example deploy/.env
source scripts/compose.sh
compose build
# Prometheus for the `metrics` profile, from Debian's package (no registry needed).
if ! docker image inspect "${PROMETHEUS_IMAGE:-lightfarm-prometheus:local}" >/dev/null 2>&1; then
    compose --profile metrics build prometheus
fi
