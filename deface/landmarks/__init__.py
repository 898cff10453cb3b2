"""Facial landmarks: MediaPipe Face Mesh detection and tracking, face choice, model correspondences."""
