"""The scene's white level W from each piece of evidence alone, per photo: what a photo's exposure is when a white
patch shows it, and how far the grey world is from it (``deface/priors/illuminant.py``; BENCHMARKS.md "Skin tone").

    DEFACE_MODELS=../shared/models .venv/bin/python benchmarks/white_level.py IMAGE [IMAGE ...]

Per image: the white patch's level and log spread (``-`` when the grey world is the surer), the grey world's
level, and the share of the scene near white; then the medians over the images with a patch. The face is the
landmarks' convex hull (the fit uses the stage-1 face's coverage), grown as the estimate grows it.
"""

from __future__ import annotations

import argparse
import statistics

import cv2
import numpy as np


def levels(path: str) -> tuple[float | None, float | None, float, float]:
    """(patch level, patch sigma, grey-world level, near-white share) of one image."""
    import torch

    from deface.fit import pipeline, presets
    from deface.fit.config import override
    from deface.io.images import LUMINANCE, load_image, srgb_to_linear
    from deface.priors import illuminant

    torch.set_num_threads(1)
    # the whole photo at 256 px, as the illuminant estimate read it before the fit cropped to the face (issue 39)
    config = override(presets.get("default"), resolution=256, **{"crop.enabled": False})
    settings = config.tone.illuminant
    target = pipeline.detect_target([load_image(path)], config, path, False)
    frame = np.asarray(target.frames_srgb[0])
    face = np.zeros(frame.shape[:2], np.uint8)
    cv2.fillConvexPoly(face, cv2.convexHull(target.landmarks[0].points.astype(np.int32)), 1)
    pixels = illuminant._scene_pixels(frame, face.astype(bool), settings)
    linear = srgb_to_linear(pixels)
    luminance = linear @ LUMINANCE
    usable = (pixels.max(-1) < settings.clipped) & (luminance >= settings.dark)
    _, grey = illuminant.grey_world(linear[usable], settings)
    patch = illuminant._white_patch(pixels, linear, illuminant.grey_world_spread(usable, settings), settings)
    white = float((pixels.min(-1) >= settings.white_threshold).mean())
    return (None, None, grey, white) if patch is None else (patch[1], patch[2], grey, white)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("images", nargs="+")
    args = parser.parse_args()
    with_patch = []
    for path in args.images:
        patch, sigma, grey, white = levels(path)
        shown = "-" if patch is None else f"{patch:.2f} (sigma {sigma:.2f})"
        print(f"{path.rsplit('/', 1)[-1][:40]:40s} patch {shown:18s} grey world {grey:5.2f} near white {white:.3f}")
        if patch is not None:
            with_patch.append((patch, grey))
    if with_patch:
        patches, greys = zip(*with_patch, strict=True)
        print(f"{len(with_patch)} of {len(args.images)} with a white patch: patch W {min(patches):.2f}-"
              f"{max(patches):.2f} (median {statistics.median(patches):.2f}), grey world on them {min(greys):.2f}-"
              f"{max(greys):.2f} (median {statistics.median(greys):.2f})")


if __name__ == "__main__":
    main()
