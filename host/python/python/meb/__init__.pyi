"""Type stubs of the meb package (the extension module meb._meb)."""

from collections.abc import Iterator, Sequence
from os import PathLike
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

_Path = str | PathLike[str]
_Integrator = Literal["auto", "least-squares", "bilateral", "fast-marching"]

class MebError(Exception):
    """An input meb cannot process or a result it refuses; the message says what looks wrong
    and what to try (the same text as the `meb` command's)."""

class ImplausibleError(MebError):
    """A result meb judges implausible: a decode, a rig or a reconstruction that does not
    explain the data. ``force=True`` keeps such a result (with a warning)."""

    verdict: dict[str, Any]
    """``status``, ``problems`` (what looks wrong) and ``advice`` (what to try)."""
    report: dict[str, Any] | None
    """The refused result's report (a decode's ``decode.json`` fields, a rig check), if any."""

class Rig:
    """A capture rig: the camera and its LEDs in LED order (docs/formats/rig.md)."""

    @staticmethod
    def load(spec: _Path) -> Rig:
        """A rig from a TOML file, or the preset of that name (thesis-in-plane,
        thesis-out-of-plane, thesis-dynamic, thesis-hybrid). Raises MebError."""
    @staticmethod
    def from_toml(text: str, name: str = "<string>") -> Rig:
        """Parses and validates a rig's TOML text. Raises MebError naming the field."""
    def to_toml(self) -> str:
        """The rig as TOML text (round-trips through ``from_toml``)."""
    def save(self, path: _Path) -> None:
        """Writes the rig's TOML to ``path``."""
    def to_dict(self) -> dict[str, Any]:
        """The rig's tables: ``camera``, ``led`` (a list), ``tof_camera``."""
    def light_vectors(self) -> list[list[float]]:
        """Distant light vectors L_i(0), one (x, y, z) row per LED."""
    @property
    def leds(self) -> int:
        """Number of LEDs."""
    @property
    def shape(self) -> tuple[int, int]:
        """Camera image (height, width) in pixels."""
    @property
    def fps(self) -> float:
        """Camera frame rate."""

class Decoded:
    """The LED images of a decode, their noise, the clipped and dark pixels, and the decoder's
    report with its verdict. Arrays are read-only views of the decode's memory."""

    @property
    def images(self) -> list[npt.NDArray[np.float32]]:
        """One H×W image A_i per LED (LED 1 first), fraction of full scale."""
    @property
    def noise(self) -> npt.NDArray[np.float32]:
        """H×W noise σ of one frame sample, fraction of full scale."""
    @property
    def saturated(self) -> npt.NDArray[np.bool_]:
        """H×W: pixels that reached the white level in some frame."""
    @property
    def underexposed(self) -> npt.NDArray[np.bool_]:
        """H×W: pixels whose brightest frame stayed dark."""
    @property
    def report(self) -> dict[str, Any]:
        """The fields of ``decode.json``: timing fit, per-LED quality (``per_led``), verdict."""
    @property
    def verdict(self) -> dict[str, Any]:
        """``status`` (plausible, implausible, overridden), ``problems``, ``advice``."""
    @property
    def leds(self) -> int:
        """Number of LED images."""
    @property
    def shape(self) -> tuple[int, int]:
        """Image (height, width)."""
    @staticmethod
    def load(path: _Path) -> Decoded:
        """Reads a ``meb decode`` folder."""
    def save(self, path: _Path, *, force: bool = False) -> None:
        """Writes a ``meb decode`` folder, atomically; a non-empty folder that is not an
        earlier decode is refused unless ``force``."""

def decode(
    source: npt.NDArray[np.uint8] | npt.NDArray[np.uint16] | _Path,
    leds: int | Literal["auto"] | None = None,
    *,
    fps: float | None = None,
    bit_depth: int | None = None,
    frames: int | None = None,
    start: int = 0,
    estimator: Literal["waveform", "thesis"] = "waveform",
    linearize: str = "none",
    roi: tuple[int, int, int, int] | None = None,
    rate_ratio: float | None = None,
    max_rate_mismatch: float = 0.06,
    exposure: float | None = None,
    line_time_us: float | None = None,
    check_led_count: bool = True,
    force: bool = False,
) -> Decoded:
    """Decodes a capture into one image per LED, as ``meb decode``.

    ``source``: a C-contiguous (frames, height, width) array of uint8 or uint16 code values
    (read in place; ``bit_depth`` 9–16 for uint16, default 16), or a path to anything
    ``meb decode`` reads (frame folder, TIFF, .y4m, video). ``leds`` defaults to 4; ``fps``
    is the frame rate (for a path, an override). ``linearize``: "none", "srgb" or
    "gamma:G". ``roi``: (x, y, width, height).

    Raises ImplausibleError (with ``verdict``) for a decode its quality verdict finds
    implausible unless ``force``; MebError for what cannot be decoded; TypeError/ValueError
    for wrong dtypes, shapes or settings.
    """

class Reconstruction:
    """Normals, albedo, depth, confidence and mask of a reconstruction (read-only views)."""

    @property
    def normals(self) -> npt.NDArray[np.float32]:
        """H×W×3 unit normals (x right, y up, z towards the camera); NaN outside the mask."""
    @property
    def albedo(self) -> npt.NDArray[np.float32]:
        """H×W albedo; NaN outside the mask."""
    @property
    def depth(self) -> npt.NDArray[np.float32]:
        """H×W depth z in mm towards the camera (``depth.npy``); NaN where not reconstructed."""
    @property
    def confidence(self) -> npt.NDArray[np.uint8]:
        """H×W: 0 not reconstructed, 1 filled, 2 two LEDs, 3 measured (``confidence.npy``)."""
    @property
    def mask(self) -> npt.NDArray[np.bool_]:
        """H×W: pixels whose normal was estimated."""
    @property
    def pitch_mm(self) -> float:
        """Grid pitch, mm per pixel."""
    @property
    def report(self) -> dict[str, Any]:
        """Integrator, light model, object pixels, kept share, support verdict, rig check,
        highlights, stage timings and the decode's report."""

def reconstruct(
    source: Decoded | npt.NDArray[np.uint8] | npt.NDArray[np.uint16] | _Path,
    rig: Rig | _Path,
    *,
    integrator: _Integrator = "least-squares",
    mask: npt.NDArray[np.bool_] | None = None,
    near_field: bool = True,
    force: bool = False,
    leds: int | Literal["auto"] | None = None,
    fps: float | None = None,
    bit_depth: int | None = None,
    frames: int | None = None,
    start: int = 0,
    estimator: Literal["waveform", "thesis"] = "waveform",
    linearize: str = "none",
    roi: tuple[int, int, int, int] | None = None,
    rate_ratio: float | None = None,
    max_rate_mismatch: float = 0.06,
    exposure: float | None = None,
    line_time_us: float | None = None,
    check_led_count: bool = True,
) -> Reconstruction:
    """Reconstructs normals, albedo and depth, as ``meb reconstruct``.

    ``source``: a Decoded, a ``meb decode`` folder, or a capture (array or path; decoded
    first with the decoder keywords, ``leds`` defaulting to the rig's). ``rig``: a Rig, a
    preset name or a TOML path. The defaults are the command's (least squares, near-field
    lights).

    Raises ImplausibleError unless ``force`` for a decode whose verdict is not plausible, a
    rig the capture contradicts, or a depth its support check finds implausible.
    """

def integrate(
    normals: npt.NDArray[np.float32],
    mask: npt.NDArray[np.bool_],
    *,
    K: npt.ArrayLike | None = None,
    distance: float | None = None,
    pitch: float | None = None,
    rig: Rig | _Path | None = None,
    method: _Integrator = "auto",
    lambda_: float = 0.06,
) -> npt.NDArray[np.float32]:
    """Integrates an H×W×3 float32 normal map inside a bool mask into H×W float32 depth (mm;
    NaN outside), as ``meb integrate``. The camera: ``pitch`` (orthographic, mm per pixel),
    ``K`` (3×3 pinhole intrinsics, OpenCV convention) with ``distance`` (mm to the object's
    outline), or ``rig``. ``lambda_``: Fast Marching's λ. Raises ValueError for NaN normals
    inside the mask, wrong shapes or no camera."""

def photometric(
    images: npt.NDArray[np.float32],
    lights: npt.ArrayLike,
    *,
    mask: npt.NDArray[np.bool_] | None = None,
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]:
    """Photometric stereo with distant lights, as ``meb photometric``: (N, H, W) float32 images
    (N ≥ 3) and N light vectors (x, y, z; length = intensity) → (H×W×3 normals, H×W albedo),
    NaN where no normal was estimated. The object mask is found when not given."""

class Capture:
    """A simulated capture: frames as the camera recorded them and the ground truth."""

    frames: npt.NDArray[np.uint8] | npt.NDArray[np.uint16]
    """(frames, height, width) code values: uint8 for 8-bit captures, else uint16."""
    fps: float
    bit_depth: int
    depth: npt.NDArray[np.float32]
    """H×W true height z in mm; NaN outside the objects."""
    normals: npt.NDArray[np.float32]
    mask: npt.NDArray[np.bool_]
    albedo: npt.NDArray[np.float32]
    led_images: list[npt.NDArray[np.float32]]
    """What a perfect decoder returns: each LED alone, no background, no noise."""
    info: dict[str, Any]
    """The capture's facts (``truth.json``): phases, chip rates, gain, noise, seed."""
    rig: Rig

def simulate(
    rig: Rig | _Path | None = None,
    scene: Literal["sphere", "cube", "ellipsoid", "multi"] = "sphere",
    *,
    size_mm: float | None = None,
    corner: bool = False,
    axes_mm: Sequence[float] = (100.0, 60.0, 60.0),
    albedo: float | None = None,
    ground_mm: float | None = None,
    ground_albedo: float = 0.5,
    rpm: float = 0.0,
    spin_axis: Sequence[float] = (0.0, 1.0, 0.0),
    frames: int = 128,
    exposure: float = 1.0,
    line_time_us: float = 0.0,
    bit_depth: int = 8,
    noise: float = 0.005,
    gain: float | None = None,
    peak: float | None = None,
    phases: Sequence[float] | None = None,
    seed: int = 0,
    camera_size: tuple[int, int] | None = None,
    truth_frame: int = 0,
) -> Capture:
    """Renders a capture in memory with the simulator of ``meb simulate`` (same settings and
    defaults; the rig defaults to thesis-out-of-plane; ``camera_size`` is (width, height)).
    The frames equal the command's bit for bit."""

class VideoFrame:
    """One 3-D frame: its record and, when reconstructed, its depth (and normals)."""

    index: int
    status: str
    record: dict[str, Any]
    depth: npt.NDArray[np.float32] | None
    normals: npt.NDArray[np.float32] | None
    camera_frames: int

class Video(Iterator[VideoFrame]):
    """3-D frames as the pipeline finishes them; ``summary`` once exhausted. Ctrl-C raises
    ``KeyboardInterrupt`` from ``next()`` while the pipeline goes on: ``stop()`` then ends the
    stream (the windows already read are still yielded), ``close()`` drops the rest."""

    def __iter__(self) -> Video: ...
    def __next__(self) -> VideoFrame: ...
    @property
    def summary(self) -> dict[str, Any] | None:
        """``video.json``'s summary once the iterator is exhausted, else None."""
    def stop(self) -> None:
        """Ends the stream as ``meb video``'s first Ctrl-C does: no more camera frames are
        read, the windows the frames already read complete are still yielded, and the
        summary's ``end`` is ``"interrupted"``."""
    def close(self) -> None:
        """Stops the pipeline; the frames not yet taken are dropped."""

def video(
    source: npt.NDArray[np.uint8] | npt.NDArray[np.uint16] | _Path,
    rig: Rig | _Path,
    *,
    window: int = 40,
    drop: int = 4,
    hop: int | None = None,
    leds: int | Literal["auto"] | None = None,
    fps: float | None = None,
    bin: int = 1,
    linearize: str = "none",
    integrator: _Integrator = "least-squares",
    max_frames: int | None = None,
    force: bool = False,
) -> Video:
    """3-D video as ``meb video``: windows of ``window`` camera frames (``drop`` dropped at
    each end, every ``hop`` frames) decoded and reconstructed on a thread of their own. A
    frame array is copied into the pipeline's frame queue (it outlives the call); a path is
    streamed."""

def list_luminaires() -> list[dict[str, Any]]:
    """The serial ports (path, USB IDs and strings, is_luminaire), as ``meb device list``."""

class Luminaire:
    """A luminaire on a serial port, or the virtual one of ``meb device emulate``."""

    def __init__(self, port: _Path, *, timeout_ms: int = 500) -> None: ...
    def info(self) -> dict[str, Any]:
        """Firmware, protocol version, board, LED and chip-rate limits."""
    def status(self) -> dict[str, Any]:
        """Running, faults, unsaved changes, save state, link counters."""
    def get(self) -> dict[str, Any]:
        """The active configuration: leds, rate (Hz), brightness, phase and modulation depth per
        LED, allow_flicker, running."""
    def set(
        self,
        leds: int,
        rate: float,
        *,
        brightness: Sequence[int] | None = None,
        phase: Sequence[int] | None = None,
        depth: float | Sequence[float] | Literal["auto"] | None = None,
        allow_flicker: bool = False,
    ) -> None:
        """Applies a configuration (not saved). ``depth`` is the modulation depth
        (on − off)/(on + off): "auto" for each LED's largest IEEE 1789 low-risk depth, one
        value in (0, 1] or one per LED (default: the current depths). ValueError for values
        outside the protocol's limits, and for a configuration above IEEE 1789 low risk unless
        ``allow_flicker`` (then a UserWarning)."""
    def save(self, *, allow_flicker: bool = False) -> str:
        """Persists the configuration: "saved" or "already saved"; ValueError above IEEE 1789
        low risk unless ``allow_flicker``."""
    def start(self) -> None: ...
    def stop(self) -> None: ...
    @property
    def port(self) -> str: ...
