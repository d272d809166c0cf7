"""Independent cross-check of Silvennoinen et al. 2025 §5.1 (SH-exp vs split-sum) in numpy.

Written apart from the Rust crates (own SH basis by Legendre recursion, own GGX/Smith, ground
truth by summation over an equirect grid, an *ideal* split-sum prefiltered at the exact α with no
mip interpolation, random rather than Fibonacci rows, exact E0) to check that the low win rate
of one eq. 11 probe, and the gain of coefficients linear in α (`--alpha-knots`), are properties
of the model and not of our pipeline. Both fits here are plain log-space least squares (eq. 13).

    pip install numpy && python3 bench/crosscheck/shexp_crosscheck.py > bench/crosscheck/shexp.md

Environment: the bench's held-out `sunsky` (a 2e4 sun of 3.6° over a gradient sky), here on a
128×64 equirect grid, 8×8 supersampled. Not run by `make test` (numpy is not a dependency).
"""
import numpy as np, sys, math
rng = np.random.default_rng(1)
W = 128
H = W // 2

def env_dirs(W, H):
    # equirect: u -> phi, v -> theta (y up); DESIGN-independent since everything is computed here
    j, i = np.meshgrid(np.arange(H), np.arange(W), indexing="ij")
    phi = (i + 0.5) / W * 2 * np.pi - np.pi
    theta = (j + 0.5) / H * np.pi
    d = np.stack([np.sin(theta) * np.sin(phi), np.cos(theta), -np.sin(theta) * np.cos(phi)], -1)
    dw = (2 * np.pi / W) * (np.pi / H) * np.sin(theta)
    return d, dw

SUN = np.array([0.3, 0.5, -0.6]); SUN /= np.linalg.norm(SUN)
def sunsky(d, super_=4):
    y = d[..., 1]
    sky = np.where(y[..., None] > 0, np.stack([0.3 + 0.5 * (1 - y), 0.5 + 0.4 * (1 - y), np.ones_like(y)], -1),
                   np.array([0.25, 0.2, 0.15]))
    s = np.where(d @ SUN > 0.9995, 2e4, 0.0)[..., None] * np.array([1, 0.95, 0.85])
    return sky + s

def build_env(W, H, ss=8):
    # supersampled texel averages so the tiny sun keeps its power
    d, dw = env_dirs(W, H)
    acc = np.zeros(d.shape)
    for a in range(ss):
        for b in range(ss):
            jj, ii = np.meshgrid(np.arange(H), np.arange(W), indexing="ij")
            phi = (ii + (a + 0.5) / ss) / W * 2 * np.pi - np.pi
            th = (jj + (b + 0.5) / ss) / H * np.pi
            dd = np.stack([np.sin(th) * np.sin(phi), np.cos(th), -np.sin(th) * np.cos(phi)], -1)
            acc += sunsky(dd) * np.sin(th)[..., None]
    wsum = sum(np.sin(((np.arange(H)[:, None] + (b + 0.5) / ss) / H * np.pi)) for b in range(ss)) * ss
    L = acc / wsum[..., None]
    return d.reshape(-1, 3), dw.reshape(-1), L.reshape(-1, 3)

def d_ggx(nh, a):
    a2 = a * a
    t = nh * nh * (a2 - 1) + 1
    return a2 / (np.pi * t * t)

def v_smith(nv, nl, a):
    a2 = a * a
    gv = nl * np.sqrt(nv * nv * (1 - a2) + a2)
    gl = nv * np.sqrt(nl * nl * (1 - a2) + a2)
    return 0.5 / np.maximum(gv + gl, 1e-12)

def e01(n, v, a, D, dw, L):
    """Exact E0, E1 for arrays n, v (k,3) by summation over env texels."""
    out0 = np.zeros((len(n), 3)); out1 = np.zeros((len(n), 3))
    for s in range(0, len(n), 256):
        nn, vv = n[s:s+256], v[s:s+256]
        aa = a[s:s+256] if np.ndim(a) else a
        aa = np.asarray(aa)[..., None] if np.ndim(aa) else aa
        nl = nn @ D.T
        nv = np.sum(nn * vv, -1)[:, None]
        h = vv[:, None, :] + D[None, :, :]
        h /= np.linalg.norm(h, axis=-1, keepdims=True)
        nh = np.einsum("kd,ktd->kt", nn, h)
        vh = np.einsum("kd,ktd->kt", vv, h)
        f = d_ggx(nh, aa) * v_smith(np.maximum(nv, 1e-6), np.maximum(nl, 0), aa) * np.maximum(nl, 0) * dw
        f = np.where(nl > 0, f, 0)
        out0[s:s+256] = f @ L
        out1[s:s+256] = (f * (1 - np.clip(vh, 0, 1)) ** 5) @ L
    return out0, out1

def sh_basis(d, order):
    # real SH up to band `order` via associated Legendre recursion (any orthonormal real basis works)
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    ct = z; st = np.sqrt(np.maximum(0, 1 - z * z)); ph = np.arctan2(y, x)
    cols = []
    from math import factorial
    for l in range(order + 1):
        for m in range(-l, l + 1):
            am = abs(m)
            # P_l^m(ct)
            pmm = np.ones_like(ct)
            for k in range(1, am + 1):
                pmm = pmm * (-(2 * k - 1)) * st
            if l == am:
                plm = pmm
            else:
                pm1 = ct * (2 * am + 1) * pmm
                if l == am + 1:
                    plm = pm1
                else:
                    p0, p1 = pmm, pm1
                    for ll in range(am + 2, l + 1):
                        p0, p1 = p1, ((2 * ll - 1) * ct * p1 - (ll + am - 1) * p0) / (ll - am)
                    plm = p1
            K = math.sqrt((2 * l + 1) / (4 * np.pi) * factorial(l - am) / factorial(l + am))
            if m == 0:
                cols.append(K * plm)
            elif m > 0:
                cols.append(math.sqrt(2) * K * plm * np.cos(m * ph))
            else:
                cols.append(math.sqrt(2) * K * plm * np.sin(am * ph))
    return np.stack(cols, -1)

def band_of(order):
    return np.concatenate([[l] * (2 * l + 1) for l in range(order + 1)])

def hat(knots, a):
    """Linear interpolation weights of the knots at α (clamped), one row per α."""
    a = np.clip(np.asarray(a, float), knots[0], knots[-1])
    w = np.zeros((a.size, len(knots)))
    for s in range(len(knots) - 1):
        lo, hi = knots[s], knots[s + 1]
        m = (a >= lo) & (a <= hi) if s == 0 else (a > lo) & (a <= hi)
        t = (a[m] - lo) / (hi - lo)
        w[m, s] = 1 - t
        w[m, s + 1] = t
    return w

def features(n, v, a, PO=4, QO=2):
    r = 2 * np.sum(n * v, -1, keepdims=True) * n - v
    hr = n + r; hr /= np.linalg.norm(hr, axis=-1, keepdims=True)
    a = np.broadcast_to(np.asarray(a, float), (len(n),))[:, None]
    bp = band_of(PO); bq = band_of(QO)[1:]
    fp = sh_basis(r, PO) * np.exp(-bp * (bp + 1) * a / 2)
    fq = sh_basis(hr, QO)[:, 1:] * np.exp(-bq * (bq + 1) * a / 2)
    return np.concatenate([fp, fq], -1)

def unit(x): return x / np.linalg.norm(x, axis=-1, keepdims=True)

def fib(k):
    i = np.arange(k) + 0.5
    z = 1 - 2 * i / k; ph = np.pi * (1 + 5 ** 0.5) * i
    s = np.sqrt(1 - z * z)
    return np.stack([s * np.cos(ph), s * np.sin(ph), z], -1)

D, dw, L = build_env(W, H)

# ---- fit (eq. 13-14, plain log LS, exact E0) ----
NN, NV = 32, 32
alphas = [0.2, 0.4667, 0.7333, 1.0]
ns = unit(rng.normal(size=(NN * NV * len(alphas), 3)))
vs = unit(rng.normal(size=ns.shape)); vs = np.where(np.sum(vs * ns, -1, keepdims=True) < 0, -vs, vs)
As = np.repeat(alphas, NN * NV)
rng.shuffle(As)
E0, _ = e01(ns, vs, As, D, dw, L)
F = features(ns, vs, As)
floor = 1e-4 * (L * dw[:, None]).sum(0) / (4 * np.pi)
Y = np.log(np.maximum(E0, floor))
coef, *_ = np.linalg.lstsq(F, Y, rcond=None)
KNOTS = [0.2, 1.0]
Wk = hat(KNOTS, As)
Fk = np.concatenate([F * Wk[:, k:k + 1] for k in range(len(KNOTS))], -1)
coef_k, *_ = np.linalg.lstsq(Fk, Y, rcond=None)
def refine(A, x0, E, w, groups, iters=30):
    """Gauss-Newton on sum_g sum_r w_r (exp(A x) - E)^2 / sum_{r in g} w_r E^2 (per channel)."""
    x = x0.copy()
    for c in range(E.shape[1]):
        om = w.copy()
        for g in np.unique(groups):
            m = groups == g
            om[m] /= np.sum(w[m] * E[m, c] ** 2)
        so = np.sqrt(om)
        f = lambda xc: np.sum(om * (np.exp(np.minimum(A @ xc, 300)) - E[:, c]) ** 2)
        xc = x[:, c].copy()
        fx = f(xc)
        for _ in range(iters):
            e = np.exp(np.minimum(A @ xc, 300))
            J = (so * e)[:, None] * A
            step, *_ = np.linalg.lstsq(J, -so * (e - E[:, c]), rcond=None)
            t = 1.0
            while t > 1e-4 and f(xc + t * step) >= fx:
                t *= 0.5
            if t <= 1e-4:
                break
            xc = xc + t * step
            fn = f(xc)
            done = fx - fn < 1e-6 * fx
            fx = fn
            if done:
                break
        x[:, c] = xc
    return x

nv_rows = np.sum(ns * vs, -1)
coef_r = refine(F, coef, E0, nv_rows, As)
coef_kr = refine(Fk, coef_k, E0, nv_rows, As)
log_rms = np.sqrt(np.mean((F @ coef - Y) ** 2))
log_rms_k = np.sqrt(np.mean((Fk @ coef_k - Y) ** 2))

def shexp_e0(n, v, a, x):
    return np.exp(features(n, v, a) @ x)

def knots_e0(n, v, a, xk):
    w = hat(KNOTS, [a])[0]
    c = sum(w[k] * xk[k * F.shape[1]:(k + 1) * F.shape[1]] for k in range(len(KNOTS)))
    return np.exp(features(n, v, a) @ c)

MODELS = [("eq. 11, log fit", lambda n, v, a: shexp_e0(n, v, a, coef)),
          ("eq. 11, refined", lambda n, v, a: shexp_e0(n, v, a, coef_r)),
          ("knots 0.2, 1, log fit", lambda n, v, a: knots_e0(n, v, a, coef_k)),
          ("knots 0.2, 1, refined", lambda n, v, a: knots_e0(n, v, a, coef_kr))]

# ---- DFG (A, B) table by quadrature over env texels of a fine sphere ----
Dq, dwq = env_dirs(512, 256); Dq = Dq.reshape(-1, 3); dwq = dwq.reshape(-1)
Dq = Dq[:, [0, 2, 1]] * np.array([1, 1, 1])  # z-up for the tangent frame
def dfg(nv, a):
    n = np.array([0, 0, 1.0]); v = np.array([math.sqrt(1 - nv * nv), 0, nv])
    nl = Dq[:, 2]; m = nl > 0
    h = unit(v + Dq); vh = h @ v
    f = d_ggx(h[:, 2], a) * v_smith(nv, np.maximum(nl, 0), a) * np.maximum(nl, 0) * dwq
    f = np.where(m, f, 0)
    return f.sum() - (f * (1 - vh) ** 5).sum(), (f * (1 - vh) ** 5).sum()

# ---- ideal split-sum prefilter at the exact α ----
def prefiltered(rdirs, a):
    out = np.zeros((len(rdirs), 3))
    for s in range(0, len(rdirs), 256):
        rr = rdirs[s:s+256]
        rl = rr @ D.T
        h = unit(rr[:, None, :] + D[None])
        rh = np.einsum("kd,ktd->kt", rr, h)
        w = np.where(rl > 0, d_ggx(rh, a) * rl * dw, 0)
        out[s:s+256] = (w @ L) / w.sum(1, keepdims=True)
    return out

# ---- evaluation: orthographic sphere, horizontal views ----
S = 32
res = []
for view in [0, 90, 180, 270]:
    ph = math.radians(view)
    cam = np.array([math.sin(ph), 0, math.cos(ph)])  # towards the eye
    right = np.array([math.cos(ph), 0, -math.sin(ph)]); up = np.array([0, 1.0, 0])
    jj, ii = np.meshgrid(np.arange(S), np.arange(S), indexing="ij")
    x = (ii + 0.5) / S * 2 - 1; y = 1 - (jj + 0.5) / S * 2
    m = x * x + y * y < 1
    x, y = x[m], y[m]; z = np.sqrt(1 - x * x - y * y)
    n = x[:, None] * right + y[:, None] * up + z[:, None] * cam
    v = np.broadcast_to(cam, n.shape).copy()
    rdir = 2 * np.sum(n * v, -1, keepdims=True) * n - v
    for rough in [0.5, 0.6, 0.7, 0.8, 0.9, 1.0]:
        a = rough * rough
        g0, g1 = e01(n, v, a, D, dw, L)
        e0s = [m(n, v, a) for _, m in MODELS]
        pref = prefiltered(rdir, a)
        nvs = np.sum(n * v, -1)
        AB = np.array([dfg(q, a) for q in np.round(nvs, 3)])
        for mat, f0 in [("chrome", 1.0), ("dielectric", 0.04)]:
            gt = f0 * g0 + (1 - f0) * g1
            ss = pref * (f0 * AB[:, 0:1] + AB[:, 1:2])
            fr = AB[:, 1:2] / (AB[:, 0:1] + AB[:, 1:2])
            mse_ss = np.mean((ss - gt) ** 2)
            ratios = [np.mean((e * (f0 + (1 - f0) * fr) - gt) ** 2) / mse_ss for e in e0s]
            res.append((rough, ratios))
            print(f"view {view:3} r {rough:.1f} {mat:10} ratios {np.round(ratios, 3)}", file=sys.stderr, flush=True)

print("# Independent numpy cross-check of SH-exp vs split-sum (`sunsky`)\n")
print(f"`bench/crosscheck/shexp_crosscheck.py`: {W}×{H} equirect ground truth, ideal split-sum (prefiltered at the exact α), {len(ns)} rows ({NN * NV} (n, v) pairs × α = {alphas}), exact E0, plain log-space least squares; log RMS residual eq. 11 {log_rms:.3f}, knots {KNOTS} {log_rms_k:.3f}. Orthographic 32² spheres from 4 horizontal views, chrome and F0 = 0.04, E1 by B/(A+B).\n")
print("Wins (MSE below the split-sum's) out of 8 per roughness (2 materials × 4 views), with the geometric-mean MSE ratio SH-exp / split-sum. \"Refined\": Gauss–Newton on the linear error relative per α group, rows weighted by n·v (as `--cosine-weight --log-weight 0`).\n")
print("| r | α | " + " | ".join(f"{name}" for name, _ in MODELS) + " |")
print("|---:|---:|" + "---:|" * len(MODELS))
gm = lambda q: np.exp(np.mean(np.log(q)))
for r in sorted({r for r, _ in res}):
    cells = []
    for mi in range(len(MODELS)):
        q = [rat[mi] for rr, rat in res if rr == r]
        cells.append(f"{sum(x < 1 for x in q)}/{len(q)} ({gm(q):.2f})")
    print(f"| {r:.1f} | {r*r:.2f} | " + " | ".join(cells) + " |")
tot = [sum(rat[mi] < 1 for _, rat in res) for mi in range(len(MODELS))]
print("| **all** | | " + " | ".join(f"**{t}/{len(res)}**" for t in tot) + " |")
