"""The texture-recovery benchmark: every baseline and ablation of the paper through one harness
(:func:`deface.eval.protocol.evaluate_pair`), run as the batch's recorded tasks (:mod:`deface.batch.recorded`:
the batch's worker pool, each pair's scores recorded with the configuration and not refitted while it holds),
and written as tables shaped like the paper's into BENCHMARKS.md.

Variants are data (:data:`VARIANTS`); rows that coincide with another variant (e.g. "+f +g" is the
default preset itself) point to it instead of being fitted twice.
"""

from __future__ import annotations

import json
import os
import platform
import time
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

from deface.batch.recorded import RecordedTask, run_recorded
from deface.batch.resume import finished_record
from deface.eval.pairs import Pair, read_pairs
from deface.eval.report import PairScores, write_metrics_json
from deface.fit import presets
from deface.fit.config import FitConfig, override


@dataclass(frozen=True)
class Variant:
    name: str  # folder name of its results
    preset: str
    ablation: dict = field(default_factory=dict)  # keyword arguments of presets.with_ablation


VARIANTS = {v.name: v for v in [
    Variant("nextface", "nextface"),
    Variant("ours", "default"),
    Variant("mean-skin", "deface-mean-skin"),
    Variant("nextface-star", "nextface-star"),
    Variant("paper", "paper"),
    # The ablations change one thing of the default preset, so each row differs from "ours" in that only.
    Variant("no-f-no-g", "default", {"light_masks": False}),
    Variant("g-only", "default", {"light_masks": False, "face_region": True}),
    Variant("f-and-g", "default", {"face_region": True}),
    Variant("priors-gp", "default", {"priors": "gp"}),
    Variant("priors-gp-lp", "default", {"priors": "gp,lp"}),
    Variant("n3", "default", {"num_lights": 3}),
    Variant("n5", "default", {"num_lights": 5}),
    Variant("n7", "default", {"num_lights": 7}),
    Variant("n9", "default", {"num_lights": 9}),
    Variant("sh12", "nextface", {"bands": 12}),
    Variant("sh15", "nextface", {"bands": 15}),
    Variant("sh18", "nextface", {"bands": 18}),
]}

# Tables shaped like the paper's: (title, [(row label, variant name)]). A row that is the default preset
# itself names "ours" (tests/test_eval_benchmark.py checks every row's configuration against its label).
TABLES = [
    ("Methods (paper Table 1 / 5)", [("NextFace", "nextface"), ("NextFace*", "nextface-star"),
                                     ("Ours (default preset)", "ours"),
                                     ("Mean skin, free lights (deface-mean-skin, the earlier default)", "mean-skin"),
                                     ("Paper preset", "paper")]),
    ("Neural representations (paper Table 7; without g, M_o = M_R h)",
     [("w/o f, w/o g", "no-f-no-g"), ("+ f (Ours)", "ours"), ("+ g only", "g-only"), ("+ f + g", "f-and-g")]),
    ("Priors (paper Table 8; HP needs FaceNet weights: absent here, so GP+LP is the full set; the default "
     "has none: GP and LP held the beard and moles at the statistical skin, docs/textures.md)",
     [("NA (Ours)", "ours"), ("GP", "priors-gp"), ("GP + LP", "priors-gp-lp")]),
    ("Initial light conditions n (appendix)", [("n = 3 (Ours)", "ours"), ("n = 5", "n5"), ("n = 7", "n7"),
                                               ("n = 9", "n9")]),
    ("One global SH, no decoupling (appendix)", [("B = 9", "nextface"), ("B = 12", "sh12"),
                                                 ("B = 15", "sh15"), ("B = 18", "sh18")]),
]

UV_TABLE = ("UV-space textures (issue 12)", [("NextFace", "nextface"), ("Paper preset", "paper"),
                                             ("Ours (default preset)", "ours")])

# The schedules: "full" is each preset as it is; "quick" is the CPU benchmark schedule used for the
# recorded tables (128-px working images, half-length stages), applied to every variant alike.
SCHEDULES = {
    "full": {},
    "smoke": {"resolution": 64, "texture_size": 64, "render.shadow_rays": 16, "iterations.stage1": 20,
              "iterations.stage2": 8, "iterations.stage3": 3, "decouple.ace_iteration": 4},
    "quick": {"resolution": 128, "texture_size": 256, "render.shadow_rays": 64, "iterations.stage1": 200,
              "iterations.stage2": 200, "iterations.stage3": 100, "decouple.ace_iteration": 50},
}


def variant_config(variant: Variant, schedule: str) -> FitConfig:
    config = presets.with_ablation(presets.get(variant.preset), **variant.ablation)
    return override(config, **SCHEDULES[schedule], preset=f"{config.preset}:{variant.name}")


def pair_tasks(pairs: list[Pair], out_dir: Path, variants: list[str], schedule: str,
               models_dir=None) -> list[RecordedTask]:
    """One task per variant and pair, recorded in OUT/<variant>/<pair>/scores.json with its configuration."""
    tasks = []
    for name in variants:
        config = variant_config(VARIANTS[name], schedule)
        for pair in pairs:
            folder = Path(out_dir) / name / pair.name
            tasks.append(RecordedTask(f"{name} / {pair.name}", folder / "scores.json", config,
                                      partial(pair_scores, pair, config, folder, models_dir)))
    return tasks


def pair_scores(pair: Pair, config: FitConfig, folder: Path, models_dir) -> dict:
    """One variant on one pair: the scores.json fields (its images are written into ``folder``)."""
    from deface.eval.protocol import evaluate_pair

    outcome = evaluate_pair(pair, config, folder, models_dir)
    return {"source": outcome.scores.source, "target": outcome.scores.target,
            "seconds_per_fit": outcome.seconds_per_fit, "albedo_ita": outcome.albedo_ita, "uv": outcome.uv}


def run_benchmark(pairs_dir: Path, out_dir: Path, variants: list[str], schedule: str = "quick",
                  jobs: int = 2, limit: int | None = None, models_dir=None, log=print) -> None:
    """Evaluate ``variants`` (in this priority order) on the first ``limit`` pairs (all by default),
    ``jobs`` fits at a time; pairs already fitted with a variant's configuration are not fitted again."""
    unknown = [v for v in variants if v not in VARIANTS]
    if unknown:
        raise ValueError(f"unknown variant(s) {unknown}; known: {', '.join(VARIANTS)}")
    pairs = read_pairs(pairs_dir)[:limit]
    tasks = pair_tasks(pairs, out_dir, variants, schedule, models_dir)
    run_recorded(tasks, jobs, models_dir,
                 lambda index, scores: log(f"{tasks[index].name}: {scores['seconds_per_fit']:.0f} s per fit"))
    for name in variants:
        _write_variant_metrics(out_dir, name, pairs)


def _write_variant_metrics(out_dir: Path, name: str, pairs: list[Pair]) -> None:
    scores, seconds, ita_gaps, uv = [], [], [], []
    for pair in pairs:
        data = json.loads((out_dir / name / pair.name / "scores.json").read_text())
        scores.append(PairScores(pair.name, data["source"], data["target"]))
        seconds.append(data["seconds_per_fit"])
        if "albedo_ita" in data:
            ita_gaps.append(abs(data["albedo_ita"]["source"] - data["albedo_ita"]["target"]))
        if data.get("uv", {}).get("consistency"):
            uv.append(data["uv"])
    write_metrics_json(out_dir / name / "metrics.json", name, scores)
    gap = sum(ita_gaps) / len(ita_gaps) if len(ita_gaps) == len(pairs) else None
    (out_dir / name / "timing.json").write_text(json.dumps({"seconds_per_fit": seconds, "albedo_ita_gap": gap,
                                                            "uv": _mean_uv(uv) if len(uv) == len(pairs) else None}))


def _mean_uv(uv: list[dict]) -> dict:
    """Means over pairs of the UV consistency scores and the speckle (deface/eval/uv_measure.py)."""
    mean = {key: sum(item["consistency"][key] for item in uv) / len(uv) for key in ("psnr", "ssim", "lpips")}
    for key in ("speckle", "detail"):
        values = [item[key] for item in uv if key in item]
        mean[key] = sum(values) / len(values) if len(values) == len(uv) else None
    fringes = [item["edge_fringe"]["fringe"] for item in uv if "edge_fringe" in item]
    fringes = [value for value in fringes if value == value]  # NaN: too few edge texels seen
    mean["edge_fringe"] = sum(fringes) / len(fringes) if fringes else None
    return mean


def _fitted_now(out_dir: Path, name: str, schedule: str, pairs: list[Pair]) -> bool:
    """Whether every pair's cached scores were fitted with the variant's current configuration."""
    config = variant_config(VARIANTS[name], schedule)
    return all(finished_record(out_dir / name / pair.name / "scores.json", config) is not None for pair in pairs)


def _row(out_dir: Path, label: str, name: str, schedule: str, pairs: list[Pair]) -> str:
    path = out_dir / name / "metrics.json"
    if not path.exists():
        return f"| {label} | not run | | | | | | | | |"
    if not _fitted_now(out_dir, name, schedule, pairs):
        return f"| {label} | not run with the current configuration | | | | | | | | |"
    mean = json.loads(path.read_text())["mean"]
    target, source = mean["target"], mean["source"]
    timing = json.loads((out_dir / name / "timing.json").read_text())
    seconds, gap = timing["seconds_per_fit"], timing.get("albedo_ita_gap")
    cells = [target["face"]["psnr"], target["face"]["ssim"], target["face"]["lpips"], target["full"]["psnr"],
             target["full"]["ssim"], target["full"]["lpips"], source["face"]["psnr"]]
    text = [f"{c:.2f}" if i not in (1, 4) else f"{c:.3f}" for i, c in enumerate(cells)]
    identity = target.get("identity")  # absent without dlib, or when a cached pair predates the column
    text.append(f"{identity['distance']:.3f}" if identity else "-")
    text.append(f"{gap:.1f}" if gap is not None else "-")
    return f"| {label} | " + " | ".join(text) + f" | {sum(seconds) / len(seconds):.0f} |"


def _uv_row(out_dir: Path, label: str, name: str, schedule: str, pairs: list[Pair]) -> str:
    timing_path = out_dir / name / "timing.json"
    if not timing_path.exists() or not _fitted_now(out_dir, name, schedule, pairs):
        return f"| {label} | not run with the current configuration | | | | | | |"
    uv = json.loads(timing_path.read_text()).get("uv")
    if uv is None:
        return f"| {label} | not measured (cached pairs predate the UV measure) | | | | | | |"
    synthesis = json.loads((out_dir / name / "metrics.json").read_text())["mean"]["target"]["face"]["psnr"]
    detail = f"{uv['detail']:.2f}" if uv.get("detail") is not None else "-"
    fringe = f"{uv['edge_fringe']:.2f}" if uv.get("edge_fringe") is not None else "-"
    return (f"| {label} | {uv['psnr']:.2f} | {uv['ssim']:.3f} | {uv['lpips']:.2f} | {uv['speckle']:.2f}"
            f" | {detail} | {fringe} | {synthesis:.2f} |")


def report_markdown(out_dir: Path, pairs_dir: Path, schedule: str, command: str, limit: int | None = None) -> str:
    """The BENCHMARKS.md section: data, machine, schedule, then one table per paper table."""
    pairs = read_pairs(pairs_dir)[:limit]
    lines = [
        "## Texture recovery: target synthesis on synthetic-shadow pairs",
        "",
        f"Regenerate: `{command}`",
        "",
        f"Data: {len(pairs)} pairs ({', '.join(p.name for p in pairs)}) from `deface bench make-shadows`"
        " (clean photos of ../shared/data/images, list in docs/evaluation.md): source = photo with a"
        " synthetic cast shadow, target = the clean photo.",
        f"Schedule `{schedule}`: {SCHEDULES[schedule] or 'each preset as defined'}. Machine: "
        f"{platform.machine()}, {os.cpu_count()} cores, no GPU; one fit per core, 1 torch thread each.",
        "Columns: target synthesis (target geometry, pose and lights with the source's textures) scored over"
        " the face region h and over the full composite; source reconstruction PSNR over the face region;"
        " LPIPS x100; ID dist = dlib face-descriptor distance of the target synthesis (full composite) to the"
        " target photo, lower is better, < 0.6 = same person (docs/evaluation.md; '-' where dlib was not"
        " installed or some pair's cached scores predate it); ITA gap = mean |ITA(source albedo) - ITA(target"
        " albedo)|, degrees: the same person's skin tone from the shadowed and the clean photo (docs/skin-tone.md);"
        " seconds = mean wall time per fit.",
        "",
    ]
    header = ("| | PSNR face | SSIM face | LPIPS face | PSNR full | SSIM full | LPIPS full | src PSNR face | ID dist"
              " | ITA gap | s/fit |\n|---|---|---|---|---|---|---|---|---|---|---|")
    for title, rows in TABLES:
        table = [_row(out_dir, label, name, schedule, pairs) for label, name in rows]
        lines += [f"### {title}", "", header, *table, ""]
    lines += [
        f"### {UV_TABLE[0]}", "",
        "UV PSNR / SSIM / LPIPS x100: the source fit's diffuse map against the target fit's (same person and pose,"
        " shadowed vs clean photo), over the texels both fits saw within 60 degrees inside h; speckle: the maps'"
        " high-frequency contrast beyond the photo's at that scale, % (0 = none); detail: the maps' fine contrast"
        " as a share of the photo's (1 = all of it; docs/textures.md); edge fringe: the chroma the shadow's edge"
        " left in the source's map beyond the two maps' chroma difference elsewhere, x100 (deface/eval/uv_measure.py;"
        " 0 = none); synthesis = target synthesis PSNR face, as above.", "",
        "| | UV PSNR | UV SSIM | UV LPIPS | speckle | detail | edge fringe | synthesis PSNR face |\n"
        "|---|---|---|---|---|---|---|---|",
        *[_uv_row(out_dir, label, name, schedule, pairs) for label, name in UV_TABLE[1]], ""]
    lines.append(f"_Written {time.strftime('%Y-%m-%d %H:%M')}._")
    return "\n".join(lines) + "\n"


def update_benchmarks_md(path: Path, section: str, key: str = "eval") -> None:
    """Replace the section ``key`` of BENCHMARKS.md (between its markers), or append it."""
    start, end = f"<!-- {key}:start -->", f"<!-- {key}:end -->"
    text = path.read_text() if path.exists() else "# Benchmarks\n"
    block = f"{start}\n{section}{end}\n"
    if start in text and end in text:
        text = text[: text.index(start)] + block + text[text.index(end) + len(end) + 1:]
    else:
        text = text.rstrip("\n") + "\n\n" + block
    path.write_text(text)
