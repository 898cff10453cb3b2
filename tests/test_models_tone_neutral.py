"""Tone-neutral albedo coefficients (deface/models/tone_neutral.py): after the projection the texture's tone,
measured as the benchmark measures it (median CIELAB over the boxes' texels, a second implementation of the
boxes' colour), is the tone axis's; the change is the least one; what does not move the tone is left alone."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from deface.io.images import linear_to_srgb
from deface.models import load_face_model
from deface.models.ita import texture_ita
from deface.models.tone_neutral import ToneBoxColours, keep_tone_


@pytest.fixture(scope="module")
def albedo(shared):
    return load_face_model("ict").albedo


def measured_ita(albedo, coeffs: torch.Tensor, ita: float) -> float:
    diffuse, _ = albedo.textures(coeffs, 128, torch.tensor(ita))
    return texture_ita(linear_to_srgb(diffuse.numpy()))


def tone_scale(albedo, ita: float) -> torch.Tensor:
    return albedo.tone.scale(torch.tensor(ita))


@pytest.mark.parametrize("ita", [-30.0, 10.0, 60.0])
def test_projected_coefficients_keep_the_measured_tone(albedo, ita):
    colours = ToneBoxColours.of(albedo)
    coeffs = torch.as_tensor(np.random.default_rng(int(ita) + 50).normal(0, 1.0, albedo.num_coeffs),
                             dtype=torch.float32)
    coeffs[albedo.component_names.index("melanin:s0v0")] = 1.5  # a darker skin than the tone says
    reference = measured_ita(albedo, torch.zeros(albedo.num_coeffs), ita)
    assert abs(measured_ita(albedo, coeffs, ita) - reference) > 4  # the coefficients did move the tone
    keep_tone_(coeffs, colours, tone_scale(albedo, ita))
    # the projection holds the ITA of the median colour, the measure that of the median CIELAB
    assert measured_ita(albedo, coeffs, ita) == pytest.approx(reference, abs=0.3)


def test_the_change_is_the_least_one(albedo):
    """Least change onto the constraint: the step is along the tone's gradient at the solution (Lagrange)."""
    colours, scale = ToneBoxColours.of(albedo), tone_scale(albedo, 30.0)
    before = torch.as_tensor(np.random.default_rng(1).normal(0, 0.8, albedo.num_coeffs), dtype=torch.float32)
    before[albedo.component_names.index("brightness:s0v0")] = 2.0
    after = before.clone()
    keep_tone_(after, colours, scale)
    step = (after - before).double().numpy()
    gradient = colours.gradient(after.double().numpy(), scale.double().numpy())
    cosine = abs(step @ gradient) / (np.linalg.norm(step) * np.linalg.norm(gradient))
    assert np.linalg.norm(step) > 0.05 and cosine > 0.99


def test_coefficients_that_keep_the_tone_are_left_alone(albedo):
    colours, scale = ToneBoxColours.of(albedo), tone_scale(albedo, 0.0)
    coeffs = torch.as_tensor(np.random.default_rng(2).normal(0, 0.8, albedo.num_coeffs), dtype=torch.float32)
    keep_tone_(coeffs, colours, scale)
    again = coeffs.clone()
    keep_tone_(again, colours, scale)
    assert torch.allclose(again, coeffs, atol=1e-5)


def test_the_gradient_matches_the_axis_direction(albedo):
    """Independent reference: the constant melanin component darkens (ITA down), brightness lightens."""
    colours = ToneBoxColours.of(albedo)
    gradient = colours.gradient(np.zeros(albedo.num_coeffs), np.ones(3))
    names = albedo.component_names
    assert gradient[names.index("melanin:s0v0")] < -3 and gradient[names.index("brightness:s0v0")] > 0.5
