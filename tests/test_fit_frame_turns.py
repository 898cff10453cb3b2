"""Stage 2's frames per step (deface/fit/frame_turns.py): every frame once per round, repeatable, the shadow
transfers refreshed as with every frame at every step, and a step's loss the mean over its frames."""

from __future__ import annotations

import pytest
import torch

from deface.eval.benchmark import SCHEDULES
from deface.eval.synthetic import make_shadowed_face
from deface.fit import presets, stage2
from deface.fit.config import override
from deface.fit.frame_turns import FrameTurns
from deface.fit.log import FitLog
from deface.fit.pipeline import prepare
from deface.fit.target import FitTarget
from deface.models import load_face_model


@pytest.mark.parametrize(("frames", "per_step"), [(8, 4), (8, 3), (5, 4), (7, 2)])
def test_each_round_shows_every_frame_once_in_near_equal_turns(frames, per_step):
    turns = FrameTurns(frames, per_step, refresh_every=50)
    steps_per_round = -(-frames // per_step)
    for start in range(0, 6 * steps_per_round, steps_per_round):
        round_ = [turns.at(step) for step in range(start, start + steps_per_round)]
        shown = sorted(frame for turn in round_ for frame in turn)
        assert shown == list(range(frames))
        assert max(map(len, round_)) <= per_step and max(map(len, round_)) - min(map(len, round_)) <= 1
    first, second = [turns.at(step) for step in range(steps_per_round)], \
        [turns.at(step) for step in range(steps_per_round, 2 * steps_per_round)]
    assert first != second or frames <= per_step  # a new order each round
    again = FrameTurns(frames, per_step, refresh_every=50)
    assert [again.at(step) for step in range(20)] == [turns.at(step) for step in range(20)]


@pytest.mark.parametrize("per_step", [0, 3, 9])
def test_every_frame_at_every_step_when_the_turn_holds_them_all(per_step):
    turns = FrameTurns(3, per_step, refresh_every=50)
    assert turns.every_step and all(turns.at(step) == (0, 1, 2) for step in range(10))


def test_shadow_refreshes_are_those_of_every_frame_at_every_step_and_never_further_apart_in_turns():
    every = FrameTurns(4, 0, refresh_every=50)
    due = [step for step in range(400) if all([every.refresh(frame, step) for frame in every.at(step)])]
    assert due == [step for step in range(400) if step % 50 == 0]
    turns, last = FrameTurns(8, 3, refresh_every=50), {}
    for step in range(400):
        for frame in turns.at(step):
            if turns.refresh(frame, step):
                assert step - last.get(frame, step - 50) >= 50
                last[frame] = step
    # a frame is rendered at least every two rounds (6 steps), so no refresh is later than that past its due step
    assert all(400 - step <= 50 + 6 for step in last.values())


@pytest.fixture(scope="module")
def three_photos(shared):
    """Three photos of one person, each with its own lights (a person's fit)."""
    model = load_face_model("ict")
    faces = [make_shadowed_face(model, size=48, seed=seed, rays=8) for seed in (1, 2, 3)]
    config = override(presets.get("default"), **SCHEDULES["smoke"])
    target = FitTarget([face.image_srgb for face in faces], [face.landmarks for face in faces], 1.0,
                       light_groups=(0, 1, 2))
    return target, prepare(target, config, log=FitLog(quiet=True))[0]


@pytest.mark.slow
def test_a_step_on_some_frames_is_the_mean_of_their_frame_terms(three_photos):
    _, context = three_photos
    with torch.no_grad():
        stage2.objective(context, before_ace=False, refresh_shadows=True)  # the shadow transfers, once
        whole = float(stage2.objective(context, before_ace=False, refresh_shadows=False))
        alone = [float(stage2.objective(context, False, False, frames=(frame,))) for frame in range(3)]
        pair = float(stage2.objective(context, False, False, frames=(0, 2)))
    assert whole == pytest.approx(sum(alone) / 3, rel=1e-5)
    assert pair == pytest.approx((alone[0] + alone[2]) / 2, rel=1e-5)
    assert len({round(value, 4) for value in alone}) == 3  # the frames differ, so the test can fail


def _stage2_frames(target, config, monkeypatch) -> tuple[list[tuple[int, ...]], FitLog, object]:
    """The frames of each stage-2 step of a fit of ``target``, its log and its context."""
    log, steps, original = FitLog(quiet=True), [], stage2.objective

    def recorded(*args, frames=None, **kwargs):
        steps.append(frames)
        return original(*args, frames=frames, **kwargs)

    monkeypatch.setattr(stage2, "objective", recorded)
    context = prepare(target, config, log=log)[0]
    stage2.run_stage2(context)
    return steps, log, context


@pytest.mark.slow
def test_photos_with_their_own_lights_are_stepped_in_turns_and_all_shadowed(three_photos, monkeypatch):
    target, context = three_photos
    config = override(context.config, **{"iterations.stage2_frames_per_step": 2, "iterations.stage2": 6})
    steps, log, context = _stage2_frames(target, config, monkeypatch)
    assert all(len(frames) <= 2 for frames in steps) and set(steps[0] + steps[1]) == {0, 1, 2}
    assert all(cache.transfer is not None and cache.refreshes >= 1 for cache in context.shadow_caches)
    assert any("2 of the 3 frames per step, in turn" in note for note in log.notes)


@pytest.mark.slow
def test_frames_sharing_their_lights_are_all_rendered_at_every_step(three_photos, monkeypatch):
    target, context = three_photos
    clip = FitTarget(target.frames_srgb, target.landmarks, 1.0)  # no light groups: a clip's frames
    config = override(context.config, **{"iterations.stage2_frames_per_step": 2, "iterations.stage2": 4})
    steps, log, _ = _stage2_frames(clip, config, monkeypatch)
    assert steps == [(0, 1, 2)] * 4 and not any("in turn" in note for note in log.notes)
