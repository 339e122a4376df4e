"""Part symmetries and symmetry-aware pose errors, as Glint's `glint_geometry::symmetry` and
`pose_deviation` define them.

A symmetry group is a finite group D of object-frame rotations (always holding the identity),
optionally combined with every rotation about one object axis. The rotation error of an
estimate against the truth is the smallest angle over the group: `min_S ∠(R_estᵀ R_gt S)`, and
with a continuous axis a, the angle between a and `(R_estᵀ R_gt S) a` (the spin about a is
unobservable). The translation error is the distance between the object origins (every
element turns about the origin, so it does not depend on the group).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .pose import Pose, Quat, quat_angle, quat_conj, quat_from_axis_angle, quat_mul, quat_rotate, vector_angle

_AXES: dict[str, tuple[float, float, float]] = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
#: Two rotations closer than this (radians) are one group element.
_SAME_ROTATION_RAD = 1e-6


def _axis(name: str) -> tuple[float, float, float]:
    try:
        return _AXES[name]
    except KeyError:
        raise ValueError(f"unknown axis {name!r}: expected x, y or z") from None


@dataclass(frozen=True)
class Symmetry:
    """A symmetry group `D · C`: `discrete` rotations (identity first) and an optional
    `continuous_axis` (a unit vector in the object frame)."""

    discrete: tuple[Quat, ...]
    continuous_axis: tuple[float, float, float] | None
    spec: str

    @staticmethod
    def _closure(generators: list[Quat], continuous_axis, spec: str) -> Symmetry:
        elements: list[Quat] = [(1.0, 0.0, 0.0, 0.0)]
        frontier = list(elements)
        while frontier:
            e = frontier.pop()
            for g in generators:
                c = quat_mul(g, e)
                if all(quat_angle(quat_mul(quat_conj(x), c)) >= _SAME_ROTATION_RAD for x in elements):
                    elements.append(c)
                    frontier.append(c)
        return Symmetry(tuple(elements), continuous_axis, spec)

    @staticmethod
    def none() -> Symmetry:
        return Symmetry._closure([], None, "none")

    @staticmethod
    def cyclic(axis: str, n: int) -> Symmetry:
        """n-fold symmetry about an object axis ("x", "y" or "z")."""
        g = quat_from_axis_angle(_axis(axis), 2.0 * math.pi / max(n, 1))
        return Symmetry._closure([g], None, f"discrete:{axis}:{n}")

    @staticmethod
    def dihedral(axis: str, n: int, flip_axis: str) -> Symmetry:
        """n-fold about `axis` plus the half-turn about `flip_axis` (order 2n)."""
        g = quat_from_axis_angle(_axis(axis), 2.0 * math.pi / max(n, 1))
        flip = quat_from_axis_angle(_axis(flip_axis), math.pi)
        return Symmetry._closure([g, flip], None, f"dihedral:{axis}:{n}:{flip_axis}")

    @staticmethod
    def continuous(axis: str) -> Symmetry:
        """Every rotation about an object axis (a body of revolution)."""
        return Symmetry._closure([], _axis(axis), f"continuous:{axis}")


@dataclass(frozen=True)
class PoseDeviation:
    """Error of an estimated pose against the truth: origin distance (metres) and the smallest
    rotation angle to any symmetric equivalent of the truth (radians, in [0, π])."""

    translation_m: float
    rotation_rad: float

    @property
    def translation_mm(self) -> float:
        return self.translation_m * 1e3

    @property
    def rotation_deg(self) -> float:
        return math.degrees(self.rotation_rad)

    def within(self, translation_m: float, rotation_rad: float) -> bool:
        """Both errors strictly below the thresholds (the paper's correct-detection test)."""
        return self.translation_m < translation_m and self.rotation_rad < rotation_rad


def pose_deviation(t_x_o_est: Pose, t_x_o_gt: Pose, symmetry: Symmetry) -> PoseDeviation:
    """The error of `t_x_o_est` against `t_x_o_gt` (object → any common frame x) under
    `symmetry`; see the module's doc."""
    translation_m = math.dist(t_x_o_est.translation_m, t_x_o_gt.translation_m)
    relative = quat_mul(quat_conj(t_x_o_est.rotation_wxyz), t_x_o_gt.rotation_wxyz)
    best = math.inf
    for s in symmetry.discrete:
        m = quat_mul(relative, s)
        if symmetry.continuous_axis is not None:
            a = symmetry.continuous_axis
            angle = vector_angle(a, quat_rotate(m, a))
        else:
            angle = quat_angle(m)
        best = min(best, angle)
    return PoseDeviation(translation_m, best)
