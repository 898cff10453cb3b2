"""Stage 2's half-size level (deface/fit/coarse.py): resampling, camera and landmark consistency with the
working frame, and a stage 2 whose first steps run at half size."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from deface.eval.benchmark import SCHEDULES
from deface.eval.synthetic import make_shadowed_face
from deface.fit import presets
from deface.fit.coarse import can_coarsen, coarse_context, half_size, resample_half, to_half
from deface.fit.config import override
from deface.fit.pipeline import prepare
from deface.fit.stage2 import run_stage2
from deface.fit.target import FitTarget
from deface.models import load_face_model
from deface.render.camera import Camera


@pytest.mark.parametrize("size", [(8, 6), (9, 7), (1, 5)])
def test_resampling_keeps_constants_and_the_mean_of_a_linear_ramp_at_each_centre(size):
    width, height = size
    constant = torch.full((2, height, width, 3), 0.37)
    assert torch.allclose(resample_half(constant), constant[:, : (height + 1) // 2, : (width + 1) // 2])
    # a ramp x + 10 y sampled at working pixel centres; a half-size pixel must hold the ramp at its own centre
    ys, xs = torch.meshgrid(torch.arange(height) + 0.5, torch.arange(width) + 0.5, indexing="ij")
    ramp = (xs + 10 * ys)[None, ..., None].double()
    coarse = resample_half(ramp)[0, ..., 0]
    coarse_w, coarse_h = half_size(size)
    cy, cx = torch.meshgrid(torch.arange(coarse_h) + 0.5, torch.arange(coarse_w) + 0.5, indexing="ij")
    centres = torch.stack([cx, cy], -1)  # half-size pixel centres
    working = (centres - torch.tensor([coarse_w / 2, coarse_h / 2])) * 2 + torch.tensor([width / 2, height / 2])
    expected = working[..., 0] + 10 * working[..., 1]
    inside = ((working[..., 0] >= 1) & (working[..., 0] <= width - 1) & (working[..., 1] >= 1)
              & (working[..., 1] <= height - 1))  # the border replicates: not a ramp there
    assert torch.allclose(coarse[inside], expected[inside].double(), atol=1e-9)


def test_an_even_size_is_a_two_by_two_box_and_an_odd_size_a_tent():
    image = torch.arange(16.0).reshape(1, 4, 4, 1)
    assert torch.allclose(resample_half(image)[0, ..., 0],
                          image[0, ..., 0].reshape(2, 2, 2, 2).mean(dim=(1, 3)))
    row = torch.tensor([0.0, 4.0, 8.0, 0.0, 4.0]).reshape(1, 1, 5, 1)
    out = resample_half(row)[0, 0, :, 0]
    # odd: half-size pixel j sits on working pixel 2j, weights 1/4, 1/2, 1/4; at a border the missing pair of
    # pixels takes the mean of the nearest pair
    assert torch.allclose(out, torch.tensor([(0 + 4) / 2, (4 + 16 + 0) / 4, (0 + 4) / 2]))


@pytest.mark.parametrize("size", [(64, 48), (63, 47)])
def test_half_size_camera_sees_every_point_where_the_mapped_working_pixel_is(size):
    points = torch.tensor([[0.0, 0.0, 0.0], [3.0, -2.0, 1.0], [-5.0, 4.0, -2.0]])
    camera = Camera(torch.tensor(600.0), torch.tensor([np.pi, 0.0, 0.0]), torch.tensor([0.0, 0.0, 50.0]), *size)
    coarse = Camera(torch.tensor(300.0), camera.rotation, camera.translation, *half_size(size))
    assert torch.allclose(coarse.project(points)[0], to_half(camera.project(points)[0], size), atol=1e-4)
    assert np.allclose(to_half(np.array([size[0] / 2, size[1] / 2]), size), np.array(half_size(size)) / 2)


def _context(size: int, **settings):
    face = make_shadowed_face(load_face_model("ict"), size=size, seed=1, rays=8)
    config = override(presets.get("default"), **{**SCHEDULES["smoke"], **settings})
    return prepare(FitTarget([face.image_srgb], [face.landmarks], 1.0), config)[0]


@pytest.mark.slow
def test_the_half_size_level_shares_the_parameters_and_measures_landmarks_in_working_pixels(shared):
    context = _context(48)
    coarse = coarse_context(context)
    assert coarse.scene is context.scene and coarse.decoupling is context.decoupling
    assert coarse.shadow_caches is context.shadow_caches
    assert coarse.target.size == half_size(context.target.size) and coarse.target.images.shape[1:3] == (24, 24)
    with torch.no_grad():
        working = context.inputs.landmarks.loss(context.geometry(0), 0)
        half = coarse.inputs.landmarks.loss(coarse.geometry(0), 0)
    assert float(half) == pytest.approx(float(working), rel=1e-4)
    # f and g are evaluated on the half-size grid: masks of the half-size coverage, summing to 1 where covered
    coverage = coarse.renderer.rasterize(coarse.geometry(0).mesh, coarse.geometry(0).camera).mask
    masks = coarse.decoupling.light_masks(0, coverage)
    assert masks.shape[1:] == coverage.shape and torch.allclose(masks.sum(0), coverage, atol=1e-5)


@pytest.mark.slow
def test_stage2_runs_its_first_steps_at_half_size_then_at_the_working_size(shared):
    context = _context(48, **{"iterations.stage2": 6, "decouple.ace_iteration": 2,
                              "iterations.stage2_coarse_share": 0.5, "iterations.coarse_min_side": 16})
    messages = []
    context.log.info = messages.append
    result = run_stage2(context)
    assert len(result.history) == 6 and all(np.isfinite(result.history))
    assert any("first 3 of 6 steps at half size (24x24" in message for message in messages)
    assert not can_coarsen((48, 48), 32)  # 24 px < 32: no half-size steps
