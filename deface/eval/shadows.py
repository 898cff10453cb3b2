"""Synthetic foreign shadows on clean face photos: the shadow benchmark (source = shadowed, target = clean).

Image model (linear RGB, sRGB decoded with the power law gamma 2.2 of :mod:`deface.io.images`):

    source_c = target_c * (1 - M_c * (1 - keep * tint_c))          c in {R, G, B}

``keep`` in [0.2, 0.6] is the fraction of light left in the umbra (ambient light still reaches it),
``tint_c`` in [0.95, 1] a mild random colour of that ambient light, and ``M_c`` the per-channel matte
(1 = fully shadowed). Since ``M_c, keep * tint_c`` are in [0, 1], the source is never brighter than
the target. This is the foreign-shadow model of Zhang et al. 2020, "Portrait Shadow Manipulation"
(SIGGRAPH), ``I = I_lit * (1 - M) + I_shadow * M``, with their three refinements as we read them:

1. **Penumbra with spatially varying width.** The occluder's hard matte is blurred with a Gaussian
   whose sigma varies smoothly across the face (a linear ramp in a random direction, as if the
   occluder were nearer to the skin on one side): blurs at a few sigma levels are interpolated per pixel.
2. **Subsurface scattering approximation.** Light that enters skin exits a few millimetres away, and
   red light travels furthest. The penumbra matte is blurred once more per channel with a larger
   sigma for red than for green and blue, so shadow edges turn red: inside the shadow edge the red
   matte is lower (more red light bleeds in), outside it slightly higher.
3. **Intensity variation.** The matte is modulated by smooth low-frequency noise (partially
   translucent occluders, foliage).

Occluder shapes: binary silhouettes from a folder (``shared/data/shadow-silhouettes``: white
occluder on black) and procedural shapes (hat brim, leaves, fingers, window blinds), drawn in a
canonical occluder plane around the face and projected by a random homography (rotation, scale,
perspective jitter of the plane's corners, offset). The face is located with MediaPipe (static mode;
the region is the convex hull of the landmarks) or a centred fallback ellipse; samples are redrawn
until the hard shadow covers ``coverage`` (15-50%) of that region. The shadow fades out beyond the
head (``receiver``): the occluder is near the face, so the background (far behind) is not shadowed.

Everything random comes from ``numpy.random.default_rng([seed, crc32(photo stem), k])`` and is
recorded in the manifest, so a benchmark is reproducible bit for bit and independent of photo order.
"""

from __future__ import annotations

import json
import zlib
from dataclasses import asdict, dataclass, field
from pathlib import Path

import cv2
import numpy as np
from PIL import Image

from deface.io.images import linear_to_srgb, load_image, resize_max, srgb_to_linear
from deface.paths import shared_dir

SHAPE_KINDS = ("silhouette", "hat", "leaves", "fingers", "blinds")
EXTRA_KINDS = ("stripes", "dapples")
"""Kinds drawn only when asked (``--kinds``): thin stripes (a fence, a slatted shade) and sun-dapples."""
CANVAS = 1024  # side of the canonical occluder plane raster; the face box spans its central half


@dataclass(frozen=True)
class ShadowConfig:
    """Ranges of the random shadow parameters (each sample draws uniformly within them)."""

    kinds: tuple[str, ...] = SHAPE_KINDS
    """Occluder kinds to draw from (uniformly); "silhouette" needs ``silhouettes``."""
    silhouettes: tuple[str, ...] = ()
    """Paths of silhouette PNGs (white occluder on black); empty = no silhouette kind."""
    coverage: tuple[float, float] = (0.15, 0.5)
    """Accepted fraction of the face region under the hard shadow."""
    keep: tuple[float, float] = (0.2, 0.6)
    """Fraction of the light kept in the umbra."""
    tint: tuple[float, float] = (0.95, 1.0)
    """Per-channel factor of the umbra's remaining (ambient) light."""
    fill: tuple[float, float, float] = (1.0, 1.0, 1.0)
    """Colour of the umbra's remaining light (multiplies ``tint``): (1, 1, 1) neutral; a cool sky fill under a warm
    sun is bluer, e.g. (0.55, 0.75, 1.0)."""
    warm: tuple[float, float] = (0.0, 0.0)
    """Warmth of the key light cast on the whole photo, both sides of the pair (0 none; 1: blue x0.45, green
    x0.75 in linear RGB): strong warm sunlight, whose shadows the cool ``fill`` lights."""
    penumbra: tuple[float, float] = (0.004, 0.035)
    """Penumbra Gaussian sigma as a fraction of the face size (min, max over the face)."""
    sss_sigma: tuple[float, float] = (0.015, 0.035)
    """Subsurface-scattering blur of the red channel, fraction of the face size."""
    sss_green_blue: tuple[float, float] = (0.35, 0.25)
    """Green and blue SSS sigma as fractions of the red one (red scatters furthest in skin)."""
    noise: tuple[float, float] = (0.0, 0.2)
    """Amplitude of the low-frequency intensity variation of the matte."""
    perspective: float = 0.15
    """Max corner jitter of the occluder plane, fraction of the plane's size."""
    receiver: tuple[float, float] = (0.1, 0.35)
    """The shadow falls on the head: full strength up to the first distance from the face region,
    fading to zero at the second (fractions of the face size); the background is taken to be far."""
    max_tries: int = 40
    """Samples drawn per shadow before taking the one closest to the coverage range."""


@dataclass
class ShadowSample:
    """One synthesised pair; arrays are sRGB float32 in [0, 1]."""

    source: np.ndarray  # [H, W, 3] shadowed photo
    target: np.ndarray  # [H, W, 3] clean photo (the input, untouched)
    matte: np.ndarray  # [H, W] shadow matte (channel mean of M_c), 0 = lit, 1 = full shadow
    params: dict = field(default_factory=dict)  # every random parameter, JSON-serialisable


# ----------------------------------------------------------------------------------------- face region


def face_region(image: np.ndarray, use_mediapipe: bool = True) -> tuple[np.ndarray, str]:
    """Bool ``[H, W]`` face region: MediaPipe landmark hull, or a centred ellipse fallback.

    Returns (region, how) with how in {"mediapipe", "fallback"}.
    """
    height, width = image.shape[:2]
    region = np.zeros((height, width), np.uint8)
    if use_mediapipe:
        from deface.landmarks.detect import NoFaceError, detect_landmarks

        try:
            points = detect_landmarks(image).points[:468]  # [468, 2]
            hull = cv2.convexHull(np.round(points).astype(np.int32))
            cv2.fillConvexPoly(region, hull, 1)
            if region.any():
                return region.astype(bool), "mediapipe"
        except NoFaceError:
            pass
    centre = (width // 2, int(height * 0.45))
    axes = (max(1, int(width * 0.25)), max(1, int(height * 0.32)))
    cv2.ellipse(region, centre, axes, 0, 0, 360, 1, -1)
    return region.astype(bool), "fallback"


# ------------------------------------------------------------------------------ occluder shapes (canvas)
# Canvas coordinates: u, v in [-1, 1] (v down); the face box maps to [-0.5, 0.5]^2.


def _px(u: np.ndarray) -> np.ndarray:
    """Canvas coordinates [-1, 1] -> pixel coordinates of the CANVAS raster."""
    return (np.asarray(u, np.float64) + 1.0) * 0.5 * CANVAS


def _poly(canvas: np.ndarray, points_uv: np.ndarray) -> None:
    cv2.fillPoly(canvas, [np.round(_px(points_uv)).astype(np.int32)], 255, lineType=cv2.LINE_AA)


def _ellipse_points(centre, axes, angle: float, n: int = 72) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    local = np.stack([axes[0] * np.cos(t), axes[1] * np.sin(t)], axis=1)
    c, s = np.cos(angle), np.sin(angle)
    return local @ np.array([[c, s], [-s, c]]) + np.asarray(centre)


def _capsule_points(p0, p1, radius: float, n: int = 24) -> np.ndarray:
    """Outline of a capsule (segment p0-p1 thickened by radius, round ends)."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    d = p1 - p0
    angle = np.arctan2(d[1], d[0])
    t0 = np.linspace(angle + np.pi / 2, angle + 3 * np.pi / 2, n)
    t1 = np.linspace(angle - np.pi / 2, angle + np.pi / 2, n)
    cap0 = p0 + radius * np.stack([np.cos(t0), np.sin(t0)], 1)
    cap1 = p1 + radius * np.stack([np.cos(t1), np.sin(t1)], 1)
    return np.concatenate([cap0, cap1])


def _draw_hat(rng: np.random.Generator) -> tuple[np.ndarray, dict]:
    """A hat brim: a wide ellipse whose lower edge crosses the upper face."""
    canvas = np.zeros((CANVAS, CANVAS), np.uint8)
    half_w, half_h = rng.uniform(0.9, 1.6), rng.uniform(0.35, 0.7)
    edge = rng.uniform(-0.35, 0.05)  # v of the brim's lower edge at the face centre
    tilt = rng.uniform(-0.25, 0.25)
    centre = (rng.uniform(-0.2, 0.2), edge - half_h)
    _poly(canvas, _ellipse_points(centre, (half_w, half_h), tilt))
    return canvas, dict(half_width=half_w, half_height=half_h, edge=edge, tilt=tilt, centre=list(centre))


def _leaf_points(centre, length: float, width: float, angle: float, n: int = 20) -> np.ndarray:
    """A pointed leaf (vesica) outline."""
    t = np.linspace(-1, 1, n)
    top = np.stack([t * length / 2, width / 2 * (1 - t**2)], 1)
    bottom = np.stack([t[::-1] * length / 2, -width / 2 * (1 - t[::-1] ** 2)], 1)
    local = np.concatenate([top, bottom])
    c, s = np.cos(angle), np.sin(angle)
    return local @ np.array([[c, s], [-s, c]]) + np.asarray(centre)


def _draw_leaves(rng: np.random.Generator) -> tuple[np.ndarray, dict]:
    """Foliage: a few clusters of leaves and small ellipses (dappled light between them)."""
    canvas = np.zeros((CANVAS, CANVAS), np.uint8)
    clusters = int(rng.integers(1, 4))
    leaves = []
    for _ in range(clusters):
        centre = rng.uniform(-0.5, 0.5, 2)
        for _ in range(int(rng.integers(5, 14))):
            pos = centre + rng.normal(0, 0.18, 2)
            length = rng.uniform(0.18, 0.42)
            width = length * rng.uniform(0.3, 0.55)
            angle = rng.uniform(0, np.pi)
            if rng.random() < 0.15:
                _poly(canvas, _ellipse_points(pos, (length / 3, width / 3), angle))
            else:
                _poly(canvas, _leaf_points(pos, length, width, angle))
            leaves.append([float(pos[0]), float(pos[1]), float(length), float(angle)])
    return canvas, dict(clusters=clusters, leaves=leaves)


def _draw_fingers(rng: np.random.Generator) -> tuple[np.ndarray, dict]:
    """A hand: 3-5 finger capsules reaching in from one side, palm outside the face."""
    canvas = np.zeros((CANVAS, CANVAS), np.uint8)
    count = int(rng.integers(3, 6))
    direction = rng.uniform(0, 2 * np.pi)
    axis = np.array([np.cos(direction), np.sin(direction)])  # from the palm toward the fingertips
    normal = np.array([-axis[1], axis[0]])
    reach = rng.uniform(0.0, 0.45)  # how far fingertips get past the face centre
    radius = rng.uniform(0.05, 0.08)
    gap = radius * rng.uniform(2.1, 2.8)
    palm = -axis * rng.uniform(0.75, 0.95)
    for i in range(count):
        offset = (i - (count - 1) / 2) * gap
        length = rng.uniform(0.55, 0.8) * (1 - 0.15 * abs(i - (count - 1) / 2))
        base = palm + normal * offset
        tip = base + axis * length + axis * reach
        _poly(canvas, _capsule_points(base, tip, radius))
    _poly(canvas, _ellipse_points(palm - axis * 0.2, (0.35, count * gap / 2 + radius), direction))
    return canvas, dict(count=count, direction=direction, reach=reach, radius=radius, gap=gap)


def _bands(canvas: np.ndarray, period: float, duty: float, angle: float, phase: float, count: int) -> None:
    """Draw 2 count + 1 parallel bands of ``duty`` x ``period`` across the plane, at ``angle``."""
    c, s = np.cos(angle), np.sin(angle)
    for k in range(-count, count + 1):
        v0 = k * period + phase
        band = np.array([[-3, v0], [3, v0], [3, v0 + duty * period], [-3, v0 + duty * period]])
        _poly(canvas, band @ np.array([[c, s], [-s, c]]))


def _draw_blinds(rng: np.random.Generator) -> tuple[np.ndarray, dict]:
    """Window blinds: parallel bands across the plane."""
    canvas = np.zeros((CANVAS, CANVAS), np.uint8)
    period = rng.uniform(0.12, 0.3)
    duty = rng.uniform(0.35, 0.6)  # fraction of each period in shadow
    angle = rng.uniform(-0.5, 0.5)
    phase = rng.uniform(0, period)
    _bands(canvas, period, duty, angle, phase, 12)
    # a frame edge: sometimes only part of the plane is behind the blinds
    cut = rng.uniform(-1.0, 1.0) if rng.random() < 0.5 else None
    if cut is not None:
        canvas[:, : int(_px(cut))] = 0
    return canvas, dict(period=period, duty=duty, angle=angle, phase=phase, cut=cut)


def _draw_stripes(rng: np.random.Generator) -> tuple[np.ndarray, dict]:
    """Thin parallel stripes, near vertical (a fence, a slatted shade): many narrow bands across the face."""
    canvas = np.zeros((CANVAS, CANVAS), np.uint8)
    period = rng.uniform(0.08, 0.16)
    duty = rng.uniform(0.25, 0.45)
    angle = np.pi / 2 + rng.uniform(-0.3, 0.3)
    phase = rng.uniform(0, period)
    _bands(canvas, period, duty, angle, phase, 60)
    return canvas, dict(period=period, duty=duty, angle=angle, phase=phase)


def _draw_dapples(rng: np.random.Generator) -> tuple[np.ndarray, dict]:
    """Sun through foliage: shade with many small round and oval gaps of light."""
    canvas = np.full((CANVAS, CANVAS), 255, np.uint8)
    count = int(rng.integers(25, 60))
    gaps = []
    for _ in range(count):
        centre = rng.uniform(-0.9, 0.9, 2)
        radius = rng.uniform(0.03, 0.12)
        axes = (radius, radius * rng.uniform(0.5, 1.0))
        points = _ellipse_points(centre, axes, rng.uniform(0, np.pi))
        cv2.fillPoly(canvas, [np.round(_px(points)).astype(np.int32)], 0)
        gaps.append([float(centre[0]), float(centre[1]), float(radius)])
    return canvas, dict(gaps=gaps)


def _draw_silhouette(rng: np.random.Generator, paths: tuple[str, ...]) -> tuple[np.ndarray, dict]:
    """A silhouette file placed with a random scale, rotation and offset."""
    path = paths[int(rng.integers(len(paths)))]
    sil = np.asarray(Image.open(path).convert("L"), np.float32)
    scale = rng.uniform(0.8, 2.0) * CANVAS / max(sil.shape)
    angle = rng.uniform(0, 360)
    offset = rng.uniform(-0.35, 0.35, 2) * CANVAS
    centre = (sil.shape[1] / 2, sil.shape[0] / 2)
    affine = cv2.getRotationMatrix2D(centre, angle, scale)
    affine[:, 2] += np.array([CANVAS / 2, CANVAS / 2]) - np.array(centre) + offset
    canvas = cv2.warpAffine(sil, affine, (CANVAS, CANVAS), flags=cv2.INTER_LINEAR)
    params = dict(file=Path(path).name, scale=scale, angle=angle, offset=(offset / CANVAS).tolist())
    return np.clip(canvas, 0, 255).astype(np.uint8), params


def shared_silhouettes() -> Path | None:
    """The shared silhouettes folder (``../shared/data/shadow-silhouettes``), or None where it is absent."""
    shared = shared_dir()
    folder = shared / "data" / "shadow-silhouettes" if shared else None
    return folder if folder is not None and folder.is_dir() else None


def silhouette_files(folder: Path | None) -> tuple[str, ...]:
    """The silhouette PNGs of ``folder`` in name order (none without a folder)."""
    return tuple(str(p) for p in sorted(folder.glob("*.png"))) if folder else ()


def draw_occluder(
    kind: str, rng: np.random.Generator, silhouettes: tuple[str, ...] = ()
) -> tuple[np.ndarray, dict]:
    """Raster ``[CANVAS, CANVAS]`` uint8 (255 = occluder) of one occluder kind in the canonical plane."""
    if kind == "hat":
        return _draw_hat(rng)
    if kind == "leaves":
        return _draw_leaves(rng)
    if kind == "fingers":
        return _draw_fingers(rng)
    if kind == "blinds":
        return _draw_blinds(rng)
    if kind == "stripes":
        return _draw_stripes(rng)
    if kind == "dapples":
        return _draw_dapples(rng)
    if kind == "silhouette":
        if not silhouettes:
            raise ValueError("occluder kind 'silhouette' needs silhouette files (ShadowConfig.silhouettes)")
        return _draw_silhouette(rng, silhouettes)
    raise ValueError(f"unknown occluder kind {kind!r}; choose from {', '.join(SHAPE_KINDS + EXTRA_KINDS)}")


# --------------------------------------------------------------------------------------- projection


def _face_box(region: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre (x, y) and size (max side, pixels) of the face region's bounding box."""
    rows, cols = np.nonzero(region)
    centre = np.array([(cols.min() + cols.max() + 1) / 2, (rows.min() + rows.max() + 1) / 2])
    size = float(max(cols.max() + 1 - cols.min(), rows.max() + 1 - rows.min()))
    return centre, size


def random_homography(rng: np.random.Generator, centre: np.ndarray, size: float, jitter: float) -> tuple:
    """Canvas pixels -> image pixels: the plane's [-1, 1]^2 on 2x the face box, rotated, scaled, offset,
    with its four corners jittered (perspective). Returns (H [3, 3], params)."""
    angle = rng.uniform(-0.4, 0.4)
    scale = rng.uniform(0.8, 1.3)
    offset = rng.uniform(-0.3, 0.3, 2)
    corners_uv = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], np.float64)
    moved = corners_uv + rng.uniform(-jitter, jitter, (4, 2)) * 2
    c, s = np.cos(angle), np.sin(angle)
    dst = (moved @ np.array([[c, s], [-s, c]]) + offset) * scale * size + centre  # face box = [-0.5, 0.5]
    matrix = cv2.getPerspectiveTransform(_px(corners_uv).astype(np.float32), dst.astype(np.float32))
    params = dict(angle=angle, scale=scale, offset=offset.tolist(), corners=dst.tolist())
    return matrix, params


# -------------------------------------------------------------------------------- matte and shading


def _smooth_noise(rng: np.random.Generator, shape: tuple[int, int], sigma: float) -> np.ndarray:
    """Low-frequency noise in [0, 1]: blurred white noise rescaled."""
    small = max(4, int(max(shape) / max(sigma, 1.0)))
    noise = rng.random((small, small)).astype(np.float32)
    noise = cv2.resize(noise, (shape[1], shape[0]), interpolation=cv2.INTER_CUBIC)
    noise = cv2.GaussianBlur(noise, (0, 0), sigma / 2)
    lo, hi = noise.min(), noise.max()
    return (noise - lo) / max(hi - lo, 1e-6)


def varying_blur(matte: np.ndarray, sigma_map: np.ndarray, levels: int = 5) -> np.ndarray:
    """Blur ``[H, W]`` with a per-pixel Gaussian sigma (``[H, W]``, px): fixed-sigma blurs interpolated."""
    lo, hi = float(sigma_map.min()), float(sigma_map.max())
    sigmas = np.linspace(lo, hi, levels) if hi > lo else np.array([lo])
    stack = np.stack([cv2.GaussianBlur(matte, (0, 0), max(s, 0.3)) for s in sigmas])  # [L, H, W]
    if len(sigmas) == 1:
        return stack[0]
    pos = (sigma_map - lo) / (hi - lo) * (len(sigmas) - 1)
    i0 = np.clip(np.floor(pos).astype(int), 0, len(sigmas) - 2)
    w = (pos - i0).astype(np.float32)
    rows, cols = np.indices(matte.shape)
    return (1 - w) * stack[i0, rows, cols] + w * stack[i0 + 1, rows, cols]


def shade(target_srgb: np.ndarray, matte_rgb: np.ndarray, keep: float, tint: np.ndarray) -> np.ndarray:
    """Apply a shadow in linear RGB: ``target * (1 - M_c (1 - keep tint_c))``; sRGB in, sRGB out."""
    linear = srgb_to_linear(target_srgb)
    attenuation = 1.0 - matte_rgb * (1.0 - keep * np.asarray(tint, np.float32))  # [H, W, 3]
    return linear_to_srgb(linear * attenuation)


WARM_GAIN = np.array([0.0, 0.25, 0.55], np.float32)  # per unit of warmth, the linear gain lost per channel


def warm_light(image_srgb: np.ndarray, warmth: float) -> np.ndarray:
    """The photo under a warmer key light: linear RGB times (1, 1 - 0.25 w, 1 - 0.55 w); sRGB in and out."""
    if warmth == 0:
        return image_srgb
    return linear_to_srgb(srgb_to_linear(image_srgb) * (1.0 - warmth * WARM_GAIN))


def receiver_weight(region: np.ndarray, size: float, falloff: tuple[float, float]) -> np.ndarray:
    """``[H, W]`` weight: 1 near the face region, 0 beyond ``falloff[1] * size`` from it."""
    outside = (~region).astype(np.uint8)
    distance = cv2.distanceTransform(outside, cv2.DIST_L2, 5) / size  # 0 inside the region
    t = np.clip((distance - falloff[0]) / max(falloff[1] - falloff[0], 1e-6), 0.0, 1.0)
    return (1.0 - t * t * (3 - 2 * t)).astype(np.float32)  # smoothstep


def _sample_hard_matte(rng, config: ShadowConfig, region: np.ndarray) -> tuple[np.ndarray, dict]:
    """Draw occluders + homographies until the hard shadow covers ``config.coverage`` of the region."""
    height, width = region.shape
    centre, size = _face_box(region)
    best = None
    kind = config.kinds[int(rng.integers(len(config.kinds)))]  # once: retries must not favour easy kinds
    for attempt in range(config.max_tries):
        canvas, shape_params = draw_occluder(kind, rng, config.silhouettes)
        matrix, proj_params = random_homography(rng, centre, size, config.perspective)
        plane = canvas.astype(np.float32) / 255
        hard = cv2.warpPerspective(plane, matrix, (width, height), flags=cv2.INTER_LINEAR)
        coverage = float((hard[region] > 0.5).mean())
        lo, hi = config.coverage
        miss = max(lo - coverage, coverage - hi, 0.0)
        params = dict(kind=kind, shape=shape_params, projection=proj_params, coverage=coverage)
        params["attempt"] = attempt
        if best is None or miss < best[0]:
            best = (miss, hard, params)
        if miss == 0.0:
            break
    return best[1], best[2]


def synthesize_shadow(
    target: np.ndarray, region: np.ndarray, rng: np.random.Generator, config: ShadowConfig = ShadowConfig()
) -> ShadowSample:
    """Cast one random foreign shadow on ``target`` ([H, W, 3] sRGB in [0, 1]) over the bool face region."""
    if target.ndim != 3 or target.shape[2] != 3:
        raise ValueError(f"target must be [H, W, 3], got {target.shape}")
    if region.shape != target.shape[:2] or not region.any():
        raise ValueError("face region must be a non-empty [H, W] mask matching the image")
    height, width = region.shape
    hard, params = _sample_hard_matte(rng, config, region)
    centre, size = _face_box(region)
    hard = hard * receiver_weight(region, size, config.receiver)

    # 1. penumbra: sigma ramps linearly across the face in a random direction
    pen = sorted(rng.uniform(*config.penumbra, 2) * size)
    direction = rng.uniform(0, 2 * np.pi)
    ys, xs = np.indices((height, width), dtype=np.float32)
    along = ((xs - centre[0]) * np.cos(direction) + (ys - centre[1]) * np.sin(direction)) / size + 0.5
    sigma_map = pen[0] + (pen[1] - pen[0]) * np.clip(along, 0, 1)
    soft = varying_blur(hard, sigma_map.astype(np.float32))

    # 3. intensity variation (before SSS: the light reaching the skin varies, then scatters)
    noise_amp = rng.uniform(*config.noise)
    soft = soft * (1 - noise_amp * _smooth_noise(rng, (height, width), 0.15 * size))

    # 2. subsurface scattering: extra per-channel blur, widest for red
    sss_red = rng.uniform(*config.sss_sigma) * size
    sss = (sss_red, sss_red * config.sss_green_blue[0], sss_red * config.sss_green_blue[1])
    matte_rgb = np.stack([cv2.GaussianBlur(soft, (0, 0), max(s, 0.3)) for s in sss], axis=-1)
    matte_rgb = np.clip(matte_rgb, 0.0, 1.0).astype(np.float32)

    keep = rng.uniform(*config.keep)
    tint = rng.uniform(*config.tint, 3) * np.asarray(config.fill)
    warmth = rng.uniform(*config.warm)
    target = warm_light(target, warmth)
    source = shade(target, matte_rgb, keep, tint)
    params.update(
        penumbra_sigma_px=[float(p) for p in pen],
        penumbra_direction=direction,
        noise_amplitude=noise_amp,
        sss_sigma_px=[float(s) for s in sss],
        keep=keep,
        tint=tint.tolist(),
        warmth=warmth,
        face_size_px=size,
    )
    return ShadowSample(source=source, target=target, matte=matte_rgb.mean(axis=-1), params=params)


# ----------------------------------------------------------------------------------------- benchmark


def sample_rng(seed: int, stem: str, index: int) -> np.random.Generator:
    """The generator of one sample: depends on (seed, photo stem, index) only, not on photo order."""
    return np.random.default_rng([seed, zlib.crc32(stem.encode()), index])


def _save_png(path: Path, image: np.ndarray) -> None:
    array = np.clip(np.rint(np.asarray(image) * 255), 0, 255).astype(np.uint8)
    Image.fromarray(array).save(path, format="PNG", optimize=False)


def make_shadow_benchmark(
    photos: list[Path],
    out_dir: Path,
    seed: int = 0,
    per_photo: int = 1,
    max_size: int = 512,
    use_mediapipe: bool = True,
    config: ShadowConfig = ShadowConfig(),
) -> dict:
    """Write ``out_dir/<stem>-<k>/{source,target,shadow_mask}.png`` and ``out_dir/manifest.json``.

    Photos are shrunk to ``max_size`` (longest side; never enlarged). Returns the manifest dict.
    """
    if not photos:
        raise ValueError("make_shadow_benchmark: no photos given")
    if per_photo < 1:
        raise ValueError(f"per_photo must be >= 1, got {per_photo}")
    stems = [Path(p).stem for p in photos]
    if len(set(stems)) != len(stems):
        raise ValueError("make_shadow_benchmark: two photos share a file stem; pair names would collide")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    pairs = []
    for photo in sorted(photos, key=lambda p: Path(p).stem):
        target, _ = resize_max(load_image(photo), max_size)
        target = np.clip(np.rint(target * 255), 0, 255).astype(np.float32) / 255  # what target.png holds
        region, how = face_region(target, use_mediapipe)
        for k in range(per_photo):
            name = f"{Path(photo).stem}-{k:02d}"
            sample = synthesize_shadow(target, region, sample_rng(seed, Path(photo).stem, k), config)
            pair_dir = out_dir / name
            pair_dir.mkdir(exist_ok=True)
            _save_png(pair_dir / "source.png", sample.source)
            _save_png(pair_dir / "target.png", sample.target)
            _save_png(pair_dir / "shadow_mask.png", sample.matte)
            pairs.append(dict(name=name, photo=Path(photo).name, face_region=how, size=list(target.shape[:2]),
                              **sample.params))
    config_dict = asdict(config)
    config_dict["silhouettes"] = [Path(p).name for p in config.silhouettes]
    manifest = dict(seed=seed, per_photo=per_photo, max_size=max_size, config=config_dict, pairs=pairs)
    (out_dir / "manifest.json").write_text(json.dumps(manifest, indent=2, default=float) + "\n")
    return manifest
