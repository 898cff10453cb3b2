"""The pairs protocol's inputs: reading ``DIR/<name>/{source,target}`` pairs.

Layout (one folder per pair, pairs sorted by name; the authors' code used unsorted directory order):

    DIR/<name>/source.png | source.jpg      a single image, or
    DIR/<name>/source/<frames>              a folder of frames (video pair), natural order
    DIR/<name>/target.png | target.jpg | target/<frames>

``shadow_mask.png`` (the synthetic benchmark's: white where the source photo is shadowed, in its pixels) is read
when present: the UV measures score the colour the shadow's edge leaves in the map. Other files and top-level
files (``manifest.json``) are ignored.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")


@dataclass(frozen=True)
class Pair:
    """One evaluation pair: occluded/shadowed source frames and clean target frames of one person."""

    name: str
    """Folder name of the pair."""
    source: list[Path]
    """Source image(s): one path for an image pair, the sorted frames for a video pair."""
    target: list[Path]
    """Target image(s), same convention."""
    shadow_mask: Path | None = None
    """Where the source photo is shadowed (``shadow_mask.png``; None when the pair has none)."""


def natural_key(text: str) -> list:
    """Sort key that orders embedded numbers numerically: frame2 < frame10."""
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", text)]


def _read_side(pair_dir: Path, side: str) -> list[Path]:
    """The image(s) of one side (``source`` or ``target``) of a pair folder."""
    files = [pair_dir / f"{side}{suffix}" for suffix in IMAGE_SUFFIXES]
    files = [f for f in files if f.is_file()]
    folder = pair_dir / side
    if folder.is_dir():
        files.append(folder)
    if not files:
        raise ValueError(f"pair {pair_dir.name!r}: no {side}.png, {side}.jpg or {side}/ folder in {pair_dir}")
    if len(files) > 1:
        raise ValueError(f"pair {pair_dir.name!r}: ambiguous {side}: {', '.join(f.name for f in files)}")
    if files[0].is_file():
        return files
    frames = [f for f in folder.iterdir() if f.is_file() and f.suffix.lower() in IMAGE_SUFFIXES]
    if not frames:
        raise ValueError(f"pair {pair_dir.name!r}: {folder} holds no .png/.jpg frames")
    return sorted(frames, key=lambda f: natural_key(f.name))


def read_pairs(directory: str | Path) -> list[Pair]:
    """All pairs under ``directory``, sorted naturally by name; raises ValueError on a malformed pair."""
    directory = Path(directory)
    if not directory.is_dir():
        raise ValueError(f"pairs directory {directory} does not exist or is not a directory")
    pair_dirs = sorted((d for d in directory.iterdir() if d.is_dir()), key=lambda d: natural_key(d.name))
    if not pair_dirs:
        raise ValueError(f"no pair folders in {directory} (expected {directory}/<name>/source.png ...)")
    pairs = []
    for pair_dir in pair_dirs:
        source, target = _read_side(pair_dir, "source"), _read_side(pair_dir, "target")
        if (pair_dir / "source").is_dir() != (pair_dir / "target").is_dir():
            raise ValueError(f"pair {pair_dir.name!r}: one side is a frames folder, the other an image")
        mask = pair_dir / "shadow_mask.png"
        pairs.append(Pair(pair_dir.name, source, target, mask if mask.is_file() else None))
    return pairs
