"""Hands over the face (deface/landmarks/hands.py, deface/priors/occluders.py :func:`hand_mask`,
deface/fit/face_region.py :func:`without_hands`): MediaPipe's hand landmarks find a hand holding a phone to the
cheek, which the skin classifier keeps as face, and h leaves it out; a photo without a hand keeps its h."""

from __future__ import annotations

import cv2
import numpy as np

from deface.fit.face_region import without_hands
from deface.fit.log import FitLog
from deface.priors.occluders import HAND_BONES, HandConfig, hand_mask, reaches_in


def _open_hand(centre=(70.0, 70.0), palm=30.0) -> np.ndarray:
    """21 points of an upright open hand (MediaPipe's order): the wrist ``palm`` below ``centre``, the thumb and
    four fingers fanning upwards from it, each four points ``0.35 palm`` apart."""
    wrist = np.array(centre) + [0.0, palm]
    points = [wrist]
    for finger, angle in enumerate(np.radians([-60, -25, -8, 8, 25])):
        direction = np.array([np.sin(angle), -np.cos(angle)])
        base = wrist + direction * (0.3 * palm if finger == 0 else palm)  # the thumb's base, or the knuckle
        points += [base + direction * 0.35 * palm * step for step in range(4)]
    return np.array(points, np.float64)


def test_the_hand_covers_its_bones_and_palm_and_not_the_skin_beside_it():
    points = _open_hand()
    mask = hand_mask(points, (170, 140), HandConfig())
    for start, end in HAND_BONES:  # every bone's middle
        middle = np.round((points[start] + points[end]) / 2).astype(int)
        assert mask[middle[1], middle[0]]
    palm_centre = np.round(points[[0, 5, 9, 13, 17]].mean(0)).astype(int)
    assert mask[palm_centre[1], palm_centre[0]]
    far = np.ones(mask.shape, np.uint8)
    cv2.fillConvexPoly(far, cv2.convexHull(np.round(points).astype(np.int32)), 0)
    far = cv2.erode(far, np.ones((31, 31), np.uint8)).astype(bool)  # 15 px beyond the hull
    assert far.any() and not mask[far].any()
    wider = hand_mask(points, (170, 140), HandConfig(finger_width=0.5))
    assert wider.sum() > 1.3 * mask.sum() and (wider >= mask).all()


def test_only_a_hand_whose_wrist_is_beyond_the_face_reaches_in():
    face = np.array([[40.0, 20.0], [100.0, 20.0], [110.0, 90.0], [70.0, 130.0], [30.0, 90.0]])  # an outline
    hand = _open_hand(centre=(70.0, 70.0), palm=30.0)  # wrist at (70, 100): inside
    assert not reaches_in(hand, face, 0.0)
    assert reaches_in(hand + [0.0, 40.0], face, 0.0)  # wrist at (70, 140): 10 below the chin
    assert not reaches_in(hand + [0.0, 40.0], face, 0.1)  # the outline's box diagonal is 124: 10 is under 12.4


def test_a_hand_on_the_cheek_leaves_h_and_a_photo_without_one_keeps_it(photos):
    from deface.io.images import load_image
    from deface.landmarks.detect import detect_landmarks
    from deface.landmarks.hands import detect_hands

    image = load_image(photos / "alfw1.png")  # a hand holding a phone to her cheek
    face = detect_landmarks(image).points[:, :2]
    hands = detect_hands(image, min_confidence=HandConfig().min_confidence)
    assert len(hands) == 1 and hands[0].shape == (21, 2) and reaches_in(hands[0], face, HandConfig().wrist_beyond)
    covered = hand_mask(hands[0], image.shape[:2], HandConfig())
    h = np.ones(image.shape[:2], np.float32)
    log = FitLog(quiet=True)
    left = without_hands(h, image, face, HandConfig(), log, 0)
    assert left[covered].max() == 0.0 and left[~covered].min() == 1.0
    assert 0.02 < covered.mean() < 0.3 and any("hand" in note for note in log.notes)
    ring = np.array([190, 145])  # her ring finger's ring, on the hand
    assert covered[ring[1], ring[0]]
    assert (without_hands(h, image, face, HandConfig(enabled=False), log, 0) == h).all()
    clean = load_image(photos / "nextface-s1.png")
    assert detect_hands(clean) == []
    clean_face = detect_landmarks(clean).points[:, :2]
    assert (without_hands(np.ones(clean.shape[:2], np.float32), clean, clean_face, HandConfig(), log, 0) == 1).all()
