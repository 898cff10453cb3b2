"""How much of the true albedo's fine structure the working image itself holds: the ceiling of what stage 3 can put
into the map at a working size (issue 39). For each fit of `deface bench albedo`, the working photo is read into UV
at 256² through the fitted mesh and camera (deface/texture/confidence.py ``unwrap``) and its fine luminance (minus a
Gaussian of 2 texels, deface/eval/albedo_measures.py) is correlated with the truth's over each region of the set's
masks, on the texels the benchmark scores (the true surface seen within 70 degrees) that the fitted camera sees.
The fitted map's own correlation is printed beside it (from the fit's scores.json).

Then the PSNR that is left to gain below a scale: the map's gain-matched PSNR against the truth over the same
texels, and the PSNR of the map (and of the photo in UV) after an oracle has taken out every error coarser than a
Gaussian of ``ORACLE_SIGMAS`` texels (the map times the truth's blur over the map's blur, both over the scored
texels): what perfect shading and tone at those scales would give, the rest being registration and detail.

    .venv/bin/deface bench albedo ../shared/data/detail-synth -o OUT [--set ...]
    .venv/bin/python benchmarks/photo_detail.py ../shared/data/detail-synth OUT
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from deface.eval import albedo_measures as measures
from deface.eval.albedo_benchmark import REFERENCE, photo_in_uv, read_truth_set, region_masks, shown_texels
from deface.eval.uv_measure import local_mean
from deface.export.load import load_fit
from deface.io.images import load_image, srgb_to_linear
from deface.models.ict_build import read_obj

REGIONS = ("beard", "freckle_area")
ORACLE_SIGMAS = (4, 8, 16)


def coarse_oracle(image: np.ndarray, truth: np.ndarray, texels: np.ndarray, sigma: float) -> np.ndarray:
    """``image`` [S, S, 3] with its errors coarser than a Gaussian of ``sigma`` texels taken out by the ``truth``:
    image x blur(truth) / blur(image), each blur taken within ``texels`` [S, S] (uv_measure.local_mean)."""
    return image * local_mean(truth, texels, sigma) / np.maximum(local_mean(image, texels, sigma), 1e-6)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("truth", type=Path, help="the truth set (images/, albedo/, masks/, mesh.obj)")
    parser.add_argument("runs", type=Path, help="the output folder of `deface bench albedo`")
    args = parser.parse_args()
    masks = region_masks(args.truth)
    truth_mesh = read_obj(args.truth / "mesh.obj", with_faces=False)["positions"]
    for variant in sorted(p for p in args.runs.iterdir() if p.is_dir()):
        print(variant.name)
        for render in read_truth_set(args.truth):
            folder = variant / render.stem
            if not (folder / "params.json").is_file():
                continue
            fit = load_fit(folder)
            photo = photo_in_uv(fit)
            shown = shown_texels(fit, truth_mesh) & np.isfinite(photo).all(-1)
            truth = measures.at_score_size(srgb_to_linear(load_image(args.truth / "albedo" / render.albedo))
                                           .astype(np.float64))
            scores = json.loads((folder / "scores.json").read_text())["scores"]
            cells = [f"{name} photo {measures.fine_structure(np.nan_to_num(photo), truth, masks[name] & shown):5.2f} "
                     f"map {scores.get(name, {}).get('fine_structure', float('nan')):5.2f}" for name in REGIONS]
            size = "x".join(map(str, fit.framing.size))
            print(f"  {render.stem:12s} working {size:9s} " + " | ".join(cells))
            fitted = measures.at_score_size(srgb_to_linear(load_image(folder / "textures" / "diffuse.png"))
                                            .astype(np.float64))
            print("  " + " " * 12 + psnr_line(fitted, np.nan_to_num(photo), truth, shown, masks))


def psnr_line(fitted: np.ndarray, photo: np.ndarray, truth: np.ndarray, shown: np.ndarray, masks: dict) -> str:
    """The map's gain-matched PSNR, and the map's and photo's with the truth's coarse scales (module doc)."""
    reference = masks[REFERENCE] & shown
    psnr = measures.psnr_ssim(measures.gain_matched(fitted, truth, reference), truth, shown)[0]
    cells = [f"PSNR map {psnr:5.2f}"]
    for sigma in ORACLE_SIGMAS:
        mine, read = (measures.psnr_ssim(coarse_oracle(image, truth, shown, sigma), truth, shown)[0]
                      for image in (fitted, photo))
        cells.append(f"coarser than {sigma:2d}: map {mine:5.2f} photo {read:5.2f}")
    return " | ".join(cells)


if __name__ == "__main__":
    main()
