"""Identity score: does the synthesis still look like the person in the photo? (optional metric)

dlib's face descriptor (ResNet-29 trained for face verification, 128-d, "dlib_face_recognition_resnet_model_v1")
on the largest face found by dlib's HOG frontal face detector, aligned by its 5-point shape predictor. The
reported number is dlib's own: the **identity distance**, the Euclidean distance between the two descriptors,
**lower is better**; dlib calls two faces the same person when it is below 0.6 (99.38% on LFW). On the
shared photos of 16 different people the smallest cross-person distance is 0.61, the median 0.83.

Small images: the HOG detector needs a face of about 80 px, and the benchmark's working images are 128 px
(faces of 40-100 px), so both images are upscaled (bicubic) to at least :data:`MIN_SIDE` px on their longer
side before detection: of the 16 benchmark photos shrunk to 128 px, it finds all, the raw detector 11.
Shrinking a photo to 128 px alone moves its descriptor by 0.04-0.20 (the floor of this score at that size).
When no face is found in the synthesis, the photo's face box is used for it too (the two are pixel-aligned:
the synthesis is the photo's own camera re-rendered); when the photo has no face, there is no score.

Optional dependency: ``pip install -e ".[identity]"`` (``dlib-bin`` and ``face-recognition-models``, which
ships the model files). :func:`available` says whether they are there; callers leave the column out
otherwise, never fill it in.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
from PIL import Image

SAME_PERSON_DISTANCE = 0.6
"""dlib's verification threshold on the descriptor distance."""
MIN_SIDE = 512
"""Images are upscaled to at least this longer side before detection (see the module docstring)."""
DESCRIPTOR_MODEL = "dlib_face_recognition_resnet_model_v1.dat"
SHAPE_MODEL = "shape_predictor_5_face_landmarks.dat"


def model_dir() -> Path | None:
    """Folder of the face_recognition_models data files, or None when the package is not installed.

    Found without importing the package: its ``__init__`` imports ``pkg_resources``, which newer setuptools
    no longer ship.
    """
    spec = importlib.util.find_spec("face_recognition_models")
    if spec is None or not spec.submodule_search_locations:
        return None
    return Path(next(iter(spec.submodule_search_locations))) / "models"


def unavailable_reason() -> str | None:
    """Why identity scores cannot be computed here, or None when they can."""
    if importlib.util.find_spec("dlib") is None:
        return 'dlib is not installed (pip install -e ".[identity]")'
    folder = model_dir()
    if folder is None:
        return 'face_recognition_models is not installed (pip install -e ".[identity]")'
    missing = [name for name in (DESCRIPTOR_MODEL, SHAPE_MODEL) if not (folder / name).is_file()]
    if missing:
        return f"face_recognition_models lacks {', '.join(missing)} in {folder}"
    return None


def available() -> bool:
    return unavailable_reason() is None


def to_detector_image(image: np.ndarray) -> np.ndarray:
    """sRGB float ``[H, W, 3]`` in [0, 1] -> uint8 ``[H', W', 3]``, upscaled to a longer side >= MIN_SIDE."""
    array = (np.clip(np.asarray(image, np.float32), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    height, width = array.shape[:2]
    scale = MIN_SIDE / max(height, width)
    if scale <= 1.0:
        return np.ascontiguousarray(array)
    size = (round(width * scale), round(height * scale))
    return np.asarray(Image.fromarray(array).resize(size, Image.BICUBIC))


class IdentityScorer:
    """dlib face detector + 5-point aligner + ResNet descriptor, loaded on first use."""

    def __init__(self):
        self._models = None

    def _load(self):
        if self._models is None:
            reason = unavailable_reason()
            if reason is not None:
                raise RuntimeError(f"identity scores unavailable: {reason}")
            import dlib

            folder = model_dir()
            self._models = (
                dlib.get_frontal_face_detector(),
                dlib.shape_predictor(str(folder / SHAPE_MODEL)),
                dlib.face_recognition_model_v1(str(folder / DESCRIPTOR_MODEL)),
            )
        return self._models

    def face_box(self, image: np.ndarray):
        """The largest face's ``dlib.rectangle`` in a :func:`to_detector_image` image, or None."""
        detector, _, _ = self._load()
        boxes = detector(image, 0)
        return max(boxes, key=lambda box: box.area()) if len(boxes) else None

    def _describe(self, image: np.ndarray, box) -> np.ndarray:
        _, shape_predictor, encoder = self._load()
        return np.asarray(encoder.compute_face_descriptor(image, shape_predictor(image, box)), np.float64)

    def descriptor(self, image: np.ndarray) -> np.ndarray | None:
        """128-d descriptor of the largest face in an sRGB float ``[H, W, 3]`` image, or None if none is found."""
        prepared = to_detector_image(image)
        box = self.face_box(prepared)
        return None if box is None else self._describe(prepared, box)

    def distance(self, synthesis: np.ndarray, photo: np.ndarray) -> float | None:
        """Identity distance (lower is better, < 0.6 = same person) between a synthesis and its photo.

        Both sRGB float ``[H, W, 3]`` of one size. None when the photo has no detectable face.
        """
        if synthesis.shape != photo.shape:
            raise ValueError(f"synthesis {synthesis.shape} and photo {photo.shape} must have one shape")
        photo_image, synthesis_image = to_detector_image(photo), to_detector_image(synthesis)
        photo_box = self.face_box(photo_image)
        if photo_box is None:
            return None
        synthesis_box = self.face_box(synthesis_image)
        if synthesis_box is None:
            synthesis_box = photo_box
        difference = self._describe(synthesis_image, synthesis_box) - self._describe(photo_image, photo_box)
        return float(np.linalg.norm(difference))


def identity_scores(scorer: IdentityScorer, syntheses: list[np.ndarray], photos: list[np.ndarray]) -> dict | None:
    """``{"distance": mean over frames}`` for frames whose photo has a face, or None when none has."""
    distances = [scorer.distance(synthesis, photo) for synthesis, photo in zip(syntheses, photos, strict=True)]
    found = [d for d in distances if d is not None]
    return {"distance": float(np.mean(found))} if found else None
