"""Test fixtures: the `glint.v1` stubs (generated from proto/ by grpcio-tools at first use, see
`glint_client.stubs`) and Glint servers started from the workspace's `glint` binary on free
loopback ports."""

import os
import pathlib
import subprocess
import sys
import threading

import pytest

CLIENT = pathlib.Path(__file__).resolve().parents[1]
REPO = CLIENT.parents[1]
sys.path.insert(0, str(CLIENT))

from glint_client import stubs as glint_stubs  # noqa: E402


@pytest.fixture(scope="session")
def stubs():
    """The calibration test's modules: (calibration_pb2, calibration_pb2_grpc, common_pb2)."""
    s = glint_stubs.load()
    return s.calibration_pb2, s.calibration_pb2_grpc, s.common_pb2


def glint_binary():
    path = os.environ.get("GLINT_BIN", str(REPO / "target" / "debug" / "glint"))
    if not os.path.exists(path):
        pytest.fail(f"{path} does not exist: run `cargo build -p glint-cli` first (or set GLINT_BIN)")
    return path


#: The servers' security settings from the environment (`glint serve` reads them as fallbacks
#: of its flags): the test servers take theirs from flags only.
SECURITY_ENV = ("GLINT_TOKEN_FILE", "GLINT_TLS_CERT", "GLINT_TLS_KEY", "GLINT_TLS_CLIENT_CA", "GLINT_TLS_CA")


def server_env():
    """The environment less `SECURITY_ENV`, for servers and the example alike."""
    return {k: v for k, v in os.environ.items() if k not in SECURITY_ENV}


class Server:
    """`glint serve <args> --listen 127.0.0.1:0`: its address from the first stdout line
    ("listening on ADDR"); stdout after it is drained in the background, stderr goes to a
    file shown when the server fails."""

    def __init__(self, args, log_path):
        self.log_path = log_path
        self._log = open(log_path, "w")
        self.proc = subprocess.Popen(
            [glint_binary(), "serve", *args, "--listen", "127.0.0.1:0"],
            stdout=subprocess.PIPE,
            stderr=self._log,
            text=True,
            env=server_env(),
        )
        line = self.proc.stdout.readline()
        if not line.startswith("listening on "):
            self.proc.kill()
            self.proc.wait()
            pytest.fail(f"`glint serve {' '.join(args)}` printed {line!r} first; stderr:\n{self.log()}")
        self.addr = line.split()[-1]
        threading.Thread(target=self.proc.stdout.read, daemon=True).start()

    def log(self):
        self._log.flush()
        return pathlib.Path(self.log_path).read_text()[-4000:]

    def stop(self):
        """SIGTERM; the server must stop cleanly (exit 0)."""
        self.proc.terminate()
        code = self.proc.wait(timeout=30)
        self._log.close()
        assert code == 0, f"the server did not stop cleanly on SIGTERM (exit {code}); stderr:\n{self.log()}"


@pytest.fixture()
def calibration_server(tmp_path):
    """`glint serve calibration` on 127.0.0.1:0; yields its address, stops it with SIGTERM."""
    server = Server(["calibration"], tmp_path / "calibration.log")
    try:
        yield server.addr
    finally:
        server.stop()


@pytest.fixture(scope="session")
def glint_all(tmp_path_factory):
    """`glint serve all` (camera, estimation, a render worker and the orchestrator on one port)
    for the whole test session; yields the `Server` (address in `.addr`)."""
    server = Server(["all"], tmp_path_factory.mktemp("serve-all") / "serve-all.log")
    try:
        yield server
    finally:
        server.stop()
