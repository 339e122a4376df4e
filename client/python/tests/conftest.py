"""Test fixtures: stubs generated from proto/ by grpcio-tools (never hand-written) and a Glint
server started from the workspace's `glint` binary on a free loopback port."""

import os
import pathlib
import subprocess
import sys

import pytest

REPO = pathlib.Path(__file__).resolve().parents[3]
PROTO = REPO / "proto"


@pytest.fixture(scope="session")
def stubs(tmp_path_factory):
    """The `glint.v1` modules, generated from proto/glint/v1/*.proto into a temporary dir."""
    from grpc_tools import protoc

    out = tmp_path_factory.mktemp("stubs")
    files = sorted(str(p) for p in (PROTO / "glint" / "v1").glob("*.proto"))
    code = protoc.main(
        ["protoc", f"-I{PROTO}", f"--python_out={out}", f"--grpc_python_out={out}", *files]
    )
    assert code == 0, f"grpc_tools.protoc failed with {code}"
    sys.path.insert(0, str(out))
    from glint.v1 import calibration_pb2, calibration_pb2_grpc, common_pb2

    return calibration_pb2, calibration_pb2_grpc, common_pb2


def glint_binary():
    path = os.environ.get("GLINT_BIN", str(REPO / "target" / "debug" / "glint"))
    if not os.path.exists(path):
        pytest.fail(f"{path} does not exist: run `cargo build -p glint-cli` first (or set GLINT_BIN)")
    return path


@pytest.fixture()
def calibration_server():
    """`glint serve calibration` on 127.0.0.1:0; yields its address, stops it with SIGTERM."""
    proc = subprocess.Popen(
        [glint_binary(), "serve", "calibration", "--listen", "127.0.0.1:0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    line = proc.stdout.readline()
    assert line.startswith("listening on "), f"unexpected first line {line!r}"
    try:
        yield line.split()[-1]
    finally:
        proc.terminate()
        assert proc.wait(timeout=20) == 0, "the server did not stop cleanly on SIGTERM"
