"""Texels in the dark take the lit skin's level and colour around them (deface/texture/shade_level.py)."""

from __future__ import annotations

import numpy as np
import pytest

from deface.io.images import LUMINANCE
from deface.texture.shade_level import ShadeLevelConfig, lit_share, shade_levelled

SIZE = 128
SKIN = np.array([0.45, 0.30, 0.22])
CONFIG = ShadeLevelConfig(enabled=True)


def _skin(seed: int = 0) -> np.ndarray:
    """Skin with a fine luminance texture (a texel's own detail)."""
    texture = 1.0 + 0.08 * np.random.default_rng(seed).standard_normal((SIZE, SIZE))
    return (SKIN * texture[..., None]).astype(np.float32)


def _patch() -> np.ndarray:
    """A band about as tall as the lit window's sigma (3.8 texels here), as the lids' crescents are at 512²."""
    patch = np.zeros((SIZE, SIZE), bool)
    patch[60:66, 44:84] = True
    return patch


def _inner() -> np.ndarray:
    inner = np.zeros((SIZE, SIZE), bool)
    inner[61:65, 48:80] = True  # away from the band's ends, where the windows mix
    return inner


def _luminance(image: np.ndarray) -> np.ndarray:
    return image @ np.asarray(LUMINANCE)


def _dark(patch: np.ndarray) -> np.ndarray:
    return np.where(patch, 0.0, 1.0)


def test_lit_everywhere_changes_nothing():
    skin = _skin()
    out = shade_levelled(skin, np.ones((SIZE, SIZE)), np.ones((SIZE, SIZE)), CONFIG)
    np.testing.assert_allclose(out, skin, rtol=1e-5)


def test_a_bright_tinted_patch_in_the_dark_takes_the_skin_around_it_and_keeps_its_detail():
    skin, patch = _skin(), _patch()
    spoiled = skin.copy()
    spoiled[patch] *= np.array([1.6, 1.5, 1.1], np.float32)  # brighter and yellower: the masks' error
    out = shade_levelled(spoiled, _dark(patch), np.ones((SIZE, SIZE)), CONFIG)
    inner = _inner()
    ratio = out[inner].mean(0) / skin[inner].mean(0)
    assert np.abs(ratio - 1).max() < 0.05, ratio  # level and colour of the skin around
    detail_before = np.log(_luminance(spoiled[inner]))
    detail_after = np.log(_luminance(out[inner]))
    correlation = np.corrcoef(detail_before, detail_after)[0, 1]
    assert correlation > 0.95  # the texels' own texture is kept
    assert np.std(detail_after) == pytest.approx(np.std(detail_before), rel=0.1)
    far = np.ones_like(patch)
    far[30:100, 20:110] = False
    np.testing.assert_allclose(out[far], spoiled[far], rtol=1e-5)  # lit skin far from it: unchanged


def test_a_dark_patch_in_the_dark_keeps_its_darkness_and_only_its_colour_moves():
    skin, patch = _skin(), _patch()
    mole = skin.copy()
    mole[patch] *= np.array([0.5, 0.45, 0.45], np.float32)  # darker: may be pigment under a shade
    out = shade_levelled(mole, _dark(patch), np.ones((SIZE, SIZE)), CONFIG)
    assert np.all(_luminance(out) <= _luminance(mole) * (1 + 1e-4))  # never brightened
    inner = _inner()
    assert _luminance(out[inner]).mean() == pytest.approx(_luminance(mole[inner]).mean(), rel=0.02)


def test_a_shadow_wider_than_the_window_is_left_as_it_is():
    skin = _skin()
    half = np.zeros((SIZE, SIZE), bool)
    half[:, : SIZE // 2] = True
    spoiled = skin.copy()
    spoiled[half] *= np.array([1.5, 1.4, 1.0], np.float32)
    out = shade_levelled(spoiled, _dark(half), np.ones((SIZE, SIZE)), CONFIG)
    deep = np.zeros_like(half)
    deep[:, :20] = True  # more than three windows from any lit texel
    np.testing.assert_allclose(out[deep], spoiled[deep], rtol=1e-4)


def test_lit_share_is_relative_to_the_faces_median_and_smooth():
    light = np.full((SIZE, SIZE), 0.6)
    light[50:80, 50:80] = 0.1  # a sixth of the median: dark
    lit = lit_share(light, np.ones((SIZE, SIZE)), CONFIG)
    assert lit[65, 65] < 0.05 and lit[5, 5] == pytest.approx(1.0)
    assert np.abs(np.diff(lit, axis=1)).max() < 0.5  # the step where the shading steps is spread over texels
    np.testing.assert_allclose(lit_share(2 * light, np.ones((SIZE, SIZE)), CONFIG), lit, atol=1e-6)
    unseen = lit_share(light, np.zeros((SIZE, SIZE)), CONFIG)
    assert np.all(unseen == 1.0)  # nothing seen: completion's business
