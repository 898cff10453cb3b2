"""How well a photo constrains each texel: the texel's view from the camera, and the confidence map.

Each texel centre of the UV layout lies on one triangle (:func:`deface.models.uvmap.rasterize_uv`); with the
fitted mesh that gives it a 3-D point and a normal. Seen from the frame's camera the texel has
- ``visible``: the point is in the image and the first surface a camera ray meets (Embree, as the renderer);
- ``facing``: cos of the angle between its normal and the direction to the camera (foreshortening);
- ``density``: pixels per texel, the projected area of its triangle over the triangle's area in texels
  (it already includes the foreshortening: density = facing x pixels per texel seen face-on);
- ``pixel``: where it lands in the image, to read per-pixel quantities there.

The confidence of a texel in one frame is

    c = visible x weight(pixel) x min(facing, density)  =  visible x weight x facing x min(1, face-on density)

with ``weight`` a per-pixel factor in [0, 1] (the fit uses face region h x the fraction of the light that is
not cast-shadowed). A texel seen head-on with at least one pixel of its own gets 1; at 2 texels per pixel 0.5;
at a grazing angle cos(angle). Frames combine as independent looks: 1 - prod(1 - c_f).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from deface.models.uvmap import UVRaster
from deface.render.camera import Camera
from deface.render.mesh import Mesh
from deface.render.raycast import RayScene

VISIBILITY_TOLERANCE_CM = 0.05  # a ray that stops this close before the texel's point still sees it


@dataclass(frozen=True)
class TexelView:
    """One camera's view of every texel of an [Ht, Wt] map (zeros where the layout has no texel)."""

    visible: np.ndarray  # [Ht, Wt] bool, in the image and not occluded
    facing: np.ndarray  # [Ht, Wt] float, cos(normal, direction to the camera), clipped at 0
    density: np.ndarray  # [Ht, Wt] float, pixels per texel (projected area)
    pixel: np.ndarray  # [Ht, Wt, 2] float, image position (x right, y down; pixel centres at +0.5)

    def confidence(self, pixel_weight: np.ndarray | None = None) -> np.ndarray:
        """[Ht, Wt] in [0, 1]: visible x weight(pixel) x min(facing, density); pixel_weight [H, W] or None (1)."""
        return self._weighted(np.minimum(self.facing, self.density), pixel_weight)

    def seen(self, pixel_weight: np.ndarray | None = None) -> np.ndarray:
        """[Ht, Wt] in [0, 1]: visible x weight(pixel) x facing, whether the texel was seen at all, at any
        resolution (what texture completion and the UV measure go by)."""
        return self._weighted(self.facing, pixel_weight)

    def _weighted(self, quality: np.ndarray, pixel_weight: np.ndarray | None) -> np.ndarray:
        quality = quality * self.visible
        if pixel_weight is not None:
            quality = quality * unwrap(pixel_weight[..., None], self)[..., 0]
        return np.clip(quality, 0.0, 1.0).astype(np.float32)


def texel_view(raster: UVRaster, mesh: Mesh, camera: Camera, scene: RayScene | None = None) -> TexelView:
    """The view of ``camera`` [W x H] on the texels of ``raster`` (the layout of ``mesh``'s UVs)."""
    covered = raster.covered
    tri = raster.triangle[covered]  # [N]
    bary = torch.as_tensor(raster.barycentric[covered], dtype=torch.float64)  # [N, 3]
    vertices = mesh.vertices.detach().double()
    corners = vertices[mesh.triangles[tri]]  # [N, 3, 3]
    points = (bary[..., None] * corners).sum(1)
    normals = (bary[..., None] * mesh.vertex_normals().detach().double()[mesh.triangles[tri]]).sum(1)
    normals = normals / normals.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    camera = _double(camera)
    centre = camera.center_in_model()
    to_camera = centre - points
    distance = to_camera.norm(dim=-1)
    facing = ((normals * to_camera).sum(-1) / distance).clamp_min(0)
    pixels, depth = camera.project(points)
    density = triangle_density(mesh, camera, raster.triangle.shape)[tri]
    inside = (depth > 0) & (pixels[:, 0] >= 0) & (pixels[:, 0] < camera.width)
    inside &= (pixels[:, 1] >= 0) & (pixels[:, 1] < camera.height)
    scene = scene or RayScene(vertices.float().numpy(), mesh.triangles.numpy())
    seen = inside.numpy() & _unoccluded(scene, centre, points, distance)
    return TexelView(*_scatter(covered, seen, facing.numpy(), density.numpy(), pixels.numpy()))


def combine_frames(confidences: list[np.ndarray]) -> np.ndarray:
    """Confidence of several frames' looks at each texel: 1 - prod(1 - c_f)."""
    missed = np.ones_like(confidences[0])
    for confidence in confidences:
        missed = missed * (1.0 - confidence)
    return (1.0 - missed).astype(np.float32)


def unwrap(image: np.ndarray, view: TexelView) -> np.ndarray:
    """An image [H, W, C] read at each visible texel's pixel (bilinear) -> [Ht, Wt, C], 0 where not visible."""
    height, width = image.shape[:2]
    grid = torch.as_tensor(view.pixel, dtype=torch.float32).clone()
    grid[..., 0] = grid[..., 0] / width * 2 - 1  # align_corners=False: pixel centres at +0.5
    grid[..., 1] = grid[..., 1] / height * 2 - 1
    planes = torch.as_tensor(np.ascontiguousarray(image), dtype=torch.float32).permute(2, 0, 1)[None]
    sampled = torch.nn.functional.grid_sample(planes, grid[None], mode="bilinear", padding_mode="border",
                                              align_corners=False)[0].permute(1, 2, 0).numpy()
    return sampled * view.visible[..., None]


def _double(camera: Camera) -> Camera:
    return Camera(camera.focal.detach().double(), camera.rotation.detach().double(),
                  camera.translation.detach().double(), camera.width, camera.height, camera.principal_point)


def triangle_density(mesh: Mesh, camera: Camera, texture_shape: tuple[int, int]) -> torch.Tensor:
    """[F] float64 pixels per texel of each triangle of an [Ht, Wt] map: projected area (px²) over UV area
    (texels²)."""
    pixels, _ = _double(camera).project(mesh.vertices.detach().double())
    screen = _area(pixels[mesh.triangles])
    uv = mesh.uvs.double() * torch.tensor([texture_shape[1], texture_shape[0]], dtype=torch.float64)
    texels = _area(uv[mesh.triangle_uvs])
    return screen / texels.clamp_min(1e-12)


def _area(corners: torch.Tensor) -> torch.Tensor:
    """Unsigned area of 2-D triangles [F, 3, 2]."""
    a, b = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    return 0.5 * (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).abs()


def _unoccluded(scene: RayScene, centre: torch.Tensor, points: torch.Tensor, distance: torch.Tensor) -> np.ndarray:
    """Whether the first hit of the ray from the camera centre towards each point is (about) the point."""
    directions = ((points - centre) / distance[:, None]).numpy()
    origins = np.broadcast_to(centre.numpy(), directions.shape)
    _, hit = scene.intersect(origins, directions)
    return hit >= distance.numpy() - VISIBILITY_TOLERANCE_CM


def _scatter(covered: np.ndarray, seen: np.ndarray, facing, density, pixels):
    """Per-covered-texel values -> full [Ht, Wt] maps, zero where a texel is not seen."""
    shape = covered.shape
    visible = np.zeros(shape, bool)
    visible[covered] = seen
    maps = []
    for values in (facing, density):
        full = np.zeros(shape, np.float32)
        full[covered] = np.where(seen, values, 0.0)
        maps.append(full)
    pixel = np.zeros((*shape, 2), np.float32)
    pixel[covered] = pixels
    return visible, maps[0], maps[1], pixel
