"""Synthetic faces with a known texture and a real cast shadow, made with the project's own renderer.

A hat brim (a plate above the forehead, out of the camera's view) occludes part of a light coming from
above the face: the shadow transfer is computed on face + brim, so the forehead is darkened by true ray
traced occlusion, while only the face is visible. Used by the end-to-end test and the synthetic benchmark:
unlike photos, the diffuse texture that should be recovered is known exactly.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import torch

from deface.io.images import linear_to_srgb
from deface.landmarks.correspondence import projection_for
from deface.landmarks.detect import Landmarks
from deface.models.base import FaceModel
from deface.render.camera import Camera
from deface.render.frame import cast_frame, shade_frame
from deface.render.mesh import Mesh, Textures
from deface.render.renderer import RenderConfig, Renderer
from deface.render.sh import sh_basis
from deface.render.shadow import ShadowTransfer

BRIM_CORNERS = np.array([[-15, 13.0, -2], [15, 13.0, -2], [15, 13.0, 17], [-15, 13.0, 17]], np.float32)  # cm


@dataclass(frozen=True)
class SyntheticFace:
    image_srgb: np.ndarray  # [H, W, 3] the shadowed photo
    landmarks: Landmarks  # exact MediaPipe-order points of the true geometry
    textures: Textures  # ground-truth UV maps
    shadow: np.ndarray  # [H, W] bool, pixels the brim darkens by more than 25 %
    uv: np.ndarray  # [H, W, 2] texture coordinates of each pixel (for scoring textures where seen)
    coverage: np.ndarray  # [H, W] render mask


def directional_sh(direction, strength: float, ambient: float, bands: int = 9, sharpness: float = 8.0):
    """[1, B*B, 3] white light: an ambient term plus a smooth lobe towards ``direction``."""
    direction = torch.tensor(direction, dtype=torch.float32)
    basis = sh_basis(direction / direction.norm(), bands)  # [B*B]
    degree = torch.tensor([int(np.floor(np.sqrt(i))) for i in range(bands * bands)], dtype=torch.float32)
    coeffs = strength * torch.exp(-(degree**2) / (2 * sharpness)) * basis
    coeffs[0] += ambient / 0.2820948  # Y_00 = 1 / (2 sqrt(pi))
    return coeffs[None, :, None].expand(1, bands * bands, 3).clone()


def make_shadowed_face(model: FaceModel, size: int = 128, seed: int = 0, rays: int = 128) -> SyntheticFace:
    """Render ``model``'s mean face with a random albedo under a light partly blocked by a hat brim."""
    generator = torch.Generator().manual_seed(seed)
    renderer = Renderer(RenderConfig(shadow_rays=rays), seed=seed)
    face = Mesh.create(model.mean_shape, model.triangles, model.uvs, model.triangle_uvs)
    camera = Camera.frontal(size, size, distance=60.0, fov_degrees=34.0)
    coeffs = 0.7 * torch.randn(model.albedo.num_coeffs, generator=generator)
    diffuse, specular = model.albedo.textures(coeffs, 128)
    textures = Textures(diffuse.clamp(0, 1), specular.clamp(0, 1), torch.full((128, 128, 1), 0.45))
    light = directional_sh((0.0, 0.8, 0.6), strength=2.0, ambient=0.25)
    with torch.no_grad():
        cast = cast_frame(renderer, face, camera, _brim_transfer(renderer, face))
        shadowed = shade_frame(renderer, cast, textures, light)
        clear = shade_frame(renderer, replace(cast, transfer=renderer.shadow_transfer(face)), textures, light)
    image = shadowed.images[0].numpy()
    coverage = shadowed.mask.numpy()
    background = np.array([0.18, 0.2, 0.16], np.float32)
    image = image * coverage[..., None] + background * (1 - coverage[..., None])
    ratio = shadowed.images[0].mean(-1) / clear.images[0].mean(-1).clamp_min(1e-6)
    shadow = (ratio.numpy() < 0.75) & (coverage > 0.5)
    return SyntheticFace(linear_to_srgb(np.clip(image, 0, 1)), true_landmarks(model, face, camera), textures,
                         shadow, shadowed.uv.numpy(), coverage)


def _brim_transfer(renderer: Renderer, face: Mesh) -> ShadowTransfer:
    """The face's shadow transfer with the brim in the scene (rows of the brim's vertices dropped)."""
    count = face.num_vertices
    vertices = torch.cat([face.vertices, torch.as_tensor(BRIM_CORNERS)])
    triangles = torch.cat([face.triangles, torch.tensor([[count, count + 1, count + 2],
                                                         [count, count + 2, count + 3]])])
    uv_ids = torch.cat([face.triangle_uvs, torch.zeros(2, 3, dtype=torch.long)])
    scene = Mesh(vertices, triangles, face.uvs, uv_ids)
    full = renderer.shadow_transfer(scene)
    # Face normals are unchanged by the disjoint brim; keep only the face's rows.
    return ShadowTransfer(full.occluded[:count], full.visibility[:count], full.vertices[:count],
                          full.bands, full.rays)


def true_landmarks(model: FaceModel, face: Mesh, camera: Camera) -> Landmarks:
    """MediaPipe-order landmarks of a posed mesh, exactly (no detector)."""
    projection = projection_for(model)
    corners = face.vertices[torch.as_tensor(model.triangles[projection.triangle_ids])]  # [478, 3, 3]
    points = (corners * torch.as_tensor(projection.barycentrics)[..., None]).sum(1)
    pixels, depth = camera.project(points)
    return Landmarks(pixels.numpy().astype(np.float32), depth.numpy().astype(np.float32),
                     (camera.width, camera.height), 1, 0)
