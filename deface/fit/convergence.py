"""Early stop of an optimisation stage once its loss has settled.

A stage has converged when the mean loss of its last ``window`` steps is lower than the mean of the
``window`` steps before by less than ``tolerance`` of the latter (a relative decrease per window). Window
means smooth Adam's step-to-step noise; the test runs after every step from ``start + 2 window`` steps on
(``start``: the step where the loss last changed its definition, e.g. ACE in stage 2). The step count a
stage ran is its loss history's length (``loss_log.csv``, ``params.json`` "iterations_run").
"""

from __future__ import annotations


def converged(history: list[float], window: int, tolerance: float, start: int = 0) -> bool:
    """Whether the loss ``history`` (one value per step) has settled; tolerance <= 0 never stops."""
    if tolerance <= 0 or window < 1 or len(history) - start < 2 * window:
        return False
    previous = sum(history[-2 * window:-window]) / window
    last = sum(history[-window:]) / window
    return previous - last <= tolerance * abs(previous)
