"""Simulate a capture, decode it, reconstruct it and plot normals and depth.

A Ø48 mm sphere under the thesis' out-of-plane rig (four LEDs, 960 fps), 64 frames at
640x360: decoded into one image per LED, reconstructed into normals, albedo and depth, and
compared with the simulator's ground truth.

    python examples/simulate_and_reconstruct.py [--out figure.png]
"""

import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import meb


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="simulate_and_reconstruct.png", help="figure file")
    args = parser.parse_args()

    capture = meb.simulate("thesis-out-of-plane", "sphere", frames=64, camera_size=(640, 360))
    decoded = meb.decode(capture.frames, leds=4, fps=capture.fps)
    print(decoded, "verdict:", decoded.verdict["status"])
    result = meb.reconstruct(decoded, capture.rig)
    error = result.depth - capture.depth
    rmse = float(np.sqrt(np.nanmean(error**2)))
    print(f"{result}: depth RMSE {rmse:.3f} mm against the ground truth")

    # The object's box, with a margin.
    rows, cols = np.nonzero(capture.mask)
    box = np.s_[rows.min() - 8 : rows.max() + 9, cols.min() - 8 : cols.max() + 9]
    figure, axes = plt.subplots(1, 4, figsize=(16, 4))
    axes[0].imshow(decoded.images[0][box], cmap="gray")
    axes[0].set_title("LED 1 image")
    axes[1].imshow(np.nan_to_num(result.normals[box] * 0.5 + 0.5, nan=1.0))
    axes[1].set_title("normals (x, y, z → r, g, b)")
    shown = axes[2].imshow(result.depth[box], cmap="viridis")
    axes[2].set_title("depth (mm)")
    figure.colorbar(shown, ax=axes[2])
    shown = axes[3].imshow(error[box], cmap="coolwarm", vmin=-1, vmax=1)
    axes[3].set_title(f"depth error (mm), RMSE {rmse:.2f}")
    figure.colorbar(shown, ax=axes[3])
    for axis in axes:
        axis.axis("off")
    figure.tight_layout()
    figure.savefig(args.out, dpi=100)
    print("wrote", args.out)


if __name__ == "__main__":
    main()
