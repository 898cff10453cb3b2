"""Several photos of one person as the frames of one fit (``deface fit --person NAME a.jpg b.jpg c.jpg``).

The fit's frames share one size, one focal length and a principal point at their centre (deface/fit/scene.py), and
a clip's frames share one crop (deface/fit/framing.py). Photos come from different cameras, sizes and distances, so
each photo is cut to its own square around its face (``crop.margin`` x its landmarks' box, moved inside the photo
where it fits, the photo's edge pixels repeated where it does not) and resized to one working side. Each crop is
then treated as the frame of a camera looking at the face's centre: its principal point is the crop's centre, not
the photo's. For a face near a wide photo's edge the true camera sees it a few degrees obliquely; the frame's own
rotation takes that up, and the perspective (the shared focal length) differs by the few percent faces' depths
allow. Shared across the photos: the identity's shape and every map; per photo: pose, expression, lights and their
masks, face region, and the white level the scene-light terms read off each crop (``tone.white_per_photo``,
deface/fit/scene_white.py)."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from deface.fit.config import FitConfig
from deface.fit.log import FitLog
from deface.fit.target import FitTarget
from deface.landmarks import identity
from deface.landmarks.detect import Landmarks
from deface.landmarks.identity import SamePersonConfig


@dataclass(frozen=True)
class PhotoCrop:
    """Where one photo's working frame lies in the photo."""

    source: str  # the photo's file
    size: tuple[int, int]  # (width, height) of the photo as decoded
    box: tuple[float, float, float, float]  # the square crop in the photo's pixels: left, top, right, bottom (may
    # reach past its edges, where the edge pixels are repeated)

    @property
    def side(self) -> float:
        return self.box[2] - self.box[0]

    def record(self, focal: float | None = None, side: int | None = None) -> dict:
        """What params.json says of this photo; with the working frames' ``focal`` and ``side`` (pixels), the
        frame's camera in the photo's pixels (its principal point the crop's centre: module doc)."""
        record = {"path": self.source, "size": list(self.size), "box": [round(v, 3) for v in self.box]}
        if focal is not None and side is not None:
            record["camera"] = {"focal_px": round(focal * self.side / side, 4),
                                "principal_point": [round((self.box[0] + self.box[2]) / 2, 3),
                                                    round((self.box[1] + self.box[3]) / 2, 3)]}
        return record


def square_box(points: np.ndarray, margin: float,
               size: tuple[int, int] | None = None) -> tuple[float, float, float, float]:
    """The square of side ``margin`` x the longer side of the box of ``points`` [P, 2], centred on it; with the
    photo's ``size`` (width, height), moved inside the photo along each axis the square fits in (as a photo's crop
    is, deface/fit/framing.py), so that few of its pixels are the photo's repeated edge."""
    low, high = points.min(0).astype(np.float64), points.max(0).astype(np.float64)
    centre, side = (low + high) / 2, margin * max(float((high - low).max()), 1.0)
    start = centre - side / 2
    if size is not None:
        for axis, length in enumerate(size):
            if side <= length:
                start[axis] = min(max(start[axis], 0.0), length - side)
    return float(start[0]), float(start[1]), float(start[0] + side), float(start[1] + side)


def cut_square(photo: np.ndarray, box: tuple[float, float, float, float], side: int) -> np.ndarray:
    """[side, side, 3] the photo's square ``box`` resized to ``side`` pixels (area-averaged when shrinking), its
    edge pixels repeated outside the photo."""
    left, top, right, _ = box
    factor = side / (right - left)
    # photo pixel (x, y) -> crop pixel ((x - left) * factor, ...), pixel centres at +0.5 on both sides
    matrix = np.array([[factor, 0.0, 0.5 * factor - 0.5 - left * factor],
                       [0.0, factor, 0.5 * factor - 0.5 - top * factor]])
    if factor < 1.0:  # shrink by area first so the warp does not alias
        small = cv2.resize(photo, None, fx=factor, fy=factor, interpolation=cv2.INTER_AREA)
        scale = np.array([small.shape[1] / photo.shape[1], small.shape[0] / photo.shape[0]])
        matrix = matrix @ np.array([[1 / scale[0], 0, 0.5 / scale[0] - 0.5],
                                    [0, 1 / scale[1], 0.5 / scale[1] - 0.5], [0, 0, 1]])
        photo = small
    warped = cv2.warpAffine(photo.astype(np.float32), matrix, (side, side), flags=cv2.INTER_LINEAR,
                            borderMode=cv2.BORDER_REPLICATE)
    return np.clip(warped, 0.0, 1.0)


def crop_landmarks(landmarks: Landmarks, box: tuple[float, float, float, float], side: int) -> Landmarks:
    """Landmarks found on the photo, in the pixels of its ``box`` resized to ``side``."""
    factor = side / (box[2] - box[0])
    points = ((landmarks.points - np.array(box[:2])) * factor).astype(np.float32)
    return Landmarks(points, (landmarks.depth * factor).astype(np.float32), (side, side), landmarks.num_faces,
                     landmarks.face_index)


def working_side(crops: list[PhotoCrop], config: FitConfig) -> int:
    """The common side of the working frames: the largest crop's pixels, within the caps of a fit of several
    frames (``resolution`` and ``clip_resolution``); no photo's face is worth more pixels than its own."""
    cap = min(config.resolution, config.clip_resolution)
    return int(max(16, min(cap, round(max(crop.side for crop in crops)))))


def person_target(photos: list[np.ndarray], landmarks: list[Landmarks], sources: list[str],
                  config: FitConfig) -> tuple[FitTarget, list[PhotoCrop]]:
    """The target of one person's ``photos`` (sRGB [H, W, 3] of any sizes) whose ``landmarks`` were found on them:
    each cut to the square around its face and resized to one side (module doc); with where each crop lies."""
    crops = []
    for photo, found, source in zip(photos, landmarks, sources, strict=True):
        size = (photo.shape[1], photo.shape[0])
        crops.append(PhotoCrop(source, size, square_box(found.points, config.crop.margin, size)))
    side = working_side(crops, config)
    frames = [cut_square(photo, crop.box, side) for photo, crop in zip(photos, crops, strict=True)]
    working = [crop_landmarks(found, crop.box, side) for found, crop in zip(landmarks, crops, strict=True)]
    scale = side / float(np.median([crop.side for crop in crops]))
    return FitTarget(frames, working, scale, light_groups=tuple(range(len(frames)))), crops


def one_person(distances: np.ndarray, limit: float) -> tuple[int, list[int]]:
    """(the reference photo, the photos of another person) from the identity distances [n, n] between n photos'
    faces: the reference is the photo within ``limit`` of the most others (the first of those tied, so with two
    photos of different people the first given); a photo farther than ``limit`` from it is another person's."""
    reference = int(np.argmax((distances <= limit).sum(1)))  # argmax: the first of a tie
    return reference, [i for i in range(len(distances)) if distances[reference, i] > limit]


def photos_of_one_person(photos: list[tuple[np.ndarray, Landmarks, str]], settings: SamePersonConfig,
                         log: FitLog) -> list[tuple[np.ndarray, Landmarks, str]]:
    """``photos`` (photo, its landmarks, its source) less those of another person (:func:`one_person` on dlib's
    descriptors), each said in one line; all of them when the check is off, there are fewer than two, or dlib is
    not installed (said)."""
    if not settings.enabled or len(photos) < 2:
        return photos
    reason = identity.unavailable_reason()
    if reason is not None:
        log.info(f"the photos are not checked for another person's face: {reason}")
        return photos
    scorer = identity.IdentityScorer()
    descriptors = np.stack([scorer.descriptor_of_face(photo, found.points) for photo, found, _ in photos])
    distances = np.linalg.norm(descriptors[:, None] - descriptors[None], axis=-1)
    reference, others = one_person(distances, settings.distance)
    for index in others:
        log.info(f"{photos[index][2]}: another person's face than in {photos[reference][2]} (identity distance "
                 f"{distances[reference, index]:.2f} > {settings.distance}); left out of the fit")
    return [photo for index, photo in enumerate(photos) if index not in others]
