"""The skin-tone benchmark: does the recovered albedo keep each person's tone?

A folder holds ``images/`` and ``MANIFEST.tsv`` (columns ``file`` and ``tone_group``; ``gt_ita`` when the true
albedo's ITA is known, as in ``../shared/data/skin-tone-synth``; ``settings``, ``PATH=VALUE`` separated by ``;``,
for a photo's own settings, e.g. the box of the card it shows, as ``benchmarks/tone_truth.py`` writes them).
Every photo is fitted with each variant (the chosen preset, and NextFace as the baseline), cached per photo with
its configuration, and scored by
:mod:`deface.models.ita`: the ITA of the diffuse texture against the reference, which is ``gt_ita`` where
given and otherwise the ITA of the photo's lit skin over the same facial regions (a proxy: it includes the
photo's light and exposure).

Figures (FAIR's, Feng et al. 2022): mean absolute ITA error overall and per tone group; the bias score, the
standard deviation of the groups' mean absolute errors; Spearman's rank correlation and the regression slope
of albedo ITA on reference ITA (0: one tone for everybody; 1: the tone scale is kept). Beside the tone, the
texture's speckle and detail per group (deface/eval/uv_measure.py: fine contrast beyond the photo's, and as a
share of the photo's): a fit whose texel noise grows, or whose detail fades, as the skin darkens treats the
groups unequally even when it keeps the tone.

Where the truth is known, the proxy is scored against it too (:data:`PROXY`, :func:`with_proxy`): how far the
photo's lit skin is from the albedo where that can be checked says how much of a photo set's error against the
proxy is the proxy's own.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np
from scipy import stats

from deface.batch.recorded import RecordedTask, run_recorded
from deface.eval.manifest import read_manifest_rows
from deface.eval.sheets import image_grid
from deface.fit import presets
from deface.fit.config import FitConfig, override, set_from_text

GROUP_ORDER = ("dark", "medium", "light")
BASELINE = "nextface"
PROXY = "photo's lit skin"
"""The pseudo-variant whose "albedo" is the photo's lit-skin ITA: scored only where the truth is known."""


@dataclass(frozen=True)
class TonePhoto:
    file: str
    group: str
    gt_ita: float | None  # the true albedo's ITA (synthetic sets), else None
    settings: tuple[str, ...] = ()  # PATH=VALUE applied to this photo's fit (e.g. its card's box)

    @property
    def stem(self) -> str:
        return Path(self.file).stem


def read_manifest(folder: Path) -> list[TonePhoto]:
    """The photos of a skin-tone folder; one-line errors for a missing manifest, column or image."""
    _, rows = read_manifest_rows(folder, ("file", "tone_group"), "columns file, tone_group[, gt_ita]")
    photos = [TonePhoto(r["file"], r["tone_group"], float(r["gt_ita"]) if r.get("gt_ita") else None,
                        tuple(s.strip() for s in (r.get("settings") or "").split(";") if s.strip())) for r in rows]
    absent = [p.file for p in photos if not (folder / "images" / p.file).is_file()]
    if absent:
        raise ValueError(f"{folder / 'images'}: missing {', '.join(absent)}")
    return photos


def variant_config(preset: str, schedule: dict) -> FitConfig:
    return override(presets.get(preset), **schedule)


def photo_config(photo: TonePhoto, preset: str, schedule: dict) -> FitConfig:
    """A variant's configuration for one photo: the photo's own settings (its card) are the method's; NextFace has
    no white level."""
    config = variant_config(preset, schedule)
    return config if preset == BASELINE else with_photo_settings(photo, config)


def with_photo_settings(photo: TonePhoto, config: FitConfig) -> FitConfig:
    """``config`` with the photo's own settings (its card) applied."""
    for assignment in photo.settings:
        config = set_from_text(config, assignment)
    return config


def measure_photo(path: Path, config: FitConfig, result_dir: Path, models_dir=None) -> dict:
    """Fit ``path``, write the fit and a neutral-light render into ``result_dir``, return the tone record."""

    from deface.eval.protocol import fit_detail
    from deface.export.outputs import write_fit
    from deface.fit.log import FitLog
    from deface.fit.pipeline import fit
    from deface.io.images import linear_to_srgb, load_image, save_png
    from deface.models.ita import photo_tone, pixel_uvs, texture_ita
    from deface.render.sh import white_light
    from deface.report.html import write_report

    started = time.perf_counter()
    result = fit([load_image(path)], config, models_dir=models_dir, source=str(path), log=FitLog(quiet=True))
    seconds = time.perf_counter() - started
    write_fit(result, result_dir, {"path": str(path), "kind": "image", "frames": [0]}, page=write_report)
    neutral = result.render(lights=white_light(config.lights.bands))[0].face
    save_png(result_dir / "neutral.png", neutral.clamp(0, 1).numpy())
    frame = result.frames[0]
    fragments = result.renderer.rasterize(frame.geometry.mesh, frame.geometry.camera)
    skin = frame.face_classifier.numpy() > 0.5
    photo = photo_tone(frame.photo_srgb, pixel_uvs(fragments, frame.geometry.mesh), fragments.mask.numpy() > 0, skin)
    to_srgb = lambda t: linear_to_srgb(t.detach().clamp(0, 1).numpy())  # noqa: E731
    tone = result.skin_tone()
    return {"albedo_ita": texture_ita(to_srgb(result.textures.diffuse)),
            "initial_ita": texture_ita(to_srgb(result.texels.initial.diffuse)),
            "photo_ita": photo.ita, "photo_pixels": photo.pixels, "seconds": seconds,
            **fit_detail(result),
            "tone": result.albedo.tone, "illuminant": None if result.illuminant is None else result.illuminant.record(),
            "ita_interval": tone["ita_interval"], "ita_interval_2sigma": tone["ita_interval_2sigma"]}


def run_tone_benchmark(folder: Path, out_dir: Path, preset: str, baseline: bool, schedule: dict,
                       jobs: int = 2, models_dir=None, log=print) -> dict:
    """Fit every photo with ``preset`` (and NextFace when ``baseline``), each recorded in OUT/<variant>/<photo>/
    tone.json with its configuration (not refitted while it holds); returns {variant: {stem: record}}."""
    photos = read_manifest(folder)
    variants = [preset] + ([BASELINE] if baseline and preset != BASELINE else [])
    runs = [(v, p) for v in variants for p in photos]
    tasks = []
    for variant, photo in runs:
        config, result_dir = photo_config(photo, variant, schedule), Path(out_dir) / variant / photo.stem
        tasks.append(RecordedTask(f"{variant} / {photo.stem}", result_dir / "tone.json", config,
                                  partial(measure_photo, Path(folder) / "images" / photo.file, config, result_dir,
                                          models_dir)))

    def logged(index: int, record: dict) -> None:
        photo = runs[index][1]
        log(f"{tasks[index].name}: albedo ITA {record['albedo_ita']:.1f}, reference "
            f"{reference_ita(photo, record):.1f} ({record['seconds']:.0f} s)")

    records: dict = {v: {} for v in variants}
    for (variant, photo), record in zip(runs, run_recorded(tasks, jobs, models_dir, logged), strict=True):
        records[variant][photo.stem] = record
    return records


def reference_ita(photo: TonePhoto, record: dict) -> float:
    """The truth where known, else the photo's lit skin."""
    return photo.gt_ita if photo.gt_ita is not None else record["photo_ita"]


def with_proxy(photos: list[TonePhoto], records: dict) -> dict:
    """``records`` {variant: {stem: record}} plus :data:`PROXY` (the photo's lit-skin ITA taken as the albedo's)
    when every photo's true ITA is known; the first variant's photo ITA is used (the fitted mesh locates it)."""
    if not records or any(p.gt_ita is None for p in photos):
        return records
    first = next(iter(records.values()))
    proxy = {p.stem: {"albedo_ita": first[p.stem]["photo_ita"], "photo_ita": first[p.stem]["photo_ita"]}
             for p in photos}
    return {**records, PROXY: proxy}


def summary(photos: list[TonePhoto], records: dict) -> dict:
    """FAIR-style figures of one variant's records {stem: record}."""
    albedo = np.array([records[p.stem]["albedo_ita"] for p in photos])
    reference = np.array([reference_ita(p, records[p.stem]) for p in photos])
    valid = np.isfinite(reference)
    error = np.abs(albedo - reference)
    groups = [g for g in GROUP_ORDER if any(p.group == g for p in photos)]
    groups += sorted({p.group for p in photos} - set(groups))
    group_mae = {g: float(np.nanmean([e for e, p in zip(error, photos, strict=True) if p.group == g]))
                 for g in groups}
    slope = float(np.polyfit(reference[valid], albedo[valid], 1)[0]) if valid.sum() > 1 else float("nan")
    rho = float(stats.spearmanr(reference[valid], albedo[valid])[0]) if valid.sum() > 2 else float("nan")
    group_speckle = {g: _mean_of(records, photos, g, "speckle") for g in groups}
    group_detail = {g: _mean_of(records, photos, g, "detail") for g in groups}
    return {"mae": float(np.nanmean(error)), "group_mae": group_mae, "group_speckle": group_speckle,
            "group_detail": group_detail, **_interval_figures(photos, records, reference),
            "bias": float(np.std(list(group_mae.values()))), "spearman": rho, "slope": slope,
            "mean_signed": float(np.nanmean(albedo - reference)), "photos": int(valid.sum())}


def summary_line(variant: str, figures: dict) -> str:
    """One line of a variant's :func:`summary` for the console."""
    groups = ", ".join(f"{g} {v:.1f}" for g, v in figures["group_mae"].items())
    speckles = ", ".join(f"{g} {v:.2f}" for g, v in figures["group_speckle"].items())
    details = ", ".join(f"{g} {v:.2f}" for g, v in figures["group_detail"].items())
    texture = "" if variant == PROXY else f"; speckle {speckles}; detail {details}"
    return (f"{variant}: MAE {figures['mae']:.1f}, groups {groups}, bias {figures['bias']:.2f}, "
            f"Spearman {figures['spearman']:.2f}, slope {figures['slope']:.2f}{texture}")


def _interval_figures(photos: list[TonePhoto], records: dict, reference: np.ndarray) -> dict:
    """How often the reference lies within the fits' ITA interval for the white level's one-sigma spread (about
    68 % if the spread is right) and its two-sigma spread (about 95 %), and the one-sigma intervals' mean and median
    width (NaN for a variant without intervals: no white level, or records cached before they existed)."""
    figures = {}
    for key, name in (("ita_interval", "in_interval"), ("ita_interval_2sigma", "in_interval_2sigma")):
        ranges = [records[p.stem].get(key) for p in photos]
        scored = [(r, ref) for r, ref in zip(ranges, reference, strict=True) if r is not None and np.isfinite(ref)]
        figures[name] = float(np.mean([low <= ref <= high for (low, high), ref in scored])) if scored else float("nan")
        if key == "ita_interval":
            widths = [high - low for (low, high), _ in scored]
            figures["interval_width"] = float(np.mean(widths)) if widths else float("nan")
            figures["interval_median_width"] = float(np.median(widths)) if widths else float("nan")
    return figures


def _mean_of(records: dict, photos: list[TonePhoto], group: str, key: str) -> float:
    """Mean of ``key`` over the group's records that have it (records cached before it existed lack it)."""
    values = [records[p.stem][key] for p in photos if p.group == group and key in records[p.stem]]
    return float(np.nanmean(values)) if values else float("nan")


def report_markdown(photos: list[TonePhoto], records: dict, title: str, command: str) -> str:
    """A section for BENCHMARKS.md: the figures per variant, then one row per photo."""
    reference_kind = "true albedo ITA (gt_ita)" if all(p.gt_ita is not None for p in photos) else \
        "ITA of the photo's lit skin (a proxy)"
    lines = [f"## Skin tone: {title}", "", f"Regenerate: `{command}`", "",
             f"{len(photos)} photos; reference = {reference_kind}; ITA in degrees over both cheeks and the forehead"
             " (docs/skin-tone.md). Bias = std of the groups' mean absolute errors; slope = regression slope of"
             " albedo ITA on the reference (1 keeps the tone scale, 0 gives everybody one tone). Speckle: the"
             " texture's fine contrast beyond the photo's, relative to its level, x100, mean per group (0 = none);"
             " detail: its fine contrast as a share of the photo's (1 = all of it; docs/textures.md). In interval: the"
             " share of photos whose reference lies within the fit's ITA interval for its white level's one-sigma"
             " spread (params.json skin_tone.ita_interval; about 68 % if that spread is right), in 2-sigma: within"
             " the two-sigma interval (about 95 %); interval width: the one-sigma intervals' median width in"
             " degrees."]
    records = with_proxy(photos, records)
    if PROXY in records:
        lines[-1] += (f" The row \"{PROXY}\" is the reference photo sets use (a proxy) scored against the truth:"
                      " how far it is from the albedo where that is known.")
    lines.append("")
    groups = list(summary(photos, next(iter(records.values())))["group_mae"])
    lines += ["| variant | MAE | " + " | ".join(f"MAE {g}" for g in groups) + " | bias | Spearman | slope |"
              " mean signed | max error | in interval | in 2-sigma | interval width | "
              + " | ".join(f"speckle {g}" for g in groups) + " | " + " | ".join(f"detail {g}" for g in groups) + " |",
              "|---" * (10 + 3 * len(groups)) + "|"]
    for variant, recs in records.items():
        s = summary(photos, recs)
        worst = max(abs(recs[p.stem]["albedo_ita"] - reference_ita(p, recs[p.stem])) for p in photos
                    if np.isfinite(reference_ita(p, recs[p.stem])))
        cells = [f"{s['mae']:.1f}", *[f"{s['group_mae'][g]:.1f}" for g in groups], f"{s['bias']:.2f}",
                 f"{s['spearman']:.2f}", f"{s['slope']:.2f}", f"{s['mean_signed']:+.1f}", f"{worst:.1f}",
                 _cell(100 * s["in_interval"], "{:.0f} %"), _cell(100 * s["in_interval_2sigma"], "{:.0f} %"),
                 _cell(s["interval_median_width"], "{:.1f}"),
                 *[_cell(s['group_speckle'][g]) for g in groups], *[_cell(s['group_detail'][g]) for g in groups]]
        lines.append(f"| {variant} | " + " | ".join(cells) + " |")
    lines += ["", "| photo | group | reference | " + " | ".join(v if v == PROXY else f"{v} albedo" for v in records)
              + " |",
              "|---|---|---|" + "---|" * len(records)]
    for p in photos:
        reference = reference_ita(p, next(iter(records.values()))[p.stem])
        cells = [f"{records[v][p.stem]['albedo_ita']:.1f}" for v in records]
        lines.append(f"| {p.file} | {p.group} | {reference:.1f} | " + " | ".join(cells) + " |")
    lines.append(f"\n_Written {time.strftime('%Y-%m-%d %H:%M')}._")
    return "\n".join(lines) + "\n"


def _cell(value: float, form: str = "{:.2f}") -> str:
    """A measure for the table; "-" where the variant has none (the proxy has no texture, NextFace no interval)."""
    return "-" if np.isnan(value) else form.format(value)


def contact_sheet(folder: Path, out_dir: Path, photos: list[TonePhoto], variants: list[str], tile: int = 160):
    """OUT/contact_sheet.png: per photo, the photo | albedo texture | albedo under a neutral white light
    (first variant) | the other variants' albedo textures; the ITAs underneath."""
    from PIL import Image

    rows, captions = [], []
    for photo in photos:
        first = out_dir / variants[0] / photo.stem
        with Image.open(first / "neutral.png") as neutral:
            albedo = _face_crop(neutral.convert("RGB"))
        row = [folder / "images" / photo.file, first / "textures" / "diffuse.png", albedo]
        rows.append(row + [out_dir / v / photo.stem / "textures" / "diffuse.png" for v in variants[1:]])
        texts = [f"{photo.file[:22]}", *[_ita_caption(out_dir / v / photo.stem / "tone.json", photo) for v in variants]]
        captions.append("   |   ".join(texts))
    path = out_dir / "contact_sheet.png"
    image_grid(rows, captions, tile).save(path)
    return path


def _face_crop(image):
    """The bounding box of the non-black pixels (the rendered face), squared."""
    box = image.getbbox() or (0, 0, *image.size)
    side = max(box[2] - box[0], box[3] - box[1])
    cx, cy = (box[0] + box[2]) // 2, (box[1] + box[3]) // 2
    return image.crop((cx - side // 2, cy - side // 2, cx + side // 2, cy + side // 2))


def _ita_caption(path: Path, photo: TonePhoto) -> str:
    record = json.loads(path.read_text())
    return f"{path.parent.parent.name} {record['albedo_ita']:.0f} (ref {reference_ita(photo, record):.0f})"
