"""What the fitted frames tell about each texel: per-frame texel views and the texture confidence map.

Per frame, the pixel weight of the confidence (:mod:`deface.texture.confidence`) is the face region M_o times
the unshadowed fraction of the light: sum_k M_k Y(I_k) / max_k Y(I_k) over the kept lights k (Y: luminance of
the per-light render I_k, the albedo cancels), 1 where the brightest light reaches the pixel, the shadow light's
share where the masks put a cast shadow. The geometric ``seen`` factor (visible x h x facing, no resolution,
no shadow) is what the evaluation's UV measure selects texels with: it does not depend on the method.
"""

from __future__ import annotations

import numpy as np
import torch

from deface.fit.log import FitLog
from deface.io.images import LUMINANCE
from deface.models.uvmap import rasterize_uv
from deface.render.mesh import Textures
from deface.texture.chroma import ChromaConfig, filter_chroma, skin_chroma_gain, texels_per_pixel
from deface.texture.completion import CompletionConfig, complete_map, layout_regions
from deface.texture.confidence import TexelView, combine_frames, texel_view, unwrap
from deface.texture.pigment_gamut import PigmentGamutConfig, in_pigment_gamut, outside_share
from deface.texture.shade_level import ShadeLevelConfig, lit_share, shade_levelled

LUMINANCE_T = torch.as_tensor(LUMINANCE, dtype=torch.float32)

def frame_views(model, frozen: list, size: int) -> list[TexelView]:
    """The texel view of each frozen frame's working-resolution camera for a size² map of its mesh's layout:
    ``model``'s, or its UVs moved into register (deface/fit/frame_register.py)."""
    layout = rasterize_uv(model.uvs, model.triangle_uvs, size)
    views = []
    for frame in frozen:
        geometry = frame.geometry
        moved = geometry.moves_uvs(model.uvs)
        raster = rasterize_uv(geometry.mesh.uvs.numpy(), model.triangle_uvs, size) if moved else layout
        views.append(texel_view(raster, geometry.mesh, geometry.camera))
    return views


def unshadowed_fraction(light_images: torch.Tensor, light_masks: torch.Tensor) -> np.ndarray:
    """[H, W] in [0, 1]: sum_k M_k Y(I_k) / max_k Y(I_k); light_images [K, H, W, 3], light_masks [K, H, W]."""
    luminance = light_images.detach() @ LUMINANCE_T.to(light_images.dtype)  # [K, H, W]
    brightest = luminance.max(0).values
    reached = (luminance * light_masks.detach()).sum(0)
    fraction = torch.where(brightest > 1e-6, reached / brightest.clamp_min(1e-6), torch.zeros_like(brightest))
    return fraction.clamp(0, 1).numpy()


def texture_confidence(views: list[TexelView], renders: list) -> np.ndarray:
    """[Ht, Wt] confidence over all frames; ``renders`` are the frames' FrameRender (M_o, masks, I_k)."""
    per_frame = []
    for view, rendered in zip(views, renders, strict=True):
        weight = rendered.face_region.detach().numpy() * unshadowed_fraction(rendered.light_images,
                                                                               rendered.light_masks)
        per_frame.append(view.confidence(weight))
    return combine_frames(per_frame)


def seen_texels(views: list[TexelView], face_regions: list[torch.Tensor]) -> np.ndarray:
    """[Ht, Wt] in [0, 1]: how squarely some frame saw each texel inside its face region h (no resolution term)."""
    looks = [view.seen(region.detach().numpy()) for view, region in zip(views, face_regions, strict=True)]
    return np.max(np.stack(looks), 0)


def light_at_texels(diffuse: np.ndarray, views: list[TexelView], renders: list) -> np.ndarray:
    """[Ht, Wt] the shading at each texel (the render's luminance over the albedo's, the masks and the geometry's
    shading and cast shadows in it), in the frame that lights it most; ``diffuse`` [Ht, Wt, 3] the rendered map."""
    albedo = np.maximum(diffuse @ LUMINANCE, 1e-4)
    per_frame = [unwrap((rendered.face.detach().numpy() @ LUMINANCE)[..., None], view)[..., 0] / albedo
                 for view, rendered in zip(views, renders, strict=True)]
    return np.max(np.stack(per_frame), 0)


def shade_levelled_textures(textures: Textures, seen_map: np.ndarray, views: list[TexelView], renders: list,
                            config: ShadeLevelConfig) -> Textures:
    """Stage 3's maps with the texels the render lights dimly moved to the lit skin's level and colour around them
    (deface/texture/shade_level.py)."""
    diffuse = textures.diffuse.detach().numpy()
    lit = lit_share(light_at_texels(diffuse, views, renders), seen_map, config)
    diffuse = shade_levelled(diffuse, lit, seen_map, config)
    return Textures(torch.from_numpy(diffuse), textures.specular, textures.roughness)


def filtered_chroma(textures: Textures, seen_map: np.ndarray, views: list[TexelView],
                    config: ChromaConfig) -> Textures:
    """Stage 3's maps with the diffuse map's chroma guided by its luminance (deface/texture/chroma.py), its window
    at least ``config.pixels`` of the frames' pixels wide (the best frame's at each texel)."""
    density = np.max([view.density for view in views], axis=0)
    diffuse = filter_chroma(textures.diffuse.detach().numpy(), seen_map, config,
                            texels_per_pixel(density, seen_map))
    return Textures(torch.from_numpy(diffuse), textures.specular, textures.roughness)


def pigment_gamut_textures(textures: Textures, seen_map: np.ndarray, config: PigmentGamutConfig,
                           log: FitLog) -> Textures:
    """The maps with the diffuse map's hues held to the pigments' gamut (deface/texture/pigment_gamut.py); the share
    of seen texels that were outside it said in ``log``."""
    diffuse = textures.diffuse.detach().numpy()
    share = outside_share(diffuse, seen_map)
    if share >= 0.0005:  # said from what prints as 0.1 % up
        log.info(f"{100 * share:.1f} % of the seen texels had a hue no skin, hair or lip pigment makes (a light's "
                 "colour left in the map): they took the skin's around them (pigment_gamut.enabled=false keeps them, "
                 "for blue, green or violet make-up)")
    diffuse = in_pigment_gamut(diffuse, seen_map, config)
    return Textures(torch.from_numpy(diffuse), textures.specular, textures.roughness)


SKIN_SEEN = 0.5
"""The texels whose colour the skin's chroma is read from: seen at least this squarely (completion's ``seen_full``)."""


def skin_chroma_matched(model, textures: Textures, seen_map: np.ndarray, skin: np.ndarray,
                        lights: torch.Tensor) -> tuple[Textures, np.ndarray | None]:
    """The maps with the skin's chroma of ``skin`` [3] (:func:`~deface.texture.chroma.skin_chroma_gain` over the
    texels seen at least ``SKIN_SEEN`` squarely, the lips left out), and the gain [3]; ``lights`` [n, B*B, 3] are
    divided by it in place, so every render is unchanged (diffuse and specular both multiply the light). Gain None:
    too little skin seen, nothing changed."""
    texels = (seen_map >= SKIN_SEEN) & layout_regions(model, seen_map.shape[0]).skin
    gain = skin_chroma_gain(textures.diffuse.detach().numpy(), texels, skin)
    if gain is None:
        return textures, None
    factor = torch.as_tensor(gain, dtype=textures.diffuse.dtype)
    lights.div_(factor.to(lights.dtype))
    return Textures((textures.diffuse * factor).clamp(0, 1), textures.specular * factor, textures.roughness), gain


def complete_textures(model, textures: Textures, initial: Textures, seen_map: np.ndarray,
                      config: CompletionConfig) -> Textures:
    """Stage 3's maps with the unseen texels completed (deface/texture/completion.py)."""
    regions = layout_regions(model, seen_map.shape[0])
    maps = {}
    for name in ("diffuse", "specular", "roughness"):
        fitted, prior = getattr(textures, name).detach().numpy(), getattr(initial, name).detach().numpy()
        maps[name] = torch.from_numpy(complete_map(fitted, prior, seen_map, regions, config,
                                                   cavity=name == "diffuse"))
    maps["roughness"] = maps["roughness"].clamp_min(0.05)  # stage 3's roughness range
    return Textures(**maps)
