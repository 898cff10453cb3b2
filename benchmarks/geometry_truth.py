"""The fitted geometry against the true one: the renders of ../shared/data/detail-synth were made from a known mesh
(``mesh.obj``, the face model's topology), so each fit's mesh can be compared vertex by vertex after the similarity
that best aligns them (Umeyama). Also the landmark residual the fit ends with and the expression weights it pushed
to their bound: with stage 2's landmark term too weak, L_pho drove the ICT blendshapes to their bounds (mouthClose 1
with the jaw shut folds the lips over the nose).

    .venv/bin/deface bench albedo ../shared/data/detail-synth -o OUT [--preset P]
    .venv/bin/python benchmarks/geometry_truth.py OUT/<variant> [more variant folders]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from deface.eval.albedo_benchmark import similarity_aligned
from deface.models.ict_build import read_obj
from deface.paths import shared_dir


def vertex_errors(fit_dir: Path, truth: np.ndarray) -> np.ndarray:
    """[V] cm: each fitted vertex's distance to the true one after the best similarity."""
    fitted = read_obj(fit_dir / "mesh.obj", with_faces=False)["positions"]
    return np.linalg.norm(similarity_aligned(fitted, truth) - truth, axis=1)


def saturated_expressions(fit_dir: Path) -> int:
    """How many expression weights the fit left at their upper bound (>= 0.99)."""
    expression = np.asarray(json.loads((fit_dir / "params.json").read_text())["expression"], dtype=float)
    return int((expression >= 0.99).sum())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("variants", nargs="+", type=Path, help="variant folders of `deface bench albedo` output")
    args = parser.parse_args()
    truth = read_obj(shared_dir() / "data" / "detail-synth" / "mesh.obj", with_faces=False)["positions"]
    for variant in args.variants:
        fits = sorted(p for p in variant.iterdir() if (p / "mesh.obj").is_file())
        print(f"{variant.name}: vertex error after alignment, cm (median / 90th / 99th percentile); "
              "expressions at their bound")
        rows = []
        for fit in fits:
            errors = vertex_errors(fit, truth)
            row = [*np.percentile(errors, [50, 90, 99]), saturated_expressions(fit)]
            rows.append(row)
            print(f"  {fit.name:14s} {row[0]:5.2f} {row[1]:5.2f} {row[2]:5.2f}   {row[3]:2d}")
        mean = np.mean(rows, 0)
        print(f"  {'mean':14s} {mean[0]:5.2f} {mean[1]:5.2f} {mean[2]:5.2f}   {mean[3]:4.1f}")


if __name__ == "__main__":
    main()
