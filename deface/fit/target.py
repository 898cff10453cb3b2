"""What a fit is fitted to: the working-resolution frames (linear RGB), their landmarks, and the
face-region classifier's output h per frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

from deface.fit.config import FitConfig
from deface.io.images import resize_max, srgb_to_linear
from deface.landmarks.correspondence import model_landmarks
from deface.landmarks.detect import Landmarks
from deface.losses.landmarks import landmark_loss
from deface.render.renderer import RenderConfig


@dataclass
class FitTarget:
    """T frames of size (W, H): sRGB for classifiers/outputs, linear for the photometric loss."""

    frames_srgb: list[np.ndarray]  # T x [H, W, 3] float32 in [0, 1]
    landmarks: list[Landmarks]  # T detections at working resolution
    scale: float  # working / original resolution
    face_classifier: list[torch.Tensor | None] = field(default_factory=list)  # T x [H, W] h, set later
    kept_frames: list[int] | None = None  # positions of these frames among the input frames (None: all)
    images: torch.Tensor = field(init=False)  # [T, H, W, 3] linear RGB

    def __post_init__(self) -> None:
        self.images = torch.as_tensor(np.stack([srgb_to_linear(f) for f in self.frames_srgb]), dtype=torch.float32)
        if not self.face_classifier:
            self.face_classifier = [None] * len(self.frames_srgb)

    def attach_landmarks(self, corr, stage1) -> None:
        """Keep the correspondence and the detected points in its order for stage 2's L_lan."""
        self.correspondence = corr
        self.detected = torch.as_tensor(stage1.landmarks_2d, dtype=torch.float32)  # [T, N, 2]
        self.landmark_weights = torch.as_tensor(corr.weights, dtype=torch.float32)  # [N]

    def landmark_loss(self, geometry, frame: int) -> torch.Tensor:
        """L_lan as in the authors' code: weighted mean squared pixel distance of the projected points
        of ``geometry`` (the frame's posed mesh and camera)."""
        points, _ = geometry.camera.project(model_landmarks(geometry.mesh.vertices, self.correspondence))
        return landmark_loss(points, self.detected[frame], 1.0, self.landmark_weights, squared=True)

    @property
    def num_frames(self) -> int:
        return len(self.frames_srgb)

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) of the working frames."""
        height, width = self.frames_srgb[0].shape[:2]
        return width, height

    @staticmethod
    def render_config(config: FitConfig) -> RenderConfig:
        render = config.render
        return RenderConfig(bands=config.lights.bands, shadows=render.shadows, shadow_rays=render.shadow_rays,
                            specular=render.specular, shadow_tolerance_cm=render.shadow_tolerance_cm,
                            seed=config.seed, shadow_ray_offset=render.shadow_ray_offset)


def working_frames(frames: list[np.ndarray], resolution: int) -> tuple[list[np.ndarray], float]:
    """Resize frames so the longest side is at most ``resolution``; returns frames and the scale."""
    resized = [resize_max(frame, resolution) for frame in frames]
    return [image for image, _ in resized], resized[0][1]


def scale_landmarks(landmarks: Landmarks, scale: float, size: tuple[int, int]) -> Landmarks:
    """Landmarks detected on the original frame, expressed at working resolution."""
    return Landmarks(landmarks.points * scale, landmarks.depth * scale, size, landmarks.num_faces,
                     landmarks.face_index)
