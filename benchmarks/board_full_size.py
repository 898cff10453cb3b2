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
from pathlib import Path

from deface.eval.benchmark import SCHEDULES
from deface.eval.board import SPLITS, PairSplit, run_board
from deface.fit import user_options

STEPS = {key: value for key, value in SCHEDULES["quick"].items() if key not in ("resolution", "texture_size")}
"""The quick schedule's steps, without its working size and map size."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("splits", help="comma list of the board's pair splits")
    parser.add_argument("--set", dest="settings", action="append", default=[], help="PATH=VALUE, as deface fit")
    args = parser.parse_args()
    names = [name.strip() for name in args.splits.split(",") if name.strip()]
    pair_splits = {split.name for split in SPLITS if isinstance(split, PairSplit)}
    if not set(names) <= pair_splits:
        parser.error(f"pair splits only: {', '.join(sorted(pair_splits))}")
    figures = run_board(user_options.fit_config(sets=args.settings), args.out, names, pair_schedule=STEPS)
    for name, values in figures.items():
        print(name, " ".join(f"{measure} {value:.3f}" for measure, value in values.items()))


if __name__ == "__main__":
    main()
