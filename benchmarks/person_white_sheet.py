"""A sheet of several-photo fits' diffuse maps beside the truth's, one row per set: what ``tone.white_per_photo``
changes, looked at.

    .venv/bin/python benchmarks/person_white_sheet.py TRUTH_FOLDER SHEET.jpg SET[,SET...] LABEL=OUT [LABEL=OUT ...]

Each OUT is a ``benchmarks/person_sets.py`` output folder (OUT/<set>/textures/diffuse.png); each row shows the set's
photos (TRUTH_FOLDER/images/<set>_<n>.png), the truth's albedo, and each OUT's map, labelled.
"""

from __future__ import annotations

import sys
from pathlib import Path

from PIL import Image, ImageDraw

TILE = 256


def tile(path: Path, label: str) -> Image.Image:
    image = Image.open(path).convert("RGB").resize((TILE, TILE), Image.LANCZOS)
    ImageDraw.Draw(image).text((4, 4), label, fill=(255, 255, 255))
    return image


def main(truth: Path, sheet: Path, sets: list[str], outs: list[tuple[str, Path]]) -> None:
    rows = []
    for name in sets:
        tone = name.split("_")[0]
        photos = sorted((truth / "images").glob(f"{name}_*.png"))
        cells = [tile(photo, photo.stem) for photo in photos] + [tile(truth / "albedo" / f"{tone}.png", "truth")]
        cells += [tile(out / name / "textures" / "diffuse.png", label) for label, out in outs]
        rows.append(cells)
    width = max(len(row) for row in rows)
    canvas = Image.new("RGB", (width * TILE, len(rows) * TILE))
    for r, row in enumerate(rows):
        for c, cell in enumerate(row):
            canvas.paste(cell, (c * TILE, r * TILE))
    canvas.save(sheet, quality=88)


if __name__ == "__main__":
    if len(sys.argv) < 5:
        sys.exit(__doc__)
    main(Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3].split(","),
         [(arg.split("=", 1)[0], Path(arg.split("=", 1)[1])) for arg in sys.argv[4:]])
