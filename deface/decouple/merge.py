"""Merging light conditions that one light explains: the number of lights chosen by the photo, not by f.

ACE keeps the lights whose masks are large; nothing asks whether two kept lights are needed. f is free to cut
an evenly lit face in two (at the mouth, along a beard) and give each part a light of its own. A light fitted
to a region's few evidence pixels is then extrapolated over the pixels without evidence, a beard among them,
and the map takes the difference (docs/textures.md "Lights that one light explains").

The test is the photo's: the render is linear in each light's SH coefficients, so the best single light over
two regions and the best light per region are linear least squares over the evidence pixels. Two lights are
one when one light fits their union nearly as well as two fit their parts:

    cost = max over the two lights' pixels of (relative RMS error of the light over both
                                                - relative RMS error of that part's own light)

A cast shadow cannot be fitted by one smooth light over both sides of its edge, and its cost is large; a
face cut where nothing changes costs nothing.

Shapes: N evidence pixels (all frames), J = B*B SH coefficients, 3 colours, G kept lights.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch


@dataclass(frozen=True)
class MergeEvidence:
    """What the test reads at the evidence pixels (all frames stacked)."""

    basis: torch.Tensor  # [N, J, 3] the render of each SH coefficient alone (a unit light, unclamped)
    target: torch.Tensor  # [N, 3] the photo
    weight: torch.Tensor  # [N] evidence weight (h times the shading evidence), > 0
    label: torch.Tensor  # [N] long: the kept light (0..G-1) whose mask is largest at the pixel

    def __post_init__(self):
        n = self.target.shape[0]
        if self.basis.dim() != 3 or self.basis.shape[0] != n or self.basis.shape[2] != self.target.shape[1]:
            raise ValueError(f"basis {tuple(self.basis.shape)} does not match target {tuple(self.target.shape)}")
        if self.weight.shape != (n,) or self.label.shape != (n,):
            raise ValueError(f"weight {tuple(self.weight.shape)} and label {tuple(self.label.shape)} need [{n}]")


def best_light_render(evidence: MergeEvidence, select: torch.Tensor, ridge: float) -> torch.Tensor:
    """The render [n, 3] at the pixels ``select`` [N] (bool) of the single light that fits them best: per colour,
    weighted least squares damped by ``ridge`` times the normal matrix's mean diagonal (which keeps a region
    with few pixels well posed)."""
    weight = evidence.weight[select].double()
    basis, target = evidence.basis[select].double(), evidence.target[select].double()
    render = torch.empty_like(target)
    for colour in range(target.shape[1]):
        design = basis[:, :, colour]  # [n, J]
        normal = design.T @ (design * weight[:, None])  # [J, J]
        damping = ridge * float(normal.diagonal().mean().clamp_min(1e-12))
        normal = normal + damping * torch.eye(normal.shape[0], dtype=normal.dtype)
        render[:, colour] = design @ torch.linalg.solve(normal, design.T @ (weight * target[:, colour]))
    return render


def relative_error(evidence: MergeEvidence, select: torch.Tensor, render: torch.Tensor) -> float:
    """The weighted RMS of ``render`` [n, 3] against the photo at the pixels ``select`` [N], over their weighted
    mean intensity (both per colour)."""
    weight, target = evidence.weight[select].double(), evidence.target[select].double()
    squared = (weight * (render - target).square().mean(dim=1)).sum() / weight.sum()
    level = (weight * target.mean(dim=1)).sum() / weight.sum()
    return float(squared.sqrt() / level.clamp_min(1e-12))


def region_errors(evidence: MergeEvidence, first: int, second: int,
                  ridge: float = 1e-4) -> list[tuple[float, float]] | None:
    """For each of the two lights' pixels: (relative error of its own best light, of the best light over both);
    None when either light has no pixel."""
    parts = [evidence.label == first, evidence.label == second]
    if not all(bool(part.any()) for part in parts):
        return None
    union = parts[0] | parts[1]
    joint = torch.zeros_like(evidence.target, dtype=torch.float64)
    joint[union] = best_light_render(evidence, union, ridge)
    return [(relative_error(evidence, part, best_light_render(evidence, part, ridge)),
             relative_error(evidence, part, joint[part])) for part in parts]


def merge_cost(evidence: MergeEvidence, first: int, second: int, ridge: float = 1e-4) -> float:
    """How much worse one light fits either light's pixels than that light's own best light does: the largest
    rise of the relative error over the two (a small shadow's region counts as much as the face around it).
    inf when either light has no pixel."""
    errors = region_errors(evidence, first, second, ridge)
    if errors is None:
        return math.inf
    return max(joint - own for own, joint in errors)


def cheapest_merge(evidence: MergeEvidence, num_lights: int, ridge: float = 1e-4) -> tuple[int, int, float] | None:
    """The pair (first, second) of kept lights whose merge costs least, and its cost; None for one light."""
    pairs = [(a, b, merge_cost(evidence, a, b, ridge)) for a in range(num_lights) for b in range(a + 1, num_lights)]
    return min(pairs, key=lambda pair: pair[2]) if pairs else None
