"""Fitted maps under occluders against the truth: the renders of the occluder truth set
(``benchmarks/blender/occluder_scenes.py``: glasses, tinted glasses, hair strands, fingers in front of detail-synth's
face) come with the truth of which texels each occluder hides (``occluded/``, ``_lens``, ``_shadow``) and with the
render read into UV through the true geometry (``photo_uv/``). For each fit's ``textures/diffuse.png`` this reports,
over the texels under the occluder that the fit's benchmark scores, how much of the occluder the map painted in
(its darkness) and its colour error against the true albedo; and the same of the truth (and of the photo).

    .venv/bin/deface bench albedo /work/occluder-synth -o BENCH
    .venv/bin/python benchmarks/occluder_truth.py /work/occluder-synth BENCH

Regions (at the albedo benchmark's score size, deface/eval/albedo_measures.py): ``frame`` (glasses: the occluded
texels not seen through a lens), ``lens`` (seen through a lens), ``hair``, ``fingers``; and, under the key light,
``shadow``: the texels the camera sees in the occluder's cast shadow; and ``<region> mirror``: the region's mirror
image in UV (u -> 1 - u, the ICT layout is symmetric) outside the occluder and its shadow, with the occluder's C,
where the fit's symmetry term may copy the occluder to the other side of the face. Each region is taken where the
fit's benchmark scores the map (the true surface facing the fitted camera, ``albedo_benchmark.shown_texels``) and
the true surface faces the camera unhidden by the face (``visible/``).

- **skin ring** of a region: the texels within :data:`RING` texels of the region grown by :data:`GROW` (below),
  widened a texel at a time (up to :data:`WIDEST`) until it holds :data:`LEAST` texels, that are scored, visible,
  neither occluded, in the occluder's shadow nor in a feature mask (beard, freckles, birthmark), and whose true
  albedo's luminance is within :data:`PLAIN` of its mean over the forehead box: plain skin around the region (not
  a brow, a lip, a mole).
- **photo contrast** C = L(photo, region) / L(photo, ring): L the mean linear luminance, the photo read in UV; the
  occluder's (or its shadow's) luminance relative to the skin around it, as the camera saw it.
- **darkness** D of a map = (L_ring - L_under) / (L_ring - L_occ), L_under and L_ring the map's mean luminance over
  the region and its ring, L_occ = L_ring x C (the occluder brought to the map's level by the photo's contrast), i.e.
  D = (1 - K) / (1 - C), K = L_under / L_ring: 0 when the map is as light under the occluder as the skin around it,
  1 when it is as dark (relative to that skin) as the occluder in the photo. Undefined (NaN) when the photo's
  region is within MIN_CONTRAST of its ring's level, and for clear lenses (they hide nothing; their region's C is
  the eye socket's shading). The truth's D is the reference: the true albedo may be darker there itself (a brow
  under the frame, a mole under a strand).
- **grown darkness** D+: the fitted map's texels are where the fit's geometry puts them, which may miss a thin
  region (a rim, a strand) by a few texels. D+ = sum over the region grown by :data:`GROW` texels (the growth only
  over scored plain skin: not into the occluder's other parts, its shadow, a feature, a brow) of (1 - L / L_ring),
  over (region's texels x (1 - C)): the same darkness, counted wherever it landed within GROW texels. A map that
  painted the occluder in a little off its place scores D+ 1 (and D less); a clean map 0; the truth about its D.
  D and D+ are signed: where the occluder is lighter than the skin around it in the photo (C > 1: fingers toward
  an even light), 1 is the map as much lighter there.
- **colour error**: the albedo benchmark's (``albedo_measures.colour_error``: RMS CIELAB a*b* difference at the
  truth's luminance) over the region, the map matched to the truth by one gain per channel on the forehead box as
  the benchmark does (on its scored texels outside the occluder and its shadow, which the strands keep clear of).
  The truth's is 0 by definition; the photo's (matched the same way) is that of a map that painted the occluder in.
"""

from __future__ import annotations

import argparse
import csv
import math
from pathlib import Path

import numpy as np
from scipy import ndimage

from deface.eval import albedo_measures as measures
from deface.eval.albedo_benchmark import REFERENCE, region_masks, shown_texels

RING = 4
"""Texels (at the score size) of the skin ring around a region."""
PLAIN = 0.15
"""A ring texel is plain skin when its true luminance is within this share of its mean over the forehead box."""
GROW = 3
"""Texels (at the score size) a region grows by for the grown darkness D+."""
LEAST = 50
"""The ring is widened until it holds this many texels ..."""
WIDEST = 24
"""... or reaches this width."""
FEATURES = ("beard", "freckles", "birthmark")
"""The set's masks of dark features, left out of the skin ring."""
REGIONS = {"glasses": ("frame", "lens", "shadow"), "tinted": ("frame", "lens", "shadow"),
           "strand": ("hair", "shadow"), "fingers": ("fingers", "shadow")}
MIRRORED = 0.25
"""A region's mirror image (u -> 1 - u) is measured when this share of it at least lies outside the occluder."""
CLEAR = {("glasses", "lens")}
"""(occluder, region) that hide nothing: no darkness."""


def skin_ring(region: np.ndarray, excluded: np.ndarray, width: int = RING, least: int = LEAST,
              widest: int = WIDEST) -> np.ndarray:
    """[S, S] bool: the texels within ``width`` texels of ``region`` (Euclidean), outside it and not ``excluded``,
    the width grown a texel at a time until the ring holds ``least`` texels (or reaches ``widest``)."""
    distance = ndimage.distance_transform_edt(~region)
    ring = np.zeros_like(region)
    for w in range(width, widest + 1):
        ring = (distance <= w) & ~region & ~excluded
        if ring.sum() >= least:
            break
    return ring


def plain_skin(truth: np.ndarray, reference: np.ndarray, plain: float = PLAIN) -> np.ndarray:
    """[S, S] bool: texels whose true luminance is within ``plain`` of its mean over ``reference``."""
    luminance = measures.luminance(truth)
    return np.abs(luminance / max(luminance[reference].mean(), 1e-9) - 1.0) <= plain


def grown(region: np.ndarray, blocked: np.ndarray, width: int = GROW) -> np.ndarray:
    """``region`` grown by ``width`` texels (Euclidean), not into ``blocked``."""
    return (ndimage.distance_transform_edt(~region) <= width) & ~(blocked & ~region)


def contrast(image: np.ndarray, region: np.ndarray, ring: np.ndarray) -> float:
    """Mean luminance of ``image`` [S, S, 3] (linear) over ``region`` over its mean over ``ring``."""
    return float(measures.luminance(image[region]).mean() / max(measures.luminance(image[ring]).mean(), 1e-9))


def darkness(image: np.ndarray, region: np.ndarray, ring: np.ndarray, photo_contrast: float) -> float:
    """D = (1 - K) / (1 - C) (module doc), K the image's :func:`contrast`, C the photo's; NaN when |1 - C| is under
    MIN_CONTRAST."""
    if abs(1.0 - photo_contrast) < measures.MIN_CONTRAST:
        return float("nan")
    return (1.0 - contrast(image, region, ring)) / (1.0 - photo_contrast)


def grown_darkness(image: np.ndarray, region: np.ndarray, wider: np.ndarray, ring: np.ndarray,
                   photo_contrast: float) -> float:
    """D+ (module doc): the darkness of ``image`` summed over ``wider`` (the grown region), per texel of
    ``region``, relative to the occluder's (1 - C); NaN as :func:`darkness`."""
    if abs(1.0 - photo_contrast) < measures.MIN_CONTRAST:
        return float("nan")
    level = max(measures.luminance(image[ring]).mean(), 1e-9)
    deficit = (1.0 - measures.luminance(image[wider]) / level).sum()
    return float(deficit / (region.sum() * (1.0 - photo_contrast)))


def region_figures(fitted: np.ndarray, truth: np.ndarray, photo: np.ndarray, region: np.ndarray, ring: np.ndarray,
                   reference: np.ndarray, wider: np.ndarray | None = None, clear: bool = False,
                   photo_contrast: float | None = None) -> dict:
    """The figures of one region: the map's darkness (D, and D+ over ``wider``, the grown region, when given; the
    ``ring`` outside it) and colour error, the truth's darkness, the photo's contrast and colour error. All maps
    linear [S, S, 3]; ``photo`` must be finite over the region, its ring and the ``reference`` (the plain skin both
    maps are gain-matched to the truth on); ``clear``: an occluder that hides nothing (no darkness);
    ``photo_contrast``: C, when it is another region's (a mirrored region's is its occluder's)."""
    if photo_contrast is None:
        photo_contrast = contrast(photo, region, ring)
    matched = measures.gain_matched(fitted, truth, reference)
    photo_matched = measures.gain_matched(photo, truth, reference)
    nan = float("nan")
    figures = {"texels": int(region.sum()), "ring": int(ring.sum()), "photo_contrast": photo_contrast,
               "darkness": nan if clear else darkness(matched, region, ring, photo_contrast),
               "darkness_truth": nan if clear else darkness(truth, region, ring, photo_contrast),
               "grown_darkness": nan, "grown_darkness_truth": nan,
               "colour_error": measures.colour_error(matched, truth, region),
               "colour_error_photo": measures.colour_error(photo_matched, truth, region)}
    if wider is not None and not clear:
        figures["grown_darkness"] = grown_darkness(matched, region, wider, ring, photo_contrast)
        figures["grown_darkness_truth"] = grown_darkness(truth, region, wider, ring, photo_contrast)
    return figures


# --- reading the set and the fits ---

def _mask(path: Path) -> np.ndarray:
    """A 512² UV mask at the score size (all False when the file does not exist)."""
    from deface.io.images import load_image

    if not path.is_file():
        return np.zeros((measures.SCORE_SIZE, measures.SCORE_SIZE), bool)
    return measures.at_score_size(load_image(path)[..., 0] > 0.5)


def _linear_map(path: Path) -> np.ndarray:
    from deface.io.images import load_image, srgb_to_linear

    return measures.at_score_size(srgb_to_linear(load_image(path)[..., :3]).astype(np.float64))


def photo_at_score_size(photo: np.ndarray, seen: np.ndarray, size: int = measures.SCORE_SIZE) -> np.ndarray:
    """``photo`` [N, N, 3] (linear, N a multiple of ``size``) averaged over the ``seen`` texels of each block,
    NaN where a block has none."""
    factor = photo.shape[0] // size
    weights = seen.reshape(size, factor, size, factor).sum((1, 3)).astype(np.float64)
    sums = (photo * seen[..., None]).reshape(size, factor, size, factor, 3).sum((1, 3))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(weights[..., None] > 0, sums / weights[..., None], np.nan)


def render_regions(set_dir: Path, stem: str, occluder: str, masks: dict[str, np.ndarray]) -> dict:
    """One render's truth at the score size, before the fit's scored texels are applied: {"regions": {region:
    [S, S] bool} (module doc), "visible": the visible texels, "features": the feature masks' union, "excluded":
    what no skin ring holds (occluded, in the occluder's shadow, a feature)}."""
    occluded = _mask(set_dir / "occluded" / f"{stem}.png")
    lens = _mask(set_dir / "occluded" / f"{stem}_lens.png")
    visible = _mask(set_dir / "visible" / f"{stem}.png")
    shadow = _mask(set_dir / "occluded" / f"{stem}_shadow.png") & visible & ~occluded
    names = REGIONS[occluder]
    regions = {"shadow": shadow}
    if "frame" in names:
        regions.update(frame=occluded & ~lens, lens=lens & occluded)
    else:
        regions[names[0]] = occluded
    features = np.zeros_like(occluded)
    for name in FEATURES:
        features |= masks.get(name, np.zeros_like(occluded))
    return {"regions": regions, "visible": visible, "features": features,
            "excluded": occluded | shadow | features}


def measure_fit(set_dir: Path, fit_dir: Path, stem: str, occluder: str, albedo: str, masks: dict[str, np.ndarray],
                truth_mesh: np.ndarray, models_dir=None) -> dict:
    """{region: figures} of one fit (regions with fewer than 4 scored texels left out)."""
    from deface.export.load import load_fit
    from deface.io.images import load_image, srgb_to_linear

    fitted = _linear_map(fit_dir / "textures" / "diffuse.png")
    truth = _linear_map(set_dir / "albedo" / albedo)
    photo_full = srgb_to_linear(load_image(set_dir / "photo_uv" / f"{stem}.png")[..., :3]).astype(np.float64)
    seen_full = load_image(set_dir / "visible" / f"{stem}.png")[..., 0] > 0.5
    photo = photo_at_score_size(photo_full, seen_full)
    shown = shown_texels(load_fit(fit_dir, models_dir=models_dir), truth_mesh)
    parts = render_regions(set_dir, stem, occluder, masks)
    usable = shown & parts["visible"] & np.isfinite(photo).all(-1)
    photo = np.nan_to_num(photo)
    reference = masks[REFERENCE] & usable & ~parts["excluded"]
    excluded = parts["excluded"] | ~usable
    plain = plain_skin(truth, reference)
    excluded |= ~plain
    figures = {}
    for name in REGIONS[occluder]:
        whole = parts["regions"][name]
        region = whole & usable
        if region.sum() < 4:
            continue
        wider = grown(region, parts["excluded"] | ~usable | ~plain)
        ring = skin_ring(wider, excluded | whole)
        clear = (occluder, name) in CLEAR
        figures[name] = region_figures(fitted, truth, photo, region, ring, reference, wider, clear=clear)
        # the same occluder's darkness copied to the other side of the face (the fit's symmetry term)
        mirrored = whole[:, ::-1] & ~parts["excluded"] & usable
        if clear or mirrored.sum() < max(4, MIRRORED * region.sum()):
            continue
        wider = grown(mirrored, parts["excluded"] | ~usable | ~plain)
        ring = skin_ring(wider, excluded | whole[:, ::-1])
        figures[f"{name} mirror"] = region_figures(fitted, truth, photo, mirrored, ring, reference, wider,
                                                   photo_contrast=figures[name]["photo_contrast"])
    return figures


def read_manifest(set_dir: Path) -> list[dict[str, str]]:
    with (set_dir / "MANIFEST.tsv").open(newline="") as handle:
        return list(csv.DictReader(handle, delimiter="\t"))


def _cell(value: float | None) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{value:.2f}"


COLUMNS = (("C", "photo_contrast"), ("D map", "darkness"), ("D truth", "darkness_truth"),
           ("D+ map", "grown_darkness"), ("D+ truth", "grown_darkness_truth"), ("CE map", "colour_error"),
           ("CE photo", "colour_error_photo"))
"""The printed figures: (heading, key of :func:`region_figures`)."""


def _line(first: str, region: str, texels: str, ring: str, figures: dict) -> str:
    return f"  {first:22s} {region:15s} {texels:>6s} {ring:>5s}" + "".join(
        f" {_cell(figures[key]):>{max(len(heading), 6)}s}" for heading, key in COLUMNS)


def main() -> None:
    from deface.models.ict_build import read_obj

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("set_dir", type=Path, help="the occluder truth set (occluder_scenes.py's OUT)")
    parser.add_argument("bench_dir", type=Path, help="`deface bench albedo SET_DIR -o BENCH_DIR`'s output")
    parser.add_argument("--models", type=Path, default=None, help="model files folder (default: DEFACE_MODELS)")
    parser.add_argument("--tsv", type=Path, default=None, help="also write every row's figures to this file")
    args = parser.parse_args()
    rows = read_manifest(args.set_dir)
    masks = region_masks(args.set_dir)
    truth_mesh = read_obj(args.set_dir / "mesh.obj", with_faces=False)["positions"]
    variants = sorted(p for p in args.bench_dir.iterdir() if p.is_dir() and any(
        (p / Path(row["file"]).stem / "textures" / "diffuse.png").is_file() for row in rows))
    keys = ["texels", "ring", *(key for _, key in COLUMNS)]
    records = ["\t".join(["variant", "render", "region", *keys])]
    for variant in variants:
        print(f"{variant.name}: each fit's textures/diffuse.png under the occluder (benchmarks/occluder_truth.py's "
              "doc). C: the photo's luminance there over the skin ring's; D: darkness, 0 = as the skin ring, 1 = as "
              "dark as the occluder in the photo (truth: the reference); D+: the same within "
              f"{GROW} texels of the region; CE: colour error (RMS a*b*; the truth's is 0, the photo's = the "
              "occluder painted in)")
        print(f"  {'render':22s} {'region':15s} {'texels':>6s} {'ring':>5s}"
              + "".join(f" {heading:>{max(len(heading), 6)}s}" for heading, _ in COLUMNS))
        table: dict[tuple[str, str], list[dict]] = {}
        for row in rows:
            stem = Path(row["file"]).stem
            fit_dir = variant / stem
            if not (fit_dir / "textures" / "diffuse.png").is_file():
                continue
            figures = measure_fit(args.set_dir, fit_dir, stem, row["occluder"], f"{row['tone']}.png", masks,
                                  truth_mesh, args.models)
            for region, f in figures.items():
                table.setdefault((f"{row['occluder']}_{row['light']}", region), []).append(f)
                print(_line(stem, region, str(f["texels"]), str(f["ring"]), f))
                records.append("\t".join([variant.name, stem, region, *(f"{f[key]:.4g}" for key in keys)]))
        print("  mean over tones:")
        for (scene, region), values in table.items():
            print(_line(scene, region, "", "", {key: _mean([v[key] for v in values]) for _, key in COLUMNS}))
    if args.tsv is not None:
        args.tsv.write_text("\n".join(records) + "\n")


def _mean(values: list[float]) -> float:
    finite = [v for v in values if math.isfinite(v)]
    return float(np.mean(finite)) if finite else float("nan")


if __name__ == "__main__":
    main()
