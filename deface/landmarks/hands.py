"""Hands in a photo: MediaPipe Hands (palm detection, then 21 landmarks per hand), whose models ship inside the
mediapipe wheel, so it works offline like the face mesh.

A hand resting on a cheek or holding a phone to the ear is skin-coloured and lies inside the face's outline, so
the skin classifier keeps it as face; a face parser has no hand class either (CelebAMask-HQ's BiSeNet). Its
landmarks say where it is (deface/priors/occluders.py :func:`hand_mask` draws it).
"""

from __future__ import annotations

from contextlib import ExitStack

import numpy as np

from deface.landmarks.detect import _to_uint8
from deface.landmarks.quiet import native_log_filter, quiet_environment


def detect_hands(image: np.ndarray, max_hands: int = 2, min_confidence: float = 0.7) -> list[np.ndarray]:
    """The hands in ``image`` ([H, W, 3] sRGB, float in [0, 1] or uint8): one [21, 2] float32 array of pixel
    positions (x right, y down) per hand found, at most ``max_hands``: 0 the wrist, then four per finger from the
    thumb (1-4) to the little finger (17-20)."""
    pixels = _to_uint8(image)
    quiet_environment()
    with ExitStack() as stack:
        stack.enter_context(native_log_filter())
        from mediapipe.python.solutions import hands

        detector = stack.enter_context(hands.Hands(static_image_mode=True, max_num_hands=max_hands,
                                                   min_detection_confidence=min_confidence, model_complexity=1))
        found = detector.process(pixels).multi_hand_landmarks or []
    size = np.array([pixels.shape[1], pixels.shape[0]], np.float32)
    return [np.array([[p.x, p.y] for p in hand.landmark], np.float32) * size for hand in found]
