"""A texture whose degrees of freedom match what the photos constrain: a gated Laplacian-style pyramid.

Stage 3 refines the UV maps from T^0. Stored per texel, every texel is free, including the ones a photo pixel
shares with three others (2 texels per pixel side) or sees at a grazing angle: the photometric loss does not
see their differences, Adam still steps each of them by about its learning rate, and the map fills with
per-texel colour noise (speckle). Here a map is

    T = T^0 + sum_l up(g_l * P_l),     level l of side N / 2^l, up = bilinear upsampling to N,

with gate g_l = clip(D_l, 0, 1)^p (p = ``gate_power``), D_l the pixels per level-l texel (the frames' texel
density summed over frames, :attr:`deface.texture.confidence.TexelView.density`, pooled to the level and times
4^l). A level is
free where the photos give it at least a pixel per texel and damped in proportion where they give less, so
the detail a photo shows (stubble, moles, wrinkles at its resolution) is fitted at the finest level it
supports and nothing finer. The coarsest level is always free (gate 1). With ``levels = 1`` the map is the
per-texel parametrisation of the paper.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import torch
import torch.nn.functional as F

from deface.texture import fast_pyramid


@dataclass(frozen=True)
class PyramidConfig:
    """The stage-3 texture parametrisation (``FitConfig.texture_pyramid``)."""

    levels: int = 5
    """Pyramid levels: coarse levels carry what the photos' pixels cannot resolve per texel, so a map does not
    fill with per-texel colour noise (docs/textures.md "Stage 3's maps"). 1 = one free value per texel, the
    paper's parametrisation (``paper``)."""
    min_side: int = 16
    """No level is coarser than this many texels per side (fewer levels on small maps)."""
    gated: bool = True
    """Damp each level where the photos give less than a pixel per texel of that level (see the module doc)."""
    frames: Literal["sum", "best"] = "sum"
    """How several frames' pixels per texel make the gates: "sum", all frames' together (a texel seen by three
    frames may be finer than any one frame resolves); "best", the frame that sees it most densely. With the
    frames brought into register (``registration``) "best" lowered the colour error on every person set measured,
    but the PSNR and the beard's darkness on most (docs/experiments/person-log.md)."""
    gate_power: float = 2.0
    """Gates are clip(D_l, 0, 1) ** gate_power. Adam steps every parameter by about its learning rate whatever
    its gradient, so a gate is a per-texel speed limit, and a linear one (power 1) still let sparsely seen
    texels drift: on two benchmark pairs power 1 / 2 / 3 left speckle 4.6 / 2.0 / 1.4 (per-texel maps: 8.0) and
    fine contrast 1.29 / 1.06 / 1.02 times the photo's (per-texel: 1.72), with the same UV consistency and target
    synthesis; 3 starts to lose the photo's own detail on one pair (0.92), so 2 (docs/textures.md)."""


def level_sizes(size: int, config: PyramidConfig) -> list[int]:
    """Sides of the levels, finest first: size, size/2, ... (at least one level, none below min_side)."""
    sizes = [size]
    while len(sizes) < config.levels and sizes[-1] // 2 >= config.min_side and sizes[-1] % 2 == 0:
        sizes.append(sizes[-1] // 2)
    return sizes


def level_gates(density: np.ndarray, sizes: list[int], gated: bool = True, power: float = 1.0) -> list[torch.Tensor]:
    """[s, s] gate per level: clip(pixels per level texel, 0, 1) ** power; the coarsest level (and every level
    when not ``gated``) is 1. ``density`` [N, N] is pixels per texel at the finest level."""
    full = torch.as_tensor(np.asarray(density), dtype=torch.float32)[None, None]
    gates = []
    for index, side in enumerate(sizes):
        if not gated or index == len(sizes) - 1:
            gates.append(torch.ones(side, side))
            continue
        factor = sizes[0] // side
        per_level_texel = F.avg_pool2d(full, factor)[0, 0] * factor**2 if factor > 1 else full[0, 0]
        gates.append(per_level_texel.clamp(0, 1) ** power)
    return gates


class TexturePyramid(torch.nn.Module):
    """One UV map [N, N, C] as T^0 plus gated levels (see the module doc); starts at T^0 exactly."""

    def __init__(self, initial: torch.Tensor, gates: list[torch.Tensor]):
        super().__init__()
        self.register_buffer("initial", initial.detach().clone())  # [N, N, C]
        channels = initial.shape[-1]
        self.levels = torch.nn.ParameterList(
            [torch.nn.Parameter(torch.zeros(channels, *gate.shape)) for gate in gates])  # [C, s, s]
        for index, gate in enumerate(gates):
            self.register_buffer(f"gate{index}", gate.detach().clone())

    def forward(self) -> torch.Tensor:
        """The map: the op ``pyramid_map`` (deface/texture/fast_pyramid.py; one loop per level on the CPU)."""
        return fast_pyramid.pyramid_map(self.initial, self._gates(), *self.levels)

    def reference(self) -> torch.Tensor:
        """The map by torch ops (the op's reference, the definition the fast path is tested against)."""
        return fast_pyramid.pyramid_map.reference(self.initial, self._gates(), *self.levels)

    def _gates(self) -> list[torch.Tensor]:
        return [getattr(self, f"gate{index}") for index in range(len(self.levels))]
