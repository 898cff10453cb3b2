"""Texture transfer: the target fit's geometry, pose, lights, light masks and face region with the source
fit's textures. ``deface transfer`` and the evaluation's texture swap (target synthesis, Sec. 4) both call
:func:`transfer_renders`."""

from __future__ import annotations

from deface.fit.output import FitOutput
from deface.fit.state import FrameRender


def transfer_renders(source: FitOutput, target: FitOutput) -> list[FrameRender]:
    """Per target frame: the target's render with ``source``'s UV maps (same face model required)."""
    if source.model.name != target.model.name:
        raise ValueError(f"cannot transfer textures between face models: the source was fitted with "
                         f"{source.model.name}, the target with {target.model.name}")
    return target.render(textures=source.textures)
