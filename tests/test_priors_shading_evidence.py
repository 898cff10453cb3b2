"""Stage 2's pixel weights from the photo's fine texture (deface/priors/shading_evidence.py): shading leaves them
as they are, hair-like texture lowers them, a cast shadow's edge only along a thin band."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from deface.priors.shading_evidence import ShadingEvidenceConfig, texture_weight

SIZE, FACE_SIZE = 160, 150.0
CONFIG = ShadingEvidenceConfig(strength=3.0)


def _skin(seed: int = 0) -> np.ndarray:
    """Linear skin with a faint pore-scale texture (2 % in luminance)."""
    rng = np.random.default_rng(seed)
    texture = 1.0 + 0.02 * ndimage.gaussian_filter(rng.standard_normal((SIZE, SIZE)), 0.7)
    return np.array([0.5, 0.35, 0.25]) * texture[..., None]


FACE = np.ones((SIZE, SIZE))


def test_off_weighs_every_pixel_alike():
    assert np.all(texture_weight(_skin(), FACE, FACE_SIZE, ShadingEvidenceConfig()) == 1.0)


def test_smooth_shading_does_not_change_the_weight():
    """A light's smooth shading (a gradient across the face, three stops) multiplies the skin: same weights."""
    ramp = np.exp(np.linspace(-1.0, 1.0, SIZE))[None, :, None] * np.exp(np.linspace(-0.5, 0.5, SIZE))[:, None, None]
    plain, shaded = (texture_weight(image, FACE, FACE_SIZE, CONFIG) for image in (_skin(), _skin() * ramp))
    np.testing.assert_allclose(shaded[8:-8, 8:-8], plain[8:-8, 8:-8], atol=0.02)  # (the image border aside)
    assert plain.mean() > 0.6


def test_hair_texture_is_weighed_down_and_shadow_edges_only_along_a_band():
    image = _skin()
    rng = np.random.default_rng(1)
    beard = (slice(90, 140), slice(50, 110))
    strokes = rng.random((50, 60)) < 0.4  # dark strokes over half the patch: a beard's texture
    image[beard] *= np.where(strokes, 0.15, 1.0)[..., None]
    shadow = np.ones((SIZE, SIZE))
    shadow[:60, :] = 0.3  # a brim's shadow over the top, a sharp edge at row 60
    image = image * shadow[..., None]
    weight = texture_weight(image, FACE, FACE_SIZE, CONFIG)
    assert weight[100:130, 60:100].mean() < 0.05  # inside the beard
    assert weight[10:50, 20:140].mean() > 0.6  # inside the shadow, as on lit skin
    band = np.abs(np.arange(SIZE) - 60) <= 3  # the edge lowers a band of a few pixels
    assert weight[band][:, 20:140].mean() < weight[10:50, 20:140].mean()
    assert weight[70:85, 20:40].mean() > 0.6  # lit skin below the band


@pytest.mark.parametrize("scale", [0.5, 2.0])
def test_weights_follow_the_face_size(scale):
    """The same face drawn at another size, with its size given, gets the same weights (resampled)."""
    image = _skin()
    image[60:100, 60:100] *= np.where(np.random.default_rng(2).random((40, 40)) < 0.4, 0.15, 1.0)[..., None]
    base = texture_weight(image, FACE, FACE_SIZE, CONFIG)
    resized = ndimage.zoom(image, (scale, scale, 1), order=1)
    other = texture_weight(resized, np.ones(resized.shape[:2]), FACE_SIZE * scale, CONFIG)
    back = ndimage.zoom(other, 1 / scale, order=1)[:SIZE, :SIZE]
    assert abs(back[65:95, 65:95].mean() - base[65:95, 65:95].mean()) < 0.1
