"""Contact sheets: rows of image tiles with a caption under each row (benchmarks look at their images)."""

from __future__ import annotations

from pathlib import Path

from PIL import Image, ImageDraw

CAPTION = 14  # pixels of caption text under each row


def image_grid(rows: list[list[Path | Image.Image | None]], captions: list[str], tile: int = 160) -> Image.Image:
    """One tile per image (thumbnailed into tile x tile, None = empty), one caption under each row."""
    columns = max(len(row) for row in rows)
    sheet = Image.new("RGB", (columns * tile, len(rows) * (tile + CAPTION)), "white")
    draw = ImageDraw.Draw(sheet)
    for index, (row, caption) in enumerate(zip(rows, captions, strict=True)):
        top = index * (tile + CAPTION)
        for column, item in enumerate(row):
            if item is None:
                continue
            image = Image.open(item) if isinstance(item, Path) else item
            image = image.convert("RGB")
            image.thumbnail((tile, tile))
            sheet.paste(image, (column * tile, top))
        draw.text((2, top + tile), caption, fill="black")
    return sheet


def texture_sheet(out_dir: Path, pairs: list[str], variants: list[str], before: Path | None = None,
                  tile: int = 192) -> Path:
    """OUT/textures_sheet.png: per pair, the shadowed and clean photos, then per variant the diffuse maps fitted
    from each (and, with ``before``, the same variant's source map from an earlier results folder)."""
    rows, captions = [], []
    for pair in pairs:
        first = out_dir / variants[0] / pair
        row: list[Path | None] = [first / "source.png", first / "target.png"]
        labels = ["shadowed", "clean"]
        if before is not None:
            row.append(_existing(before / variants[0] / pair / "diffuse_source.png"))
            labels.append(f"{variants[0]} before (from shadowed)")
        for variant in variants:
            row += [_existing(out_dir / variant / pair / f"diffuse_{side}.png") for side in ("source", "target")]
            labels += [f"{variant} from shadowed", f"{variant} from clean"]
        rows.append(row)
        captions.append(f"{pair}: " + " | ".join(labels))
    path = out_dir / "textures_sheet.png"
    image_grid(rows, captions, tile).save(path)
    return path


def _existing(path: Path) -> Path | None:
    return path if path.is_file() else None
