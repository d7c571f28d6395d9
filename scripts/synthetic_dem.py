#!/usr/bin/env python3
"""A fractal height field no sample ships, for measuring on terrain the project has not seen.

    scripts/synthetic_dem.py OUT.png [--size N] [--seed S]

Writes a 16-bit greyscale PNG and its JSON sidecar (the format of samples/dem/): the sum of
octaves of smoothly interpolated value noise (amplitude halving, frequency doubling) with a
ridged octave, which gives valleys, ridges and cliffs at every scale. Pure Python.
"""
import argparse
import json
import math
import random
import struct
import zlib


def noise_grid(n, cells, rng):
    g = [[rng.random() for _ in range(cells + 2)] for _ in range(cells + 2)]

    def at(x, y):
        fx, fy = x * cells / n, y * cells / n
        ix, iy = int(fx), int(fy)
        tx, ty = fx - ix, fy - iy
        sx, sy = tx * tx * (3 - 2 * tx), ty * ty * (3 - 2 * ty)
        a = g[iy][ix] + (g[iy][ix + 1] - g[iy][ix]) * sx
        b = g[iy + 1][ix] + (g[iy + 1][ix + 1] - g[iy + 1][ix]) * sx
        return a + (b - a) * sy

    return at


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--size", type=int, default=384)
    ap.add_argument("--seed", type=int, default=7)
    a = ap.parse_args()
    rng = random.Random(a.seed)
    n = a.size
    octaves = [(noise_grid(n, 2 ** (k + 1), rng), 0.5 ** k) for k in range(7)]
    ridge = noise_grid(n, 6, rng)
    h = []
    for y in range(n):
        row = []
        for x in range(n):
            v = sum(f(x, y) * w for f, w in octaves)
            r = 1.0 - abs(2.0 * ridge(x, y) - 1.0)
            row.append(v + 0.8 * r * r)
        h.append(row)
    lo = min(min(r) for r in h)
    hi = max(max(r) for r in h)
    raw = b"".join(
        b"\0" + b"".join(struct.pack(">H", round((v - lo) / (hi - lo) * 65535)) for v in row)
        for row in h
    )

    def chunk(kind, data):
        c = struct.pack(">I", len(data)) + kind + data
        return c + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", n, n, 16, 0, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b"")
    with open(a.out, "wb") as f:
        f.write(png)
    side = {
        "width": n,
        "height": n,
        "min_elevation_m": 400.0,
        "max_elevation_m": 2600.0,
        "meters_per_pixel_x": 60.0,
        "meters_per_pixel_y": 60.0,
        "png_encoding": "elev = min + v/65535*(max-min); row 0 = north",
        "source": f"scripts/synthetic_dem.py --size {n} --seed {a.seed} (synthetic fractal terrain)",
    }
    with open(a.out[: -len(".png")] + ".json", "w") as f:
        json.dump(side, f, indent=1)


if __name__ == "__main__":
    main()
