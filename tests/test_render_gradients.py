"""Finite-difference gradient checks (float64) through the full shading path with fixed visibility."""

from __future__ import annotations

import math

import pytest
import torch

from deface.render.camera import Camera
from deface.render.mesh import Mesh, Textures
from deface.render.primitives import grid_plane, merge, uv_sphere
from deface.render.renderer import RenderConfig, Renderer

SIZE = 28


def make_scene():
    gen = torch.Generator().manual_seed(0)
    mesh = merge(uv_sphere(1.0, 10, 20), grid_plane((-2.0, 2.0), (-2.0, 2.0), z=-1.05, cells=6))
    textures = Textures(
        diffuse=0.2 + 0.6 * torch.rand(8, 8, 3, generator=gen, dtype=torch.float64),
        specular=0.1 * torch.rand(8, 8, 3, generator=gen, dtype=torch.float64),
        roughness=0.2 + 0.5 * torch.rand(8, 8, 1, generator=gen, dtype=torch.float64),
    )
    sh = 0.3 * torch.randn(2, 9, 3, generator=gen, dtype=torch.float64)
    sh[:, 0] += 2.0
    params = {
        "focal": torch.tensor(34.0, dtype=torch.float64),
        "rotation": torch.tensor([math.pi - 0.6, 0.2, 0.1], dtype=torch.float64),
        "translation": torch.tensor([0.1, 0.2, 5.0], dtype=torch.float64),
    }
    weights = torch.rand(2, SIZE, SIZE, 3, generator=gen, dtype=torch.float64)
    return mesh, textures, sh, params, weights


class Loss:
    """Weighted sum of the rendered images with triangle ids and shadow transfer frozen at the start."""

    def __init__(self):
        self.mesh, self.textures, self.sh, self.params, self.weights = make_scene()
        self.renderer = Renderer(RenderConfig(shadow_rays=64), bands=3)
        cam = self.camera(self.params)
        self.transfer = self.renderer.shadow_transfer(self.mesh)
        self.triangle_id = self.renderer.rasterize(self.mesh, cam).triangle_id
        assert 0.2 < float((self.triangle_id >= 0).double().mean()) < 0.95
        assert float(self.transfer.occluded.abs().max()) > 0  # the sphere shadows the plane

    @staticmethod
    def camera(params) -> Camera:
        return Camera(params["focal"], params["rotation"], params["translation"], SIZE, SIZE)

    def __call__(self, vertices=None, textures=None, sh=None, params=None) -> torch.Tensor:
        vertices = self.mesh.vertices if vertices is None else vertices
        mesh = Mesh(vertices, self.mesh.triangles, self.mesh.uvs, self.mesh.triangle_uvs)
        cam = self.camera(params or self.params)
        fragments = self.renderer.fragments_for(mesh, cam, self.triangle_id)
        sh = self.sh if sh is None else sh
        out = self.renderer.shade(mesh, cam, fragments, textures or self.textures, sh, self.transfer)
        return (out.images * self.weights).sum()


@pytest.fixture(scope="module")
def loss():
    return Loss()


def strongest(grad: torch.Tensor) -> tuple[int, ...]:
    """Index of the largest-magnitude gradient entry (a texel/vertex that the image really depends on)."""
    return tuple(int(i) for i in torch.unravel_index(grad.abs().argmax(), grad.shape))


@pytest.mark.parametrize("name", ["diffuse", "specular", "roughness"])
def test_texture_texel_gradient(loss, name):
    texture = getattr(loss.textures, name).clone().requires_grad_()
    replaced = {**loss.textures.__dict__, name: texture}
    loss(textures=Textures(**replaced)).backward()
    index = strongest(texture.grad)
    assert texture.grad.abs().max() > 0

    def f(value):
        tex = getattr(loss.textures, name).clone()
        tex[index] = value
        return loss(textures=Textures(**{**loss.textures.__dict__, name: tex}))

    value = getattr(loss.textures, name)[index].clone().reshape(1).requires_grad_()
    assert torch.autograd.gradcheck(lambda v: f(v[0]), (value,), eps=1e-6, atol=1e-7, rtol=1e-5)


def test_sh_coefficient_gradient(loss):
    def f(values):
        sh = loss.sh.clone()
        sh[0, :, 1] = values
        return loss(sh=sh)

    values = loss.sh[0, :, 1].clone().requires_grad_()
    assert torch.autograd.gradcheck(f, (values,), eps=1e-6, atol=1e-7, rtol=1e-5)


def test_vertex_position_gradient(loss):
    vertices = loss.mesh.vertices.clone().requires_grad_()
    loss(vertices=vertices).backward()
    index = strongest(vertices.grad.norm(dim=1))[0]

    def f(position):
        verts = loss.mesh.vertices.clone()
        verts[index] = position
        return loss(vertices=verts)

    position = loss.mesh.vertices[index].clone().requires_grad_()
    assert torch.autograd.gradcheck(f, (position,), eps=1e-6, atol=1e-7, rtol=1e-5)


def test_camera_gradient(loss):
    def f(focal, rotation, translation):
        return loss(params={"focal": focal, "rotation": rotation, "translation": translation})

    inputs = tuple(loss.params[k].clone().requires_grad_() for k in ("focal", "rotation", "translation"))
    assert torch.autograd.gradcheck(f, inputs, eps=1e-6, atol=1e-7, rtol=1e-5)


def test_filtered_interpolation_matches_dense_and_gradcheck():
    """The sparse per-pixel specular op equals sum_i b_i sum_l lobe_l S[corner_i, l] with exact gradients."""
    from deface.render.kernels import filtered_interpolation

    reference = filtered_interpolation.reference  # the sparse torch path

    gen = torch.Generator().manual_seed(3)
    vertices, pixels, bands, channels = 7, 11, 4, 5
    values = torch.randn(vertices, bands * channels, generator=gen, dtype=torch.float64).requires_grad_()
    corners = torch.stack([torch.randperm(vertices, generator=gen)[:3] for _ in range(pixels)])
    bary = torch.rand(pixels, 3, generator=gen, dtype=torch.float64).requires_grad_()
    lobe = torch.rand(pixels, bands, generator=gen, dtype=torch.float64).requires_grad_()
    dense = (bary[:, :, None, None] * lobe[:, None, :, None]
             * values.reshape(vertices, bands, channels)[corners]).sum((1, 2))  # [N, C]
    assert torch.allclose(reference(values, corners, bary, lobe), dense, atol=1e-12)
    assert torch.autograd.gradcheck(lambda v, b, f: reference(v, corners, b, f), (values, bary, lobe))
