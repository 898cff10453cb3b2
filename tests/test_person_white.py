"""Several photos of one person, each with its own white level (``tone.white_per_photo``, docs/person.md): each
photo's white level is read off its own frame, and each photo's lights are held to its own."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from deface.fit import rendering, scene_white
from deface.fit.config import DecoupleConfig, FitConfig
from deface.fit.decoupling import Decoupling
from deface.fit.log import FitLog
from deface.fit.scene import initial_lights
from deface.fit.scene_light import lights_scaled_to_white
from deface.fit.target import FitTarget
from deface.io.images import LUMINANCE, linear_to_srgb
from deface.landmarks.detect import Landmarks
from deface.losses.illuminant import front_directions, peak_white

SIDE = 96


def _scene(exposure: float, tint: np.ndarray) -> np.ndarray:
    """[SIDE, SIDE, 3] sRGB: a grey-world scene of random reflectances (0.05-0.4) under a light of ``tint`` times
    ``exposure``, the face a disc in its middle."""
    rng = np.random.default_rng(3)
    reflectance = np.repeat(np.repeat(rng.uniform(0.05, 0.4, (SIDE // 8, SIDE // 8, 1)), 8, 0), 8, 1)
    return linear_to_srgb(np.clip(reflectance * exposure * tint, 0, 1)).astype(np.float32)


def _face_disc(face, target, frame, size) -> np.ndarray:
    rows, cols = np.mgrid[: size[0], : size[1]]
    return np.hypot(rows - size[0] / 2, cols - size[1] / 2) < size[0] / 5


def _two_photos_target() -> FitTarget:
    """The same scene photographed twice: once as it is, once a stop darker through a warmer white balance."""
    frames = [_scene(1.0, np.ones(3)), _scene(0.5, np.array([1.15, 1.0, 0.8]))]
    points = np.full((478, 2), SIDE / 2, dtype=np.float32)
    landmarks = [Landmarks(points, np.zeros(478, np.float32), (SIDE, SIDE), 1, 0) for _ in frames]
    return FitTarget(frames, landmarks, 1.0, light_groups=(0, 1))


@pytest.mark.parametrize("per_photo", [True, False])
def test_each_photo_reads_its_own_white_level_or_all_share_one(monkeypatch, per_photo):
    monkeypatch.setattr(scene_white, "scene_face", _face_disc)
    config = FitConfig()
    config = replace(config, tone=replace(config.tone, white_per_photo=per_photo))
    first, second = scene_white.scene_illuminants(None, _two_photos_target(), config, FitLog(quiet=True))
    if not per_photo:
        assert first is second
        return
    assert first is not second
    # the scene's level, before the photo's white point is weighed in, is a stop lower in the darker photo
    assert second.scene_reading[0] / first.scene_reading[0] == pytest.approx(0.5, rel=0.02)
    assert float(second.white @ LUMINANCE) < float(first.white @ LUMINANCE)
    # and its white is warmer (or at most as warm: the plausible-illuminant prior pulls towards the white point)
    assert second.white[0] / second.white[2] > first.white[0] / first.white[2]


def test_a_clip_and_photos_sharing_their_lights_share_one_white_level():
    config = FitConfig()
    target = _two_photos_target()
    assert scene_white.white_groups(target, config) == [[0], [1]]
    assert scene_white.white_groups(replace(target, light_groups=None), config) == [[0, 1]]
    shared_lights = replace(config, lights=replace(config.lights, per_photo=False))
    assert scene_white.white_groups(target, shared_lights) == [[0, 1]]


def _context(whites: list[np.ndarray], levels: list[float]):
    """Two photos with two even lights each, the brighter of photo i white at level ``levels[i]``, photo i's
    white level ``whites[i]``."""
    config = FitConfig()
    base = torch.zeros_like(initial_lights(config.lights)[:2])
    base[:, 0] = torch.tensor([[1.0], [0.5]])  # even lights: the same white response at every normal
    lights = torch.cat([lights_scaled_to_white(base, np.full(3, level)) for level in levels])
    decoupling = Decoupling(DecoupleConfig(), num_lights=4, num_frames=2, size=(4, 4), light_groups=(0, 1))
    regions = [torch.ones(4, 4, dtype=torch.bool)] * 2
    return SimpleNamespace(
        config=config, kept_lights=lights, decoupling=decoupling, target=SimpleNamespace(num_frames=2),
        inputs=SimpleNamespace(scene_light=SimpleNamespace(
            regions=regions, illuminants=[SimpleNamespace(white=white) for white in whites])))


def test_each_photos_lights_are_held_to_its_own_white_level():
    """The level and colour terms of a photo read its own lights against its own white level: photos whose
    lights match their own white levels cost nothing, whatever the other photo's light is."""
    normals = SimpleNamespace(normals=torch.tensor([0.0, 0.0, 1.0]).expand(4, 4, 3))
    bright, dim = np.full(3, 2.0), np.full(3, 0.5)
    matched = _context([bright, dim], [2.0, 0.5])
    peak = peak_white(matched.kept_lights, front_directions())  # [4, 3]: the first photo's lights 4x the second's
    assert float(peak[0, 1] / peak[2, 1]) == pytest.approx(4.0, rel=1e-4)
    swapped = _context([dim, bright], [2.0, 0.5])
    for frame in (0, 1):
        level = float(rendering.scene_light_level(matched, frame, normals))
        assert level < 0.5 < float(rendering.scene_light_level(swapped, frame, normals))
    warm, cool = np.array([1.2, 1.0, 0.75]), np.array([0.8, 1.0, 1.25])
    coloured = _context([warm, cool], [1.0, 1.0])
    coloured.kept_lights = torch.cat([lights_scaled_to_white(coloured.kept_lights[:2], warm),
                                      lights_scaled_to_white(coloured.kept_lights[2:], cool)])
    assert float(rendering.scene_light_colour(coloured)) < 1e-3
    coloured.inputs.scene_light.illuminants.reverse()
    assert float(rendering.scene_light_colour(coloured)) > 10.0
