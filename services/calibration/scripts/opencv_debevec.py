#!/usr/bin/env python3
"""Cross-check of Glint's Debevec-Malik response against OpenCV's on the same image files.

Usage: opencv_debevec.py STACK_DIR GLINT_RESPONSE_JSON GT_SENSOR_JSON [FROM TO]

Runs cv2.createCalibrateDebevec(samples=70, lambda=10, random=False) on the exposure stack in
STACK_DIR (stack.json + grayscale PNGs), then prints, for OpenCV and for Glint (the g.json of
`glint calibrate response`), the max and RMS |delta ln g^-1| against the ground-truth response
of GT_SENSOR_JSON over FROM..TO of full scale (default 0.1..0.9), after removing the best
constant offset (both methods recover exposure only up to a scale). Evaluation only.
Needs: pip install opencv-python-headless numpy
"""
import json
import math
import os
import sys

import cv2
import numpy as np


def true_response(curve):
    """g: normalised exposure -> normalised intensity, as glint_render::sensor::ResponseCurve."""
    if curve == "Linear":
        return lambda x: min(max(x, 0.0), 1.0)
    (kind, p), = curve.items()
    if kind == "Gamma":
        return lambda x: min(max(x, 0.0), 1.0) ** (1.0 / p["gamma"])
    if kind == "SCurve":
        g, c = p["gamma"], p["contrast"]

        def s(x):
            y = min(max(x, 0.0), 1.0) ** (1.0 / g)
            return 0.5 * (1.0 + math.tanh(c * (y - 0.5)) / math.tanh(0.5 * c))
        return s
    raise ValueError(f"unknown response {curve!r}")


def invert(g, i):
    lo, hi = 0.0, 1.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if g(mid) < i:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def errors(dn, ln_x, g, max_dn, lo, hi):
    keep = [(d, l) for d, l in zip(dn, ln_x) if lo <= d / max_dn <= hi and math.isfinite(l)]
    diff = np.array([l - math.log(invert(g, d / max_dn)) for d, l in keep])
    diff -= diff.mean()
    return np.abs(diff).max(), math.sqrt((diff ** 2).mean()), len(keep)


def main():
    if len(sys.argv) not in (4, 6):
        sys.exit(__doc__)
    stack_dir, glint_json, gt_json = sys.argv[1:4]
    lo, hi = (float(sys.argv[4]), float(sys.argv[5])) if len(sys.argv) == 6 else (0.1, 0.9)
    with open(os.path.join(stack_dir, "stack.json")) as f:
        stack = json.load(f)
    if stack["bit_depth"] > 8:
        sys.exit("OpenCV's CalibrateDebevec takes 8-bit images only")
    images, times = [], []
    for entry in stack["images"]:
        path = os.path.join(stack_dir, entry["file"])
        img = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
        if img is None:
            sys.exit(f"cannot read {path}")
        # OpenCV's photo module wants 3-channel 8-bit images.
        images.append(cv2.cvtColor(img, cv2.COLOR_GRAY2BGR))
        times.append(entry["exposure_s"])
    times = np.array(times, dtype=np.float32)
    calibrate = cv2.createCalibrateDebevec(70, 10.0, False)  # samples, lambda, random
    response = calibrate.process(images, times)  # 256 x 1 x 3, linear g^-1 (relative)
    ocv_ln = np.log(np.maximum(response[:, 0, 0].astype(np.float64), 1e-30))

    with open(gt_json) as f:
        gt = json.load(f)
    g = true_response(gt["response"] if "response" in gt else gt["sensor"]["response"])
    with open(glint_json) as f:
        glint = json.load(f)
    max_dn = 255
    dn = np.arange(256, dtype=np.float64)
    rows = [
        ("OpenCV createCalibrateDebevec", errors(dn, ocv_ln, g, max_dn, lo, hi)),
        ("Glint debevec::calibrate", errors(glint["inverse"]["dn"], glint["inverse"]["ln_exposure"], g,
                                            glint["max_dn"], lo, hi)),
    ]
    print(f"stack {stack_dir}: {len(images)} exposures, well-exposed range {lo:.0%} .. {hi:.0%} of full scale")
    print(f"| method | levels | max |d ln g^-1| | rms |")
    print(f"|---|---:|---:|---:|")
    for name, (mx, rms, n) in rows:
        print(f"| {name} | {n} | {mx:.4f} | {rms:.4f} |")


if __name__ == "__main__":
    main()
