"""FaceNet architecture (facenet-pytorch names) and the human prior."""

from __future__ import annotations

import math

import pytest
import torch
from torch import nn

from deface.priors.facenet import InceptionResnetV1
from deface.priors.human import (
    FACENET_FILE,
    HumanPrior,
    HumanPriorConfig,
    MissingWeightsError,
    face_box,
    facenet_input,
    load_human_prior,
)

TOP_LEVEL = [
    "conv2d_1a", "conv2d_2a", "conv2d_2b", "conv2d_3b", "conv2d_4a", "conv2d_4b", "repeat_1", "mixed_6a",
    "repeat_2", "mixed_7a", "repeat_3", "block8", "last_linear", "last_bn", "logits",
]  # fmt: skip


@pytest.fixture(scope="module")
def facenet():
    torch.manual_seed(0)
    return InceptionResnetV1().eval()


def test_facenet_names_and_shapes(facenet):
    state = facenet.state_dict()
    assert sorted({key.split(".")[0] for key in state}) == sorted(TOP_LEVEL)
    assert len(facenet.repeat_1) == 5 and len(facenet.repeat_2) == 10 and len(facenet.repeat_3) == 5
    assert [b.scale for b in facenet.repeat_1] == [0.17] * 5 and facenet.repeat_2[0].scale == 0.10
    assert facenet.repeat_3[0].scale == 0.20 and facenet.block8.noReLU and not hasattr(facenet.block8, "relu")
    assert state["conv2d_1a.conv.weight"].shape == (32, 3, 3, 3) and "conv2d_1a.conv.bias" not in state
    assert facenet.conv2d_1a.bn.eps == 0.001 and facenet.conv2d_1a.bn.momentum == 0.1
    assert state["repeat_1.4.branch2.2.conv.weight"].shape == (32, 32, 3, 3)
    assert state["repeat_2.9.branch1.1.conv.weight"].shape == (128, 128, 1, 7)
    assert state["mixed_7a.branch2.2.conv.weight"].shape == (256, 256, 3, 3)
    assert state["block8.conv2d.weight"].shape == (1792, 384, 1, 1)
    assert state["last_linear.weight"].shape == (512, 1792) and "last_linear.bias" not in state
    assert state["last_bn.running_var"].shape == (512,) and facenet.last_bn.eps == 0.001
    assert state["logits.weight"].shape == (8631, 512) and state["logits.bias"].shape == (8631,)
    with torch.no_grad():
        assert facenet(torch.randn(2, 3, 160, 160)).shape == (2, 8631)


def test_state_dict_round_trip_through_human_prior(facenet, tmp_path):
    path = tmp_path / FACENET_FILE
    torch.save(facenet.state_dict(), path)
    prior = HumanPrior(path)
    loaded = prior.network.state_dict()
    for key, value in facenet.state_dict().items():
        assert torch.equal(loaded[key], value), key
    renders = torch.rand(2, 64, 64, 3)
    coverage = torch.zeros(64, 64)
    coverage[10:50, 16:48] = 1
    value = prior(renders, coverage)
    assert value.dim() == 0 and 0 <= value.item() <= 1
    found, reason = load_human_prior(tmp_path)
    assert isinstance(found, HumanPrior) and reason == ""


def test_missing_weights_are_reported(tmp_path, monkeypatch):
    monkeypatch.setenv("DEFACE_MODELS", str(tmp_path))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    with pytest.raises(MissingWeightsError, match=FACENET_FILE):
        HumanPrior(tmp_path / FACENET_FILE)
    prior, reason = load_human_prior(tmp_path)
    assert prior is None and FACENET_FILE in reason and "HP off" in reason


class MeanLogit(nn.Module):
    """Stand-in classifier: logits (mean of the input, 0)."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        mean = x.mean(dim=(1, 2, 3))
        return torch.stack([mean, torch.zeros_like(mean)], dim=1)


def test_human_prior_value_by_hand_with_a_stand_in_network():
    renders = torch.stack([torch.full((8, 8, 3), math.log(3.0)), torch.zeros(8, 8, 3)])  # max p: 0.75, 0.5
    renders.requires_grad_(True)
    coverage = torch.ones(8, 8)
    code = HumanPrior.with_network(MeanLogit(), HumanPriorConfig(input_mode="authors", form="code"))
    value = code(renders, coverage)
    assert value.item() == pytest.approx((0.25**2 + 0.5**2) / 2, abs=1e-6)
    value.backward()
    assert renders.grad.abs().sum() > 0
    paper = HumanPrior.with_network(MeanLogit(), HumanPriorConfig(input_mode="authors", form="paper"))
    assert paper(renders, coverage).item() == pytest.approx(0.25 + 0.5, abs=1e-6)


def test_facenet_input_crops_converts_and_standardises():
    coverage = torch.zeros(100, 120)
    coverage[20:60, 40:80] = 1.0
    top, left, height, width = face_box(coverage, margin=0.25)
    assert (height, width) == (60, 60) and (top, left) == (10, 30)
    renders = torch.full((1, 100, 120, 3), 0.2, requires_grad=True)
    x = facenet_input(renders, coverage, margin=0.25)
    assert x.shape == (1, 3, 160, 160)
    expected = (0.2 ** (1 / 2.2) * 255 - 127.5) / 128
    assert torch.allclose(x, torch.full_like(x, expected), atol=1e-5)
    x.sum().backward()
    assert renders.grad[0, 10:70, 30:90].abs().min() > 0 and renders.grad[0, :5].abs().max() == 0
