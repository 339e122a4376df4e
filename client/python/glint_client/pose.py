"""Rigid transforms and unit quaternions in pure Python.

A pose `t_a_b` maps a point from frame b to frame a: `p_a = R p_b + translation_m`, with R the
unit quaternion `rotation_wxyz` (Hamilton convention, scalar first; q and -q are one rotation).
Metres and radians throughout. Composition follows the frames: `t_a_c = t_a_b @ t_b_c`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Iterable, Sequence

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]

#: Largest |‖q‖ - 1| the servers accept in a `UnitQuaternion` (common.proto).
UNIT_TOLERANCE = 1e-6


def quat_mul(a: Quat, b: Quat) -> Quat:
    """Hamilton product a·b (rotate by b, then by a)."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


def quat_conj(q: Quat) -> Quat:
    """The inverse rotation of a unit quaternion."""
    return (q[0], -q[1], -q[2], -q[3])


def quat_normalize(q: Sequence[float]) -> Quat:
    """q / ‖q‖; raises ValueError for a zero or non-finite quaternion."""
    n = math.sqrt(sum(c * c for c in q))
    if not (math.isfinite(n) and n > 0.0):
        raise ValueError(f"quaternion {tuple(q)} cannot be normalised")
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


def quat_from_axis_angle(axis: Sequence[float], angle_rad: float) -> Quat:
    """Rotation by `angle_rad` about `axis` (normalised here)."""
    n = math.sqrt(sum(c * c for c in axis))
    if n == 0.0:
        return (1.0, 0.0, 0.0, 0.0)
    s = math.sin(angle_rad / 2.0) / n
    return (math.cos(angle_rad / 2.0), axis[0] * s, axis[1] * s, axis[2] * s)


def quat_from_rotation_vector(omega_rad: Sequence[float]) -> Quat:
    """exp of a rotation vector: angle ‖ω‖ (radians) about ω/‖ω‖."""
    return quat_from_axis_angle(omega_rad, math.sqrt(sum(c * c for c in omega_rad)))


def quat_angle(q: Quat) -> float:
    """Rotation angle of a unit quaternion, radians in [0, π]."""
    return 2.0 * math.atan2(math.sqrt(q[1] ** 2 + q[2] ** 2 + q[3] ** 2), abs(q[0]))


def quat_rotate(q: Quat, v: Sequence[float]) -> Vec3:
    """R(q) v."""
    w, x, y, z = q
    # v + 2 w (u × v) + 2 u × (u × v), u = (x, y, z)
    cx = y * v[2] - z * v[1]
    cy = z * v[0] - x * v[2]
    cz = x * v[1] - y * v[0]
    return (
        v[0] + 2.0 * (w * cx + y * cz - z * cy),
        v[1] + 2.0 * (w * cy + z * cx - x * cz),
        v[2] + 2.0 * (w * cz + x * cy - y * cx),
    )


def vector_angle(a: Sequence[float], b: Sequence[float]) -> float:
    """Angle between two vectors, radians in [0, π]."""
    cross = (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])
    return math.atan2(math.sqrt(sum(c * c for c in cross)), sum(x * y for x, y in zip(a, b)))


@dataclass(frozen=True)
class Pose:
    """A rigid transform `t_a_b` (frame b → frame a): `p_a = R p_b + translation_m`.

    `translation_m` is b's origin in frame a, metres; `rotation_wxyz` the unit quaternion of R.
    The constructor does not validate: the servers check finiteness and the unit norm (within
    1e-6) and name the field they reject; `normalized()` fixes a hand-typed quaternion.
    """

    translation_m: Vec3 = (0.0, 0.0, 0.0)
    rotation_wxyz: Quat = (1.0, 0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "translation_m", tuple(float(c) for c in self.translation_m))
        object.__setattr__(self, "rotation_wxyz", tuple(float(c) for c in self.rotation_wxyz))
        if len(self.translation_m) != 3 or len(self.rotation_wxyz) != 4:
            raise ValueError("a pose needs 3 translation components and 4 quaternion components")

    @staticmethod
    def identity() -> Pose:
        return Pose()

    @staticmethod
    def from_rotation_vector(translation_m: Sequence[float], omega_rad: Sequence[float]) -> Pose:
        """Translation plus the rotation exp(ω), ω a rotation vector in radians."""
        return Pose(tuple(translation_m), quat_from_rotation_vector(omega_rad))

    def normalized(self) -> Pose:
        """The same pose with its quaternion scaled to unit norm."""
        return Pose(self.translation_m, quat_normalize(self.rotation_wxyz))

    def is_unit(self, tolerance: float = UNIT_TOLERANCE) -> bool:
        """Whether the quaternion's norm is 1 within `tolerance` (what the servers require)."""
        n = math.sqrt(sum(c * c for c in self.rotation_wxyz))
        return abs(n - 1.0) <= tolerance

    def __matmul__(self, other: Pose) -> Pose:
        """Composition: `t_a_b @ t_b_c = t_a_c`."""
        if not isinstance(other, Pose):
            return NotImplemented
        t = quat_rotate(self.rotation_wxyz, other.translation_m)
        translation = tuple(a + b for a, b in zip(t, self.translation_m))
        return Pose(translation, quat_normalize(quat_mul(self.rotation_wxyz, other.rotation_wxyz)))

    def inverse(self) -> Pose:
        """`t_b_a` from `t_a_b`."""
        q = quat_conj(self.rotation_wxyz)
        t = quat_rotate(q, self.translation_m)
        return Pose((-t[0], -t[1], -t[2]), q)

    def transform_point(self, p_b: Sequence[float]) -> Vec3:
        """`p_a = t_a_b * p_b`."""
        r = quat_rotate(self.rotation_wxyz, p_b)
        return (r[0] + self.translation_m[0], r[1] + self.translation_m[1], r[2] + self.translation_m[2])

    # --- proto and JSON -------------------------------------------------------------------

    def to_proto(self, common_pb2: Any) -> Any:
        """As a `glint.v1.Pose` of the given generated `common_pb2` module."""
        x, y, z = self.translation_m
        w, qx, qy, qz = self.rotation_wxyz
        return common_pb2.Pose(
            translation_m=common_pb2.Vector3(x=x, y=y, z=z),
            rotation=common_pb2.UnitQuaternion(w=w, x=qx, y=qy, z=qz),
        )

    @staticmethod
    def from_proto(msg: Any) -> Pose:
        """From a `glint.v1.Pose` (absent parts read as zero translation / identity)."""
        t = msg.translation_m
        translation = (t.x, t.y, t.z)
        if msg.HasField("rotation"):
            r = msg.rotation
            rotation = (r.w, r.x, r.y, r.z)
        else:
            rotation = (1.0, 0.0, 0.0, 0.0)
        return Pose(translation, rotation)

    def to_json(self) -> dict[str, list[float]]:
        """`{"translation_m": [x, y, z], "rotation_wxyz": [w, x, y, z]}`."""
        return {"translation_m": list(self.translation_m), "rotation_wxyz": list(self.rotation_wxyz)}

    @staticmethod
    def from_json(data: dict[str, Iterable[float]]) -> Pose:
        return Pose(tuple(data["translation_m"]), tuple(data["rotation_wxyz"]))
