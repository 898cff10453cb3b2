"""Earlier commits' defaults on the board's pair splits, beside today's: what each round's default does on fresh
pairs (issue 57, "find what cost what").

    .venv/bin/python benchmarks/old_defaults.py BOARD_OUT COMMIT [COMMIT ...] -o OUT [--sheet SHEET.jpg]

BOARD_OUT is a `deface bench board -o` folder: its ``pairs/`` holds the splits' pairs, its ``fits/`` today's
default. For each commit, a git worktree of it (OUT/src-COMMIT) runs that commit's own
`deface bench run PAIRS --variants ours --schedule quick` on every pair split: the texture-swap protocol as it was
then (before the crop of issue 39, the whole frame at 128 px, where a face spans fewer pixels than in today's
crop; run today's default with `--set crop.enabled=false` for the same framing). Prints each split's mean target
synthesis (face PSNR / SSIM / LPIPS) per commit and for BOARD_OUT, then every pair's PSNR. ``--sheet``: per pair,
the shadowed photo, then each commit's map of it, then today's.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

REPOSITORY = Path(__file__).resolve().parents[1]
TILE = 128


def worktree(commit: str, out: Path) -> Path:
    """A checkout of ``commit`` under ``out`` (made once)."""
    folder = out / f"src-{commit}"
    if not folder.exists():
        subprocess.run(["git", "-C", str(REPOSITORY), "worktree", "add", "--detach", str(folder), commit],
                       check=True, capture_output=True)
    return folder


def run_commit(commit: str, pairs: Path, out: Path) -> None:
    """That commit's default on every split of ``pairs`` (its fits cached per pair by its own `bench run`)."""
    source = worktree(commit, out)
    environment = dict(os.environ, PYTHONPATH=str(source))
    for split in sorted(p.name for p in pairs.iterdir() if p.is_dir()):
        subprocess.run([sys.executable, "-c", "from deface.cli.main import main; main()", "bench", "run",
                        str(pairs / split), "-o", str(out / commit / split), "--variants", "ours", "--schedule",
                        "quick", "--report", str(out / f"report-{commit}.md")], cwd=source, env=environment,
                       check=True)


def pair_folders(root: Path, split: str) -> dict[str, Path]:
    """{pair: folder holding its scores.json} of a `bench run` (root/split/ours) or a board (root/fits/split)."""
    for folder in (root / split / "ours", root / "fits" / split):
        if folder.is_dir():
            return {p.parent.name: p.parent for p in sorted(folder.glob("*/scores.json"))}
    return {}


def face_scores(folder: Path) -> dict:
    return json.loads((folder / "scores.json").read_text())["target"]["face"]


def report(columns: dict[str, Path], splits: list[str]) -> str:
    lines = ["| split | " + " | ".join(columns) + " |", "|---" * (len(columns) + 1) + "|"]
    for split in splits:
        cells = []
        for root in columns.values():
            scores = [face_scores(f) for f in pair_folders(root, split).values()]
            cells.append(" / ".join(f"{np.mean([s[k] for s in scores]):.{d}f}" for k, d in
                                    (("psnr", 2), ("ssim", 3), ("lpips", 2))) if scores else "-")
        lines.append(f"| {split} | " + " | ".join(cells) + " |")
    lines += ["", "| split | pair | " + " | ".join(columns) + " |", "|---" * (len(columns) + 2) + "|"]
    for split in splits:
        for pair in pair_folders(next(iter(columns.values())), split):
            cells = [pair_folders(root, split).get(pair) for root in columns.values()]
            lines.append(f"| {split} | {pair} | " + " | ".join(
                f"{face_scores(c)['psnr']:.2f}" if c else "-" for c in cells) + " |")
    return "\n".join(lines)


def sheet(columns: dict[str, Path], splits: list[str], path: Path) -> None:
    """Per pair (rows): the shadowed photo, then each column's diffuse map of it."""
    rows = []
    for split in splits:
        for pair, first in pair_folders(next(iter(columns.values())), split).items():
            folders = [pair_folders(root, split).get(pair) for root in columns.values()]
            row = Image.new("RGB", (TILE * (len(columns) + 1), TILE))
            row.paste(Image.open(first / "source.png").convert("RGB").resize((TILE, TILE)), (0, 0))
            for index, folder in enumerate(folders, 1):
                if folder is not None:
                    row.paste(Image.open(folder / "diffuse_source.png").convert("RGB").resize((TILE, TILE)),
                              (index * TILE, 0))
            ImageDraw.Draw(row).text((3, 3), f"{split[:7]} {pair[:14]}", fill=(255, 255, 0))
            rows.append(row)
    half = (len(rows) + 1) // 2
    canvas = Image.new("RGB", (2 * rows[0].width, half * TILE + 14), "black")
    for index, row in enumerate(rows):
        canvas.paste(row, ((index // half) * row.width, 14 + (index % half) * TILE))
    ImageDraw.Draw(canvas).text((3, 1), "photo | " + " | ".join(columns) + " (each pair's shadowed-photo map)",
                                fill=(255, 255, 255))
    canvas.save(path, quality=88)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("board", type=Path, help="a `deface bench board -o` folder")
    parser.add_argument("commits", nargs="+", help="commits whose default is run")
    parser.add_argument("-o", "--output", type=Path, required=True)
    parser.add_argument("--also", action="append", default=[], metavar="LABEL=BOARD_OUT",
                        help="another board folder to show (e.g. today's default without the crop)")
    parser.add_argument("--sheet", type=Path)
    args = parser.parse_args()
    pairs = args.board / "pairs"
    splits = sorted(p.name for p in pairs.iterdir() if p.is_dir())
    for commit in args.commits:
        run_commit(commit, pairs, args.output.resolve())
    columns = {commit: args.output / commit for commit in args.commits}
    columns.update(dict((label, Path(folder)) for label, folder in (a.split("=", 1) for a in args.also)))
    columns["today"] = args.board
    print(report(columns, splits))
    if args.sheet:
        sheet(columns, splits, args.sheet)


if __name__ == "__main__":
    main()
