"""The board that guards the default (deface/eval/board.py): its splits are well formed, a loss beyond a measure's
tolerance is flagged and one within it is not, and a tiny split runs end to end into its table."""

from __future__ import annotations

import json

import numpy as np
import pytest

from deface.eval import board
from deface.eval.board import MEASURES, SPLITS, PairSplit, compare, read_accepted, table_markdown
from deface.eval.shadows import EXTRA_KINDS, SHAPE_KINDS
from deface.fit import presets


def test_every_split_is_named_once_and_one_pair_split_is_held_out():
    names = [s.name for s in SPLITS]
    assert len(names) == len(set(names))
    assert [s.name for s in SPLITS if s.held_out] == ["held-out"]
    assert "held-out" not in board.split_names() and "held-out" in board.split_names(include_held_out=True)
    for split in SPLITS:
        if isinstance(split, PairSplit):
            assert set(split.kinds) <= set(SHAPE_KINDS + EXTRA_KINDS)
            board_photos = [p for p in split.photos if p.startswith("board:")]
            assert all(board._photo_path(p).is_file() for p in board_photos)


def test_the_board_photos_have_their_sources_written_beside_them():
    sources = (board.BOARD_DIR / "photos" / "SOURCES.md").read_text()
    for photo in (board.BOARD_DIR / "photos").iterdir():
        if photo.suffix in (".png", ".jpg"):
            assert photo.name in sources


def test_a_loss_beyond_the_tolerance_is_flagged_in_either_direction():
    accepted = {"pairs": {"synthesis_psnr": 24.0, "ita_gap": 3.0}, "truth": {"beard_kept": 0.4}}
    psnr, gap, beard = MEASURES["synthesis_psnr"], MEASURES["ita_gap"], MEASURES["beard_kept"]
    figures = {"pairs": {"synthesis_psnr": 24.0 - 2 * psnr.tolerance, "ita_gap": 3.0 + 0.5 * gap.tolerance},
               "truth": {"beard_kept": 0.4 + beard.tolerance}}
    rows = {(r["split"], r["measure"]): r for r in compare(figures, accepted)}
    assert rows["pairs", "synthesis_psnr"]["loss"]  # lower PSNR, beyond the tolerance
    assert rows["pairs", "synthesis_psnr"]["change"] == pytest.approx(-2 * psnr.tolerance)
    assert not rows["pairs", "ita_gap"]["loss"]  # a larger gap, but within the noise
    assert rows["pairs", "ita_gap"]["change"] == pytest.approx(-0.5 * gap.tolerance)
    assert not rows["truth", "beard_kept"]["loss"] and rows["truth", "beard_kept"]["change"] > 0
    table = table_markdown(list(rows.values()))
    assert table.count("LOSS") == 1 and "| pairs | synthesis_psnr |" in table


def test_a_figure_without_an_accepted_value_is_shown_but_never_a_loss():
    rows = compare({"new": {"psnr": 20.0}}, {})
    assert rows == [{"split": "new", "measure": "psnr", "value": 20.0, "accepted": None, "change": None,
                     "loss": False}]


@pytest.mark.slow
def test_a_tiny_split_runs_into_figures_and_a_rerun_fits_nothing(tmp_path, monkeypatch, shared):
    tiny = PairSplit("tiny", ("board:obama.jpg",), seed=5, kinds=("stripes",), fill=(0.55, 0.75, 1.0),
                     warm=(0.5, 0.5), penumbra=(0.002, 0.01))
    monkeypatch.setattr(board, "SPLITS", (tiny,))
    monkeypatch.setitem(board.SCHEDULES, "quick", board.SCHEDULES["smoke"])
    config = presets.get("default")
    lines = []
    figures = board.run_board(config, tmp_path, ["tiny"], jobs=1, log=lines.append)
    assert set(figures["tiny"]) == {"synthesis_psnr", "synthesis_ssim", "synthesis_lpips", "ita_gap",
                                    "colour_noise"}
    assert all(np.isfinite(v) for v in figures["tiny"].values())
    manifest = json.loads((tmp_path / "pairs" / "tiny" / "manifest.json").read_text())
    assert manifest["pairs"][0]["warmth"] == 0.5 and manifest["config"]["fill"] == [0.55, 0.75, 1.0]
    again = []
    assert board.run_board(config, tmp_path, ["tiny"], jobs=1, log=again.append) == figures
    assert lines == again == ["tiny / obama-00: done"]  # the second run read the record back


def test_the_accepted_figures_are_recorded_with_their_command():
    accepted = read_accepted()
    assert accepted.get("command", "").startswith("deface bench board")
    assert set(accepted["figures"]) >= set(board.split_names())
