"""The skin's chroma set after stage 3 (deface/fit/texels.py ``skin_chroma_matched``): the map's skin takes the
photo's reading, the lights take the inverse, and so every render, diffuse and specular, is the same."""

from __future__ import annotations

import math

import numpy as np
import torch

from deface.fit.texels import skin_chroma_matched
from deface.models.ict import load_ict
from deface.render.camera import Camera
from deface.render.frame import render_frame
from deface.render.mesh import Textures
from deface.render.primitives import grid_plane
from deface.render.renderer import RenderConfig, Renderer

SIZE = 128


def _maps(rng) -> Textures:
    diffuse = torch.as_tensor(np.array([0.45, 0.33, 0.28]) * (1 + 0.1 * rng.standard_normal((SIZE, SIZE, 1))))
    specular = torch.full((SIZE, SIZE, 3), 0.04, dtype=torch.float64)
    return Textures(diffuse, specular, torch.full((SIZE, SIZE, 1), 0.4, dtype=torch.float64))


def _lights() -> torch.Tensor:
    light = torch.zeros(2, 9, 3, dtype=torch.float64)
    light[0, 0], light[0, 2] = torch.tensor([2.2, 1.9, 1.6]), torch.tensor([0.8, 0.7, 0.5])  # a warm key from the front
    light[1, 0], light[1, 1] = torch.tensor([0.9, 1.0, 1.2]), torch.tensor([0.3, 0.3, 0.4])  # a cool fill from above
    return light


def _render(textures: Textures, light: torch.Tensor) -> torch.Tensor:
    """The plane under one light [1, 9, 3]."""
    camera = Camera(torch.tensor(110.0, dtype=torch.float64), torch.tensor([math.pi, 0.0, 0.0], dtype=torch.float64),
                    torch.tensor([0.0, 0.0, 5.0], dtype=torch.float64), 48, 48)
    renderer = Renderer(RenderConfig(shadows=False, specular=True))
    return render_frame(renderer, grid_plane((-1, 1), (-1, 1), cells=4), camera, textures, light).images


def test_the_skin_takes_the_readings_chroma_and_every_render_is_unchanged(shared):
    textures, lights = _maps(np.random.default_rng(0)), _lights()
    before = [_render(textures, lights[k:k + 1]) for k in range(2)]
    reading = np.array([0.60, 0.34, 0.22])
    seen = np.ones((SIZE, SIZE))
    matched, gain = skin_chroma_matched(load_ict(), textures, seen, reading, lights)
    assert gain is not None and gain[0] > 1 > gain[2]  # the reading is warmer than the map
    skin = np.median(matched.diffuse.numpy().reshape(-1, 3), 0)
    np.testing.assert_allclose(skin / skin[1], reading / reading[1], rtol=0.03)
    torch.testing.assert_close(lights, _lights() / torch.as_tensor(gain))  # divided in place
    for k in range(2):  # each light alone: the diffuse and the specular terms both unchanged
        torch.testing.assert_close(_render(matched, lights[k:k + 1]), before[k], rtol=1e-9, atol=1e-9)


def test_with_no_skin_seen_nothing_changes(shared):
    textures, lights = _maps(np.random.default_rng(1)), _lights()
    matched, gain = skin_chroma_matched(load_ict(), textures, np.zeros((SIZE, SIZE)), np.ones(3), lights)
    assert gain is None and matched is textures
    torch.testing.assert_close(lights, _lights())
