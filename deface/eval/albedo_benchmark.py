"""The albedo benchmark: fits of renders whose albedo is known, scored against it in UV space.

A truth set is a folder with ``images/`` (the renders), ``albedo/`` (the true diffuse albedo maps, sRGB, in the
face model's UV layout), ``MANIFEST.tsv`` and optionally ``masks/`` (regions to score, white = in; ``forehead`` is
plain skin, the reference of the map's level) and ``mesh.obj`` (the rendered geometry, the model's topology).
Manifest columns: ``file``; the albedo is ``albedo`` if given, else ``tone`` + ``.png``, else the part of the file
name before its first ``_``; the light is named by ``light``, else by ``kelvin`` and ``shadow``.
``../shared/data/detail-synth`` and ``../shared/data/skin-tone-synth`` are two such sets.

Each render is fitted (cached per render with its configuration) and scored (:mod:`deface.eval.albedo_measures`)
over the texels the render shows: the true mesh (aligned to the fitted one) seen from the fitted camera, facing it
within ``MAX_ANGLE`` (without ``mesh.obj``: the texels the fit saw). A region of a mask is scored on its shown
texels; without masks the whole shown face is the region and its own reference.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from deface.batch.recorded import RecordedTask, run_recorded
from deface.eval import albedo_measures as measures
from deface.eval.manifest import read_manifest_rows
from deface.fit.config import FitConfig

MAX_ANGLE = 70.0
"""Texels facing the camera further than this (degrees) are not scored: the photo hardly shows them."""
REFERENCE = "forehead"
"""The mask of plain skin whose level the fitted map is matched to."""
FACE = "face"
"""The region name of the whole shown face (PSNR, SSIM, colour noise)."""


@dataclass(frozen=True)
class TruthRender:
    file: str  # the render in images/
    albedo: str  # its true albedo in albedo/
    light: str  # what lit it (a table column)

    @property
    def stem(self) -> str:
        return Path(self.file).stem


def read_truth_set(folder: Path) -> list[TruthRender]:
    """The renders of a truth set; one-line errors for a missing manifest, image or albedo."""
    manifest, rows = read_manifest_rows(folder, ("file",), "a column 'file'; see deface/eval/albedo_benchmark.py")
    renders = [TruthRender(row["file"], _albedo_name(row), _light_name(row)) for row in rows]
    for render in renders:
        for path in (folder / "images" / render.file, folder / "albedo" / render.albedo):
            if not path.is_file():
                raise ValueError(f"{path}: not found (listed in {manifest})")
    return renders


def _albedo_name(row: dict) -> str:
    if row.get("albedo"):
        return row["albedo"]
    if row.get("tone"):
        return f"{row['tone']}.png"
    return f"{Path(row['file']).stem.split('_')[0]}.png"


def _light_name(row: dict) -> str:
    if row.get("light"):
        return row["light"]
    shadow = " shadow" if row.get("shadow", "0") not in ("", "0") else ""
    return f"{row['kelvin']} K{shadow}" if row.get("kelvin") else Path(row["file"]).stem


def region_masks(folder: Path) -> dict[str, np.ndarray]:
    """The set's masks at the score size, name -> [S, S] bool (empty without ``masks/``)."""
    from deface.io.images import load_image

    return {path.stem: measures.at_score_size(load_image(path)[..., 0] > 0.5)
            for path in sorted((folder / "masks").glob("*.png"))}


def score_fit(fitted: np.ndarray, truth: np.ndarray, shown: np.ndarray, masks: dict[str, np.ndarray],
              photo: np.ndarray | None = None) -> dict:
    """Every measure of a fitted map against the truth (both linear [S, S, 3] at the score size) over the shown
    texels ``shown`` [S, S]: {region: {...}} with the whole face under :data:`FACE`. With ``photo`` (the working
    photo read in UV, :func:`photo_in_uv`, NaN where unseen) each region also gets the photo's own darkness kept,
    shading and all: where the photo keeps a region's darkness and the map does not, the fit's lights took it."""
    reference = masks[REFERENCE] & shown if REFERENCE in masks else shown
    matched = measures.gain_matched(fitted, truth, reference)
    psnr, ssim = measures.psnr_ssim(matched, truth, shown)
    scores = {FACE: {"psnr": psnr, "ssim": ssim, "colour_noise": measures.colour_noise(matched, shown),
                     "colour_noise_truth": measures.colour_noise(truth, shown),
                     "colour_error": measures.colour_error(matched, truth, shown), "texels": int(shown.sum())}}
    if photo is not None:
        seen = np.isfinite(photo).all(-1)
        photo_matched = measures.gain_matched(np.nan_to_num(photo), truth, reference & seen)
    for name, mask in masks.items():
        region = mask & shown
        if name == REFERENCE or region.sum() < 4:
            continue
        scores[name] = {"darkness_kept": measures.darkness_kept(matched, truth, region, reference),
                        "fine_structure": measures.fine_structure(matched, truth, region),
                        "texels": int(region.sum())}
        if photo is not None:
            scores[name]["photo_darkness"] = measures.darkness_kept(photo_matched, truth, region & seen,
                                                                     reference & seen)
    return scores


def photo_in_uv(result, size: int = measures.SCORE_SIZE) -> np.ndarray:
    """The fit's first working photo (linear) read at each texel of a ``size``² map through the fitted mesh and
    camera [S, S, 3], NaN where that frame does not see the texel."""
    from deface.io.images import srgb_to_linear
    from deface.models.uvmap import rasterize_uv
    from deface.texture.confidence import texel_view, unwrap

    frame = result.frames[0]
    raster = rasterize_uv(result.model.uvs, result.model.triangle_uvs, size)
    view = texel_view(raster, frame.geometry.mesh, frame.geometry.camera)
    photo = unwrap(srgb_to_linear(frame.photo_srgb).astype(np.float64), view)
    return np.where(view.visible[..., None], photo, np.nan)


def shown_texels(result, truth_mesh: np.ndarray | None, size: int = measures.SCORE_SIZE, frame: int = 0) -> np.ndarray:
    """[S, S] bool: texels of the true surface (or, without it, of the fitted one) that the fit's ``frame`` shows
    within :data:`MAX_ANGLE`."""
    import torch

    from deface.models.uvmap import rasterize_uv
    from deface.render.mesh import Mesh
    from deface.texture.confidence import texel_view

    frame = result.frames[frame]
    fitted = frame.geometry.mesh
    vertices = fitted.vertices
    if truth_mesh is not None:
        vertices = torch.as_tensor(similarity_aligned(truth_mesh, fitted.vertices.detach().numpy()),
                                   dtype=torch.float32)
    mesh = Mesh(vertices, fitted.triangles, fitted.uvs, fitted.triangle_uvs)
    raster = rasterize_uv(result.model.uvs, result.model.triangle_uvs, size)
    view = texel_view(raster, mesh, frame.geometry.camera)
    return view.visible & (view.facing >= np.cos(np.radians(MAX_ANGLE)))


def surface_error(result, truth_mesh: np.ndarray, frame: int = 0) -> float:
    """Median distance (cm) of the fitted ``frame``'s vertices from the true mesh's [V, 3] (the same topology) after
    the similarity that best aligns them: the shape's error, whatever the pose and scale."""
    fitted = result.frames[frame].geometry.mesh.vertices.detach().numpy().astype(np.float64)
    return float(np.median(np.linalg.norm(similarity_aligned(fitted, truth_mesh) - truth_mesh, axis=1)))


def similarity_aligned(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """``source`` [V, 3] moved by the similarity (rotation, scale, translation) that best fits ``target`` [V, 3]
    in least squares (Umeyama 1991)."""
    source_mean, target_mean = source.mean(0), target.mean(0)
    a, b = source - source_mean, target - target_mean
    u, s, vt = np.linalg.svd(a.T @ b)
    flip = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    rotation = u @ flip @ vt
    scale = (s * np.diag(flip)).sum() / (a ** 2).sum()
    return scale * a @ rotation + target_mean


def measure_render(folder: Path, render: TruthRender, config: FitConfig, result_dir: Path, models_dir=None) -> dict:
    """Fit a render, write the fit (and its albedo under a neutral light) to ``result_dir``, score its map."""
    from deface.export.outputs import write_fit
    from deface.fit.log import FitLog
    from deface.fit.pipeline import fit
    from deface.io.images import load_image, save_png, srgb_to_linear
    from deface.models.ict_build import read_obj
    from deface.render.sh import white_light
    from deface.report.html import write_report

    started = time.perf_counter()
    path = folder / "images" / render.file
    result = fit([load_image(path)], config, models_dir=models_dir, source=str(path), log=FitLog(quiet=True))
    seconds = time.perf_counter() - started
    write_fit(result, result_dir, {"path": str(path), "kind": "image", "frames": [0]}, page=write_report)
    neutral = result.render(lights=white_light(config.lights.bands))[0].face
    save_png(result_dir / "neutral.png", neutral.clamp(0, 1).numpy())
    mesh_path = folder / "mesh.obj"
    truth_mesh = read_obj(mesh_path, with_faces=False)["positions"] if mesh_path.is_file() else None
    shown = shown_texels(result, truth_mesh)
    truth = measures.at_score_size(srgb_to_linear(load_image(folder / "albedo" / render.albedo)).astype(np.float64))
    fitted = measures.at_score_size(result.textures.diffuse.detach().clamp(0, 1).numpy().astype(np.float64))
    masks = region_masks(folder)
    reference = masks[REFERENCE] & shown if REFERENCE in masks else shown
    matched = measures.gain_matched(fitted, truth, reference)
    save_png(result_dir / "albedo_difference.png", measures.difference_image(matched, truth, shown), srgb=False)
    return {"scores": score_fit(fitted, truth, shown, masks, photo_in_uv(result)), "seconds": seconds,
            "light": render.light, "kept_lights": len(result.lights.kept),
            "surface_cm": None if truth_mesh is None else surface_error(result, truth_mesh)}


def run_albedo_benchmark(folder: Path, out_dir: Path, variants: dict[str, FitConfig], jobs: int = 2,
                         models_dir=None, log=print) -> dict:
    """Fit every render with every variant {name: config}, each recorded in OUT/<variant>/<render>/scores.json with
    its configuration (not refitted while it holds); returns {variant: {stem: record}}."""
    renders = read_truth_set(folder)
    runs = [(name, render) for name in variants for render in renders]
    tasks = []
    for name, render in runs:
        config, result_dir = variants[name], Path(out_dir) / name / render.stem
        tasks.append(RecordedTask(f"{name} / {render.stem}", result_dir / "scores.json", config,
                                  partial(measure_render, Path(folder), render, config, result_dir, models_dir)))

    def logged(index: int, record: dict) -> None:
        face = record["scores"][FACE]
        log(f"{tasks[index].name}: PSNR {face['psnr']:.2f} dB, SSIM {face['ssim']:.3f}"
            + "".join(f", {region} kept {s['darkness_kept']:.2f} fine {s['fine_structure']:.2f}"
                      for region, s in record["scores"].items() if region != FACE)
            + f" ({record['seconds']:.0f} s)")

    records: dict = {name: {} for name in variants}
    for (name, render), record in zip(runs, run_recorded(tasks, jobs, models_dir, logged), strict=True):
        records[name][render.stem] = record
    return records


def summary(records: dict) -> dict:
    """Means over renders of one variant's records {stem: record}: {region: {measure: mean}}."""
    table: dict = {}
    for record in records.values():
        for region, values in record["scores"].items():
            for measure, value in values.items():
                table.setdefault(region, {}).setdefault(measure, []).append(value)
    return {region: {m: _mean(v) for m, v in values.items()} for region, values in table.items()}


def summary_line(variant: str, figures: dict) -> str:
    """One line of a variant's :func:`summary` for the console."""
    face = figures[FACE]
    regions = ", ".join(f"{r} kept {v['darkness_kept']:.2f} (photo {v.get('photo_darkness', float('nan')):.2f})"
                        f" fine {v['fine_structure']:.2f}"
                        for r, v in figures.items() if r != FACE)
    return (f"{variant}: PSNR {face['psnr']:.2f} dB, SSIM {face['ssim']:.3f}, colour noise "
            f"{face['colour_noise']:.2f} ({face['colour_noise_truth']:.2f}), colour error "
            f"{_cell(face.get('colour_error'))}; {regions}")


def _mean(values: list[float]) -> float:
    finite = [v for v in values if np.isfinite(v)]
    return float(np.mean(finite)) if finite else float("nan")


def report_markdown(renders: list[TruthRender], records: dict, title: str, command: str) -> str:
    """A section for BENCHMARKS.md: one row per variant and render, the variant's mean last."""
    regions = sorted({r for recs in records.values() for rec in recs.values() for r in rec["scores"]} - {FACE})
    header = ["variant", "render", "light", "PSNR", "SSIM", "colour noise (truth)", "colour error"]
    header += [f"{r} {m}" for r in regions for m in ("kept", "photo", "fine")]
    lines = [f"## Albedo against the truth: {title}", "", f"Regenerate: `{command}`", "",
             "The fitted diffuse map against the true albedo in UV at 256², over the texels the render shows (the"
             f" true surface within {MAX_ANGLE:.0f} degrees of facing the fitted camera), after one gain per channel"
             f" matched on the {REFERENCE} (deface/eval/albedo_measures.py). PSNR/SSIM of the sRGB maps; colour noise:"
             " RMS chroma of the map's fine structure x100 (the truth's in brackets); colour error: RMS CIELAB a*b*"
             " difference from the truth over the face at the truth's luminance (tints and fringes at any scale; 0 ="
             " the truth's colours; about 2.3 is just noticeable);"
             " kept: darkness kept,"
             " (1 - K_fit) / (1 - K_truth), K = the region's luminance over the reference's (1 = as dark as the"
             " truth, 0 = bleached to skin); photo: the same of the working photo read into UV through the fitted mesh,"
             " shading and all (about 1 or more where the photo shows the region dark; a map's kept well below its"
             " photo's means the fit's lights took the darkness); fine: correlation of the fine luminance (minus a"
             " Gaussian of 2 texels) with the truth's.", "",
             "| " + " | ".join(header) + " |", "|---" * len(header) + "|"]
    for variant, recs in records.items():
        rows = [(render.stem, render.light, recs[render.stem]["scores"]) for render in renders]
        rows.append(("mean", "", summary(recs)))
        for stem, light, scores in rows:
            face = scores[FACE]
            cells = [variant, stem, light, f"{face['psnr']:.2f}", f"{face['ssim']:.3f}",
                     f"{face['colour_noise']:.2f} ({face['colour_noise_truth']:.2f})", _cell(face.get("colour_error"))]
            for region in regions:
                values = scores.get(region, {})
                cells += [_cell(values.get(m)) for m in ("darkness_kept", "photo_darkness", "fine_structure")]
            lines.append("| " + " | ".join(cells) + " |")
    lines.append(f"\n_Written {time.strftime('%Y-%m-%d %H:%M')}._")
    return "\n".join(lines) + "\n"


def _cell(value) -> str:
    return "-" if value is None or not np.isfinite(value) else f"{value:.2f}"


def contact_sheet(folder: Path, out_dir: Path, renders: list[TruthRender], variants: list[str], tile: int = 192):
    """OUT/contact_sheet.png: per variant and render, render | true albedo | fitted albedo | the fit under a
    neutral light | |fitted - truth| x4 (grey: not shown)."""
    from deface.eval.sheets import image_grid

    rows, captions = [], []
    for variant in variants:
        for render in renders:
            fit = out_dir / variant / render.stem
            rows.append([folder / "images" / render.file, folder / "albedo" / render.albedo,
                         fit / "textures" / "diffuse.png", fit / "neutral.png", fit / "albedo_difference.png"])
            captions.append(f"{variant} / {render.stem}: render | truth | fitted | neutral light | difference x4")
    path = out_dir / "contact_sheet.png"
    image_grid(rows, captions, tile).save(path)
    return path
