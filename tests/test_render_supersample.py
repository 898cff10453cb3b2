"""Supersampling (deface/render/supersample.py): box-filtered renders against exact area fractions."""

from __future__ import annotations

import math

import torch

from deface.render.camera import Camera
from deface.render.frame import render_frame
from deface.render.mesh import Textures
from deface.render.primitives import grid_plane
from deface.render.renderer import RenderConfig, Renderer
from deface.render.supersample import box_filter, supersampled_camera

SIZE, FOCAL, DISTANCE = 48, 110.0, 5.0


def camera(size: int = SIZE) -> Camera:
    return Camera(torch.tensor(FOCAL, dtype=torch.float64), torch.tensor([math.pi, 0.0, 0.0], dtype=torch.float64),
                  torch.tensor([0.0, 0.0, DISTANCE], dtype=torch.float64), size, size)


def flat_light() -> torch.Tensor:
    light = torch.zeros(1, 9, 3, dtype=torch.float64)
    light[0, 0] = 2.0  # constant radiance: every covered sample shades the same
    return light


def render(mesh, textures, factor: int):
    renderer = Renderer(RenderConfig(shadows=False, specular=False))
    return render_frame(renderer, mesh, camera(), textures, flat_light(), None, factor)


def constant_textures(size: int = 8, requires_grad: bool = False) -> Textures:
    diffuse = torch.full((size, size, 3), 0.6, dtype=torch.float64, requires_grad=requires_grad)
    return Textures(diffuse, torch.zeros(size, size, 3, dtype=torch.float64),
                    torch.full((size, size, 1), 0.5, dtype=torch.float64))


def test_factor_one_returns_the_render_unchanged():
    mesh = grid_plane((-1, 1), (-1, 1), cells=2)
    renderer = Renderer(RenderConfig(shadows=False, specular=False))
    output = render_frame(renderer, mesh, camera(), constant_textures(), flat_light())
    assert box_filter(output, 1) is output
    assert supersampled_camera(camera(), 1).width == SIZE


def test_interior_pixels_keep_the_surface_colour():
    mesh = grid_plane((-1, 1), (-1, 1), cells=2)
    single, fine = render(mesh, constant_textures(), 1), render(mesh, constant_textures(), 3)
    inside = (single.mask > 0) & (fine.mask == 1)
    assert inside.sum() > 400
    torch.testing.assert_close(fine.images[0][inside], single.images[0][inside], rtol=1e-9, atol=1e-9)


def test_edge_pixels_get_the_covered_area_fraction_and_the_surface_colour():
    # The plane's left edge projects to x = 24.5 px: the middle of pixel column 24.
    edge = 0.5 * DISTANCE / FOCAL
    mesh = grid_plane((edge, 1.0), (-1.0, 1.0), cells=2)
    for factor in (2, 4):
        output = render(mesh, constant_textures(), factor)
        row = SIZE // 2
        assert float(output.mask[row, 23]) == 0.0
        assert float(output.mask[row, 24]) == 0.5
        assert float(output.mask[row, 25]) == 1.0
        # Averaged over covered samples only: no blend with the black background.
        torch.testing.assert_close(output.images[0, row, 24], output.images[0, row, 25])


def test_texel_gradient_is_spread_evenly_when_texels_outnumber_pixels():
    # ~2.3 texels per pixel: single-sample bilinear taps leave texels between pixel centres almost unseen.
    mesh = grid_plane((-0.15, 0.15), (-0.15, 0.15), cells=2)  # ~13 px across at this camera
    spreads = {}
    for factor in (1, 4):
        textures = constant_textures(size=30, requires_grad=True)
        render(mesh, textures, factor).images.sum().backward()
        interior = textures.diffuse.grad[4:-4, 4:-4, 0]
        spreads[factor] = float(interior.std() / interior.mean())
    assert spreads[1] > 0.5
    assert spreads[4] < 0.25 * spreads[1]
