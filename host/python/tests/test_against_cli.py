"""The package gives what the `meb` command gives on the same inputs, bit for bit: the
simulator's frames and truth, the decoder's LED images and noise, the reconstruction's depth
and normals, the integrator's depth."""

import json

import numpy as np
import pytest

import meb
from conftest import nan_equal, read_y4m, run_meb, shared_data


def test_simulate_renders_the_commands_frames_and_truth(sphere_cli, sphere_py):
    frames = read_y4m(sphere_cli / "capture.y4m")
    assert sphere_py.frames.dtype == np.uint8
    assert sphere_py.frames.shape == frames.shape
    assert np.array_equal(sphere_py.frames, frames)
    assert nan_equal(sphere_py.depth, np.load(sphere_cli / "depth.npy"))
    assert nan_equal(sphere_py.normals, np.load(sphere_cli / "normals.npy"))
    rig = meb.Rig.load(str(sphere_cli / "rig.toml"))
    assert rig == sphere_py.rig


def test_decode_of_an_array_and_of_the_file_equal_meb_decode(sphere_cli, sphere_py, tmp_path):
    out = tmp_path / "dec"
    run_meb("decode", str(sphere_cli / "capture.y4m"), "--leds", "4", "--out", str(out))
    from_array = meb.decode(sphere_py.frames, leds=4, fps=sphere_py.fps)
    from_file = meb.decode(sphere_cli / "capture.y4m", leds=4)
    report = json.loads((out / "decode.json").read_text())
    for decoded in (from_array, from_file):
        assert decoded.leds == 4
        for i, image in enumerate(decoded.images):
            assert image.dtype == np.float32 and image.flags.c_contiguous
            assert nan_equal(image, np.load(out / f"led{i + 1}.npy")), f"LED {i + 1}"
        assert nan_equal(decoded.noise, np.load(out / "noise.npy"))
        assert decoded.verdict["status"] == "plausible"
        for mine, theirs in zip(decoded.report["per_led"], report["per_led"]):
            assert mine["mean_level"] == theirs["mean_level"]
            assert mine["quality"]["gain_uncertainty"] == theirs["quality"]["gain_uncertainty"]
        assert decoded.report["rate_ratio"] == report["rate_ratio"]


def test_reconstruct_equals_meb_reconstruct(sphere_cli, tmp_path):
    dec, rec = tmp_path / "dec", tmp_path / "rec"
    run_meb("decode", str(sphere_cli / "capture.y4m"), "--leds", "4", "--out", str(dec))
    rig = str(sphere_cli / "rig.toml")
    run_meb("reconstruct", str(dec), "--rig", rig, "--out", str(rec))
    for source in (meb.Decoded.load(dec), dec):
        result = meb.reconstruct(source, rig)
        assert nan_equal(result.depth, np.load(rec / "depth.npy"))
        assert nan_equal(result.normals, np.load(rec / "normals.npy"))
        assert nan_equal(result.albedo, np.load(rec / "albedo.npy"))
        assert np.array_equal(result.confidence, np.load(rec / "confidence.npy"))
    report = json.loads((rec / "report.json").read_text())
    assert result.report["object_pixels"] == report["summary"]["object_pixels"]


def test_reconstruct_of_a_capture_path_decodes_it_as_the_command_does(sphere_cli, tmp_path):
    rec = tmp_path / "rec"
    rig = str(sphere_cli / "rig.toml")
    run_meb("reconstruct", str(sphere_cli / "capture.y4m"), "--rig", rig,
            "--integrator", "auto", "--out", str(rec))
    result = meb.reconstruct(sphere_cli / "capture.y4m", rig, integrator="auto")
    assert nan_equal(result.depth, np.load(rec / "depth.npy"))


def test_integrate_equals_meb_integrate_orthographic(sphere_cli, tmp_path):
    out = tmp_path / "int"
    run_meb("integrate", str(sphere_cli / "normals.npy"), "--mask", str(sphere_cli / "mask.png"),
            "--pitch", "0.5", "--out", str(out))
    normals = np.load(sphere_cli / "normals.npy")
    mask = ~np.isnan(normals[..., 0])
    depth = meb.integrate(normals, mask, pitch=0.5)
    assert depth.dtype == np.float32
    assert nan_equal(depth, np.load(out / "depth.npy"))


@pytest.mark.parametrize("method", ["auto", "least-squares"])
def test_integrate_equals_meb_integrate_through_a_pinhole(sphere_cli, tmp_path, method):
    # The sphere's normals seen through a pinhole camera of K.txt: the DiLiGenT objects'
    # intrinsics, as `meb integrate --intrinsics K.txt --distance D` reads them.
    k_file = shared_data() / "diligent-normals" / "cow" / "K.txt"
    K = np.loadtxt(k_file)
    out = tmp_path / "int"
    run_meb("integrate", str(sphere_cli / "normals.npy"), "--mask", str(sphere_cli / "mask.png"),
            "--intrinsics", str(k_file), "--distance", "1500", "--integrator", method,
            "--out", str(out))
    normals = np.load(sphere_cli / "normals.npy")
    mask = ~np.isnan(normals[..., 0])
    depth = meb.integrate(normals, mask, K=K, distance=1500.0, method=method)
    assert nan_equal(depth, np.load(out / "depth.npy"))
