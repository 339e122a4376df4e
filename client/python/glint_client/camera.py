"""Typed answers of the camera services: the mock's bin and its ground truth (EVALUATION
ONLY: estimators never read it; the examples and tests use it to place a stand-in detector's
guess and to score poses)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from .pose import Pose


@dataclass(frozen=True)
class MockBin:
    """A bin the mock set up: the part's mesh by content (SHA-256 of its canonical encoding in
    metres, the key sessions cache it under), its name and the instances dropped."""

    mesh_sha256_hex: str
    name: str
    instances: int


@dataclass(frozen=True)
class InstanceVisibility:
    """How much of one instance the left camera sees (BOP's scene_gt_info terms): silhouette
    pixels with occluders ignored, the visible ones, and their ratio (0 off-image)."""

    px_count_all: int
    px_count_visib: int
    visib_fract: float


@dataclass(frozen=True)
class GroundTruth:
    """The mock's truth: every instance's object → world pose (instance i is scene label
    i + 1), the part's true principled material, and each instance's visibility from the view
    asked about (empty if none was)."""

    t_w_o: list[Pose]
    material: dict[str, float]
    visibility: list[InstanceVisibility]

    @staticmethod
    def from_proto(msg: Any) -> GroundTruth:
        material = {f.name: float(v) for f, v in msg.material.ListFields()} if msg.HasField("material") else {}
        return GroundTruth(
            t_w_o=[Pose.from_proto(p) for p in msg.t_w_o],
            material=material,
            visibility=[
                InstanceVisibility(v.px_count_all, v.px_count_visib, v.visib_fract) for v in msg.visibility
            ],
        )
