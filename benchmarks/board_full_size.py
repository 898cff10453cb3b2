"""The board's shadow-pair splits at the default working size: the quick schedule's steps, but the working image and
the map at the default's sizes (a 512-px crop), where thin shadows a few pixels wide at the board's 128 px resolve.

    DEFACE_MODELS=../shared/models .venv/bin/python benchmarks/board_full_size.py OUT stripes-warm,dapples \
        [--set PATH=VALUE ...]

OUT/pairs/<split> holds the pairs (made from the split's seed when absent, as `deface bench board` makes them);
each pair's scores are recorded in OUT/fits/<split>/<pair>/scores.json, so a re-run fits only what changed. Prints
the same means as the board (deface/eval/board.py ``pair_figures``) per split. Fits two pairs at a time.
"""

from __future__ import annotations

import argparse
from functools import partial
from pathlib import Path

from deface.batch.recorded import RecordedTask, run_recorded
from deface.eval.benchmark import SCHEDULES, pair_scores
from deface.eval.board import SPLITS, make_pairs, pair_figures
from deface.eval.pairs import read_pairs
from deface.fit import user_options
from deface.fit.config import FitConfig, override


def full_size_config(settings: list[str]) -> FitConfig:
    """The default with the quick schedule's steps (not its working size nor its map size) and ``settings``."""
    steps = {key: value for key, value in SCHEDULES["quick"].items() if key not in ("resolution", "texture_size")}
    return override(user_options.fit_config(sets=settings), **steps)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("splits", help="comma list of the board's pair splits")
    parser.add_argument("--set", dest="settings", action="append", default=[], help="PATH=VALUE, as deface fit")
    args = parser.parse_args()
    config = full_size_config(args.settings)
    by_name = {split.name: split for split in SPLITS}
    names = [name.strip() for name in args.splits.split(",") if name.strip()]
    tasks, owners = [], []
    for name in names:
        for pair in read_pairs(make_pairs(by_name[name], args.out / "pairs" / name)):
            folder = args.out / "fits" / name / pair.name
            tasks.append(RecordedTask(f"{name} / {pair.name}", folder / "scores.json", config,
                                      partial(pair_scores, pair, config, folder, None)))
            owners.append(name)
    records = run_recorded(tasks, 2, None, lambda index, _: print(f"{tasks[index].name}: done", flush=True))
    for name in names:
        figures = pair_figures([record for record, owner in zip(records, owners, strict=True) if owner == name])
        print(name, " ".join(f"{measure} {value:.3f}" for measure, value in figures.items()))


if __name__ == "__main__":
    main()
