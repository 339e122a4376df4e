"""Poses, symmetry-aware errors and the stand-in detector in pure Python (no server)."""

import math
import random

import pytest

from glint_client import InitialPoseNoise, Pose, Symmetry, builtin_symmetry, pose_deviation, stand_in_detector
from glint_client import stubs
from glint_client.pose import quat_from_axis_angle, quat_rotate

# Exact arithmetic up to a few ulps of doubles of order 1.
EPS = 1e-12


def random_pose(rng):
    axis = [rng.gauss(0, 1) for _ in range(3)]
    return Pose(tuple(rng.uniform(-1, 1) for _ in range(3)), quat_from_axis_angle(axis, rng.uniform(0, math.pi)))


def close(a, b, eps=EPS):
    return all(abs(x - y) < eps for x, y in zip(a, b))


def same_pose(a, b, eps=EPS):
    q, r = a.rotation_wxyz, b.rotation_wxyz
    sign = 1.0 if sum(x * y for x, y in zip(q, r)) >= 0 else -1.0
    return close(a.translation_m, b.translation_m, eps) and close(q, [sign * c for c in r], eps)


def test_composition_inverse_and_points():
    rng = random.Random(7)
    for _ in range(50):
        a, b, c = random_pose(rng), random_pose(rng), random_pose(rng)
        assert same_pose(a @ a.inverse(), Pose.identity())
        assert same_pose((a @ b) @ c, a @ (b @ c))
        p = (rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1))
        assert close((a @ b).transform_point(p), a.transform_point(b.transform_point(p)))
        assert close(a.inverse().transform_point(a.transform_point(p)), p)


def test_a_quarter_turn_about_z_maps_x_to_y():
    q = quat_from_axis_angle((0, 0, 1), math.pi / 2)
    assert close(quat_rotate(q, (1, 0, 0)), (0, 1, 0))
    t_a_b = Pose((0.1, 0.0, 0.0), q)
    assert close(t_a_b.transform_point((1, 0, 0)), (0.1, 1, 0))


def test_proto_and_json_round_trips():
    common = stubs.load().common_pb2
    pose = random_pose(random.Random(3))
    assert Pose.from_proto(pose.to_proto(common)) == pose
    assert Pose.from_json(pose.to_json()) == pose
    # Absent rotation reads as the identity, as an absent pose part would.
    assert Pose.from_proto(common.Pose()).rotation_wxyz == (1.0, 0.0, 0.0, 0.0)


def test_errors_respect_the_declared_symmetries():
    rng = random.Random(11)
    gt = random_pose(rng)
    spin = lambda angle, axis=(0, 0, 1): Pose((0, 0, 0), quat_from_axis_angle(axis, angle))  # noqa: E731
    tilt = spin(math.radians(1.0), (1, 0, 0))
    # Tube fitting, 6-fold about z: 60° + 1° tilt is 1° off; 30° is the worst case.
    six = builtin_symmetry("tube-fitting")
    assert pose_deviation(gt @ spin(math.pi / 3) @ tilt, gt, six).rotation_deg == pytest.approx(1.0, abs=1e-9)
    assert pose_deviation(gt @ spin(math.pi / 6), gt, six).rotation_deg == pytest.approx(30.0, abs=1e-9)
    assert pose_deviation(gt @ spin(math.pi / 3), gt, Symmetry.none()).rotation_deg == pytest.approx(60.0, abs=1e-9)
    # Chrome screw, continuous about z: any spin is free, a tilt is not.
    screw = builtin_symmetry("chrome-screw")
    assert pose_deviation(gt @ spin(2.3), gt, screw).rotation_rad < 1e-9
    assert pose_deviation(gt @ spin(1.2) @ spin(math.radians(3), (0, 1, 0)), gt, screw).rotation_deg == pytest.approx(3.0, abs=1e-9)
    # Gear, 20-fold about z plus the half-turn about x (40 elements).
    gear = builtin_symmetry("gear")
    assert len(gear.discrete) == 40
    assert pose_deviation(gt @ spin(math.pi, (1, 0, 0)) @ spin(2 * math.pi / 20 * 7), gt, gear).rotation_rad < 1e-9
    # The translation error is the origin distance, whatever the rotation.
    moved = Pose(tuple(t + d for t, d in zip(gt.translation_m, (0.003, 0.004, 0.0))), gt.rotation_wxyz)
    assert pose_deviation(moved, gt, gear).translation_mm == pytest.approx(5.0, abs=1e-9)


def test_stand_in_detector_picks_the_most_visible_and_stays_within_the_gate():
    rng = random.Random(5)
    gt = [random_pose(rng) for _ in range(4)]
    # visib_fract * px_count_all: 450, 800 (the most visible pixels), 500, 0.
    visibility = [(0.9, 500), (0.4, 2000), (1.0, 500), (0.0, 0)]
    t_w_c = random_pose(rng)
    symmetry = builtin_symmetry("zigzag")
    guess = stand_in_detector(gt, visibility, t_w_c, symmetry, seed=1)
    assert guess.target == 1 and guess.visib_fract == 0.4
    assert stand_in_detector(gt, visibility, t_w_c, symmetry, seed=1) == guess  # seeded
    assert stand_in_detector(gt, visibility, t_w_c, symmetry, seed=2) != guess
    errors = []
    for seed in range(200):
        d = pose_deviation(stand_in_detector(gt, visibility, t_w_c, symmetry, seed).initial_t_w_o, gt[1], symmetry)
        assert d.translation_m < 0.03 and d.rotation_rad < math.radians(30)
        errors.append(d.translation_m)
    # The translation error is nearly all depth (σ 16.9 mm against 0.53 mm across), and the
    # 30 mm gate truncates it at a = 30 mm / σ: a normal truncated to |z| < a·σ has variance
    # σ² (1 − 2aφ(a) / (2Φ(a) − 1)). Over 200 draws the sample RMS lies within ±15 % of the
    # expected (its relative standard error is at most √(2/200) / 2 = 5 %, 3 standard errors).
    rms = math.sqrt(sum(e * e for e in errors) / len(errors))
    noise = InitialPoseNoise()
    a = 30e-3 / noise.depth_sigma_m
    phi = math.exp(-a * a / 2) / math.sqrt(2 * math.pi)
    inside = math.erf(a / math.sqrt(2))
    depth_var = noise.depth_sigma_m**2 * (1 - 2 * a * phi / inside)
    expected = math.sqrt(2 * noise.lateral_sigma_m**2 + depth_var)
    assert abs(rms / expected - 1) < 0.15, (rms, expected)
