#!/usr/bin/env python3
"""Cross-check Glint's renderer against Mitsuba 3 on the same scene.

    glint bench render --mitsuba-export DIR [--part chrome-screw] [--export-spp 64]
    python3 services/render/scripts/mitsuba_crosscheck.py DIR [--variant llvm_ad_mono]

Loads DIR/scene.json (see client/cli/src/mitsuba_export.rs), renders it with Mitsuba's `path`
integrator at the same samples per pixel as Glint — max_depth 2 for single-path (direct light
only) and max_bounces + 1 for multi-path — and prints, per light transport and for the parts, the
bin and all signal pixels:

- `ΣM/ΣG − 1`: Σ Mitsuba / Σ Glint − 1 over the signal pixels (energy bias), Mitsuba averaged
  over `--seeds` renders; beside it the range of the same figure for each seed alone, and its
  mean over seeds with both images clamped at the 99th percentile of their pixels. Shiny
  parts under a point light give heavy-tailed pixel estimates (highlights, caustic paths) whose
  plain sums swing by ±15 % from seed to seed at 64 spp; the range and the clamp show whether a
  difference is more than that;
- `mean abs rel, median`: per-pixel |M − G| / G over the signal pixels, Mitsuba's first seed;
- `noise floor`: the same per-pixel statistics between Mitsuba's first two seeds (still divided
  by Glint's radiance), i.e. what Monte Carlo noise alone gives: a Glint-vs-Mitsuba figure near
  it means agreement up to noise;
- times: Glint's wall time from the export; Mitsuba's fastest warm render and, in brackets, the
  first (cold, with JIT compilation for llvm variants) one; the ratio Glint / Mitsuba (warm),
  both at Glint's thread count.

Signal pixels: Glint radiance above 1 % of its 99th percentile over the image (and a surface
hit through the pixel centre).

Equal settings, and why each is so:
- Glint is monochrome: the `*_mono` variants render one channel; an RGB variant is reduced to
  the channel mean (grey materials and a white light make the channels equal).
- Glint shades with face normals on both sides: PLYs load with `face_normals`, every BSDF is
  wrapped in `twosided`.
- Glint's projector has constant radiant intensity I (W/sr) over its frustum. Mitsuba's
  `projector` emitter sends π·E(uv)/cos³θ per unit `irradiance` texture value E (constant
  irradiance on a fronto-parallel plane), so the texture is E = I cos³θ / π per texel.
- Pixels: both use a box filter over the pixel; Glint's first sample goes through the pixel centre
  (u + 0.5, v + 0.5), the others are uniform in the pixel like Mitsuba's independent sampler.
- Frames: Glint's cameras are x right, y down, z forward; Mitsuba's are x left, y up, z forward,
  so to_world = t_w_c · diag(−1, −1, 1).
"""

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("export_dir", type=Path, help="directory written by glint bench render --mitsuba-export")
    p.add_argument(
        "--variant",
        default=None,
        help="Mitsuba variant (default: llvm_ad_mono when libLLVM loads, else scalar_rgb)",
    )
    p.add_argument("--seed", type=int, default=1, help="first Mitsuba seed")
    p.add_argument("--seeds", type=int, default=4, help="Mitsuba renders per transport (≥ 2)")
    return p.parse_args()


def fail(msg):
    print(f"error: {msg}", file=sys.stderr)
    sys.exit(2)


def point_drjit_at_llvm():
    """Dr.Jit's llvm variants JIT through libLLVM; LLVM 14–16 fail on its code ("Cannot select:
    fminimum"), so unless DRJIT_LIBLLVM_PATH is set, point it at the newest libLLVM ≥ 17 found
    (Debian: `apt-get install libllvm19`). Call before importing drjit."""
    if os.environ.get("DRJIT_LIBLLVM_PATH"):
        return
    found = []
    for d in ("/usr/lib/x86_64-linux-gnu", "/usr/lib/aarch64-linux-gnu", "/usr/lib", "/usr/local/lib"):
        for f in Path(d).glob("libLLVM-*.so*") if Path(d).is_dir() else []:
            major = f.name.split("-")[1].split(".")[0]
            if major.isdigit() and int(major) >= 17:
                found.append((int(major), str(f)))
    if found:
        os.environ["DRJIT_LIBLLVM_PATH"] = max(found)[1]


def choose_variant(mi, wanted):
    if wanted:
        mi.set_variant(wanted)
        return wanted
    # Without a libLLVM ≥ 17 the llvm variant loads but aborts the process at its first render.
    llvm = ("llvm_ad_mono",) if os.environ.get("DRJIT_LIBLLVM_PATH") else ()
    if not llvm:
        print("note: no libLLVM ≥ 17 found (apt-get install libllvm19); using scalar_rgb", file=sys.stderr)
    for v in llvm + ("scalar_rgb",):
        try:
            mi.set_variant(v)
            return v
        except Exception as e:  # llvm variants need libLLVM ≥ 17 (point_drjit_at_llvm)
            print(f"note: variant {v} unavailable ({e}); trying the next", file=sys.stderr)
    fail("no usable Mitsuba variant")


def flip_xy(t_rows):
    """Glint frame (x right, y down) → Mitsuba's (x left, y up): t · diag(−1, −1, 1, 1)."""
    t = np.array(t_rows, dtype=np.float64)
    if t.shape != (4, 4):
        fail(f"a pose in scene.json is {t.shape}, expected 4×4")
    return t @ np.diag([-1.0, -1.0, 1.0, 1.0])


def centred_fov_deg(k, what):
    """Mitsuba's perspective models need fx = fy and the principal point at the image centre."""
    w, h = k["width_px"], k["height_px"]
    if abs(k["fx_px"] - k["fy_px"]) > 1e-9 * k["fx_px"]:
        fail(f"{what}: fx ≠ fy ({k['fx_px']} vs {k['fy_px']}); the cross-check needs square pixels")
    if abs(k["cx_px"] - w / 2) > 1e-6 or abs(k["cy_px"] - h / 2) > 1e-6:
        fail(f"{what}: principal point ({k['cx_px']}, {k['cy_px']}) is not the image centre")
    return math.degrees(2.0 * math.atan(w / 2.0 / k["fx_px"]))


def projector_texture(k, intensity_w_per_sr):
    """Per-texel irradiance E = I cos³θ / π that makes Mitsuba's projector a constant-intensity one."""
    w, h = k["width_px"], k["height_px"]
    x = (np.arange(w) + 0.5 - k["cx_px"]) / k["fx_px"]
    y = (np.arange(h) + 0.5 - k["cy_px"]) / k["fy_px"]
    xx, yy = np.meshgrid(x, y)
    cos3 = (1.0 + xx * xx + yy * yy) ** -1.5
    return (intensity_w_per_sr * cos3 / math.pi).astype(np.float32)


def load_glint_exr(mi, path):
    if not path.is_file():
        fail(f"{path} is missing: rerun glint bench render --mitsuba-export")
    bitmap = mi.Bitmap(str(path))
    names = [field.name for field in bitmap.struct_()]
    pixels = np.array(bitmap, dtype=np.float64).reshape(bitmap.height(), bitmap.width(), len(names))
    channels = {n: pixels[:, :, i] for i, n in enumerate(names)}
    for name in ("radiance", "depth_m", "label"):
        if name not in channels:
            fail(f"{path} has no channel {name!r} (has {sorted(channels)})")
    return channels


def sensor_dict(mi, k, t_w_c, what, crop=None):
    """A perspective sensor for Glint camera intrinsics `k` at `t_w_c` (row-major 4×4); `crop`
    (u_min, v_min, width, height), px, renders only that window of the full film."""
    film = {
        "type": "hdrfilm",
        "width": k["width_px"],
        "height": k["height_px"],
        "rfilter": {"type": "box"},
    }
    if crop is not None:
        u, v, w, h = crop
        film.update({"crop_offset_x": u, "crop_offset_y": v, "crop_width": w, "crop_height": h})
    return {
        "type": "perspective",
        "fov": centred_fov_deg(k, what),
        "fov_axis": "x",
        "near_clip": 1e-3,
        "far_clip": 100.0,
        "to_world": mi.ScalarTransform4f(flip_xy(t_w_c).tolist()),
        "film": film,
        "sampler": {"type": "independent", "sample_count": 1},
    }


def projector_dict(mi, proj, t_w_p):
    """Glint's constant-intensity projector (white pattern) at `t_w_p` as Mitsuba's `projector`."""
    if proj.get("pattern") != "white":
        fail(f"projector pattern {proj.get('pattern')!r}: only 'white' is supported")
    kp = proj["intrinsics"]
    return {
        "type": "projector",
        "fov": centred_fov_deg(kp, "projector"),
        "fov_axis": "x",
        "to_world": mi.ScalarTransform4f(flip_xy(t_w_p).tolist()),
        "irradiance": {
            "type": "bitmap",
            "bitmap": mi.Bitmap(projector_texture(kp, proj["intensity_w_per_sr"])),
            "raw": True,
            "filter_type": "bilinear",
        },
    }


def shape_entries(scene, root):
    """The scene's materials (two-sided principled BSDFs) and PLY shapes as scene-dict entries."""
    d = {}
    for i, m in enumerate(scene["materials"]):
        p = m["principled"]
        d[f"bsdf_{i}"] = {
            "type": "twosided",
            "id": f"bsdf_{i}",
            "bsdf": {
                "type": "principled",
                "base_color": {"type": "rgb", "value": [p["base_color"]] * 3},
                "metallic": p["metallic"],
                "roughness": p["roughness"],
                "specular": p["specular"],
                "spec_tint": p["spec_tint"],
                "anisotropic": p["anisotropic"],
                "sheen": p["sheen"],
                "sheen_tint": p["sheen_tint"],
                "clearcoat": p["clearcoat"],
                "clearcoat_gloss": p["clearcoat_gloss"],
                "spec_trans": 0.0,
            },
        }
    for s in scene["shapes"]:
        path = root / s["file"]
        if not path.is_file():
            fail(f"{path} is missing")
        d[s["name"]] = {
            "type": "ply",
            "filename": str(path),
            "face_normals": True,
            "bsdf": {"type": "ref", "id": f"bsdf_{s['material']}"},
        }
    return d


def build_scene(mi, scene, root, integrator):
    cam = scene["camera"]
    proj = scene["projector"]
    d = {
        "type": "scene",
        "integrator": integrator,
        "sensor": sensor_dict(mi, cam["intrinsics"], cam["t_w_c"], "camera"),
        "projector": projector_dict(mi, proj, proj["t_w_p"]),
    }
    d.update(shape_entries(scene, root))
    return mi.load_dict(d)


def render(mi, dr, scene, spp, seed):
    start = time.perf_counter()
    img = mi.render(scene, spp=spp, seed=seed)
    dr.eval(img)
    a = np.array(img, dtype=np.float64)
    elapsed = time.perf_counter() - start
    # Mono: one channel; RGB: grey scene, so the mean of the channels.
    return (a.mean(axis=2) if a.ndim == 3 else a), elapsed


def rel_stats(a, b, glint, mask):
    """Σa/Σb − 1 (plain, and with both clamped at the 99th percentile of the pair's pixels) and
    per-pixel |a − b| / Glint over `mask` (Glint > 0 there)."""
    a, b, g = a[mask], b[mask], glint[mask]
    rel = np.abs(a - b) / g
    cap = np.percentile(np.concatenate([a, b]), 99)
    return {
        "sum_ratio_minus_1": float(a.sum() / b.sum() - 1.0),
        "clamped_sum_ratio_minus_1": float(np.minimum(a, cap).sum() / np.minimum(b, cap).sum() - 1.0),
        "mean_abs_rel": float(rel.mean()),
        "median_abs_rel": float(np.median(rel)),
    }


def main():
    args = parse_args()
    if args.seeds < 2:
        fail("--seeds must be at least 2 (the noise floor compares two seeds)")
    root = args.export_dir
    scene_path = root / "scene.json"
    if not scene_path.is_file():
        fail(f"{scene_path} not found: run glint bench render --mitsuba-export {root} first")
    scene_json = json.loads(scene_path.read_text())

    point_drjit_at_llvm()
    try:
        import drjit as dr
        import mitsuba as mi
    except ImportError as e:
        fail(f"{e}: install Mitsuba 3 with `pip install mitsuba` (PyPI)")

    variant = choose_variant(mi, args.variant)
    renders = scene_json["renders"]
    threads = renders[0]["threads"]
    dr.set_thread_count(threads)  # Dr.Jit's pool runs every variant's render
    k = scene_json["camera"]["intrinsics"]
    print(
        f"Mitsuba {mi.__version__} variant {variant}, {threads} threads (Glint's); "
        f"{k['width_px']}×{k['height_px']}, {len(scene_json['shapes'])} shapes, "
        f"{renders[0]['samples_per_pixel']} spp\n"
    )
    bin_label = next(s["label"] for s in scene_json["shapes"] if s["name"] == "bin")

    rows = []
    for r in renders:
        spp = r["samples_per_pixel"]
        depth = 2 if r["transport"] == "single-path" else r["max_bounces"] + 1
        integrator = {"type": "path", "max_depth": depth, "hide_emitters": True}
        if r.get("roulette_after") is not None:
            integrator["rr_depth"] = r["roulette_after"]
        scene = build_scene(mi, scene_json, root, integrator)
        glint = load_glint_exr(mi, root / r["exr"])
        g = glint["radiance"]
        # A cold run (JIT compilation for llvm variants), then one timed run per seed.
        _, cold_s = render(mi, dr, scene, spp, args.seed + 1000)
        runs = [render(mi, dr, scene, spp, args.seed + i) for i in range(args.seeds)]
        ms = [m for m, _ in runs]
        if ms[0].shape != g.shape:
            fail(f"Mitsuba image {ms[0].shape} vs Glint {g.shape}")
        m_mean = np.mean(ms, axis=0)
        hit = np.isfinite(glint["depth_m"])
        signal = hit & (g > 0.01 * np.percentile(g[hit], 99))
        labels = glint["label"]
        regions = {
            "parts": signal & (labels > 0) & (labels != bin_label),
            "bin": signal & (labels == bin_label),
            "all": signal,
        }
        for name, mask in regions.items():
            if mask.sum() == 0:
                continue
            per_seed = [rel_stats(m, g, g, mask) for m in ms]
            rows.append(
                {
                    "transport": r["transport"],
                    "region": name,
                    "pixels": int(mask.sum()),
                    "mean_of_seeds_vs_glint": rel_stats(m_mean, g, g, mask),
                    "per_seed_sum_ratio_minus_1": [x["sum_ratio_minus_1"] for x in per_seed],
                    # Clamping is fair only between images of equal sample counts: per seed.
                    "per_seed_clamped_sum_ratio_minus_1": [
                        x["clamped_sum_ratio_minus_1"] for x in per_seed
                    ],
                    "seed1_vs_glint": rel_stats(ms[0], g, g, mask),
                    "noise_floor_seed1_vs_seed2": rel_stats(ms[0], ms[1], g, mask),
                    "glint_s": r["time_s"],
                    "mitsuba_s": min(t for _, t in runs),
                    "mitsuba_cold_s": cold_s,
                }
            )

    print(
        f"| transport | region | signal px | ΣM/ΣG − 1 (mean of {args.seeds} seeds) "
        "| per seed: min … max | q99-clamped, seed mean | mean abs rel, median (seed 1) "
        "| noise floor: mean, median (seed 1 vs 2) | Glint s | Mitsuba s (cold) "
        "| Glint/Mitsuba time |"
    )
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for x in rows:
        a, v, n = x["mean_of_seeds_vs_glint"], x["seed1_vs_glint"], x["noise_floor_seed1_vs_seed2"]
        seeds = x["per_seed_sum_ratio_minus_1"]
        clamped = float(np.mean(x["per_seed_clamped_sum_ratio_minus_1"]))
        print(
            f"| {x['transport']} | {x['region']} | {x['pixels']} | {a['sum_ratio_minus_1']:+.4f} "
            f"| {min(seeds):+.4f} … {max(seeds):+.4f} | {clamped:+.4f} "
            f"| {v['mean_abs_rel']:.4f}, {v['median_abs_rel']:.4f} "
            f"| {n['mean_abs_rel']:.4f}, {n['median_abs_rel']:.4f} "
            f"| {x['glint_s']:.3f} | {x['mitsuba_s']:.3f} ({x['mitsuba_cold_s']:.3f}) "
            f"| {x['glint_s'] / x['mitsuba_s']:.2f} |"
        )
    out = root / "crosscheck.json"
    tmp = out.with_suffix(".json.tmp")
    tmp.write_text(json.dumps({"variant": variant, "threads": threads, "rows": rows}, indent=2))
    os.replace(tmp, out)  # atomic: never a half-written result
    print(f"\nwrote {out}")


if __name__ == "__main__":
    main()
