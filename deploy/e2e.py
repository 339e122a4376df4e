#!/usr/bin/env python3
"""Helpers of deploy/e2e.sh (standard library only).

  e2e.py free-port                 a free TCP port on 127.0.0.1
  e2e.py kill-mid-decision ORCH_CONTAINER SINCE_UNIX WORKER_CONTAINER...
        once the orchestrator has logged its step 0 since SINCE_UNIX (its first decision is
        done), `docker pause`s the first worker, waits until the others have rendered their
        share of the next decision and gone idle (CPU time from /proc/PID/stat), so that the
        decision waits on the paused worker's calls alone, and `docker kill`s it. Prints the
        worker killed, when the decision started (s after the pause) and how long its calls
        hung before the kill.
  e2e.py rust-table OUT.txt OUT.json
        the rows `glint session run` printed, as the example's JSON (entropies to 0.01 nats)
  e2e.py compare A.json B.json     the same views chosen, entropies equal to 1e-9 relative
                                   (2 decimals for rust-table JSON); exits 1 otherwise
"""

import json
import re
import socket
import subprocess
import sys
import threading
import time

ANSI = re.compile(r"\x1b\[[0-9;]*m")


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        print(s.getsockname()[1])


def docker(*args):
    return subprocess.run(["docker", *args], capture_output=True, text=True, check=True)


def cpu_ticks(pid):
    """utime + stime of the whole process (every thread), in clock ticks."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return int(fields[11]) + int(fields[12])


def wait_for_step0(orchestrator, since, deadline):
    """Returns once the orchestrator has logged `step done ... step=0` since `since`."""
    logs = subprocess.Popen(["docker", "logs", "--follow", "--since", since, orchestrator],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    timer = threading.Timer(max(0.0, deadline - time.monotonic()), logs.kill)
    timer.start()
    try:
        step0 = re.compile(r"step done.*\bstep=0\b")
        for line in logs.stdout:
            if step0.search(ANSI.sub("", line)):
                return
        sys.exit("kill-mid-decision: the orchestrator logged no step 0 in time")
    finally:
        timer.cancel()
        logs.kill()
        logs.wait()


def kill_mid_decision(orchestrator, since, workers, timeout_s=120.0):
    """After the orchestrator's step 0, pauses one worker (its calls of the next decision then
    hang in flight), waits until the other workers have rendered their share of that decision
    and gone idle (the decision now waits on the paused worker alone), and `docker kill`s it:
    its calls fail mid-flight and the orchestrator must re-send them."""
    deadline = time.monotonic() + timeout_s
    wait_for_step0(orchestrator, since, deadline)
    victim, others = workers[0], workers[1:]
    t0 = time.monotonic()
    docker("pause", victim)
    pids = {w: int(docker("inspect", "--format", "{{.State.Pid}}", w).stdout.strip()) for w in others}
    poll, idle_needed = 0.02, 0.5
    try:
        last = {w: cpu_ticks(p) for w, p in pids.items()}
    except OSError:
        last = None  # the engine's processes are not visible here (a VM): wait by the clock
    busy_at = idle_since = None
    while last is not None and time.monotonic() < deadline:
        time.sleep(poll)
        now = {w: cpu_ticks(p) for w, p in pids.items()}
        busy = any(now[w] > last[w] for w in pids)
        last = now
        t = time.monotonic()
        if busy:
            busy_at = busy_at or t
            idle_since = None
        elif busy_at is not None:
            idle_since = idle_since or t
            if t - idle_since >= idle_needed:
                break
    else:
        if last is not None:
            docker("unpause", victim)
            sys.exit("kill-mid-decision: the other workers never rendered after step 0")
        time.sleep(5.0)
    docker("kill", victim)
    t = time.monotonic()
    if busy_at is None:
        print(f"{victim} by-clock {t - t0:.2f}")
    else:
        print(f"{victim} {busy_at - t0:.2f} {t - busy_at:.2f}")


def rust_table(text_path, json_path):
    steps = []
    for line in open(text_path):
        f = line.split()
        if len(f) >= 6 and f[0].isdigit() and f[1].isdigit():
            steps.append({
                "step": int(f[0]), "view": int(f[1]),
                "predicted_entropy_nats": None if f[4] == "-" else float(f[4]),
                "entropy_nats": float(f[5]),
            })
    state = ""
    for line in open(text_path):
        m = re.search(r"\b(SESSION_STATE_\w+|CONVERGED|BUDGET_SPENT|FAILED|CANCELLED)\b", line)
        if m:
            state = m.group(1)
    json.dump({"state": state, "steps": steps, "precision_nats": 0.01}, open(json_path, "w"), indent=1)


def close(a, b, rel, abs_tol):
    if a is None or b is None:
        return a is None and b is None
    return abs(a - b) <= max(abs_tol, rel * max(abs(a), abs(b)))


def flat(values):
    """candidate_entropies_nats as a list of numbers, or as {index: value}."""
    if isinstance(values, dict):
        return sorted((str(k), v) for k, v in values.items())
    if isinstance(values, list):
        return [(str(i), v.get("entropy_nats") if isinstance(v, dict) else v) for i, v in enumerate(values)]
    return []


def compare(a_path, b_path):
    a, b = json.load(open(a_path)), json.load(open(b_path))
    coarse = "precision_nats" in a or "precision_nats" in b
    rel, abs_tol = (0.0, 0.0051) if coarse else (1e-9, 1e-12)
    problems = []
    if a.get("state") != b.get("state"):
        problems.append(f"state {a.get('state')} vs {b.get('state')}")
    sa, sb = a.get("steps", []), b.get("steps", [])
    if len(sa) != len(sb) or not sa:
        problems.append(f"{len(sa)} steps vs {len(sb)}")
    print(f"{'step':>4} {'view':>5} {'view_killed':>11} {'h_undisturbed':>16} {'h_killed':>16} {'max rel diff':>12}")
    for x, y in zip(sa, sb):
        worst = 0.0
        for k in ("entropy_nats", "predicted_entropy_nats"):
            if not close(x.get(k), y.get(k), rel, abs_tol):
                problems.append(f"step {x['step']}: {k} {x.get(k)!r} vs {y.get(k)!r}")
            elif x.get(k) is not None and y.get(k) is not None and x[k] != 0:
                worst = max(worst, abs(x[k] - y[k]) / abs(x[k]))
        cx, cy = flat(x.get("candidate_entropies_nats")), flat(y.get("candidate_entropies_nats"))
        if [i for i, _ in cx] != [i for i, _ in cy]:
            problems.append(f"step {x['step']}: candidates {[i for i, _ in cx]} vs {[i for i, _ in cy]}")
        for (i, u), (_, v) in zip(cx, cy):
            if not close(u, v, rel, abs_tol):
                problems.append(f"step {x['step']}: candidate {i} entropy {u!r} vs {v!r}")
            elif u and v:
                worst = max(worst, abs(u - v) / abs(u))
        if x.get("view") != y.get("view"):
            problems.append(f"step {x['step']}: view {x.get('view')} vs {y.get('view')}")
        print(f"{x['step']:>4} {x['view']:>5} {y['view']:>11} {x['entropy_nats']:>16.10f} {y['entropy_nats']:>16.10f} {worst:>12.1e}"
              + (f"  ({len(cx)} candidate entropies)" if cx else ""))
    for p in problems:
        print(f"DIFFERENT: {p}")
    print(f"compare: {'same' if not problems else 'DIFFERENT'} ({'0.01 nats, as printed' if coarse else 'relative 1e-9'})")
    return 1 if problems else 0


def main(argv):
    if argv[1:2] == ["free-port"]:
        free_port()
    elif argv[1:2] == ["kill-mid-decision"] and len(argv) >= 5:
        kill_mid_decision(argv[2], argv[3], argv[4:])
    elif argv[1:2] == ["rust-table"] and len(argv) == 4:
        rust_table(argv[2], argv[3])
    elif argv[1:2] == ["compare"] and len(argv) == 4:
        return compare(argv[2], argv[3])
    else:
        print(__doc__, file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
