#!/usr/bin/env python3
"""Independent numpy recomputation of `aniso-eval` pixels (issue 23: "an independent
implementation of the truth and of the major-axis method recomputes a sample of the cases").

    pip install numpy flip-evaluator      # flip-evaluator only to read the EXR files
    aniso-eval ENV --out R --methods major-16 --lookup oracle ...   # GGX cases, per-case files on
    python3 bench/crosscheck/aniso_crosscheck.py R [--every 7]

For every k-th shaded pixel of every GGX case, from the report folder alone (case.json: frame,
view, material; env_<name>_{radiance,direction,solid_angle}.exr: the truth's environment as a
texel list; dfg.exr):
- the truth E0 by exact texel summation of D·G2/(4 n·v)·L·Ω (anisotropic GGX, Heitz 2014
  eqs. 85/86, height-correlated Smith), compared with truth_e0.exr within 4 standard errors
  + 2% (the texel-centre quadrature);
- Cocco et al. 2024's major-axis method (App. A-D, eqs. 5-10), written again here from the
  paper, with the exact prefiltering kernel D(n·h)·max(n·l, 0), h = normalize(n + l), summed
  over every texel at √r_s, times A+B of the DFG table at (n·v, r): compared with
  major-16_oracle_e0.exr (the Rust oracle sums the same kernel hierarchically).

Measured (interior_256, 16² spheres, spiral tangents, r 0.4-1, η ±0.5/0.8, every 9th pixel):
the major axis agrees to 4.0e-3-7.4e-3 relative everywhere; the truth passes at 2^18 samples
(48 pixels, worst 0.34 of the tolerance) but not at 8192 (worst 2.6-3.2): where a few bright
texels (interior's lamps) carry the integral, 16 batch means under-estimate the error of a
small sample (5σ deviations, the MC below the texel sum). See docs/ANISOTROPY.md.
"""
import argparse
import json
import os
import sys

import flip_evaluator as flip
import numpy as np


def ggx_lambda(w, ax, ay):
    a = (ax * ax * w[..., 0] ** 2 + ay * ay * w[..., 1] ** 2) / np.maximum(w[..., 2] ** 2, 1e-30)
    return 0.5 * (np.sqrt(1 + a) - 1)


def truth_e0(v, ls, lw, ax, ay):
    """v local (3,), ls local texel directions (M,3), lw = L·Ω (M,3)."""
    ok = ls[:, 2] > 0
    l = ls[ok]
    h = l + v
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    t = (h[:, 0] / ax) ** 2 + (h[:, 1] / ay) ** 2 + h[:, 2] ** 2
    d = 1.0 / (np.pi * ax * ay * t * t)
    g2 = 1.0 / (1.0 + ggx_lambda(v[None, :], ax, ay) + ggx_lambda(l, ax, ay))
    g2 = np.where((h @ v > 0) & (np.einsum("ij,ij->i", h, l) > 0), g2, 0.0)
    f = d * g2 / (4 * v[2])
    return (f[:, None] * lw[ok]).sum(axis=0)


def normal_at(rx, ry, t):
    m = np.array([-rx * np.cos(t), -ry * np.sin(t), 1.0])
    return m / np.linalg.norm(m)


def refl(o, m):
    return 2 * np.dot(m, o) * m - o


def nlerp(a, b, t):
    w = (1 - t) * a + t * b
    n = np.linalg.norm(w)
    return w / n if n > 0 else a


def major_axis(o, su, sv, n_taps=16, beta=2.3, k=1.0):
    """Cocco et al. 2024 App. A-D and eq. 10, in the ellipse frame (U = t, V = b)."""
    rx, ry = k * su, k * sv
    ox, oy = o[0], o[1]
    p0 = 2 * ox * oy * rx * ry
    p1 = ox * ox * (rx * rx * ry * ry + ry * ry) - oy * oy * (rx * rx * ry * ry + rx * rx) + rx * rx - ry * ry
    p2 = -p0 * (ry * ry + 1)
    p3 = p0 * p2 * (rx * rx + 1)
    root = np.sqrt(max(p1 * p1 - p3, 0.0))
    if p2 != 0:
        t0 = np.arctan((p1 + root) / p2)
        t1 = np.arctan((p1 - root) / p2)
    else:
        t0 = np.pi / 2 if p1 >= 0 else 0.0
        t1 = t0 + np.pi / 2
    top0, top1 = normal_at(rx, ry, t1), normal_at(rx, ry, t1 + np.pi)
    q0 = top1[0] * o[0] + top1[1] * o[1]
    q1 = o[2] * (1 - top1[2] ** 2)
    if q1 > 1e-12:
        r = np.sqrt(max(q0 * q0 + o[2] * q1, 0.0))
        tau0 = 0.5 + top1[2] * (q0 - r) / (2 * q1)
        tau1 = 0.5 + top1[2] * (q0 + r) / (2 * q1)
    else:
        tau0, tau1 = 0.0, 1.0
    tc0, tc1 = np.clip(tau0, 0, 1), np.clip(tau1, 0, 1)
    c0, c1 = nlerp(top0, top1, tc0), nlerp(top0, top1, tc1)
    delta = tc0 * (t0 - t1) if tc0 > 0 else (tc1 - 1) * (t0 - t1)
    b0, b1 = normal_at(rx, ry, t0 + delta), normal_at(rx, ry, t0 - delta + np.pi)
    width = np.linalg.norm(refl(o, b0) - refl(o, b1))
    major = np.linalg.norm(refl(o, c0) - refl(o, c1))
    zeta = np.clip((major - width) / major, 0, 1) if major > 0 else 0.0
    centre = nlerp(c0, c1, 0.5)
    e0, e1 = nlerp(centre, c0, zeta), nlerp(centre, c1, zeta)
    taps = [refl(o, nlerp(e0, e1, j / (n_taps - 1) if n_taps > 1 else 0.5)) for j in range(n_taps)]
    rs = max(width / (2 * k), beta * major / (2 * n_taps))
    return taps, min(np.sqrt(max(rs, 0.0)), 1.0)


def prefiltered(d, r, dirs, rad, sa):
    """The exact chain kernel at roughness r in world direction d (n = v = d)."""
    a2 = max(r * r, 1e-4) ** 2
    nl = dirs @ d
    h = dirs + d
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    nh = h @ d
    t = nh * nh * (a2 - 1) + 1
    kern = a2 / (np.pi * t * t) * np.maximum(nl, 0) * sa
    return (kern[:, None] * rad).sum(axis=0) / kern.sum()


def dfg_ab(tab, nv, r):
    h, w = tab.shape[:2]
    x = np.clip(np.clip(nv, 0, 1) * w - 0.5, 0, w - 1)
    y = np.clip(np.clip(r, 0, 1) * h - 0.5, 0, h - 1)
    x0, y0 = int(np.floor(x)), int(np.floor(y))
    x1, y1 = min(x0 + 1, w - 1), min(y0 + 1, h - 1)
    fx, fy = x - x0, y - y0
    top = tab[y0, x0] * (1 - fx) + tab[y0, x1] * fx
    bot = tab[y1, x0] * (1 - fx) + tab[y1, x1] * fx
    ab = top * (1 - fy) + bot * fy
    return ab[0], ab[1]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("report")
    ap.add_argument("--every", type=int, default=7)
    a = ap.parse_args()
    dfg = flip.load(os.path.join(a.report, "dfg.exr")).astype(np.float64)
    envs = {}
    worst_t, worst_m, n_t, n_m = 0.0, 0.0, 0, 0
    for c in sorted(d for d in os.listdir(a.report) if d.startswith("case")):
        d = os.path.join(a.report, c)
        meta = json.load(open(os.path.join(d, "case.json")))
        mat = meta["case"]["material"]
        if "Ggx" not in mat:
            continue
        ax, ay = mat["Ggx"]["alpha_t"], mat["Ggx"]["alpha_b"]
        env = meta["case"]["env"]
        if env not in envs:
            load = lambda k: flip.load(os.path.join(a.report, f"env_{env}_{k}.exr")).reshape(-1, 3).astype(np.float64)
            envs[env] = (load("radiance"), load("direction"), load("solid_angle")[:, 0])
        rad, dirs, sa = envs[env]
        lw = rad * sa[:, None]
        # The texel sum is the midpoint rule of the piecewise-constant cube: valid only when the
        # lobe spans several texels (min α ≥ 4 texel angles, docs/ANISOTROPY.md).
        face = int(round(np.sqrt(len(sa) / 6)))
        texel_angle = (np.pi / 2) / face
        check_truth = min(ax, ay) >= 4 * texel_angle
        s = meta["sphere_size"]
        t_e0 = flip.load(os.path.join(d, "truth_e0.exr")).astype(np.float64)
        t_se = flip.load(os.path.join(d, "truth_se0.exr")).astype(np.float64)
        mpath = os.path.join(d, "major-16_oracle_e0.exr")
        m_e0 = flip.load(mpath).astype(np.float64) if os.path.exists(mpath) else None
        for p in meta["pixels"][:: a.every]:
            fr = p["frame"]
            t, b, n = (np.array(fr[k], dtype=np.float64) for k in ("t", "b", "n"))
            v = np.array(p["v"], dtype=np.float64)
            basis = np.stack([t, b, n])
            vl = basis @ v
            i, j = p["idx"] % s, p["idx"] // s
            if check_truth:
                mine = truth_e0(vl, dirs @ basis.T, lw, ax, ay)
                theirs, se = t_e0[j, i], t_se[j, i]
                err = np.abs(mine - theirs) / np.maximum(0.02 * mine + 4 * se, 1e-12)
                worst_t = max(worst_t, err.max())
                n_t += 1
            if m_e0 is not None:
                taps, r = major_axis(vl / np.linalg.norm(vl), ax / np.sqrt(2), ay / np.sqrt(2))
                lbar = np.mean([prefiltered(basis.T @ tp / np.linalg.norm(tp), r, dirs, rad, sa) for tp in taps], axis=0)
                r_iso = np.sqrt(0.5 * (ax + ay))
                A, B = dfg_ab(dfg, float(n @ v), r_iso)
                est = lbar * (A + B)
                rel = np.abs(est - m_e0[j, i]) / np.maximum(np.abs(est), 1e-6)
                worst_m = max(worst_m, rel.max())
                n_m += 1
        print(f"{c} (α {ax:.3f} × {ay:.3f}): {len(meta['pixels'][:: a.every])} pixels"
              f"{'' if check_truth else ', truth not checked (lobe under 4 texels)'}")
    print(f"truth: {n_t} pixels, worst |numpy − report| / (2% + 4 se) = {worst_t:.3f} (≤ 1 passes)")
    if n_m:
        print(f"major-16 oracle: {n_m} pixels, worst relative difference {worst_m:.2e}")
    sys.exit(0 if worst_t <= 1.0 and (n_m == 0 or worst_m < 0.01) else 1)


if __name__ == "__main__":
    main()
