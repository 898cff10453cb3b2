"""A photo whose face is a small part of it against the same photo cropped to the face by hand (issue 39): the
default fit crops around the face itself, so both should give the same texture. Fits the whole photo and the
hand crop with the same configuration and seed, writes both fits to OUT/whole and OUT/hand, and prints the UV
consistency of their diffuse maps (PSNR / SSIM / LPIPS of the sRGB maps, deface/eval/uv_measure.py) over the texels
both saw squarely (``seen`` >= 0.5), beside each fit's working size and time. What a seed alone moves is the
scale to read it on: the hand crop is fitted again with the next seed (OUT/hand_seed) and compared the same way.

    .venv/bin/python benchmarks/crop_consistency.py ../shared/data/images/psm-clean-008.png \\
        --box 205,30,665,490 -o OUT [--set key=value ...]
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from deface.eval.uv_measure import both_seen, uv_consistency
from deface.export.outputs import write_fit
from deface.fit.log import FitLog
from deface.fit.pipeline import fit
from deface.fit.user_options import fit_config
from deface.io.images import linear_to_srgb, load_image, save_png


def fitted(image: np.ndarray, source: str, config, out: Path):
    started = time.perf_counter()
    result = fit([image], config, source=source, log=FitLog(quiet=True))
    seconds = time.perf_counter() - started
    write_fit(result, out, {"path": source, "kind": "image", "frames": [0]})
    return result, seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("photo", type=Path)
    parser.add_argument("--box", required=True, help="the hand crop x0,y0,x1,y1 in the photo's pixels")
    parser.add_argument("-o", "--out", type=Path, required=True)
    parser.add_argument("--set", action="append", default=[], help="config override key=value (both fits)")
    args = parser.parse_args()
    config = fit_config("default", None, args.set, seed=3)
    x0, y0, x1, y1 = (int(v) for v in args.box.split(","))
    image = load_image(args.photo)
    crop = np.ascontiguousarray(image[y0:y1, x0:x1])
    args.out.mkdir(parents=True, exist_ok=True)
    save_png(args.out / "hand_crop.png", crop, srgb=False)
    whole, whole_seconds = fitted(image, str(args.photo), config, args.out / "whole")
    hand, hand_seconds = fitted(crop, str(args.out / "hand_crop.png"), config, args.out / "hand")
    again, again_seconds = fitted(crop, str(args.out / "hand_crop.png"), replace(config, seed=config.seed + 1),
                                  args.out / "hand_seed")
    for name, result, seconds in (("whole", whole, whole_seconds), ("hand", hand, hand_seconds),
                                  ("hand, next seed", again, again_seconds)):
        size = "x".join(map(str, result.framing.size))
        print(f"{name}: working {size}, maps {result.textures.diffuse.shape[0]}², {seconds:.0f} s")
    for name, a, b in (("whole vs hand", whole, hand), ("hand vs hand with the next seed", hand, again)):
        seen = both_seen(a.texels.seen, b.texels.seen)
        maps = [linear_to_srgb(r.textures.diffuse.detach().clamp(0, 1).numpy()) for r in (a, b)]
        scores = uv_consistency(maps[0], maps[1], seen)
        print(f"{name}: UV consistency over {int(seen.sum())} texels: PSNR {scores['psnr']:.2f} dB, "
              f"SSIM {scores['ssim']:.3f}, LPIPS {scores['lpips']:.2f}")


if __name__ == "__main__":
    main()
