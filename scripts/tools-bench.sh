#!/usr/bin/env bash
# Whole-process CPU, wall and peak memory of each tool's usual job, as a new user would run it:
# the figures the README's "Accuracy and speed" table quotes, regenerated and dated in
# bench/tools.md. (The default bake against a base build is scripts/speed-bench.sh.)
# Usage: scripts/tools-bench.sh [--quick]   (RUNS=N runs per job, default 7; --quick: 1)
# CPU = user + sys of the process (/usr/bin/time), medians over runs that alternate between the
# jobs; peak = the largest max RSS. Every run writes into a fresh folder of its own under
# target/tools-bench, which the script alone writes and removes.
set -euo pipefail
cd "$(dirname "$0")/.."
runs=${RUNS:-7}
[ "${1:-}" = "--quick" ] && runs=1
cargo build --release -q -p equirect-to-cube -p irradiance -p brdf-lut -p hv-lut -p tpr-map \
	-p quat-map -p shexp-fit
work=target/tools-bench
mkdir -p "$work"
# The 1024×512 city.exr of the shared fixtures when this machine has them (the inputs the
# issues measured), else the repository's own (city_512 is 512×256).
fx=fixtures/hdri
[ -d /work/shared/fixtures/hdri ] && [ -z "${LOCAL_FIXTURES:-}" ] && fx=/work/shared/fixtures/hdri
export runs work fx
python3 - <<'PY'
import datetime, os, shutil, statistics, struct, subprocess, zlib

runs, work, fx = int(os.environ["runs"]), os.environ["work"], os.environ["fx"]
bin_dir = "target/release"
city = os.path.join(fx, "city.exr") if os.path.exists(os.path.join(fx, "city.exr")) else "fixtures/hdri/city_512.exr"
city_name = os.path.basename(city)


def png16(path, size):
    """A 16-bit RGB normal map of size² texels (bumps at several scales), written once."""
    if os.path.exists(path):
        return
    import math
    rows = []
    for j in range(size):
        v = (j + 0.5) / size
        row = bytearray([0])
        for i in range(size):
            u = (i + 0.5) / size
            x = 0.4 * math.sin(12 * math.pi * u) * math.cos(5 * math.pi * v)
            y = 0.3 * math.cos(31 * math.pi * v + 3 * u)
            n = math.sqrt(x * x + y * y + 1)
            for c in (x / n, y / n, 1 / n):
                row += struct.pack(">H", int(round((c * 0.5 + 0.5) * 65535)))
        rows.append(bytes(row))
    raw = b"".join(rows)
    def chunk(t, d):
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xFFFFFFFF)
    data = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", size, size, 16, 2, 0, 0, 0))
    data += chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b"")
    with open(path + ".tmp", "wb") as f:
        f.write(data)
    os.replace(path + ".tmp", path)


normal = os.path.join(work, "normal_1024.png")
png16(normal, 1024)


def out(name):
    d = os.path.join(work, "out", name)
    shutil.rmtree(d, ignore_errors=True)
    os.makedirs(d)
    return d


# The face folder the irradiance job reads (made once, by equirect-to-cube).
faces = os.path.join(work, "faces_256_" + city_name.split(".")[0])
if not os.path.isdir(faces):
    subprocess.run([f"{bin_dir}/equirect-to-cube", city, "-o", faces, "--size", "256", "-q"], check=True)

jobs = [
    ("equirect-to-cube", f"{city_name} → 256² faces (EXR)",
     lambda o: ["equirect-to-cube", city, "-o", o, "--size", "256"]),
    ("irradiance --from-sh", "3-band SH + 32² E/π cube from a 6×256² face folder",
     lambda o: ["irradiance", faces, "-o", o, "--from-sh"]),
    ("irradiance", "city_512.exr (512×256) → SH + the exact 32² E/π cube (the gltf default)",
     lambda o: ["irradiance", "fixtures/hdri/city_512.exr", "-o", o]),
    ("brdf-lut dfg", "128², 1024 samples (defaults)",
     lambda o: ["brdf-lut", "dfg", "-o", os.path.join(o, "dfg.exr")]),
    ("brdf-lut as-size-bias", "n_u 10, n_v 1000 at the default 64², 1024 samples",
     lambda o: ["brdf-lut", "as-size-bias", "--nu", "10", "--nv", "1000", "-o", os.path.join(o, "as.exr")]),
    ("hv-lut", "n_u 10, n_v 1000 at the default 256²",
     lambda o: ["hv-lut", "--nu", "10", "--nv", "1000", "-o", os.path.join(o, "hv.exr")]),
    ("tpr-map", "1024², radial preset, 16-bit PNG",
     lambda o: ["tpr-map", "-o", os.path.join(o, "tpr.png"), "--size", "1024", "--preset", "radial:0.5,0.5", "--roughness", "0.2,0.6"]),
    ("quat-map", "1024² 16-bit PNG normal map → 16-bit PNG",
     lambda o: ["quat-map", normal, "-o", os.path.join(o, "q.png")]),
    ("shexp-fit", f"{city_name}, defaults (16,384 rows × 1024 samples)",
     lambda o: ["shexp-fit", city, "-o", os.path.join(o, "c.json")]),
    ("shexp-fit --alpha-knots 0.2,1", f"{city_name}",
     lambda o: ["shexp-fit", city, "-o", os.path.join(o, "c.json"), "--alpha-knots", "0.2,1"]),
]

res = {name: [] for name, _, _ in jobs}
for r in range(runs):
    for k, (name, _, cmd) in enumerate(jobs):
        o = out(f"job{k}")
        argv = cmd(o)
        argv[0] = os.path.join(bin_dir, argv[0])
        p = subprocess.run(["/usr/bin/time", "-f", "%U %S %M %e", *argv, "-q"], capture_output=True, text=True)
        if p.returncode != 0:
            raise SystemExit(f"{' '.join(argv)}: exit {p.returncode}: {p.stderr.strip()}")
        u, s, m, e = p.stderr.strip().splitlines()[-1].split()
        res[name].append((float(u) + float(s), float(e), float(m) / 1024))
        shutil.rmtree(o)

date = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d")
load = os.getloadavg()[0]
lines = [
    "## Tools, whole processes",
    "",
    f"Generated by `scripts/tools-bench.sh` on {date} ({os.cpu_count()} cores, load average {load:.2f} at the end): "
    f"each tool's usual job run as a new user runs it (`-q`, a fresh output folder), {runs} run(s) each, "
    "alternating between the jobs; CPU = user + sys seconds of the process, medians; wall = medians; "
    "peak = the largest max RSS (`/usr/bin/time`, which counts in steps of 10 ms). Reading the input and "
    "writing the files are included. "
    "The default bake's figures are in `bench/speed.md`.",
    "",
    "| tool | job | CPU s | wall s | peak MiB |",
    "|---|---|---:|---:|---:|",
]
for name, job, _ in jobs:
    v = res[name]
    lines.append(f"| `{name}` | {job} | {statistics.median(x[0] for x in v):.3f} | "
                 f"{statistics.median(x[1] for x in v):.3f} | {max(x[2] for x in v):.0f} |")
with open("bench/tools.md.tmp", "w") as f:
    f.write("\n".join(lines) + "\n")
os.replace("bench/tools.md.tmp", "bench/tools.md")
print("wrote bench/tools.md")
PY
