"""The stubs are generated from proto/ at first use into a cache keyed by the protos' hash."""

import os
import shutil
import subprocess
import sys

from conftest import CLIENT, REPO

LOAD = "from glint_client import stubs; s = stubs.load(); print(s.out_dir); print(s.orchestrator_pb2.StartSessionRequest.DESCRIPTOR.full_name)"


def load_in_a_new_process(cache, proto_dir=None):
    env = dict(os.environ, GLINT_STUBS_DIR=str(cache), PYTHONPATH=str(CLIENT))
    if proto_dir is not None:
        env["GLINT_PROTO_DIR"] = str(proto_dir)
    run = subprocess.run([sys.executable, "-c", LOAD], env=env, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    out_dir, name = run.stdout.split()
    assert name == "glint.v1.StartSessionRequest"
    return out_dir


def test_generated_once_per_proto_contents(tmp_path):
    cache = tmp_path / "cache"
    first = load_in_a_new_process(cache)
    generated = os.path.join(first, "glint", "v1", "orchestrator_pb2_grpc.py")
    assert first.startswith(str(cache)) and os.path.isfile(generated)
    assert os.path.isfile(os.path.join(first, ".complete"))
    stamp = os.stat(generated).st_mtime_ns
    assert load_in_a_new_process(cache) == first and os.stat(generated).st_mtime_ns == stamp  # reused
    # A changed contract (here one comment) is another cache entry.
    protos = tmp_path / "proto"
    shutil.copytree(REPO / "proto" / "glint", protos / "glint")
    with open(protos / "glint" / "v1" / "common.proto", "a") as f:
        f.write("// changed\n")
    changed = load_in_a_new_process(cache, protos)
    assert changed != first and changed.startswith(str(cache))
    # Nothing half-written is left beside the finished entries.
    assert sorted(p.name for p in cache.iterdir()) == sorted({os.path.basename(first), os.path.basename(changed)})
