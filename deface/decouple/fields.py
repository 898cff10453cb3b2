"""The two neural fields of light decoupling (Sec. 3.2), with the authors' architectures.

- f, :class:`LightMaskField`: per-pixel MLP (x, y, t) -> n logits, softmax over the lights.
  3 -> 16 -> 64 -> 64 -> n with LeakyReLU(0.02), PyTorch's default init, no positional encoding
  (an optional Fourier encoding is available, off by default).
- g, :class:`FaceRegionField`: 5x5 conv 3 -> 16 on the coordinate image, then per pixel 16 -> 64 -> 64 -> 1
  with LeakyReLU(0.02), sigmoid.

After ACE only some lights are kept. ``LightMaskField.keep(indices)`` records them (in ACE's order) and the
forward pass then returns masks over the kept lights only, renormalised to sum to 1. Softmax over the kept
logits equals the full softmax renormalised over the kept subset:
p_k / sum_kept p_j = e^{z_k} / sum_kept e^{z_j}.
The kept set is saved in the module's state dict (``_extra_state``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import nn


def fourier_features(coords: torch.Tensor, num_frequencies: int) -> torch.Tensor:
    """[..., D] -> [..., D (1 + 2F)]: the input followed by sin/cos(2^k pi p) for k < F."""
    if num_frequencies <= 0:
        return coords
    scales = (2.0 ** torch.arange(num_frequencies, dtype=coords.dtype, device=coords.device)) * math.pi  # [F]
    angles = coords[..., None] * scales  # [..., D, F]
    encoded = torch.cat([torch.sin(angles), torch.cos(angles)], dim=-1).flatten(-2)  # [..., 2 D F]
    return torch.cat([coords, encoded], dim=-1)


def _mlp(widths: Sequence[int], negative_slope: float) -> nn.Sequential:
    layers: list[nn.Module] = []
    for i in range(len(widths) - 1):
        layers.append(nn.Linear(widths[i], widths[i + 1]))
        if i < len(widths) - 2:
            layers.append(nn.LeakyReLU(negative_slope))
    return nn.Sequential(*layers)


def _check_coords(coords: torch.Tensor) -> None:
    if coords.shape[-1] != 3:
        raise ValueError(f"coordinates must end in (x, y, t), got shape {tuple(coords.shape)}")


class LightMaskField(nn.Module):
    """f: (x, y, t) -> light-mask probabilities over the n lights (or over the kept ones after ACE)."""

    def __init__(
        self,
        num_lights: int,
        hidden: Sequence[int] = (16, 64, 64),
        negative_slope: float = 0.02,
        fourier_frequencies: int = 0,
        uniform_start: bool = False,
    ):
        super().__init__()
        if num_lights < 1:
            raise ValueError(f"num_lights must be >= 1, got {num_lights}")
        self.num_lights = num_lights
        self.fourier_frequencies = fourier_frequencies
        in_dim = 3 * (1 + 2 * fourier_frequencies)
        self.mlp = _mlp([in_dim, *hidden, num_lights], negative_slope)
        if uniform_start:  # every mask 1 / n until the photo's gradients split them
            nn.init.zeros_(self.mlp[-1].weight)
            nn.init.zeros_(self.mlp[-1].bias)
        self._kept: list[int] = list(range(num_lights))

    @property
    def kept(self) -> list[int]:
        """Indices of the lights in use, in the order the masks are returned."""
        return list(self._kept)

    @property
    def num_kept(self) -> int:
        return len(self._kept)

    def keep(self, indices: Sequence[int]) -> None:
        """Restrict the output to these lights (ACE's result); masks are renormalised over them."""
        indices = [int(i) for i in indices]
        valid = all(0 <= i < self.num_lights for i in indices)
        if not indices or len(set(indices)) != len(indices) or not valid:
            raise ValueError(f"kept lights must be distinct indices in [0, {self.num_lights}), got {indices}")
        self._kept = indices

    def logits(self, coords: torch.Tensor) -> torch.Tensor:
        """Raw logits [..., n] over all n lights."""
        _check_coords(coords)
        return self.mlp(fourier_features(coords, self.fourier_frequencies))

    def forward(self, coords: torch.Tensor) -> torch.Tensor:
        """coords [..., 3] -> masks [..., n_kept], non-negative, summing to 1 over the last axis."""
        logits = self.logits(coords)
        if self.num_kept != self.num_lights:
            logits = logits[..., self._kept]
        return torch.softmax(logits, dim=-1)

    def get_extra_state(self) -> dict:
        return {"kept": list(self._kept)}

    def set_extra_state(self, state: dict) -> None:
        self.keep(state["kept"])


class FaceRegionField(nn.Module):
    """g: coordinate image -> probability that a pixel belongs to the face region."""

    def __init__(
        self,
        conv_channels: int = 16,
        hidden: Sequence[int] = (64, 64),
        kernel_size: int = 5,
        negative_slope: float = 0.02,
        fourier_frequencies: int = 0,
    ):
        super().__init__()
        if kernel_size % 2 != 1:
            raise ValueError(f"kernel_size must be odd (same-size output), got {kernel_size}")
        self.fourier_frequencies = fourier_frequencies
        in_dim = 3 * (1 + 2 * fourier_frequencies)
        self.conv = nn.Conv2d(in_dim, conv_channels, kernel_size, padding=kernel_size // 2)
        self.act = nn.LeakyReLU(negative_slope)
        self.mlp = _mlp([conv_channels, *hidden, 1], negative_slope)

    def forward(self, coords: torch.Tensor) -> torch.Tensor:
        """coords [T, H, W, 3] (or [H, W, 3]) -> probabilities [T, H, W] (or [H, W]) in (0, 1)."""
        _check_coords(coords)
        single = coords.dim() == 3
        if single:
            coords = coords[None]
        if coords.dim() != 4:
            raise ValueError(f"FaceRegionField expects [T, H, W, 3] coordinates, got {tuple(coords.shape)}")
        encoded = fourier_features(coords, self.fourier_frequencies)
        features = self.act(self.conv(encoded.permute(0, 3, 1, 2))).permute(0, 2, 3, 1)  # [T, H, W, C]
        prob = torch.sigmoid(self.mlp(features)[..., 0])  # [T, H, W]
        return prob[0] if single else prob

    def masked(self, coords: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """g at the pixels of ``mask`` only: coords [H, W, 3], mask [H, W] bool -> [H, W], 0 outside.

        The 5x5 convolution still sees the whole coordinate image (same values as :meth:`forward` at the
        masked pixels); only the per-pixel MLP, the expensive part, is restricted.
        """
        _check_coords(coords)
        encoded = fourier_features(coords[None], self.fourier_frequencies)
        features = self.act(self.conv(encoded.permute(0, 3, 1, 2)))[0].permute(1, 2, 0)  # [H, W, C]
        values = torch.sigmoid(self.mlp(features[mask])[..., 0])  # [N]
        return features.new_zeros(mask.shape).index_put((mask,), values)

