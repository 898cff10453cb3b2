"""Renderer against analytic references: ray-sphere / ray-plane visibility, unshadowed sphere irradiance."""

from __future__ import annotations

import math

import numpy as np
import torch

from deface.render import kernels
from deface.render.camera import Camera
from deface.render.frame import render_frame
from deface.render.mesh import Textures
from deface.render.primitives import grid_plane, uv_sphere
from deface.render.raycast import RayScene
from deface.render.renderer import RenderConfig, Renderer
from deface.render.sh import sh_basis

SIZE = 96


def camera(rotation=(math.pi, 0.0, 0.0), translation=(0.0, 0.0, 5.0), size=SIZE, focal=110.0) -> Camera:
    """A float64 camera (OpenCV convention) looking down -z of the model frame by default."""
    return Camera(
        focal=torch.tensor(focal, dtype=torch.float64),
        rotation=torch.tensor(rotation, dtype=torch.float64),
        translation=torch.tensor(translation, dtype=torch.float64),
        width=size,
        height=size,
    )


def pixel_rays(cam: Camera) -> tuple[np.ndarray, np.ndarray]:
    """Our own pixel rays (model frame): origin [3], unit directions [H, W, 3]."""
    ys, xs = np.meshgrid(np.arange(cam.height) + 0.5, np.arange(cam.width) + 0.5, indexing="ij")
    f = float(cam.focal)
    d_cam = np.stack([(xs - cam.width / 2) / f, (ys - cam.height / 2) / f, np.ones_like(xs)], -1)
    rot = cam.rotation_matrix.double().numpy()
    d = d_cam @ rot
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    origin = -rot.T @ cam.translation.double().numpy()
    return origin, d


def ray_sphere(origin: np.ndarray, dirs: np.ndarray, radius: float) -> np.ndarray:
    """Distance to the first hit of a sphere at the origin, nan on a miss."""
    b = dirs @ origin
    disc = b**2 - (origin @ origin - radius**2)
    return np.where(disc >= 0, -b - np.sqrt(np.maximum(disc, 0)), np.nan)


def lobe_by_quadrature(bands: int) -> np.ndarray:
    """A_l = 2 pi ∫_0^1 t P_l(t) dt per coefficient (independent of sh.cosine_lobe_coefficients)."""
    t, w = np.polynomial.legendre.leggauss(100)
    t, w = 0.5 * (t + 1), 0.5 * w
    values = [2 * np.pi * np.sum(w * t * np.polynomial.legendre.Legendre.basis(l)(t)) for l in range(bands)]
    return np.repeat(values, [2 * l + 1 for l in range(bands)])


def random_light(bands: int, seed: int, lights: int = 2) -> torch.Tensor:
    gen = torch.Generator().manual_seed(seed)
    sh = 0.25 * torch.randn(lights, bands * bands, 3, generator=gen, dtype=torch.float64)
    sh[:, 0] = 3.0  # keeps the irradiance well above zero, so relative errors are meaningful
    return sh


def test_sphere_depth_and_mask_match_ray_sphere():
    radius, cam = 1.0, camera()
    out = render_frame(Renderer(RenderConfig(shadows=False, specular=False)), uv_sphere(radius, 48, 96), cam,
                       Textures.constant(4, dtype=torch.float64), random_light(3, 0))
    origin, dirs = pixel_rays(cam)
    t = ray_sphere(origin, dirs, radius)
    hit = ~np.isnan(t)
    grazing = np.abs(ray_sphere(origin, dirs, radius * 0.98) - ray_sphere(origin, dirs, radius * 1.02))
    interior = ~np.isnan(ray_sphere(origin, dirs, radius * 0.97))
    exterior = np.isnan(ray_sphere(origin, dirs, radius * 1.01))
    mask = out.mask.numpy() > 0
    assert mask[interior].all() and not mask[exterior].any()
    assert hit.sum() > 1000 and np.isfinite(grazing).sum() > 0
    # camera-frame depth of the analytic hit vs the rendered depth (the mesh is a chordal polyhedron)
    d_cam = dirs @ cam.rotation_matrix.double().numpy().T
    analytic_depth = t * d_cam[..., 2]
    sag = radius * (1 - math.cos(math.pi / 48))
    np.testing.assert_allclose(out.depth.numpy()[interior], analytic_depth[interior], atol=1.5 * sag)
    assert np.all(out.depth.numpy()[~mask] == 0) and np.all(out.triangle_id.numpy()[~mask] == -1)


def test_plane_triangle_ids_and_depth_match_ray_plane():
    plane = grid_plane((-1.0, 1.0), (-1.0, 1.0), z=0.0, cells=1)  # triangles [a,b,c] and [a,c,d]
    cam = camera(rotation=(math.pi + 0.4, 0.3, 0.1), translation=(0.1, -0.2, 4.0))
    fragments = Renderer().rasterize(plane, cam)
    origin, dirs = pixel_rays(cam)
    t = -origin[2] / dirs[..., 2]
    hit = origin + t[..., None] * dirs
    x, y = hit[..., 0], hit[..., 1]
    inside = (np.abs(x) < 1) & (np.abs(y) < 1) & (t > 0)
    expected = np.where(inside, np.where(x > y, 0, 1), -1)  # a=(-1,-1), c=(1,1): triangle 0 is below y=x
    margin = (np.abs(np.abs(x) - 1) > 1e-3) & (np.abs(np.abs(y) - 1) > 1e-3) & (np.abs(x - y) > 1e-3)
    tid = fragments.triangle_id.numpy()
    np.testing.assert_array_equal(tid[margin], expected[margin])
    assert inside.sum() > 2000
    out = Renderer(RenderConfig(shadows=False)).shade(
        plane, cam, fragments, Textures.constant(4, dtype=torch.float64), random_light(2, 1), None
    )
    d_cam = dirs @ cam.rotation_matrix.double().numpy().T
    sel = inside & margin
    np.testing.assert_allclose(out.depth.numpy()[sel], (t * d_cam[..., 2])[sel], rtol=1e-9)
    # perspective-correct UVs: u = (x + 1) / 2, v = (y + 1) / 2 on this plane
    np.testing.assert_allclose(out.uv.numpy()[sel], np.stack([x + 1, y + 1], -1)[sel] / 2, atol=1e-9)


def test_unshadowed_diffuse_sphere_matches_analytic_irradiance():
    radius, cam, bands = 1.0, camera(rotation=(math.pi - 0.5, 0.4, 0.0)), 9
    sh = random_light(bands, 2)
    albedo = 0.7
    textures = Textures.constant(4, diffuse=(albedo,) * 3, dtype=torch.float64)
    # The analytic reference is linear in the SH light; the clamp of negative radiance is tested in test_render_sh.
    renderer = Renderer(RenderConfig(shadows=False, specular=False, non_negative_lights=False), bands=bands)
    out = render_frame(renderer, uv_sphere(radius, 48, 96), cam, textures, sh)
    origin, dirs = pixel_rays(cam)
    t = ray_sphere(origin, dirs, radius)
    normal = (origin + t[..., None] * dirs) / radius
    facing = -(normal * dirs).sum(-1)  # cos between the normal and the view ray
    keep = facing > 0.3  # away from the rim (nan compares False)
    y = sh_basis(torch.tensor(normal[keep]), bands).numpy()  # [P, B²]
    irradiance = np.einsum("pj,kjc->kpc", y * lobe_by_quadrature(bands), sh.numpy())
    expected = albedo / np.pi * irradiance
    rendered = out.images.numpy()[:, keep]
    assert irradiance.min() > 1.0 and keep.sum() > 1000
    rel = np.abs(rendered - expected) / expected
    assert rel.max() < 0.01, f"max relative error {rel.max():.4f}"
    print(f"max relative error {rel.max():.5f}")


def test_convex_sphere_has_no_self_shadow_and_constant_light_gives_albedo():
    sphere = uv_sphere(1.0, 24, 48)
    renderer = Renderer(RenderConfig(shadow_rays=64), bands=3)
    transfer = renderer.shadow_transfer(sphere)
    assert float(transfer.occluded.abs().max()) == 0.0 and float(transfer.visibility.min()) == 1.0
    # constant radiance L: diffuse albedo * L + specular k_s * L, for any roughness
    sh = torch.zeros(1, 9, 3, dtype=torch.float64)
    sh[0, 0] = 2.0 * math.sqrt(4 * math.pi)
    textures = Textures.constant(
        4, diffuse=(0.3, 0.5, 0.7), specular=(0.1, 0.2, 0.05), roughness=0.3, dtype=torch.float64
    )
    out = render_frame(renderer, sphere, camera(), textures, sh, transfer)
    expected = 2.0 * (torch.tensor([0.3, 0.5, 0.7]) + torch.tensor([0.1, 0.2, 0.05])).double()
    covered = out.mask > 0
    np.testing.assert_allclose(
        out.images[0][covered].numpy(), expected.expand(int(covered.sum()), 3).numpy(), rtol=1e-6
    )
    assert torch.all(out.images[0][~covered] == 0)


def test_ray_batches_split_across_threads_give_the_single_thread_answers():
    """Embree batches are traced in chunks on several threads; every query answers as on one thread."""
    sphere = uv_sphere(1.0, 24, 48)
    scene = RayScene(sphere.vertices.numpy(), sphere.triangles.numpy())
    gen = np.random.default_rng(0)
    origins = gen.normal(size=(20000, 3)) * 3.0
    directions = -origins + gen.normal(size=origins.shape)  # roughly towards the sphere: hits and misses
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    answers = {}
    for threads in (1, 3):
        kernels.set_threads(threads)
        try:
            answers[threads] = (
                scene.first_triangles(origins, directions),
                *scene.intersect(origins, directions),
                scene.occluded(origins, directions),
            )
        finally:
            kernels.set_threads(None)
    first, distance = answers[1][0], answers[1][2]
    assert 0.2 < (first >= 0).mean() < 0.95  # both hits and misses
    hits = origins + distance[:, None] * directions  # on the tessellated unit sphere
    np.testing.assert_allclose(np.linalg.norm(hits[first >= 0], axis=1), 1.0, atol=0.02)
    for one, several in zip(answers[1], answers[3], strict=True):
        np.testing.assert_array_equal(one, several)
