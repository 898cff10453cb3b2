"""What a fit is fitted to: the working-resolution frames (sRGB and linear RGB) and their landmarks.
The face-region classifier h and L_lan's target are added after stage 1 in :class:`deface.fit.state.FitInputs`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

from deface.fit.config import FitConfig
from deface.io.images import CLIPPED, resize_max, srgb_to_linear
from deface.landmarks.detect import Landmarks
from deface.render.renderer import RenderConfig


@dataclass(frozen=True)
class FitTarget:
    """T frames of size (W, H) and their landmarks: sRGB for classifiers/outputs, linear for the photometric
    loss. Immutable: what is derived from it after stage 1 lives in :class:`deface.fit.state.FitInputs`."""

    frames_srgb: list[np.ndarray]  # T x [H, W, 3] float32 in [0, 1]
    landmarks: list[Landmarks]  # T detections at working resolution
    scale: float  # working / original resolution
    kept_frames: list[int] | None = None  # positions of these frames among the input frames (None: all)
    images: torch.Tensor = field(init=False)  # [T, H, W, 3] linear RGB
    clipped: torch.Tensor = field(init=False)  # [T, H, W, 3] bool: channels at the encoding's top (CLIPPED)

    def __post_init__(self) -> None:
        images = torch.as_tensor(np.stack([srgb_to_linear(f) for f in self.frames_srgb]), dtype=torch.float32)
        object.__setattr__(self, "images", images)
        clipped = torch.as_tensor(np.stack([f >= CLIPPED for f in self.frames_srgb]))
        object.__setattr__(self, "clipped", clipped)

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
                            seed=config.seed, shadow_ray_offset=render.shadow_ray_offset,
                            non_negative_lights=render.non_negative_lights)


def working_frames(frames: list[np.ndarray], resolution: int) -> tuple[list[np.ndarray], float]:
    """Resize frames so the longest side is at most ``resolution``; returns frames and the scale."""
    resized = [resize_max(frame, resolution) for frame in frames]
    return [image for image, _ in resized], resized[0][1]


def scale_landmarks(landmarks: Landmarks, scale: float, size: tuple[int, int]) -> Landmarks:
    """Landmarks detected on the original frame, expressed at working resolution."""
    return Landmarks(landmarks.points * scale, landmarks.depth * scale, size, landmarks.num_faces,
                     landmarks.face_index)
