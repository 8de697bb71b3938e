#!/usr/bin/env bash
# Cluster fault test across containers. A 3-worker compose cluster renders a 30-sample job
# while one worker is `docker kill`ed, another is cut off the network (`docker network
# disconnect`) for three lease lengths, and the coordinator is `docker restart`ed: the job must
# complete with every sample committed exactly once. A worker started with a wrong token must be
# refused and say so. Prometheus (profile metrics) must report the job's 30 committed tasks.
# Then the trainer trains on the job's folder export and is `docker kill`ed mid-run: restarted,
# it resumes the job, and the client following it must see it complete with one loss line per
# step. Then the trainer trains on the job straight from the coordinator (farm://) while the
# coordinator is `docker kill`ed and restarted: one loss line per step again. Needs Docker and a Debian mirror (base images); not part of .ci/run. Builds the images
# first (scripts/docker-build.sh). A few minutes once images exist.
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
echo "Prometheus (profile metrics) scrapes the coordinator's job"
compose --profile metrics up -d prometheus >/dev/null
prom=http://127.0.0.1:${PROMETHEUS_PORT:-9091}
done_metric() {
    curl -sf "$prom/api/v1/query" --data-urlencode 'query=max(lightfarm_tasks_done)' |
        python3 -c 'import json, sys; r = json.load(sys.stdin)["data"]["result"]; print(int(float(r[0]["value"][1])) if r else 0)'
}
v=0
for _ in $(seq 1 120); do v=$(done_metric 2>/dev/null || echo 0); [ "$v" -ge 30 ] && break; sleep 1; done
[ "$v" -ge 30 ] || { echo "FAIL: Prometheus reports lightfarm_tasks_done = $v, expected 30"; exit 1; }
echo "prometheus: lightfarm_tasks_done = $v"
echo "the trainer trains on the export and survives docker kill"
mkdir -p deploy/datasets
rm -rf "deploy/datasets/$job"
"$B" export "$job" --format folder --out "deploy/datasets/$job" >/dev/null
trainer=http://127.0.0.1:${LIGHTFARM_TRAINER_PORT:-7071}
for _ in $(seq 1 120); do "$B" train-jobs --trainer "$trainer" >/dev/null 2>&1 && break; sleep 0.5; done
# The newest train job's loss log, read inside the trainer container.
newest_losses='cat "$(ls -d /data/jobs/*/ | sort | tail -1)run/losses.jsonl" 2>/dev/null'
logged() { docker exec lightfarm_trainer_1 sh -c "$newest_losses | wc -l"; }
# train_through_kill CONFIG DATASET STEPS AT VICTIM PAUSE: submits a train job, `docker kill`s
# the VICTIM container once AT steps are logged, starts it again PAUSE seconds later, and checks
# that the job completes with steps 1..STEPS logged once each.
train_through_kill() {
    local cfg=$1 dataset=$2 steps=$3 at=$4 victim=$5 pause=$6 log client got
    log=$(mktemp)
    "$B" train "$cfg" --trainer "$trainer" --dataset "$dataset" >"$log" 2>&1 &
    client=$!
    for _ in $(seq 1 600); do [ "$(logged || echo 0)" -ge "$at" ] 2>/dev/null && break; sleep 0.5; done
    echo "docker kill $victim at $(logged) steps"
    docker kill "$victim" >/dev/null
    sleep "$pause"
    docker start "$victim" >/dev/null
    wait "$client" || { echo "FAIL: the train client failed:"; tail -5 "$log"; exit 1; }
    grep -q "completed at step $steps" "$log" || { echo "FAIL: job did not complete:"; tail -5 "$log"; exit 1; }
    got=$(docker exec lightfarm_trainer_1 sh -c "$newest_losses" | grep -o '"step": *[0-9]*' | grep -o '[0-9]*$' | tr '\n' ' ')
    [ "$got" = "$(seq -s ' ' 1 "$steps") " ] || { echo "FAIL: loss steps are not 1..$steps once each: $got"; exit 1; }
}
cfg=$(mktemp)
printf 'steps = 40\nbatch = 2\ncrop = 16\ncheckpoint_every = 5\n[net]\nwidths = [8, 16, 32]\ncritic_width = 8\n' > "$cfg"
train_through_kill "$cfg" "$job" 40 8 lightfarm_trainer_1 2
echo "the trainer trains from the coordinator directly (farm://) while the coordinator is docker killed"
scfg=$(mktemp)
printf 'steps = 30\nbatch = 2\ncrop = 16\ncheckpoint_every = 5\nvgg_weights = "none"\n[net]\nwidths = [8, 16, 32]\ncritic_width = 8\n' > "$scfg"
train_through_kill "$scfg" "farm://coordinator:7070/$job" 30 6 lightfarm_coordinator_1 5
"$B" train-jobs --trainer "$trainer"
echo "PASS"
