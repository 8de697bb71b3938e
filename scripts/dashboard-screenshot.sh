#!/usr/bin/env bash
# Screenshots of the web dashboard during `lightfarm demo`, as the README shows them: the demo
# renders with its dashboard on a local port while the dashboard_shot example logs in with
# headless Chromium, waits for thumbnails in the gallery and saves the jobs, job, sample and
# workers pages. Usage: scripts/dashboard-screenshot.sh [OUT_DIR (default docs/img)]
# LIGHTFARM_PROFILE=debug uses the debug build of `cargo test --workspace` (shared with
# ./scripts/test.sh, so nothing is rebuilt after the suite ran).
set -euo pipefail
cd "$(dirname "$0")/.."
export LIGHTFARM_NEED_CHROMIUM=1
source scripts/setup-system.sh
profile=${LIGHTFARM_PROFILE:-release}
if [ "$profile" = release ]; then
    cargo build --release --locked -p lightfarm
    cargo build --locked -p lightfarm-coordinator --example dashboard_shot
else
    cargo test --workspace --locked --no-run
fi
out=${1:-docs/img}
port=${LIGHTFARM_SHOT_PORT:-9181}
token="shot-$$-$RANDOM"
"$CARGO_TARGET_DIR/$profile/lightfarm" demo --out out/demo-shot --count 12 --size 96 --spp 16 \
    --train-steps 0 --dashboard "127.0.0.1:$port" --dashboard-linger 120 --token "$token" &
demo=$!
trap 'kill "$demo" 2>/dev/null || true' EXIT
for _ in $(seq 600); do
    if (exec 3<>"/dev/tcp/127.0.0.1/$port") 2>/dev/null; then break; fi
    kill -0 "$demo" 2>/dev/null || { echo "dashboard-screenshot: the demo exited early" >&2; exit 1; }
    sleep 0.5
done
"$CARGO_TARGET_DIR/debug/examples/dashboard_shot" "http://127.0.0.1:$port" "$token" "$out" 4
kill -TERM "$demo" 2>/dev/null || true
wait "$demo" || true
echo "dashboard-screenshot: screenshots in $out"
