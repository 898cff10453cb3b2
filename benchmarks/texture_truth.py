"""The fitted diffuse maps of the renders of known albedo against that albedo, in UV space: whether stage 3's
refinement adds the person's detail or noise. A shadow pair only says whether two fits agree; here the truth is
known (../shared/data/skin-tone-synth/albedo, the ICT layout the maps share).

    .venv/bin/deface bench skin-tone ../shared/data/skin-tone-synth -o OUT --no-baseline
    .venv/bin/python benchmarks/texture_truth.py OUT [OUT2 ...]

Over the texels the fit constrains (``textures/confidence.png`` >= ``--confidence``, eroded by 3 texels):
- PSNR of the sRGB map against the truth, and after one gain per channel in linear RGB (the map's structure,
  whatever its tone; the tone has its own figures in ``deface bench skin-tone``);
- per scale (a Gaussian of 1 and 2 texels), the relative fine detail of the map and of the truth
  (deface/eval/uv_measure.py ``relative_detail``): its amplitude (regression of the map's detail on the truth's:
  1 = all of the true detail), its correlation with the truth's, and the rest (x100: noise, baked shading).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy import ndimage

from deface.eval.metrics import psnr
from deface.eval.uv_measure import relative_detail
from deface.io.images import load_image, srgb_to_linear
from deface.paths import shared_dir

SCALES = (1.0, 2.0)


def compare(fit_dir: Path, truth: np.ndarray, threshold: float) -> list[float]:
    """[psnr, gain-matched psnr, then per scale: amplitude, correlation, rest x100] of one fit."""
    fitted = load_image(fit_dir / "textures" / "diffuse.png").astype(np.float64)
    region = load_image(fit_dir / "textures" / "confidence.png")[..., 0] >= threshold
    inner = ndimage.binary_erosion(region, iterations=3)
    fitted_linear, truth_linear = srgb_to_linear(fitted), srgb_to_linear(truth)
    gain = np.median(truth_linear[inner], 0) / np.median(fitted_linear[inner], 0)
    matched = np.clip(fitted_linear * gain, 0, 1) ** (1 / 2.2)
    row = [psnr(fitted, truth, inner), psnr(matched, truth_linear ** (1 / 2.2), inner)]
    for sigma in SCALES:
        mine = relative_detail(fitted_linear, region, sigma)[inner]
        true = relative_detail(truth_linear, region, sigma)[inner]
        amplitude = float((mine * true).sum() / (true * true).sum())
        correlation = float((mine * true).sum() / np.sqrt((mine * mine).sum() * (true * true).sum()))
        rest = float(100 * np.sqrt(np.mean(((mine - amplitude * true) ** 2).sum(-1))))
        row += [amplitude, correlation, rest]
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", type=Path, help="output folders of `deface bench skin-tone` on the renders")
    parser.add_argument("--confidence", type=float, default=0.06, help="least confidence.png value of a texel")
    parser.add_argument("--variant", default="default")
    args = parser.parse_args()
    albedo = shared_dir() / "data" / "skin-tone-synth" / "albedo"
    header = "psnr | gain-matched | " + " | ".join(f"amplitude {s:g} | correlation {s:g} | rest {s:g}" for s in SCALES)
    for run in args.runs:
        fits = sorted(p for p in (run / args.variant).iterdir() if (p / "textures" / "diffuse.png").exists())
        rows = [compare(fit, load_image(albedo / f"{fit.name.split('_')[0]}.png").astype(np.float64), args.confidence)
                for fit in fits]
        print(f"{run} ({len(rows)} renders; {header})")
        for fit, row in zip(fits, rows, strict=True):
            print(f"  {fit.name:18s} " + " ".join(f"{v:6.2f}" for v in row))
        print(f"  {'mean':18s} " + " ".join(f"{v:6.2f}" for v in np.mean(rows, 0)))


if __name__ == "__main__":
    main()
