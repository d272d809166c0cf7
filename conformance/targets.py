"""Engine targets as the engines' loaders read them (`make conformance`, after containers.py).

- libktx loads Filament's KTX1 (R11F_G11F_B10F cube, cmgen's level count) and finds cmgen's `sh`
  metadata: 9 lines of 3 numbers, equal to the irradiance bake's sh.txt for the same
  environment (up to the 6 significant digits cmgen prints and the chain's resolution);
- libktx loads Bevy's KTX2 (RGB9E5 + zstd) and glTF's KTX2 (RGBA16F) with their levels;
- the list of files and formats Bevy's own loader (conformance/bevy) is then run on.

Usage: targets.py TARGETS_DIR BAKES_DIR  → prints checks, writes TARGETS_DIR/bevy-args.txt.
"""

import ctypes
import json
import re
import sys
from pathlib import Path

import containers as c


def ktx_metadata(lib, st, key):
    lib.ktxHashList_FindValue.argtypes = [ctypes.c_void_p, ctypes.c_char_p, ctypes.POINTER(ctypes.c_uint), ctypes.POINTER(ctypes.c_void_p)]
    head = ctypes.addressof(st) + c.KtxBase.kvDataHead.offset
    n = ctypes.c_uint()
    p = ctypes.c_void_p()
    if lib.ktxHashList_FindValue(head, key.encode(), ctypes.byref(n), ctypes.byref(p)) != 0:
        return None
    return ctypes.string_at(p, n.value)


def main():
    tdir, bakes = Path(sys.argv[1]).resolve(), Path(sys.argv[2]).resolve()
    lib = c.load_libktx()
    levels = {t: json.loads((tdir / t / "prefilter.json").read_text())["levels"] for t in ("gltf", "bevy", "filament", "unity")}

    # Filament: KTX1 + sh metadata, as cmgen writes and Filament's KtxBundle reads.
    data = (tdir / "filament" / "env_ibl.ktx").read_bytes()
    st, tex = c.libktx_load(lib, data)
    c.check(isinstance(st, c.Ktx1) and st.glInternalformat == c.GL["b10g11r11"] and st.isCubemap and st.numLevels == levels["filament"],
            f"filament env_ibl.ktx: libktx loads a KTX1 R11F_G11F_B10F cube of {st.numLevels} levels")
    sh = ktx_metadata(lib, st, "sh")
    rows = [[float(x) for x in line.split()] for line in sh.decode().strip("\0").strip().splitlines()] if sh else []
    c.check(len(rows) == 9 and all(len(r) == 3 for r in rows), f"filament env_ibl.ktx: libktx finds the `sh` metadata ({len(rows)} lines)")
    txt = (tdir / "filament-irr" / "sh.txt").read_text()
    ref = [[float(x) for x in re.findall(r"-?\d+\.\d+(?:e-?\d+)?", line)[:3]] for line in txt.strip().splitlines()]
    scale = max(abs(v) for r in ref for v in r)
    worst = max(abs(a - b) for ra, rb in zip(rows, ref) for a, b in zip(ra, rb)) / scale if len(rows) == 9 else 1.0
    c.check(worst < 0.01, f"filament: KTX `sh` metadata = irradiance --target filament sh.txt within {worst:.2e} of the largest coefficient")
    lib.ktxTexture1_Destroy(tex)

    for t, name, fmt in (("bevy", "specular_rgb9e5_zstd.ktx2", "rgb9e5"), ("gltf-ktx2", "prefilter.ktx2", "rgba16f")):
        data = (tdir / t / name).read_bytes()
        st, tex = c.libktx_load(lib, data)
        want = levels["bevy" if t == "bevy" else "gltf"]
        c.check(isinstance(st, c.Ktx2) and st.vkFormat == c.VK[fmt] and st.isCubemap and st.numLevels == want,
                f"{t} {name}: libktx loads a KTX2 {fmt} cube of {st.numLevels} levels")
        lib.ktxTexture2_Destroy(tex)

    # What Bevy's own loader is run on: the Bevy target's files and the whole KTX2/DDS matrix.
    args = [f"{tdir / 'bevy' / 'specular_rgb9e5_zstd.ktx2'}:rgb9e5:{levels['bevy']}",
            f"{tdir / 'bevy-irr' / 'diffuse_rgb9e5_zstd.ktx2'}:rgb9e5:1",
            f"{tdir / 'bevy-cube' / 'skybox_rgb9e5_zstd.ktx2'}:rgb9e5:1"]
    for p in sorted(bakes.glob("prefilter/*/prefilter.ktx2")) + sorted(bakes.glob("prefilter/*/prefilter.dds")):
        fmt = p.parent.name.split("-")[-1]
        n = len(json.loads((p.parent / "prefilter.json").read_text())["level"])
        args.append(f"{p}:{fmt}:{n}")
    (tdir / "bevy-args.txt").write_text("\n".join(args) + "\n")
    print(f"targets: {c.passed} passed, {c.failed} failed")
    sys.exit(1 if c.failed else 0)


if __name__ == "__main__":
    main()
