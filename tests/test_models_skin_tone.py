"""The skin-tone axis: it spans the human range, its prior is flat, and it is differentiable."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from deface.models.albedo_prior import JENSEN2001_SKIN1_RD, JENSEN2001_SKIN2_RD, AlbedoPriorConfig
from deface.models.ita import ita_of_srgb
from deface.models.skin_tone import SkinToneAxis

AXIS = SkinToneAxis.through(AlbedoPriorConfig().skin_rgb)


def test_axis_passes_through_the_reference_skin():
    reference = AXIS.linear_rgb(torch.tensor(AXIS.reference_ita))
    assert reference.numpy() == pytest.approx(np.array(AlbedoPriorConfig().skin_rgb), abs=2e-3)
    assert AXIS.scale(torch.tensor(AXIS.reference_ita)).numpy() == pytest.approx(np.ones(3), abs=1e-5)


@pytest.mark.parametrize("ita", [-50.0, -30.0, 0.0, 30.0, 55.0, 70.0])
def test_axis_spans_the_human_range(ita):
    """A colour taken from the axis at ITA x measures ITA x (sRGB-encoded as the textures are written)."""
    rgb = AXIS.linear_rgb(torch.tensor(ita)).numpy()
    assert ita_of_srgb((rgb ** (1 / 2.2))[None]) == pytest.approx(ita, abs=1.0)


def test_tones_are_ordered_and_cover_jensens_samples():
    itas = torch.linspace(AXIS.min_ita, AXIS.max_ita, 50)
    luminance = AXIS.linear_rgb(itas) @ torch.tensor([0.2126, 0.7152, 0.0722])
    assert (luminance.diff() > 0).all()  # lighter with ITA
    for sample in (JENSEN2001_SKIN1_RD, JENSEN2001_SKIN2_RD):
        ita = ita_of_srgb((np.array(sample) ** (1 / 2.2))[None])
        assert AXIS.min_ita < ita < AXIS.max_ita


def test_axis_gradient_matches_finite_differences():
    ita = torch.tensor(12.3, dtype=torch.float64, requires_grad=True)
    weights = torch.tensor([0.3, -0.5, 0.9], dtype=torch.float64)
    (AXIS.linear_rgb(ita) @ weights).backward()
    step = 0.01
    value = lambda x: float(AXIS.linear_rgb(torch.tensor(x, dtype=torch.float64)) @ weights)  # noqa: E731
    numeric = (value(12.3 + step) - value(12.3 - step)) / (2 * step)
    assert float(ita.grad) == pytest.approx(numeric, rel=1e-3)




def test_albedo_model_moves_the_diffuse_map_along_the_axis(shared):
    from deface.models import load_face_model

    albedo = load_face_model("ict").albedo
    coeffs = torch.zeros(albedo.num_coeffs)
    base, _ = albedo.textures(coeffs, 64)
    dark, specular = albedo.textures(coeffs, 64, torch.tensor(-20.0))
    ratio = dark / base.clamp_min(1e-6)
    expected = AXIS.scale(torch.tensor(-20.0))
    assert ratio[20:40, 20:40].reshape(-1, 3).median(0).values.numpy() == pytest.approx(expected.numpy(), rel=1e-3)
    assert specular.numpy() == pytest.approx(albedo.textures(coeffs, 64)[1].numpy())  # specular unchanged


def test_tone_is_projected_into_the_range():
    tone = torch.tensor(200.0)
    AXIS.clamp_(tone)
    assert float(tone) == AXIS.max_ita
    AXIS.clamp_(tone, (-50.0, 72.0))
    assert float(tone) == 72.0


def test_the_registry_knows_which_models_have_a_tone_axis(shared):
    from deface.models import load_face_model
    from deface.models.registry import TONE_AXIS

    assert TONE_AXIS["ict"] and load_face_model("ict").albedo.tone is not None
    assert not TONE_AXIS["bfm"]  # AlbedoMM (docs/bfm.md); its files are not here to load
