"""A contact sheet of the board's pair maps, two board runs side by side, to look at every map they made.

    .venv/bin/python benchmarks/board_sheet.py BEFORE_OUT AFTER_OUT -o SHEET.jpg [--splits stripes-warm,dapples]

Per pair (rows, in two columns of pairs): the shadowed photo | the shadowed photo's diffuse map before | after |
the clean photo's map before | after. BEFORE_OUT and AFTER_OUT are `deface bench board -o` folders.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from PIL import Image, ImageDraw

TILE = 128
COLUMNS = ("source.png", ("before", "diffuse_source.png"), ("after", "diffuse_source.png"),
           ("before", "diffuse_target.png"), ("after", "diffuse_target.png"))


def pair_row(before: Path, after: Path) -> Image.Image:
    row = Image.new("RGB", (TILE * len(COLUMNS), TILE))
    for index, column in enumerate(COLUMNS):
        folder, name = (before, column) if isinstance(column, str) else ({"before": before, "after": after}[
            column[0]], column[1])
        row.paste(Image.open(folder / name).convert("RGB").resize((TILE, TILE)), (index * TILE, 0))
    ImageDraw.Draw(row).text((3, 3), before.name, fill=(255, 255, 0))
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("before", type=Path)
    parser.add_argument("after", type=Path)
    parser.add_argument("-o", "--output", type=Path, required=True)
    parser.add_argument("--splits", default="stripes-warm,dapples,mixed,held-out")
    args = parser.parse_args()
    rows = []
    for split in args.splits.split(","):
        folder = args.before / "fits" / split
        if not folder.is_dir():
            continue
        for pair in sorted(p for p in folder.iterdir() if (p / "diffuse_source.png").is_file()):
            rows.append(pair_row(pair, args.after / "fits" / split / pair.name))
    half = (len(rows) + 1) // 2
    sheet = Image.new("RGB", (2 * TILE * len(COLUMNS) + TILE // 4, half * TILE), (255, 255, 255))
    for index, row in enumerate(rows):
        sheet.paste(row, ((index // half) * (TILE * len(COLUMNS) + TILE // 4), (index % half) * TILE))
    sheet.save(args.output, quality=88)
    print(f"{len(rows)} pairs -> {args.output}")


if __name__ == "__main__":
    main()
