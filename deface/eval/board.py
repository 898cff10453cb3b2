"""The board that guards the default: every split a change to the fit is judged on, in one command, against the
figures of the last accepted default (``benchmarks/board/accepted.json``).

Splits (:data:`SPLITS`):
- pair splits: shadowed/clean pairs made by ``deface bench make-shadows`` from photos the choices before the board
  never saw (``benchmarks/board/photos``, sources in its SOURCES.md) and from the shared skin-tone photos, each with
  its own seed and shadow family (thin stripes under a warm sun with a cool fill, sun-dapples, the mixed
  occluders of the shared silhouettes and procedural shapes), fitted at the ``quick`` schedule;
  scored by the texture swap (target synthesis, face PSNR / SSIM / LPIPS), the same person's tone gap (ITA of
  the shadowed photo's map against the clean one's) and the maps' colour noise;
- truth splits: renders of a known albedo (``../shared/data/detail-synth``: PSNR, colour error, colour noise
  over the truth's, the beard's darkness kept) and of known skin tones (``skin-tone-synth``: ITA error), fitted at
  the configuration as it is.
One pair split (``held_out``) is left out unless asked for (``--held-out``): it is the split no choice has seen;
when a choice has used it, replace it by a new one (new seed, new photos) and say so in the log. Seed 34 accepted
the chroma filter (2026-11-27), seed 35 the occluder finder, seed 36 the shading evidence's hair zone, seed 37 the
chroma window of two photo pixels (all 2026-11-28; the figures of each are kept in accepted.json's
``used_held_out``). Seed 38 was retired unused, once a variant's figures on it had been read (``retired_held_out``).
Seed 39 accepted the texels in the dark moved to the lit skin, seed 40 the pigments' hues, seed 41 the eyes' openings
left out of h (all 2026-11-29). It is now seed 42 (hats, leaves, stripes, silhouettes; a warm key with a cool fill;
four of its photos new to the held-out split, though the other splits have them).

A figure is flagged when it is worse than the accepted one by more than its tolerance (:data:`MEASURES`), about
the noise between runs, so a flag is a loss beyond the noise.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import numpy as np

from deface.batch.recorded import RecordedTask, run_recorded
from deface.eval.albedo_benchmark import FACE, measure_render, read_truth_set
from deface.eval.albedo_benchmark import summary as albedo_summary
from deface.eval.benchmark import SCHEDULES, pair_scores
from deface.eval.pairs import read_pairs
from deface.eval.shadows import SHAPE_KINDS, ShadowConfig, make_shadow_benchmark, shared_silhouettes, silhouette_files
from deface.fit.config import FitConfig, override
from deface.paths import shared_dir

REPOSITORY = Path(__file__).resolve().parents[2]
BOARD_DIR = REPOSITORY / "benchmarks" / "board"
ACCEPTED = BOARD_DIR / "accepted.json"


@dataclass(frozen=True)
class PairSplit:
    """Pairs made from ``photos`` ("board:NAME" in benchmarks/board/photos, "shared:PATH" under ../shared)."""

    name: str
    photos: tuple[str, ...]
    seed: int
    kinds: tuple[str, ...] = SHAPE_KINDS
    fill: tuple[float, float, float] = (1.0, 1.0, 1.0)
    warm: tuple[float, float] = (0.0, 0.0)
    penumbra: tuple[float, float] = (0.004, 0.035)
    held_out: bool = False


@dataclass(frozen=True)
class TruthSplit:
    """Renders of a known albedo ("albedo") or known skin tones ("tone") in ``folder`` under ../shared."""

    name: str
    folder: str
    kind: str
    held_out: bool = False


BOARD_PHOTOS = ("board:astronaut.png", "board:biden.jpg", "board:obama.jpg", "board:obama_speech.jpg")
SKIN = "shared:data/skin-tone/images/"
SPLITS: tuple[PairSplit | TruthSplit, ...] = (
    PairSplit("stripes-warm", BOARD_PHOTOS + tuple(SKIN + f for f in (
        "dark_curly_hair_woman.jpg", "light_blond_bearded_man.jpg", "medium_young_man_smiling.jpg",
        "medium_fairface_older_woman_1561.jpg")), seed=31, kinds=("stripes",), fill=(0.55, 0.75, 1.0),
        warm=(0.5, 0.9), penumbra=(0.002, 0.01)),
    PairSplit("dapples", BOARD_PHOTOS + tuple(SKIN + f for f in (
        "dark_fairface_boy.jpg", "light_girl_bangs.jpg", "medium_pexels_woman_glasses.jpg",
        "light_unsplash_woman.jpg")), seed=32, kinds=("dapples",)),
    PairSplit("mixed", tuple(SKIN + f for f in (
        "dark_unsplash_turban_man.jpg", "light_man_dark_background.jpg", "light_woman_pout.png",
        "medium_aflw_woman_00480.jpg", "medium_man_glasses_beard.jpg", "dark_fairface_woman_1423.jpg")) + (
        "shared:data/images/nextface-s3.png", "shared:data/images/vd092.png"), seed=33),
    PairSplit("held-out", BOARD_PHOTOS + tuple(SKIN + f for f in (
        "light_man_dark_background.jpg", "medium_aflw_woman_00480.jpg", "light_unsplash_woman.jpg",
        "dark_unsplash_turban_man.jpg")), seed=42, kinds=("hat", "leaves", "stripes", "silhouette"),
        fill=(0.5, 0.75, 1.0), warm=(0.4, 0.8), penumbra=(0.002, 0.02), held_out=True),
    TruthSplit("detail-synth", "data/detail-synth", "albedo"),
    TruthSplit("skin-tone-synth", "data/skin-tone-synth", "tone"),
)


@dataclass(frozen=True)
class Measure:
    """A board figure: higher or lower is better, and the loss beyond which it is flagged."""

    higher_is_better: bool
    tolerance: float
    unit: str = ""


MEASURES = {
    "synthesis_psnr": Measure(True, 0.3, "dB"),
    "synthesis_ssim": Measure(True, 0.01),
    "synthesis_lpips": Measure(False, 1.0),
    "ita_gap": Measure(False, 1.0, "deg"),
    "colour_noise": Measure(False, 0.5),
    "psnr": Measure(True, 0.3, "dB"),
    "colour_error": Measure(False, 0.3),
    "noise_over_truth": Measure(False, 0.15),
    "beard_kept": Measure(True, 0.1),
    "ita_error": Measure(False, 1.0, "deg"),
}
"""Tolerances: what a figure may lose before it is called a loss, chosen by hand as the board's rule (about what
a seed moves a mean over eight fits). The default's measured spread over seeds (``--set seed=1``, ``seed=2``) is in
docs/evaluation.md "The board": on dapples a seed alone moves the synthesis by 0.35 dB and the ITA gap by 1.2
degrees, on stripes-warm the colour noise by 0.6, so a flag there is checked with a second seed."""


def split_names(include_held_out: bool = False) -> list[str]:
    return [s.name for s in SPLITS if include_held_out or not s.held_out]


def _photo_path(spec: str) -> Path:
    where, _, name = spec.partition(":")
    if where == "board":
        return BOARD_DIR / "photos" / name
    shared = shared_dir()
    if shared is None:
        raise ValueError(f"board split photo {spec}: ../shared is absent (set DEFACE_SHARED)")
    return shared / name


def make_pairs(split: PairSplit, folder: Path) -> Path:
    """The split's pairs in ``folder`` (made once: the same seed writes the same bytes)."""
    if not (folder / "manifest.json").is_file():
        files = silhouette_files(shared_silhouettes()) if "silhouette" in split.kinds else ()
        kinds = split.kinds if files else tuple(k for k in split.kinds if k != "silhouette")
        config = ShadowConfig(kinds=kinds, fill=split.fill, warm=split.warm, penumbra=split.penumbra,
                              silhouettes=files)
        make_shadow_benchmark([_photo_path(p) for p in split.photos], folder, seed=split.seed, config=config)
    return folder


@dataclass
class BoardRun:
    """The tasks of one board run, and per split which tasks are its and how their records become its figures."""

    tasks: list[RecordedTask] = field(default_factory=list)
    owners: list[str] = field(default_factory=list)  # the split of each task
    readers: dict = field(default_factory=dict)  # split name -> ([task records]) -> {measure: value}

    def add(self, split: str, task: RecordedTask) -> None:
        self.tasks.append(task)
        self.owners.append(split)


def _pair_split(run: BoardRun, split: PairSplit, config: FitConfig, out_dir: Path, models_dir) -> None:
    """``config`` is the pairs' own (the judged one with the pair splits' schedule, :func:`run_board`)."""
    pairs = read_pairs(make_pairs(split, out_dir / "pairs" / split.name))
    for pair in pairs:
        folder = out_dir / "fits" / split.name / pair.name
        run.add(split.name, RecordedTask(f"{split.name} / {pair.name}", folder / "scores.json", config,
                                         partial(pair_scores, pair, config, folder, models_dir)))
    run.readers[split.name] = pair_figures


def _truth_split(run: BoardRun, split: TruthSplit, config: FitConfig, out_dir: Path, models_dir) -> None:
    shared = shared_dir()
    if shared is None:
        raise ValueError(f"board split {split.name}: ../shared is absent (set DEFACE_SHARED)")
    folder = shared / split.folder
    if split.kind == "albedo":
        for render in read_truth_set(folder):
            result_dir = out_dir / "fits" / split.name / render.stem
            run.add(split.name, RecordedTask(f"{split.name} / {render.stem}", result_dir / "scores.json", config,
                                             partial(measure_render, folder, render, config, result_dir,
                                                     models_dir)))
        run.readers[split.name] = albedo_figures
        return
    from deface.eval.tone_benchmark import measure_photo, read_manifest, with_photo_settings

    photos = read_manifest(folder)
    for photo in photos:
        result_dir = out_dir / "fits" / split.name / photo.stem
        photo_config = with_photo_settings(photo, config)
        run.add(split.name, RecordedTask(f"{split.name} / {photo.stem}", result_dir / "tone.json", photo_config,
                                         partial(measure_photo, folder / "images" / photo.file, photo_config,
                                                 result_dir, models_dir)))
    run.readers[split.name] = partial(tone_figures, photos)


def pair_figures(records: list[dict]) -> dict:
    """Means over a pair split's recorded scores."""
    mean = lambda values: float(np.mean(values))  # noqa: E731
    return {"synthesis_psnr": mean([r["target"]["face"]["psnr"] for r in records]),
            "synthesis_ssim": mean([r["target"]["face"]["ssim"] for r in records]),
            "synthesis_lpips": mean([r["target"]["face"]["lpips"] for r in records]),
            "ita_gap": mean([abs(r["albedo_ita"]["source"] - r["albedo_ita"]["target"]) for r in records]),
            "colour_noise": mean([r["uv"]["colour_noise"] for r in records])}


def albedo_figures(records: list[dict]) -> dict:
    figures = albedo_summary(dict(enumerate(records)))
    face = figures[FACE]
    out = {"psnr": face["psnr"], "colour_error": face["colour_error"],
           "noise_over_truth": face["colour_noise"] / face["colour_noise_truth"]}
    if "beard" in figures:
        out["beard_kept"] = figures["beard"]["darkness_kept"]
    return out


def tone_figures(photos, records: list[dict]) -> dict:
    from deface.eval.tone_benchmark import reference_ita

    errors = [abs(r["albedo_ita"] - reference_ita(p, r)) for p, r in zip(photos, records, strict=True)]
    return {"ita_error": float(np.nanmean(errors))}


def run_board(config: FitConfig, out_dir: Path, names: list[str], jobs: int = 2, models_dir=None,
              log=print, pair_schedule: dict | None = None) -> dict[str, dict]:
    """Fit every split of ``names`` with ``config`` (recorded, so a re-run fits only what changed) -> {split:
    {measure: value}}. The pair splits are fitted with ``pair_schedule``'s settings over ``config`` (default: the
    quick schedule; the truth splits as ``config`` is)."""
    pair_config = override(config, **(SCHEDULES["quick"] if pair_schedule is None else pair_schedule))
    run = BoardRun()
    by_name = {s.name: s for s in SPLITS}
    unknown = [n for n in names if n not in by_name]
    if unknown:
        raise ValueError(f"unknown board split(s) {', '.join(unknown)}; known: {', '.join(by_name)}")
    for name in names:
        split = by_name[name]
        if isinstance(split, PairSplit):
            _pair_split(run, split, pair_config, Path(out_dir), models_dir)
        else:
            _truth_split(run, split, config, Path(out_dir), models_dir)
    records = run_recorded(run.tasks, jobs, models_dir, lambda index, _: log(f"{run.tasks[index].name}: done"))
    return {name: run.readers[name]([r for r, owner in zip(records, run.owners, strict=True) if owner == name])
            for name in names}


def read_accepted(path: Path = ACCEPTED) -> dict:
    return json.loads(path.read_text()) if path.is_file() else {"figures": {}}


def compare(figures: dict[str, dict], accepted: dict[str, dict]) -> list[dict]:
    """One row per split and measure: the value, the accepted one, the change (+ = better) and whether it is a
    loss beyond the measure's tolerance."""
    rows = []
    for split, values in figures.items():
        for measure, value in values.items():
            before = accepted.get(split, {}).get(measure)
            rule = MEASURES[measure]
            change = None if before is None else (value - before) * (1 if rule.higher_is_better else -1)
            rows.append({"split": split, "measure": measure, "value": value, "accepted": before, "change": change,
                         "loss": change is not None and change < -rule.tolerance})
    return rows


def table_markdown(rows: list[dict]) -> str:
    """The board's table: split, measure, value, accepted value, change (+ better), the measure's tolerance (its seed
    noise), flag."""
    lines = ["| split | measure | now | accepted | change (+ better) | tolerance | |", "|---|---|---|---|---|---|---|"]
    for row in rows:
        accepted = "-" if row["accepted"] is None else f"{row['accepted']:.3f}"
        change = "-" if row["change"] is None else f"{row['change']:+.3f}"
        flag = "LOSS" if row["loss"] else ""
        lines.append(f"| {row['split']} | {row['measure']} | {row['value']:.3f} | {accepted} | {change} | "
                     f"{MEASURES[row['measure']].tolerance:g} | {flag} |")
    return "\n".join(lines) + "\n"
