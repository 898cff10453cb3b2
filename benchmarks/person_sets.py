"""The sets of a person truth folder fitted as several photos of one person, without fitting each photo alone (what
``deface bench albedo FOLDER --sets`` adds for its 'alone' columns): for comparing variants of the joint fit.

    .venv/bin/python benchmarks/person_sets.py FOLDER OUT SET[,SET...] [PATH=VALUE ...]
    .venv/bin/python benchmarks/person_sets.py --table OUT [OUT ...]

FOLDER is a truth folder of person sets (``benchmarks/blender/person_scenes.py``), SET its sets' names (albedo_set,
as ``sets.md`` names them), PATH=VALUE config changes as ``deface fit --set`` takes them, at the default preset's
full schedule. Each set's fit and ``record.json`` (the scores of ``deface/eval/person_benchmark.py``) go to
OUT/<set>/; a set already recorded there is not fitted again. ``--table`` prints the recorded sets of each OUT side
by side, and their means over the sets they share.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from deface.eval.person_benchmark import measure_set, read_truth_sets
from deface.fit import presets
from deface.fit.config import set_from_text

COLUMNS = (("PSNR", ("face", "psnr")), ("CE", ("face", "colour_error")), ("noise", ("face", "colour_noise")),
           ("beard", ("beard", "darkness_kept")), ("fine", ("beard", "fine_structure")),
           ("birthmark", ("birthmark", "darkness_kept")), ("freckles fine", ("freckle_area", "fine_structure")))


def fit_sets(folder: Path, out: Path, names: list[str], settings: list[str]) -> None:
    config = presets.get("default")
    for assignment in settings:
        config = set_from_text(config, assignment)
    for truth_set in read_truth_sets(folder):
        record = out / truth_set.stem / "record.json"
        if truth_set.stem not in names or record.exists():
            continue
        record.parent.mkdir(parents=True, exist_ok=True)
        result = measure_set(folder, truth_set, config, record.parent)
        record.write_text(json.dumps(dict(result, settings=settings), indent=1))
        print(truth_set.stem, " ".join(f"{name} {value:.2f}" for name, value in row(result)), flush=True)


def row(record: dict) -> list[tuple[str, float]]:
    scores = record["scores"]
    return [(name, float(scores[region][key])) for name, (region, key) in COLUMNS] + [("s", record["seconds"])]


def table(outs: list[Path]) -> str:
    rows = {out: {path.parent.name: row(json.loads(path.read_text())) for path in out.glob("*/record.json")}
            for out in outs}
    names = [name for name, _ in COLUMNS] + ["s"]
    lines = [" | ".join(["set", *(f"{out.name}: " + " / ".join(names) for out in outs)])]
    for stem in sorted(set().union(*rows.values())):
        cells = [" / ".join(f"{v:.2f}" for _, v in rows[out][stem]) if stem in rows[out] else "-" for out in outs]
        lines.append(" | ".join([stem, *cells]))
    shared = sorted(set.intersection(*(set(r) for r in rows.values())))
    means = [" / ".join(f"{v:.2f}" for v in np.mean([[v for _, v in rows[out][s]] for s in shared], 0))
             if shared else "-" for out in outs]
    lines.append(" | ".join([f"mean of {len(shared)}", *means]))
    return "\n".join(lines)


if __name__ == "__main__":
    if sys.argv[1] == "--table":
        print(table([Path(arg) for arg in sys.argv[2:]]))
    else:
        fit_sets(Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3].split(","), sys.argv[4:])
