"""Light masks at pixels without shading evidence come from the pixels around (deface/decouple/fill.py)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import torch
from scipy import ndimage

from deface.decouple.fill import fill_from_evidence, gaussian_blur


def test_gaussian_blur_matches_scipy_with_zeros_outside():
    image = torch.rand(2, 40, 50, dtype=torch.float64)
    ours = gaussian_blur(image, 2.5).numpy()
    for channel in range(2):
        reference = ndimage.gaussian_filter(image[channel].numpy(), 2.5, mode="constant", truncate=3.0)
        # scipy truncates at 3 sigma too, rounding its radius the same way (int(3 * 2.5 + 0.5) = 8 = ceil(7.5))
        np.testing.assert_allclose(ours[channel], reference, atol=1e-12)


def _two_lights(lit_share: torch.Tensor) -> torch.Tensor:
    return torch.stack([lit_share, 1.0 - lit_share])


def test_full_evidence_keeps_the_masks_and_every_result_sums_to_one():
    torch.manual_seed(0)
    masks = _two_lights(torch.rand(30, 30))
    np.testing.assert_allclose(fill_from_evidence(masks, torch.ones(30, 30), 4.0), masks, atol=1e-12)
    filled = fill_from_evidence(masks, torch.rand(30, 30), 4.0)
    np.testing.assert_allclose(filled.sum(0), torch.ones(30, 30), atol=1e-6)


def test_a_dark_patch_without_evidence_takes_the_light_of_the_lit_skin_around_it():
    lit = torch.ones(60, 60)
    lit[20:40, 20:40] = 0.0  # f drew the other (dim) light over a beard
    evidence = torch.ones(60, 60)
    evidence[20:40, 20:40] = 0.0  # the beard's pixels say nothing of the shading
    filled = fill_from_evidence(_two_lights(lit), evidence, 8.0)
    assert float(filled[0, 20:40, 20:40].min()) > 0.95  # lit, as the skin around it
    np.testing.assert_allclose(filled[:, :10], _two_lights(lit)[:, :10])  # evidence kept elsewhere


def test_a_shadow_with_evidence_keeps_its_light_and_its_edge_band_ramps_between_the_sides():
    lit = torch.ones(40, 80)
    lit[:, 40:] = 0.0  # a cast shadow over the right half, its skin seen (evidence 1) on both sides
    evidence = torch.ones(40, 80)
    evidence[:, 38:42] = 0.0  # the band along its edge
    filled = fill_from_evidence(_two_lights(lit), evidence, 6.0)[0, 20]
    np.testing.assert_allclose(filled[:38], 1.0)
    np.testing.assert_allclose(filled[42:], 0.0)
    band = filled[38:42]
    assert bool((band[1:] < band[:-1]).all()) and 0.5 < float(band[0]) < 1.0 and 0.0 < float(band[-1]) < 0.5


def test_a_dappled_shadows_edge_bands_keep_their_masks_and_a_patch_far_from_evidence_is_filled():
    # leaves' shadow: 12-pixel patches of light and shade, the 4-pixel bands along their edges without evidence,
    # where f drew nothing useful (0.5)
    lit = torch.as_tensor((np.indices((96, 96)) // 12).sum(0) % 2, dtype=torch.float64)
    band = torch.zeros(96, 96, dtype=torch.bool)
    for edge in range(12, 96, 12):
        band[:, edge - 2:edge + 2] = True
        band[edge - 2:edge + 2, :] = True
    evidence = (~band).double()
    drawn = _two_lights(torch.where(band, torch.full_like(lit, 0.5), lit))
    inside = band.clone()
    inside[:16], inside[-16:], inside[:, :16], inside[:, -16:] = False, False, False, False

    def error(filled: torch.Tensor) -> float:
        return float((filled[0] - lit).abs()[inside].mean())

    wide = error(fill_from_evidence(drawn, evidence, 24.0))  # 0.5 drawn: already 0.5 off; the wide fill no better
    near = fill_from_evidence(drawn, evidence, 24.0, near=3.0)
    # with evidence a few pixels either side, the bands keep what f drew (0.5 here: error 0.5 at most), the wide
    # fill blurs them towards the patches' mean; far from any evidence (a 20-pixel patch) both fill
    assert float((near[0] - drawn[0]).abs()[inside].max()) < 0.1 < 0.45 < wide, wide
    np.testing.assert_allclose(near.sum(0), 1.0, atol=1e-6)
    lit_patch = _two_lights(torch.ones(60, 60, dtype=torch.float64))
    lit_patch[:, 20:40, 20:40] = torch.tensor([0.0, 1.0], dtype=torch.float64)[:, None, None]
    patch_evidence = torch.ones(60, 60, dtype=torch.float64)
    patch_evidence[20:40, 20:40] = 0.0
    assert float(fill_from_evidence(lit_patch, patch_evidence, 8.0, near=2.0)[0, 25:35, 25:35].min()) > 0.9


def test_the_fits_masks_are_filled_only_when_asked_and_at_every_working_size():
    from deface.fit.config import DecoupleConfig
    from deface.fit.decoupling import Decoupling

    torch.manual_seed(0)
    evidence = torch.ones(1, 40, 40)
    evidence[0, 10:30, 10:30] = 0.0
    coverage = torch.zeros(40, 40)
    coverage[4:36, 4:36] = 1.0
    drawn_masks = DecoupleConfig(uniform_start=False)  # f's random blobs: masks that vary, for the fill to change
    plain = Decoupling(drawn_masks, num_lights=3, num_frames=1, size=(40, 40))
    filled = Decoupling(replace(drawn_masks, mask_fill=0.2), num_lights=3, num_frames=1, size=(40, 40))
    filled.load_state_dict(plain.state_dict())
    for decoupling in (plain, filled):
        decoupling.set_evidence(evidence)
    with torch.no_grad():
        drawn, mine = plain.light_masks(0, coverage), filled.light_masks(0, coverage)
    unset = Decoupling(drawn_masks, num_lights=3, num_frames=1, size=(40, 40))
    unset.load_state_dict(plain.state_dict())
    with torch.no_grad():
        assert torch.equal(unset.light_masks(0, coverage), drawn)  # mask_fill 0: f's masks as they are
    torch.testing.assert_close(mine[:, 4:8, 4:36], drawn[:, 4:8, 4:36])  # full evidence: unchanged
    assert float((mine[:, 15:25, 15:25] - drawn[:, 15:25, 15:25]).abs().max()) > 1e-4  # the patch: filled
    for shape in ((40, 40), (20, 20), (80, 80)):  # stage 2's half size and stage 3's working size
        cover = torch.nn.functional.interpolate(coverage[None, None], size=shape)[0, 0]
        with torch.no_grad():
            torch.testing.assert_close(filled.light_masks(0, cover).sum(0), cover, atol=1e-5, rtol=0)
