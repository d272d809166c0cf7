#!/usr/bin/env python3
"""FLIP (Andersson et al. 2020) of every method in an `aniso-eval` report folder, for comparison
with Cocco et al. 2024 Figs. 18-19 (mean FLIP).

    pip install flip-evaluator numpy
    python3 bench/crosscheck/aniso_flip.py REPORT_DIR [--ppd 67] [--ldr]

Reads, per case folder, truth_e0.exr and every <method>_<lookup>_e0.exr (F0 = 1), and
frame_n.exr for the mask of shaded pixels. HDR-FLIP by default (the radiance is HDR); --ldr
applies the evaluator's Reinhard + sRGB display transform first and runs LDR-FLIP. The mean is
taken over the shaded pixels only (the background is 0 in both images). Prints one row per case
and the share of cases where each method's mean FLIP is below bent-lg18's (same lookup).
The paper's pixels per degree and exposure settings are unknown: compare trends, not values.
"""
import argparse
import json
import os
import sys

import flip_evaluator as flip
import numpy as np


def display(x):
    t = np.clip(np.maximum(x, 0) / (1 + np.maximum(x, 0)), 0, 1)
    return np.where(t <= 0.0031308, 12.92 * t, 1.055 * np.power(t, 1 / 2.4) - 0.055)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("report")
    ap.add_argument("--ppd", type=float, default=67.0)
    ap.add_argument("--ldr", action="store_true")
    a = ap.parse_args()
    cases = sorted(d for d in os.listdir(a.report) if d.startswith("case"))
    if not cases:
        sys.exit(f"{a.report}: no case folders (was aniso-eval run with --no-pixels?)")
    wins, counts, sums = {}, {}, {}
    for c in cases:
        d = os.path.join(a.report, c)
        meta = json.load(open(os.path.join(d, "case.json")))
        n = flip.load(os.path.join(d, "frame_n.exr"))
        mask = np.linalg.norm(n, axis=2) > 0.5
        truth = flip.load(os.path.join(d, "truth_e0.exr")).astype(np.float32)
        row = {}
        for m in meta["methods"]:
            img = flip.load(os.path.join(d, f"{m}_e0.exr")).astype(np.float32)
            if a.ldr:
                err, _, _ = flip.evaluate(display(truth), display(img), "LDR", inputsRGB=True,
                                          applyMagma=False, parameters={"ppd": a.ppd})
            else:
                err, _, _ = flip.evaluate(truth, img, "HDR", applyMagma=False,
                                          parameters={"ppd": a.ppd})
            row[m] = float(err[..., 0][mask].mean())
        cs = meta["case"]
        print(f"{c} r {cs['r']} eta {cs['eta']}: " + ", ".join(f"{k} {v:.4f}" for k, v in row.items()))
        for m, v in row.items():
            lookup = m.rsplit("_", 1)[1]
            base = row.get(f"bent-lg18_{lookup if lookup != 'none' else 'engine'}")
            sums[m] = sums.get(m, 0.0) + v
            counts[m] = counts.get(m, 0) + 1
            if base is not None:
                wins[m] = wins.get(m, 0) + int(v < base)
    print("\nmethod | mean FLIP | wins vs bent-lg18")
    for m in sums:
        print(f"{m} | {sums[m] / counts[m]:.4f} | {wins.get(m, 0)}/{counts[m]}")


if __name__ == "__main__":
    main()
