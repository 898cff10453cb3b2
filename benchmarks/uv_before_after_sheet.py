"""Both maps of each shadow pair (from the shadowed and from the clean photo), before and after a change, cropped
to the face: what UV consistency measures, to judge by eye (`deface bench sheet` shows one map of "before").

    .venv/bin/python benchmarks/uv_before_after_sheet.py BEFORE AFTER OUT.jpg PAIR [PAIR ...]

BEFORE and AFTER are `deface bench run` results folders (variant ``ours``).
"""

from __future__ import annotations

import sys
from pathlib import Path

from PIL import Image, ImageDraw

SIDE = 220
FACE = (0.2, 0.0, 0.8, 0.6)  # the face's part of the ICT UV layout (left, top, right, bottom)
COLUMNS = ("shadowed photo", "before: from shadowed", "before: from clean", "after: from shadowed",
           "after: from clean")


def _face(path: Path) -> Image.Image:
    image = Image.open(path).convert("RGB")
    w, h = image.size
    return image.crop((int(w * FACE[0]), int(h * FACE[1]), int(w * FACE[2]), int(h * FACE[3]))).resize((SIDE, SIDE))


def main() -> None:
    before, after, out, pairs = Path(sys.argv[1]), Path(sys.argv[2]), Path(sys.argv[3]), sys.argv[4:]
    sheet = Image.new("RGB", (SIDE * len(COLUMNS), 24 + SIDE * len(pairs)), "white")
    draw = ImageDraw.Draw(sheet)
    for column, title in enumerate(COLUMNS):
        draw.text((column * SIDE + 6, 6), title, fill="black")
    for row, pair in enumerate(pairs):
        top = 24 + row * SIDE
        sheet.paste(Image.open(after / "ours" / pair / "source.png").convert("RGB").resize((SIDE, SIDE)), (0, top))
        maps = [run / "ours" / pair / name for run in (before, after)
                for name in ("diffuse_source.png", "diffuse_target.png")]
        for column, path in enumerate(maps, start=1):
            sheet.paste(_face(path), (column * SIDE, top))
    sheet.save(out, quality=88)


if __name__ == "__main__":
    main()
