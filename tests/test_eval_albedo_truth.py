"""The albedo benchmark's measures against hand-built maps with known answers (deface/eval/albedo_measures.py),
its truth-set reading and its alignment (deface/eval/albedo_benchmark.py)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from deface.eval import albedo_measures as m
from deface.eval.albedo_benchmark import FACE, read_truth_set, score_fit, similarity_aligned

S = m.SCORE_SIZE


def _skin(level=(0.5, 0.35, 0.25)) -> np.ndarray:
    return np.broadcast_to(np.array(level), (S, S, 3)).copy()


def _box(top, left, size) -> np.ndarray:
    mask = np.zeros((S, S), bool)
    mask[top:top + size, left:left + size] = True
    return mask


REFERENCE, REGION = _box(10, 10, 40), _box(120, 100, 60)


def test_gain_matched_undoes_one_gain_per_channel():
    truth = _skin() * np.random.default_rng(0).uniform(0.5, 1.5, (S, S, 1))
    fitted = truth * np.array([2.0, 1.0, 0.5])
    np.testing.assert_allclose(m.gain_matched(fitted, truth, REFERENCE), truth, rtol=1e-12)


@pytest.mark.parametrize("fitted_darkening, expected", [(0.5, 1.0), (1.0, 0.0), (0.75, 0.5), (1.2, -0.4)])
def test_darkness_kept(fitted_darkening, expected):
    """A region half as light as the skin in the truth: kept 1 when the map has it half as light too, 0 when the
    map made it skin, in proportion between, negative when the map is lighter there."""
    truth, fitted = _skin(), _skin()
    truth[REGION] *= 0.5
    fitted[REGION] *= fitted_darkening
    assert m.darkness_kept(fitted, truth, REGION, REFERENCE) == pytest.approx(expected)


def test_darkness_kept_is_undefined_without_contrast():
    assert np.isnan(m.darkness_kept(_skin(), _skin(), REGION, REFERENCE))


def test_fine_structure_correlation():
    rng = np.random.default_rng(1)
    truth = _skin() * rng.uniform(0.6, 1.0, (S, S, 1))  # texel-scale dots and strokes
    assert m.fine_structure(truth, truth, REGION) == pytest.approx(1.0)
    assert m.fine_structure(truth * 0.7, truth, REGION) == pytest.approx(1.0)  # a gain changes no correlation
    assert m.fine_structure(_skin(), truth, REGION) == 0.0  # a flat map carries none of it
    blurred_region = m.fine_structure(truth * rng.uniform(0.6, 1.0, (S, S, 1)), truth, REGION)
    assert 0.3 < blurred_region < 0.9  # the truth's detail under as much independent noise
    assert abs(m.fine_structure(_skin() * rng.uniform(0.6, 1.0, (S, S, 1)), truth, REGION)) < 0.1


def test_colour_noise_sees_chroma_not_brightness():
    rng = np.random.default_rng(2)
    grey_detail = _skin() * rng.uniform(0.6, 1.0, (S, S, 1))  # the same factor in every channel
    assert m.colour_noise(grey_detail, REGION) == pytest.approx(0.0, abs=1e-9)
    tint = np.exp(0.05 * rng.standard_normal((S, S, 1)) * np.array([1.0, -1.0, 0.0]) / np.sqrt(2))
    noisy = _skin() * tint  # log-chroma noise of std 0.05 along the red-green axis
    blur_loss = 1.0 - 1.0 / (4 * np.pi * m.FINE_SIGMA ** 2)  # white noise keeps this share of its variance
    assert m.colour_noise(noisy, REGION) == pytest.approx(100 * 0.05 * np.sqrt(blur_loss), rel=0.1)


def test_colour_error_sees_a_tint_at_any_scale_and_not_brightness():
    """0 for the truth's colours at any lightness; a green patch scores its CIELAB a*b* shift, by an independent
    colour-science conversion, in proportion to the share of the face it covers."""
    import colour

    rng = np.random.default_rng(4)
    truth = _skin() * rng.uniform(0.6, 1.0, (S, S, 1))
    assert m.colour_error(truth * 0.5, truth, REGION) == pytest.approx(0.0, abs=1e-6)  # darker, same colours
    assert m.colour_error(truth * rng.uniform(0.3, 1.0, (S, S, 1)), truth, REGION) == pytest.approx(0.0, abs=1e-6)
    green = np.array([0.9, 1.15, 0.9])
    tinted = truth.copy()
    tinted[REGION] *= green
    pixel = truth[REGION][0]
    shifted = pixel * green * (pixel @ m.LUMINANCE) / ((pixel * green) @ m.LUMINANCE)
    lab = [colour.XYZ_to_Lab(colour.sRGB_to_XYZ(colour.cctf_encoding(x))) for x in (shifted, pixel)]
    expected = np.hypot(*(lab[0][1:] - lab[1][1:]))
    assert expected > 3  # a visible tint
    assert m.colour_error(tinted, truth, REGION) == pytest.approx(expected, rel=0.05)
    half = REGION & (np.arange(S)[None, :] < 130)  # the patch over half the region: RMS sqrt(1/2) as large
    assert m.colour_error(np.where(half[..., None], tinted, truth), truth, REGION) == pytest.approx(
        expected * np.sqrt(half.sum() / REGION.sum()), rel=0.05)


def test_psnr_ssim():
    truth = _skin() * np.random.default_rng(3).uniform(0.6, 1.0, (S, S, 1))
    psnr, ssim = m.psnr_ssim(truth, truth, REGION)
    assert psnr > 100 and ssim == pytest.approx(1.0)
    psnr, ssim = m.psnr_ssim(_skin(), truth, REGION)
    assert 10 < psnr < 40 and ssim < 0.5


def test_score_fit_regions_and_reference():
    truth, fitted = _skin(), _skin() * 1.3  # a brighter map with the beard bleached
    truth[REGION] *= 0.5
    scores = score_fit(fitted, truth, np.ones((S, S), bool), {"forehead": REFERENCE, "beard": REGION})
    assert set(scores) == {FACE, "beard"}
    assert scores["beard"]["darkness_kept"] == pytest.approx(0.0)
    assert scores["beard"]["texels"] == REGION.sum()


def test_score_fit_photo_darkness_tells_the_photo_from_the_map():
    truth = _skin()
    truth[REGION] *= 0.5
    photo = truth * 0.7  # the photo: the truth under an even light, so it keeps the beard whole
    photo[:5] = np.nan  # rows the photo does not see
    bleached = _skin()
    scores = score_fit(bleached, truth, np.ones((S, S), bool), {"forehead": REFERENCE, "beard": REGION}, photo)
    assert scores["beard"]["photo_darkness"] == pytest.approx(1.0)
    assert scores["beard"]["darkness_kept"] == pytest.approx(0.0)  # the lights took it, not the photo
    shaded = photo.copy()
    shaded[REGION] *= 1.6  # the region lit brighter than the reference: the photo shows it lighter
    scores = score_fit(bleached, truth, np.ones((S, S), bool), {"forehead": REFERENCE, "beard": REGION}, shaded)
    assert scores["beard"]["photo_darkness"] == pytest.approx((1 - 0.8) / 0.5)
    assert "photo_darkness" not in score_fit(bleached, truth, np.ones((S, S), bool),
                                             {"forehead": REFERENCE, "beard": REGION})["beard"]


def test_similarity_aligned_recovers_a_similarity():
    rng = np.random.default_rng(4)
    target = rng.standard_normal((50, 3))
    rotation = Rotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix()
    source = 0.7 * target @ rotation.T + np.array([1.0, -2.0, 3.0])
    np.testing.assert_allclose(similarity_aligned(source, target), target, atol=1e-9)


def test_read_truth_set_names_albedo_and_light(tmp_path):
    (tmp_path / "images").mkdir()
    (tmp_path / "albedo").mkdir()
    for name in ("a_even.png", "b_k4500.png"):
        (tmp_path / "images" / name).write_bytes(b"")
    for name in ("ita30.png", "b.png"):
        (tmp_path / "albedo" / name).write_bytes(b"")
    (tmp_path / "MANIFEST.tsv").write_text("file\ttone\tlight\tkelvin\tshadow\n"
                                           "a_even.png\tita30\teven\t4800\t0\nb_k4500.png\t\t\t4500\t1\n")
    renders = read_truth_set(tmp_path)
    assert [(r.albedo, r.light) for r in renders] == [("ita30.png", "even"), ("b.png", "4500 K shadow")]
    (tmp_path / "albedo" / "b.png").unlink()
    with pytest.raises(ValueError, match="b.png: not found"):
        read_truth_set(tmp_path)


def test_shared_truth_sets_read(shared):
    assert len(read_truth_set(shared / "data" / "detail-synth")) == 6
    assert len(read_truth_set(shared / "data" / "skin-tone-synth")) == 15
