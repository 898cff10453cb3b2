"""How much of the true albedo's fine structure the working image itself holds: the ceiling of what stage 3 can put
into the map at a working size (issue 39). For each fit of `deface bench albedo`, the working photo is read into UV
at 256² through the fitted mesh and camera (deface/texture/confidence.py ``unwrap``) and its fine luminance (minus a
Gaussian of 2 texels, deface/eval/albedo_measures.py) is correlated with the truth's over each region of the set's
masks, on the texels the benchmark scores (the true surface seen within 70 degrees) that the fitted camera sees.
The fitted map's own correlation is printed beside it (from the fit's scores.json).

    .venv/bin/deface bench albedo ../shared/data/detail-synth -o OUT [--set ...]
    .venv/bin/python benchmarks/photo_detail.py ../shared/data/detail-synth OUT
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from deface.eval import albedo_measures as measures
from deface.eval.albedo_benchmark import photo_in_uv, read_truth_set, region_masks, shown_texels
from deface.export.load import load_fit
from deface.io.images import load_image, srgb_to_linear
from deface.models.ict_build import read_obj

REGIONS = ("beard", "freckle_area")


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


if __name__ == "__main__":
    main()
