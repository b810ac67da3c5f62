"""Times the package's calls beside the same library calls in Rust (bench/timing.rs), built in
the same cargo profile, and optionally beside BiNI's reference implementation.

    python bench/compare.py [--profile dev] [--repeats 5] [--bini PATH/TO/BiNI] [OBJECT_DIR…]

* decode: 32 frames of 1280x720 (a simulated sphere capture) passed as a uint8 numpy array;
* integrate: each DiLiGenT object of the normal-integration benchmark (default: the shared
  data's five) through its camera (K.txt, 1500 mm), automatic integrator.

The Python side must be the package built in the same profile as the Rust side (`maturin
develop --profile dev` in host/python, or `--profile release` for a release build). With
--bini, BiNI's plain scipy reference implementation `bilateral_normal_integration_simple.py`
(Cao et al., "Bilateral Normal Integration", ECCV 2022; needs scipy; its progress bar and mesh
export imports are stubbed) integrates each object too, perspective, k = 2, with its defaults
(at most 150 iterations, tolerance 1e-4), in the same run. Prints a Markdown table; medians in milliseconds.
"""

import argparse
import importlib.util
import json
import statistics
import subprocess
import time
from pathlib import Path

import numpy as np

import meb

ROOT = Path(__file__).resolve().parents[3]
SHARED = ROOT.parent / "shared" / "data" / "diligent-normals"
if not SHARED.is_dir():
    SHARED = ROOT.parent.parent / "shared" / "data" / "diligent-normals"


def rust_times(profile: str, *args: str) -> dict[str, list[float]]:
    """Runs the Rust timing example; its times per case."""
    done = subprocess.run(
        ["cargo", "run", "--quiet", "--profile", profile, "-p", "meb-python", "--example",
         "timing", "--", *args],
        cwd=ROOT, capture_output=True, text=True, check=True,
    )
    return {d["case"]: d["ms"] for d in map(json.loads, done.stdout.splitlines())}


def timed(call, repeats: int) -> list[float]:
    """Wall times of `repeats` calls, ms."""
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        call()
        times.append((time.perf_counter() - started) * 1e3)
    return times


def read_object(folder: Path):
    """Normals, mask and K of a benchmark object, as meb's reader makes them."""
    import matplotlib.image

    # The codes back from matplotlib's floats, then code / (2^bits − 1) in float32 as meb's
    # reader (the image crate) computes it; the PNG header's byte 24 is the bit depth.
    path = folder / "normal_map.png"
    full = np.float32(65535 if path.read_bytes()[24] == 16 else 255)
    codes = np.rint(matplotlib.image.imread(path)[..., :3] * full)
    rgb = codes.astype(np.float32) / full
    n = rgb * np.float32(2) - np.float32(1)
    # The length as meb's reader sums it (x² + y² + z², left to right, in float32).
    length = np.sqrt(n[..., 0] * n[..., 0] + n[..., 1] * n[..., 1] + n[..., 2] * n[..., 2])[..., None]
    normals = np.where(length > 0, n / np.where(length > 0, length, 1), np.nan).astype(np.float32)
    mask_image = matplotlib.image.imread(folder / "mask.png")
    mask = (mask_image[..., 0] if mask_image.ndim == 3 else mask_image) > 0
    return np.ascontiguousarray(normals), mask, np.loadtxt(folder / "K.txt")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("objects", nargs="*", type=Path)
    parser.add_argument("--profile", default="dev")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--bini", type=Path, help="a checkout of BiNI's repository")
    parser.add_argument("--skip-decode", action="store_true")
    args = parser.parse_args()
    objects = args.objects or sorted(p for p in SHARED.iterdir() if (p / "K.txt").exists())

    print("| case | Rust (ms) | Python (ms) | Python / Rust | BiNI (ms) | BiNI / Python |")
    print("|---|---|---|---|---|---|")
    if not args.skip_decode:
        rust = rust_times(args.profile, "decode", str(args.repeats))["decode"]
        capture = meb.simulate("thesis-out-of-plane", "sphere", frames=32, camera_size=(1280, 720))
        frames, fps = capture.frames, capture.fps
        python = timed(lambda: meb.decode(frames, leds=4, fps=fps, force=True), args.repeats)
        r, p = statistics.median(rust), statistics.median(python)
        print(f"| decode 32 × 1280x720 | {r:.0f} | {p:.0f} | {p / r:.2f} | | |")
    # The Rust side integrates the very normals the Python side passes.
    import tempfile

    scratch = Path(tempfile.mkdtemp(prefix="meb-compare-"))
    inputs = {folder.name: read_object(folder) for folder in objects}
    pairs = []
    for folder in objects:
        np.save(scratch / f"{folder.name}.npy", inputs[folder.name][0])
        pairs += [str(folder), str(scratch / f"{folder.name}.npy")]
    rust = rust_times(args.profile, "integrate", str(args.repeats), *pairs)
    bini = None
    if args.bini:
        import sys
        import types

        mesh = types.ModuleType("pyvista")
        mesh.PolyData = lambda *_, **__: None
        sys.modules.setdefault("pyvista", mesh)
        progress = types.ModuleType("tqdm.auto")
        progress.tqdm = lambda iterable, **_: iterable
        sys.modules.setdefault("tqdm", types.ModuleType("tqdm"))
        sys.modules.setdefault("tqdm.auto", progress)
        spec = importlib.util.spec_from_file_location(
            "bini", args.bini / "bilateral_normal_integration_simple.py")
        bini = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(bini)
    for folder in objects:
        normals, mask, K = inputs[folder.name]
        python = timed(lambda: meb.integrate(normals, mask, K=K, distance=1500.0), args.repeats)
        r, p = statistics.median(rust[folder.name]), statistics.median(python)
        row = f"| integrate {folder.name} | {r:.0f} | {p:.0f} | {p / r:.2f} |"
        if bini is not None:
            # BiNI takes the benchmark's normal maps as they are (x right, y up, z towards
            # the camera) and converts them itself.
            n = np.nan_to_num(normals)
            started = time.perf_counter()
            bini.bilateral_normal_integration(normal_map=n, normal_mask=mask, k=2, K=K)
            b = (time.perf_counter() - started) * 1e3
            row += f" {b:.0f} | {b / p:.0f} |"
        else:
            row += " | |"
        print(row, flush=True)


if __name__ == "__main__":
    main()
