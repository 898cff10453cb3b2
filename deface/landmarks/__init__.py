"""Facial landmarks: MediaPipe Face Mesh detection and tracking, face choice, model correspondences."""

from deface.landmarks.correspondence import Correspondence, correspondence_for, model_landmarks
from deface.landmarks.detect import Landmarks, NoFaceError, detect_landmarks, track_video

__all__ = [
    "Correspondence",
    "Landmarks",
    "NoFaceError",
    "correspondence_for",
    "detect_landmarks",
    "model_landmarks",
    "track_video",
]
