"""Compare two fit output folders for bit-identity: a refactor that keeps behaviour must pass this.

    python scripts/compare_runs.py BEFORE AFTER

Compares, for every run folder (one holding params.json) found under BEFORE and its counterpart under AFTER:
every array of params.npz exactly, every PNG's pixels exactly, loss_log.csv as text, and params.json
without what records when, where and how long (timings, versions, the input's path). Prints each difference
and exits 1 when there is one.
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import numpy as np
from PIL import Image

VOLATILE = {"seconds_per_stage", "versions", "input"}  # when, with what, from where


def _strip(value):
    if isinstance(value, str):
        return re.sub(r"\d+(\.\d+)? s\b", "<seconds>", value)  # "stage 2 done in 40.2 s"
    if isinstance(value, dict):
        return {k: _strip(v) for k, v in value.items() if k not in VOLATILE}
    if isinstance(value, list):
        return [_strip(v) for v in value]
    return value


def _compare_run(before: Path, after: Path) -> list[str]:
    problems = []
    if _strip(json.loads((before / "params.json").read_text())) != \
            _strip(json.loads((after / "params.json").read_text())):
        problems.append("params.json differs")
    if (before / "params.npz").exists():
        old, new = np.load(before / "params.npz"), np.load(after / "params.npz")
        for key in sorted(set(old.files) | set(new.files)):
            if key not in old.files or key not in new.files or not np.array_equal(old[key], new[key]):
                problems.append(f"params.npz[{key}] differs")
    for name in ("loss_log.csv",):
        if (before / name).exists() and (before / name).read_text() != (after / name).read_text():
            problems.append(f"{name} differs")
    for png in sorted(before.rglob("*.png")):
        other = after / png.relative_to(before)
        if not other.exists():
            problems.append(f"{png.relative_to(before)} missing")
        elif not np.array_equal(np.asarray(Image.open(png)), np.asarray(Image.open(other))):
            problems.append(f"{png.relative_to(before)} differs")
    return problems


def main(before: Path, after: Path) -> int:
    runs = sorted(p.parent for p in before.rglob("params.json"))
    if not runs:
        print(f"no run folder (with params.json) under {before}")
        return 1
    failed = 0
    for run in runs:
        problems = _compare_run(run, after / run.relative_to(before))
        failed += bool(problems)
        print(f"{run.relative_to(before)}: " + ("identical" if not problems else "; ".join(problems)))
    return 1 if failed else 0


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    sys.exit(main(Path(sys.argv[1]), Path(sys.argv[2])))
