"""A face model's named 3D landmarks (BFM 2017's ``metadata/landmarks/json``) and the MediaPipe Face Mesh points
with the same meaning: what anchors the MediaPipe correspondence of a model without iBUG-68 landmark vertices
(:mod:`deface.landmarks.correspondence`), and what the BFM loader checks its file against (docs/bfm.md).
"""

from __future__ import annotations

import numpy as np

# BFM 2017 landmark name (``metadata/landmarks/json`` ids; "right" = the subject's right) -> MediaPipe index
# with the same meaning. Left out: ears, trichion and pupils (no MediaPipe surface equivalent), inner lips
# (the no-mouth model closes them onto one seam) and nose wings (their definition differs between the two).
NAMED_TO_MEDIAPIPE = {
    "center.chin.tip": 152,
    "center.nose.tip": 4,
    "center.nose.attachement_to_philtrum": 2,
    "center.lips.upper.outer": 0,
    "center.lips.lower.outer": 17,
    "right.lips.corner": 61,
    "left.lips.corner": 291,
    "right.lips.philtrum_ridge": 37,
    "left.lips.philtrum_ridge": 267,
    "right.eye.corner_outer": 33,
    "right.eye.corner_inner": 133,
    "left.eye.corner_inner": 362,
    "left.eye.corner_outer": 263,
    "right.eye.top": 159,
    "right.eye.bottom": 145,
    "left.eye.top": 386,
    "left.eye.bottom": 374,
    "right.eyebrow.inner_upper": 107,
    "left.eyebrow.inner_upper": 336,
    "right.eyebrow.bend.upper": 105,
    "left.eyebrow.bend.upper": 334,
    "right.eyebrow.inner_lower": 55,
    "left.eyebrow.inner_lower": 285,
    "right.eyebrow.bend.lower": 52,
    "left.eyebrow.bend.lower": 282,
}
MIN_NAMED_ANCHORS = 6  # similarity + TPS need a few well-spread pairs; BFM 2017 has 25 of the names above


def named_anchor_ids(names: tuple[str, ...] | list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Which named landmarks have a MediaPipe equivalent: (indices into ``names`` [K], MediaPipe ids [K])."""
    pairs = [(i, NAMED_TO_MEDIAPIPE[name]) for i, name in enumerate(names) if name in NAMED_TO_MEDIAPIPE]
    return np.array([i for i, _ in pairs], np.int64), np.array([m for _, m in pairs], np.int64)
