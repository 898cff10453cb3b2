"""A person truth folder whose sets are merged into larger ones: the same renders (linked, not copied) under a
manifest whose ``set`` column names the merged set, for fits of more photos of one person than a Blender set holds.

    .venv/bin/python benchmarks/merge_person_sets.py FOLDER OUT NEW=SET+SET[+...] [NEW=...]

FOLDER is a truth folder of person sets (``benchmarks/blender/person_scenes.py``; every set of a folder shows one
head and its albedos); OUT gets a link to each of its files but MANIFEST.tsv, which is rewritten with each listed SET
renamed NEW. E.g. ``eight=five+three`` gives each tone's eight photos as the set ``<tone>_eight``, which
``benchmarks/person_sets.py OUT OUTFITS ita30_eight`` fits.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path


def merge(folder: Path, out: Path, renames: dict[str, str]) -> int:
    """Write OUT (module doc); the number of renders whose set was renamed."""
    out.mkdir(parents=True, exist_ok=True)
    for path in folder.iterdir():
        link = out / path.name
        if path.name != "MANIFEST.tsv" and not link.exists():
            link.symlink_to(path.resolve())
    with (folder / "MANIFEST.tsv").open(newline="") as source:
        rows = list(csv.DictReader(source, delimiter="\t"))
    if not rows or "set" not in rows[0]:
        raise SystemExit(f"error: {folder / 'MANIFEST.tsv'} has no 'set' column")
    unknown = set(renames) - {row["set"] for row in rows}
    if unknown:
        raise SystemExit(f"error: no set {', '.join(sorted(unknown))} in {folder / 'MANIFEST.tsv'}")
    renamed = 0
    for row in rows:
        if row["set"] in renames:
            row["set"], renamed = renames[row["set"]], renamed + 1
    with (out / "MANIFEST.tsv").open("w", newline="") as target:
        writer = csv.DictWriter(target, fieldnames=list(rows[0]), delimiter="\t", lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    return renamed


def renames_of(arguments: list[str]) -> dict[str, str]:
    """NEW=A+B ... -> {A: NEW, B: NEW, ...}."""
    renames = {}
    for argument in arguments:
        new, _, sets = argument.partition("=")
        if not new or not sets:
            raise SystemExit(f"error: {argument!r} is not NEW=SET+SET")
        renames.update({name: new for name in sets.split("+") if name})
    return renames


if __name__ == "__main__":
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    count = merge(Path(sys.argv[1]), Path(sys.argv[2]), renames_of(sys.argv[3:]))
    print(f"{count} renders in merged sets -> {sys.argv[2]}")
