"""MediaPipe Face Mesh landmarks: 478 points (468 + 10 iris points, ``refine_landmarks=True``).

Static mode for photos, tracking mode for video frames. Coordinates are pixels of the input image
(x right, y down, continuous coordinates: MediaPipe's normalised x times the width, so a point at the
centre of pixel (i, j) has coordinates (j + 0.5, i + 0.5) as in :mod:`deface.render.camera`).

Several faces: they are sorted by the area of their landmark bounding box, largest first;
``face_index`` picks one (0 = largest) and :attr:`Landmarks.num_faces` says how many were found.
No face: :class:`NoFaceError`. MediaPipe's short-range face detector misses faces that fill a tiny
crop (e.g. 160x160 aligned crops), so when nothing is found the image is retried padded with a
border (the face then looks smaller and further away) and upscaled to at least 384 px.
"""

from __future__ import annotations

from collections.abc import Sequence
from contextlib import ExitStack
from dataclasses import dataclass

import numpy as np

from deface.landmarks.quiet import native_log_filter, quiet_environment

NUM_LANDMARKS = 478
MIN_RETRY_SIZE = 384  # tiny images are upscaled to this (longest side) before retrying


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
            faces = self._retry(image)
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
    """Landmarks in every frame with MediaPipe's tracking mode.

    The face is chosen by size (face_index) in the first frame where faces are seen, then followed:
    in later frames the face whose landmark centre is nearest to the previous one is taken.
    Frames where no face is found give None. Raises NoFaceError when no frame has a face.
    """
    results: list[Landmarks | None] = []
    previous_centre: np.ndarray | None = None
    with FaceMeshDetector(static=False) as detector:
        for frame in frames:
            faces = detector.detect_all(frame)
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
