"""Measures of textures in UV space, where users see them (Blender, game engines, datasets).

- **UV consistency**: the same person and pose fitted from a shadowed photo and from the clean one should give
  the same diffuse texture. PSNR / SSIM / LPIPS (:func:`deface.eval.metrics.score_images`, "face" region)
  between the two sRGB-encoded diffuse maps over the texels both fits saw well: ``seen`` >= :data:`SEEN` in both
  (visible x face region h x cos of the viewing angle, :meth:`deface.texture.confidence.TexelView.seen`; it
  depends on the pose, not on the method, so every method is scored on the same texels).
- **Speckle**: high-frequency energy of the diffuse map beyond what the photo shows at that scale. For a map X
  the relative detail is hf(X) = (X - G(X)) / G(X), G a Gaussian of sigma :data:`SPECKLE_SIGMA` texels taken
  within the region (normalised convolution); E(X) is the mean over the region of sum_c hf(X)_c². The photo,
  read at each texel's pixel (:func:`deface.texture.confidence.unwrap`), gives the detail that is really there;
  speckle = 100 x sqrt(max(0, E(texture) - E(photo))), in percent of local contrast. Region: texels seen
  >= :data:`SEEN`, eroded by 2 texels (the region's border is not detail).
- **Detail**: sqrt(E(texture) / E(photo)), the map's fine contrast as a share of the photo's: 1 keeps all of
  it, well below 1 is the prior with a faint layer of the person's detail (stubble, brows, wrinkles).
- **Edge fringe**: the colour a cast shadow's edge leaves in the map fitted from the shadowed photo. Where the
  edge of the shadow (its mask read in UV through the source fit's view) runs, within :data:`EDGE_BAND` texels
  of it, the RMS of the chroma of log(source map / target map), the two maps matched by one gain per channel
  over the texels both saw; x100 (red-green and yellow-blue axes, as ``deface bench albedo``'s colour noise).
  Over the rest of the texels both saw the same figure says how much the two maps' colour differs anyway: the
  fringe is the edge's excess over it. 0: the edge left no colour.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from deface.eval.metrics import score_images

SEEN = 0.5  # seen at least this squarely (within 60 degrees, inside h) by a fit
SPECKLE_SIGMA = 1.0  # texels: the scale of per-texel noise
MIN_TEXELS = 64  # fewer texels in a region than this: no score
EDGE_BAND = 2  # texels either side of a shadow's edge in UV (at 256²) that the edge fringe reads
CHROMA_AXES = np.array([[1.0, -1.0, 0.0], [0.5, 0.5, -1.0]]) / np.array([[np.sqrt(2)], [np.sqrt(1.5)]])
"""Red-green and yellow-blue unit axes, orthogonal to grey, in log RGB."""


def both_seen(seen_a: np.ndarray, seen_b: np.ndarray) -> np.ndarray:
    """bool [Ht, Wt]: texels both fits saw at least :data:`SEEN`."""
    return (seen_a >= SEEN) & (seen_b >= SEEN)


def uv_consistency(diffuse_a: np.ndarray, diffuse_b: np.ndarray, region: np.ndarray) -> dict[str, float] | None:
    """{"psnr", "ssim", "lpips"} of two sRGB diffuse maps [Ht, Wt, 3] over ``region`` (bool [Ht, Wt])."""
    if region.sum() < MIN_TEXELS:
        return None
    return score_images(diffuse_a, diffuse_b, region.astype(np.float32))["face"]


def local_mean(image: np.ndarray, region: np.ndarray, sigma: float) -> np.ndarray:
    """[Ht, Wt, C]: G X, a Gaussian of ``sigma`` texels taken within ``region`` (normalised convolution: texels
    outside it do not count)."""
    weight = region.astype(np.float64)
    blurred_weight = np.maximum(ndimage.gaussian_filter(weight, sigma), 1e-6)
    return np.stack([ndimage.gaussian_filter(image[..., channel].astype(np.float64) * weight, sigma) / blurred_weight
                     for channel in range(image.shape[-1])], -1)


def relative_detail(image: np.ndarray, region: np.ndarray, sigma: float = SPECKLE_SIGMA) -> np.ndarray:
    """[Ht, Wt, C]: (X - G X) / G X, G a Gaussian of ``sigma`` texels taken within ``region`` (:func:`local_mean`),
    so the region's edge is not detail."""
    local = local_mean(image, region, sigma)
    return (image - local) / np.maximum(local, 1e-3)


def relative_detail_energy(image: np.ndarray, region: np.ndarray, sigma: float = SPECKLE_SIGMA) -> float:
    """E(X): mean over ``region`` (eroded by 2 texels) of sum_c ((X - G X) / G X)²."""
    energy = (relative_detail(image, region, sigma) ** 2).sum(-1)
    inner = ndimage.binary_erosion(region, iterations=2)
    return float(energy[inner].mean()) if inner.sum() >= MIN_TEXELS else float("nan")


def speckle(diffuse_linear: np.ndarray, photo_in_uv: np.ndarray, region: np.ndarray) -> float:
    """Excess relative detail of a linear diffuse map over the photo read in UV (both [Ht, Wt, 3]), x100."""
    excess = relative_detail_energy(diffuse_linear, region) - relative_detail_energy(photo_in_uv, region)
    return float(100.0 * np.sqrt(max(excess, 0.0))) if np.isfinite(excess) else float("nan")


def detail_ratio(diffuse_linear: np.ndarray, photo_in_uv: np.ndarray, region: np.ndarray) -> float:
    """sqrt(E(map) / E(photo)): the map's fine relative contrast as a share of the photo's at that scale."""
    photo = relative_detail_energy(photo_in_uv, region)
    ratio = relative_detail_energy(diffuse_linear, region) / photo if photo > 0 else float("nan")
    return float(np.sqrt(ratio)) if np.isfinite(ratio) else float("nan")


def chroma_rms(log_ratio: np.ndarray, region: np.ndarray) -> float:
    """RMS over ``region`` of the chroma (:data:`CHROMA_AXES`) of a log-RGB ratio [Ht, Wt, 3], x100."""
    chroma = log_ratio[region] @ CHROMA_AXES.T
    return float(100 * np.sqrt((chroma ** 2).sum(-1).mean())) if region.sum() >= MIN_TEXELS else float("nan")


def edge_fringe(source: np.ndarray, target: np.ndarray, shadow: np.ndarray, region: np.ndarray) -> dict:
    """The module doc's edge fringe of two linear diffuse maps [Ht, Wt, 3] and the shadow read in UV [Ht, Wt]
    (> 0.5 in shadow), over ``region``: {"edge": at the edge, "rest": elsewhere, "fringe": edge - rest}."""
    scale = max(1, round(source.shape[0] / 256))  # the band's texels at 256²
    inside = shadow > 0.5
    band = ndimage.binary_dilation(inside, iterations=EDGE_BAND * scale) & \
        ~ndimage.binary_erosion(inside, iterations=EDGE_BAND * scale) & region
    log_source, log_target = (np.log(np.maximum(m, 1e-3)) for m in (source, target))
    gain = np.median((log_target - log_source)[region], axis=0) if region.any() else 0.0
    ratio = log_source + gain - log_target
    edge, rest = chroma_rms(ratio, band), chroma_rms(ratio, region & ~band)
    return {"edge": edge, "rest": rest, "fringe": edge - rest, "texels": int(band.sum())}
