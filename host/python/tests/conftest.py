"""Shared fixtures: the `meb` command the results are compared with, captures it simulated,
and a y4m reader."""

import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[3]
SHARED_DATA = ROOT.parent.parent / "shared" / "data"
"""`../shared/data` beside the repository (the checkout is /work/main or /work/wt/NAME)."""


def shared_data() -> Path:
    """The shared public data folder (MEB_SHARED_DATA overrides)."""
    if "MEB_SHARED_DATA" in os.environ:
        return Path(os.environ["MEB_SHARED_DATA"])
    for candidate in (ROOT.parent / "shared" / "data", SHARED_DATA):
        if candidate.is_dir():
            return candidate
    return SHARED_DATA


def meb_binary() -> Path:
    """The `meb` command built from this checkout (MEB_BIN overrides)."""
    path = Path(os.environ.get("MEB_BIN", ROOT / "target" / "debug" / "meb"))
    if not path.is_file():
        pytest.fail(
            f"the meb command is not built at {path}: run `cargo build --locked "
            "--features meb/opencv -p meb` (scripts/test.sh does) or set MEB_BIN"
        )
    return path


def run_meb(*args: str) -> subprocess.CompletedProcess:
    """Runs `meb ARGS` and fails the test with its stderr if it fails."""
    done = subprocess.run(
        [str(meb_binary()), *args], capture_output=True, text=True, check=False
    )
    if done.returncode != 0:
        pytest.fail(f"meb {' '.join(args)} failed:\n{done.stderr}")
    return done


def run_meb_err(*args: str) -> str:
    """Runs `meb ARGS`, expects it to fail, and returns its stderr."""
    done = subprocess.run(
        [str(meb_binary()), *args], capture_output=True, text=True, check=False
    )
    if done.returncode == 0:
        pytest.fail(f"meb {' '.join(args)} succeeded; expected a refusal")
    return done.stderr


def read_y4m(path: Path) -> np.ndarray:
    """The luma planes of a mono (8-bit) y4m file as (frames, height, width) uint8."""
    data = path.read_bytes()
    end = data.index(b"\n")
    params = data[:end].split()
    width = int(next(p[1:] for p in params if p.startswith(b"W")))
    height = int(next(p[1:] for p in params if p.startswith(b"H")))
    colour = next((p[1:] for p in params if p.startswith(b"C")), b"mono")
    assert colour == b"mono", f"not an 8-bit mono y4m: C{colour.decode()}"
    frames = []
    pos = end + 1
    while pos < len(data):
        header_end = data.index(b"\n", pos)
        assert data[pos:header_end].startswith(b"FRAME")
        start = header_end + 1
        frames.append(np.frombuffer(data[start : start + width * height], np.uint8))
        pos = start + width * height
    return np.stack(frames).reshape(len(frames), height, width)


def nan_equal(a: np.ndarray, b: np.ndarray) -> bool:
    """Bit-for-bit equality with NaN equal to NaN."""
    return a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b, equal_nan=True)


SPHERE = dict(rig="thesis-out-of-plane", scene="sphere", size="320x180", frames=64)
"""The capture most tests share: a Ø48 mm sphere under the thesis' out-of-plane rig."""


@pytest.fixture(scope="session")
def sphere_cli(tmp_path_factory) -> Path:
    """The shared sphere capture as `meb simulate` writes it (capture.y4m, rig.toml, truth)."""
    out = tmp_path_factory.mktemp("sphere") / "cap"
    run_meb(
        "simulate", "--rig", SPHERE["rig"], "--scene", SPHERE["scene"],
        "--camera-size", SPHERE["size"], "--frames", str(SPHERE["frames"]),
        "--format", "y4m", "--out", str(out),
    )
    return out


@pytest.fixture(scope="session")
def sphere_py():
    """The same capture simulated from Python."""
    import meb

    width, height = (int(v) for v in SPHERE["size"].split("x"))
    return meb.simulate(
        SPHERE["rig"], SPHERE["scene"], frames=SPHERE["frames"], camera_size=(width, height)
    )
