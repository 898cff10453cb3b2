"""The face-region classifier h that g is distilled from (L_seg), and the project's offline default.

Every classifier follows :class:`FaceRegionClassifier`: ``h = classifier(image, coverage, landmarks)`` with
image [H, W, 3] sRGB in [0, 1], coverage M_R [H, W] of the fitted face (or any rough face mask), optional 2D
landmarks [N, 2] (x, y pixels), returning h [H, W] float32 in [0, 1] (numpy; h is computed once per image).

The authors used a pretrained BiSeNet parser (:class:`deface.priors.bisenet.BiSeNetFaceParser`), whose weights
are not available offline. The default here, :class:`SkinColourClassifier`, needs no weights:

1. region: pixels with coverage > 0.5 (intersected with the landmarks' convex hull when landmarks are given);
2. features: brows, eyes, nose (nostrils) and lips, as the convex hulls of their landmarks (MediaPipe 468/478
   or iBUG 68 layouts), dilated, optionally united with a projected model mask; they always count as face;
3. skin colour model: a Gaussian in linear-RGB chromaticity (r, g) = (R, G) / (R + G + B), fitted on a
   robust core = region minus features, eroded, without near-black or clipped pixels, trimmed in two passes
   around the median. Chromaticity is unchanged when intensity is scaled, so a shadowed skin pixel keeps
   the chroma of lit skin (up to the colour of the shadow's ambient light, which the trimmed spread absorbs);
4. h = logistic(threshold - Mahalanobis distance) inside the region. A pixel with one or two clipped channels
   (the red of a light skin in a warm key light) only says those channels are at least what it shows: its
   distance is the smallest over every value they may have had (:func:`clipped_chroma_distance`), so key-lit
   skin stays face. Dark pixels, whose chroma is noise, and pixels clipped in every channel (a highlight, a
   lamp) take the median of h around them; then a median filter, a morphological closing and opening of the
   binary part, and a small Gaussian blur.

Limits: colour only. Hair, beards, hats or hands whose chroma is close to skin (blond or auburn hair, skin
coloured fabric) are kept as face; very dark regions (deep shadow next to black hair) are judged from their
surroundings; strongly coloured light (a red lamp on half the face) shifts chroma beyond the skin model; the
region never extends beyond the coverage. Thin dark structures (glasses frames, strands of hair) and tinted lenses
are found by their shape (deface/priors/occluders.py) and left out, and so are the openings between the inner lips
and between the lids (``mouth_opening``, ``eye_opening``): not the face's surface.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Protocol

import cv2
import numpy as np
from scipy import ndimage

from deface.io.images import LUMINANCE
from deface.priors.occluders import OccluderConfig, disk, find_occluders

# Feature landmark groups (indices into MediaPipe's 468/478-point face mesh, from its connection lists).
MEDIAPIPE_FEATURES = {
    "lips": (0, 13, 14, 17, 37, 39, 40, 61, 78, 80, 81, 82, 84, 87, 88, 91, 95, 146, 178, 181, 185, 191, 267,
             269, 270, 291, 308, 310, 311, 312, 314, 317, 318, 321, 324, 375, 402, 405, 409, 415),
    "left_eye": (249, 263, 362, 373, 374, 380, 381, 382, 384, 385, 386, 387, 388, 390, 398, 466),
    "right_eye": (7, 33, 133, 144, 145, 153, 154, 155, 157, 158, 159, 160, 161, 163, 173, 246),
    "left_brow": (276, 282, 283, 285, 293, 295, 296, 300, 334, 336),
    "right_brow": (46, 52, 53, 55, 63, 65, 66, 70, 105, 107),
    "nostrils": (1, 2, 4, 5, 19, 45, 48, 64, 94, 97, 98, 115, 220, 275, 278, 294, 326, 327, 344, 440),
}  # fmt: skip
MEDIAPIPE_FACE_OVAL = (10, 21, 54, 58, 67, 93, 103, 109, 127, 132, 136, 148, 149, 150, 152, 162, 172, 176, 234, 251,
                       284, 288, 297, 323, 332, 338, 356, 361, 365, 377, 378, 379, 389, 397, 400, 454)
MEDIAPIPE_NOSE_BASE = (2, 98, 327)  # subnasale and the alae's bases: the beard zone's top
MEDIAPIPE_CHIN = 152
MEDIAPIPE_LID_MARGINS = ((33, 7, 163, 144, 145, 153, 154, 155, 133, 173, 157, 158, 159, 160, 161, 246),
                         (263, 249, 390, 373, 374, 380, 381, 382, 362, 398, 384, 385, 386, 387, 388, 466))
"""Each eye's contour along its lid margins, in order round the opening (the right eye's, then the left's)."""
MEDIAPIPE_INNER_LIPS = (78, 191, 80, 81, 82, 13, 312, 311, 310, 415, 308, 324, 318, 402, 317, 14, 87, 178, 88, 95)
"""The inner lip contour in order around the mouth's opening (the corners 61 and 291 are on the outer one)."""
IBUG68_FEATURES = {
    "left_brow": tuple(range(17, 22)),
    "right_brow": tuple(range(22, 27)),
    "nostrils": tuple(range(30, 36)),
    "left_eye": tuple(range(36, 42)),
    "right_eye": tuple(range(42, 48)),
    "lips": tuple(range(48, 68)),
}


class FaceRegionClassifier(Protocol):
    """h(image [H, W, 3] sRGB in [0, 1], coverage [H, W], landmarks [N, 2] | None) -> [H, W] in [0, 1]."""

    def __call__(self, image, coverage, landmarks=None) -> np.ndarray: ...


@dataclass(frozen=True)
class SkinClassifierConfig:
    """Knobs of the colour-based face-region classifier (sizes are fractions of the face box's diagonal)."""

    threshold: float = 3.5
    """Mahalanobis distance (in chroma) at which h = 0.5."""
    softness: float = 0.6
    """Width of the logistic transition of h in Mahalanobis units."""
    chroma_floor: float = 0.012
    """Minimum standard deviation of the chroma model (camera noise, compression)."""
    dark_luma: float = 0.015
    """Linear luminance under which chroma is unreliable and h is taken from the neighbourhood."""
    bright_value: float = 0.98
    """sRGB channel value above which a pixel counts as clipped (excluded from the colour fit)."""
    feature_dilation: float = 0.03
    """Dilation of the feature hulls (brows/eyes/nose/lips)."""
    core_erosion: float = 0.03
    """Erosion of the region before fitting the colour model (keeps boundary pixels out)."""
    trim_sigmas: float = 2.5
    """Robust trimming of the core's chroma, in MAD-based standard deviations."""
    smoothing: float = 0.015
    """Median filter size / blur sigma for the final map."""
    beard_zone: bool = True
    """The face below the nose's base within the face's outline (where beards and moustaches grow) is face
    whatever its colour, as face parsers label a beard skin: its albedo is the person's (deface/priors/
    shading_evidence.py keeps its texture from pulling stage 2's lights; docs/textures.md "The person's
    detail"). MediaPipe landmarks only. Off in ``paper``."""
    hull_margin: float = 0.06
    """The landmarks' convex hull, which bounds h, grows by this share of the face box's diagonal (0: 2 pixels). The
    hull of MediaPipe's points stops short of the hairline and the jaw's sides; the skin model, not the hull, is
    then what sets the face's edge there (docs/textures.md "The person's detail"; 0 in ``paper``)."""
    enclosed_area: float = 0.06
    """Non-skin patches enclosed by skin, each up to this share of the face region, are face: moles, freckles,
    a birthmark, a moustache or goatee, make-up. They lie on the face's surface (face parsers label them skin),
    while what occludes the face (hair, a hand, a hat, glasses' arms) reaches in from its border."""
    mouth_opening: bool = True
    """The opening between the inner lips (teeth, tongue, the mouth's dark inside) is not face: it is not the face's
    surface, and a fit whose mouth is less open than the photo's would paint the teeth onto the lips' texels, which
    completion fills instead. MediaPipe landmarks only; with BiSeNet, its mouth class leaves h. Off in ``paper``
    (its parser counts the mouth as face)."""
    eye_opening: bool = True
    """The openings between the lids (the white of the eye, the iris, the pink inner corner, the lower lid's wet rim)
    are not face: they are not the skin's surface, and a fit whose lids sit a little off the photo's would paint
    them onto the lids' texels as red, white or dark streaks, which completion fills instead. The lashes, on the
    lid margins, stay. MediaPipe landmarks only; with BiSeNet, its eye classes leave h. Off in ``paper``."""
    occluders: OccluderConfig = OccluderConfig()
    """Thin, long, dark structures (a glasses frame, a strand of hair, a thin stripe of shade) and the tinted lenses
    a frame encloses are left out, enclosed by skin or not (deface/priors/occluders.py). MediaPipe landmarks
    only."""


def _as_numpy(array, dtype=np.float32) -> np.ndarray:
    if hasattr(array, "detach"):
        array = array.detach().cpu().numpy()
    return np.asarray(array, dtype=dtype)


def _hull_mask(points: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    mask = np.zeros(shape, np.uint8)
    if len(points) >= 3:
        hull = cv2.convexHull(np.round(points).astype(np.int32))
        cv2.fillConvexPoly(mask, hull, 1)
    return mask.astype(bool)


def beard_zone_mask(landmarks: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """[H, W] bool: the convex hull of the face outline's points below the nose's base and the base itself
    (MediaPipe 468/478 layout; empty for others)."""
    if landmarks.shape[0] not in (468, 478):
        return np.zeros(shape, bool)
    base = landmarks[list(MEDIAPIPE_NOSE_BASE)]
    oval = landmarks[list(MEDIAPIPE_FACE_OVAL)]
    lower = oval[oval[:, 1] > base[:, 1].max()]
    return _hull_mask(np.concatenate([base, lower]), shape)


def beard_reach_mask(landmarks: np.ndarray, shape: tuple[int, int], margin: int) -> np.ndarray:
    """[H, W] bool: the beard zone grown by ``margin`` pixels on the chin's side of the line through the alae's
    bases (a beard grows past the face outline's points onto the jaw's underside; not up onto the cheeks)."""
    zone = beard_zone_mask(landmarks, shape)
    if not zone.any() or margin < 1:
        return zone
    grown = cv2.dilate(zone.astype(np.uint8), disk(margin)).astype(bool)
    left, right = landmarks[MEDIAPIPE_NOSE_BASE[1]], landmarks[MEDIAPIPE_NOSE_BASE[2]]
    normal = np.array([left[1] - right[1], right[0] - left[0]])  # perpendicular to the alae's line
    normal *= np.sign(normal @ (landmarks[MEDIAPIPE_CHIN] - left)) or 1.0
    ys, xs = np.mgrid[: shape[0], : shape[1]]
    below = (xs - left[0]) * normal[0] + (ys - left[1]) * normal[1] >= 0
    return zone | (grown & below)


def hair_zone_mask(landmarks: np.ndarray, shape: tuple[int, int], margin: int, reach: int) -> np.ndarray:
    """[H, W] bool: where a face has fine texture of its own: the brows, eyes (lashes), nostrils and lips grown by
    ``margin`` pixels, and the beard's reach grown by ``reach`` (MediaPipe 468/478 layout; features only for
    iBUG-68)."""
    return feature_mask_from_landmarks(landmarks, shape, margin) | beard_reach_mask(landmarks, shape, reach)


def mouth_opening_mask(landmarks: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """[H, W] bool: the polygon of the inner lip contour, the mouth's opening (empty when the mouth is closed and
    for layouts other than MediaPipe's 468/478)."""
    return _openings(landmarks, shape, (MEDIAPIPE_INNER_LIPS,))


def eye_openings_mask(landmarks: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """[H, W] bool: the polygons of the two lid margins, the eyes' openings (empty when the eyes are closed and for
    layouts other than MediaPipe's 468/478)."""
    return _openings(landmarks, shape, MEDIAPIPE_LID_MARGINS)


def _openings(landmarks: np.ndarray, shape: tuple[int, int], contours: tuple[tuple[int, ...], ...]) -> np.ndarray:
    """[H, W] bool: the filled polygons of MediaPipe's ``contours`` (index lists in order); empty for other layouts."""
    mask = np.zeros(shape, np.uint8)
    if landmarks.shape[0] in (468, 478):
        cv2.fillPoly(mask, [np.round(landmarks[list(contour)]).astype(np.int32) for contour in contours], 1)
    return mask.astype(bool)


def feature_mask_from_landmarks(landmarks: np.ndarray, shape: tuple[int, int], dilation: int) -> np.ndarray:
    """Union of the dilated convex hulls of brows, eyes, nostrils and lips (MediaPipe or iBUG-68 layouts)."""
    count = landmarks.shape[0]
    groups = MEDIAPIPE_FEATURES if count in (468, 478) else IBUG68_FEATURES if count == 68 else {}
    mask = np.zeros(shape, bool)
    for indices in groups.values():
        mask |= _hull_mask(landmarks[list(indices)], shape)
    if mask.any() and dilation > 0:
        mask = cv2.dilate(mask.astype(np.uint8), disk(dilation)).astype(bool)
    return mask


def chromaticity(linear: np.ndarray) -> np.ndarray:
    """[..., 3] linear RGB -> [..., 2] (r, g) = (R, G) / (R + G + B)."""
    total = linear.sum(axis=-1, keepdims=True)
    return linear[..., :2] / np.maximum(total, 1e-6)


def _robust_gaussian(samples: np.ndarray, trim_sigmas: float, floor: float) -> tuple[np.ndarray, np.ndarray]:
    """Mean [2] and covariance [2, 2] of samples [N, 2] after two median/MAD trimming passes."""
    kept = samples
    for _ in range(2):
        centre = np.median(kept, axis=0)
        scale = 1.4826 * np.median(np.abs(kept - centre), axis=0) + 1e-6
        inside = (((kept - centre) / scale) ** 2).sum(axis=1) <= trim_sigmas**2 * 2
        if inside.sum() >= 10:
            kept = kept[inside]
    mean = kept.mean(axis=0)
    covariance = np.cov(kept.T) + np.eye(2) * floor**2
    return mean, covariance


def _mahalanobis(chroma: np.ndarray, mean: np.ndarray, precision: np.ndarray) -> np.ndarray:
    """[...] distance of chroma [..., 2] from a Gaussian's ``mean`` [2] with inverse covariance ``precision``."""
    offset = chroma - mean
    return np.sqrt(np.maximum(np.einsum("...i,ij,...j->...", offset, precision, offset), 0.0))


CLIP_HEADROOM = 16.0
"""Most a clipped channel's true value may exceed what the pixel shows (four stops)."""


def clipped_chroma_distance(linear: np.ndarray, clipped: np.ndarray, mean: np.ndarray,
                            precision: np.ndarray) -> np.ndarray:
    """[N]: the smallest Mahalanobis distance from the skin model (``mean`` [2], ``precision`` [2, 2]) of pixels
    ``linear`` [N, 3] whose ``clipped`` [N, 3] channels may have been any value from the one shown up to
    ``CLIP_HEADROOM`` times it, each independently: a clipped channel is a lower bound, the others are exact, so
    a pixel is skin when some value of its clipped channels gives skin's chroma."""
    best = np.full(len(linear), np.inf)
    for pattern in np.unique(clipped, axis=0):
        chosen = np.flatnonzero((clipped == pattern).all(-1))
        best[chosen] = _closest_over_clipped(linear[chosen], pattern, mean, precision)
    return best


def _closest_over_clipped(linear: np.ndarray, pattern: np.ndarray, mean: np.ndarray,
                          precision: np.ndarray) -> np.ndarray:
    """[N]: :func:`clipped_chroma_distance` for pixels clipped in the same channels ``pattern`` [3]: a grid of
    factors, even in log space, then a finer grid around each pixel's best."""
    step = np.log(CLIP_HEADROOM) / 24
    logs, best = np.zeros(linear.shape), np.full(len(linear), np.inf)
    for offsets in (np.arange(25) * step, np.linspace(-1.0, 1.0, 9) * step):
        axes = [offsets if flag else np.zeros(1) for flag in pattern]
        start = logs.copy()
        for offset in np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3):
            trial = np.clip(start + offset, 0.0, np.log(CLIP_HEADROOM))
            distance = _mahalanobis(chromaticity(linear * np.exp(trial)), mean, precision)
            better = distance < best
            best, logs[better] = np.where(better, distance, best), trial[better]
    return best


def enclosed_patches(skin: np.ndarray, region: np.ndarray, largest: float) -> np.ndarray:
    """[H, W] bool: the non-skin patches inside ``region`` that skin encloses (touching neither the region's border
    nor its outside), each at most ``largest`` times the region's area."""
    holes = ndimage.binary_fill_holes(skin) & ~skin & region
    labels, count = ndimage.label(holes)
    if count == 0:
        return holes
    areas = ndimage.sum_labels(holes, labels, index=np.arange(1, count + 1))
    small = np.concatenate([[False], areas <= largest * region.sum()])
    return small[labels]


class SkinColourClassifier:
    """Offline h: skin-chroma Gaussian fitted on the face itself, landmark features kept (see module doc)."""

    def __init__(self, config: SkinClassifierConfig | None = None):
        self.config = config or SkinClassifierConfig()

    def __call__(self, image, coverage, landmarks=None, features=None) -> np.ndarray:
        """h [H, W] float32. ``features``: optional [H, W] mask of projected model features kept as face."""
        return self.with_occluders(image, coverage, landmarks, features)[0]

    def with_occluders(self, image, coverage, landmarks=None, features=None) -> tuple[np.ndarray, np.ndarray | None]:
        """(h, what the occluder finder left out of it [H, W] bool, None when it did not look): the fit says how
        much of the face the second covers."""
        cfg = self.config
        srgb = np.clip(_as_numpy(image), 0.0, 1.0)
        if srgb.ndim != 3 or srgb.shape[-1] != 3:
            raise ValueError(f"image must be [H, W, 3] sRGB in [0, 1], got shape {srgb.shape}")
        shape = srgb.shape[:2]
        region = _as_numpy(coverage) > 0.5
        if region.shape != shape:
            raise ValueError(f"coverage {region.shape} must match the image {shape}")
        points = None if landmarks is None else _as_numpy(landmarks, np.float64)[:, :2]
        if points is not None and points.shape[0] >= 3:
            hull = _hull_mask(points, shape)
            margin = cfg.hull_margin * float(np.hypot(*np.ptp(points, axis=0))) if cfg.hull_margin > 0 else 2
            region &= cv2.dilate(hull.astype(np.uint8), disk(round(margin))).astype(bool)
        if region.sum() < 20:
            raise ValueError("the face region (coverage, landmarks) holds fewer than 20 pixels")
        ys, xs = np.nonzero(region)
        diagonal = float(np.hypot(ys.max() - ys.min() + 1, xs.max() - xs.min() + 1))

        feature = np.zeros(shape, bool)
        if points is not None:
            feature |= feature_mask_from_landmarks(points, shape, round(cfg.feature_dilation * diagonal))
        if features is not None:
            feature |= _as_numpy(features) > 0.5
        feature &= region
        beard = beard_zone_mask(points, shape) & region if cfg.beard_zone and points is not None else None
        mediapipe = points is not None and points.shape[0] in (468, 478)

        linear = srgb**2.2
        luma = linear @ LUMINANCE.astype(np.float32)
        clipped = srgb >= cfg.bright_value  # [H, W, 3]
        reliable = (luma > cfg.dark_luma) & ~clipped.any(axis=-1)
        core = cv2.erode((region & ~feature).astype(np.uint8), disk(round(cfg.core_erosion * diagonal)))
        core = core.astype(bool) & reliable
        if core.sum() < 20:  # tiny faces: fall back on the whole region
            core = region & reliable & ~feature
        if core.sum() < 20:
            raise ValueError("too few well-exposed skin pixels to fit a colour model")
        chroma = chromaticity(linear)
        mean, covariance = _robust_gaussian(chroma[core], cfg.trim_sigmas, cfg.chroma_floor)
        precision = np.linalg.inv(covariance)
        distance = _mahalanobis(chroma, mean, precision)
        partly = region & (luma > cfg.dark_luma) & clipped.any(axis=-1) & ~clipped.all(axis=-1)
        distance[partly] = clipped_chroma_distance(linear[partly], clipped[partly], mean, precision)
        reliable |= partly
        skin = 1.0 / (1.0 + np.exp((distance - cfg.threshold) / cfg.softness))
        found = self._occluders(srgb, region, points, diagonal) if cfg.occluders.enabled and mediapipe else None
        left_out = [] if found is None else [found]
        if cfg.mouth_opening and mediapipe:  # grown by a pixel: the opening's soft edge
            left_out.append(cv2.dilate(mouth_opening_mask(points, shape).astype(np.uint8), disk(1)).astype(bool))
        if cfg.eye_opening and mediapipe:  # not grown: the lashes on the margins are the person's
            left_out.append(eye_openings_mask(points, shape))
        occluders = np.logical_or.reduce(left_out) if left_out else None

        size = max(3, int(round(cfg.smoothing * diagonal)) | 1)
        skin = np.where(region, skin, 0.0).astype(np.float32)
        neighbourhood = cv2.medianBlur((skin * 255).astype(np.uint8), min(size * 3 | 1, 255)) / 255.0
        skin = np.where(reliable, skin, neighbourhood)
        skin = cv2.medianBlur((skin * 255).astype(np.uint8), size) / 255.0
        skin = np.maximum(skin, feature.astype(np.float32))
        skin = np.maximum(skin, enclosed_patches(skin > 0.5, region, cfg.enclosed_area).astype(np.float32))
        if beard is not None:
            skin = np.maximum(skin, beard.astype(np.float32))
        binary = (skin > 0.5).astype(np.uint8)
        kernel = disk(size // 2)
        cleaned = cv2.morphologyEx(cv2.morphologyEx(binary, cv2.MORPH_CLOSE, kernel), cv2.MORPH_OPEN, kernel)
        # keep the soft values where the cleaning agreed, the cleaned decision elsewhere
        skin = np.where(cleaned.astype(bool) == binary.astype(bool), skin, cleaned.astype(np.float32))
        if occluders is not None:  # after the cleaning, whose closing would fill a thin frame or a mouth back in
            skin = np.where(occluders, 0.0, skin)
        skin = cv2.GaussianBlur(skin.astype(np.float32), (0, 0), sigmaX=max(0.5, size / 3))
        if occluders is not None:  # and after the blur: a frame's pixels at half weight painted a trace of it
            skin = np.where(occluders, 0.0, skin)
        return np.clip(np.where(region, skin, 0.0), 0.0, 1.0).astype(np.float32), found


    def _occluders(self, srgb: np.ndarray, region: np.ndarray, points: np.ndarray, diagonal: float) -> np.ndarray:
        """[H, W] bool: what covers the face (deface/priors/occluders.py), grown by ``occluders.grow`` pixels."""
        config = self.config.occluders
        shape = region.shape
        kept = feature_mask_from_landmarks(points, shape, round(config.feature_margin * diagonal))
        if self.config.beard_zone:  # with the beard past the outline's points, as far as the region reaches
            kept |= beard_reach_mask(points, shape, round(self.config.hull_margin * diagonal))
        eyes = _hull_mask(points[list(MEDIAPIPE_FEATURES["left_eye"])], shape)
        eyes |= _hull_mask(points[list(MEDIAPIPE_FEATURES["right_eye"])], shape)
        found = find_occluders(srgb, region, kept, eyes, diagonal, config)
        if not found.any() or config.grow < 1:
            return found
        return cv2.dilate(found.astype(np.uint8), disk(config.grow)).astype(bool)


def load_face_region_classifier(
    models_dir: str | os.PathLike | None = None, prefer: str = "bisenet", skin: SkinClassifierConfig | None = None
) -> tuple[FaceRegionClassifier, str]:
    """(classifier, description): BiSeNet when asked for and its checkpoint is found, else the skin model."""
    if prefer not in ("bisenet", "skin"):
        raise ValueError(f"unknown face-region classifier {prefer!r}; choose 'bisenet' or 'skin'")
    if prefer == "bisenet":
        from deface.priors.bisenet import EYE_CLASSES, FACE_CLASSES, MOUTH_CLASS, BiSeNetFaceParser, MissingWeightsError

        config = skin or SkinClassifierConfig()
        left_out = ((MOUTH_CLASS,) if config.mouth_opening else ()) + (EYE_CLASSES if config.eye_opening else ())
        classes = tuple(c for c in FACE_CLASSES if c not in left_out)
        try:
            return (BiSeNetFaceParser.from_models_dir(models_dir, face_classes=classes),
                    "BiSeNet face parsing (79999_iter.pth)")
        except MissingWeightsError as error:
            return SkinColourClassifier(skin), f"skin-colour classifier (BiSeNet off: {error})"
    return SkinColourClassifier(skin), "skin-colour classifier"
