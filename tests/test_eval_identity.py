"""Identity score (dlib face descriptor distance) on real photos, and the identity key in reports and tables."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image
from skimage.filters import gaussian

from deface.batch.resume import config_record
from deface.eval.benchmark import VARIANTS, report_markdown, variant_config
from deface.eval.identity import identity_scores
from deface.eval.report import PairScores, ReportRow, write_index_html, write_metrics_json
from deface.landmarks.identity import SAME_PERSON_DISTANCE, IdentityScorer


@pytest.fixture(scope="module")
def scorer():
    pytest.importorskip("dlib")
    return IdentityScorer()


def _photo(photos, name: str, longer: int | None = None) -> np.ndarray:
    """sRGB float [H, W, 3]; shrunk (aspect kept) to ``longer`` px on its longer side when given."""
    image = Image.open(photos / name).convert("RGB")
    if longer is not None:
        scale = longer / max(image.size)
        image = image.resize((round(image.width * scale), round(image.height * scale)), Image.BICUBIC)
    return np.asarray(image, np.float32) / 255.0


@pytest.mark.slow
def test_same_photo_near_zero_and_degraded_copies_close(scorer, photos):
    photo = _photo(photos, "000031.jpg")
    noisy = np.clip(photo + np.random.default_rng(0).normal(0, 0.02, photo.shape), 0, 1).astype(np.float32)
    blurred = gaussian(photo, sigma=1, channel_axis=-1).astype(np.float32)
    assert scorer.distance(photo, photo) < 1e-6
    # Measured 0.054 (noise) and 0.043 (blur) for this photo; same person by a wide margin.
    assert 0 < scorer.distance(noisy, photo) < 0.2
    assert 0 < scorer.distance(blurred, photo) < 0.2


def test_different_people_are_farther_than_the_same_person(scorer, photos):
    first, second = _photo(photos, "000031.jpg"), _photo(photos, "015270.jpg")
    blurred = gaussian(first, sigma=1, channel_axis=-1)
    across = np.linalg.norm(scorer.descriptor(first) - scorer.descriptor(second))
    within = np.linalg.norm(scorer.descriptor(first) - scorer.descriptor(blurred))
    assert across > SAME_PERSON_DISTANCE > within


def test_faces_in_128px_working_images_are_found(scorer, photos):
    # Faces of 40-70 px here: below the HOG detector's ~80 px window unless the image is upscaled first.
    for name in ("JianzhuGuo.jpg", "psm-clean-008.png", "vd092.png"):
        small = _photo(photos, name, longer=128)
        full = _photo(photos, name)
        assert np.linalg.norm(scorer.descriptor(small) - scorer.descriptor(full)) < SAME_PERSON_DISTANCE, name


def test_synthesis_without_a_face_uses_the_photo_box_and_no_face_in_photo_gives_none(scorer, photos):
    photo = _photo(photos, "000031.jpg", longer=128)
    blank = np.full_like(photo, 0.5)
    assert scorer.descriptor(blank) is None
    distance = scorer.distance(blank, photo)  # the photo's box, applied to the grey image
    assert distance is not None and distance > SAME_PERSON_DISTANCE
    assert scorer.distance(photo, blank) is None
    assert identity_scores(scorer, [photo], [blank]) is None
    both = identity_scores(scorer, [photo, blank], [photo, photo])  # mean over frames
    assert both["distance"] == pytest.approx(distance / 2, abs=1e-6)


def _scores(psnr: float, distance: float | None = None) -> dict:
    scores = {
        "face": {"psnr": psnr, "ssim": 0.9, "lpips": 5.0},
        "full": {"psnr": psnr + 10, "ssim": 0.95, "lpips": 2.0},
    }
    if distance is not None:
        scores["identity"] = {"distance": distance}
    return scores


def test_metrics_json_carries_identity_and_stays_valid_without(tmp_path):
    with_identity = [
        PairScores("a", _scores(30, 0.2), _scores(28, 0.3)),
        PairScores("b", _scores(20, 0.4), _scores(22, 0.5)),
    ]
    doc = json.loads(write_metrics_json(tmp_path / "with.json", "p", with_identity).read_text())
    assert doc["pairs"][1]["target"]["identity"] == {"distance": 0.5}
    assert doc["mean"]["target"]["identity"]["distance"] == pytest.approx(0.4)
    assert doc["mean"]["source"]["identity"]["distance"] == pytest.approx(0.3)
    assert doc["mean"]["target"]["face"]["psnr"] == pytest.approx(25)

    # One pair without it (old cache, or no face in its photo): kept per pair, no mean over a subset.
    mixed = [with_identity[0], PairScores("b", _scores(20), _scores(22))]
    doc = json.loads(write_metrics_json(tmp_path / "mixed.json", "p", mixed).read_text())
    assert "identity" in doc["pairs"][0]["target"] and "identity" not in doc["pairs"][1]["target"]
    assert set(doc["mean"]["target"]) == {"face", "full"}

    without = [PairScores("a", _scores(30), _scores(28))]
    doc = json.loads(write_metrics_json(tmp_path / "without.json", "p", without).read_text())
    assert set(doc["pairs"][0]["source"]) == set(doc["mean"]["target"]) == {"face", "full"}

    with pytest.raises(ValueError, match="identity"):
        write_metrics_json(tmp_path / "bad.json", "p", [PairScores("a", _scores(30), {**_scores(28), "identity": {}})])


def test_index_html_shows_the_identity_column_only_when_present(tmp_path):
    image = tmp_path / "x.png"
    Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(image)
    page = write_index_html(tmp_path / "a.html", [ReportRow("a", {"x": image}, {"target": _scores(28, 0.3456)})])
    assert "<th>ID dist</th>" in page.read_text() and "<td>0.3456</td>" in page.read_text()
    page = write_index_html(tmp_path / "b.html", [ReportRow("a", {"x": image}, {"target": _scores(28)})])
    assert "<td>" in page.read_text() and "ID dist</th>" not in page.read_text()


def test_benchmark_table_has_an_id_column_with_a_dash_when_missing(tmp_path):
    pairs = tmp_path / "pairs" / "one"
    pairs.mkdir(parents=True)
    for side in ("source", "target"):
        Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(pairs / f"{side}.png")
    out = tmp_path / "results"
    for name, distance in (("ours", 0.4321), ("nextface", None)):
        write_metrics_json(out / name / "metrics.json", name, [PairScores("one", _scores(30), _scores(25, distance))])
        (out / name / "timing.json").write_text(json.dumps({"seconds_per_fit": [12.0]}))
        # The per-pair cache records the configuration; the report only shows rows fitted with the current one.
        config = config_record(variant_config(VARIANTS[name], "smoke"))
        (out / name / "one").mkdir()
        (out / name / "one" / "scores.json").write_text(json.dumps({"config": config}))
    text = report_markdown(out, tmp_path / "pairs", "smoke", "deface bench run ...")
    header = next(line for line in text.splitlines() if line.startswith("| | PSNR face"))
    ours = next(line for line in text.splitlines() if line.startswith("| Ours (default preset) |"))
    nextface = next(line for line in text.splitlines() if line.startswith("| NextFace |"))
    assert "ID dist" in header and header.count("|") == ours.count("|") == nextface.count("|")
    assert "| 0.432 | - | 12 |" in ours and "| - | - | 12 |" in nextface  # no ITA gap recorded here
