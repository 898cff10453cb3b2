"""Properties of the project's ICT albedo prior: range, left-right symmetry, smoothness, no sharp edges."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.fft import dctn
from scipy.spatial import cKDTree

from deface.models.albedo_prior import AlbedoPriorConfig, build_albedo_prior, vertex_uvs
from deface.models.ict import load_ict, load_ict_geometry


@pytest.fixture(scope="module")
def ict(shared):
    return load_ict(shared / "models")


@pytest.fixture(scope="module")
def prior(ict):
    return ict.albedo


def test_load_ict_attaches_prior(prior):
    assert prior is not None
    assert prior.diffuse_mean.shape == (128, 128, 3) and prior.specular_mean.shape == (128, 128, 3)
    assert 20 <= prior.num_coeffs <= 40
    assert prior.diffuse_basis.shape == prior.specular_basis.shape == (prior.num_coeffs, 128, 128, 3)
    assert prior.face_mask.shape == (128, 128) and 0.85 < prior.face_mask.mean() <= 1.0
    assert 0.3 <= prior.roughness_default <= 0.5
    assert len(prior.component_names) == prior.num_coeffs


def test_deterministic(ict, prior):
    geo = load_ict_geometry()
    again = build_albedo_prior(geo.uvs, geo.triangle_uvs, geo.triangles, geo.mean_shape, geo.landmarks_68)
    assert np.array_equal(again.diffuse_mean, prior.diffuse_mean)
    assert np.array_equal(again.diffuse_basis, prior.diffuse_basis)


def test_in_range(prior):
    for mean, basis in (
        (prior.diffuse_mean, prior.diffuse_basis),
        (prior.specular_mean, prior.specular_basis),
    ):
        std = np.sqrt((basis.astype(np.float64) ** 2).sum(0))
        assert (mean - 3 * std).min() >= 0.02 - 1e-6 and (mean + 3 * std).max() <= 0.95 + 1e-6
    # Random N(0, 1) draws stay in range and vary plausibly (not a constant model).
    rng = np.random.default_rng(0)
    maps = [
        prior.textures(torch.tensor(rng.standard_normal(prior.num_coeffs)), 128)[0].numpy() for _ in range(50)
    ]
    maps = np.stack(maps)
    assert maps.min() >= 0.02 and maps.max() <= 0.95
    face_mean = maps.mean((1, 2))  # [50, 3]
    assert face_mean.std(0).min() > 0.01


def test_skin_plausible(prior):
    mean = prior.diffuse_mean[prior.face_mask > 0.99].mean(0)
    assert mean[0] > mean[1] > mean[2]  # skin is red > green > blue
    spec = prior.specular_mean[prior.face_mask > 0.99]
    assert 0.03 <= spec.mean() <= 0.09


def test_regions_lips_redder_brows_darker(ict, prior):
    uv = vertex_uvs(ict.triangles, ict.uvs, ict.triangle_uvs, ict.num_vertices)
    lm = uv[ict.landmarks_68]
    sample = lambda p: prior.diffuse_mean[int((1 - p[1]) * 128), int(p[0] * 128)]  # noqa: E731
    cheek = sample(0.5 * (lm[3] + lm[31]) + [0.0, 0.05])
    lip = sample(0.5 * (lm[51] + lm[62]))
    brow = sample(lm[19] + [0.0, -0.01])
    assert lip[0] / lip[1] > cheek[0] / cheek[1] * 1.2
    assert brow.sum() < 0.8 * cheek.sum()


def _bilinear(image, uv):
    t = torch.as_tensor(image).permute(2, 0, 1)[None]
    grid = torch.as_tensor(np.stack([uv[:, 0] * 2 - 1, 1 - uv[:, 1] * 2], -1))[None, None].to(t.dtype)
    return torch.nn.functional.grid_sample(t, grid, align_corners=False)[0, :, 0].T.numpy()


def test_left_right_symmetric_on_the_mesh(ict, prior):
    verts = ict.mean_shape
    mirrored = verts * np.array([-1.0, 1.0, 1.0])
    dist, partner = cKDTree(verts).query(mirrored)
    ok = dist < 0.05  # vertices with a mirror partner (the mesh is near-symmetric)
    assert ok.mean() > 0.9
    uv = vertex_uvs(ict.triangles, ict.uvs, ict.triangle_uvs, ict.num_vertices)
    rng = np.random.default_rng(1)
    coeffs = torch.tensor(rng.standard_normal(prior.num_coeffs))
    for texture in prior.textures(coeffs, 128):
        values = _bilinear(texture.numpy(), uv)
        diff = np.abs(values[ok] - values[partner[ok]])
        assert np.percentile(diff, 99) < 0.01, np.percentile(diff, 99)


def test_asymmetric_option_breaks_symmetry(ict):
    geo = load_ict_geometry()
    asym = build_albedo_prior(
        geo.uvs,
        geo.triangle_uvs,
        geo.triangles,
        geo.mean_shape,
        geo.landmarks_68,
        AlbedoPriorConfig(symmetric=False),
    )
    odd = [i for i, n in enumerate(asym.component_names) if ":odd" in n]
    assert odd
    b = asym.diffuse_basis[odd[0]]
    assert np.abs(b + b[:, ::-1]).max() < 1e-6 * np.abs(b).max() + 1e-7  # odd in u


def test_basis_is_smooth(prior):
    for basis in (prior.diffuse_basis, prior.specular_basis):
        for k, b in enumerate(basis):
            energy = np.abs(dctn(b, axes=(0, 1), norm="ortho")) ** 2
            total = energy.sum()
            if total == 0:
                continue
            high = energy[16:, :].sum() + energy[:16, 16:].sum()  # frequencies above 8 cycles per map
            assert high / total < 0.01, (k, high / total)


def test_cannot_fit_a_shadow_edge(prior):
    """Least squares with the basis cannot produce a sharp cast-shadow boundary."""
    mask = prior.face_mask > 0.99
    basis = prior.diffuse_basis.reshape(prior.num_coeffs, -1).T.astype(np.float64)  # [H*W*3, K]
    rows = np.repeat(mask.reshape(-1), 3)
    for axis in (0, 1):  # horizontal edge (brow/nose shadow) and vertical edge (side light) at the midline
        coord = np.arange(128)[:, None] if axis == 0 else np.arange(128)[None, :]
        shadow = np.broadcast_to(coord >= 64, (128, 128))
        target = prior.diffuse_mean * np.where(shadow, 0.4, 1.0)[..., None]
        residual_target = (target - prior.diffuse_mean).reshape(-1)
        coeffs, *_ = np.linalg.lstsq(basis[rows], residual_target[rows], rcond=None)
        fit = prior.diffuse_mean + (basis @ coeffs).reshape(128, 128, 3)
        err = np.abs(fit - target)[mask].mean() / np.abs(target - prior.diffuse_mean)[mask].mean()
        assert err > 0.15, err  # a smooth basis leaves a large residual along the edge
        # The fitted transition is wide: 3 texels either side of the edge differ by < half the step.
        line = fit[:, 64, 0] if axis == 0 else fit[64, :, 0]
        step = prior.diffuse_mean[:, 64, 0] * 0.6 if axis == 0 else prior.diffuse_mean[64, :, 0] * 0.6
        assert abs(line[61] - line[67]) < 0.5 * step[61]
