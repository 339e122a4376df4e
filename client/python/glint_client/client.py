"""`GlintClient`: a session on a Glint deployment from Python — the orchestrator at `target`,
the camera (and, on the mock, its scene set-up and ground truth) at `camera`.

Every failed call raises `GlintError` with the gRPC code and the server's message (bad input
is INVALID_ARGUMENT with a message starting with the field's path; a call without the
deployment's token, or with a wrong one, is UNAUTHENTICATED).

A secured deployment (`glint serve … --token-file FILE --tls-cert FILE --tls-key FILE
[--tls-client-ca FILE]`) is reached with `token=`/`token_file=` (sent as `authorization:
Bearer <token>` on every call) and `tls_ca=` (TLS on, trusting that CA), plus `tls_cert=` and
`tls_key=` when the servers require client certificates."""

from __future__ import annotations

import os
from typing import Any, Iterator, Optional, Sequence, Union

import grpc

from . import stubs as stubs_module
from .calibration import PartCalibration
from .camera import GroundTruth, MockBin
from .errors import GlintError, calling
from .parts import PartLike, part_spec
from .pose import Pose
from .security import BearerToken, PathLike, SecurityConfigError, channel_credentials, resolve_token
from .session import Session, Step, ViewPolicy

#: Deadline of a unary call, seconds (a mock's SetUpScene on a debug build takes a while).
DEFAULT_TIMEOUT_S = 120.0


def grpc_target(addr: str, tls: bool = False) -> str:
    """`HOST:PORT` for grpcio: a leading `http://` is dropped (as Glint's Rust client accepts
    it), and so is `https://` when TLS is on (`tls_ca`); TLS is never inferred from the
    address."""
    for scheme in ("http://", "https://"):
        if addr.startswith(scheme):
            if scheme == "https://" and not tls:
                raise SecurityConfigError(f"{addr}: https:// needs tls_ca (the CA of the server's certificate); or give HOST:PORT")
            return addr[len(scheme) :].rstrip("/")
    if "://" in addr:
        raise ValueError(f"{addr}: give HOST:PORT (or http://HOST:PORT, https://HOST:PORT with tls_ca)")
    return addr


class GlintClient:
    """A connection to a deployment: the orchestrator at `target` (HOST:PORT) and the camera
    at `camera` (default: `target`, as `glint serve all` serves every service on one port).

    Security (both connections alike): `token` (the text) or `token_file` (a file holding it,
    surrounding whitespace trimmed) is sent as `authorization: Bearer <token>` on every call;
    `tls_ca` (PEM file of the CA that signed the servers' certificates) turns TLS on, and
    `tls_cert` with `tls_key` (PEM) present a client certificate to servers that require one
    (mutual TLS). Unusable files or settings raise `SecurityConfigError` (a `ValueError`)
    naming the file, never the token.

    Use as a context manager, or call `close()`. `timeout_s` bounds every unary call;
    `run_session` waits as long as the session runs unless given its own `timeout_s`.
    """

    def __init__(
        self,
        target: str,
        camera: Optional[str] = None,
        token: Optional[str] = None,
        token_file: Optional[PathLike] = None,
        tls_ca: Optional[PathLike] = None,
        tls_cert: Optional[PathLike] = None,
        tls_key: Optional[PathLike] = None,
        *,
        timeout_s: float = DEFAULT_TIMEOUT_S,
        proto_dir: Union[str, os.PathLike[str], None] = None,
    ) -> None:
        secret = resolve_token(token, token_file)
        credentials = channel_credentials(tls_ca, tls_cert, tls_key)
        self.pb = stubs_module.load(proto_dir)
        self.target = grpc_target(target, tls=credentials is not None)
        self.camera_target = grpc_target(camera, tls=credentials is not None) if camera else self.target
        self.timeout_s = timeout_s
        #: Whether calls go over TLS / carry a token (the token itself is not kept here).
        self.tls = credentials is not None
        self.authenticated = secret is not None
        interceptors = [BearerToken(secret)] if secret is not None else []

        def connect(addr: str) -> grpc.Channel:
            if credentials is None:
                return grpc.insecure_channel(addr)
            return grpc.secure_channel(addr, credentials)

        self._raw_channels = [connect(self.target)]
        if self.camera_target != self.target:
            self._raw_channels.append(connect(self.camera_target))
        channels = [grpc.intercept_channel(c, *interceptors) for c in self._raw_channels]
        self._channel = channels[0]
        self._camera_channel = channels[-1]
        self._orchestrator = self.pb.orchestrator_pb2_grpc.OrchestratorServiceStub(self._channel)
        self._camera = self.pb.camera_pb2_grpc.CameraServiceStub(self._camera_channel)
        self._mock = self.pb.camera_pb2_grpc.MockCameraServiceStub(self._camera_channel)

    def close(self) -> None:
        for channel in self._raw_channels:
            channel.close()

    def __enter__(self) -> GlintClient:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # --- the camera ----------------------------------------------------------------------

    def set_up_mock_bin(
        self,
        part: PartLike,
        instances: int = 8,
        seed: int = 1,
        width_px: int = 0,
        height_px: int = 0,
        samples_per_pixel: int = 0,
        material: Optional[dict[str, float]] = None,
    ) -> MockBin:
        """MOCK ONLY: replaces the mock's scene by `instances` copies of `part` (a built-in
        name or a `MeshPart`) dropped into the bin with `seed`. Image size 0×0 = 1280×1024;
        `samples_per_pixel` 0 = 4; `material` (principled parameters in [0, 1]) None = the
        part's measured-like one."""
        pb = self.pb
        request = pb.camera_pb2.SetUpSceneRequest(
            part=part_spec(part, pb.camera_pb2, pb.common_pb2),
            instances=instances,
            seed=seed,
            width_px=width_px,
            height_px=height_px,
            samples_per_pixel=samples_per_pixel,
        )
        if material is not None:
            request.material.CopyFrom(pb.camera_pb2.PrincipledMaterial(**material))
        with calling("SetUpScene"):
            reply = self._mock.SetUpScene(request, timeout=self.timeout_s)
        return MockBin(reply.mesh.sha256_hex, reply.mesh.name, reply.instances)

    def candidate_views(
        self,
        count: int = 20,
        distance_m: float = 0.0,
        cap_half_angle_deg: float = 0.0,
        target_w_m: Optional[Sequence[float]] = None,
    ) -> list[Pose]:
        """`count` left-camera poses (camera → world) spread over a cap of views around world
        +z, looking at `target_w_m` (world, metres; default the bin's centre) from
        `distance_m` (0: the camera's working distance) within `cap_half_angle_deg` (0: its
        cap)."""
        pb = self.pb
        request = pb.camera_pb2.ListCandidateViewsRequest(
            count=count, distance_m=distance_m, cap_half_angle_deg=cap_half_angle_deg
        )
        if target_w_m is not None:
            x, y, z = target_w_m
            request.target_w_m.CopyFrom(pb.common_pb2.Vector3(x=x, y=y, z=z))
        with calling("ListCandidateViews"):
            reply = self._camera.ListCandidateViews(request, timeout=self.timeout_s)
        return [Pose.from_proto(p) for p in reply.t_w_c]

    def ground_truth(self, visibility_from_t_w_c: Optional[Pose] = None) -> GroundTruth:
        """MOCK ONLY, EVALUATION ONLY: every instance's true pose, the true material and, with
        `visibility_from_t_w_c` (left camera → world), each instance's visibility from it. A
        real camera answers UNIMPLEMENTED."""
        pb = self.pb
        request = pb.camera_pb2.GetGroundTruthRequest()
        if visibility_from_t_w_c is not None:
            request.visibility_from_t_w_c.CopyFrom(visibility_from_t_w_c.to_proto(pb.common_pb2))
        with calling("GetGroundTruth"):
            reply = self._mock.GetGroundTruth(request, timeout=self.timeout_s)
        return GroundTruth.from_proto(reply)

    # --- sessions ------------------------------------------------------------------------

    def start_session(
        self,
        part: PartLike,
        initial_t_w_o: Pose,
        *,
        candidates_t_w_c: Optional[Sequence[Pose]] = None,
        policy: Union[ViewPolicy, str] = ViewPolicy.NBV,
        max_views: int = 4,
        entropy_threshold_nats: float = 0.0,
        seed: int = 1,
        first_view: int = 0,
        default_candidates: int = 0,
        calibration: Optional[PartCalibration] = None,
    ) -> str:
        """Creates a session (it does not run yet) and returns its id.

        `initial_t_w_o` is the detector's pose (object → world); `candidates_t_w_c` the views
        the robot can take (left camera → world; None: `default_candidates` of the camera's
        own, 0 = 20); `first_view` indexes the candidate the detector looked from;
        `entropy_threshold_nats` 0 = only `max_views` stops. The NBV policies render the part:
        they need `calibration` unless Glint ships one for the built-in part (the Zigzag)."""
        pb = self.pb
        request = pb.orchestrator_pb2.StartSessionRequest(
            part=part_spec(part, pb.camera_pb2, pb.common_pb2),
            initial_t_w_o=initial_t_w_o.to_proto(pb.common_pb2),
            candidates_t_w_c=[p.to_proto(pb.common_pb2) for p in candidates_t_w_c or []],
            policy=pb.orchestrator_pb2.ViewPolicy.Value(ViewPolicy.parse(policy).proto_name),
            max_views=max_views,
            entropy_threshold_nats=entropy_threshold_nats,
            seed=seed,
            first_view=first_view,
            default_candidates=default_candidates,
        )
        if calibration is not None:
            request.material.CopyFrom(calibration.material_proto(pb.camera_pb2))
            request.response.CopyFrom(calibration.response.to_proto(pb.calibration_pb2))
            request.radiometric_scale = calibration.radiometric_scale
        with calling("StartSession"):
            return self._orchestrator.StartSession(request, timeout=self.timeout_s).session_id

    def run_session(self, session_id: str, timeout_s: Optional[float] = None) -> Iterator[Union[Step, Session]]:
        """Runs the session to its end, yielding each `Step` as it completes and then the final
        `Session` (last). Re-running a finished session replays its steps. Raises GlintError
        if the stream fails (e.g. FAILED_PRECONDITION for a session already running)."""
        pb = self.pb
        request = pb.orchestrator_pb2.RunSessionRequest(session_id=session_id)
        finished = False
        call = self._orchestrator.RunSession(request, timeout=timeout_s)
        try:
            with calling("RunSession"):
                for event in call:
                    kind = event.WhichOneof("event")
                    if kind == "step":
                        yield Step.from_proto(event.step)
                    elif kind == "finished":
                        finished = True
                        yield Session.from_proto(event.finished, pb.orchestrator_pb2)
        finally:
            # A consumer that stops early closes the stream (the session itself runs on).
            call.cancel()
        if not finished:
            raise GlintError("RunSession", grpc.StatusCode.UNKNOWN, "the stream ended without the session's final state")

    def get_session(self, session_id: str) -> Session:
        pb = self.pb
        with calling("GetSession"):
            msg = self._orchestrator.GetSession(
                pb.orchestrator_pb2.GetSessionRequest(session_id=session_id), timeout=self.timeout_s
            )
        return Session.from_proto(msg, pb.orchestrator_pb2)

    def list_sessions(self) -> list[Session]:
        pb = self.pb
        with calling("ListSessions"):
            msg = self._orchestrator.ListSessions(pb.orchestrator_pb2.ListSessionsRequest(), timeout=self.timeout_s)
        return [Session.from_proto(s, pb.orchestrator_pb2) for s in msg.sessions]

    def cancel_session(self, session_id: str) -> Session:
        """Cancels a session (a running one stops after its current stage) and returns it."""
        pb = self.pb
        with calling("CancelSession"):
            msg = self._orchestrator.CancelSession(
                pb.orchestrator_pb2.CancelSessionRequest(session_id=session_id), timeout=self.timeout_s
            )
        return Session.from_proto(msg, pb.orchestrator_pb2)
