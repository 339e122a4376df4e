#!/usr/bin/env python3
"""Peer ICP benchmark: Open3D and small_gicp on the problems `glint bench refine --export DIR`
wrote, timed and scored beside Glint's own rows from the same export.

    apt-get install -y libusb-1.0-0          # Open3D's wheel links it
    pip install open3d small_gicp numpy
    glint bench refine --export DIR
    python3 services/estimation/scripts/peer_icp_bench.py DIR --threads 1
    python3 services/estimation/scripts/peer_icp_bench.py DIR --threads 2

Several exports (say `glint bench refine --seed K --export DIR/seedK` for K = 1..5: new noise
and initial poses per seed) are scored together: the goal's verdict per part, point count and
view count then compares median errors over the seeds, since one problem's error is mostly its
noise draw.

Each problem directory holds `model.ply` (model surface samples with normals, object frame,
metres), `points.ply` (the data, world frame), `problem.json` (`t_o_w_init`, `t_o_w_gt`: 4x4
row-major, world -> object; the iteration budget and maximum correspondence distance Glint's
ICP used; the part's symmetry) and `glint.json` (Glint's median times and errors).

Every peer registers the data (source) onto the model (target) from the same initial pose,
with the same maximum correspondence distance and iteration budget, so its transformation is
t_o_w. Open3D: registration_icp point-to-point and point-to-plane (legacy pipeline; it builds
its k-d tree of the target inside every call, which is part of its time: the tree's build
time alone is printed too). small_gicp: align() on pre-built PointClouds and KdTree (no
downsampling), ICP, PLANE_ICP and GICP; its tree and covariances are built once, outside the
timing, as Glint's model is; its convergence thresholds are set to Glint ICP's (1 µm,
1e-6 rad) instead of its defaults (1 mm, 0.1°), which would stop it early. Open3D keeps its
default relative fitness/RMSE criteria (1e-6). Errors are Glint's definition: distance of the object origins
and the smallest rotation angle over the part's symmetry group.

The thread count is set before the libraries load (OMP_NUM_THREADS for Open3D, num_threads
for small_gicp); compare with Glint's rows of the same thread count.
"""

import argparse
import json
import os
import sys
import time
from pathlib import Path


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("export", type=Path, nargs="+",
                   help="directories written by glint bench refine --export (one per seed)")
    p.add_argument("--threads", type=int, default=1, help="threads of every peer (default 1)")
    p.add_argument("--repeats", type=int, default=5, help="timed runs; the median is printed")
    p.add_argument("--gicp-neighbours", type=int, default=20,
                   help="neighbours for small_gicp's covariances (its default is 20)")
    return p.parse_args()


ARGS = parse_args()
if ARGS.threads < 1 or ARGS.repeats < 1:
    sys.exit("error: --threads and --repeats must be at least 1")
os.environ["OMP_NUM_THREADS"] = str(ARGS.threads)

import numpy as np  # noqa: E402

try:
    import open3d as o3d  # noqa: E402
except ImportError as e:
    sys.exit(f"error: cannot import open3d ({e}); pip install open3d (and apt-get install libusb-1.0-0)")
try:
    import small_gicp  # noqa: E402
except ImportError as e:
    sys.exit(f"error: cannot import small_gicp ({e}); pip install small_gicp")


def matrix(problem, key, path):
    try:
        m = np.asarray(problem[key], dtype=float).reshape(4, 4)
    except (KeyError, ValueError) as e:
        sys.exit(f"error: {path}: field `{key}` must be 16 numbers (4x4 row-major): {e}")
    if not np.all(np.isfinite(m)):
        sys.exit(f"error: {path}: field `{key}` is not finite")
    return m


def rotation_angle(r):
    return float(np.arccos(np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0)))


def pose_error(t_o_w_est, t_o_w_gt, symmetry):
    """Glint's pose_error on t_w_o: origin distance (mm) and rotation (deg) over the symmetry."""
    t_w_o_est, t_w_o_gt = np.linalg.inv(t_o_w_est), np.linalg.inv(t_o_w_gt)
    trans_mm = 1e3 * float(np.linalg.norm(t_w_o_est[:3, 3] - t_w_o_gt[:3, 3]))
    r_rel = t_w_o_est[:3, :3].T @ t_w_o_gt[:3, :3]
    axis = symmetry.get("continuous_axis")
    best = np.inf
    for s in symmetry["discrete_rotations_row_major"]:
        m = r_rel @ np.asarray(s, dtype=float).reshape(3, 3)
        if axis is not None:
            a = np.asarray(axis, dtype=float)
            angle = float(np.arccos(np.clip(a @ (m @ a) / (a @ a), -1.0, 1.0)))
        else:
            angle = rotation_angle(m)
        best = min(best, angle)
    return trans_mm, float(np.degrees(best))


def timed(f, repeats):
    times, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        r = f()
        times.append(time.perf_counter() - start)
        result = r if result is None else result
    return float(np.median(times)), result


def read_cloud(path):
    cloud = o3d.io.read_point_cloud(str(path))
    if len(cloud.points) == 0:
        sys.exit(f"error: {path}: no points (is it a PLY written by glint bench refine --export?)")
    return cloud


def run_problem(d):
    problem_path = d / "problem.json"
    problem = json.loads(problem_path.read_text())
    glint = json.loads((d / "glint.json").read_text())
    t_init = matrix(problem, "t_o_w_init", problem_path)
    t_gt = matrix(problem, "t_o_w_gt", problem_path)
    iterations = int(problem["iterations"])
    max_dist = float(problem["max_correspondence_distance_m"])
    symmetry = problem["symmetry"]
    model = read_cloud(d / "model.ply")
    data = read_cloud(d / "points.ply")
    if not model.has_normals():
        sys.exit(f"error: {d / 'model.ply'}: no normals (nx, ny, nz)")
    rows = []

    def add(method, seconds, t, iters):
        rows.append((method, seconds, pose_error(t, t_gt, symmetry), iters))

    reg = o3d.pipelines.registration
    criteria = reg.ICPConvergenceCriteria(max_iteration=iterations)
    for name, estimation in [("open3d-p2p", reg.TransformationEstimationPointToPoint()),
                             ("open3d-p2plane", reg.TransformationEstimationPointToPlane())]:
        seconds, r = timed(lambda: reg.registration_icp(data, model, max_dist, t_init,
                                                        estimation, criteria), ARGS.repeats)
        # Open3D's legacy result does not report its iteration count.
        add(name, seconds, np.asarray(r.transformation), None)
    kd_s, _ = timed(lambda: o3d.geometry.KDTreeFlann(model), ARGS.repeats)

    target = small_gicp.PointCloud(np.asarray(model.points))
    source = small_gicp.PointCloud(np.asarray(data.points))
    target_tree = small_gicp.KdTree(target, num_threads=ARGS.threads)
    # PLANE_ICP and GICP need normals/covariances: estimated by small_gicp from the samples.
    small_gicp.estimate_normals_covariances(target, target_tree, ARGS.gicp_neighbours,
                                            ARGS.threads)
    source_tree = small_gicp.KdTree(source, num_threads=ARGS.threads)
    small_gicp.estimate_normals_covariances(source, source_tree, ARGS.gicp_neighbours,
                                            ARGS.threads)
    for name, kind in [("small_gicp-icp", "ICP"), ("small_gicp-plane", "PLANE_ICP"),
                       ("small_gicp-gicp", "GICP")]:
        seconds, r = timed(lambda: small_gicp.align(
            target, source, target_tree, init_T_target_source=t_init, registration_type=kind,
            max_correspondence_distance=max_dist, num_threads=ARGS.threads,
            max_iterations=iterations, rotation_epsilon=1e-6, translation_epsilon=1e-6),
            ARGS.repeats)
        add(name, seconds, np.asarray(r.T_target_source), r.iterations)

    glint_rows = [g for g in glint["runs"] if g["threads"] == ARGS.threads]
    return problem, glint_rows, rows, kd_s


def main():
    dirs = [p.parent for export in ARGS.export for p in sorted(export.glob("*/problem.json"))]
    if not dirs:
        sys.exit(f"error: {' '.join(map(str, ARGS.export))}: no */problem.json "
                 "(run glint bench refine --export there)")
    print(f"Peers: open3d {o3d.__version__}, small_gicp {getattr(small_gicp, '__version__', '?')}; "
          f"{ARGS.threads} thread(s) each; median of {ARGS.repeats} runs\n")
    print("| part | points | views | method | threads | iterations | time (ms) | final error (mm / °) "
          "| Glint SDF time / this | Glint SDF error (mm / °) |")
    print("|---|---:|---:|---|---:|---:|---:|---:|---:|---:|")
    groups = {}
    for d in dirs:
        problem, glint_rows, rows, kd_s = run_problem(d)
        sdf = next((g for g in glint_rows if g["method"] == "sdf"), None)
        if sdf is None:
            print(f"| {problem['part']} | … | no Glint rows at {ARGS.threads} threads in "
                  f"{d / 'glint.json'}: rerun glint bench refine with --threads {ARGS.threads} |")
            continue
        head = f"| {problem['part']} | {problem['points']} | {problem['views']}"
        for g in glint_rows:
            print(f"{head} | glint-{g['method']} | {g['threads']} | {g['iterations']} | "
                  f"{1e3 * g['time_s_median']:.3f} | {g['t_err_mm']:.3f} / {g['r_err_deg']:.3f} | "
                  f"{sdf['time_s_median'] / g['time_s_median']:.3f} | "
                  f"{sdf['t_err_mm']:.3f} / {sdf['r_err_deg']:.3f} |")
        for method, seconds, (t_mm, r_deg), iters in rows:
            ratio = sdf["time_s_median"] / seconds
            print(f"{head} | {method} | {ARGS.threads} | {iters if iters is not None else '≤' + str(problem['iterations'])} | "
                  f"{1e3 * seconds:.3f} | {t_mm:.3f} / {r_deg:.3f} | {ratio:.3f} | "
                  f"{sdf['t_err_mm']:.3f} / {sdf['r_err_deg']:.3f} |")
            if method == "open3d-p2p":
                key = (problem["part"], problem["points"], problem["views"])
                # Open3D rebuilds the model's k-d tree in every call; Glint builds its model once.
                groups.setdefault(key, []).append(dict(
                    speedup=seconds / sdf["time_s_median"],
                    speedup_no_tree=max(seconds - kd_s, 0.0) / sdf["time_s_median"],
                    glint=(sdf["t_err_mm"], sdf["r_err_deg"]), open3d=(t_mm, r_deg)))
        print(f"{head} | (open3d k-d tree build of the model alone) | {ARGS.threads} | | "
              f"{1e3 * kd_s:.3f} | | | |")
    print("\nGoal: Glint SDF ≥ 10× faster than Open3D point-to-point ICP at equal or better accuracy")
    print("(per part, points and views: median over the problems given, one per export)\n")
    print("| part | points | views | problems | speed-up (median, min) | without Open3D's tree build "
          "| Glint error (mm / °) | Open3D error (mm / °) | Glint at least as accurate (t, r) | goal |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---|")
    held = 0

    def med(xs):
        return float(np.median(xs))

    for (part, points, views), runs in sorted(groups.items()):
        speedup = med([r["speedup"] for r in runs])
        g_t, g_r = med([r["glint"][0] for r in runs]), med([r["glint"][1] for r in runs])
        o_t, o_r = med([r["open3d"][0] for r in runs]), med([r["open3d"][1] for r in runs])
        wins_t = sum(r["glint"][0] <= r["open3d"][0] for r in runs)
        wins_r = sum(r["glint"][1] <= r["open3d"][1] for r in runs)
        accurate = g_t <= o_t and g_r <= o_r
        holds = speedup >= 10.0 and accurate
        held += holds
        print(f"| {part} | {points} | {views} | {len(runs)} | {speedup:.1f}× "
              f"({min(r['speedup'] for r in runs):.1f}×) | "
              f"{med([r['speedup_no_tree'] for r in runs]):.1f}× | {g_t:.3f} / {g_r:.3f} | "
              f"{o_t:.3f} / {o_r:.3f} | {wins_t}/{len(runs)}, {wins_r}/{len(runs)} | "
              f"{'holds' if holds else 'does not hold'}"
              f"{'' if accurate else ' (accuracy)'}{'' if speedup >= 10 else ' (speed)'} |")
    print(f"\nThe goal holds on {held} of {len(groups)} configurations.")


if __name__ == "__main__":
    main()
