"""The gated texture pyramid: level sizes, gates from texel density, start at T^0, gated gradients (the op
``pyramid_map``'s fast path against its reference: tests/test_render_kernels.py)."""

from __future__ import annotations

import numpy as np
import torch

from deface.texture.pyramid import PyramidConfig, TexturePyramid, level_gates, level_sizes


def test_level_sizes_stop_at_the_minimum_side():
    assert level_sizes(256, PyramidConfig(levels=5)) == [256, 128, 64, 32, 16]
    assert level_sizes(64, PyramidConfig(levels=5)) == [64, 32, 16]
    assert level_sizes(256, PyramidConfig(levels=1)) == [256]


def test_gates_are_pixels_per_level_texel_clipped():
    density = np.full((64, 64), 0.25)  # 4 texels per pixel at the finest level
    density[:, 32:] = 2.0  # finely seen half
    density[:8, :8] = 0.0  # unseen corner
    gates = level_gates(density, [64, 32, 16])
    np.testing.assert_allclose(gates[0][:, :32][8:].numpy(), 0.25)
    np.testing.assert_allclose(gates[0][:, 32:].numpy(), 1.0)
    np.testing.assert_allclose(gates[0][:8, :8].numpy(), 0.0)
    np.testing.assert_allclose(gates[1][4:, :].numpy(), 1.0)  # 2x2 texels pool to one pixel: free
    np.testing.assert_allclose(gates[2].numpy(), 1.0)  # coarsest: always free
    assert all(float(g.min()) == 1.0 for g in level_gates(density, [64, 32, 16], gated=False))


def test_pyramid_starts_at_the_initial_map_and_one_level_is_per_texel():
    initial = torch.rand(32, 32, 3)
    pyramid = TexturePyramid(initial, level_gates(np.ones((32, 32)), [32, 16]))
    torch.testing.assert_close(pyramid(), initial)
    single = TexturePyramid(initial, level_gates(np.ones((32, 32)), [32]))
    with torch.no_grad():
        single.levels[0].add_(torch.ones(3, 32, 32))
    torch.testing.assert_close(single(), initial + 1)


def test_gradients_reach_each_level_scaled_by_its_gate():
    torch.manual_seed(0)
    initial = torch.rand(16, 16, 1, dtype=torch.float64)
    density = np.full((16, 16), 0.5)
    pyramid = TexturePyramid(initial, level_gates(density, [16, 8])).double()
    weights = torch.rand(16, 16, 1, dtype=torch.float64)
    (pyramid() * weights).sum().backward()
    fine, coarse = pyramid.levels[0].grad, pyramid.levels[1].grad
    torch.testing.assert_close(fine, 0.5 * weights.permute(2, 0, 1))  # d/dP0 = gate x dL/dT
    # the coarse level's gradient is the bilinear upsampling's adjoint: it sums to the total weight
    torch.testing.assert_close(coarse.sum(), weights.sum())
    # and matches a central finite difference on one coarse value
    with torch.no_grad():
        step = 1e-6
        pyramid.levels[1][0, 3, 4] += step
        plus = float((pyramid() * weights).sum())
        pyramid.levels[1][0, 3, 4] -= 2 * step
        minus = float((pyramid() * weights).sum())
    assert abs((plus - minus) / (2 * step) - float(coarse[0, 3, 4])) < 1e-6
