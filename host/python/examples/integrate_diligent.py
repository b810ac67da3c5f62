"""Integrate a DiLiGenT normal map through its camera's intrinsics and plot the depth.

DiLiGenT's ground-truth normal maps as bundled for the normal-integration benchmark of Cao et
al. ("Bilateral Normal Integration", ECCV 2022): `normal_map.png` (n = rgb / 255 · 2 − 1, x
right, y up, z towards the camera), `mask.png` and `K.txt` (3x3 pinhole intrinsics). The
distance to the object's outline sets the scale (DiLiGenT's set-up: about 1500 mm).

    python examples/integrate_diligent.py [../../../shared/data/diligent-normals/cow] [--out f.png]
"""

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.image
import matplotlib.pyplot as plt
import numpy as np

import meb

DEFAULT = Path(__file__).resolve().parents[3].parent / "shared" / "data" / "diligent-normals" / "cow"


def read_object(folder: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Normals (H×W×3 float32), mask (H×W bool) and K (3×3) of a benchmark object."""
    rgb = matplotlib.image.imread(folder / "normal_map.png")[..., :3]  # floats in 0..1
    normals = np.ascontiguousarray(rgb * 2 - 1, dtype=np.float32)
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True).clip(1e-6)
    mask_image = matplotlib.image.imread(folder / "mask.png")
    mask = (mask_image[..., 0] if mask_image.ndim == 3 else mask_image) > 0.5
    return normals, mask, np.loadtxt(folder / "K.txt")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", nargs="?", type=Path, default=DEFAULT)
    parser.add_argument("--distance", type=float, default=1500.0, help="mm to the outline")
    parser.add_argument("--out", default="integrate_diligent.png", help="figure file")
    args = parser.parse_args()

    normals, mask, K = read_object(args.folder)
    depth = meb.integrate(normals, mask, K=K, distance=args.distance, method="auto")
    print(f"{args.folder.name}: {np.isfinite(depth).sum()} of {mask.sum()} pixels integrated, "
          f"depth {np.nanmin(depth):.1f} to {np.nanmax(depth):.1f} mm")

    figure, axes = plt.subplots(1, 2, figsize=(10, 4.5))
    axes[0].imshow(np.where(mask[..., None], normals * 0.5 + 0.5, 1.0))
    axes[0].set_title(f"{args.folder.name}: normal map")
    shown = axes[1].imshow(depth, cmap="viridis")
    axes[1].set_title("depth z (mm, towards the camera)")
    figure.colorbar(shown, ax=axes[1])
    for axis in axes:
        axis.axis("off")
    figure.tight_layout()
    figure.savefig(args.out, dpi=100)
    print("wrote", args.out)


if __name__ == "__main__":
    main()
