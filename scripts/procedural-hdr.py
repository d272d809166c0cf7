#!/usr/bin/env python3
"""Writes a procedural equirect HDR (Radiance .hdr, RGBE): a sky gradient, a 1e5 sun, a ground
with texture detail at every scale. For the speed bench (no big files committed).
Usage: procedural-hdr.py WIDTH OUT.hdr (height = width/2)."""
import sys

import numpy as np


def main():
    w = int(sys.argv[1])
    h = w // 2
    out = sys.argv[2]
    # Rows in blocks so an 8k map stays a few hundred MB.
    with open(out + ".tmp", "wb") as f:
        f.write(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n")
        f.write(f"-Y {h} +X {w}\n".encode())
        sun = np.array([0.4, 0.55, 0.73])
        sun /= np.linalg.norm(sun)
        phi = (np.arange(w) + 0.5) / w * 2 * np.pi - np.pi
        for j0 in range(0, h, 256):
            j1 = min(h, j0 + 256)
            theta = (np.arange(j0, j1) + 0.5) / h * np.pi
            th, ph = np.meshgrid(theta, phi, indexing="ij")
            x, y, z = np.sin(th) * np.sin(ph), np.cos(th), -np.sin(th) * np.cos(ph)
            up = np.clip(y, 0, 1)
            rgb = np.stack([0.3 + 0.5 * up, 0.45 + 0.6 * up, 0.8 + 1.0 * up], -1)
            # Ground: detail at many scales (a city/forest floor).
            ground = y < 0
            detail = 0.5 + 0.25 * np.sin(40 * ph) * np.sin(40 * th) + 0.25 * np.sin(313 * ph + 7 * th)
            detail *= 0.5 + 0.5 * np.sin(w / 8 * ph) ** 2
            for c, k in enumerate([0.12, 0.1, 0.07]):
                rgb[..., c] = np.where(ground, k * detail, rgb[..., c])
            # Sun: 0.5° disc of 1e5 with a soft aureole.
            cosang = x * sun[0] + y * sun[1] + z * sun[2]
            ang = np.arccos(np.clip(cosang, -1, 1))
            rgb += (1e5 * (ang < 0.0045) + 30.0 * np.exp(-ang / 0.05))[..., None] * np.array([1.0, 0.9, 0.75])
            # RGBE encode.
            m = rgb.max(-1)
            e = np.ceil(np.log2(np.maximum(m, 1e-32)))
            e = np.where(m < 1e-32, -128, e)
            scale = np.where(m < 1e-32, 0, 256.0 / np.exp2(e))
            mant = np.clip(np.floor(rgb * scale[..., None]), 0, 255).astype(np.uint8)
            ex = np.where(m < 1e-32, 0, e + 128).astype(np.uint8)
            f.write(np.concatenate([mant, ex[..., None]], -1).tobytes())
    import os

    os.replace(out + ".tmp", out)


if __name__ == "__main__":
    main()
