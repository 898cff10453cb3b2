"""Stage 2's pixel weights from the photo's fine texture (deface/priors/shading_evidence.py): shading leaves them
as they are, hair-like texture lowers them, a cast shadow's edge only along a thin band."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy import ndimage

from deface.priors.shading_evidence import ShadingEvidenceConfig, coherence, texture_weight

SIZE, FACE_SIZE = 160, 150.0
CONFIG = ShadingEvidenceConfig(strength=3.0, edges_as_shading=True)


def _skin(seed: int = 0) -> np.ndarray:
    """Linear skin with a faint pore-scale texture (2 % in luminance)."""
    rng = np.random.default_rng(seed)
    texture = 1.0 + 0.02 * ndimage.gaussian_filter(rng.standard_normal((SIZE, SIZE)), 0.7)
    return np.array([0.5, 0.35, 0.25]) * texture[..., None]


FACE = np.ones((SIZE, SIZE))


def test_off_weighs_every_pixel_alike():
    assert np.all(texture_weight(_skin(), FACE, FACE_SIZE, ShadingEvidenceConfig(strength=0.0)) == 1.0)


def test_smooth_shading_does_not_change_the_weight():
    """A light's smooth shading (a gradient across the face, three stops) multiplies the skin: same weights."""
    ramp = np.exp(np.linspace(-1.0, 1.0, SIZE))[None, :, None] * np.exp(np.linspace(-0.5, 0.5, SIZE))[:, None, None]
    plain, shaded = (texture_weight(image, FACE, FACE_SIZE, CONFIG) for image in (_skin(), _skin() * ramp))
    inner = (slice(24, -24),) * 2  # the image border aside: the step term's window (3 b) reaches beyond it
    np.testing.assert_allclose(shaded[inner], plain[inner], atol=0.03)
    assert plain.mean() > 0.6


def _bearded_and_shadowed() -> np.ndarray:
    image = _skin()
    rng = np.random.default_rng(1)
    beard = (slice(90, 140), slice(50, 110))
    strokes = rng.random((50, 60)) < 0.4  # dark strokes over half the patch: a beard's texture
    image[beard] *= np.where(strokes, 0.15, 1.0)[..., None]
    shadow = np.ones((SIZE, SIZE))
    shadow[:60, :] = 0.3  # a brim's shadow over the top, a sharp edge at row 60
    return image * shadow[..., None]


BAND = np.abs(np.arange(SIZE) - 60) <= 3  # the shadow's edge and a few pixels either side


def test_hair_texture_is_weighed_down_and_a_shadow_s_sharp_edge_keeps_its_weight():
    weight = texture_weight(_bearded_and_shadowed(), FACE, FACE_SIZE, CONFIG)
    assert weight[100:130, 60:100].mean() < 0.05  # inside the beard
    assert weight[10:50, 20:140].mean() > 0.6  # inside the shadow, as on lit skin
    assert weight[BAND][:, 20:140].mean() > 0.6  # along the edge: a step of log luminance is shading
    assert weight[70:85, 20:40].mean() > 0.6  # lit skin below the edge


def test_without_the_step_term_a_shadow_s_edge_is_weighed_down_like_hair():
    """The step term is what keeps the edge: without it the edge's fine energy counts as texture."""
    image = _bearded_and_shadowed()
    plain = texture_weight(image, FACE, FACE_SIZE, ShadingEvidenceConfig(strength=3.0, edges_as_shading=False))
    assert plain[BAND][:, 20:140].mean() < 0.2
    assert plain[100:130, 60:100].mean() < 0.05


def test_the_step_ratio_takes_an_ideal_step_s_energy_at_the_step():
    """k is the step's fine energy over its windowed gradient energy: on a pure step of any height, the
    energy left at the step is zero."""
    for height in (0.5, 2.0):
        log_luminance = np.where(np.arange(SIZE) >= SIZE // 2, height, 0.0)[None, :] * np.ones((SIZE, 1))
        image = np.exp(log_luminance)[..., None] * np.array([0.5, 0.35, 0.25])
        weight = texture_weight(image, FACE, FACE_SIZE, CONFIG)
        assert weight[40:120, SIZE // 2 - 1:SIZE // 2 + 1].min() > 0.9


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


def test_the_strength_sets_how_fast_the_weight_falls_with_the_face_s_typical_texture():
    """The scale is the face's median texture energy, steps and all: a stronger setting (smaller strength)
    lowers plain skin's weight smoothly, it does not turn the weight into a yes/no mask."""
    image = _bearded_and_shadowed()
    strong, mild = (texture_weight(image, FACE, FACE_SIZE, replace(CONFIG, strength=s)) for s in (0.75, 3.0))
    skin = (slice(10, 50), slice(20, 140))
    assert 0.2 < strong[skin].mean() < mild[skin].mean() < 0.95


def test_coherence_is_one_along_an_edge_and_low_in_scattered_strokes():
    rows = np.arange(SIZE)[:, None] * np.ones((1, SIZE))
    edge = np.where(rows >= SIZE // 2, 1.0, 0.0)
    fine = edge - ndimage.gaussian_filter(edge, 2.0)
    along = coherence(fine, 4.0)[SIZE // 2 - 2:SIZE // 2 + 2, 20:-20]
    assert along.min() > 0.99
    strokes = ndimage.gaussian_filter(np.random.default_rng(3).standard_normal((SIZE, SIZE)), 0.7)
    assert np.median(coherence(strokes - ndimage.gaussian_filter(strokes, 2.0), 4.0)) < 0.3


def test_with_coherence_a_shadow_s_edge_keeps_its_weight_and_a_beard_does_not():
    """The scattered strokes' energy stays texture; the straight edge's is taken off as shading (without the
    step term)."""
    image = _bearded_and_shadowed()
    weight = texture_weight(image, FACE, FACE_SIZE, ShadingEvidenceConfig(strength=3.0, coherence_power=2.0))
    assert weight[BAND][:, 20:140].mean() > 0.6
    assert weight[100:130, 60:100].mean() < 0.05
    assert weight[70:85, 20:40].mean() > 0.6


def test_the_hair_zone_keeps_a_beard_weighed_down_and_a_forehead_s_stripes_weighed(photos):
    """nextface-s1 with thin dark stripes drawn over its forehead: with the evidence everywhere on the face both the
    stripes' edges and the stubble are weighed down; with ``hair_zone`` (the default) the stubble (in the beard's
    reach) still is, the forehead's stripes count as every pixel does."""
    from deface.io.images import load_image, srgb_to_linear
    from deface.landmarks.detect import detect_landmarks
    from deface.priors.face_region import MEDIAPIPE_CHIN, beard_zone_mask

    image = srgb_to_linear(load_image(photos / "nextface-s1.png"))
    points = detect_landmarks(load_image(photos / "nextface-s1.png")).points[:, :2]
    size = float(np.hypot(*np.ptp(points, axis=0)))
    brow, top = points[[105, 334], 1].min(), points[10, 1]  # the brows' tops, the forehead's top
    rows = slice(int(top + 0.2 * (brow - top)), int(brow - 0.15 * (brow - top)))
    columns = np.arange(image.shape[1])
    stripes = np.where((columns // 4) % 2 == 0, 0.35, 1.0)  # 4-pixel stripes of shade
    image[rows] *= stripes[None, :, None]
    face = ndimage.binary_dilation(beard_zone_mask(points, image.shape[:2]), iterations=40).astype(float)
    face[rows] = 1.0
    forehead = (slice(rows.start, int(brow - 0.5 * (brow - top))), slice(int(points[105, 0]), int(points[334, 0])))
    chin = np.round(points[MEDIAPIPE_CHIN]).astype(int)
    beard = (slice(chin[1] - 25, chin[1] - 5), slice(chin[0] - 20, chin[0] + 20))
    config = ShadingEvidenceConfig()
    everywhere = texture_weight(image, face, size, replace(config, hair_zone=-1.0), points)
    zoned = texture_weight(image, face, size, config, points)
    assert everywhere[forehead].mean() < 0.5 and zoned[forehead].min() > 0.99
    np.testing.assert_allclose(zoned[beard], everywhere[beard])
    assert zoned[beard].mean() < 0.75  # the stubble is still weighed down
