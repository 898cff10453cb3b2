"""Outputs of a pairs evaluation: ``metrics.json`` (fixed schema) and a browsable ``index.html``.

``metrics.json``::

    {"preset": "...",
     "pairs": [{"name": "...", "source": {"face": {"psnr", "ssim", "lpips"}, "full": {...}},
                "target": {"face": {...}, "full": {...}}}, ...],
     "mean": {"source": {"face": {...}, "full": {...}}, "target": {"face": {...}, "full": {...}}}}

``source`` scores the reconstruction of the source photo, ``target`` the target re-rendered with the
source's textures (the paper's "target synthesis"). PSNR in dB, LPIPS x100. Non-finite values (PSNR of
identical images is +inf) are written as ``null`` so the file stays strict JSON.

Optional: a side's scores may also hold ``"identity": {"distance": d}`` (:mod:`deface.eval.identity`, dlib
descriptor distance, lower is better). It is written for the pairs that have it, and its mean only when
every pair has it (a mean over a subset of the pairs would not compare with the other columns).
"""

from __future__ import annotations

import html
import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from deface.eval.metrics import METRIC_NAMES, mean_scores

SIDES = ("source", "target")
REGIONS = ("face", "full")
Scores = Mapping[str, Mapping[str, float]]  # {"face": {"psnr", "ssim", "lpips"}, "full": {...}[, "identity"]}
IDENTITY = "identity"
IDENTITY_NAMES = ("distance",)


@dataclass(frozen=True)
class PairScores:
    """Scores of one pair: each side is a :func:`deface.eval.metrics.score_images` result."""

    name: str
    """Pair name (its folder name)."""
    source: Scores
    """Source reconstruction vs source photo (for video pairs: the mean over frames)."""
    target: Scores
    """Target synthesis (target geometry/lights, source textures) vs target photo."""


def _check_scores(scores: Scores, where: str) -> dict[str, dict[str, float | None]]:
    out = {}
    for region in REGIONS:
        if region not in scores:
            raise ValueError(f"{where}: missing region {region!r} (need 'face' and 'full')")
        out[region] = {}
        for name in METRIC_NAMES:
            if name not in scores[region]:
                raise ValueError(f"{where}.{region}: missing metric {name!r}")
            out[region][name] = _finite(scores[region][name])
    if IDENTITY in scores:
        missing = [name for name in IDENTITY_NAMES if name not in scores[IDENTITY]]
        if missing:
            raise ValueError(f"{where}.{IDENTITY}: missing {missing}")
        out[IDENTITY] = {name: _finite(scores[IDENTITY][name]) for name in IDENTITY_NAMES}
    return out


def _finite(value: float) -> float | None:
    value = float(value)
    return value if math.isfinite(value) else None


def _mean_side(side_scores: Sequence[Scores], where: str) -> dict[str, dict[str, float | None]]:
    mean = mean_scores(side_scores)
    if all(IDENTITY in s for s in side_scores):
        mean[IDENTITY] = {
            name: sum(float(s[IDENTITY][name]) for s in side_scores) / len(side_scores) for name in IDENTITY_NAMES
        }
    return _check_scores(mean, where)


def metrics_document(preset: str, pair_scores: Sequence[PairScores]) -> dict:
    """The ``metrics.json`` content as a dict (see the module docstring)."""
    if not pair_scores:
        raise ValueError("metrics_document: no pair scores")
    pairs = [
        {"name": p.name, **{side: _check_scores(getattr(p, side), f"{p.name}.{side}") for side in SIDES}}
        for p in pair_scores
    ]
    mean = {side: _mean_side([getattr(p, side) for p in pair_scores], side) for side in SIDES}
    return {"preset": preset, "pairs": pairs, "mean": mean}


def write_metrics_json(path: str | Path, preset: str, pair_scores: Sequence[PairScores]) -> Path:
    """Write ``metrics.json`` (strict JSON, 2-space indent) and return its path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    document = metrics_document(preset, pair_scores)
    path.write_text(json.dumps(document, indent=2, allow_nan=False) + "\n")
    return path


@dataclass(frozen=True)
class ReportRow:
    """One pair in ``index.html``: its images side by side and its scores."""

    name: str
    """Pair name."""
    images: Mapping[str, Path]
    """Label -> image file, shown left to right in this order (e.g. source, target, source
    reconstruction, target reconstruction, swapped render, diffuse/specular/roughness textures)."""
    scores: Mapping[str, Scores] = field(default_factory=dict)
    """Optional ``{"source": scores, "target": scores}`` shown in a table under the images."""


def _fmt(value: float | None) -> str:
    if value is None or not math.isfinite(value):
        return "inf" if value is not None and value > 0 else "-"
    return f"{value:.4f}" if abs(value) < 1.5 else f"{value:.2f}"


def _scores_table(scores: Mapping[str, Scores]) -> str:
    head = "".join(f"<th>{r} {m}</th>" for r in REGIONS for m in METRIC_NAMES)
    with_identity = any(IDENTITY in side_scores for side_scores in scores.values())
    head += "<th>ID dist</th>" if with_identity else ""
    rows = []
    for side, side_scores in scores.items():
        cells = "".join(f"<td>{_fmt(side_scores[r][m])}</td>" for r in REGIONS for m in METRIC_NAMES)
        if with_identity:
            cells += f"<td>{_fmt(side_scores.get(IDENTITY, {}).get('distance'))}</td>"
        rows.append(f"<tr><th>{html.escape(side)}</th>{cells}</tr>")
    return f"<table class='scores'><tr><th></th>{head}</tr>{''.join(rows)}</table>"


def write_index_html(path: str | Path, rows: Sequence[ReportRow], title: str = "deface evaluation") -> Path:
    """Write a static HTML page: per pair, images side by side (relative links) and a scores table.

    Image paths are linked relative to the page's folder, so the output folder can be moved as a whole.
    PSNR in dB, LPIPS x100; "face" and "full" as defined in :mod:`deface.eval.metrics`.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    base = path.parent.resolve()
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'>",
        f"<title>{html.escape(title)}</title><style>",
        "body{font-family:sans-serif;margin:1em} figure{display:inline-block;margin:4px;text-align:center}",
        "img{height:192px;image-rendering:auto} figcaption{font-size:12px}",
        "table.scores{border-collapse:collapse;font-size:13px} table.scores td,table.scores th"
        "{border:1px solid #aaa;padding:2px 6px;text-align:right}",
        f"</style></head><body><h1>{html.escape(title)}</h1>",
        "<p>PSNR in dB, LPIPS x100. <b>face</b>: face-mask pixels only; <b>full</b>: mask&middot;output + "
        "(1&minus;mask)&middot;input over the whole image (the authors' protocol). <b>ID dist</b> (when dlib is "
        "installed): dlib face-descriptor distance of that composite to the photo, lower is better, &lt; 0.6 = "
        "same person.</p>",
    ]
    for row in rows:
        parts.append(f"<section><h2>{html.escape(row.name)}</h2><div>")
        for label, image in row.images.items():
            rel = Path(os.path.relpath(Path(image).resolve(), base)).as_posix()
            src = html.escape(rel, quote=True)
            parts.append(
                f"<figure><a href='{src}'><img src='{src}' alt='{html.escape(label)}'></a>"
                f"<figcaption>{html.escape(label)}</figcaption></figure>"
            )
        parts.append("</div>")
        if row.scores:
            parts.append(_scores_table(row.scores))
        parts.append("</section>")
    parts.append("</body></html>\n")
    path.write_text("\n".join(parts))
    return path
