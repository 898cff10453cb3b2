"""The texel view and confidence map on planes seen at known angles (analytic answers)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from deface.models.uvmap import rasterize_uv
from deface.render.camera import Camera
from deface.render.mesh import Mesh
from deface.texture.confidence import combine_frames, texel_view, unwrap

SIZE_CM = 10.0  # the plane is SIZE_CM x SIZE_CM, centred on the origin, facing +z
TEXELS = 32


def plane(cells: int = 8, angle_degrees: float = 0.0, z: float = 0.0) -> Mesh:
    """A square plane with UV = its (x, y) mapped to [0, 1], turned by ``angle_degrees`` about y."""
    ticks = np.linspace(-SIZE_CM / 2, SIZE_CM / 2, cells + 1)
    x, y = np.meshgrid(ticks, ticks, indexing="xy")
    angle = math.radians(angle_degrees)
    points = np.stack([x * math.cos(angle), y, -x * math.sin(angle) + z], -1).reshape(-1, 3)
    uvs = np.stack([(x + SIZE_CM / 2) / SIZE_CM, (y + SIZE_CM / 2) / SIZE_CM], -1).reshape(-1, 2)
    index = np.arange((cells + 1) ** 2).reshape(cells + 1, cells + 1)
    a, b, c, d = index[:-1, :-1], index[:-1, 1:], index[1:, 1:], index[1:, :-1]
    triangles = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return Mesh.create(points, triangles, uvs, triangles)


DISTANCE_CM = 1000.0  # far away: perspective changes the angle across the plane by < 0.2 degrees


def camera(pixels: int) -> Camera:
    return Camera.frontal(pixels, pixels, distance=DISTANCE_CM, fov_degrees=1.0)


def view_of(mesh: Mesh, cam: Camera):
    raster = rasterize_uv(mesh.uvs.numpy(), mesh.triangle_uvs.numpy(), TEXELS)
    return raster, texel_view(raster, mesh, cam)


def face_on_density(cam: Camera) -> float:
    """Pixels per texel of the untilted plane: (focal x texel size / distance)²."""
    return (float(cam.focal) * SIZE_CM / TEXELS / DISTANCE_CM) ** 2


@pytest.mark.parametrize("angle", [0.0, 30.0, 60.0])
def test_a_finely_seen_plane_has_confidence_cos_angle(angle):
    cam = camera(512)
    assert face_on_density(cam) > 4  # fine sampling: the resolution term does not bind
    raster, view = view_of(plane(angle_degrees=angle), cam)
    inner = raster.covered.copy()
    assert view.visible[inner].all()
    np.testing.assert_allclose(view.facing[inner], math.cos(math.radians(angle)), atol=0.005)
    np.testing.assert_allclose(view.confidence()[inner], math.cos(math.radians(angle)), atol=0.005)
    # the density is the face-on density foreshortened (perspective changes it by a few percent)
    np.testing.assert_allclose(np.median(view.density[inner]),
                               face_on_density(cam) * math.cos(math.radians(angle)), rtol=0.01)


def test_a_coarsely_seen_plane_has_confidence_pixels_per_texel():
    cam = camera(32)
    expected = face_on_density(cam)
    assert expected < 0.5  # several texels share a pixel: resolution binds
    raster, view = view_of(plane(), cam)
    np.testing.assert_allclose(view.confidence()[raster.covered], expected, rtol=0.03)


def test_a_plane_facing_away_or_hidden_is_not_seen():
    cam = camera(256)
    raster, view = view_of(plane(angle_degrees=180.0), cam)  # seen from behind: facing 0
    assert view.confidence()[raster.covered].max() == 0.0
    front, back = plane(cells=4, z=5.0), plane(cells=8)
    # a smaller plane in front hides the middle of the back plane
    small = Mesh.create(front.vertices * torch.tensor([0.5, 0.5, 1.0]), front.triangles, front.uvs, front.triangle_uvs)
    both = Mesh.create(torch.cat([back.vertices, small.vertices]),
                       torch.cat([back.triangles, small.triangles + back.num_vertices]),
                       torch.cat([back.uvs, small.uvs * 0.0]),  # the small plane maps onto one UV point
                       torch.cat([back.triangle_uvs, small.triangle_uvs + back.uvs.shape[0]]))
    raster = rasterize_uv(back.uvs.numpy(), back.triangle_uvs.numpy(), TEXELS)
    view = texel_view(raster, both, cam)
    centre, corner = (TEXELS // 2, TEXELS // 2), (1, 1)
    assert not view.visible[centre] and view.visible[corner]


def test_pixel_weight_and_unwrap_read_the_image_where_the_texel_lands():
    cam = camera(128)
    raster, view = view_of(plane(), cam)
    # an image whose value is the pixel's x coordinate: unwrapping it gives each texel's projected x
    xs = np.broadcast_to((np.arange(128) + 0.5)[None, :, None], (128, 128, 1)).astype(np.float32)
    np.testing.assert_allclose(unwrap(xs, view)[..., 0][raster.covered], view.pixel[..., 0][raster.covered],
                               atol=1e-3)
    half = np.zeros((128, 128), np.float32)
    half[:, 64:] = 1.0  # the right half of the image counts
    confidence = view.confidence(half)
    right = view.pixel[..., 0] > 66
    left = view.pixel[..., 0] < 62
    assert (confidence[right & raster.covered] > 0).all() and (confidence[left & raster.covered] == 0).all()


def test_frames_combine_as_independent_looks():
    a, b = np.array([0.0, 0.5, 1.0]), np.array([0.5, 0.5, 0.2])
    np.testing.assert_allclose(combine_frames([a, b]), [0.5, 0.75, 1.0])
    np.testing.assert_allclose(combine_frames([a]), a)
