"""The diffuse map's hues held to the pigments' gamut (deface/texture/pigment_gamut.py)."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from deface.io.images import LUMINANCE
from deface.texture.chroma import log_parts
from deface.texture.pigment_gamut import PigmentGamutConfig, gamut_excess, in_pigment_gamut, outside_share

SIZE = 96
SKIN = np.array([0.45, 0.30, 0.22])
CONFIG = PigmentGamutConfig()
SEEN = np.ones((SIZE, SIZE))


def _skin(seed: int = 0) -> np.ndarray:
    """Skin with a fine luminance texture and a faint chroma texture."""
    rng = np.random.default_rng(seed)
    level = 1.0 + 0.1 * rng.standard_normal((SIZE, SIZE, 1))
    tint = np.exp(0.02 * rng.standard_normal((SIZE, SIZE, 3)))
    return (SKIN * level * tint).astype(np.float32)


def _patch() -> np.ndarray:
    patch = np.zeros((SIZE, SIZE), bool)
    patch[40:56, 30:66] = True
    return patch


def _luminance(image: np.ndarray) -> np.ndarray:
    return image.astype(np.float64) @ np.asarray(LUMINANCE)


def test_a_map_within_the_gamut_is_unchanged():
    """Skin, a dark brown mole, red lips and a grey-white patch are all pigment hues."""
    skin = _skin()
    skin[10:16, 10:16] = [0.08, 0.05, 0.035]  # mole
    skin[70:80, 30:60] = [0.40, 0.12, 0.11]  # lips
    skin[20:30, 70:80] = [0.6, 0.6, 0.6]  # grey hair
    assert (gamut_excess(log_parts(skin)[2]) == 0).all()
    np.testing.assert_array_equal(in_pigment_gamut(skin, SEEN, CONFIG), skin)


def test_a_green_patch_takes_the_skin_chroma_around_it_and_keeps_its_luminance():
    """Sunlight through leaves left on a beard: dark and green in the map."""
    skin, patch = _skin(), _patch()
    spoiled = skin.copy()
    spoiled[patch] = skin[patch] * 0.4 * np.array([0.6, 1.3, 1.0], np.float32)  # dark, teal-green
    out = in_pigment_gamut(spoiled, SEEN, CONFIG)
    np.testing.assert_allclose(_luminance(out), _luminance(spoiled), rtol=1e-5)
    assert (gamut_excess(log_parts(out)[2]) <= 1e-9).all()
    inner = np.zeros_like(patch)
    inner[44:52, 36:60] = True
    skin_chroma = log_parts(skin[~patch])[2].mean(0)
    np.testing.assert_allclose(log_parts(out[inner])[2].mean(0), skin_chroma, atol=0.03)
    np.testing.assert_array_equal(out[~patch], spoiled[~patch])  # the skin itself is not touched


def test_texels_just_outside_move_in_proportion_and_end_inside():
    skin = _skin()
    tinted = skin * np.array([1.0, 1.0, 1.0], np.float32)
    tinted[_patch()] = [0.30, 0.30, 0.305]  # grey with a hint of blue: just outside (v < 0)
    out = in_pigment_gamut(tinted, SEEN, CONFIG)
    excess = gamut_excess(log_parts(tinted)[2])[_patch()]
    assert 0 < excess.max() < CONFIG.ramp
    assert (gamut_excess(log_parts(out)[2]) <= 1e-9).all()
    moved = np.abs(log_parts(out)[2] - log_parts(tinted)[2]).max(-1)[_patch()]
    assert moved.max() < 0.2  # a share of the way, not all of it
    np.testing.assert_allclose(_luminance(out), _luminance(tinted), rtol=1e-5)


def test_a_face_all_outside_goes_to_the_gamut_edge_and_a_second_pass_changes_nothing():
    """No in-gamut texel to take chroma from (a whole map under a blue light): the edge of the gamut."""
    blue = (_skin() * np.array([0.5, 1.0, 2.5], np.float32)).astype(np.float32)
    once = in_pigment_gamut(blue, SEEN, CONFIG)
    assert (gamut_excess(log_parts(once)[2]) <= 1e-9).all()
    np.testing.assert_allclose(_luminance(once), _luminance(blue), rtol=1e-5)
    np.testing.assert_array_equal(in_pigment_gamut(once, SEEN, CONFIG), once)


def test_unseen_texels_give_no_chroma_and_black_texels_stay_black():
    skin, patch = _skin(), _patch()
    spoiled = skin.copy()
    spoiled[patch] *= np.array([0.6, 1.3, 1.0], np.float32)
    seen = SEEN.copy()
    seen[:, :48] = 0  # the left half unseen: its skin may not colour the patch
    spoiled[:, :48] = [0.5, 0.2, 0.1]  # an unseen, very red left half
    spoiled[0:4, 0:4] = 0.0  # outside the layout
    out = in_pigment_gamut(spoiled, seen, CONFIG)
    right = patch.copy()
    right[:, :56] = False
    u = np.log(out[right][:, 0] / out[right][:, 1])
    assert np.abs(u.mean() - np.log(SKIN[0] / SKIN[1])) < 0.05  # the seen skin's red, not the unseen half's
    np.testing.assert_array_equal(out[0:4, 0:4], 0.0)


def test_the_window_takes_the_skin_not_the_fringe_just_inside_the_gamut():
    """A green patch ringed by olive texels (red = green: on the gamut's edge) takes the skin's chroma beyond."""
    skin, patch = _skin(), _patch()
    spoiled = skin.copy()
    ring = ndimage.binary_dilation(patch, iterations=2) & ~patch
    spoiled[ring] = skin[ring].mean(-1, keepdims=True) * np.array([1.0, 1.0, 0.6], np.float32)  # olive: u = 0
    spoiled[patch] = skin[patch] * 0.4 * np.array([0.6, 1.3, 1.0], np.float32)
    out = in_pigment_gamut(spoiled, SEEN, PigmentGamutConfig(radius=0.05))  # a window wider than patch and ring
    inner = np.zeros_like(patch)
    inner[44:52, 36:60] = True
    red_over_green = np.log(out[inner][:, 0] / out[inner][:, 1]).mean()
    assert abs(red_over_green - np.log(SKIN[0] / SKIN[1])) < 0.05  # the skin's, not the ring's 0


def test_the_share_outside_counts_seen_texels_only():
    skin, patch = _skin(), _patch()
    assert outside_share(skin, SEEN) == 0.0
    spoiled = skin.copy()
    spoiled[patch] *= np.array([0.6, 1.3, 1.0], np.float32)
    assert outside_share(spoiled, SEEN) == patch.mean()
    seen = SEEN.copy()
    seen[patch] = 0
    assert outside_share(spoiled, seen) == 0.0
    assert outside_share(spoiled, np.zeros_like(SEEN)) == 0.0
