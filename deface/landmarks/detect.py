"""MediaPipe Face Mesh landmarks: 478 points (468 + 10 iris points, ``refine_landmarks=True``).

Static mode for photos, tracking mode for video frames. Coordinates are pixels of the input image
(x right, y down, continuous coordinates: MediaPipe's normalised x times the width, so a point at the
centre of pixel (i, j) has coordinates (j + 0.5, i + 0.5) as in :mod:`deface.render.camera`).

Several faces: they are sorted by the area of their landmark bounding box, largest first;
``face_index`` picks one (0 = largest) and :attr:`Landmarks.num_faces` says how many were found.
No face: :class:`NoFaceError`. MediaPipe's short-range face detector misses faces that fill a tiny
crop (e.g. 160x160 aligned crops), so when nothing is found the image is retried padded with a
border (the face then looks smaller and further away) and upscaled to at least 384 px. It also misses
faces narrower than about a tenth of the image (a half-body shot, a group, a face 400 px wide in a
6000 px photo): then the faces are searched for as boxes by the full-range detector, over the whole
image and over overlapping tiles of a half, a third and a quarter of it, and Face Mesh runs on a square
crop around each box (:meth:`FaceMeshDetector._small_faces`).
"""

from __future__ import annotations

from collections.abc import Sequence
from contextlib import ExitStack
from dataclasses import dataclass

import numpy as np

from deface.landmarks.quiet import native_log_filter, quiet_environment

NUM_LANDMARKS = 478
MIN_RETRY_SIZE = 384  # tiny images are upscaled to this (longest side) before retrying
CROP_MARGIN = 2.0  # a small face's crop: this many times its detected box's larger side, centred on the box
TILINGS = (2, 3, 4)  # tiles of 1/k of the image's longer side (half overlapping) searched for small faces
SAME_FACE_IOU = 0.3  # boxes overlapping by more are one face (found in several tiles)


class NoFaceError(ValueError):
    """No face was found in an image or video (one line, names the source)."""


@dataclass(frozen=True)
class Landmarks:
    """The landmarks of one face in one image."""

    points: np.ndarray  # [478, 2] float32 pixels, x right, y down
    depth: np.ndarray  # [478] float32 MediaPipe's relative z, in pixels (x scale), smaller = nearer
    image_size: tuple[int, int]  # (width, height) of the image the points refer to
    num_faces: int  # faces found in the image
    face_index: int  # which face these are, faces sorted by size (0 = largest)

    @property
    def bbox_area(self) -> float:
        """Area of the landmarks' bounding box, pixels²."""
        return _bbox_area(self.points)


def _bbox_area(points: np.ndarray) -> float:
    extent = points.max(axis=0) - points.min(axis=0)
    return float(extent[0] * extent[1])


def _to_uint8(image: np.ndarray) -> np.ndarray:
    """[H, W, 3] float in [0, 1] or uint8 -> contiguous uint8 RGB."""
    if image.ndim != 3 or image.shape[2] < 3:
        raise ValueError(f"image must be [H, W, 3], got shape {image.shape}")
    image = image[..., :3]
    if image.dtype != np.uint8:
        image = np.clip(np.rint(np.asarray(image, dtype=np.float32) * 255.0), 0, 255).astype(np.uint8)
    return np.ascontiguousarray(image)


class FaceMeshDetector:
    """A MediaPipe Face Mesh instance (static or tracking mode); close it or use it as a context manager."""

    def __init__(self, static: bool = True, max_faces: int = 4, min_confidence: float = 0.5):
        quiet_environment()
        # MediaPipe's threads print C++ notices until the graph is closed: filter for the detector's lifetime.
        self._quiet = ExitStack()
        self._quiet.enter_context(native_log_filter())
        try:
            from mediapipe.python.solutions import face_mesh

            self.static = static
            self._mesh = face_mesh.FaceMesh(
                static_image_mode=static,
                max_num_faces=max_faces,
                refine_landmarks=True,
                min_detection_confidence=min_confidence,
                min_tracking_confidence=min_confidence,
            )
        except BaseException:
            self._quiet.close()
            raise

    def __enter__(self) -> FaceMeshDetector:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        try:
            self._mesh.close()
        finally:
            self._quiet.close()

    def raw_faces(self, image: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """Run MediaPipe once on uint8 [H, W, 3] -> [(points [478, 2], depth [478])] in MediaPipe's order."""
        height, width = image.shape[:2]
        result = self._mesh.process(image)
        faces = []
        for face in result.multi_face_landmarks or []:
            xyz = np.array([(p.x, p.y, p.z) for p in face.landmark], dtype=np.float32)  # [478, 3]
            points = xyz[:, :2] * np.array([width, height], dtype=np.float32)
            faces.append((points, xyz[:, 2] * width))
        return faces

    def detect_all(self, image: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """All faces, largest first, with retries (padding, upscaling) when nothing is found."""
        image = _to_uint8(image)
        faces = self.raw_faces(image)
        if not faces and self.static:
            faces = self._retry(image) or self._small_faces(image)
        return sorted(faces, key=lambda face: -_bbox_area(face[0]))

    def _retry(self, image: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """Pad by 25% / 50% of the size on each side (edge colours) and upscale small images."""
        import cv2

        height, width = image.shape[:2]
        for pad_fraction in (0.25, 0.5):
            pad = int(round(pad_fraction * max(height, width)))
            padded = cv2.copyMakeBorder(image, pad, pad, pad, pad, cv2.BORDER_REPLICATE)
            scale = max(1.0, MIN_RETRY_SIZE / max(padded.shape[:2]))
            if scale > 1.0:
                size = (round(padded.shape[1] * scale), round(padded.shape[0] * scale))
                padded = cv2.resize(padded, size, interpolation=cv2.INTER_CUBIC)
                scale_xy = np.array([size[0] / (width + 2 * pad), size[1] / (height + 2 * pad)], np.float32)
            else:
                scale_xy = np.ones(2, np.float32)
            faces = self.raw_faces(padded)
            if faces:
                return [(points / scale_xy - pad, depth / scale_xy[0]) for points, depth in faces]
        return []

    def _small_faces(self, image: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """Faces too small for Face Mesh's own detector: Face Mesh on a crop around each box the full-range
        detector finds (module doc)."""
        faces = []
        for box in face_boxes(image):
            crop, origin, scale = _square_crop(image, box)
            found = self.raw_faces(crop)
            if found:  # the face the box was around, not a neighbour that the crop also shows
                centre = np.array(crop.shape[1::-1], np.float32) / 2
                points, depth = min(found, key=lambda face: float(np.linalg.norm(face[0].mean(0) - centre)))
                faces.append((points / scale + origin, depth / scale))
        return faces


def face_boxes(image: np.ndarray) -> list[np.ndarray]:
    """Boxes [x0, y0, x1, y1] (pixels of uint8 ``image`` [H, W, 3]) of the faces MediaPipe's full-range detector
    finds over the whole image or, when it finds none there, over the first tiling of :data:`TILINGS` that shows
    any (a face a tenth of a tile is a fortieth of the image at the finest); overlapping boxes kept once."""
    from mediapipe.python.solutions import face_detection

    height, width = image.shape[:2]
    with face_detection.FaceDetection(model_selection=1, min_detection_confidence=0.5) as detector:
        boxes = _detected_boxes(detector, image, (0, 0))
        for k in TILINGS:
            if boxes:
                break
            side = int(np.ceil(max(height, width) / k))
            step = max(side // 2, 1)
            for y in range(0, max(height - side, 0) + step, step):
                for x in range(0, max(width - side, 0) + step, step):
                    boxes += _detected_boxes(detector, image[y:y + side, x:x + side], (x, y))
    kept: list[np.ndarray] = []
    for box in sorted(boxes, key=lambda b: -(b[2] - b[0]) * (b[3] - b[1])):
        if all(_iou(box, other) <= SAME_FACE_IOU for other in kept):
            kept.append(box)
    return kept


def _detected_boxes(detector, image: np.ndarray, origin: tuple[int, int]) -> list[np.ndarray]:
    """The detector's boxes on ``image`` in the pixels of the image it was cut from at ``origin`` (x, y)."""
    height, width = image.shape[:2]
    boxes = []
    for detection in detector.process(np.ascontiguousarray(image)).detections or []:
        relative = detection.location_data.relative_bounding_box
        x0, y0 = relative.xmin * width + origin[0], relative.ymin * height + origin[1]
        boxes.append(np.array([x0, y0, x0 + relative.width * width, y0 + relative.height * height]))
    return boxes


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    overlap = np.maximum(np.minimum(a[2:], b[2:]) - np.maximum(a[:2], b[:2]), 0).prod()
    union = (a[2:] - a[:2]).prod() + (b[2:] - b[:2]).prod() - overlap
    return float(overlap / max(union, 1e-9))


def _square_crop(image: np.ndarray, box: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """(crop, origin [2], scale): a square of :data:`CROP_MARGIN` times ``box``'s larger side around its centre,
    edges replicated beyond the image, resized to :data:`MIN_RETRY_SIZE`; a point p of the crop is
    p / scale + origin in ``image``."""
    import cv2

    side = int(np.ceil(CROP_MARGIN * max(box[2] - box[0], box[3] - box[1], 1.0)))
    x0, y0 = (int(round(c)) - side // 2 for c in ((box[0] + box[2]) / 2, (box[1] + box[3]) / 2))
    height, width = image.shape[:2]
    pad = max(0, -x0, -y0, x0 + side - width, y0 + side - height)
    padded = cv2.copyMakeBorder(image, pad, pad, pad, pad, cv2.BORDER_REPLICATE) if pad else image
    crop = padded[y0 + pad:y0 + pad + side, x0 + pad:x0 + pad + side]
    scale = MIN_RETRY_SIZE / side
    interpolation = cv2.INTER_CUBIC if scale > 1 else cv2.INTER_AREA
    crop = cv2.resize(np.ascontiguousarray(crop), (MIN_RETRY_SIZE, MIN_RETRY_SIZE), interpolation=interpolation)
    return crop, np.array([x0, y0], np.float32), scale


def detect_landmarks(image: np.ndarray, face_index: int = 0, source: str = "image") -> Landmarks:
    """Landmarks of one face in a photo [H, W, 3] (float sRGB in [0, 1] or uint8).

    face_index: faces sorted by size, 0 = largest. source names the input in error messages.
    Raises NoFaceError when no face is found, IndexError-like ValueError when face_index is too large.
    """
    with FaceMeshDetector(static=True) as detector:
        faces = detector.detect_all(image)
    return _choose(faces, face_index, image, source)


def _choose(faces, face_index: int, image: np.ndarray, source: str) -> Landmarks:
    if not faces:
        raise NoFaceError(f"{source}: no face found")
    if not 0 <= face_index < len(faces):
        raise ValueError(f"{source}: face_index {face_index} out of range, {len(faces)} face(s) found")
    points, depth = faces[face_index]
    height, width = image.shape[:2]
    return Landmarks(points, depth, (width, height), len(faces), face_index)


def track_video(
    frames: Sequence[np.ndarray], face_index: int = 0, source: str = "video"
) -> list[Landmarks | None]:
    """Landmarks in every frame with MediaPipe's tracking mode (a frame it misses is searched as a photo is).

    The face is chosen by size (face_index) in the first frame where faces are seen, then followed:
    in later frames the face whose landmark centre is nearest to the previous one is taken.
    Frames where no face is found give None. Raises NoFaceError when no frame has a face.
    """
    results: list[Landmarks | None] = []
    previous_centre: np.ndarray | None = None
    with FaceMeshDetector(static=False) as detector, ExitStack() as stack:
        still: FaceMeshDetector | None = None  # for frames the tracker misses: a small face, a face after a cut
        for frame in frames:
            faces = detector.detect_all(frame)
            if not faces:
                still = still or stack.enter_context(FaceMeshDetector(static=True))
                faces = still.detect_all(frame)
            if not faces:
                results.append(None)
                continue
            if previous_centre is None:
                chosen = _choose(faces, face_index, frame, source)
            else:
                distances = [np.linalg.norm(points.mean(0) - previous_centre) for points, _ in faces]
                nearest = int(np.argmin(distances))
                chosen = _choose(faces, nearest, frame, source)
            previous_centre = chosen.points.mean(0)
            results.append(chosen)
    if all(item is None for item in results):
        raise NoFaceError(f"{source}: no face found in any of {len(results)} frame(s)")
    return results
