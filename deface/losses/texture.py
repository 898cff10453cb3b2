"""Stage-3 texture regularisers: NextFace's, with the weights the paper's code passes to them.

Per UV map T against its statistical initialisation T^0 (all maps [Ht, Wt, C], mask [Ht, Wt] = UV face area):
- symmetry: mean |T - mirror(T)|, mirror = flip in u (the ICT UV layout is symmetric about u = 0.5);
- reference: mean |T - T^0|;
- chromaticity: mean |xy(T) - xy(T^0)| with CIE xy from linear RGB (3-channel maps only);
- smoothness: *sum* of squared differences of neighbouring texels (a sum, as coded: per-texel noise costs in
  proportion to the texel count, a smooth map about the same at any resolution);
- grey: sum of squared deviations from each texel's channel mean (specular: keeps the highlight white).
Means are over all texels with the terms zeroed outside the mask, i.e. the authors' mean over the whole map
with the unused UV area left at T^0. The L1 terms make small deviations from T^0 costly in proportion to
their size, so stage 3 only departs from T^0 where the photo pays for it, and the symmetry term makes a
one-sided change (a cast shadow on one cheek) cost twice (``../shared/docs/method-facts.md``, Stage 3).
The authors also penalise values outside [0, 1]; stage 3 clamps the maps instead.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import torch

from deface.render.mesh import Textures

# Linear sRGB (D65) -> CIE XYZ, scaled to 0-100 as in NextFace's chromaticity term.
RGB_TO_XYZ = 100.0 * torch.tensor([[0.412391, 0.357584, 0.180481],
                                   [0.212639, 0.715169, 0.072192],
                                   [0.019331, 0.119195, 0.950532]])


@dataclass(frozen=True)
class MapWeights:
    """Weights of one map's terms (the authors' config names in brackets)."""

    symmetry: float  # weight*SymmetryReg
    reference: float  # weight*ConsistencyReg (passed as the RGB reference weight)
    chromaticity: float  # weight*ConsistencyReg (passed as the xy consistency weight)
    smoothness: float  # weight*SmoothnessReg
    grey: float = 0.0  # the mean-colour weight (0.5 for specular)

    def relative(self, scale: float) -> MapWeights:
        """The weights for maps ``1 / scale`` times as bright (a reference level over the map's): each term is
        homogeneous in the maps (degree 1: symmetry, reference; 2: smoothness, grey; 0: chromaticity, but for the
        1 that keeps black finite), so T / scale against T^0 / scale costs with these what T against T^0 costs
        with ``self``."""
        return replace(self, symmetry=self.symmetry * scale, reference=self.reference * scale,
                       smoothness=self.smoothness * scale ** 2, grey=self.grey * scale ** 2)


# The paper's code: diffuse 300/100/0.001, specular 200/2/0.001 with 0.5 grey, roughness 200/0/0.002.
PAPER_WEIGHTS = {
    "diffuse": MapWeights(symmetry=300.0, reference=100.0, chromaticity=100.0, smoothness=0.001),
    "specular": MapWeights(symmetry=200.0, reference=2.0, chromaticity=2.0, smoothness=0.001, grey=0.5),
    "roughness": MapWeights(symmetry=200.0, reference=0.0, chromaticity=0.0, smoothness=0.002),
}


def mirror_u(texture: torch.Tensor) -> torch.Tensor:
    """The map mirrored left-right in UV: [Ht, Wt, C] flipped along u (the width axis)."""
    return texture.flip(1)


def chromaticity(rgb: torch.Tensor) -> torch.Tensor:
    """CIE xy of linear RGB [..., 3] -> [..., 2]: X / (1 + X + Y + Z), Y / (1 + X + Y + Z) on a 0-100 scale
    (the 1 keeps black finite)."""
    xyz = rgb @ RGB_TO_XYZ.to(rgb).T
    return xyz[..., :2] / (1.0 + xyz.clamp_min(0).sum(-1, keepdim=True))


def neighbour_smoothness(texture: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Sum of squared differences of horizontally and vertically adjacent texels inside ``mask``."""
    dx = (texture[:, 1:] - texture[:, :-1]).pow(2).sum(-1) * mask[:, 1:] * mask[:, :-1]
    dy = (texture[1:] - texture[:-1]).pow(2).sum(-1) * mask[1:] * mask[:-1]
    return dx.sum() + dy.sum()


def map_regulariser(texture: torch.Tensor, reference: torch.Tensor, mask: torch.Tensor,
                    weights: MapWeights) -> torch.Tensor:
    """Weighted terms of one map (see the module doc); texture, reference [Ht, Wt, C], mask [Ht, Wt]."""
    channels = texture.shape[-1]

    def masked_mean(per_texel: torch.Tensor) -> torch.Tensor:  # [Ht, Wt, c] -> mean over every value
        return (per_texel * mask[..., None]).sum() / per_texel.numel()

    both_sides = mask * mirror_u(mask)  # texels whose mirror image is also on the face
    loss = weights.symmetry * (((texture - mirror_u(texture)).abs() * both_sides[..., None]).sum()
                               / texture.numel())
    loss = loss + weights.reference * masked_mean((texture - reference).abs())
    if weights.chromaticity and channels == 3:
        loss = loss + weights.chromaticity * masked_mean((chromaticity(texture) - chromaticity(reference)).abs())
    loss = loss + weights.smoothness * neighbour_smoothness(texture, mask)
    if weights.grey:
        grey = (texture - texture.mean(-1, keepdim=True)).pow(2)
        loss = loss + weights.grey * (grey * mask[..., None]).sum()
    return loss


def texture_regularisers(textures: Textures, initial: Textures, mask: torch.Tensor,
                         weights: dict[str, MapWeights] = PAPER_WEIGHTS) -> torch.Tensor:
    """Sum of :func:`map_regulariser` over the diffuse, specular and roughness maps."""
    total = torch.zeros(())
    for name, map_weights in weights.items():
        total = total + map_regulariser(getattr(textures, name), getattr(initial, name), mask, map_weights)
    return total


class SmoothDeparture:
    """Mean squared log departure of a diffuse map's low frequencies from T^0's beyond one gain per channel.

    Both maps (linear, [Ht, Wt, 3]) are averaged over ``cells`` x ``cells`` blocks of the UV face (mask [Ht, Wt];
    blocks under half covered are left out). The photos cannot tell a smooth change of albedo from a smooth
    change of shading the lights do not model (soft shadow residue, occlusion), so such changes are left to T^0;
    one overall gain per channel (the tone the photo shows) and everything finer than a block stay free. Every
    channel counts: with the brightness alone held (the mean over channels), stage 3 drew dark brows and folds
    with coloured fringes, a cheaper way to darken one channel. T^0's side is computed once."""

    def __init__(self, reference: torch.Tensor, mask: torch.Tensor, cells: int):
        self.mask, self.block = mask, max(1, reference.shape[0] // cells)  # maps under ``cells``: per texel
        cover = torch.nn.functional.avg_pool2d(mask[None, None], self.block)[0, 0]
        self.used, self.cover = cover > 0.5, cover.clamp_min(1e-6)
        self.log_reference = self._log_blocks(reference)

    def _log_blocks(self, texture: torch.Tensor) -> torch.Tensor:  # [Ht, Wt, 3] -> [3, blocks used]
        pooled = torch.nn.functional.avg_pool2d((texture * self.mask[..., None]).permute(2, 0, 1)[None],
                                                 self.block)[0] / self.cover
        return pooled.clamp_min(1e-4).log()[:, self.used]

    def __call__(self, diffuse: torch.Tensor) -> torch.Tensor:
        log_ratio = self._log_blocks(diffuse) - self.log_reference  # [3, blocks used]
        return (log_ratio - log_ratio.mean(-1, keepdim=True)).pow(2).mean()

