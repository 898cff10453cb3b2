"""Scene parameters shared by stages 2 and 3, and the per-frame geometry they produce.

Shapes: T frames, Ki identity / Ke expression / Ka albedo coefficients, n lights with B*B SH coefficients.
Shared by all frames (video): identity, albedo, lights, focal. Per frame: expression, rotation, translation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from deface.fit.config import LightConfig
from deface.models.base import FaceModel
from deface.render.camera import Camera
from deface.render.mesh import Mesh


def initial_lights(config: LightConfig) -> torch.Tensor:
    """[n, B*B, 3]: every coefficient of light i set to the paper's or the code's gamma_i."""
    n, size = config.num_lights, config.bands * config.bands
    if config.init == "paper":
        values = [2.0 * i / n - 1.0 for i in range(1, n + 1)]  # gamma_i = 2(i/n) - 1, i = 1..n
    else:
        scale = config.init_scale
        values = [-scale + 2.0 * scale * (i + 1) / n for i in range(n)]  # -L + 2L(i+1)/n, i = 0..n-1
    return torch.tensor(values, dtype=torch.float32)[:, None, None].expand(n, size, 3).clone()


class SceneParameters(torch.nn.Module):
    """All optimisable face/camera/light coefficients of one fit."""

    def __init__(self, identity: torch.Tensor, expression: torch.Tensor, rotation: torch.Tensor,
                 translation: torch.Tensor, focal: torch.Tensor, albedo: torch.Tensor, lights: torch.Tensor,
                 tone: float = 0.0):
        super().__init__()
        self.identity = torch.nn.Parameter(identity.float().clone())  # [Ki]
        self.expression = torch.nn.Parameter(expression.float().clone())  # [T, Ke]
        self.rotation = torch.nn.Parameter(rotation.float().clone())  # [T, 3] axis-angle
        self.translation = torch.nn.Parameter(translation.float().clone())  # [T, 3] cm
        self.focal = torch.nn.Parameter(focal.float().clone().reshape(()))  # [] pixels
        self.albedo = torch.nn.Parameter(albedo.float().clone())  # [Ka]
        self.lights = torch.nn.Parameter(lights.float().clone())  # [n, B*B, 3]
        self.tone = torch.nn.Parameter(torch.tensor(float(tone)))  # [] skin tone, ITA degrees (tone axis)

    @property
    def num_frames(self) -> int:
        return int(self.expression.shape[0])

    def camera(self, frame: int, width: int, height: int, pixel_scale: float = 1.0,
               principal_point: tuple[float, float] | None = None) -> Camera:
        """The frame's camera for a (width, height) image of ``pixel_scale`` pixels per working pixel whose
        principal point is ``principal_point`` (its pixels; None: the image centre)."""
        focal = self.focal if pixel_scale == 1.0 else self.focal * pixel_scale
        return Camera(focal, self.rotation[frame], self.translation[frame], width, height, principal_point)

    def clamp_(self, expression_prior: str) -> None:
        """Keep blendshape weights in [0, 1] after each step (projected gradient)."""
        if expression_prior == "blendshape":
            with torch.no_grad():
                self.expression.clamp_(0.0, 1.0)


@dataclass(frozen=True)
class FrameGeometry:
    """One frame's posed mesh and camera."""

    mesh: Mesh
    camera: Camera

    def moves_uvs(self, model_uvs) -> bool:
        """Whether this frame samples the maps elsewhere than the model's UVs [U, 2] (moved into register)."""
        return not np.allclose(self.mesh.uvs.detach().numpy(), model_uvs, atol=1e-7)

    def with_uvs(self, uvs: torch.Tensor) -> FrameGeometry:
        """The same frame sampling the maps at ``uvs`` [U, 2] (moved into register: deface/fit/frame_register.py)."""
        mesh = self.mesh
        return FrameGeometry(Mesh(mesh.vertices, mesh.triangles, uvs, mesh.triangle_uvs), self.camera)


def frame_geometry(model: FaceModel, scene: SceneParameters, topology: dict, frame: int,
                   size: tuple[int, int], pixel_scale: float = 1.0,
                   principal_point: tuple[float, float] | None = None) -> FrameGeometry:
    """The mesh (model frame) and camera of ``frame`` drawn at ``size`` (``pixel_scale`` pixels per working
    pixel, principal point ``principal_point``, None: the centre); ``topology`` holds the model's index
    tensors."""
    vertices = model.vertices(scene.identity, scene.expression[frame])
    mesh = Mesh(vertices, topology["triangles"], topology["uvs"], topology["triangle_uvs"])
    return FrameGeometry(mesh, scene.camera(frame, *size, pixel_scale, principal_point))


def topology_tensors(model: FaceModel) -> dict:
    return {
        "triangles": torch.as_tensor(model.triangles, dtype=torch.long),
        "uvs": torch.as_tensor(model.uvs, dtype=torch.float32),
        "triangle_uvs": torch.as_tensor(model.triangle_uvs, dtype=torch.long),
    }
