"""Several frames' detail brought into register in UV.

Each frame of a fit of several photos (or of a clip) has its own fitted pose and expression, and landmarks pin
the face's surface only to a few millimetres: one photo's geometry puts the beard, a mole or the brows' hairs a few
texels from where another photo's puts them (at yaw 35 degrees, 6 texels of a 256² map). One map fitted to all of
them then averages the misplaced copies: the stubble blurs, a mole doubles. Multi-view texturing meets the same
problem with per-image deformation fields (Zhou and Koltun, "Color map optimization for 3D reconstruction with
consumer depth cameras", 2014). Here each frame gets a smooth flow in UV that carries its unwrapped detail onto
the consensus of the other frames' (each moved by its own flow), and its mesh's UVs are moved by the flow, so every
frame samples the shared map where its own pixels' detail belongs.

The detail compared is each frame's unwrapped log-luminance high-passed: the fine structure of the albedo (shading
and a cast shadow's interior are smooth at that scale; their edges are weighed down by the frames' weights). The
flow is a coarse grid of offsets (``cells`` per side), bilinear between its nodes, fitted coarse to fine by
maximising the weighted correlation with the consensus, its size and roughness penalised. A flow that does not
raise the correlation clearly is not believed.

Shapes: S the map's side, G = ``cells`` + 1 the flow grid's nodes per side; flows in texels (x right, y down).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

from deface.decouple.fill import gaussian_blur


@dataclass(frozen=True)
class RegistrationConfig:
    """How the frames of a fit of several photos or of a clip are brought into register (module doc)."""

    enabled: bool = False
    """Register the frames of a fit of several photos or of a clip (one photo: nothing to register). Off: on the
    person sets it let stage 3 run twice as long and gave the stubble more of its structure and its own colour,
    but lost PSNR and raised the colour noise (docs/person.md)."""
    cells: int = 8
    """Cells of the flow's grid per side of the UV square: the flow bends on the scale of a cheek, not a pore."""
    detail_scale: float = 1 / 64
    """Width (sigma) of the high-pass that keeps the detail compared, as a share of the map's side."""
    max_side: int = 256
    """The flows are fitted on the maps shrunk to at most this side (the flow is smooth; its size scales up)."""
    steps: int = 60
    """Adam steps at each of the coarse-to-fine blurs."""
    size_weight: float = 0.002
    """Penalty on the flow's mean square size, per texel² at ``max_side``: no offset without evidence."""
    roughness_weight: float = 0.02
    """Penalty on the mean square difference of neighbouring grid nodes, per texel²."""
    rounds: int = 2
    """Each frame is registered to the consensus of the others (each moved by its latest flow) this many times."""
    min_gain: float = 0.1
    """A frame keeps its flow only if it raised the correlation of its detail with the consensus by this much
    (unrelated 256² patterns reach about 0.09 by chance; a true misplacement of a few texels, about 0.9)."""


def detail(log_luminance: np.ndarray, weight: np.ndarray, sigma: float) -> np.ndarray:
    """[S, S] the weighted high-pass of ``log_luminance`` [S, S] (``weight`` [S, S] >= 0): itself less its
    normalised Gaussian blur of ``sigma`` texels, 0 where the weight is 0."""
    values = torch.as_tensor(log_luminance * weight, dtype=torch.float32)[None, None]
    mass = torch.as_tensor(weight, dtype=torch.float32)[None, None]
    blurred = _blur(values, sigma) / _blur(mass, sigma).clamp_min(1e-6)
    return ((values / mass.clamp_min(1e-6) - blurred) * (mass > 0))[0, 0].numpy()


@dataclass(frozen=True)
class FrameFlow:
    """One frame's registration: its flow, and the weighted correlation of its detail with the other frames'."""

    flow: np.ndarray  # [S, S, 2] texels: the frame shows the others' texel x at x + flow(x)
    before: float  # correlation unmoved
    after: float  # correlation at the fitted flow (the flow is zero, and after = before, when it gained too little)


def register(details: list[np.ndarray], weights: list[np.ndarray], config: RegistrationConfig) -> list[FrameFlow]:
    """Per frame, the flow with ``details[i]`` at x + flow(x) matching the other frames' consensus at x (their
    details, each moved by its latest flow, averaged by their ``weights`` [S, S]), fitted in turn,
    ``config.rounds`` times over; then less the frames' weighted mean flow, so the maps stay where the frames'
    geometry puts them on average. A frame whose flow raised its correlation with the consensus by less than
    ``config.min_gain`` keeps none (a flow as free as this one finds a little correlation between unrelated
    patterns)."""
    side = details[0].shape[0]
    factor = min(1.0, config.max_side / side)
    small = [torch.as_tensor(_shrunk(d, factor))[None, None] for d in details]
    small_weights = [torch.as_tensor(_shrunk(w, factor))[None, None] for w in weights]
    grids = [torch.zeros(1, 2, config.cells + 1, config.cells + 1) for _ in details]
    moved = list(zip(small, small_weights, strict=True))
    for _ in range(config.rounds):
        for index in range(len(details)):  # each against the others as last moved (in turn: two frames fitted
            # at once to each other's unmoved detail would swap places)
            consensus, mass = _consensus(moved, index)
            grids[index] = _fit_grid(small[index], small_weights[index], consensus, mass, grids[index], config)
            flow = _upsampled(grids[index], small[index].shape[-1])
            moved[index] = (_warp(small[index], flow), _warp(small_weights[index], flow))
    gains = []
    for index, grid in enumerate(grids):
        consensus, mass = _consensus(moved, index)
        with torch.no_grad():
            before, after = (float(_correlation(small[index], small_weights[index], consensus, mass, g))
                             for g in (torch.zeros_like(grid), grid))
        if after - before < config.min_gain:
            grids[index], after = torch.zeros_like(grid), before
        gains.append((before, after))
    flows = [_upsampled(grid, side) / factor for grid in grids]
    dense = [torch.as_tensor(w)[None, None] for w in weights]
    mean = sum(f * w for f, w in zip(flows, dense, strict=True)) / sum(dense).clamp_min(1e-6)
    return [FrameFlow((f - mean)[0].permute(1, 2, 0).numpy(), *gain) for f, gain in zip(flows, gains, strict=True)]


def shifted_uvs(uvs: torch.Tensor, flow: np.ndarray) -> torch.Tensor:
    """[U, 2] the mesh UVs (v up) moved against ``flow`` [S, S, 2]: a frame whose geometry puts the shared map's
    texel x at x + flow(x) then samples the map at x (deface/models/uvmap.py: texel x = u S - 0.5, y = (1 - v) S
    - 0.5)."""
    side = flow.shape[0]
    planes = torch.as_tensor(flow, dtype=torch.float32).permute(2, 0, 1)[None]  # [1, 2, S, S]
    grid = torch.stack([uvs[:, 0] * 2 - 1, 1 - uvs[:, 1] * 2], -1).float()[None, None]  # align_corners=False
    offset = F.grid_sample(planes, grid, mode="bilinear", padding_mode="border", align_corners=False)[0, :, 0].T
    moved = torch.stack([uvs[:, 0] - offset[:, 0].to(uvs.dtype) / side,
                         uvs[:, 1] + offset[:, 1].to(uvs.dtype) / side], -1)
    return moved.clamp(0, 1)


def _consensus(moved: list[tuple[torch.Tensor, torch.Tensor]], index: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The weighted mean [1, 1, S, S] of the (moved) details of every frame but ``index``, and their summed
    weight clipped at 1."""
    others = [pair for other, pair in enumerate(moved) if other != index]
    mass = sum(w for _, w in others)
    return sum(d * w for d, w in others) / mass.clamp_min(1e-6), mass.clamp(max=1.0)


@torch.enable_grad()
def _fit_grid(moving: torch.Tensor, moving_weight: torch.Tensor, fixed: torch.Tensor, fixed_weight: torch.Tensor,
              start: torch.Tensor, config: RegistrationConfig) -> torch.Tensor:
    """[1, 2, G, G] the flow grid (texels of these [1, 1, S, S] maps), from ``start``, that best carries ``moving``
    onto ``fixed``, coarse to fine."""
    grid = start.clone().requires_grad_(True)
    optimiser = torch.optim.Adam([grid], lr=0.25)
    for blur in (2.0, 1.0, 0.0):
        blurred_moving, blurred_fixed = _blur(moving, blur), _blur(fixed, blur)
        for _ in range(config.steps):
            optimiser.zero_grad()
            loss = -_correlation(blurred_moving, moving_weight, blurred_fixed, fixed_weight, grid)
            loss = loss + config.size_weight * grid.square().mean()
            roughness = grid.diff(dim=2).square().mean() + grid.diff(dim=3).square().mean()
            loss = loss + config.roughness_weight * roughness
            loss.backward()
            optimiser.step()
    return grid.detach()


def _correlation(moving: torch.Tensor, moving_weight: torch.Tensor, fixed: torch.Tensor, fixed_weight: torch.Tensor,
                 grid: torch.Tensor) -> torch.Tensor:
    """The weighted correlation of ``moving`` read at x + the grid's flow with ``fixed`` (where both see)."""
    flow = _upsampled(grid, moving.shape[-1])
    weight = _warp(moving_weight, flow) * fixed_weight
    total = weight.sum().clamp_min(1e-6)
    a = _warp(moving, flow)
    a = a - (a * weight).sum() / total
    b = fixed - (fixed * weight).sum() / total
    return (a * b * weight).sum() / ((a.square() * weight).sum() * (b.square() * weight).sum()).sqrt().clamp_min(1e-9)


def _warp(image: torch.Tensor, flow: torch.Tensor) -> torch.Tensor:
    """[1, C, S, S] ``image`` read at x + flow(x) (flow [1, 2, S, S] in texels), 0 outside."""
    side = image.shape[-1]
    base = (torch.arange(side, dtype=torch.float32) + 0.5) / side * 2 - 1
    ys, xs = torch.meshgrid(base, base, indexing="ij")
    grid = torch.stack([xs + flow[0, 0] * 2 / side, ys + flow[0, 1] * 2 / side], -1)[None]
    return F.grid_sample(image, grid, mode="bilinear", padding_mode="zeros", align_corners=False)


def _upsampled(grid: torch.Tensor, side: int) -> torch.Tensor:
    """[1, 2, side, side] the flow between the grid's nodes (bilinear; the nodes on the map's corners and edges)."""
    return F.interpolate(grid, size=(side, side), mode="bilinear", align_corners=True)


def _shrunk(image: np.ndarray, factor: float) -> np.ndarray:
    if factor >= 1.0:
        return image.astype(np.float32)
    size = max(8, round(image.shape[0] * factor))
    tensor = torch.as_tensor(image, dtype=torch.float32)[None, None]
    return F.interpolate(tensor, size=(size, size), mode="area")[0, 0].numpy()


def _blur(image: torch.Tensor, sigma: float) -> torch.Tensor:
    """[1, C, S, S] blurred by a Gaussian of ``sigma`` texels (0: unchanged)."""
    return gaussian_blur(image[0], sigma)[None] if sigma > 0 else image
