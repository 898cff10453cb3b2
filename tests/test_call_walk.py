"""The reader's walk of a fit (scripts/call_walk.py): its rules on a made-up call sequence, and on a real fit the
spine enters no package more than three times."""

from __future__ import annotations

import importlib.util
from collections import Counter
from pathlib import Path
from types import SimpleNamespace

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "call_walk.py"
spec = importlib.util.spec_from_file_location("call_walk", SCRIPT)
call_walk = importlib.util.module_from_spec(spec)
spec.loader.exec_module(call_walk)


def _code(module: str, line: int, name: str = "f") -> SimpleNamespace:
    return SimpleNamespace(co_filename=f"{call_walk.ROOT}/{module}", co_firstlineno=line, co_name=name,
                           co_qualname=name)


def _run(walk, calls) -> None:
    """``calls``: nested (code, [children]) pairs, replayed as call / return events."""
    for code, children in calls:
        walk(SimpleNamespace(f_code=code), "call", None)
        _run(walk, children)
        walk(None, "return", None)


def test_entries_count_steps_into_a_package_not_calls_back_or_repeats():
    cli, task, fit_a, fit_b, render, export = (_code("cli/fit.py", 1), _code("batch/task.py", 1),
                                               _code("fit/pipeline.py", 1), _code("fit/stage2.py", 9),
                                               _code("render/frame.py", 1), _code("export/outputs.py", 1))
    callback = _code("fit/rendering.py", 5)
    walk = call_walk.Walk()
    _run(walk, [(cli, [(task, [
        (fit_a, [(render, [(callback, [])]), (fit_b, [(render, [])])]),  # render read once; callback: no entry
        (fit_a, [(export, [])]),  # fit_a read already: skipped with what it calls
        (export, []), (_code("batch/task.py", 1, "<module>"), [(fit_b, [])]),  # an import: not walked
    ])])])
    entered = [(name, level) for _, level, name, _, is_entry in walk.steps if is_entry]
    assert entered == [("deface.cli", 1), ("deface.batch", 2), ("deface.fit", 3), ("deface.render", 4),
                       ("deface.export", 3)]
    assert walk.spine() == ["deface.cli", "deface.batch", "deface.fit", "deface.export"]
    assert walk.library_entries() == Counter({"deface.render": 1})


@pytest.mark.slow
def test_a_fit_s_spine_enters_no_package_more_than_three_times(photos):
    walk = call_walk.walk_fit(str(photos / "nextface-s1.png"), iterations=2)
    spine = walk.spine()
    assert spine[0] == "deface.cli" and "deface.batch" in spine and spine[-1] == "deface.report"
    assert max(Counter(spine).values()) <= 3, spine
