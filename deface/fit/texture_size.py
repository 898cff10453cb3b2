"""The UV maps' side a fit uses: the configured one, or what the stage-1 face's pixels support (about one working
pixel per texel, a power of two within ``texture_size_range``; deface/fit/framing.py)."""

from __future__ import annotations

import torch

from deface.fit.config import FitConfig
from deface.fit.framing import texture_size_for
from deface.fit.log import FitLog
from deface.fit.state import PosedFace
from deface.fit.target import FitTarget
from deface.texture.confidence import triangle_density


@torch.no_grad()
def choose_texture_size(face: PosedFace, target: FitTarget, config: FitConfig, log: FitLog) -> int:
    """``config.texture_size``, or when it is None what the stage-1 face's pixels support
    (deface/fit/framing.py), said in the log."""
    if config.texture_size is not None:
        return config.texture_size
    supported = max(texels_per_side(face, frame) for frame in range(target.num_frames))
    size = texture_size_for(supported, config.texture_size_range)
    log.info(f"texture size {size}² (the face's pixels support about {supported:.0f}² texels; "
             f"texture_size_range {config.texture_size_range[0]}-{config.texture_size_range[1]})")
    return size


def texels_per_side(face: PosedFace, frame: int) -> float:
    """The UV maps' side at which the stage-1 face's typical pixel sees one texel: the square root of the median,
    over the pixels the face covers, of its triangle's pixels per unit of UV area."""
    geometry, fragments = face.fragments(frame)
    density = triangle_density(geometry.mesh, geometry.camera, (1, 1))  # pixels per unit of UV area
    covered = fragments.covered_triangles
    if covered.numel() == 0:
        return 0.0
    return float(density[covered].median().sqrt())
