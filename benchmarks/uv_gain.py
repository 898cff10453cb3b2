"""How much of the UV inconsistency between a pair's two fits is one overall gain (the tone / exposure each fit
chose), and how much is the maps' structure (shadow residue, detail placed on other texels).

    DEFACE_MODELS=../shared/models .venv/bin/python benchmarks/uv_gain.py RESULTS [--variant ours]

RESULTS is a ``deface bench run`` output folder. Per pair: the PSNR of the shadowed fit's sRGB diffuse map
against the clean fit's over the model's UV face mask (all of it, not only the texels both fits saw, so the
figures are not ``scores.json``'s: higher, as unseen texels are completed alike), then the same after scaling
the shadowed map's linear RGB by the per-channel least-squares gain onto the clean one.
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

import numpy as np
import torch

from deface.eval.metrics import psnr
from deface.io.images import linear_to_srgb, load_image, srgb_to_linear
from deface.models.registry import load_face_model


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", type=Path)
    parser.add_argument("--variant", default="ours")
    args = parser.parse_args()
    face_mask = torch.as_tensor(np.asarray(load_face_model("ict").albedo.face_mask, np.float32))
    raw, matched = [], []
    for pair in sorted(p for p in (args.results / args.variant).iterdir() if (p / "diffuse_source.png").exists()):
        source, target = load_image(pair / "diffuse_source.png"), load_image(pair / "diffuse_target.png")
        mask = torch.nn.functional.interpolate(face_mask[None, None], size=source.shape[:2], mode="bilinear")
        mask = mask[0, 0].numpy() > 0.5
        linear_source, linear_target = srgb_to_linear(source), srgb_to_linear(target)
        gain = (linear_source[mask] * linear_target[mask]).sum(0) / (linear_source[mask] ** 2).sum(0)
        scaled = linear_to_srgb(np.clip(linear_source * gain, 0, 1))
        raw.append(psnr(source, target, mask))
        matched.append(psnr(scaled, target, mask))
        print(f"{pair.name:22s} PSNR {raw[-1]:6.2f}  gain-matched {matched[-1]:6.2f}  gain {np.round(gain, 3)}")
    print(f"{'mean':22s} PSNR {statistics.mean(raw):6.2f}  gain-matched {statistics.mean(matched):6.2f}")


if __name__ == "__main__":
    main()
