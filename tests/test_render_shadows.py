"""Ray-traced self-shadowing against an independent Monte Carlo estimate; the transfer cache."""

from __future__ import annotations

import math

import numpy as np
import torch
from scipy.special import sph_harm_y

from deface.render.mesh import Mesh
from deface.render.primitives import grid_plane, merge
from deface.render.renderer import RenderConfig, Renderer, ShadowTransferCache, vertex_irradiance

PLATE_X, PLATE_Y, PLATE_Z = (-0.5, 1.0), (-0.6, 0.6), 0.6


def scene() -> Mesh:
    """A ground plane (normal +z) under a floating rectangular plate facing down."""
    ground = grid_plane((-2.0, 2.0), (-2.0, 2.0), z=0.0, cells=20)
    plate = grid_plane(PLATE_X, PLATE_Y, z=PLATE_Z, cells=2, facing_up=False)
    return merge(ground, plate)


def real_sh_scipy(dirs: np.ndarray, bands: int) -> np.ndarray:
    """Real SH from scipy's complex SH (Condon-Shortley phase removed), [N, bands²]."""
    theta, phi = np.arccos(np.clip(dirs[:, 2], -1, 1)), np.arctan2(dirs[:, 1], dirs[:, 0])
    out = np.zeros((len(dirs), bands * bands))
    for l in range(bands):  # noqa: E741
        for m in range(-l, l + 1):
            y = sph_harm_y(l, abs(m), theta, phi) * (-1) ** abs(m)
            out[:, l * l + l + m] = (math.sqrt(2) * (y.real if m > 0 else y.imag)) if m else y.real
    return out


def monte_carlo_irradiance(point: np.ndarray, sh: np.ndarray, samples: int, rng) -> np.ndarray:
    """E = ∫ V L cos dw for a +z normal, by cosine-weighted random sampling (Malley) and analytic
    ray-rectangle occlusion by the plate. sh [B², 3] -> [3]."""
    r, phi = np.sqrt(rng.random(samples)), 2 * np.pi * rng.random(samples)
    dirs = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - r**2)], -1)
    t = (PLATE_Z - point[2]) / dirs[:, 2]
    hx, hy = point[0] + t * dirs[:, 0], point[1] + t * dirs[:, 1]
    blocked = (hx > PLATE_X[0]) & (hx < PLATE_X[1]) & (hy > PLATE_Y[0]) & (hy < PLATE_Y[1])
    radiance = real_sh_scipy(dirs, math.isqrt(sh.shape[0])) @ sh  # [S, 3]
    return np.pi * (radiance * ~blocked[:, None]).mean(0)


def test_shadowed_irradiance_matches_monte_carlo():
    bands = 5
    mesh = scene()
    gen = torch.Generator().manual_seed(3)
    sh = 0.15 * torch.randn(1, bands * bands, 3, generator=gen, dtype=torch.float64)
    sh[0, 0] += 1.5
    sh[0, 2] += 1.2  # more light from above, so the plate's shadow matters
    renderer = Renderer(RenderConfig(shadow_rays=512), bands=bands)
    transfer = renderer.shadow_transfer(mesh)
    shadowed = vertex_irradiance(mesh, sh, transfer)[:, 0].numpy()  # [V, 3]
    unshadowed = vertex_irradiance(mesh, sh, None)[:, 0].numpy()

    rng = np.random.default_rng(7)
    verts = mesh.vertices.numpy()
    ground = np.nonzero((verts[:, 2] == 0) & (np.abs(verts[:, :2]).max(1) < 1.8))[0]
    chosen = rng.choice(ground, 16, replace=False)
    worst, darkest = 0.0, 1.0
    for v in chosen:
        reference = monte_carlo_irradiance(mesh.vertices[v].numpy(), sh[0].numpy(), 30_000, rng)
        worst = max(worst, float(np.max(np.abs(shadowed[v] - reference) / reference)))
        darkest = min(darkest, float(np.min(shadowed[v] / unshadowed[v])))
    assert darkest < 0.6, "the scene should contain real shadows"
    print(f"worst {worst:.4f} darkest {darkest:.3f}")
    assert worst < 0.03, f"max relative error vs Monte Carlo {worst:.4f}"


def test_transfer_is_deterministic_and_seeded():
    mesh = scene()
    a = Renderer(RenderConfig(shadow_rays=64), bands=3, seed=1).shadow_transfer(mesh)
    b = Renderer(RenderConfig(shadow_rays=64), bands=3, seed=1).shadow_transfer(mesh)
    c = Renderer(RenderConfig(shadow_rays=64), bands=3, seed=2).shadow_transfer(mesh)
    assert torch.equal(a.occluded, b.occluded)
    assert not torch.equal(a.occluded, c.occluded)
    assert a.occluded.shape == (mesh.vertices.shape[0], 9)
    assert float(a.visibility.min()) >= 0 and float(a.visibility.max()) <= 1


def test_cache_refreshes_only_beyond_tolerance():
    mesh = scene()
    cache = ShadowTransferCache(Renderer(RenderConfig(shadow_rays=32, shadow_tolerance_cm=0.05), bands=3))
    first = cache.get(mesh)
    assert cache.refreshes == 1
    nudged = Mesh(mesh.vertices + 0.02, mesh.triangles, mesh.uvs, mesh.triangle_uvs)
    assert cache.get(nudged) is first and cache.refreshes == 1
    moved = mesh.vertices.clone()
    moved[5, 2] += 0.2
    assert cache.get(Mesh(moved, mesh.triangles, mesh.uvs, mesh.triangle_uvs)) is not first
    assert cache.refreshes == 2
