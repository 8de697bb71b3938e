#!/usr/bin/env bash
# Cluster fault test across containers: a 3-worker compose cluster renders a 30-sample job while
# one worker is `docker kill`ed, another is cut off the network (`docker network disconnect`)
# for three lease lengths, and the coordinator is `docker restart`ed. Passes when the job
# completes with every sample committed exactly once, and a worker started with a wrong token
# is refused and says so. Needs Docker and a Debian mirror (for the base image); not part of
# .ci/run. Builds the images first (scripts/docker-build.sh). ~1 minute once images exist.
set -euo pipefail
cd "$(dirname "$0")/.."
export LIGHTFARM_TOKEN=${LIGHTFARM_TOKEN:-cluster-test-$$}
export LIGHTFARM_LEASE_SECONDS=6
bash scripts/docker-build.sh >/dev/null
source scripts/compose.sh
B="${CARGO_TARGET_DIR:-$HOME/.cache/lightfarm-target}/release/lightfarm"
cleanup() { compose down -v >/dev/null 2>&1 || true; }
trap cleanup EXIT
cleanup
compose up -d --scale render-worker=3 >/dev/null
spec=$(mktemp)
printf 'name = "cluster"\ncount = 30\nwidth = 16\nheight = 16\nspp = 1\n[subject]\nhair_styles = ["buzz"]\n' > "$spec"
job=$("$B" submit "$spec")
echo "job $job"
done_count() { "$B" jobs | awk -v j="$job" '$1 == j { print $4 }'; }
wait_done() { # wait_done N: until at least N samples are committed
    for _ in $(seq 1 600); do [ "$(done_count || echo 0)" -ge "$1" ] 2>/dev/null && return 0; sleep 0.5; done
    echo "timed out waiting for $1 samples"; exit 1
}
wait_done 3
echo "docker kill a worker"
docker kill lightfarm_render-worker_1 >/dev/null
echo "disconnect another for 3 lease lengths"
docker network disconnect lightfarm_default lightfarm_render-worker_2
sleep $((LIGHTFARM_LEASE_SECONDS * 3))
docker network connect lightfarm_default lightfarm_render-worker_2
wait_done 12
echo "restart the coordinator"
docker restart lightfarm_coordinator_1 >/dev/null
for _ in $(seq 1 120); do "$B" jobs >/dev/null 2>&1 && break; sleep 0.5; done
timeout 600 "$B" watch "$job" | tail -1
n=$("$B" samples --job "$job" --limit 1000 2>/dev/null | awk 'NR > 1 { print $2 }' | sort -n | uniq | wc -l)
total=$("$B" samples --job "$job" --limit 1000 2>/dev/null | awk 'NR > 1' | wc -l)
echo "committed: $total rows, $n distinct indices"
[ "$n" = 30 ] && [ "$total" = 30 ] || { echo "FAIL: expected 30 samples committed exactly once"; exit 1; }
echo "a worker with a wrong token is refused and says so"
log=$(timeout 120 docker run --rm --network lightfarm_default -e LIGHTFARM_TOKEN=wrong lightfarm:local \
      serve worker --coordinator http://coordinator:7070 2>&1 || true)
echo "$log" | grep -q "refused this worker's token" || { echo "FAIL: no refusal in the worker's log:"; echo "$log" | tail -3; exit 1; }
echo "PASS"
