"""Pinhole camera, OpenCV convention: camera x right, y down, z forward (into the scene); pixels (x right,
y down). Pixel centres sit at integer + 0.5. The principal point (where the optical axis meets the image) is
the image centre unless the camera says otherwise: a crop of a photo keeps the photo's principal point, which
then lies off the crop's centre (:meth:`Camera.window`; the fit works on a crop around the face,
deface/fit/framing.py).

Model frame of the face models: +y up, +z toward the viewer, so a frontal camera has rotation
axis-angle (pi, 0, 0) (see :meth:`Camera.frontal`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import torch


def axis_angle_to_matrix(axis_angle: torch.Tensor) -> torch.Tensor:
    """Rodrigues' formula, [..., 3] -> [..., 3, 3]; smooth at zero angle."""
    theta2 = (axis_angle * axis_angle).sum(-1, keepdim=True)[..., None]  # [..., 1, 1]
    theta = torch.sqrt(theta2 + 1e-12)
    x, y, z = axis_angle.unbind(-1)
    zero = torch.zeros_like(x)
    skew = torch.stack([zero, -z, y, z, zero, -x, -y, x, zero], -1).reshape(*axis_angle.shape[:-1], 3, 3)
    # sin(t)/t and (1-cos t)/t^2 with Taylor fallbacks near zero to keep gradients finite.
    small = theta2 < 1e-8
    sin_term = torch.where(small, 1 - theta2 / 6, torch.sin(theta) / theta)
    cos_term = torch.where(small, 0.5 - theta2 / 24, (1 - torch.cos(theta)) / theta2.clamp_min(1e-12))
    eye = torch.eye(3, dtype=axis_angle.dtype, device=axis_angle.device).expand_as(skew)
    return eye + sin_term * skew + cos_term * (skew @ skew)


@dataclass(frozen=True)
class Camera:
    """A pinhole camera looking at model-frame points.

    focal: [] focal length in pixels; rotation: [3] axis-angle, model -> camera; translation: [3] cm;
    principal_point: (x, y) pixels, None for the image centre (width / 2, height / 2).
    """

    focal: torch.Tensor
    rotation: torch.Tensor
    translation: torch.Tensor
    width: int
    height: int
    principal_point: tuple[float, float] | None = None
    """Where the optical axis meets the image, pixels (x right, y down); None: the image centre."""
    _matrix: torch.Tensor | None = field(default=None, init=False, repr=False, compare=False)
    """The rotation matrix computed once by ``resolved`` (None: computed on each use)."""

    def resolved(self) -> Camera:
        """This camera with its rotation matrix computed once, for the calls of one render: the ~6 uses of
        the matrix in a render then share one Rodrigues evaluation (and one backward through it). Not kept
        across steps: the matrix belongs to the autograd graph and the rotation it was computed from."""
        if self._matrix is not None:
            return self
        camera = dataclasses.replace(self)
        object.__setattr__(camera, "_matrix", axis_angle_to_matrix(self.rotation))
        return camera

    @staticmethod
    def frontal(width: int, height: int, distance: float = 60.0, fov_degrees: float = 20.0) -> Camera:
        """A camera on the model's +z axis looking at the origin, upright face."""
        focal = 0.5 * height / math.tan(math.radians(fov_degrees) / 2)
        return Camera(
            focal=torch.tensor(focal),
            rotation=torch.tensor([math.pi, 0.0, 0.0]),
            translation=torch.tensor([0.0, 0.0, distance]),
            width=width,
            height=height,
        )

    @property
    def principal(self) -> tuple[float, float]:
        """(x, y) pixels of the principal point (the image centre unless ``principal_point`` is given)."""
        if self.principal_point is None:
            return self.width / 2, self.height / 2
        return float(self.principal_point[0]), float(self.principal_point[1])

    def scaled(self, factor: float, width: int | None = None, height: int | None = None) -> Camera:
        """The same view on a pixel grid ``factor`` x finer (pixel edges kept: position x -> factor x), of
        ``width`` x ``height`` pixels (default: the sizes times ``factor``, rounded). A camera centred on its
        image stays centred on the new one."""
        principal = None if self.principal_point is None else tuple(p * factor for p in self.principal_point)
        return Camera(self.focal * factor, self.rotation, self.translation,
                      round(self.width * factor) if width is None else width,
                      round(self.height * factor) if height is None else height, principal)

    def window(self, left: float, top: float, width: int, height: int) -> Camera:
        """The same view seen through a ``width`` x ``height`` window of the image whose top-left corner is
        at pixel position (``left``, ``top``) (negative, or beyond the image, for a larger window): positions
        shift by (-left, -top), the principal point with them."""
        cx, cy = self.principal
        return Camera(self.focal, self.rotation, self.translation, width, height, (cx - left, cy - top))

    def detached(self) -> Camera:
        """This camera with its tensors detached from the autograd graph."""
        return Camera(self.focal.detach(), self.rotation.detach(), self.translation.detach(), self.width,
                      self.height, self.principal_point)

    @property
    def rotation_matrix(self) -> torch.Tensor:  # [3, 3]
        return axis_angle_to_matrix(self.rotation) if self._matrix is None else self._matrix

    def to_camera(self, points: torch.Tensor) -> torch.Tensor:
        """Model-frame points [..., 3] -> camera-frame points [..., 3]."""
        return points @ self.rotation_matrix.T + self.translation

    def project(self, points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Model-frame points [..., 3] -> (pixels [..., 2] (x right, y down), depth [...] along +z)."""
        cam = self.to_camera(points)
        depth = cam[..., 2]
        centre = torch.tensor(self.principal, dtype=cam.dtype, device=cam.device)
        pixels = self.focal * cam[..., :2] / depth[..., None].clamp_min(1e-6) + centre
        return pixels, depth

    def center_in_model(self) -> torch.Tensor:
        """Camera centre in the model frame [3]."""
        return -(self.rotation_matrix.T @ self.translation)
