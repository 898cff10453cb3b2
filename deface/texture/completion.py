"""Texture completion: texels the photos did not show get plausible values, so the head reads as one.

Inputs are the fitted maps T, the albedo model's maps T^0 at the fitted coefficients, and ``seen`` [Ht, Wt]
(visible x face region x facing, :meth:`deface.texture.confidence.TexelView.seen`). With
trust t = blur(clip(seen / seen_full, 0, 1)) (blurred so no seam shows where visibility stops):
1. mirror: where the u-mirrored texel is more trusted (a turned face), T moves towards mirror(T) by the
   difference of trust, and t becomes max(t, mirror t); only for a layout symmetric in u;
2. the person's skin: the rest is T^0 x g, g the per-channel median ratio T / T^0 over trusted texels, so
   unseen skin (ears, neck, the far side) takes the person's tone with the prior's structure;
3. the mouth cavity (the inner rolls of the lips, facing into the mouth) takes the person's lip colour
   darkened to a cavity's shade where it was not seen.
Trusted texels keep their fitted value exactly (t = 1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from deface.models.albedo_prior import vertex_uvs
from deface.models.uvmap import polygon_mask, rasterize_uv
from deface.render.mesh import Mesh

MIN_TRUSTED = 50  # fewer trusted skin texels than this: no colour gain (g = 1)


@dataclass(frozen=True)
class CompletionConfig:
    """How unseen texels are filled (``FitConfig.completion``)."""

    enabled: bool = True
    """Fill unseen texels after stage 3 (docs/textures.md "Completion"). Off, as in the paper (``paper``): the
    maps are stage 3's as they are."""
    seen_full: float = 0.5
    """A texel seen at least this squarely (visible x h x cos angle) keeps its fitted value."""
    blur: float = 0.01
    """Gaussian sigma of the trust map, as a fraction of the map's side (2.6 texels at 256²)."""
    mirror: bool = True
    """Copy from the mirrored texel where it was seen better (layouts symmetric in u only)."""
    cavity_shade: float = 0.35
    """The mouth cavity's colour: the person's lip colour times this (a cavity gets little light)."""


@dataclass(frozen=True)
class CompletionRegions:
    """UV regions completion needs, [Ht, Wt] bool, from the face model's layout (see :func:`layout_regions`)."""

    face: np.ndarray  # texels covered by the layout
    lips: np.ndarray  # the outer-lip polygon (68-point landmarks 48-59)
    cavity: np.ndarray  # inside the lips and facing into the mouth (the lips' inner rolls)
    symmetric: bool  # the layout is symmetric in u (mirroring is meaningful)

    @property
    def skin(self) -> np.ndarray:
        """[Ht, Wt] bool: the layout's skin, the face less the lips (where the person's skin colour is read)."""
        return self.face & ~self.lips


def trust_map(seen: np.ndarray, config: CompletionConfig) -> np.ndarray:
    """[Ht, Wt] in [0, 1]: how much of a texel's fitted value is kept."""
    trust = np.clip(seen / config.seen_full, 0.0, 1.0)
    return np.clip(ndimage.gaussian_filter(trust, config.blur * seen.shape[0]), 0.0, 1.0)


def mirror_fill(texture: np.ndarray, trust: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Move texels towards their u-mirror where the mirror is more trusted; returns (texture, trust)."""
    mirrored_trust = trust[:, ::-1]
    gain = np.clip(mirrored_trust - trust, 0.0, 1.0)[..., None]
    return texture + gain * (texture[:, ::-1] - texture), np.maximum(trust, mirrored_trust)


def skin_gain(texture: np.ndarray, prior: np.ndarray, trust: np.ndarray, skin: np.ndarray) -> np.ndarray:
    """[C] median of texture / prior over trusted (> 0.9) skin texels; 1 with too few of them."""
    chosen = (trust > 0.9) & skin
    if chosen.sum() < MIN_TRUSTED:
        return np.ones(texture.shape[-1])
    return np.median(texture[chosen] / np.maximum(prior[chosen], 1e-4), axis=0)


def complete_map(texture: np.ndarray, prior: np.ndarray, seen: np.ndarray, regions: CompletionRegions,
                 config: CompletionConfig, cavity: bool = False) -> np.ndarray:
    """One completed map [Ht, Wt, C]; ``cavity`` also shades the unseen mouth cavity (diffuse map)."""
    trust = trust_map(seen, config)
    if config.mirror and regions.symmetric:
        texture, trust = mirror_fill(texture, trust)
    gain = skin_gain(texture, prior, trust, regions.skin)
    fill = prior * gain
    if cavity:
        lip_colour = _lip_colour(texture, prior * gain, trust, regions.lips & ~regions.cavity)
        fill = np.where(regions.cavity[..., None], lip_colour * config.cavity_shade, fill)
    completed = trust[..., None] * texture + (1.0 - trust[..., None]) * fill
    return np.clip(completed, 0.0, 1.0).astype(np.float32)


def _lip_colour(texture: np.ndarray, prior: np.ndarray, trust: np.ndarray, lips: np.ndarray) -> np.ndarray:
    """[C] median colour of the trusted lips, else of the (tone-matched) prior's lips."""
    trusted = lips & (trust > 0.9)
    source = texture[trusted] if trusted.sum() >= MIN_TRUSTED else prior[lips]
    return np.median(source, axis=0) if len(source) else np.median(prior.reshape(-1, prior.shape[-1]), 0)


def layout_regions(model, size: int) -> CompletionRegions:
    """The completion regions of ``model``'s UV layout at size² (needs its 68 landmark vertices for the lips)."""
    raster = rasterize_uv(model.uvs, model.triangle_uvs, size)
    face = raster.covered
    lips = np.zeros_like(face)
    cavity = np.zeros_like(face)
    if model.landmarks_68 is not None:
        uv = vertex_uvs(model.triangles, model.uvs, model.triangle_uvs, model.num_vertices)[model.landmarks_68]
        lips = (polygon_mask(uv[48:60], size) > 0) & face
        cavity = lips & (_neutral_forward(model, raster) < CAVITY_FACING)
    return CompletionRegions(face, lips, cavity, symmetric=_symmetric(face))


CAVITY_FACING = 0.5  # lip texels whose neutral normal is more than 60 degrees from the face's forward (+z)


def _neutral_forward(model, raster) -> np.ndarray:
    """[Ht, Wt] z component of the neutral shape's unit normal at each texel (+z: the face's forward)."""
    mesh = Mesh.create(model.mean_shape, model.triangles, model.uvs, model.triangle_uvs)
    normals = raster.interpolate_vertices(mesh.vertex_normals().double().numpy(), model.triangles, fill=False)
    return normals[..., 2] / np.maximum(np.linalg.norm(normals, axis=-1), 1e-12)


def _symmetric(face: np.ndarray, agreement: float = 0.95) -> bool:
    """Whether the layout's coverage is (nearly) its own u-mirror."""
    both = (face & face[:, ::-1]).sum()
    return bool(face.sum() and both / face.sum() >= agreement)
