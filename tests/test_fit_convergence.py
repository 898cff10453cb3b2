"""Early stops of the fitting stages (deface/fit/convergence.py)."""

from __future__ import annotations

import re

import pytest

from deface.fit import presets
from deface.fit.config import override
from deface.fit.convergence import converged
from deface.fit.log import FitLog
from deface.fit.pipeline import fit_target
from deface.fit.target import FitTarget


def test_converged_compares_window_means():
    falling = [100.0 * 0.9**k for k in range(40)]  # 10 % per step: never settled
    assert not converged(falling, window=5, tolerance=0.01)
    flat = [1.0, 3.0] * 10  # noisy but level: the window means are equal
    assert converged(flat, window=4, tolerance=0.001)
    assert not converged(flat, window=4, tolerance=0.0)  # 0 = off
    assert not converged(flat[:7], window=4, tolerance=0.5)  # fewer than two windows
    assert not converged(flat, window=4, tolerance=0.5, start=14)  # two windows after start are needed
    slow = [10.0 - 0.01 * k for k in range(20)]  # 0.1 loss per 10 steps, ~1 % of 9.9
    assert converged(slow, window=10, tolerance=0.011) and not converged(slow, window=10, tolerance=0.009)


@pytest.mark.slow
def test_stages_stop_early_and_say_so(shadowed_small):
    image, landmarks, scale = shadowed_small
    config = override(presets.get("default"), **{
        "iterations.stage1": 20, "iterations.stage2": 40, "iterations.stage3": 30, "decouple.ace_iteration": 6,
        "iterations.stage2_tolerance": 10.0, "iterations.stage3_tolerance": 10.0, "iterations.stage3_holdout": 0.0,
        "iterations.convergence_window": 3, "resolution": 64, "texture_size": 64, "render.shadow_rays": 16})
    log = FitLog(quiet=True)
    fit_target(FitTarget([image], [landmarks], scale), config, log=log)
    # any loss change is below a tolerance of 10: each stage stops as soon as it may test (2 windows)
    assert len(log.losses["stage 2"]) == 6 + 1 + 2 * 3
    assert len(log.losses["stage 3"]) == 2 * 3
    assert any("stage 3 converged after 6 of 30 steps" in note for note in log.notes)


@pytest.mark.slow
def test_stage3_keeps_the_step_that_predicts_the_held_out_pixels_best(shadowed_small):
    image, landmarks, scale = shadowed_small
    config = override(presets.get("default"), **{
        "iterations.stage1": 20, "iterations.stage2": 20, "iterations.stage3": 60, "decouple.ace_iteration": 6,
        "iterations.stage3_tolerance": 0.0, "iterations.stage3_holdout": 0.2, "iterations.convergence_window": 4,
        "resolution": 64, "texture_size": 64, "render.shadow_rays": 16})
    log = FitLog(quiet=True)
    fit_target(FitTarget([image], [landmarks], scale), config, log=log)
    kept = [note for note in log.notes if note.startswith("stage 3 keeps step")]
    assert len(kept) == 1, log.notes
    step, ran = (int(n) for n in re.match(r"stage 3 keeps step (\d+) of the (\d+) it ran", kept[0]).groups())
    assert step < ran <= 60
    if ran < 60:  # stopped by the held-out pixels: patience steps after the best one
        assert ran == step + 4


@pytest.fixture(scope="module")
def shadowed_small(shared):
    from deface.eval.synthetic import make_shadowed_face
    from deface.models import load_face_model

    face = make_shadowed_face(load_face_model("ict"), size=96, seed=0, rays=16)
    landmarks = face.landmarks
    scaled = type(landmarks)(landmarks.points / 3, landmarks.depth / 3, (32, 32), 1, 0)
    return face.image_srgb[::3, ::3].copy(), scaled, 1 / 3
