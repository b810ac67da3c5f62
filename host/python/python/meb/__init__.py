"""MEB-FDMA photometric stereo from Python.

Decode a capture of LEDs switched with Manchester-encoded binary FDMA carriers into one image
per LED, reconstruct normals, albedo and depth, integrate normal maps, simulate captures with
ground truth and drive luminaires, with numpy arrays in and out. Every function calls the Rust
library the ``meb`` command uses, with the interpreter lock released while it computes.

    >>> import meb
    >>> capture = meb.simulate("thesis-out-of-plane", "sphere", frames=64, camera_size=(160, 90))
    >>> decoded = meb.decode(capture.frames, leds=4, fps=capture.fps)
    >>> result = meb.reconstruct(decoded, capture.rig)
    >>> result.depth.shape
    (90, 160)

See docs/howto/python.md for the API, what is copied and what is refused.
"""

from ._meb import (
    Capture,
    Decoded,
    ImplausibleError,
    Luminaire,
    MebError,
    Reconstruction,
    Rig,
    Video,
    VideoFrame,
    decode,
    integrate,
    list_luminaires,
    photometric,
    reconstruct,
    simulate,
    video,
)

__all__ = [
    "Capture",
    "Decoded",
    "ImplausibleError",
    "Luminaire",
    "MebError",
    "Reconstruction",
    "Rig",
    "Video",
    "VideoFrame",
    "decode",
    "integrate",
    "list_luminaires",
    "photometric",
    "reconstruct",
    "simulate",
    "video",
]
