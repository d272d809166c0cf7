#!/usr/bin/env python3
"""Compares the `runtime` blocks of two prefilter.json files (the error the target's lookup sees,
per roughness): prints the largest difference in percentage points and exits 1 when it exceeds
the tolerance (default 0.1 point). Usage: runtime-compare.py BASE.json NEW.json [--tol 0.1]"""
import json
import sys


def runtime(path):
    with open(path) as f:
        d = json.load(f)
    # Accept both the sidecar and the CLI's --json summary.
    if "details" in d:
        d = d["details"]["report"]
    r = d.get("runtime")
    if not r:
        sys.exit(f"{path}: no runtime block")
    return r["roughness"], r["mean_abs_rel"]


def main():
    args = sys.argv[1:]
    tol = 0.1
    if "--tol" in args:
        i = args.index("--tol")
        tol = float(args[i + 1])
        del args[i : i + 2]
    if len(args) != 2:
        sys.exit(__doc__)
    (ra, ea), (rb, eb) = runtime(args[0]), runtime(args[1])
    if ra != rb:
        sys.exit(f"roughness grids differ: {args[0]} vs {args[1]}")
    worst = (0.0, 0.0)
    for r, a, b in zip(ra, ea, eb):
        d = 100.0 * (b - a)
        if abs(d) > abs(worst[1]):
            worst = (r, d)
    mean_a = 100.0 * sum(ea) / len(ea)
    mean_b = 100.0 * sum(eb) / len(eb)
    ok = abs(worst[1]) <= tol
    print(
        f"runtime error: mean {mean_a:.3f}% -> {mean_b:.3f}%, largest change {worst[1]:+.3f} points at r = {worst[0]:.4f} ({'ok' if ok else 'FAIL'}, tolerance {tol})"
    )
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
