#!/usr/bin/env bash
# `glint bench fanout` against the compose deployment with 1, 2, 3… render workers (issue 14):
# brings the deployment up once (the mock camera's port published for the client), scales the
# workers to each count in turn, and runs the same sessions through the orchestrator each
# time: decision latency (median) and sessions per minute, one table row per count.
#
#   bash deploy/bench-fanout.sh                   # workers 1 2 3, 3 sessions each, 1280×1024
#   WORKERS="1 2 4" SESSIONS=2 RESOLUTION=640x512 bash deploy/bench-fanout.sh
#
# Reuses glint:latest (build it first with deploy/build-image.sh) and target/release/glint as
# the client. Takes the deployment down with its volumes at the end.
set -euo pipefail
cd "$(dirname "$0")/.."
workers_list=${WORKERS:-1 2 3}
sessions=${SESSIONS:-3}
resolution=${RESOLUTION:-1280x1024}
glint=${GLINT_BIN:-target/release/glint}
docker image inspect glint:latest >/dev/null
if docker compose version >/dev/null 2>&1; then compose=(docker compose); else compose=(docker-compose); fi
project=glintbench$$
orch_port=$(python3 deploy/e2e.py free-port)
cam_port=$(python3 deploy/e2e.py free-port)
export GLINT_BIND=127.0.0.1 GLINT_PORT=$orch_port GLINT_CAMERA_PORT=$cam_port GLINT_IMAGE=glint:latest
dc=("${compose[@]}" -p "$project" -f deploy/docker-compose.yml -f deploy/docker-compose.mock-port.yml)
trap '"${dc[@]}" down -v --remove-orphans --timeout 5 >/dev/null 2>&1 || true' EXIT
out=$(mktemp -d "${TMPDIR:-/tmp}/glint-bench.XXXXXX")
for n in $workers_list; do
    "${dc[@]}" up -d --scale uncertainty="$n" >/dev/null 2>&1
    # Until every container is healthy (bounded).
    for _ in $(seq 1 120); do
        total=$(docker ps --filter "label=com.docker.compose.project=$project" -q | wc -l)
        healthy=$(docker ps --filter "label=com.docker.compose.project=$project" --filter health=healthy -q | wc -l)
        [[ $total -eq $((4 + n)) && $healthy -eq $total ]] && break
        sleep 1
    done
    [[ $healthy -eq $((4 + n)) ]] || { echo "bench-fanout: $healthy of $((4 + n)) containers healthy" >&2; exit 1; }
    "$glint" bench fanout --orchestrator "127.0.0.1:$orch_port" --camera "127.0.0.1:$cam_port" \
        --sessions "$sessions" --resolution "$resolution" --label "$n worker$([[ $n == 1 ]] || echo s)" \
        --csv "$out/$n.csv" | tail -1 | tee -a "$out/rows.md" >/dev/null
done
echo "Compose deployment ($("${compose[@]}" version --short 2>/dev/null || echo compose)), $sessions NBV sessions per row, $resolution:"
echo
echo "| deployment | sessions | decisions | decision ms (median) | session s (median) | sessions/min |"
echo "|---|---:|---:|---:|---:|---:|"
cat "$out/rows.md"
rm -rf "$out"
