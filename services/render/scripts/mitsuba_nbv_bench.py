#!/usr/bin/env python3
"""Time the renders of one next-best-view decision with Mitsuba 3, against Glint's.

    glint bench nbv --part gear --candidates 60 --mitsuba-export DIR
    python3 services/render/scripts/mitsuba_nbv_bench.py DIR [--threads 1,all]

Needs `pip install mitsuba numpy` and, for the llvm variant, a libLLVM ≥ 17 (Debian 12:
`apt-get install libllvm19`; see mitsuba_crosscheck.point_drjit_at_llvm).

Loads DIR/nbv_scene.json (client/cli/src/mitsuba_export.rs, `write_nbv`): the prediction's
scene (the part at the hypothesis pose with its fitted material, the known bin), every
candidate's rig pose and the crops Glint's prediction rendered. Per thread count it renders
with Mitsuba's `path` integrator, at Glint's samples per pixel, with the equal settings of
mitsuba_crosscheck.py (monochrome, two-sided face normals, the constant-intensity projector
moved with the rig):

- **same images**: what Glint's render stage renders — single-path (max_depth 2) and
  multi-path (max_bounces + 1, Russian roulette as Glint's) white images of the left and right
  crops, for every candidate the part is in view of (right crops clipped to the sensor: Mitsuba
  cannot render off its film);
- **paper-style**: full-frame left images without a region of interest, single-path and two
  multi-path (the paper's strong and weak white renders), for every candidate.

Each candidate is a scene of its own (its projector moves with the rig); its load time is
given apart. Every render runs twice: the first compiles kernels (llvm variants), the second
is the figure compared (warm). Glint's render stage includes its scene build (BVH), so the
ratio is given against Mitsuba's warm renders alone and with its scene loads.
"""

import argparse
import json
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from mitsuba_crosscheck import (  # noqa: E402  (the shared scene builders)
    choose_variant,
    fail,
    point_drjit_at_llvm,
    projector_dict,
    sensor_dict,
    shape_entries,
)


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("export_dir", type=Path, help="directory written by glint bench nbv --mitsuba-export")
    p.add_argument("--variant", default=None, help="Mitsuba variant (default: llvm_ad_mono when a libLLVM ≥ 17 is found)")
    p.add_argument(
        "--threads",
        default="1,all",
        help="comma-separated thread counts; `all` is Glint's own all-cores count (default 1,all)",
    )
    p.add_argument("--seed", type=int, default=1)
    return p.parse_args()


def clipped_crop(crop, width_px):
    """(u, v, w, h) of a crop clipped to the sensor's columns, or None when nothing is left."""
    u0, u1 = max(crop["u_min"], 0), min(crop["u_min"] + crop["width"], width_px)
    if u1 <= u0:
        return None
    return (u0, crop["v_min"], u1 - u0, crop["height"])


def timed_render(mi, dr, scene, sensor, integrator, spp, seed):
    start = time.perf_counter()
    img = mi.render(scene, sensor=sensor, integrator=integrator, spp=spp, seed=seed)
    dr.eval(img)
    return time.perf_counter() - start


def main():
    args = parse_args()
    root = args.export_dir
    path = root / "nbv_scene.json"
    if not path.is_file():
        fail(f"{path} not found: run glint bench nbv --mitsuba-export {root} first")
    export = json.loads(path.read_text())
    glint_rows = {row["threads"]: row for row in export["glint"]}
    all_threads = max(glint_rows)
    threads = []
    for t in args.threads.split(","):
        t = t.strip()
        if t == "all":
            threads.append(all_threads)
        elif t.isdigit() and int(t) >= 1:
            threads.append(int(t))
        else:
            fail(f"--threads: {t!r} is neither a positive whole number nor `all`")

    point_drjit_at_llvm()
    try:
        import drjit as dr
        import mitsuba as mi
    except ImportError as e:
        fail(f"{e}: install Mitsuba 3 with `pip install mitsuba` (PyPI)")
    variant = choose_variant(mi, args.variant)

    spp = export["samples_per_pixel"]
    single = mi.load_dict({"type": "path", "max_depth": 2, "hide_emitters": True})
    mp = export["multi_path"]
    multi_dict = {"type": "path", "max_depth": mp["max_bounces"] + 1, "hide_emitters": True}
    if mp.get("roulette_after") is not None:
        multi_dict["rr_depth"] = mp["roulette_after"]
    multi = mi.load_dict(multi_dict)
    shapes = shape_entries(export, root)
    candidates = export["candidates"]
    in_view = [c for c in candidates if c["crops"] is not None]

    results = []
    for n in threads:
        dr.set_thread_count(n)
        load_s = same_s = same_cold_s = paper_s = 0.0
        crop_px = clipped_px = 0
        for i, c in enumerate(candidates):
            left, right = c["cameras"]
            d = {
                "type": "scene",
                "full": sensor_dict(mi, left["intrinsics"], left["t_w_c"], "camera"),
                "projector": projector_dict(mi, export["projector"], c["t_w_p"]),
            }
            sensors = ["full"]
            if c["crops"] is not None:
                for name, cam, crop in zip(("left", "right"), (left, right), c["crops"]):
                    window = clipped_crop(crop, cam["intrinsics"]["width_px"])
                    crop_px += crop["width"] * crop["height"]
                    if window is None:
                        continue
                    clipped_px += window[2] * window[3]
                    d[name] = sensor_dict(mi, cam["intrinsics"], cam["t_w_c"], "camera", window)
                    sensors.append(name)
            d.update(shapes)
            start = time.perf_counter()
            scene = mi.load_dict(d)
            load_s += time.perf_counter() - start
            # Sensors are in the dict's key order: "full" first, then the crops.
            sensor_of = {name: scene.sensors()[k] for k, name in enumerate(sensors)}
            seed = args.seed + 16 * i
            for name in sensors[1:]:
                for integrator in (single, multi):
                    same_cold_s += timed_render(mi, dr, scene, sensor_of[name], integrator, spp, seed)
                    same_s += timed_render(mi, dr, scene, sensor_of[name], integrator, spp, seed + 1)
            for k, integrator in enumerate((single, multi, multi)):
                paper_s += timed_render(mi, dr, scene, sensor_of["full"], integrator, spp, seed + 2 + k)
        g = glint_rows.get(n)
        results.append(
            {
                "threads": n,
                "mitsuba_load_ms": 1e3 * load_s,
                "mitsuba_same_ms": 1e3 * same_s,
                "mitsuba_same_cold_ms": 1e3 * same_cold_s,
                "mitsuba_paper_style_ms": 1e3 * paper_s,
                "crop_px": crop_px,
                "rendered_crop_px": clipped_px,
                "glint_render_ms": None if g is None else g["render_ms"],
                "glint_total_ms": None if g is None else g["total_ms"],
            }
        )

    print(
        f"Mitsuba {mi.__version__} variant {variant}; {len(candidates)} candidates "
        f"({len(in_view)} with the part in view), {len(export['shapes'])} shapes, {spp} spp.\n"
        "Glint's render stage: summed over candidates (on n threads about n × its wall time).\n"
    )
    print(
        "| threads | Glint render ms | Glint decision ms | Mitsuba same images ms (cold) "
        "| + scene loads ms | Mitsuba paper-style ms | Glint render / Mitsuba same "
        "| Glint decision / Mitsuba paper-style |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in results:
        gr, gt = r["glint_render_ms"], r["glint_total_ms"]
        # Glint's per-candidate stage times add up over parallel candidates: divide by n.
        g_render_wall = None if gr is None else gr / r["threads"]
        ratio = lambda a, b: "—" if a is None else f"{a / b:.3f}"
        print(
            f"| {r['threads']} | {'—' if gr is None else f'{g_render_wall:.0f}'} "
            f"| {'—' if gt is None else f'{gt:.0f}'} "
            f"| {r['mitsuba_same_ms']:.0f} ({r['mitsuba_same_cold_ms']:.0f}) "
            f"| {r['mitsuba_same_ms'] + r['mitsuba_load_ms']:.0f} "
            f"| {r['mitsuba_paper_style_ms']:.0f} "
            f"| {ratio(g_render_wall, r['mitsuba_same_ms'])} "
            f"| {ratio(gt, r['mitsuba_paper_style_ms'])} |"
        )
    lost = 1.0 - results[0]["rendered_crop_px"] / max(results[0]["crop_px"], 1)
    print(f"\ncrop pixels off the sensor (not rendered by Mitsuba): {100 * lost:.1f} %")
    out = root / "nbv_mitsuba.json"
    tmp = out.with_suffix(".json.tmp")
    tmp.write_text(json.dumps({"variant": variant, "rows": results}, indent=2))
    os.replace(tmp, out)  # atomic: never a half-written result
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
