"""deface.io: image loading (EXIF, modes, errors), gamma, resizing, folder listing, video frames."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from deface.io import (
    InputError,
    linear_to_srgb,
    list_inputs,
    load_image,
    read_spread_frames,
    read_video_frames,
    resize_max,
    srgb_to_linear,
)


def _asymmetric_rgb(height: int = 20, width: int = 40) -> np.ndarray:
    """A landscape image whose top-left quadrant is red: orientation is easy to check."""
    image = np.zeros((height, width, 3), np.uint8)
    image[: height // 2, : width // 2, 0] = 255
    return image


def test_exif_orientation_is_applied(tmp_path):
    path = tmp_path / "rotated.jpg"
    exif = Image.Exif()
    exif[0x0112] = 6  # orientation 6: the stored image must be rotated 90 degrees clockwise to display
    Image.fromarray(_asymmetric_rgb()).save(path, quality=95, exif=exif)
    image = load_image(path)
    assert image.shape == (40, 20, 3) and image.dtype == np.float32
    # After a clockwise turn the red top-left quadrant of the stored image is at the top right.
    assert image[:20, 10:, 0].mean() > 0.9 and image[:20, :10, 0].mean() < 0.1


def test_grey_and_rgba_become_rgb(tmp_path):
    Image.fromarray(np.full((5, 6), 128, np.uint8)).save(tmp_path / "grey.png")
    rgba = np.zeros((5, 6, 4), np.uint8)
    rgba[..., 1] = 255
    Image.fromarray(rgba, "RGBA").save(tmp_path / "alpha.png")
    grey = load_image(tmp_path / "grey.png")
    assert grey.shape == (5, 6, 3) and np.allclose(grey, 128 / 255)
    alpha = load_image(tmp_path / "alpha.png")
    assert alpha.shape == (5, 6, 3) and np.allclose(alpha[..., 1], 1.0)


def test_unreadable_and_missing_files_name_the_file(tmp_path):
    bad = tmp_path / "broken.jpg"
    bad.write_bytes(b"not an image at all")
    with pytest.raises(InputError, match="broken.jpg"):
        load_image(bad)
    with pytest.raises(InputError, match="missing.png"):
        load_image(tmp_path / "missing.png")
    with pytest.raises(ValueError):  # InputError is a ValueError
        load_image(bad)


def test_gamma_round_trip_and_power_law():
    values = np.linspace(0, 1, 11, dtype=np.float32)
    assert np.allclose(linear_to_srgb(srgb_to_linear(values)), values, atol=1e-6)
    assert np.isclose(srgb_to_linear(np.float32(0.5)), 0.5**2.2)


def test_resize_max_keeps_aspect_and_never_upscales():
    image = np.random.default_rng(0).random((300, 200, 3)).astype(np.float32)
    small, scale = resize_max(image, 150)
    assert small.shape == (150, 100, 3) and scale == pytest.approx(0.5)
    assert abs(small.mean() - image.mean()) < 0.01
    same, scale = resize_max(image, 1000)
    assert same is image and scale == 1.0


def test_list_inputs_expands_folders_sorted(tmp_path):
    for name in ("b.png", "a.JPG", "clip.mp4", "notes.txt"):
        (tmp_path / name).write_bytes(b"x")
    items = list_inputs([tmp_path])
    assert [(i.path.name, i.kind) for i in items] == [
        ("a.JPG", "image"),
        ("b.png", "image"),
        ("clip.mp4", "video"),
    ]
    with pytest.raises(InputError, match="notes.txt"):
        list_inputs([tmp_path / "notes.txt"])
    with pytest.raises(InputError, match="nowhere"):
        list_inputs([tmp_path / "nowhere"])


def test_video_frames_with_stride(shared):
    path = shared / "data" / "videos" / "d18.mp4"
    every, fps = read_video_frames(path, max_frames=7)
    strided, _ = read_video_frames(path, max_frames=3, stride=3)
    assert fps == pytest.approx(30.0, abs=0.5)
    assert len(every) == 7 and len(strided) == 3
    assert every[0].shape == (480, 480, 3) and every[0].dtype == np.float32
    for k, frame in enumerate(strided):
        np.testing.assert_array_equal(frame, every[3 * k])
    with pytest.raises(ValueError):
        read_video_frames(path, stride=0)


@pytest.mark.slow
def test_spread_frames_match_the_full_decode(shared):
    path = shared / "data" / "videos" / "d18.mp4"
    every, _ = read_video_frames(path, stride=4)
    frames, indices = read_spread_frames(path, 5, stride=4, max_side=240)
    chosen = np.linspace(0, len(every) - 1, 5).round().astype(int)
    assert indices == (chosen * 4).tolist() and indices[0] == 0
    assert frames[0].shape == (240, 240, 3)  # shrunk from 480 while decoding
    assert np.abs(frames[2] - resize_max(every[chosen[2]], 240)[0]).mean() < 0.02
    few, indices = read_spread_frames(path, 500, max_side=32)
    assert len(few) == len(indices) == 216 and indices == list(range(216))  # never more than the clip has
