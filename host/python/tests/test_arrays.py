"""Arrays leave as read-only views of the result's memory (no copy per access), in float32 C
order, none truncated; photometric stereo recovers a Lambertian sphere's normals."""

import numpy as np

import meb


def test_result_arrays_are_read_only_views_of_one_memory(sphere_py):
    decoded = meb.decode(sphere_py.frames, fps=sphere_py.fps)
    first, again = decoded.images[0], decoded.images[0]
    assert np.shares_memory(first, again), "each access copied the image"
    assert not first.flags.writeable
    assert first.flags.c_contiguous and first.dtype == np.float32
    assert first.shape == sphere_py.frames.shape[1:]
    result = meb.reconstruct(decoded, sphere_py.rig)
    assert np.shares_memory(result.depth, result.depth)
    assert result.depth.shape == sphere_py.frames.shape[1:]
    assert result.normals.shape == (*sphere_py.frames.shape[1:], 3)
    assert result.normals.flags.c_contiguous and not result.normals.flags.writeable
    del decoded, result
    # The views keep their owner alive.
    assert np.isfinite(first).any()


def test_every_frame_is_decoded(sphere_py):
    decoded = meb.decode(sphere_py.frames, fps=sphere_py.fps)
    assert decoded.report["frames_used"] == sphere_py.frames.shape[0]
    assert decoded.shape == sphere_py.frames.shape[1:]


def test_uint16_frames_decode_as_their_8_bit_codes_scaled(sphere_py):
    eight = meb.decode(sphere_py.frames, fps=sphere_py.fps)
    sixteen = meb.decode(sphere_py.frames.astype(np.uint16) * 4, fps=sphere_py.fps, bit_depth=10)
    # Codes ×4 at 10 bits are the same fractions of full scale up to 1023/1020.
    for a, b in zip(eight.images, sixteen.images):
        assert np.nanmax(np.abs(a * 255 / 1023 * 4 - b)) < 2e-3


def test_photometric_recovers_a_lambertian_spheres_normals():
    rows, cols = 60, 80
    y, x = np.mgrid[0:rows, 0:cols].astype(np.float64)
    nx, ny = (x - cols / 2) / 25, -(y - rows / 2) / 25
    inside = nx**2 + ny**2 < 0.95
    nz = np.sqrt(np.clip(1 - nx**2 - ny**2, 0, None))
    normals = np.stack([nx, ny, nz], -1)
    lights = np.array([[0.5, 0.3, 1], [-0.5, 0.3, 1], [0.0, -0.6, 1], [0.3, -0.2, 1]])
    images = np.stack([np.clip(normals @ l, 0, None) * 0.7 for l in lights]).astype(np.float32)
    images[:, ~inside] = 0
    found, albedo = meb.photometric(images, lights, mask=inside)
    assert found.shape == (rows, cols, 3) and found.dtype == np.float32
    lit = inside & (images > 0).all(0)
    cos = np.sum(found[lit] * normals[lit], -1)
    assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 0.1
    assert np.allclose(albedo[lit] * np.linalg.norm(lights[0]) / np.linalg.norm(lights[0]), 0.7,
                       atol=1e-3)


def test_a_rig_round_trips_through_toml(tmp_path):
    rig = meb.Rig.load("thesis-out-of-plane")
    rig.save(tmp_path / "rig.toml")
    assert meb.Rig.load(str(tmp_path / "rig.toml")) == rig
    assert rig.leds == 4 and rig.to_dict()["camera"]["fps"] == rig.fps
    assert len(rig.light_vectors()) == 4
