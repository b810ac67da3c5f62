#!/usr/bin/env python3
"""A straightforward numpy/scipy photometric-stereo pipeline, to measure `meb reconstruct` against.

Not part of the product and not run by CI: it is the yardstick of the speed target
"`meb reconstruct` of a 32-frame PNG capture >= 5x a straightforward numpy/scipy pipeline".
Each stage is the textbook version of what meb does (SPEC sections 4-6):

1. read the frames with PIL (frame_*.png in name order) into a float array;
2. decode with the thesis decoder (SPEC section 4, thesis Eqs. 3.25-3.30) in its DFT form: the
   projection of each pixel's signal onto LED i's subspace is a masked inverse DFT over time,
   I_i = max_j of it, A_i = 2 I_i;
3. least-squares photometric stereo with distant lights (SPEC section 5): G = pinv(L) A,
   albedo |G|, normal G/|G|; mask = albedo above 10 % of its 99th percentile;
4. integrate the gradients p = -nx/nz, q = -ny/nz (SPEC section 6) by least squares over the
   mask with forward differences, solved by scipy.sparse.linalg.lsqr.

Usage: python3 scripts/reference_pipeline.py CAPTURE_DIR [--frames 32] [--out depth.npy]
(CAPTURE_DIR holds frame_*.png and rig.toml, e.g. a `meb simulate` output). Needs numpy, scipy
and pillow (pip install numpy scipy pillow). Prints the time of each stage.
"""

import argparse
import glob
import math
import os
import sys
import time
import tomllib

import numpy as np
import scipy.sparse
import scipy.sparse.linalg
from PIL import Image


def read_frames(folder, count):
    files = sorted(glob.glob(os.path.join(folder, "frame_*.png")))[:count]
    if len(files) < count:
        sys.exit(f"{folder}: {len(files)} frames, {count} needed")
    frames = []
    for f in files:
        im = np.asarray(Image.open(f))
        scale = 65535.0 if im.dtype == np.uint16 else 255.0
        frames.append(im.astype(np.float64) / scale)
    return np.stack(frames)


def thesis_decode(frames, leds):
    """A_i per pixel from n = 2^(N+1) frames: masked inverse DFTs, max over time (SPEC 4)."""
    n = 2 ** (leds + 1)
    r = frames[:n]
    # Real signals: the half spectrum (bins 0..n/2) holds every bin's information.
    spectrum = np.fft.rfft(r, axis=0)
    q = np.arange(n // 2 + 1) % (2**leds)
    images = []
    for i in range(leds):
        step = 2 ** (leds - 1 - i)
        mask = (q % step == 0) & ((q // step) % 2 == 1)
        projection = np.fft.irfft(spectrum * mask[:, None, None], n=n, axis=0)
        images.append(2.0 * projection.max(axis=0))
    return np.stack(images)


def photometric_stereo(images, rig):
    lights = []
    for led in rig["led"]:
        p = np.array(led["position_mm"], dtype=np.float64)
        d = np.linalg.norm(p)
        lights.append(led.get("intensity", 1.0) / d**2 * p / d)
    pinv = np.linalg.pinv(np.array(lights))
    leds, h, w = images.shape
    g = pinv @ images.reshape(leds, -1)
    albedo = np.linalg.norm(g, axis=0)
    normals = g / np.maximum(albedo, 1e-12)
    mask = albedo > 0.1 * np.percentile(albedo, 99)
    mask &= normals[2] > 0.05
    return normals.reshape(3, h, w), mask.reshape(h, w)


def integrate(normals, mask, pitch):
    p = -normals[0] / normals[2]
    q = -normals[1] / normals[2]
    h, w = mask.shape
    index = -np.ones((h, w), dtype=np.int64)
    index[mask] = np.arange(mask.sum())
    rows, cols, vals, rhs = [], [], [], []
    eq = 0
    # x to the right: z[r, c+1] - z[r, c] = h * (p[r, c] + p[r, c+1]) / 2
    both = mask[:, :-1] & mask[:, 1:]
    rr, cc = np.nonzero(both)
    m = len(rr)
    rows += [np.arange(eq, eq + m)] * 2
    cols += [index[rr, cc + 1], index[rr, cc]]
    vals += [np.ones(m), -np.ones(m)]
    rhs.append(pitch * (p[rr, cc] + p[rr, cc + 1]) / 2)
    eq += m
    # y up = towards row 0: z[r-1, c] - z[r, c] = h * (q[r, c] + q[r-1, c]) / 2
    both = mask[1:, :] & mask[:-1, :]
    rr, cc = np.nonzero(both)
    rr = rr + 1
    m = len(rr)
    rows += [np.arange(eq, eq + m)] * 2
    cols += [index[rr - 1, cc], index[rr, cc]]
    vals += [np.ones(m), -np.ones(m)]
    rhs.append(pitch * (q[rr, cc] + q[rr - 1, cc]) / 2)
    eq += m
    a = scipy.sparse.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
        shape=(eq, int(mask.sum())),
    )
    z = scipy.sparse.linalg.lsqr(a, np.concatenate(rhs), atol=1e-7, btol=1e-7)[0]
    depth = np.full((h, w), np.nan)
    depth[mask] = z - z.mean()
    return depth


def pitch_mm(camera):
    if "pixel_pitch_mm" in camera:
        return camera["pixel_pitch_mm"]
    fov = math.radians(camera["fov_deg"])
    return 2.0 * camera["distance_mm"] * math.tan(fov / 2) / camera["width"]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("capture")
    parser.add_argument("--frames", type=int, default=32)
    parser.add_argument("--out", default=None)
    args = parser.parse_args()
    with open(os.path.join(args.capture, "rig.toml"), "rb") as f:
        rig = tomllib.load(f)
    leds = len(rig["led"])
    times = {}
    start = time.perf_counter()
    frames = read_frames(args.capture, args.frames)
    times["read"] = time.perf_counter() - start
    t = time.perf_counter()
    images = thesis_decode(frames, leds)
    times["decode"] = time.perf_counter() - t
    t = time.perf_counter()
    normals, mask = photometric_stereo(images, rig)
    times["photometric"] = time.perf_counter() - t
    t = time.perf_counter()
    depth = integrate(normals, mask, pitch_mm(rig["camera"]))
    times["integrate"] = time.perf_counter() - t
    times["total"] = time.perf_counter() - start
    if args.out:
        np.save(args.out, depth.astype(np.float32))
    print(" ".join(f"{k} {v * 1e3:.0f} ms" for k, v in times.items()))


if __name__ == "__main__":
    main()
