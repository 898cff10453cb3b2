"""SH basis: orthonormality by quadrature, agreement with scipy's complex SH, cosine lobe, gradients."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy.special import sph_harm_y

from deface.render.kernels.shading import phong_lobe_filter
from deface.render.sh import cosine_lobe_coefficients, sh_basis, sh_basis_rows


def sphere_quadrature(n_theta: int, n_phi: int):
    """Gauss-Legendre in cos(theta) x uniform phi: exact for polynomials of degree < min(2 n_theta, n_phi)."""
    z, w = np.polynomial.legendre.leggauss(n_theta)
    phi = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    zz, pp = np.meshgrid(z, phi, indexing="ij")
    s = np.sqrt(1 - zz**2)
    dirs = np.stack([s * np.cos(pp), s * np.sin(pp), zz], -1).reshape(-1, 3)
    weights = np.repeat(w[:, None], n_phi, 1).reshape(-1) * 2 * np.pi / n_phi
    return dirs, weights


@pytest.mark.parametrize("bands", [1, 2, 9, 18, 22])
def test_orthonormal(bands):
    dirs, weights = sphere_quadrature(bands + 2, 2 * bands + 2)
    y = sh_basis(torch.tensor(dirs), bands).numpy()  # [Q, B²]
    gram = (y * weights[:, None]).T @ y
    np.testing.assert_allclose(gram, np.eye(bands * bands), atol=1e-10)


def test_matches_scipy_real_sh():
    rng = np.random.default_rng(1)
    dirs = rng.normal(size=(50, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    theta, phi = np.arccos(dirs[:, 2]), np.arctan2(dirs[:, 1], dirs[:, 0])
    bands = 12
    ours = sh_basis(torch.tensor(dirs), bands).numpy()
    for l in range(bands):  # noqa: E741
        for m in range(-l, l + 1):
            complex_y = sph_harm_y(l, abs(m), theta, phi)  # includes the Condon-Shortley phase
            sign = (-1) ** abs(m)
            if m > 0:
                ref = math.sqrt(2) * sign * complex_y.real
            elif m < 0:
                ref = math.sqrt(2) * sign * complex_y.imag
            else:
                ref = complex_y.real
            np.testing.assert_allclose(ours[:, l * l + l + m], ref, atol=1e-10, err_msg=f"l={l} m={m}")


def test_rows_layout_and_shapes():
    dirs = torch.nn.functional.normalize(torch.randn(4, 5, 3, dtype=torch.float64), dim=-1)
    y = sh_basis(dirs, 4)
    assert y.shape == (4, 5, 16)
    np.testing.assert_allclose(sh_basis_rows(dirs.reshape(-1, 3), 4).T.numpy(), y.reshape(-1, 16).numpy())
    with pytest.raises(ValueError):
        sh_basis(torch.zeros(3, 2), 3)


def test_cosine_lobe_matches_quadrature():
    """A_l = 2 pi ∫_0^1 t P_l(t) dt (Funk-Hecke for max(cos, 0))."""
    t, w = np.polynomial.legendre.leggauss(200)
    t, w = 0.5 * (t + 1), 0.5 * w  # on [0, 1]
    lobe = cosine_lobe_coefficients(20).numpy()
    for l in range(20):  # noqa: E741
        p_l = np.polynomial.legendre.Legendre.basis(l)(t)
        expected = 2 * np.pi * np.sum(w * t * p_l)
        assert lobe[l * l] == pytest.approx(expected, abs=1e-6)


def test_irradiance_of_constant_light_is_pi():
    n = torch.nn.functional.normalize(torch.randn(10, 3, dtype=torch.float64), dim=-1)
    c = torch.zeros(16, dtype=torch.float64)
    c[0] = 2.0 / sh_basis(n[:1], 1)[0, 0]  # radiance 2 everywhere
    irradiance = (sh_basis(n, 4) * cosine_lobe_coefficients(4).double()) @ c
    np.testing.assert_allclose(irradiance.numpy(), 2 * np.pi, rtol=1e-6)  # A_l is float32


def test_phong_filter_properties():
    rough = torch.tensor([1e-4, 0.2, 0.5, 1.0])
    lam = phong_lobe_filter(rough, 9)
    np.testing.assert_allclose(lam[:, 0].numpy(), 1.0)  # energy of a constant environment is kept
    assert torch.all(lam[0] > 0.999)  # near-mirror keeps every band
    assert torch.all(lam[:, 1:].diff(dim=0) <= 0)  # rougher blurs more
    assert torch.all(lam.diff(dim=1) <= 0)


def test_gradient_matches_finite_differences():
    d = torch.randn(4, 3, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda v: sh_basis(torch.nn.functional.normalize(v, dim=-1), 7), (d,))


def test_non_negative_keeps_a_positive_light_and_clamps_a_negative_lobe():
    from deface.render.sh import _radiance_basis, non_negative, white_light

    light = white_light(9)
    assert non_negative(light) is light  # nowhere negative: unchanged
    lobe = torch.zeros(1, 81, 3)
    lobe[0, 0] = 1.0
    lobe[0, 2] = -2.5  # a constant minus a strong lobe towards +z: negative radiance around +z
    basis, _ = _radiance_basis(9)
    before = (basis.float() @ lobe[0])[:, 0]
    after = (basis.float() @ non_negative(lobe)[0])[:, 0]
    assert before.min() < -0.5
    assert after.min() > -0.05 * before.max()  # the band-limited clamp rings a little, no more
    away = before > 0.2  # where the light was clearly positive it keeps most of its radiance
    assert torch.corrcoef(torch.stack([before[away], after[away]]))[0, 1] > 0.95
    clamped = non_negative(lobe.double().requires_grad_())
    clamped.sum().backward()  # differentiable


def test_the_reports_lit_sphere_shows_the_light_as_rendered():
    """A light whose radiance is negative around +z renders (clamped) as a light from the sides; its picture in
    report.html must show that, not the raw SH's negative irradiance (a black sphere)."""
    from deface.render.renderer import RenderConfig, Renderer
    from deface.report.html import lit_sphere

    lobe = torch.zeros(1, 81, 3)
    lobe[0, 0] = 1.0
    lobe[0, 2] = -1.0  # radiance 0.28 - 0.49 z: negative above z = 0.58, its raw irradiance at +z too
    size = 33
    centre = (size // 2, size // 2)
    raw = lit_sphere(Renderer(RenderConfig(non_negative_lights=False)).rendered_lights(lobe)[0], size=size)
    shown = lit_sphere(Renderer(RenderConfig()).rendered_lights(lobe)[0], size=size)
    assert raw[centre][:3].max() == 0.0  # the raw lobe's irradiance facing +z is negative: clipped to black
    assert shown[centre][:3].min() > 0.01  # as rendered, light reaches it from around the horizon
