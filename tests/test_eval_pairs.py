"""Pairs reader, metrics.json schema and the HTML report on tiny synthetic data."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from deface.eval.pairs import read_pairs
from deface.eval.report import PairScores, ReportRow, metrics_document, write_index_html, write_metrics_json


def _png(path: Path, value: int = 128) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.full((8, 8, 3), value, np.uint8)).save(path)
    return path


def test_reads_image_and_video_pairs_sorted_naturally(tmp_path):
    for name in ("p10", "p2", "p1"):
        _png(tmp_path / name / "source.png")
        _png(tmp_path / name / "target.jpg")
    for frame in ("f10.png", "f2.png", "f1.png"):
        _png(tmp_path / "video" / "source" / frame)
        _png(tmp_path / "video" / "target" / frame)
    (tmp_path / "video" / "source" / "notes.txt").write_text("not a frame")
    (tmp_path / "manifest.json").write_text("{}")
    _png(tmp_path / "p1" / "shadow_mask.png")  # extra files in a pair folder are ignored

    pairs = read_pairs(tmp_path)
    assert [p.name for p in pairs] == ["p1", "p2", "p10", "video"]
    assert pairs[0].source == [tmp_path / "p1" / "source.png"]
    assert pairs[0].target == [tmp_path / "p1" / "target.jpg"]
    assert [f.name for f in pairs[3].source] == ["f1.png", "f2.png", "f10.png"]
    assert [f.name for f in pairs[3].target] == ["f1.png", "f2.png", "f10.png"]


@pytest.mark.parametrize(
    "files, message",
    [
        (["a/source.png"], "no target.png"),
        (["a/source.png", "a/source.jpg", "a/target.png"], "ambiguous source"),
        (["a/source/f1.png", "a/target.png"], "frames folder"),
    ],
)
def test_malformed_pairs_raise_clear_errors(tmp_path, files, message):
    for file in files:
        _png(tmp_path / file)
    with pytest.raises(ValueError, match=message):
        read_pairs(tmp_path)


def test_empty_frames_folder_and_missing_directory(tmp_path):
    (tmp_path / "a" / "source").mkdir(parents=True)
    (tmp_path / "a" / "target").mkdir()
    with pytest.raises(ValueError, match="no .png/.jpg frames"):
        read_pairs(tmp_path)
    with pytest.raises(ValueError, match="does not exist"):
        read_pairs(tmp_path / "nope")


def _scores(psnr: float, ssim: float, lpips: float) -> dict:
    return {"face": {"psnr": psnr, "ssim": ssim, "lpips": lpips},
            "full": {"psnr": psnr + 10, "ssim": ssim + 0.05, "lpips": lpips / 2}}


def test_metrics_json_schema_and_means(tmp_path):
    pairs = [
        PairScores("a", _scores(30.0, 0.9, 6.0), _scores(28.0, 0.85, 8.0)),
        PairScores("b", _scores(20.0, 0.7, 10.0), _scores(float("inf"), 0.95, 4.0)),
    ]
    path = write_metrics_json(tmp_path / "out" / "metrics.json", "paper", pairs)
    doc = json.loads(path.read_text())  # strict JSON: no Infinity literal
    assert set(doc) == {"preset", "pairs", "mean"} and doc["preset"] == "paper"
    assert [p["name"] for p in doc["pairs"]] == ["a", "b"]
    for entry in doc["pairs"]:
        assert set(entry) == {"name", "source", "target"}
        for side in ("source", "target"):
            assert set(entry[side]) == {"face", "full"}
            assert all(set(entry[side][r]) == {"psnr", "ssim", "lpips"} for r in ("face", "full"))
    assert doc["pairs"][1]["target"]["face"]["psnr"] is None  # inf -> null
    assert doc["mean"]["source"]["face"] == pytest.approx({"psnr": 25.0, "ssim": 0.8, "lpips": 8.0})
    assert doc["mean"]["source"]["full"]["lpips"] == pytest.approx(4.0)
    assert doc["mean"]["target"]["face"]["psnr"] is None


def test_metrics_document_rejects_incomplete_scores():
    with pytest.raises(ValueError, match="missing metric 'lpips'"):
        incomplete = {"face": {"psnr": 1, "ssim": 1}, "full": {}}
        metrics_document("p", [PairScores("a", incomplete, _scores(1, 1, 1))])
    with pytest.raises(ValueError, match="no pair scores"):
        metrics_document("p", [])


def test_index_html_links_images_relatively(tmp_path):
    out = tmp_path / "report"
    img = _png(out / "pairs" / "a" / "source.png")
    swap = _png(out / "pairs" / "a" / "swap render.png")
    rows = [ReportRow("a<1>", {"source": img, "swap": swap}, {"target": _scores(29.2, 0.91, 6.36)})]
    html = write_index_html(out / "index.html", rows).read_text()
    assert "src='pairs/a/source.png'" in html and "pairs/a/swap render.png" in html
    assert "a&lt;1&gt;" in html  # names are escaped
    assert "29.20" in html and "0.9100" in html and "6.36" in html
    assert str(tmp_path) not in html  # no absolute paths
