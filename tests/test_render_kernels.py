"""The numba kernels (fast CPU path) against the torch reference path: values and gradients, float64."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from test_render_gradients import Loss

from deface.render import kernels
from deface.render.camera import Camera
from deface.render.mesh import sample_texture
from deface.render.primitives import uv_sphere
from deface.render.renderer import (
    RenderConfig,
    Renderer,
    _filtered_interpolation,
    _pixel_rays,
    _specular_bands,
    vertex_irradiance,
)
from deface.render.sh import sh_basis_rows

pytestmark = pytest.mark.skipif(kernels.numba is None, reason="numba is not installed")


def both_paths(fn):
    """fn() under the numba kernels and under the torch reference path."""
    with kernels.backend("numba"):
        fast = fn()
    with kernels.backend("torch"):
        reference = fn()
    return fast, reference


def assert_close(fast, reference, rtol=1e-10, atol=1e-12):
    for a, b in zip(fast, reference, strict=True):
        torch.testing.assert_close(a, b, rtol=rtol, atol=atol)


def values_and_grads(fn, inputs):
    """fn(*inputs) and the gradients of a fixed random projection of it to every input."""
    inputs = [x.detach().clone().requires_grad_() for x in inputs]
    out = fn(*inputs)
    weights = torch.rand(out.shape, generator=torch.Generator().manual_seed(1), dtype=out.dtype)
    grads = torch.autograd.grad((out * weights).sum(), inputs)
    return [out.detach(), *grads]


def test_sh_basis_matches_reference_up_to_18_bands():
    gen = torch.Generator().manual_seed(0)
    dirs = torch.nn.functional.normalize(torch.randn(300, 3, generator=gen, dtype=torch.float64), dim=1)
    dirs[0] = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)  # a pole
    for bands in (1, 2, 9, 18):
        assert_close(*both_paths(lambda b=bands: values_and_grads(lambda d: sh_basis_rows(d, b), [dirs])))


def test_filtered_interpolation_matches_sparse_reference():
    gen = torch.Generator().manual_seed(0)
    values = torch.randn(40, 4 * 6, generator=gen, dtype=torch.float64)  # U = 40, B = 4, C = 6
    corners = torch.randint(0, 40, (300, 3), generator=gen)
    bary = torch.rand(300, 3, generator=gen, dtype=torch.float64)
    lobe = torch.rand(300, 4, generator=gen, dtype=torch.float64)

    def run():
        return values_and_grads(lambda v, b, f: _filtered_interpolation(v, corners, b, f), [values, bary, lobe])

    assert_close(*both_paths(run))


def test_specular_band_sums_match_reference_with_camera_gradients():
    """Mirrored view directions and their band sums, with gradients to positions, normals and the camera pose."""
    gen = torch.Generator().manual_seed(0)
    positions = torch.randn(60, 3, generator=gen, dtype=torch.float64)
    normals = torch.nn.functional.normalize(torch.randn(60, 3, generator=gen, dtype=torch.float64), dim=1)
    coeffs = torch.randn(16, 6, generator=gen, dtype=torch.float64)
    rotation = torch.tensor([3.0, 0.1, -0.2], dtype=torch.float64)
    translation = torch.tensor([0.2, -0.1, 8.0], dtype=torch.float64)
    focal = torch.tensor(30.0, dtype=torch.float64)

    def bands(x, n, c, r, t):
        return _specular_bands(x, n, Camera(focal, r, t, 32, 32), c, 4)

    inputs = [positions, normals, coeffs, rotation, translation]
    assert_close(*both_paths(lambda: values_and_grads(bands, inputs)))


def test_vertex_normals_match_reference():
    loss = Loss()
    mesh = loss.mesh

    def normals(vertices):
        return type(mesh)(vertices, mesh.triangles, mesh.uvs, mesh.triangle_uvs).vertex_normals()

    assert_close(*both_paths(lambda: values_and_grads(normals, [mesh.vertices])))


def test_primary_rays_only_in_triangle_boxes_find_the_same_triangles():
    """Tracing only pixels inside some triangle's projected box misses no hit (same ids as the whole box)."""
    loss = Loss()
    for params in (loss.params, {**loss.params, "focal": torch.tensor(90.0, dtype=torch.float64)}):
        fast, reference = both_paths(lambda p=params: [loss.renderer.rasterize(loss.mesh, loss.camera(p)).triangle_id])
        assert torch.equal(fast[0], reference[0]) and bool((fast[0] >= 0).any())


def test_bilinear_lookup_matches_grid_sample_inside_and_at_the_border():
    gen = torch.Generator().manual_seed(0)
    texture = torch.rand(7, 5, 3, generator=gen, dtype=torch.float64)
    uv = torch.rand(400, 2, generator=gen, dtype=torch.float64) * 1.4 - 0.2  # 30% outside [0, 1]: clamped
    assert_close(*both_paths(lambda: values_and_grads(sample_texture, [texture, uv])))


def test_render_values_and_gradients_match_reference():
    """The whole shading path (fixed visibility and transfer) with every kernel against the torch path."""
    loss = Loss()
    inputs = [loss.mesh.vertices, loss.textures.diffuse, loss.textures.roughness, loss.sh, loss.params["focal"]]

    def run():
        def render(vertices, diffuse, roughness, sh, focal):
            textures = type(loss.textures)(diffuse, loss.textures.specular, roughness)
            return loss(vertices=vertices, textures=textures, sh=sh, params={**loss.params, "focal": focal})

        return values_and_grads(render, inputs)

    assert_close(*both_paths(run))


def test_every_screen_buffer_and_its_gradients_match_reference():
    """The fused pixel kernel writes all RenderOutput buffers; each one's gradients match the torch path."""
    loss = Loss()
    cam = loss.camera(loss.params)
    fragments = loss.renderer.fragments_for(loss.mesh, cam, loss.triangle_id)
    textures = loss.textures
    inputs = [loss.mesh.vertices, textures.diffuse, textures.specular, textures.roughness, loss.sh]
    names = ("images", "uv", "normals", "depth", "diffuse", "specular", "roughness")

    def run():
        def buffers(vertices, diffuse, specular, roughness, sh):
            mesh = type(loss.mesh)(vertices, loss.mesh.triangles, loss.mesh.uvs, loss.mesh.triangle_uvs)
            frags = loss.renderer.fragments_for(mesh, cam, fragments.triangle_id)
            out = loss.renderer.shade(mesh, cam, frags, type(textures)(diffuse, specular, roughness), sh, loss.transfer)
            return torch.cat([getattr(out, name).reshape(-1) for name in names])

        return values_and_grads(buffers, inputs)

    assert_close(*both_paths(run))


def test_kernels_are_deterministic_and_independent_of_the_thread_count():
    """Gradients gathered per vertex / per block: 1 and 2 threads give bit-identical results."""
    loss = Loss()
    inputs = [loss.mesh.vertices, loss.textures.diffuse, loss.sh]

    def run():
        def render(vertices, diffuse, sh):
            textures = type(loss.textures)(diffuse, loss.textures.specular, loss.textures.roughness)
            return loss(vertices=vertices, textures=textures, sh=sh)

        return values_and_grads(render, inputs)

    threads = torch.get_num_threads()
    try:
        torch.set_num_threads(1)
        serial, again = run(), run()
        torch.set_num_threads(2)
        parallel = run()
    finally:
        torch.set_num_threads(threads)
    for a, b, c in zip(serial, again, parallel, strict=True):
        assert torch.equal(a, b) and torch.equal(a, c)


def test_renderer_float32_close_to_reference():
    """The production dtype: the fast path stays within float32 rounding of the reference."""
    loss = Loss()
    mesh = type(loss.mesh)(
        loss.mesh.vertices.float(), loss.mesh.triangles, loss.mesh.uvs.float(), loss.mesh.triangle_uvs
    )
    textures = type(loss.textures)(
        *(t.float() for t in (loss.textures.diffuse, loss.textures.specular, loss.textures.roughness))
    )
    camera = loss.camera({k: v.float() for k, v in loss.params.items()})
    renderer = Renderer(RenderConfig(bands=3, shadows=False))

    def run():
        return [renderer.render(mesh, camera, textures, loss.sh.float()).images]

    assert_close(*both_paths(run), rtol=1e-4, atol=1e-5)


def test_vertex_normals_follow_in_place_edits_of_the_triangles():
    """The kernels keep the per-vertex corner lists of the last triangles tensor; after an in-place edit
    that changes which vertices each triangle uses, values and gradients must still match the reference."""
    sphere = uv_sphere(1.0, 8, 16)
    vertices = sphere.vertices.detach().clone()

    def normals_and_grads():
        return values_and_grads(
            lambda v: type(sphere)(v, sphere.triangles, sphere.uvs, sphere.triangle_uvs).vertex_normals(), [vertices]
        )

    normals_and_grads()  # fills the cache for this triangles tensor
    sphere.triangles[:] = torch.roll(sphere.triangles, 1, dims=0).clone()  # other vertices at each slot
    assert_close(*both_paths(normals_and_grads))


def test_primary_ray_directions_match_the_numpy_path():
    """The numba loop building Embree's primary rays gives numpy's unit directions (float32 rounding)."""
    cam = Camera(
        focal=torch.tensor(150.0),
        rotation=torch.tensor([3.0, 0.4, -0.2]),
        translation=torch.tensor([0.5, -1.0, 40.0]),
        width=120,
        height=90,
    )
    flat = np.arange(0, 120 * 90, 7)

    def rays():
        return [torch.from_numpy(np.ascontiguousarray(a)) for a in _pixel_rays(cam, flat)]

    fast, reference = both_paths(rays)
    torch.testing.assert_close(fast[0], reference[0])
    torch.testing.assert_close(fast[1], reference[1], rtol=0, atol=1e-6)
    torch.testing.assert_close(fast[1].norm(dim=1), torch.ones(len(flat)), rtol=0, atol=1e-6)


def test_shadowed_vertex_irradiance_matches_the_reference_path():
    """The fused irradiance kernel (basis, shadowed transfer, product with the lights) on every vertex,
    values and gradients to vertices and lights, against the torch path."""
    loss = Loss()

    def run():
        def irradiance(vertices, sh):
            mesh = type(loss.mesh)(vertices, loss.mesh.triangles, loss.mesh.uvs, loss.mesh.triangle_uvs)
            return vertex_irradiance(mesh, sh, loss.transfer)

        return values_and_grads(irradiance, [loss.mesh.vertices, loss.sh])

    fast, reference = both_paths(run)
    assert_close(fast, reference)
    assert float(fast[0].abs().max()) > 0 and float(fast[1].abs().max()) > 0
