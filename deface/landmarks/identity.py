"""Whose face is it: dlib's face descriptor, for telling one person's photos from another's.

dlib's face descriptor (ResNet-29 trained for face verification, 128-d, "dlib_face_recognition_resnet_model_v1")
of a face aligned by dlib's 5-point shape predictor, in a box from dlib's HOG frontal face detector or, for a face
the fit has already found, from its MediaPipe landmarks (:meth:`IdentityScorer.descriptor_of_face`: works where the
HOG detector finds no face, a head turned by 35 degrees). The **identity distance** is the Euclidean distance
between two descriptors; dlib calls two faces the same person below 0.6 (99.38% on LFW). Used by a several-photo
fit to leave out a photo of another person (deface/fit/person.py) and by the evaluation's identity column
(deface/eval/identity.py).

Small images: the HOG detector needs a face of about 80 px, so images are upscaled (bicubic) to at least
:data:`MIN_SIDE` px on their longer side before detection.

Optional dependency: ``pip install -e ".[identity]"`` (``dlib-bin`` and ``face-recognition-models``, which
ships the model files). :func:`available` says whether they are there; callers say so and go without.
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image

SAME_PERSON_DISTANCE = 0.6
"""dlib's verification threshold on the descriptor distance."""
MIN_SIDE = 512
"""Images are upscaled to at least this longer side before detection (see the module docstring)."""
FOREHEAD_SHARE = 0.15
"""Share of a MediaPipe landmarks' box, from its top, that a face box for dlib leaves out: MediaPipe's points reach
the forehead above the brows, dlib's boxes start at the brows."""
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
                raise RuntimeError(f"dlib's face descriptor is unavailable: {reason}")
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

    def descriptor_of_face(self, image: np.ndarray, points: np.ndarray) -> np.ndarray:
        """128-d descriptor of the face in ``image`` (sRGB float [H, W, 3]) whose landmarks ``points`` [N, 2]
        (pixels of ``image``; MediaPipe's) are known, aligned within their box less its top ``FOREHEAD_SHARE``
        instead of a HOG detection's box."""
        self._load()
        import dlib

        prepared = to_detector_image(image)
        scale = prepared.shape[1] / image.shape[1]
        (left, top), (right, bottom) = np.asarray(points).min(0) * scale, np.asarray(points).max(0) * scale
        top += FOREHEAD_SHARE * (bottom - top)
        return self._describe(prepared, dlib.rectangle(int(left), int(top), int(right), int(bottom)))

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


@dataclass(frozen=True)
class SamePersonConfig:
    """Whether the photos of a several-photo fit show one person (``FitConfig.same_person``; deface/fit/person.py)."""

    enabled: bool = True
    """Leave out a photo whose face is another person's than the others', said in one line. Needs the identity
    extra (dlib); without it the fit says that the photos were not checked."""
    distance: float = 0.7
    """Identity distance beyond which two faces are different people's. dlib's own threshold is 0.6, but one
    person's photos reach 0.65 here (renders of one head turned by 35 degrees; a photo and its shadowed copy up
    to 0.51), while different people's are 0.56 or more, 0.70 at their 5th percentile (25 photos; BENCHMARKS.md
    ``#same-person``): a photo is left out only when it is clearly someone else, and a look-alike within 0.7 is
    not caught."""

    def __post_init__(self) -> None:
        if not self.distance > 0:
            raise ValueError(f"same_person.distance must be positive, got {self.distance}")
