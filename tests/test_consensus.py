"""The frames' consensus on the diffuse map's luminance (deface/texture/consensus.py)."""

from __future__ import annotations

import numpy as np
import pytest

from deface.texture.consensus import ConsensusConfig, consensus_gain, frame_ratios, weighted_quantile

SIZE = 64


def test_weighted_quantile_with_equal_weights_is_numpys_midpoint_quantile():
    values = np.random.default_rng(0).random((5, 7, 3))
    for quantile in (0.1, 0.5, 0.75, 0.95):
        np.testing.assert_allclose(weighted_quantile(values, np.ones_like(values), quantile),
                                   np.quantile(values, quantile, axis=0, method="hazen"), atol=1e-12)


def test_weighted_quantile_ignores_unweighted_values_and_the_weights_scale():
    rng = np.random.default_rng(1)
    values = rng.random((4, 50))
    weights = np.array([2.0, 0.0, 1.0, 1.5])[:, None] * np.ones((4, 50))
    kept = [0, 2, 3]
    np.testing.assert_allclose(weighted_quantile(values, weights, 0.6),
                               weighted_quantile(values[kept], weights[kept], 0.6), atol=1e-12)
    np.testing.assert_allclose(weighted_quantile(values, 7.0 * weights, 0.6),
                               weighted_quantile(values, weights, 0.6), atol=1e-12)
    assert np.isnan(weighted_quantile(values, np.zeros_like(values), 0.5)).all()


def _person(shadow_frames: tuple[int, ...], frames: int = 3):
    """A skin map with a dark patch (pigment) and what ``frames`` photos imply of it, a cast shadow stripe in
    ``shadow_frames``; each photo at its own exposure."""
    truth = np.full((SIZE, SIZE), 0.4)
    truth[20:30, 20:30] = 0.1  # the patch: pigment, dark in every photo
    estimates = []
    for frame in range(frames):
        implied = truth * (0.6 + 0.3 * frame)  # exposure
        if frame in shadow_frames:
            implied = implied.copy()
            implied[:, 40:50] *= 0.3  # a cast shadow across the map
        estimates.append(implied)
    return truth, np.stack(estimates), np.ones((frames, SIZE, SIZE))


def _corrected(fitted: np.ndarray, estimates: np.ndarray, weights: np.ndarray, **changes) -> np.ndarray:
    config = ConsensusConfig(smooth=0.0, **changes)
    return fitted * consensus_gain(frame_ratios(estimates, fitted, weights), weights, config)


def test_a_bleached_patch_comes_back_and_a_shadow_in_one_photo_stays_out():
    truth, estimates, weights = _person(shadow_frames=(1,))
    bleached = truth.copy()
    bleached[20:30, 20:30] = 0.3  # the fit took part of the patch's darkness for a dimmer light
    shadowed = truth.copy()
    shadowed[:, 40:50] *= 0.5  # and baked half of frame 1's shadow in
    fitted = np.minimum(bleached, shadowed)
    corrected = _corrected(fitted, estimates, weights)
    level = np.median(corrected / truth)  # the map's level is the fit's: compare shapes
    np.testing.assert_allclose(corrected / level, truth, rtol=1e-6)


def test_a_shadow_in_every_photo_is_taken_for_pigment_and_one_photo_changes_nothing():
    truth, estimates, weights = _person(shadow_frames=(0, 1, 2))
    corrected = _corrected(truth, estimates, weights, gain_range=(0.1, 10.0))
    assert corrected[:, 40:50].mean() / corrected[:, :20].mean() == pytest.approx(0.3, rel=1e-6)
    single = _corrected(truth, estimates[:1], weights[:1])
    np.testing.assert_array_equal(single, truth)


def test_texels_seen_by_fewer_than_min_frames_are_left_alone():
    truth, estimates, weights = _person(shadow_frames=())
    weights[1:, :, :32] = 0.0  # only frame 0 sees the left half
    fitted = truth * 1.5
    fitted[20:30, 20:30] = 0.4 * 1.5  # the patch bleached on the left half
    corrected = _corrected(fitted, estimates, weights)
    np.testing.assert_array_equal(corrected[:, :32], fitted[:, :32])


def test_the_gain_is_held_within_its_range_and_smoothed_without_bleeding():
    truth, estimates, weights = _person(shadow_frames=())
    fitted = truth * 10.0
    fitted[:, :8] = truth[:, :8] * 0.01  # far too dark: the gain would be 1000
    weights[:, :, 56:] = 0.0  # nobody sees the right edge
    gain = consensus_gain(frame_ratios(estimates, fitted, weights), weights, ConsensusConfig(smooth=0.03))
    assert gain.max() <= 2.0 + 1e-9 and gain.min() >= 0.5 - 1e-9
    np.testing.assert_array_equal(gain[:, 56:], 1.0)
