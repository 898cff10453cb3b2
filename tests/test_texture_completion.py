"""Texture completion: every face texel finite and in range, mirror fill of a half-seen face, the person's
colour on unseen skin, a dark cavity, and trusted texels kept as fitted."""

from __future__ import annotations

import numpy as np
import pytest

from deface.models.ict import load_ict
from deface.texture.completion import CompletionConfig, complete_map, layout_regions, mirror_fill, trust_map

SIZE = 128


@pytest.fixture(scope="module")
def regions(shared):
    return layout_regions(load_ict(), SIZE)


def _prior(regions) -> np.ndarray:
    """A light prior skin with darker lips (T^0 stand-in)."""
    prior = np.full((SIZE, SIZE, 3), [0.6, 0.45, 0.4])
    prior[regions.lips] = [0.5, 0.25, 0.25]
    return prior


def _person(regions, rng) -> np.ndarray:
    """A darker person with texel detail, symmetric in u except for a mole on the left cheek."""
    skin = np.array([0.3, 0.18, 0.12]) * (1 + 0.1 * rng.standard_normal((SIZE, SIZE, 1)))
    skin = 0.5 * (skin + skin[:, ::-1])
    skin[60:63, 30:33] = [0.1, 0.06, 0.04]
    skin[regions.lips] = [0.25, 0.1, 0.1]
    return skin


def test_layout_regions_of_the_ict_model(regions):
    assert regions.symmetric
    assert regions.cavity.any() and (regions.cavity <= regions.lips).all() and (regions.lips <= regions.face).all()


def test_completion_fills_every_face_texel_finitely_in_range(regions):
    rng = np.random.default_rng(0)
    fitted = rng.uniform(-0.2, 1.2, (SIZE, SIZE, 3))  # even out-of-range fitted values
    seen = rng.uniform(0, 1, (SIZE, SIZE)) * (rng.uniform(size=(SIZE, SIZE)) > 0.5)
    completed = complete_map(fitted, _prior(regions), seen, regions, CompletionConfig(enabled=True), cavity=True)
    face = completed[regions.face]
    assert np.isfinite(face).all() and face.min() >= 0 and face.max() <= 1


def test_a_half_seen_face_is_mirrored_and_the_rest_takes_the_persons_colour(regions):
    rng = np.random.default_rng(1)
    person, prior = _person(regions, rng), _prior(regions)
    seen = np.zeros((SIZE, SIZE))
    seen[:, : SIZE // 2] = 1.0  # a face turned so that only the left half of the UV map was seen
    seen[:20] = 0.0  # and the forehead under hair on both sides
    fitted = np.where(seen[..., None] > 0, person, prior)  # stage 3 leaves unseen texels at T^0
    config = CompletionConfig(enabled=True)
    completed = complete_map(fitted, prior, seen, regions, config, cavity=True)
    right = regions.face.copy()
    right[:, : SIZE // 2 + 6] = False  # away from the seam the trust blur spans
    right[:26] = False
    right &= ~regions.lips
    np.testing.assert_allclose(completed[right], person[:, ::-1][right], atol=1e-6)  # mirrored exactly
    top = regions.face[:12]
    gain = np.median(person[regions.face & ~regions.lips & (seen > 0)] / prior[regions.face & ~regions.lips
                                                                               & (seen > 0)], 0)
    np.testing.assert_allclose(np.median(completed[:12][top], 0), prior[0, 0] * gain, rtol=0.05)
    kept = (trust_map(seen, config) >= 1.0)
    np.testing.assert_allclose(completed[kept], np.clip(fitted[kept], 0, 1), atol=1e-6)  # trusted: as fitted


def test_an_unseen_mouth_cavity_is_darker_than_the_lips(regions):
    rng = np.random.default_rng(2)
    person, prior = _person(regions, rng), _prior(regions)
    seen = np.where(regions.cavity, 0.0, 1.0)  # closed mouth: the lips' inner rolls are hidden
    completed = complete_map(person, prior, seen, regions, CompletionConfig(enabled=True), cavity=True)
    deep = regions.cavity & (trust_map(seen, CompletionConfig()) < 0.05)
    assert deep.any()
    lips = regions.lips & ~regions.cavity
    assert (completed[deep].mean(0) < 0.5 * completed[lips].mean(0)).all()
    assert completed[deep][:, 0].mean() > completed[deep][:, 2].mean()  # red, not grey


def test_mirror_fill_moves_towards_the_better_seen_side():
    texture = np.zeros((4, 4, 1))
    texture[:, :2] = 1.0
    trust = np.zeros((4, 4))
    trust[:, :2] = 1.0
    filled, new_trust = mirror_fill(texture, trust)
    np.testing.assert_allclose(filled[..., 0], 1.0)
    np.testing.assert_allclose(new_trust, 1.0)
