"""Bad inputs raise clear exceptions, and results meb judges implausible raise
ImplausibleError carrying the verdict, as the command refuses them."""

import numpy as np
import pytest

import meb
from conftest import run_meb, run_meb_err


def test_frames_of_a_float_dtype_are_refused_not_converted(sphere_py):
    with pytest.raises(TypeError, match=r"uint8 or uint16.*float32"):
        meb.decode(sphere_py.frames.astype(np.float32), fps=sphere_py.fps)


def test_frames_that_are_not_a_stack_are_refused(sphere_py):
    with pytest.raises(ValueError, match=r"3-D array \(frames, height, width\)"):
        meb.decode(sphere_py.frames[0], fps=sphere_py.fps)


def test_strided_frames_are_refused_not_copied(sphere_py):
    with pytest.raises(ValueError, match="C-contiguous"):
        meb.decode(sphere_py.frames[:, :, ::2], fps=sphere_py.fps)


def test_too_few_frames_are_refused_with_the_decoders_message(sphere_py):
    with pytest.raises(meb.MebError, match="needs at least 32"):
        meb.decode(sphere_py.frames[:20], fps=sphere_py.fps)


def test_a_wrong_led_count_says_what_to_pass(sphere_py):
    with pytest.raises(meb.MebError, match=r"video shows 4 modulated LED\(s\).*leds=4"):
        meb.decode(sphere_py.frames, leds=3, fps=sphere_py.fps)
    with pytest.raises(ValueError, match="1..=8"):
        meb.decode(sphere_py.frames, leds=9)
    with pytest.raises(ValueError, match="estimator"):
        meb.decode(sphere_py.frames, estimator="magic")


def test_a_capture_without_modulation_is_refused():
    frames = np.random.default_rng(3).integers(60, 70, size=(64, 36, 64), dtype=np.uint8)
    with pytest.raises(meb.MebError, match="modulation"):
        meb.decode(frames, fps=960.0)


def test_a_missing_file_is_refused():
    with pytest.raises(meb.MebError, match="cannot open"):
        meb.decode("/nonexistent/capture.y4m")


def test_integrate_refuses_nan_wrong_dtypes_shapes_and_no_camera(sphere_py):
    normals = np.ascontiguousarray(sphere_py.normals)
    mask = sphere_py.mask
    with pytest.raises(TypeError, match=r"float32, got float64.*astype"):
        meb.integrate(normals.astype(np.float64), mask, pitch=1.0)
    with pytest.raises(ValueError, match=r"\(height, width, 3\)"):
        meb.integrate(normals[..., :2].copy(), mask, pitch=1.0)
    with pytest.raises(ValueError, match="mask is"):
        meb.integrate(normals, mask[1:], pitch=1.0)
    with pytest.raises(TypeError, match="mask must be bool"):
        meb.integrate(normals, mask.astype(np.uint8), pitch=1.0)
    with pytest.raises(ValueError, match="no camera"):
        meb.integrate(normals, mask)
    with pytest.raises(ValueError, match="K needs distance"):
        meb.integrate(normals, mask, K=np.eye(3))
    broken = normals.copy()
    rows, cols = np.nonzero(mask)
    broken[rows[0], cols[0]] = np.nan
    with pytest.raises(ValueError, match=f"NaN or infinity at row {rows[0]}, column {cols[0]}"):
        meb.integrate(broken, mask, pitch=1.0)
    with pytest.raises(ValueError, match="empty mask"):
        meb.integrate(normals, np.zeros_like(mask), pitch=1.0)


def test_photometric_refuses_too_few_images_and_mismatched_lights():
    images = np.ones((2, 8, 8), np.float32)
    with pytest.raises(ValueError, match="at least 3 images"):
        meb.photometric(images, [[0, 0, 1]] * 2)
    with pytest.raises(ValueError, match="4 images but 3 light vectors"):
        meb.photometric(np.ones((4, 8, 8), np.float32), [[0, 0, 1]] * 3)
    with pytest.raises(ValueError, match="NaN"):
        bad = np.ones((3, 8, 8), np.float32)
        bad[1, 2, 3] = np.nan
        meb.photometric(bad, [[0, 0, 1], [1, 0, 1], [0, 1, 1]])


def test_a_broken_rig_file_is_refused_naming_the_field(tmp_path):
    text = meb.Rig.load("thesis-out-of-plane").to_toml().replace("fps = 960.0", "fps = -1.0")
    with pytest.raises(meb.MebError, match="fps"):
        meb.Rig.from_toml(text)
    with pytest.raises(meb.MebError, match="no rig file or preset"):
        meb.Rig.load("no-such-rig")


def test_a_rig_of_another_size_is_refused(sphere_py):
    decoded = meb.decode(sphere_py.frames, fps=sphere_py.fps)
    with pytest.raises(ValueError, match="rig camera is"):
        meb.reconstruct(decoded, "thesis-out-of-plane")


def test_a_surface_lit_mostly_by_two_leds_is_refused_as_by_the_command(tmp_path):
    # The command's own refusal case (reconstruct_cli): a cube corner-on at 320x180 under the
    # thesis-dynamic rig, whose faces lit by two LEDs only the integrator can but guess.
    cap = tmp_path / "cap"
    run_meb("simulate", "--rig", "thesis-dynamic", "--camera-size", "320x180", "--frames", "32",
            "--format", "y4m", "--scene", "cube", "--corner", "--out", str(cap))
    err = run_meb_err("reconstruct", str(cap / "capture.y4m"), "--rig", str(cap / "rig.toml"),
                      "--out", str(tmp_path / "rec"))
    assert "lit by three or more LEDs" in err
    with pytest.raises(meb.ImplausibleError, match="lit by three or more LEDs") as refused:
        meb.reconstruct(cap / "capture.y4m", str(cap / "rig.toml"))
    assert refused.value.verdict["status"] == "implausible"
    assert any("three or more LEDs" in p for p in refused.value.verdict["problems"])
    assert refused.value.verdict["advice"]
    with pytest.warns(UserWarning, match="kept an implausible reconstruction"):
        kept = meb.reconstruct(cap / "capture.y4m", str(cap / "rig.toml"), force=True)
    assert np.isfinite(kept.depth).any()


def test_a_decode_refused_by_its_verdict_carries_it_and_force_keeps_it(sphere_py, sphere_cli,
                                                                      tmp_path):
    # A wrong rate ratio fixed by hand leaves the carriers' modulation unexplained: the command
    # refuses it with the same message.
    wrong = dict(rate_ratio=1.01, check_led_count=False)
    with pytest.raises(meb.ImplausibleError) as refused:
        meb.decode(sphere_py.frames, fps=sphere_py.fps, **wrong)
    verdict = refused.value.verdict
    assert verdict["status"] == "implausible" and verdict["problems"] and verdict["advice"]
    assert refused.value.report["per_led"]
    err = run_meb_err("decode", str(sphere_cli / "capture.y4m"), "--rate-ratio", "1.01",
                      "--no-led-check", "--out", str(tmp_path / "dec"))
    message = str(refused.value).split(" (force=True")[0]
    assert message in err.replace("\n", " "), f"{message}\n--- meb said ---\n{err}"
    with pytest.warns(UserWarning, match="kept an implausible decode"):
        kept = meb.decode(sphere_py.frames, fps=sphere_py.fps, force=True, **wrong)
    assert kept.verdict["status"] == "overridden"
    with pytest.raises(meb.ImplausibleError, match="found implausible"):
        meb.reconstruct(kept, sphere_py.rig)
