"""The skin-tone truth set that spans what cameras do (docs/skin-tone.md "Measuring it"): renders of known albedo
under eight scenes (walls dark to pale, key lights near and far, coloured environments), each exposed as a camera
on manual exposure and as cameras that meter (average and centre-weighted), some with a grey card or a
ColorChecker held beside the face. Scenes alternate between a ``tune`` part (choose settings on it) and a
``report`` part (report on it). The renders live outside the repository; this makes them again:

    .venv/bin/python benchmarks/tone_truth.py chart OUT          # OUT/checker.png, the ColorChecker's texture
    blender -b -P benchmarks/blender/tone_scenes.py -- OUT --variants plain,white
    blender -b -P benchmarks/blender/tone_scenes.py -- OUT --variants card \
        --only studio,highkey,outdoor,bluegrey,tungsten
    blender -b -P benchmarks/blender/tone_scenes.py -- OUT --only studio,bluegrey --variants checker
    .venv/bin/python benchmarks/tone_truth.py make OUT          # OUT/images/*.png, OUT/MANIFEST.tsv, OUT/sets/*
    DEFACE_MODELS=../shared/models .venv/bin/python benchmarks/tone_truth.py starts OUT [--split tune] [--variant card]

(Blender 3.4, Debian's ``blender`` package; 78 renders at 512 x 512, 32 samples: about 10 s each on a free core.)
``make`` exposes each scene-linear render three ways: ``manual`` (exposure 1: the scene's light strength decides
how bright the photo is), ``average`` (the frame's mean luminance at 18 %, as an averaging meter sets it) and
``centre`` (the same with the central circle, a fifth of the frame's width in radius, given 75 % of the weight),
and writes ``OUT/sets/<split>-<variant>[-manual]/`` for ``deface bench skin-tone`` (MANIFEST.tsv with ``gt_ita``,
and a ``settings`` column giving a card's box; ``-manual``: the manual exposures alone, a third of the fits).
``true_white``: the luminance a white surface facing the key light shows in that exposure, read from the scene's
``white`` render (80 % albedo, no specular: the 90th percentile over the face's centre, over 0.8); the level the fit
should hold its key light to. ``starts`` prints the tone each render's fit starts from (no fit: seconds per image;
stage 2 keeps the start in the default preset) against the truth, per
scene and exposure, and the estimated white level against ``true_white``.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import statistics
from concurrent.futures import ProcessPoolExecutor
from itertools import product
from pathlib import Path

import numpy as np

os.environ.setdefault("OPENCV_IO_ENABLE_OPENEXR", "1")
import cv2  # noqa: E402  (reads OpenEXR only with the variable set first)

GT_ITA = {"ita50": 50.45, "ita30": 29.79, "ita10": 9.95, "ita-10": -9.82, "ita-30": -30.07}
"""The albedos' ITA (../shared/data/skin-tone-synth/MANIFEST.tsv, measured on albedo/<tone>.png)."""
GROUP = {"ita50": "light", "ita30": "medium", "ita10": "dark", "ita-10": "dark", "ita-30": "dark"}
EXPOSURES = ("manual", "average", "centre")
METER_GREY = 0.18
CENTRE_SHARE = 0.75
"""A centre-weighted meter gives the central circle (a fifth of the frame's width in radius) this share of its weight
(Nikon's and Canon's centre-weighted modes: 70-80 %)."""
FACE_CENTRE = (0.35, 0.25, 0.65, 0.6)  # left, top, right, bottom: the face's cheeks and forehead in every scene
WHITE_ALBEDO = 0.8
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def chart(out: Path) -> None:
    """OUT/checker.png: the ColorChecker Classic's 24 patches (colour-science's reference values, adapted to D65,
    linear sRGB reflectances) on a black frame, as the Blender scene's texture."""
    import colour

    reference = colour.CCS_COLOURCHECKERS["ColorChecker24 - After November 2014"]
    xyz = colour.xyY_to_XYZ(np.array(list(reference.data.values())))
    rgb = np.clip(colour.XYZ_to_RGB(xyz, colour.RGB_COLOURSPACES["sRGB"], reference.illuminant,
                                    chromatic_adaptation_transform="Bradford"), 0, 1)
    swatch, gap = 150, 24
    image = np.full((4 * swatch + 5 * gap, 6 * swatch + 7 * gap, 3), 0.01)
    for index, colour_value in enumerate(rgb):
        row, column = divmod(index, 6)
        y, x = gap + row * (swatch + gap), gap + column * (swatch + gap)
        image[y:y + swatch, x:x + swatch] = colour_value
    out.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out / "checker.png"), (_srgb(image)[..., ::-1] * 255 + 0.5).astype(np.uint8))


def _srgb(linear: np.ndarray) -> np.ndarray:
    linear = np.clip(linear, 0, 1)
    return np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)


def _read_exr(path: Path) -> np.ndarray:
    return cv2.imread(str(path), cv2.IMREAD_UNCHANGED)[..., :3][..., ::-1].astype(np.float64)


def exposure(linear: np.ndarray, mode: str) -> float:
    """The factor a camera in ``mode`` applies to the scene-linear image."""
    if mode == "manual":
        return 1.0
    luminance = linear @ LUMINANCE
    if mode == "average":
        return METER_GREY / float(luminance.mean())
    height, width = luminance.shape
    yy, xx = np.mgrid[:height, :width]
    centre = (xx - width / 2) ** 2 + (yy - height / 2) ** 2 <= (width / 5) ** 2
    weights = np.where(centre, CENTRE_SHARE / centre.mean(), (1 - CENTRE_SHARE) / (1 - centre.mean()))
    return METER_GREY / float((luminance * weights).sum() / weights.sum())


def _face_white(white_render: np.ndarray) -> float:
    height, width = white_render.shape[:2]
    left, top, right, bottom = FACE_CENTRE
    centre = white_render[int(top * height):int(bottom * height), int(left * width):int(right * width)]
    return float(np.percentile(centre @ LUMINANCE, 90)) / WHITE_ALBEDO


def make(out: Path) -> None:
    """PNG per render and exposure, OUT/MANIFEST.tsv and OUT/sets/<split>-<variant>/ (bench folders)."""
    (out / "images").mkdir(exist_ok=True)
    rows = []
    for meta_path in sorted((out / "exr").glob("*.json")):
        meta = json.loads(meta_path.read_text())
        if meta["variant"] == "white":
            continue
        linear = _read_exr(meta_path.with_suffix(".exr"))
        white = _face_white(_read_exr(out / "exr" / f"{meta['scene']}_white_white.exr"))
        for mode in EXPOSURES:
            factor = exposure(linear, mode)
            name = f"{meta['scene']}_{meta['tone']}_{meta['variant']}_{mode}.png"
            encoded = (_srgb(linear * factor)[..., ::-1] * 255 + 0.5).astype(np.uint8)
            cv2.imwrite(str(out / "images" / name), encoded)
            box = meta["box"]
            rows.append({"file": name, "tone_group": GROUP[meta["tone"]], "gt_ita": GT_ITA[meta["tone"]],
                         "scene": meta["scene"], "split": meta["split"], "variant": meta["variant"], "exposure": mode,
                         "kelvin": meta["settings"]["kelvin"], "true_white": round(white * factor, 4),
                         "box": ",".join(f"{v:.4f}" for v in box) if box else "",
                         "settings": f"tone.illuminant.reference_box={','.join(f'{v:.4f}' for v in box)}"
                         if meta["variant"] == "card" else ""})
    _write_tsv(out / "MANIFEST.tsv", rows)
    for split in ("tune", "report"):
        for variant, exposure_mode in product(("plain", "card", "checker"), (None, "manual")):
            chosen = [r for r in rows if r["split"] == split and r["variant"] == variant
                      and exposure_mode in (None, r["exposure"])]
            if not chosen:
                continue
            folder = out / "sets" / f"{split}-{variant}" if exposure_mode is None else \
                out / "sets" / f"{split}-{variant}-{exposure_mode}"
            (folder / "images").mkdir(parents=True, exist_ok=True)
            for row in chosen:
                link = folder / "images" / row["file"]
                if not link.exists():
                    link.symlink_to(out / "images" / row["file"])
            _write_tsv(folder / "MANIFEST.tsv", chosen)
    sets = ", ".join(sorted(p.name for p in (out / "sets").iterdir()))
    print(f"{len(rows)} images in {out / 'images'}; sets: {sets}")


def _write_tsv(path: Path, rows: list[dict]) -> None:
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]), delimiter="\t")
        writer.writeheader()
        writer.writerows(rows)


def start_of(path: str, settings: tuple[str, ...], resolution: int) -> tuple[float, dict, dict]:
    """The tone a fit starts from, its illuminant record and the start's T^0 tone with its one- and two-sigma
    intervals (deface's prepare: stage 1, h, the scene's light; stage 2 keeps the start in the default preset)."""
    import torch

    from deface.fit import pipeline, presets
    from deface.fit.config import override, set_from_text
    from deface.fit.log import FitLog
    from deface.fit.rendering import albedo_textures
    from deface.io.images import load_image

    torch.set_num_threads(1)
    config = override(presets.get("default"), resolution=resolution)
    for assignment in settings:
        config = set_from_text(config, assignment)
    from deface.models.ita import texture_tone

    target = pipeline.detect_target([load_image(path)], config, path, False)
    context, _ = pipeline.prepare(target, config, log=FitLog(quiet=True))
    illuminant = context.inputs.scene_light.illuminant
    with torch.no_grad():
        tone = texture_tone(albedo_textures(context, 128).diffuse.numpy(), illuminant.level_sigma)
    return float(context.scene.tone.detach()), illuminant.record(), tone


def starts(out: Path, split: str | None, variant: str, resolution: int, extra: list[str], jobs: int) -> None:
    rows = [r for r in csv.DictReader(open(out / "MANIFEST.tsv"), delimiter="\t")
            if r["variant"] == variant and (split is None or r["split"] == split)]
    settings = [tuple(extra) + ((r["settings"],) if r["settings"] else ()) for r in rows]
    with ProcessPoolExecutor(jobs) as pool:
        results = list(pool.map(start_of, [str(out / "images" / r["file"]) for r in rows], settings,
                                [resolution] * len(rows)))
    groups: dict[str, list[float]] = {}
    level_errors, inside, inside_2, widths = [], [], [], []
    for row, (start, illuminant, tone) in zip(rows, results, strict=True):
        truth = float(row["gt_ita"])
        (low, high), (low_2, high_2) = tone["ita_interval"], tone["ita_interval_2sigma"]
        inside.append(low <= truth <= high)
        inside_2.append(low_2 <= truth <= high_2)
        widths.append(high - low)
        error = start - float(row["gt_ita"])
        white = float(np.asarray(illuminant["white"]) @ LUMINANCE)
        level_error = float(np.log(white / float(row["true_white"])))
        level_errors.append(level_error)
        for key in (row["scene"], row["exposure"], "all"):
            groups.setdefault(key, []).append(error)
        print(f"{row['file']:42s} truth {float(row['gt_ita']):6.1f} start {start:6.1f} error {error:+6.1f}  "
              f"W {white:5.2f} true {float(row['true_white']):5.2f} (log {level_error:+.2f}, sigma "
              f"{illuminant['level_sigma']:.2f}) {illuminant['source']}")
    for key, errors in groups.items():
        print(f"{key:10s} mean signed {statistics.mean(errors):+5.1f}  MAE {statistics.mean(map(abs, errors)):4.1f}  "
              f"max {max(map(abs, errors)):4.1f}  ({len(errors)})")
    print(f"white level: mean log error {statistics.mean(level_errors):+.3f}, spread "
          f"{statistics.pstdev(level_errors):.3f}")
    print(f"truth inside the start's one-sigma interval {100 * statistics.mean(inside):.0f} %, two-sigma "
          f"{100 * statistics.mean(inside_2):.0f} %; median one-sigma width {statistics.median(widths):.1f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("command", choices=("chart", "make", "starts"))
    parser.add_argument("out", type=Path)
    parser.add_argument("--split", choices=("tune", "report"))
    parser.add_argument("--variant", default="plain", choices=("plain", "card", "checker"))
    parser.add_argument("--resolution", type=int, default=256)
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--set", dest="settings", action="append", default=[], help="PATH=VALUE (deface fit --set)")
    args = parser.parse_args()
    if args.command == "chart":
        chart(args.out)
    elif args.command == "make":
        make(args.out)
    else:
        starts(args.out, args.split, args.variant, args.resolution, args.settings, args.jobs)


if __name__ == "__main__":
    main()
