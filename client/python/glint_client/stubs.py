"""Python stubs of Glint's gRPC API, generated from `proto/glint/v1/*.proto` by grpcio-tools at
first use (never hand-written, never committed).

The generated `glint/v1/*_pb2*.py` go into a cache directory keyed by a hash of the proto files
and of the grpcio-tools/protobuf versions, so a changed contract or toolchain regenerates them:
`$GLINT_STUBS_DIR/<hash>/` when that variable is set, else `<temp dir>/glint-stubs/<hash>/`.
Generation is atomic (a finished directory is renamed into place), so concurrent processes
share one cache safely.
"""

from __future__ import annotations

import hashlib
import importlib
import os
import pathlib
import shutil
import sys
import tempfile
import threading
import types
from dataclasses import dataclass

#: The package's own location: client/python/glint_client.
_PACKAGE_DIR = pathlib.Path(__file__).resolve().parent
#: The repository's `proto/` as seen from a source checkout (or `pip install -e`).
DEFAULT_PROTO_DIR = _PACKAGE_DIR.parents[2] / "proto"
#: Marks a cache directory whose generation finished.
_COMPLETE = ".complete"

_lock = threading.Lock()
_loaded: Stubs | None = None


class StubsError(RuntimeError):
    """The stubs could not be found, generated or imported; the message says what to fix."""


@dataclass(frozen=True)
class Stubs:
    """The generated modules of one proto directory.

    `modules` maps a short name (`orchestrator_pb2`, `camera_pb2_grpc`, …) to its module; each
    is also an attribute, e.g. `stubs.orchestrator_pb2.StartSessionRequest`.
    """

    proto_dir: pathlib.Path
    out_dir: pathlib.Path
    digest: str
    modules: dict[str, types.ModuleType]

    def __getattr__(self, name: str) -> types.ModuleType:
        if name.startswith("__") or name == "modules":  # copy/pickle probes before __init__
            raise AttributeError(name)
        try:
            return self.modules[name]
        except KeyError:
            raise AttributeError(
                f"no generated module {name!r}; have {', '.join(sorted(self.modules))}"
            ) from None


def proto_dir_of(proto_dir: str | os.PathLike[str] | None) -> pathlib.Path:
    """The proto root to generate from: `proto_dir`, else `$GLINT_PROTO_DIR`, else the
    repository's `proto/` beside this package. It must hold `glint/v1/common.proto`."""
    chosen = proto_dir or os.environ.get("GLINT_PROTO_DIR") or DEFAULT_PROTO_DIR
    path = pathlib.Path(chosen).resolve()
    if not (path / "glint" / "v1" / "common.proto").is_file():
        raise StubsError(
            f"{path} holds no glint/v1/common.proto: pass proto_dir= or set GLINT_PROTO_DIR "
            "to the repository's proto/ directory"
        )
    return path


def proto_files(proto_dir: pathlib.Path) -> list[pathlib.Path]:
    """Every `glint/v1/*.proto` under `proto_dir`, sorted."""
    return sorted((proto_dir / "glint" / "v1").glob("*.proto"))


def digest_of(proto_dir: pathlib.Path) -> str:
    """SHA-256 (hex) over the proto files (names and bytes) and the generator's versions."""
    import grpc_tools
    from google import protobuf

    h = hashlib.sha256()
    versions = f"grpcio-tools {_version('grpcio-tools', grpc_tools)}; protobuf {protobuf.__version__}"
    h.update(versions.encode())
    for path in proto_files(proto_dir):
        h.update(b"\0" + path.relative_to(proto_dir).as_posix().encode() + b"\0")
        h.update(path.read_bytes())
    return h.hexdigest()


def _version(distribution: str, module: types.ModuleType) -> str:
    try:
        from importlib.metadata import version

        return version(distribution)
    except Exception:  # an unusual install: fall back to the module's own attribute
        return str(getattr(module, "__version__", "unknown"))


def cache_root() -> pathlib.Path:
    """`$GLINT_STUBS_DIR`, else `<temp dir>/glint-stubs`."""
    configured = os.environ.get("GLINT_STUBS_DIR")
    return pathlib.Path(configured) if configured else pathlib.Path(tempfile.gettempdir()) / "glint-stubs"


def generate(proto_dir: pathlib.Path, out_dir: pathlib.Path) -> None:
    """Runs grpcio-tools' protoc on every `glint/v1/*.proto` into `out_dir` (created) and
    makes `glint` and `glint/v1` regular packages."""
    try:
        import grpc_tools
        from grpc_tools import protoc
    except ImportError as e:
        raise StubsError(
            "grpcio-tools is not installed: pip install -r client/python/requirements-test.txt"
        ) from e
    files = [str(p) for p in proto_files(proto_dir)]
    well_known = pathlib.Path(grpc_tools.__file__).parent / "_proto"
    out_dir.mkdir(parents=True, exist_ok=True)
    code = protoc.main(
        [
            "grpc_tools.protoc",
            f"-I{proto_dir}",
            f"-I{well_known}",
            f"--python_out={out_dir}",
            f"--grpc_python_out={out_dir}",
            *files,
        ]
    )
    if code != 0:
        raise StubsError(f"grpc_tools.protoc failed with exit code {code} on {proto_dir} (see stderr)")
    for package in (out_dir / "glint", out_dir / "glint" / "v1"):
        (package / "__init__.py").touch()


def _ensure_generated(proto_dir: pathlib.Path, digest: str) -> pathlib.Path:
    """The cache directory of `digest`, generated unless a finished one is there."""
    root = cache_root()
    final = root / digest[:24]
    if (final / _COMPLETE).is_file():
        return final
    root.mkdir(parents=True, exist_ok=True)
    staging = pathlib.Path(tempfile.mkdtemp(prefix=f".{digest[:24]}-", dir=root))
    try:
        generate(proto_dir, staging)
        (staging / _COMPLETE).write_text(f"{digest}\n{proto_dir}\n")
        try:
            staging.rename(final)
        except OSError:
            # Another process finished first (or a stale unfinished directory is in the way).
            if not (final / _COMPLETE).is_file():
                shutil.rmtree(final, ignore_errors=True)
                staging.rename(final)
    finally:
        if staging.exists():
            shutil.rmtree(staging, ignore_errors=True)
    return final


def load(proto_dir: str | os.PathLike[str] | None = None) -> Stubs:
    """Generates (once, cached) and imports the `glint.v1` stubs of `proto_dir` (default: see
    `proto_dir_of`). A process holds one version of the `glint` package: loading a proto
    directory whose contents differ from the one already imported raises `StubsError`."""
    global _loaded
    with _lock:
        root = proto_dir_of(proto_dir)
        digest = digest_of(root)
        if _loaded is not None:
            if _loaded.digest != digest:
                raise StubsError(
                    f"this process already imported the stubs of {_loaded.proto_dir}; "
                    f"{root} differs and cannot be imported beside them (start a new process)"
                )
            return _loaded
        out = _ensure_generated(root, digest)
        existing = sys.modules.get("glint")
        if existing is not None and pathlib.Path(list(existing.__path__)[0]).resolve() != (out / "glint").resolve():
            raise StubsError(
                f"a module named 'glint' is already imported from {list(existing.__path__)[0]}; "
                "import glint_client.stubs.load() before anything else named glint"
            )
        if str(out) not in sys.path:
            sys.path.insert(0, str(out))
        modules = {}
        try:
            for path in sorted((out / "glint" / "v1").glob("*_pb2*.py")):
                modules[path.stem] = importlib.import_module(f"glint.v1.{path.stem}")
        except Exception as e:
            raise StubsError(
                f"importing the stubs generated in {out} failed ({e}); delete that directory "
                "to regenerate, and check that grpcio and protobuf match grpcio-tools"
            ) from e
        _loaded = Stubs(proto_dir=root, out_dir=out, digest=digest, modules=modules)
        return _loaded
