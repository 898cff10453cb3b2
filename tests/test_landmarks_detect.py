"""MediaPipe detection: a real face, no face, two faces and face choice, tiny crops, small faces in large photos,
video tracking."""

from __future__ import annotations

import numpy as np
import pytest

from deface.io import load_image
from deface.landmarks.detect import NUM_LANDMARKS, FaceMeshDetector, NoFaceError, detect_landmarks, track_video


def test_astronaut_face():
    from skimage import data

    image = data.astronaut()  # uint8 [512, 512, 3]; her face is around x 150-230, y 40-140
    landmarks = detect_landmarks(image, source="astronaut")
    assert landmarks.points.shape == (NUM_LANDMARKS, 2) and landmarks.num_faces == 1
    centre = landmarks.points.mean(0)
    assert 140 < centre[0] < 240 and 50 < centre[1] < 150
    # Image convention: subject's right eye (33) is on the viewer's left; eyes above the mouth (13).
    assert landmarks.points[33, 0] < landmarks.points[263, 0]
    assert landmarks.points[33, 1] < landmarks.points[13, 1]


def test_real_photo(photos):
    image = load_image(photos / "nextface-s1.png")
    landmarks = detect_landmarks(image)
    assert landmarks.image_size == (256, 256)
    assert (landmarks.points > 0).all() and (landmarks.points < 256).all()
    iod = np.linalg.norm(landmarks.points[33] - landmarks.points[263])
    assert 60 < iod < 160


def test_no_face_raises_naming_the_source():
    rng = np.random.default_rng(0)
    with pytest.raises(NoFaceError, match="noise.png"):
        detect_landmarks(rng.random((200, 200, 3)).astype(np.float32), source="noise.png")
    with pytest.raises(NoFaceError):
        detect_landmarks(np.full((128, 128, 3), 0.5, np.float32))


def test_two_faces_largest_first_and_face_index(photos):
    image = load_image(photos / "trump_hillary.jpg")
    largest = detect_landmarks(image)
    other = detect_landmarks(image, face_index=1)
    assert largest.num_faces == 2 and other.num_faces == 2
    assert largest.bbox_area >= other.bbox_area
    assert abs(largest.points[:, 0].mean() - other.points[:, 0].mean()) > 200  # two different people
    with pytest.raises(ValueError, match="face_index 2"):
        detect_landmarks(image, face_index=2)


def test_tiny_crop_is_found_and_mapped_back(photos):
    """A 64-px crop: found (directly or by the pad/upscale retry), points in the crop's own pixels."""
    from PIL import Image

    full = load_image(photos / "facenet-paul_rudd.png")  # 160 x 160
    tiny = np.asarray(Image.fromarray((full * 255).astype(np.uint8)).resize((64, 64), Image.BILINEAR)) / 255.0
    reference = detect_landmarks(full)
    landmarks = detect_landmarks(tiny)
    assert landmarks.image_size == (64, 64)
    error = np.linalg.norm(landmarks.points * 2.5 - reference.points, axis=1).mean()
    assert error < 0.05 * np.linalg.norm(reference.points[33] - reference.points[263])


def test_video_tracking(shared):
    from deface.io import read_video_frames

    frames, _ = read_video_frames(shared / "data" / "videos" / "d18.mp4", max_frames=6, stride=5)
    tracked = track_video(frames, source="d18.mp4")
    assert len(tracked) == 6 and all(item is not None for item in tracked)
    centres = np.array([item.points.mean(0) for item in tracked])
    assert np.abs(np.diff(centres, axis=0)).max() < 60  # the same face, moving smoothly
    with pytest.raises(NoFaceError, match="blank"):
        track_video([np.zeros((64, 64, 3), np.float32)] * 2, source="blank")


def test_small_face_in_a_large_photo_is_found_and_mapped_back(photos):
    """A face a twelfth of its photo's width (too small for Face Mesh's own detector): found by the full-range
    detector's box and Face Mesh on a crop around it, points in the photo's pixels."""
    from deface.landmarks.detect import face_boxes

    face = (load_image(photos / "facenet-paul_rudd.png") * 255).astype(np.uint8)  # 160 x 160
    canvas = np.full((1400, 2000, 3), (110, 120, 100), np.uint8)
    canvas[900:1060, 1500:1660] = face
    reference = detect_landmarks(face)
    with FaceMeshDetector() as detector:
        assert detector.raw_faces(canvas) == []  # the short-range detector alone misses it
    boxes = face_boxes(canvas)
    assert len(boxes) == 1 and 1450 < boxes[0][0] < boxes[0][2] < 1710 and 850 < boxes[0][1] < boxes[0][3] < 1110
    landmarks = detect_landmarks(canvas)
    assert landmarks.image_size == (2000, 1400) and landmarks.num_faces == 1
    error = np.linalg.norm(landmarks.points - (reference.points + [1500, 900]), axis=1).mean()
    assert error < 0.05 * np.linalg.norm(reference.points[33] - reference.points[263])


def test_a_small_face_in_a_clip_is_tracked(photos):
    """Frames too large around the face for the tracker's own detector are searched as photos are."""
    face = (load_image(photos / "facenet-paul_rudd.png") * 255).astype(np.uint8)  # 160 x 160
    frames = []
    for shift in (0, 6, 12):
        canvas = np.full((1080, 1920, 3), (110, 120, 100), np.uint8)
        canvas[800:960, 1500 + shift:1660 + shift] = face
        frames.append(canvas)
    tracked = track_video(frames, source="small.mp4")
    assert all(item is not None for item in tracked)
    centres = np.array([item.points.mean(0) for item in tracked])
    assert np.allclose(np.diff(centres[:, 0]), 6, atol=2) and np.all(np.abs(centres[:, 1] - 880) < 25)


def test_two_small_faces_side_by_side_are_two_faces(photos):
    """A small group: each box's crop also shows the neighbour; each crop gives the face it was cut around."""
    face = (load_image(photos / "facenet-paul_rudd.png") * 255).astype(np.uint8)  # 160 x 160
    canvas = np.full((1400, 2400, 3), (110, 120, 100), np.uint8)
    canvas[600:760, 1000:1160] = face
    canvas[600:760, 1200:1360] = face[:, ::-1]
    first, second = detect_landmarks(canvas), detect_landmarks(canvas, face_index=1)
    assert first.num_faces == 2
    centres = sorted(float(item.points[:, 0].mean()) for item in (first, second))
    assert 1000 < centres[0] < 1160 and 1200 < centres[1] < 1360
