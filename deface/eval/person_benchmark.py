"""The albedo benchmark for several photos of one person: each set of renders of one albedo fitted as one person
(``deface fit --person``), scored against the truth, beside its photos fitted alone.

A set is the renders of one albedo that share the manifest's ``set`` column (without that column, all the renders
of one albedo form the set ``all``). A set's map is scored over the texels any of its photos shows (the true surface
seen by each fitted frame's camera within ``MAX_ANGLE``); each photo fitted alone (the albedo benchmark's fit of
that render, cached) is scored over the same texels, so the set and its photos answer the same question: what
the user gets for those texels. The fitted surface is scored against ``mesh.obj`` (median vertex distance after the
best similarity, cm).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from deface.batch.recorded import RecordedTask, run_recorded
from deface.eval import albedo_measures as measures
from deface.eval.albedo_benchmark import (
    FACE,
    TruthRender,
    read_truth_set,
    region_masks,
    score_fit,
    shown_texels,
    surface_error,
)
from deface.eval.manifest import read_manifest_rows
from deface.fit.config import FitConfig

FEATURES = ("beard", "freckles", "birthmark")
"""The regions whose darkness kept and fine structure the set's targets name."""


@dataclass(frozen=True)
class TruthSet:
    """The renders of one albedo seen as one person."""

    albedo: str  # the true albedo in albedo/
    name: str  # the manifest's set
    renders: tuple[TruthRender, ...]

    @property
    def stem(self) -> str:
        return f"{Path(self.albedo).stem}_{self.name}"


def read_truth_sets(folder: Path) -> list[TruthSet]:
    """The sets of a truth set's renders (module doc), in the manifest's order."""
    renders = {render.file: render for render in read_truth_set(folder)}
    _, rows = read_manifest_rows(folder, ("file",), "a column 'file'; see deface/eval/albedo_benchmark.py")
    groups: dict[tuple[str, str], list[TruthRender]] = {}
    for row in rows:
        render = renders[row["file"]]
        groups.setdefault((render.albedo, row.get("set") or "all"), []).append(render)
    return [TruthSet(albedo, name, tuple(members)) for (albedo, name), members in groups.items()]


def truth_inputs(folder: Path, truth_set: TruthSet) -> tuple[np.ndarray, np.ndarray | None, dict]:
    """The true albedo (linear, score size), the true mesh (None without mesh.obj) and the region masks."""
    from deface.io.images import load_image, srgb_to_linear
    from deface.models.ict_build import read_obj

    truth = measures.at_score_size(srgb_to_linear(load_image(folder / "albedo" / truth_set.albedo)).astype(np.float64))
    mesh_path = folder / "mesh.obj"
    mesh = read_obj(mesh_path, with_faces=False)["positions"] if mesh_path.is_file() else None
    return truth, mesh, region_masks(folder)


def measure_set(folder: Path, truth_set: TruthSet, config: FitConfig, result_dir: Path, models_dir=None) -> dict:
    """Fit a set's renders as one person, write the fit to ``result_dir``, score its map over the texels any photo
    shows (``shown.npy`` keeps them, for scoring the photos fitted alone on the same texels)."""
    from deface.export.outputs import write_fit
    from deface.fit.log import FitLog
    from deface.fit.pipeline import fit_photos
    from deface.io.images import load_image
    from deface.report.html import write_report

    paths = [folder / "images" / render.file for render in truth_set.renders]
    started = time.perf_counter()
    result, crops = fit_photos([load_image(path) for path in paths], [str(path) for path in paths], config,
                               models_dir=models_dir, log=FitLog(quiet=True))
    seconds = time.perf_counter() - started
    write_fit(result, result_dir, {"path": str(paths[0]), "kind": "person", "frames": list(range(len(crops))),
                                   "photos": [crop.record() for crop in crops]}, page=write_report)
    truth, mesh, masks = truth_inputs(folder, truth_set)
    shown = np.zeros(truth.shape[:2], dtype=bool)
    for frame in range(len(result.frames)):
        shown |= shown_texels(result, mesh, frame=frame)
    np.save(result_dir / "shown.npy", shown)
    fitted = measures.at_score_size(result.textures.diffuse.detach().clamp(0, 1).numpy().astype(np.float64))
    surfaces = [surface_error(result, mesh, frame) for frame in range(len(result.frames))] if mesh is not None else []
    return {"scores": score_fit(fitted, truth, shown, masks), "seconds": seconds,
            "photos": [render.file for render in truth_set.renders], "fitted_photos": len(crops),
            "surface_cm": float(np.median(surfaces)) if surfaces else None}


def alone_scores(folder: Path, truth_set: TruthSet, singles_dir: Path, shown: np.ndarray) -> dict:
    """Each photo's fit alone (the albedo benchmark's, in ``singles_dir/<stem>``) scored over the set's texels."""
    from deface.io.images import load_image, srgb_to_linear

    truth, _, masks = truth_inputs(folder, truth_set)
    scores = {}
    for render in truth_set.renders:
        diffuse = singles_dir / render.stem / "textures" / "diffuse.png"
        fitted = measures.at_score_size(srgb_to_linear(load_image(diffuse)).astype(np.float64))
        scores[render.stem] = score_fit(fitted, truth, shown, masks)
    return scores


def run_person_benchmark(folder: Path, out_dir: Path, variants: dict[str, FitConfig], singles: dict[str, dict],
                         jobs: int = 2, models_dir=None, log=print) -> dict:
    """Fit every set with every variant {name: config} (cached in OUT/<variant>/sets/<set>/scores.json), and
    score it beside its photos fitted alone (``singles``: the albedo benchmark's records {variant: {stem: record}},
    whose fits are in OUT/<variant>/<stem>); returns {variant: {set stem: record with "alone"}}."""
    sets = read_truth_sets(folder)
    runs = [(name, truth_set) for name in variants for truth_set in sets]
    tasks = [RecordedTask(f"{name} / {truth_set.stem}", Path(out_dir) / name / "sets" / truth_set.stem / "scores.json",
                          variants[name], partial(measure_set, Path(folder), truth_set, variants[name],
                                                  Path(out_dir) / name / "sets" / truth_set.stem, models_dir))
             for name, truth_set in runs]
    records: dict = {name: {} for name in variants}
    for (name, truth_set), record in zip(runs, run_recorded(tasks, jobs, models_dir), strict=True):
        shown = np.load(Path(out_dir) / name / "sets" / truth_set.stem / "shown.npy")
        record = dict(record, alone=alone_scores(folder, truth_set, Path(out_dir) / name, shown),
                      alone_surface_cm={r.stem: singles[name][r.stem].get("surface_cm") for r in truth_set.renders})
        records[name][truth_set.stem] = record
        log(set_line(f"{name} / {truth_set.stem}", record))
    return records


def set_line(name: str, record: dict) -> str:
    """One console line: the set's figures, then the best and mean of its photos alone."""
    face, alone = record["scores"][FACE], [scores[FACE] for scores in record["alone"].values()]
    features = ", ".join(f"{region} kept {record['scores'][region]['darkness_kept']:.2f} fine "
                         f"{record['scores'][region]['fine_structure']:.2f}"
                         for region in FEATURES if region in record["scores"])
    surface = record.get("surface_cm")
    return (f"{name}: PSNR {face['psnr']:.2f} dB (alone: best {max(a['psnr'] for a in alone):.2f}, mean "
            f"{np.mean([a['psnr'] for a in alone]):.2f}), colour error {face['colour_error']:.2f}; {features}; "
            f"surface {'-' if surface is None else f'{surface:.2f}'} cm ({record['seconds']:.0f} s)")


def sets_markdown(records: dict, title: str, command: str) -> str:
    """A section for BENCHMARKS.md: per variant and set, the set's figures beside its photos alone."""
    header = ["variant", "set", "photos", "PSNR", "alone best / mean", "colour error (alone best)"]
    header += [f"{region} kept (alone mean)" for region in FEATURES] + [f"{r} fine" for r in FEATURES]
    header += ["surface cm (alone)", "s"]
    lines = [f"## Several photos of one person against the truth: {title}", "", f"Regenerate: `{command}`", "",
             "Each set fitted as one person (deface/eval/person_benchmark.py), scored over the texels any of its "
             "photos shows; 'alone': each photo's own fit scored over the same texels. Measures as the albedo "
             "table's.", "", "| " + " | ".join(header) + " |", "|---" * len(header) + "|"]
    for variant, sets in records.items():
        for stem, record in sets.items():
            scores, alone = record["scores"], list(record["alone"].values())
            psnrs = [a[FACE]["psnr"] for a in alone]
            cells = [variant, stem, str(len(record["photos"])), f"{scores[FACE]['psnr']:.2f}",
                     f"{max(psnrs):.2f} / {np.mean(psnrs):.2f}",
                     f"{scores[FACE]['colour_error']:.2f} ({min(a[FACE]['colour_error'] for a in alone):.2f})"]
            for region in FEATURES:
                kept = [a[region]["darkness_kept"] for a in alone if region in a]
                cells.append(f"{scores[region]['darkness_kept']:.2f} ({np.mean(kept):.2f})" if region in scores
                             else "-")
            cells += [f"{scores[region]['fine_structure']:.2f}" if region in scores else "-" for region in FEATURES]
            alone_surface = [v for v in record.get("alone_surface_cm", {}).values() if v is not None]
            surface = record.get("surface_cm")
            cells.append("-" if surface is None else f"{surface:.2f} ({np.median(alone_surface):.2f})"
                         if alone_surface else f"{surface:.2f}")
            cells.append(f"{record['seconds']:.0f}")
            lines.append("| " + " | ".join(cells) + " |")
    lines.append(f"\n_Written {time.strftime('%Y-%m-%d %H:%M')}._")
    return "\n".join(lines) + "\n"
