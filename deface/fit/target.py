"""What a fit is fitted to: the working frames (sRGB and linear RGB), their landmarks, and where they lie in the
input's frames (a crop around the face, deface/fit/framing.py). The face-region classifier h and L_lan's target
are added after stage 1 in :class:`deface.fit.state.FitInputs`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

from deface.fit.config import FitConfig
from deface.fit.framing import Framing, choose_framing, face_box
from deface.io.images import CLIPPED, srgb_to_linear
from deface.landmarks.detect import Landmarks


@dataclass(frozen=True)
class FitTarget:
    """T frames of size (W, H) and their landmarks: sRGB for classifiers/outputs, linear for the photometric
    loss. Immutable: what is derived from it after stage 1 lives in :class:`deface.fit.state.FitInputs`."""

    frames_srgb: list[np.ndarray]  # T x [H, W, 3] float32 in [0, 1]
    landmarks: list[Landmarks]  # T detections at working resolution
    scale: float  # working / original resolution
    kept_frames: list[int] | None = None  # positions of these frames among the input frames (None: all)
    framing: Framing | None = None  # where the frames lie in the input's (None: the whole input at ``scale``)
    scene_srgb: list[np.ndarray] | None = None  # T x [Hs, Ws, 3] the whole input frames at the working scale
    # (the illuminant's evidence, render.png's photo); None when the frames are the whole input
    light_groups: tuple[int, ...] | None = None  # per frame, the photo whose lights it uses (several photos of one
    # person, deface/fit/person.py); None: every frame shares the lights (a photo, a clip)
    images: torch.Tensor = field(init=False)  # [T, H, W, 3] linear RGB
    clipped: torch.Tensor = field(init=False)  # [T, H, W, 3] bool: channels at the encoding's top (CLIPPED)

    def __post_init__(self) -> None:
        images = torch.as_tensor(np.stack([srgb_to_linear(f) for f in self.frames_srgb]), dtype=torch.float32)
        object.__setattr__(self, "images", images)
        clipped = torch.as_tensor(np.stack([f >= CLIPPED for f in self.frames_srgb]))
        object.__setattr__(self, "clipped", clipped)
        if self.framing is None:
            object.__setattr__(self, "framing", Framing.whole(self.size, self.scale))
        if tuple(self.framing.size) != self.size:
            raise ValueError(f"FitTarget: framing of {self.framing.size} for frames of {self.size}")

    @property
    def num_frames(self) -> int:
        return len(self.frames_srgb)

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) of the working frames."""
        height, width = self.frames_srgb[0].shape[:2]
        return width, height

    @property
    def principal_point(self) -> tuple[float, float] | None:
        """(x, y) working pixels of the photo's principal point; None when it is the frames' centre (no crop)."""
        return None if self.framing.is_whole else self.framing.principal_point

    def lights_of_frames(self, per_photo: bool) -> tuple[int, ...]:
        """Per frame, the group of lights it uses: each photo's own with ``per_photo`` (``light_groups``), else
        one group (0) for every frame."""
        return self.light_groups if per_photo and self.light_groups is not None else (0,) * self.num_frames

    def scene_frames(self) -> list[np.ndarray]:
        """T x [Hs, Ws, 3] the whole input frames at the working scale (the working frames when uncropped)."""
        if self.scene_srgb is not None:
            return self.scene_srgb
        if not self.framing.is_whole:
            raise ValueError("this target is a crop without its scene (stage 2's half-size level has none)")
        return self.frames_srgb


def frame_target(frames: list[np.ndarray], landmarks: list[Landmarks], config: FitConfig,
                 kept_frames: list[int] | None = None) -> FitTarget:
    """The target of input ``frames`` (sRGB [H0, W0, 3], all of one size) whose ``landmarks`` were found on
    them: cropped around the face and resized to the working scale (deface/fit/framing.py), at most
    ``config.resolution`` pixels on the longer side (a clip of several frames: ``clip_resolution`` too)."""
    input_size = (frames[0].shape[1], frames[0].shape[0])
    box = face_box([found.points for found in landmarks], input_size) if config.crop.enabled else None
    cap = config.resolution if len(frames) == 1 else min(config.resolution, config.clip_resolution)
    framing = choose_framing(input_size, box, cap, config.crop.margin)
    scene = [framing.scene_image(frame) for frame in frames]
    crops = [framing.window(image) for image in scene]
    working = [working_landmarks(found, framing) for found in landmarks]
    return FitTarget(crops, working, framing.scale, kept_frames, framing, None if framing.is_whole else scene)


def working_landmarks(landmarks: Landmarks, framing: Framing) -> Landmarks:
    """Landmarks detected on the input frame, in the working frame's pixels."""
    points = framing.from_input(landmarks.points).astype(np.float32)
    return Landmarks(points, (landmarks.depth * framing.scale).astype(np.float32), tuple(framing.size),
                     landmarks.num_faces, landmarks.face_index)
