"""The maths of benchmarks/occluder_truth.py (a fitted map's darkness and colour error under an occluder) on small
hand-built maps with known answers."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

_PATH = Path(__file__).resolve().parents[1] / "benchmarks" / "occluder_truth.py"
_SPEC = importlib.util.spec_from_file_location("occluder_truth", _PATH)
occluder_truth = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(occluder_truth)

S = 64
SKIN = np.array([0.5, 0.35, 0.25])
OCCLUDER = np.array([0.03, 0.02, 0.014])  # dark-brown hair


def _box(top, left, height, width) -> np.ndarray:
    mask = np.zeros((S, S), bool)
    mask[top:top + height, left:left + width] = True
    return mask


REGION = _box(30, 10, 3, 40)  # a strand across the map
REFERENCE = _box(2, 2, 10, 20)  # plain skin, far from it


def _scene(light: np.ndarray | None = None):
    """(truth, photo, ring): skin with a brow a little darker under part of the strand (the truth's own darkness),
    the photo that albedo under ``light`` [S, S] (default uniform 0.7) with the strand over it."""
    rng = np.random.default_rng(0)
    truth = SKIN * rng.uniform(0.97, 1.03, (S, S, 1))
    truth[_box(29, 10, 5, 15)] *= 0.8
    light = np.full((S, S), 0.7) if light is None else light
    photo = truth * light[..., None]
    photo[REGION] = OCCLUDER * light[REGION][:, None]
    ring = occluder_truth.skin_ring(REGION, np.zeros((S, S), bool))
    return truth, photo, ring, light


def test_a_map_equal_to_the_truth_has_no_colour_error_and_the_truths_darkness():
    truth, photo, ring, _ = _scene()
    figures = occluder_truth.region_figures(truth.copy(), truth, photo, REGION, ring, REFERENCE)
    assert figures["colour_error"] == pytest.approx(0.0, abs=1e-9)
    assert figures["darkness"] == pytest.approx(figures["darkness_truth"], abs=1e-12)
    assert 0.0 < figures["darkness_truth"] < 0.2  # the brow under part of the strand: a little, not the strand


def test_a_map_that_paints_the_occluder_in_is_as_dark_as_it():
    truth, photo, ring, light = _scene()
    painted = photo / light[..., None]  # the photo over a perfectly recovered light: the strand baked in
    figures = occluder_truth.region_figures(painted, truth, photo, REGION, ring, REFERENCE)
    assert figures["darkness"] == pytest.approx(1.0, abs=1e-9)
    assert figures["colour_error"] == pytest.approx(figures["colour_error_photo"], rel=1e-9)
    assert figures["colour_error"] > 1.0  # dark brown is a little off the skin's hue at the skin's lightness


def test_painted_under_a_light_that_varies_is_near_one():
    truth, photo, ring, _ = _scene(np.linspace(0.5, 0.9, S)[None, :].repeat(S, 0))
    figures = occluder_truth.region_figures(photo / 0.7, truth, photo, REGION, ring, REFERENCE)
    assert figures["darkness"] == pytest.approx(1.0, abs=0.05)


def test_a_map_of_plain_skin_has_no_darkness():
    truth, photo, ring, _ = _scene()
    clean = np.broadcast_to(SKIN, (S, S, 3)).copy()
    figures = occluder_truth.region_figures(clean, truth, photo, REGION, ring, REFERENCE)
    assert figures["darkness"] == pytest.approx(0.0, abs=1e-12)


def test_darkness_is_undefined_under_an_occluder_as_light_as_the_skin():
    """A clear lens: the photo shows the skin through it at the ring's level."""
    truth, _, ring, _ = _scene()
    photo = np.broadcast_to(SKIN * 0.7, (S, S, 3))
    assert np.isnan(occluder_truth.darkness(truth, REGION, ring, occluder_truth.contrast(photo, REGION, ring)))


def test_skin_ring_leaves_out_the_region_and_the_excluded_and_widens_until_it_holds_enough():
    region = np.zeros((S, S), bool)
    region[32, 32] = True
    # 48 texels lie within 4 of one texel, 80 within 5: a ring that must hold 50 is 5 wide
    ring = occluder_truth.skin_ring(region, np.zeros((S, S), bool), width=4, least=50)
    assert ring.sum() == 80 and not ring[32, 32]
    excluded = np.zeros((S, S), bool)
    excluded[:32] = True
    ring = occluder_truth.skin_ring(region, excluded, width=4, least=10)
    assert ring.sum() > 10 and not (ring & excluded).any() and ring[36, 32] and not ring[37, 32]


def test_photo_at_score_size_averages_the_seen_texels_of_each_block():
    photo = np.arange(4 * 4 * 3, dtype=float).reshape(4, 4, 3)
    seen = np.ones((4, 4), bool)
    seen[0, 0] = False
    seen[2:, 2:] = False
    small = occluder_truth.photo_at_score_size(photo, seen, size=2)
    np.testing.assert_allclose(small[0, 0], (photo[0, 1] + photo[1, 0] + photo[1, 1]) / 3)
    np.testing.assert_allclose(small[0, 1], photo[:2, 2:].mean((0, 1)))
    assert np.isnan(small[1, 1]).all()


def test_grown_darkness_counts_a_painted_occluder_a_little_off_its_place():
    """The fit's map puts the strand 2 texels lower than the truth's mask: D misses most of it, D+ (within 3
    texels) counts all of it; a map equal to the truth has the truth's D+."""
    truth, _, _, _ = _scene()
    nothing = np.zeros((S, S), bool)
    wider = occluder_truth.grown(REGION, nothing, width=3)
    # 3 rows either side; each end 7, 7 and 3 texels in the columns 1, 2 and 3 texels out (Euclidean distance <= 3)
    assert wider.sum() == (3 + 2 * 3) * 40 + 2 * (7 + 7 + 3)
    ring = occluder_truth.skin_ring(wider, nothing)
    level = truth[ring].mean(0)
    flat = truth.copy()
    flat[wider | REGION] = level  # plain skin where the strand and its margin are: no brow under it
    shifted = flat.copy()
    shifted[np.roll(REGION, 2, axis=0)] = OCCLUDER
    photo = flat * 0.7
    photo[REGION] = OCCLUDER * 0.7
    figures = occluder_truth.region_figures(shifted, flat, photo, REGION, ring, REFERENCE, wider)
    assert figures["darkness"] < 0.5
    assert figures["grown_darkness"] == pytest.approx(1.0, abs=0.03)
    same = occluder_truth.region_figures(flat, flat, photo, REGION, ring, REFERENCE, wider)
    assert same["grown_darkness"] == pytest.approx(same["grown_darkness_truth"], abs=1e-12)
    assert same["grown_darkness"] == pytest.approx(0.0, abs=0.03)


def test_grown_region_stays_out_of_what_is_blocked():
    blocked = np.zeros((S, S), bool)
    blocked[:31] = True  # e.g. the occluder's other part, above the strand
    wider = occluder_truth.grown(REGION, blocked, width=3)
    assert (wider & REGION).sum() == REGION.sum() and not (wider & blocked & ~REGION).any()
    assert wider[35, 20] and not wider[36, 20]


def test_plain_skin_leaves_out_a_brow_and_keeps_the_skin():
    truth, _, _, _ = _scene()
    plain = occluder_truth.plain_skin(truth, REFERENCE)
    assert not plain[_box(29, 10, 5, 15)].any() and plain[_box(40, 10, 10, 40)].all()


def test_a_clear_occluder_has_no_darkness_but_a_colour_error():
    truth, photo, ring, _ = _scene()
    figures = occluder_truth.region_figures(truth * 1.1, truth, photo, REGION, ring, REFERENCE, clear=True)
    assert np.isnan(figures["darkness"]) and np.isnan(figures["darkness_truth"])
    assert figures["colour_error"] == pytest.approx(0.0, abs=1e-9)


def test_a_given_photo_contrast_is_used_as_it_is():
    """A mirrored region's photo shows skin; its darkness is measured against its occluder's contrast."""
    truth, photo, ring, _ = _scene()
    painted = truth.copy()
    painted[REGION] = painted[ring].mean(0) * 0.4  # 60 % darker than the skin around it
    figures = occluder_truth.region_figures(painted, truth, truth * 0.7, REGION, ring, REFERENCE, photo_contrast=0.4)
    assert figures["photo_contrast"] == 0.4
    assert figures["darkness"] == pytest.approx(1.0, abs=0.01)
