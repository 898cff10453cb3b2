"""Is a real photo's beard in its map as dark, relative to the cheeks, as in the photo? (issue 38: nextface-s1)

A photo has no true albedo, but under an even light its shading over the chin and over the cheeks is about the same,
so the photo's own contrast between them is the albedo's, near enough. For each finished fit this compares, on the
working photo's pixels:

    K = mean luminance over the beard zone / median over the cheeks and forehead

- beard zone: below the nose's base inside the face's outline (deface/priors/face_region.py ``beard_zone_mask``),
  less the lips and nostrils (``feature_mask_from_landmarks``, grown by 2 % of the face), on pixels the fitted face
  covers and h calls face;
- cheeks and forehead: the skin-tone boxes of the UV layout (deface/models/ita.py ``in_tone_boxes``);
- K_photo from the working photo (linear), K_map from the diffuse map read at each pixel's UV through the fitted mesh.

Printed: K_photo, K_map and kept = (1 - K_map) / (1 - K_photo): 1 = the map keeps the photo's beard darkness, 0 = the
beard bleached to skin, below 0 = paler than the cheeks. The issue's target is within 20 % of the photo (0.8-1.2).
Meaningful for a bearded face under an even light; a shaven face has K near 1 and ``kept`` says nothing.

    .venv/bin/deface fit ../shared/data/images/nextface-s1.png -o OUT
    .venv/bin/python benchmarks/photo_beard.py OUT [OUT2 ...]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from deface.export.load import load_fit
from deface.io.images import LUMINANCE, srgb_to_linear
from deface.models.ita import in_tone_boxes, pixel_uvs
from deface.priors.face_region import beard_zone_mask, feature_mask_from_landmarks
from deface.render.mesh import sample_texture

FEATURE_MARGIN = 0.02
"""The features' hulls are grown by this share of the face's size (its landmarks' box diagonal) before they are
left out."""


def region_masks(landmarks: np.ndarray, uv: np.ndarray, usable: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(beard zone, cheeks and forehead) [H, W] bool over ``usable`` pixels, from MediaPipe ``landmarks`` [478, 2]
    and per-pixel ``uv`` [H, W, 2]."""
    shape = usable.shape
    size = float(np.hypot(*(landmarks.max(0) - landmarks.min(0))))
    features = feature_mask_from_landmarks(landmarks, shape, max(1, int(round(FEATURE_MARGIN * size))))
    beard = beard_zone_mask(landmarks, shape) & ~features & usable
    return beard, in_tone_boxes(uv) & usable & ~beard


def contrast(luminance: np.ndarray, beard: np.ndarray, skin: np.ndarray) -> float:
    """K: the mean of ``luminance`` over ``beard`` over its median over ``skin`` (the mean: a beard covers part of
    the zone, and the median of the zone would be its skin's)."""
    return float(np.mean(luminance[beard]) / max(float(np.median(luminance[skin])), 1e-6))


def measure(folder: Path) -> dict:
    """K_photo, K_map and the darkness kept of the fit in ``folder`` (its first frame)."""
    result = load_fit(folder)
    frame = result.frames[0]
    fragments = result.renderer.rasterize(frame.geometry.mesh, frame.geometry.camera)
    uv = pixel_uvs(fragments, frame.geometry.mesh)
    usable = (fragments.mask.numpy() > 0.5) & (frame.face_classifier.numpy() > 0.5)
    beard, skin = region_masks(np.asarray(frame.landmarks), uv, usable)
    if beard.sum() < 50 or skin.sum() < 50:
        raise SystemExit(f"{folder}: too few pixels in the beard zone ({beard.sum()}) or the cheeks ({skin.sum()})")
    photo = srgb_to_linear(frame.photo_srgb.astype(np.float64)) @ LUMINANCE
    texel = sample_texture(result.textures.diffuse.detach(), torch.as_tensor(uv.reshape(-1, 2), dtype=torch.float32))
    albedo = texel.numpy().reshape(*uv.shape[:2], 3) @ LUMINANCE
    k_photo, k_map = contrast(photo, beard, skin), contrast(albedo, beard, skin)
    return {"k_photo": k_photo, "k_map": k_map, "kept": (1.0 - k_map) / (1.0 - k_photo),
            "beard_pixels": int(beard.sum()), "skin_pixels": int(skin.sum())}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("fits", type=Path, nargs="+", help="folders written by `deface fit`")
    args = parser.parse_args()
    print("fit | K photo | K map | kept (1 = the photo's beard darkness)")
    for folder in args.fits:
        figures = measure(folder)
        print(f"{folder} | {figures['k_photo']:.3f} | {figures['k_map']:.3f} | {figures['kept']:.2f}")


if __name__ == "__main__":
    main()
