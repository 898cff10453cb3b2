"""Stage 3's frames of several photos or a clip brought into register in UV (deface/texture/registration.py).

Each frame's detail is its photo over its stage-2 render with T^0 (log luminance: the albedo's departure from T^0
that stage 3 must explain, the fitted shading and the masks' shadows divided out), unwrapped to the map and
weighted by how well the frame sees each texel (visible, facing, pixels per texel, h, the unshadowed share of the
light). Each frame's mesh UVs move by its flow onto the other frames' consensus.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import torch

from deface.fit.texels import LUMINANCE_T, unshadowed_fraction
from deface.texture.confidence import TexelView, unwrap
from deface.texture.registration import detail, register, shifted_uvs


def registers(context) -> bool:
    """Whether this fit's frames are registered: several of them, and ``config.registration`` on."""
    return context.config.registration.enabled and context.target.num_frames > 1


@torch.no_grad()
def frame_uvs(context, frozen: list, views: list[TexelView], initial, render) -> list[torch.Tensor]:
    """Per frozen frame, its mesh's UVs [U, 2] moved into register with the other frames (module doc).
    ``render(context, frame, textures)`` renders a frozen frame (stage 3's render_frozen)."""
    config = context.config.registration
    side = views[0].visible.shape[0]
    sigma = config.detail_scale * side
    details, weights = [], []
    for frame, view in zip(frozen, views, strict=True):
        rendered = render(context, frame, initial)[0]
        ratio = _log_luminance(context.target.images[frame.index]) - _log_luminance(rendered.face)
        pixel_weight = (rendered.face_region * rendered.coverage).numpy() * unshadowed_fraction(
            rendered.light_images, rendered.light_masks)
        weight = view.confidence(pixel_weight)
        details.append(detail(unwrap(ratio.numpy()[..., None], view)[..., 0], weight, sigma))
        weights.append(weight)
    flows = register(details, weights, config)
    for index, moved in enumerate(flows):
        seen = weights[index] > 0.1
        shift = float(np.abs(moved.flow[seen]).mean()) if seen.any() else 0.0
        context.log.info(f"frame {index} registered to the others: mean shift {shift:.2f} texels of {side}, "
                         f"detail correlation {moved.before:.2f} -> {moved.after:.2f}")
    uvs = frozen[0].geometry.mesh.uvs
    return [shifted_uvs(uvs, moved.flow) for moved in flows]


def with_uvs(frame, uvs: torch.Tensor):
    """A frozen frame whose mesh samples the maps at ``uvs`` (its cast, fragments and shadows unchanged)."""
    geometry = frame.geometry.with_uvs(uvs)
    return dataclasses.replace(frame, geometry=geometry, cast=dataclasses.replace(frame.cast, mesh=geometry.mesh))


def _log_luminance(image: torch.Tensor) -> torch.Tensor:
    return torch.log((image @ LUMINANCE_T.to(image.dtype)).clamp_min(1e-4))
