"""Glint's Python client: stubs generated from `proto/` at first use (`glint_client.stubs`),
a typed session wrapper (`GlintClient`, `Step`, `Session`), poses (`Pose`), the built-in parts'
symmetries and symmetry-aware pose errors, a bearer token and TLS for secured deployments
(`glint_client.security`), and a stand-in detector for the mock camera
(evaluation only).

Conventions (proto/glint/v1/common.proto): `t_a_b` maps frame b to frame a; metres and
radians unless a name says otherwise (`_mm`, `_deg`, `_px`, `_ms`, `_nats`)."""

from .calibration import CalibrationFileError, PartCalibration, ResponseCurve
from .camera import GroundTruth, InstanceVisibility, MockBin
from .client import GlintClient
from .detector import DetectorGuess, InitialPoseNoise, stand_in_detector
from .errors import GlintError
from .parts import BUILTIN_PARTS, MeshPart, builtin_symmetry
from .pose import Pose
from .security import SecurityConfigError, read_token_file
from .session import Session, SessionState, Step, ViewPolicy
from .stubs import StubsError
from .symmetry import PoseDeviation, Symmetry, pose_deviation

__all__ = [
    "BUILTIN_PARTS",
    "CalibrationFileError",
    "DetectorGuess",
    "GlintClient",
    "GlintError",
    "GroundTruth",
    "InitialPoseNoise",
    "InstanceVisibility",
    "MeshPart",
    "MockBin",
    "PartCalibration",
    "Pose",
    "PoseDeviation",
    "ResponseCurve",
    "SecurityConfigError",
    "Session",
    "SessionState",
    "Step",
    "StubsError",
    "Symmetry",
    "ViewPolicy",
    "builtin_symmetry",
    "pose_deviation",
    "read_token_file",
    "stand_in_detector",
]
