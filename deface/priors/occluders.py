"""What covers the face, found without weights: thin, long, dark structures (a glasses frame, a strand of hair)
and the tinted lenses a frame encloses, so that the face region h leaves them out
(``SkinClassifierConfig.occluders``).

A glasses frame or a strand of hair is a curve a few pixels wide, much darker than the skin on both of its sides,
running a long way across the face. Pigment on the face's surface is not like that: moles, freckles and a
birthmark are compact; brows, lashes and lips are the landmarks' features; a beard grows in the beard zone. So:

1. darkness: how much darker a pixel's log luminance is than the grey-level closing of it by a disk of radius
   r = ``width`` x the face's diagonal, i.e. than the brightest level around it on all sides within r (a
   black-top-hat: zero on anything wider than about 2r, such as a cast shadow's body or the face's shading);
2. candidates: darkness above log(1 / ``contrast``), grown over the pixels within 2 of them above
   log(1 / ``edge_contrast``) (a frame's soft sides, not the shading beside it), outside the features (brows,
   eyes, nostrils, lips, grown by ``feature_margin``) and the beard zone;
3. structures: the candidates' connected parts whose skeleton is at least ``length`` x the diagonal long and
   whose mean width (area over skeleton length) is at most ``thickness`` x the diagonal;
4. abstaining: structures over more than ``most_area`` of the region are the face's own texture (a dark skin's
   deep wrinkles), and nothing is left out;
5. lenses: the areas the structures enclose (a frame's rims around the eyes); a lens whose skin (outside the
   eye) is darker than the skin around the frame by more than ``lens_contrast``, or of another chroma, is tinted
   and left out whole; a clear lens shows the skin and stays.

A thin cast shadow (a stripe of shade, a twig's or a strand's shadow) is found too: one photo cannot tell it
from a dark strand by its shape, and its chroma is the skin's only under a light of the skin's colour (under a
warm key and a cool fill it is not). It leaves h with the occluders, which is what the fit is for anyway: its
texels are filled from the other photos, the face's other side or the skin around, instead of carrying the
shadow. Measured on the board's thin stripes of shade (BENCHMARKS.md "occluders"), leaving them out is better
than fitting them.

A hand or fingers (wide, skin-coloured) are not found by these cues; MediaPipe's hand landmarks find them
(deface/landmarks/hands.py), and :func:`hand_mask` draws the hand from its 21 points (``FitConfig.hands``).

Limits: a strand or a frame lighter than the skin is not found; a frame's rim over a brow stays with the brow
(features are never searched); fingers whose hand MediaPipe does not find (the hand's palm out of the picture)
stay.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy import ndimage
from skimage.morphology import skeletonize

from deface.io.images import LUMINANCE


@dataclass(frozen=True)
class OccluderConfig:
    """The offline occluder finder's knobs; sizes are shares of the face box's diagonal
    (``SkinClassifierConfig.occluders``)."""

    enabled: bool = True
    """Leave thin dark structures and tinted lenses out of h (off: h is the skin model's alone)."""
    width: float = 0.02
    """Radius of the closing that measures darkness: structures up to about twice this wide are found."""
    contrast: float = 0.55
    """A pixel is a candidate when its luminance is at most this share of its surroundings' ..."""
    edge_contrast: float = 0.8
    """... and the candidate grows over connected pixels at most this share (the structure's soft sides)."""
    length: float = 0.15
    """Least length of a structure."""
    thickness: float = 0.03
    """Most mean width of a structure."""
    most_area: float = 0.2
    """When the structures cover more than this share of the region, they are the face's own texture at this
    scale (deep wrinkles, rough skin, a dense pattern of shade), not what covers it: nothing is left out."""
    grow: int = 1
    """Pixels what was found grows by before it leaves h (its soft sides, a shadow's penumbra)."""
    feature_margin: float = 0.01
    """Growth of the features' hulls that the search leaves alone."""
    lens_contrast: float = 0.8
    """A lens is tinted when its skin's luminance is under this share of the skin around the frame ..."""
    lens_chroma: float = 0.025
    """... or its chromaticity (r, g) differs from that skin's by more than this."""


@dataclass(frozen=True)
class HandConfig:
    """Hands over the face, found by MediaPipe's hand landmarks, left out of h (``FitConfig.hands``)."""

    enabled: bool = True
    """Find hands and leave them out of h, whichever classifier made it (off in ``paper``: its parser has no hand
    class)."""
    min_confidence: float = 0.7
    """MediaPipe's palm detection threshold. At its own default, 0.5, it found a hand in a shirt's collar under a
    beard (one of the board's 69 photos and renders); the hand of alfw1.png, holding a phone to her cheek, is found
    up to 0.8."""
    wrist_beyond: float = 0.1
    """A hand counts when its wrist lies this share of the face's size (its landmarks' box diagonal) beyond the
    face's outline (:func:`reaches_in`): alfw1.png's hand on her cheek 0.37; a false hand in freckles 0.01."""
    finger_width: float = 0.25
    """A finger's width as a share of the palm's length (wrist to the middle finger's knuckle); the drawn hand grows
    by half of it more (its soft edge, the fingertips' ends beyond their last landmark)."""


HAND_BONES = ((0, 1), (1, 2), (2, 3), (3, 4), (0, 5), (5, 6), (6, 7), (7, 8), (5, 9), (9, 10), (10, 11), (11, 12),
              (9, 13), (13, 14), (14, 15), (15, 16), (13, 17), (0, 17), (17, 18), (18, 19), (19, 20))
"""MediaPipe's hand connections: the thumb, each finger's three joints, and the palm's outline."""
HAND_PALM = (0, 1, 5, 9, 13, 17)
"""The palm's polygon: the wrist, the thumb's base and the four knuckles."""


def reaches_in(hand: np.ndarray, face: np.ndarray, margin: float) -> bool:
    """Whether a hand's wrist (``hand`` [21, 2] pixels) lies beyond the convex hull of the face's landmarks
    (``face`` [N, 2]) by at least ``margin`` times the hull's box diagonal: a hand over a face reaches in from an arm
    beyond it. MediaPipe also finds "hands" in a cheek's freckles crossed by strands (the occluder renders),
    their wrist on the jaw's outline."""
    face = np.asarray(face, np.float32)
    hull = cv2.convexHull(face)
    beyond = -cv2.pointPolygonTest(hull, tuple(float(v) for v in hand[0]), True)
    return beyond >= margin * float(np.hypot(*np.ptp(face, axis=0)))


def hand_mask(points: np.ndarray, shape: tuple[int, int], config: HandConfig) -> np.ndarray:
    """[H, W] bool: the hand of MediaPipe's 21 ``points`` ([21, 2] pixels): its palm's polygon and a band of
    ``finger_width`` along every bone, grown by half of it."""
    points = np.asarray(points, np.float64)
    palm = float(np.linalg.norm(points[9] - points[0]))
    width = max(2, round(config.finger_width * palm))
    mask = np.zeros(shape, np.uint8)
    scaled = np.round(points * 4).astype(np.int32)  # cv2's shift: quarter-pixel precision
    cv2.fillPoly(mask, [scaled[list(HAND_PALM)]], 1, lineType=cv2.LINE_8, shift=2)
    for start, end in HAND_BONES:
        cv2.line(mask, tuple(scaled[start]), tuple(scaled[end]), 1, thickness=width, lineType=cv2.LINE_8, shift=2)
    return cv2.dilate(mask, disk(max(1, width // 2))).astype(bool)


def disk(radius: int) -> np.ndarray:
    """A disk-shaped structuring element of ``radius`` pixels (at least 1)."""
    radius = max(1, int(radius))
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


def darkness(luma: np.ndarray, radius: int) -> np.ndarray:
    """[H, W] >= 0: log(closing(luma) / luma), the closing a disk of ``radius`` pixels (a black-top-hat in log
    luminance: how much darker a pixel is than what surrounds it within the radius)."""
    level = np.log(np.maximum(luma, 1e-4)).astype(np.float32)
    return np.maximum(cv2.morphologyEx(level, cv2.MORPH_CLOSE, disk(radius)) - level, 0.0)


def thin_structures(mask: np.ndarray, least_length: float, most_width: float) -> np.ndarray:
    """[H, W] bool: the connected parts of ``mask`` (8-connected) whose skeleton is at least ``least_length`` pixels
    long and whose mean width (area over the skeleton's length) is at most ``most_width`` pixels."""
    labels, count = ndimage.label(mask, structure=np.ones((3, 3)))
    if count == 0:
        return mask.copy()
    index = np.arange(1, count + 1)
    length = ndimage.sum_labels(skeletonize(mask), labels, index)  # parts are apart: one skeleton serves all
    area = ndimage.sum_labels(mask, labels, index)
    kept = np.concatenate([[False], (length >= max(least_length, 1.0)) & (area <= most_width * length)])
    return kept[labels]


def tinted_lenses(structures: np.ndarray, srgb: np.ndarray, region: np.ndarray, eyes: np.ndarray,
                  config: OccluderConfig, radius: int) -> np.ndarray:
    """[H, W] bool: the areas ``structures`` enclose whose skin (not ``eyes``) is darker or of another chroma than
    the skin just outside them (see the module doc)."""
    enclosed = ndimage.binary_fill_holes(structures) & ~structures & region
    labels, count = ndimage.label(enclosed)
    lenses = np.zeros_like(enclosed)
    reach = disk(2 * radius)
    near_structures = cv2.dilate(structures.astype(np.uint8), reach).astype(bool)
    linear = srgb.astype(np.float32) ** 2.2
    luma = linear.mean(-1)
    chroma = linear[..., :2] / np.maximum(linear.sum(-1, keepdims=True), 1e-6)
    for index in range(1, count + 1):
        lens = labels == index
        grown = near_structures | cv2.dilate(lens.astype(np.uint8), reach).astype(bool)
        around = grown & ~lens & ~structures & region & ~eyes
        inside = lens & ~eyes
        if inside.sum() < 10 or around.sum() < 10:
            continue
        ratio = np.median(luma[inside]) / max(np.median(luma[around]), 1e-6)
        shift = np.linalg.norm(np.median(chroma[inside], 0) - np.median(chroma[around], 0))
        lenses |= lens if ratio < config.lens_contrast or shift > config.lens_chroma else False
    return lenses


def find_occluders(srgb: np.ndarray, region: np.ndarray, kept: np.ndarray, eyes: np.ndarray, diagonal: float,
                   config: OccluderConfig) -> np.ndarray:
    """[H, W] bool: thin dark structures and tinted lenses over the face (the module doc).

    ``srgb`` [H, W, 3] in [0, 1]; ``region`` [H, W] bool, where to look; ``kept`` [H, W] bool, the face's own
    features and beard zone, never taken for an occluder; ``eyes`` [H, W] bool, the eyes (a lens's skin is
    judged without them); ``diagonal``: the face box's, pixels."""
    radius = max(2, round(config.width * diagonal))
    luma = (srgb.astype(np.float32) ** 2.2) @ LUMINANCE.astype(np.float32)
    dark = darkness(luma, radius)
    search = region & ~kept
    strong = search & (dark > np.log(1.0 / config.contrast))
    weak = search & (dark > np.log(1.0 / config.edge_contrast))
    grown = strong | (weak & cv2.dilate(strong.astype(np.uint8), disk(2)).astype(bool))
    structures = thin_structures(grown, config.length * diagonal, config.thickness * diagonal)
    if not structures.any() or structures.sum() > config.most_area * region.sum():
        return np.zeros_like(structures)
    return structures | tinted_lenses(structures, srgb, region, eyes, config, radius)
