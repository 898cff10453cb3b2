"""Time left of a running fit in the web app (deface/web/progress.py), from stage events at known times."""

from __future__ import annotations

import pytest

from deface.fit import presets
from deface.fit.config import override
from deface.web.progress import COARSE_COST, FIRST_GUESS, PACE_FILE, FitClock, PaceBook, duration_text, pace_key

TOTALS = {"stage 2": 100, "stage 3": 40}


def run(clock: FitClock, until: float | None = None) -> float:
    """Feed a fit's events (stage 2: 0.5 s a step, stage 3: 0.25 s) up to time ``until``; returns the last time."""
    events = [("landmarks", 0, 0.0), ("stage 1", 0, 1.0), ("stage 2", 0, 3.0)]
    events += [("stage 2", step, 3.0 + 0.5 * step) for step in range(1, 101)]
    events += [("stage 3", 0, 53.0)] + [("stage 3", step, 53.0 + 0.25 * step) for step in range(1, 41)]
    events += [("textures", 0, 63.0), ("writing", 0, 64.0)]
    for stage, step, now in events:
        if until is not None and now > until:
            return until
        clock.event(stage, step, now)
    return events[-1][2]


def test_nothing_is_known_before_stage_2_has_taken_steps():
    clock = FitClock(TOTALS)
    run(clock, until=3.6)
    assert clock.seconds_left(3.6) is None
    assert duration_text(None) == "estimating"


def test_the_first_fit_extrapolates_from_stage_2s_pace():
    clock = FitClock(TOTALS)
    run(clock, until=8.0)  # stage 2, step 10 at 0.5 s a step
    rate = 0.5
    expected = (90 + 40 * FIRST_GUESS["stage 3"] + FIRST_GUESS["textures"] + FIRST_GUESS["writing"]) * rate
    assert clock.seconds_left(8.0) == pytest.approx(expected)


def test_stage_3s_start_is_guessed_from_stage_2():
    clock = FitClock(TOTALS)
    run(clock, until=53.0)  # stage 3 has just started; stage 2 ran at 0.5 s a step
    guess = (40 * FIRST_GUESS["stage 3"] + FIRST_GUESS["textures"] + FIRST_GUESS["writing"]) * 0.5
    assert clock.seconds_left(53.0) == pytest.approx(guess)


def test_stage_2s_half_size_steps_are_extrapolated_at_full_size():
    clock = FitClock(TOTALS, coarse_steps=50)
    clock.event("stage 2", 0, 0.0)
    for step in range(1, 21):  # half-size steps: COARSE_COST of a full one (0.5 s)
        clock.event("stage 2", step, step * 0.5 * COARSE_COST)
    now = 20 * 0.5 * COARSE_COST
    stage2 = 30 * 0.5 * COARSE_COST + 50 * 0.5
    later = 40 * FIRST_GUESS["stage 3"] * 0.5 + (FIRST_GUESS["textures"] + FIRST_GUESS["writing"]) * 0.5
    assert clock.seconds_left(now) == pytest.approx(stage2 + later)
    for step in range(51, 61):  # then full-size steps at 0.6 s: their own pace takes over
        now += 0.6 if step > 51 else (30 * 0.5 * COARSE_COST + 0.6)
        clock.event("stage 2", step, now)
    assert clock.seconds_left(now) == pytest.approx(40 * 0.6 + 40 * FIRST_GUESS["stage 3"] * 0.6
                                                    + (FIRST_GUESS["textures"] + FIRST_GUESS["writing"]) * 0.6)


def test_the_paces_are_kept_in_the_output_folder(tmp_path):
    first = FitClock(TOTALS)
    book = PaceBook(tmp_path)
    run(first)
    book.learn("config", first, 70.0)
    assert PaceBook(tmp_path).get("config") == pytest.approx(book.get("config"))
    (tmp_path / PACE_FILE).write_text("not json")
    assert PaceBook(tmp_path).get("config") is None


def test_a_finished_fit_teaches_the_next_its_pace():
    book, key = PaceBook(), "config"
    first = FitClock(TOTALS)
    end = run(first) + 6.0  # the writing took 6 s
    book.learn(key, first, end)
    pace = book.get(key)
    assert pace["stage 2"] == pytest.approx(0.5) and pace["stage 3"] == pytest.approx(0.25)
    assert pace["writing"] == pytest.approx(6.0) and pace["landmarks"] == pytest.approx(1.0)
    second = FitClock(TOTALS, pace)
    second.event("landmarks", 0, 100.0)
    assert second.seconds_left(100.0) == pytest.approx(end)  # the whole fit ahead, at the same pace
    run_to = run(second, until=60.0)  # stage 3 at step 28: 12 steps, the textures and the writing left
    assert second.seconds_left(run_to) == pytest.approx(12 * 0.25 + 1.0 + 6.0)


def test_the_pace_key_follows_the_settings():
    fast = presets.get("fast")
    assert pace_key(fast) == pace_key(presets.get("fast"))
    assert pace_key(fast) != pace_key(override(fast, resolution=64))


@pytest.mark.parametrize(("seconds", "text"), [(0.2, "about 1 s"), (42, "about 42 s"), (130, "about 2 min 10 s"),
                                               (1500, "about 25 min"), (7300, "about 2 h 1 min")])
def test_durations_read_as_words(seconds, text):
    assert duration_text(seconds) == text
