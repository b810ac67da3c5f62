"""`video` yields the 3-D frames `meb video` writes; `Luminaire` drives the virtual luminaire
of `meb device emulate` on a pseudo-terminal through the client `meb device` uses."""

import json
import os
import signal
import subprocess
import threading
import warnings

import numpy as np
import pytest

import meb
from conftest import meb_binary, nan_equal, run_meb


def turning_ellipsoid_clip(folder, size, frames):
    """`meb simulate`'s y4m clip of the turning ellipsoid on the thesis' dynamic rig."""
    run_meb("simulate", "--rig", "thesis-dynamic", "--camera-size", size, "--scene",
            "ellipsoid", "--axes-mm", "100,60,60", "--rpm", "7.5", "--frames", str(frames),
            "--format", "y4m", "--out", str(folder))
    return folder


def test_video_yields_the_frames_meb_video_writes(tmp_path):
    clip = turning_ellipsoid_clip(tmp_path / "clip", "320x180", 120)
    out = tmp_path / "video"
    rig = str(clip / "rig.toml")
    run_meb("video", str(clip / "capture.y4m"), "--rig", rig, "--out", str(out))
    records = json.loads((out / "video.json").read_text())["frames"]
    frames = meb.video(clip / "capture.y4m", rig)
    seen = list(frames)
    assert len(seen) == len(records) == 3
    for frame, record in zip(seen, records):
        assert frame.index == record["index"] and frame.status == record["status"]
        written = out / f"depth_{frame.index:05}.npy"
        if written.exists():
            assert frame.depth is not None and nan_equal(frame.depth, np.load(written))
    assert frames.summary["reconstructed"] == sum(r["status"] == "reconstructed" for r in records)


def test_a_closed_video_stops_its_pipeline():
    capture = meb.simulate("thesis-dynamic", "sphere", frames=120, camera_size=(160, 90))
    frames = meb.video(capture.frames, capture.rig, fps=capture.fps)
    first = next(frames)
    assert first.index == 0
    frames.close()
    with pytest.raises(StopIteration):
        next(frames)


def test_ctrl_c_then_stop_ends_a_live_stream_as_meb_videos_first_interrupt(tmp_path):
    clip = turning_ellipsoid_clip(tmp_path / "clip", "160x90", 100)
    # A named pipe that delivers 100 frames (two whole 40-frame windows) and stays open.
    fifo = tmp_path / "camera.y4m"
    os.mkfifo(fifo)
    release = threading.Event()

    def feed():
        with open(fifo, "wb") as pipe:
            pipe.write((clip / "capture.y4m").read_bytes())
            pipe.flush()
            release.wait(120)

    threading.Thread(target=feed, daemon=True).start()
    try:
        frames = meb.video(fifo, str(clip / "rig.toml"))
        assert [next(frames).index, next(frames).index] == [0, 1]
        # No frame comes any more: the wait for the next one is interrupted by Ctrl-C.
        ctrl_c = threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGINT))
        ctrl_c.start()
        with pytest.raises(KeyboardInterrupt):
            next(frames)
        ctrl_c.join()
        assert frames.summary is None
        frames.stop()
        assert list(frames) == []
        assert frames.summary["end"] == "interrupted", frames.summary
        assert frames.summary["windows"] == 2, frames.summary
    finally:
        release.set()


@pytest.fixture
def virtual_luminaire(tmp_path):
    """A `meb device emulate` process and the pseudo-terminal it prints."""
    process = subprocess.Popen(
        [str(meb_binary()), "device", "emulate", "--storage", str(tmp_path / "flash")],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        port = process.stdout.readline().strip()
        assert port, process.stderr.read()
        yield port
    finally:
        process.terminate()
        process.wait(timeout=10)


def test_a_luminaire_is_configured_saved_and_read_back(virtual_luminaire):
    luminaire = meb.Luminaire(virtual_luminaire)
    info = luminaire.info()
    assert info["max_leds"] == 8
    luminaire.set(4, 959.5, brightness=[1000, 900, 800, 700], phase=[0, 3, 7, 11], depth="auto")
    config = luminaire.get()
    depths = config.pop("depth")
    assert config == {"leds": 4, "rate": 959.5, "brightness": [1000, 900, 800, 700],
                      "phase": [0, 3, 7, 11], "allow_flicker": False, "running": True}
    # Each LED's largest low-risk depth at this rate: below full on/off keying, and accepted
    # again when given explicitly (no warning: it is low-risk).
    assert len(depths) == 4 and all(0 < d < 1 for d in depths)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        luminaire.set(4, 959.5, brightness=[1000, 900, 800, 700], phase=[0, 3, 7, 11],
                      depth=[round(d, 3) - 0.001 for d in depths])
    depths = luminaire.get()["depth"]
    assert luminaire.status()["unsaved_changes"] is True
    assert luminaire.save() == "saved"
    assert luminaire.status()["unsaved_changes"] is False
    # Full on/off keying is above IEEE 1789 low risk: refused with what would be low-risk,
    # accepted (with a warning) only when asked for, and then not saved without asking again.
    with pytest.raises(ValueError, match=r'refusing to set: LED \d.*depth="auto".*allow_flicker=True'):
        luminaire.set(4, 960, depth=1.0)
    assert luminaire.get()["depth"] == depths
    with pytest.warns(UserWarning, match="above IEEE 1789 low risk"):
        luminaire.set(4, 960, depth=[1.0, 1.0, 1.0, 1.0], allow_flicker=True)
    assert luminaire.get()["depth"] == [1.0, 1.0, 1.0, 1.0]
    with pytest.raises(ValueError, match="refusing to save"):
        luminaire.save()
    with pytest.raises(ValueError, match=r"depth 1\.5: a depth in \(0, 1\]"):
        luminaire.set(4, 960, depth=1.5)
    with pytest.raises(ValueError, match="depth needs 4 values"):
        luminaire.set(4, 960, depth=[0.5, 0.5])
    luminaire.stop()
    assert luminaire.get()["running"] is False
    with pytest.raises(ValueError, match="needs 4 values"):
        luminaire.set(4, 960, brightness=[1000])
    with pytest.raises(ValueError, match="outside the supported"):
        luminaire.set(4, 1e9)
    with pytest.raises(ValueError, match="phase_chips"):
        luminaire.set(2, 960, phase=[0, 8])


def test_a_port_without_a_luminaire_is_refused():
    with pytest.raises(meb.MebError, match="cannot open /nonexistent/tty"):
        meb.Luminaire("/nonexistent/tty")
