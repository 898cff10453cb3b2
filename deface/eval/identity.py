"""Identity score: does the synthesis still look like the person in the photo? (optional metric)

dlib's face descriptor (deface/landmarks/identity.py) on the largest face found by dlib's HOG frontal face
detector, aligned by its 5-point shape predictor. The reported number is dlib's own: the **identity distance**,
the Euclidean distance between the two descriptors, **lower is better**; dlib calls two faces the same person
when it is below 0.6 (99.38% on LFW). On the shared photos of 16 different people the smallest cross-person
distance is 0.61, the median 0.83.

Small images: the HOG detector needs a face of about 80 px, and the benchmark's working images are 128 px
(faces of 40-100 px), so both images are upscaled (bicubic) to at least ``MIN_SIDE`` px
(deface/landmarks/identity.py) on their longer side before detection: of the 16 benchmark photos shrunk to
128 px, it finds all, the raw detector 11.
Shrinking a photo to 128 px alone moves its descriptor by 0.04-0.20 (the floor of this score at that size).
When no face is found in the synthesis, the photo's face box is used for it too (the two are pixel-aligned:
the synthesis is the photo's own camera re-rendered); when the photo has no face, there is no score.

Optional dependency: ``pip install -e ".[identity]"`` (``dlib-bin`` and ``face-recognition-models``, which
ships the model files). :func:`deface.landmarks.identity.available` says whether they are there; callers leave
the column out otherwise, never fill it in.
"""

from __future__ import annotations

import numpy as np

from deface.landmarks.identity import IdentityScorer


def identity_scores(scorer: IdentityScorer, syntheses: list[np.ndarray], photos: list[np.ndarray]) -> dict | None:
    """``{"distance": mean over frames}`` for frames whose photo has a face, or None when none has."""
    distances = [scorer.distance(synthesis, photo) for synthesis, photo in zip(syntheses, photos, strict=True)]
    found = [d for d in distances if d is not None]
    return {"distance": float(np.mean(found))} if found else None
