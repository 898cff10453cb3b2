"""``MANIFEST.tsv``: the table of a benchmark set that lists its images (tab-separated, a header line, one row per
image), as the albedo truth sets (deface/eval/albedo_benchmark.py) and the skin-tone sets
(deface/eval/tone_benchmark.py) hold it beside ``images/``.
"""

from __future__ import annotations

import csv
from pathlib import Path

MANIFEST = "MANIFEST.tsv"


def read_manifest_rows(folder: Path, columns: tuple[str, ...], described: str) -> tuple[Path, list[dict[str, str]]]:
    """``folder``'s manifest and its rows (column -> text); one-line errors when it is missing (``described``
    says what it holds), has no rows, or lacks one of ``columns``."""
    manifest = folder / MANIFEST
    if not manifest.is_file():
        raise ValueError(f"{folder}: no {MANIFEST} ({described})")
    with manifest.open(newline="") as handle:
        reader = csv.DictReader(handle, delimiter="\t")
        rows = list(reader)
    missing = set(columns) - set(reader.fieldnames or ())
    if missing:
        raise ValueError(f"{manifest}: missing column(s) {', '.join(sorted(missing))}")
    if not rows:
        raise ValueError(f"{manifest}: no rows")
    return manifest, rows
