"""A stand-in for a real detector, for examples and tests on the MOCK camera. It reads the
mock's ground truth (EVALUATION ONLY): a real cell gets its initial pose from its detector.

It mirrors Glint's `glint_eval::active::stand_in_detector` and `InitialPoseNoise` in
magnitudes, not bit for bit (Python's Mersenne Twister instead of Rust's PCG64): the most
visible instance from the detector's view (largest visib_fract × px_count_all) and its true
pose perturbed in that view's camera frame like a template detector's error — translation
N(0, diag(0.528 mm, 0.528 mm, 16.9 mm)²) (x, y lateral, z depth), rotation exp(ω) about the
object origin with ω ~ N(0, (2.229°)² I), redrawn unless within 30 mm / 30° of the truth
(symmetry-aware). The values are Glint's fit to the paper's initial row of Table I (21.3 % at
5 mm/5°, 1.77 % at 2 mm/2°; `glint eval initial-poses`).
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass
from typing import Sequence

from .pose import Pose, quat_from_rotation_vector, quat_mul, quat_normalize
from .symmetry import Symmetry, pose_deviation

#: XORed into the seed, as the Rust detector does, so its draws differ from the bin's.
_SEED_SALT = 0xDE7EC70B
#: The detector's acceptance gate (the paper's): 30 mm / 30°.
GATE_M = 30e-3
GATE_RAD = math.radians(30.0)


@dataclass(frozen=True)
class InitialPoseNoise:
    """A template detector's error in its camera's frame: lateral (x, y) and depth (z)
    translation sigmas in metres, and the rotation sigma per axis in radians."""

    lateral_sigma_m: float = 0.528e-3
    depth_sigma_m: float = 32 * 0.528e-3
    rotation_sigma_rad: float = math.radians(2.229)

    def draw(self, t_c_o_gt: Pose, symmetry: Symmetry, rng: random.Random) -> Pose:
        """An initial `t_c_o` around the true `t_c_o_gt`, within 30 mm / 30° of it."""
        while True:
            dt = (
                rng.gauss(0.0, self.lateral_sigma_m),
                rng.gauss(0.0, self.lateral_sigma_m),
                rng.gauss(0.0, self.depth_sigma_m),
            )
            omega = tuple(rng.gauss(0.0, self.rotation_sigma_rad) for _ in range(3))
            candidate = Pose(
                tuple(t + d for t, d in zip(t_c_o_gt.translation_m, dt)),
                quat_normalize(quat_mul(quat_from_rotation_vector(omega), t_c_o_gt.rotation_wxyz)),
            )
            if pose_deviation(candidate, t_c_o_gt, symmetry).within(GATE_M, GATE_RAD):
                return candidate

    def describe(self) -> str:
        return (
            f"translation N(0, diag({self.lateral_sigma_m * 1e3:.2f}, {self.lateral_sigma_m * 1e3:.2f}, "
            f"{self.depth_sigma_m * 1e3:.2f} mm)) in the detector's camera frame, rotation exp(ω) with "
            f"ω ~ N(0, ({math.degrees(self.rotation_sigma_rad):.2f}°)² I), redrawn unless within 30 mm/30°"
        )


@dataclass(frozen=True)
class DetectorGuess:
    """The instance detected (0-based index into the ground truth), the share of its
    silhouette visible from the detector's view, and its pose guess (object → world)."""

    target: int
    visib_fract: float
    initial_t_w_o: Pose


def stand_in_detector(
    gt_t_w_o: Sequence[Pose],
    visibility: Sequence[tuple[float, int]],
    t_w_c: Pose,
    symmetry: Symmetry,
    seed: int,
    noise: InitialPoseNoise = InitialPoseNoise(),
) -> DetectorGuess:
    """Picks the instance with the most visible pixels (visib_fract × px_count_all, from
    `visibility` as (visib_fract, px_count_all) per instance) seen from `t_w_c` (left camera →
    world) and guesses its pose with a detector's error seeded by `seed`. EVALUATION ONLY: it
    reads ground truth. Raises ValueError for an empty bin."""
    scored = [(fract * px, i, fract) for i, (fract, px) in enumerate(visibility[: len(gt_t_w_o)])]
    if not scored:
        raise ValueError("the bin holds no instance (or no visibility was reported)")
    # Of equal scores the last instance, as Rust's `max_by` keeps.
    _, target, visib_fract = max(scored, key=lambda s: (s[0], s[1]))
    rng = random.Random((seed ^ _SEED_SALT) & 0xFFFFFFFFFFFFFFFF)
    t_c_o = noise.draw(t_w_c.inverse() @ gt_t_w_o[target], symmetry, rng)
    return DetectorGuess(target, visib_fract, t_w_c @ t_c_o)
