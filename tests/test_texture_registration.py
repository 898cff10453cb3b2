"""Several frames' detail brought into register in UV (deface/texture/registration.py): a known misplacement of one
frame's detail is recovered, and the frame's moved UVs read the shared map where its own detail lies."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from deface.render.kernels.texture import bilinear_forward
from deface.texture.registration import RegistrationConfig, detail, register, shifted_uvs

SIDE = 128


def speckle(side: int = SIDE, seed: int = 0) -> np.ndarray:
    """[side, side] a random detail pattern a few texels across (a beard's, freckles')."""
    noise = torch.as_tensor(np.random.default_rng(seed).normal(size=(side, side)), dtype=torch.float32)
    return F.avg_pool2d(noise[None, None], 3, stride=1, padding=1)[0, 0].numpy()


def read_at(image: np.ndarray, flow: np.ndarray) -> np.ndarray:
    """[S, S] ``image`` read at x - flow(x) (texels, x right, y down): what a frame whose geometry puts the
    reference's texel x at x + flow shows at each texel."""
    side = image.shape[0]
    base = (torch.arange(side, dtype=torch.float32) + 0.5) / side * 2 - 1
    ys, xs = torch.meshgrid(base, base, indexing="ij")
    shift = torch.as_tensor(flow, dtype=torch.float32)
    grid = torch.stack([xs - shift[..., 0] * 2 / side, ys - shift[..., 1] * 2 / side], -1)[None]
    planes = torch.as_tensor(image, dtype=torch.float32)[None, None]
    return F.grid_sample(planes, grid, mode="bilinear", padding_mode="border", align_corners=False)[0, 0].numpy()


def smooth_flow(side: int = SIDE) -> np.ndarray:
    """[S, S, 2] a flow of 2-4 texels that bends across the map, as one photo's geometry misplaces a face."""
    ys, xs = np.mgrid[0:side, 0:side] / side
    return np.stack([3.0 + np.sin(2 * ys), -2.0 + 0.5 * xs], -1).astype(np.float32)


@pytest.fixture(scope="module")
def registered():
    truth = smooth_flow()
    reference = speckle()
    moved = read_at(reference, truth)
    weight = np.zeros((SIDE, SIDE), np.float32)
    weight[16:112, 20:108] = 1.0  # the texels both frames see
    config = RegistrationConfig(max_side=SIDE)
    details = [detail(image, weight, config.detail_scale * SIDE) for image in (reference, moved)]
    return reference, moved, truth, weight, register(details, [weight, weight], config)


def test_a_frames_misplacement_is_recovered_between_the_frames(registered):
    """Frame 1 shows frame 0's detail moved by a known flow: their flows differ by it, and their mean is zero (the
    map stays where the frames' geometry puts it on average)."""
    _, _, truth, weight, flows = registered
    inside = np.repeat((weight > 0)[..., None], 2, -1)
    relative = flows[1].flow - flows[0].flow
    assert np.abs(relative - truth)[inside].mean() < 0.25  # texels, of a 2-4 texel misplacement
    assert np.abs(flows[1].flow + flows[0].flow)[inside].mean() < 0.05
    assert min(flow.after for flow in flows) > 0.9 > 0.2 > min(flow.before for flow in flows)


def test_without_evidence_there_is_no_flow():
    """Two frames that share no detail (independent patterns) keep no flow: nothing moves on a guess."""
    weight = np.ones((SIDE * 2, SIDE * 2), np.float32)
    config = RegistrationConfig()
    details = [detail(speckle(SIDE * 2, seed), weight, config.detail_scale * SIDE * 2) for seed in (1, 2)]
    for flow in register(details, [weight, weight], config):
        assert np.all(flow.flow == 0) and flow.after == flow.before


def test_moved_uvs_read_the_shared_map_where_each_frame_shows_its_detail(registered):
    """Rendering each frame with its moved UVs samples one shared map where the frame's own photo shows that
    detail: the lookups reproduce both frames' unwraps, which the unmoved UVs cannot."""
    reference, moved, _, _, flows = registered
    shared = torch.as_tensor(read_at(reference, -flows[0].flow), dtype=torch.float32)[..., None]  # the map in the
    # frames' mean registration: frame 0 samples it at z - flow_0(z) and shows reference(z)
    texels = torch.arange(28, 100, dtype=torch.float32)
    ys, xs = torch.meshgrid(texels, texels, indexing="ij")
    uvs = torch.stack([(xs.reshape(-1) + 0.5) / SIDE, 1 - (ys.reshape(-1) + 0.5) / SIDE], -1)  # v up
    for frame, shown in enumerate((reference, moved)):
        shown = shown[ys.long().reshape(-1), xs.long().reshape(-1)]
        rendered = bilinear_forward(shared, shifted_uvs(uvs, flows[frame].flow))[:, 0].numpy()
        assert np.corrcoef(rendered, shown)[0, 1] > 0.95
    naive = bilinear_forward(shared, uvs)[:, 0].numpy()
    assert np.corrcoef(naive, moved[ys.long().reshape(-1), xs.long().reshape(-1)])[0, 1] < 0.5
