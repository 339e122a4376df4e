#!/usr/bin/env bash
# The compose deployment end to end, on the machine's Docker engine:
#   1. build the image (deploy/build-image.sh; GLINT_E2E_NO_BUILD=1 reuses glint:latest);
#   2. up -d with 3 render workers (a project name of its own, free host ports), wait until
#      every container is healthy (bounded; on timeout the logs and exit 1);
#   3. the Python example (client/python/examples/active_session.py) runs a session through
#      the published orchestrator port, undisturbed;
#   4. it runs the same session again and kills one worker in the middle of a decision: at the
#      orchestrator's step 0 the worker is paused, so its calls of the next decision hang in
#      flight; once the other workers have rendered the rest and gone idle it is `docker
#      kill`ed (deploy/e2e.py kill-mid-decision). The session must complete with the same
#      views and entropies (the predictions are seeded per candidate: any worker gives the
#      same Fisher information), and the orchestrator must have re-sent the lost calls;
#   5. down -v, always (trap).
# Prints "skipped: <reason>" and exits 0 when no Docker engine or compose answers.
# GLINT_E2E_CLIENT=rust runs `target/release/glint session run` instead of the Python example
# (entropies then compared as printed, to 0.01 nats).
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
t_start=$(date +%s.%N)
since_start() { python3 -c "import sys; print(f'{float(sys.argv[2]) - float(sys.argv[1]):.1f}')" "$t_start" "$(date +%s.%N)"; }
say() { echo "e2e [$(since_start) s]: $*"; }

if ! engine=$(docker version --format '{{.Server.Version}}' 2>&1); then
    echo "e2e: skipped: no Docker engine answers (docker version: $(echo "$engine" | tail -1))"
    exit 0
fi
if docker compose version >/dev/null 2>&1; then
    compose=(docker compose)
elif command -v docker-compose >/dev/null && docker-compose version >/dev/null 2>&1; then
    compose=(docker-compose)
else
    echo "e2e: skipped: Docker engine $engine answers but neither 'docker compose' nor docker-compose is installed"
    exit 0
fi
say "Docker engine $engine, client $(docker version --format '{{.Client.Version}}'), ${compose[*]} $("${compose[@]}" version --short 2>/dev/null || "${compose[@]}" version | head -1)"

client=${GLINT_E2E_CLIENT:-python}
example=client/python/examples/active_session.py
if [[ $client == python && ! -f $example ]]; then
    echo "e2e: $example does not exist (GLINT_E2E_CLIENT=rust runs the Rust CLI instead)" >&2
    exit 1
fi

# 1. The image.
if [[ ${GLINT_E2E_NO_BUILD:-0} == 1 ]]; then
    docker image inspect glint:latest >/dev/null
    say "reusing glint:latest (GLINT_E2E_NO_BUILD=1)"
else
    bash deploy/build-image.sh
fi
if [[ $client == python ]]; then
    PIP_ROOT_USER_ACTION=ignore python3 -m pip install --quiet --disable-pip-version-check -r client/python/requirements-test.txt
fi
t_image=$(date +%s.%N)

# 2. Up, with its own project and ports.
project=glinte2e$$
orch_port=$(python3 deploy/e2e.py free-port)
cam_port=$(python3 deploy/e2e.py free-port)
while [[ $cam_port == "$orch_port" ]]; do cam_port=$(python3 deploy/e2e.py free-port); done
export GLINT_BIND=127.0.0.1 GLINT_PORT=$orch_port GLINT_CAMERA_PORT=$cam_port GLINT_IMAGE=glint:latest
dc=("${compose[@]}" -p "$project" -f deploy/docker-compose.yml -f deploy/docker-compose.mock-port.yml)
out=$(mktemp -d "${TMPDIR:-/tmp}/glint-e2e.XXXXXX")
cleanup() {
    local rc=$?
    if [[ $rc -ne 0 ]]; then
        echo "e2e: FAILED; the deployment's logs (last 40 lines per container):"
        "${dc[@]}" logs --no-color --tail 40 2>&1 || true
    fi
    "${dc[@]}" down -v --remove-orphans --timeout 5 >/dev/null 2>&1 || true
    rm -rf "$out"
    echo "e2e: down -v done; took $(since_start) s in all"
}
trap cleanup EXIT

workers=3
expected=$((4 + workers))
timeout_s=${GLINT_E2E_HEALTHY_TIMEOUT_S:-120}
deadline=$(( $(date +%s) + timeout_s ))
say "up -d --scale uncertainty=$workers (project $project, orchestrator 127.0.0.1:$orch_port, mock camera 127.0.0.1:$cam_port)"
# Compose waits for the orchestrator's dependencies to be healthy (depends_on) inside `up`:
# the same bound covers it.
if ! timeout "$timeout_s" "${dc[@]}" up -d --scale uncertainty=$workers >"$out/up.log" 2>&1; then
    sed 's/^/  /' "$out/up.log"
    echo "e2e: up -d failed or took over $timeout_s s; containers:"
    docker ps -a --filter "label=com.docker.compose.project=$project" --format '  {{.Names}} {{.Status}}'
    exit 1
fi
while true; do
    states=$(docker ps -a --filter "label=com.docker.compose.project=$project" \
        --format '{{.Names}} {{.Status}}')
    healthy=$(grep -c '(healthy)' <<<"$states" || true)
    if [[ $healthy -eq $expected ]]; then
        break
    fi
    if [[ $(date +%s) -ge $deadline ]]; then
        echo "e2e: only $healthy of $expected containers healthy after $timeout_s s:"
        echo "$states" | sed 's/^/  /'
        exit 1
    fi
    sleep 1
done
say "all $expected containers healthy"
echo "$states" | sort | sed 's/^/  /'
t_up=$(date +%s.%N)

session_args=(--part zigzag --max-views 3 --resolution 640x512 --spp 1 --candidates 12 --instances 4 --seed 3)
run_session() { # OUT_BASENAME
    if [[ $client == python ]]; then
        PYTHONPATH=$root/client/python${PYTHONPATH:+:$PYTHONPATH} python3 "$example" \
            --target "127.0.0.1:$orch_port" --camera "127.0.0.1:$cam_port" \
            "${session_args[@]}" --json "$out/$1.json" >"$out/$1.txt" 2>&1
    else
        target/release/glint session run --orchestrator "127.0.0.1:$orch_port" \
            --camera "127.0.0.1:$cam_port" "${session_args[@]}" >"$out/$1.txt" 2>&1 &&
            python3 deploy/e2e.py rust-table "$out/$1.txt" "$out/$1.json"
    fi
}

# 3. Undisturbed.
t0=$(date +%s.%N)
say "session 1 (undisturbed): ${session_args[*]}"
if ! run_session undisturbed; then
    cat "$out/undisturbed.txt"; exit 1
fi
sed 's/^/  /' "$out/undisturbed.txt"
t_run1=$(python3 -c "import sys; print(f'{float(sys.argv[2]) - float(sys.argv[1]):.1f}')" "$t0" "$(date +%s.%N)")

# 4. Again, with a worker killed as it starts rendering a decision. The harness pauses the
# worker when it reads the orchestrator's step 0 in its logs; in one of six runs on this
# 2-core machine the victim had no call of the next decision in flight when killed (that
# decision ran on the other workers: nothing to re-send). Such a run says nothing about
# re-sending, so it is tried once more with a fresh session (and one worker fewer); a
# second run without a re-send fails.
for attempt in 1 2; do
    orch=$("${dc[@]}" ps -q orchestrator)
    # Running workers only: a second attempt must not pick the one killed before.
    mapfile -t worker_ids < <(docker ps -q --filter "label=com.docker.compose.project=$project" --filter label=com.docker.compose.service=uncertainty)
    sleep 1 # `docker logs --since` counts whole seconds: nothing of the session before
    since=$(date +%s)
    t0=$(date +%s.%N)
    say "session 2, killing a worker mid-decision (attempt $attempt)"
    run_session killed & client_pid=$!
    if ! killed=$(python3 deploy/e2e.py kill-mid-decision "$orch" "$since" "${worker_ids[@]}"); then
        wait $client_pid || true
        cat "$out/killed.txt"; exit 1
    fi
    read -r killed_id started hung <<<"$killed"
    killed_name=$(docker inspect --format '{{.Name}}' "$killed_id" | tr -d /)
    if [[ $started == by-clock ]]; then
        say "killed worker $killed_name, paused at the orchestrator's step 0, $hung s later (no CPU times visible: by the clock)"
    else
        say "killed worker $killed_name mid-decision: paused at the orchestrator's step 0, the decision began $started s later on the other workers, which finished their share; its calls hung $hung s, then docker kill"
    fi
    if ! wait $client_pid; then
        cat "$out/killed.txt"; exit 1
    fi
    sed 's/^/  /' "$out/killed.txt"
    t_run2=$(python3 -c "import sys; print(f'{float(sys.argv[2]) - float(sys.argv[1]):.1f}')" "$t0" "$(date +%s.%N)")
    resent=$(docker logs --since "$since" "$orch" 2>&1 | sed 's/\x1b\[[0-9;]*m//g' | grep 'worker failed a prediction' || true)
    if [[ -n $resent ]]; then
        break
    fi
    if [[ $attempt -eq 2 ]]; then
        echo "e2e: the orchestrator re-sent nothing, twice: the kill landed outside a decision's calls"
        exit 1
    fi
    say "the orchestrator re-sent nothing: the kill landed outside a decision's calls (no call in flight on the victim); once more"
done
say "the orchestrator re-sent the killed worker's calls:"
echo "$resent" | sed 's/^/  /'
say "workers now: $(docker ps --filter "label=com.docker.compose.project=$project" --filter label=com.docker.compose.service=uncertainty --format '{{.Names}}' | sort | tr '\n' ' ')"

# The same result.
python3 deploy/e2e.py compare "$out/undisturbed.json" "$out/killed.json"
say "sessions: undisturbed ${t_run1} s, with the kill ${t_run2} s; image $(python3 -c "import sys; print(f'{float(sys.argv[2]) - float(sys.argv[1]):.1f}')" "$t_start" "$t_image") s, up and healthy $(python3 -c "import sys; print(f'{float(sys.argv[2]) - float(sys.argv[1]):.1f}')" "$t_image" "$t_up") s"
echo "e2e: passed"
