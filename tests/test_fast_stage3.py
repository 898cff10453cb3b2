"""Stage 3's fused terms (deface/fit/fast_stage3.py) beyond the registry's float64 comparison with their torch
references (tests/test_render_kernels.py): float32, the switch, and the same logged terms on both paths."""

from __future__ import annotations

import types

import pytest
import torch
from test_render_kernels import soft_mask, stage3_maps

from deface.fit import fast_stage3, stage3
from deface.fit.config import FitConfig
from deface.fit.state import LossTerms
from deface.render import kernels

pytestmark = pytest.mark.skipif(kernels.numba is None, reason="numba missing")


def test_texture_terms_float32_close_and_deterministic():
    initial, current = stage3_maps(32, 4, torch.float32), stage3_maps(32, 5, torch.float32)
    mask = soft_mask(32, 32, 6, torch.float32)
    palette = torch.rand(16, 3, generator=torch.Generator().manual_seed(7))
    terms = fast_stage3.TextureTerms(initial, mask, palette, 0.2, 2e3)
    assert fast_stage3.texture_terms.use_fast(current.diffuse, current.specular, current.roughness, terms)
    first, second = terms(current), terms(current)
    assert first[0].dtype == torch.float32
    assert [value.item() for value in first] == [value.item() for value in second]
    with kernels.backend("torch"):
        reference = terms(current)
    for got, want in zip(first, reference, strict=True):
        assert got.item() == pytest.approx(want.item(), rel=1e-5)


def test_ops_follow_the_renderer_switch_and_take_one_dtype():
    maps, mask = torch.zeros(4, 4, 3), torch.ones(4, 4)
    op = fast_stage3.local_prior_l1
    assert op.use_fast(maps, maps, mask)
    assert not op.use_fast(maps, maps.double(), mask)  # one dtype only
    with kernels.backend("torch"):
        assert not op.use_fast(maps, maps, mask)
    with kernels.on_reference("local_prior_l1"):
        assert not op.use_fast(maps, maps, mask)


@pytest.mark.parametrize("with_global_prior", [True, False])
def test_stage3_logs_the_same_terms_on_both_paths(with_global_prior):
    """loss_log.csv's columns do not depend on the backend: stage 3's texture-space terms (its objective's
    part that has a fused path) log the regularisers and, with GP on, GP under the same names on both paths;
    the values agree to float32 rounding and sum to the total the fit optimises."""
    context = types.SimpleNamespace(config=FitConfig())  # GP's weight 2e3, the paper's
    initial, current = stage3_maps(16, 0, torch.float32), stage3_maps(16, 1, torch.float32)
    palette = torch.rand(8, 3, generator=torch.Generator().manual_seed(3)) if with_global_prior else None
    mask = soft_mask(16, 16, 2, torch.float32)
    logged, totals = {}, {}
    for path in ("numba", "torch"):
        with kernels.backend(path):
            terms = LossTerms()
            totals[path] = float(stage3._texture_terms_of(context, initial, palette, mask, 1.3)(current, terms))
            logged[path] = terms.values
    names = ["texture_regularisers", "global_prior"] if with_global_prior else ["texture_regularisers"]
    assert list(logged["numba"]) == list(logged["torch"]) == names
    for name in names:
        assert logged["numba"][name] == pytest.approx(logged["torch"][name], rel=1e-5)
    assert totals["numba"] == pytest.approx(totals["torch"], rel=1e-5)
    for path in ("numba", "torch"):
        assert sum(logged[path].values()) == pytest.approx(totals[path], rel=1e-6)
    if with_global_prior:
        assert logged["numba"]["global_prior"] > 0
    else:  # one term: its logged value is the total, bit for bit
        assert logged["numba"]["texture_regularisers"] == totals["numba"]
