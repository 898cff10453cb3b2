"""The one way a frame is rendered: cast the posed mesh to (supersampled) pixels once, then shade that cast
with any maps and lights and box-filter it to the frame's pixels.

Both fitting stages, a finished fit's renders (outputs, relight, transfer, turntable, report, reload) and
the synthetic evaluation render through here; the golden render test and benchmarks/render_bench.py too.

Shapes: H x W output pixels, s the supersampling factor, K lights with B*B SH coefficients per colour.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from deface.render.camera import Camera
from deface.render.mesh import Mesh, Textures
from deface.render.renderer import Fragments, Renderer, RenderOutput
from deface.render.shadow import ShadowTransfer
from deface.render.supersample import box_filter, supersampled_camera


@dataclass(frozen=True)
class FrameCast:
    """A frame's visibility, fixed while only the maps and the lights change."""

    mesh: Mesh  # the posed mesh
    camera: Camera  # the sampling camera: s x the output's resolution (the output's camera when s = 1)
    fragments: Fragments  # what covers each sample [sH, sW]
    transfer: ShadowTransfer | None  # the mesh's self-shadowing (None: nothing occluded)
    supersampling: int = 1  # s


def cast_frame(renderer: Renderer, mesh: Mesh, camera: Camera, transfer: ShadowTransfer | None,
               supersampling: int = 1) -> FrameCast:
    """Cast ``mesh`` seen by ``camera`` (the output's pixels) at ``supersampling`` x ``supersampling`` samples
    per pixel."""
    sampling = supersampled_camera(camera, supersampling)
    return FrameCast(mesh, sampling, renderer.rasterize(mesh, sampling), transfer, supersampling)


def shade_frame(renderer: Renderer, cast: FrameCast, textures: Textures, lights: torch.Tensor) -> RenderOutput:
    """The cast shaded with ``textures`` under ``lights`` [K, B*B, 3], at the output's pixels: each pixel the
    mean of its covered samples, its coverage the covered fraction (:func:`~deface.render.supersample.box_filter`)."""
    shaded = renderer.shade(cast.mesh, cast.camera, cast.fragments, textures, lights, cast.transfer)
    return box_filter(shaded, cast.supersampling)


def render_frame(renderer: Renderer, mesh: Mesh, camera: Camera, textures: Textures, lights: torch.Tensor,
                 transfer: ShadowTransfer | None = None, supersampling: int = 1) -> RenderOutput:
    """:func:`cast_frame` then :func:`shade_frame`: a frame rendered once."""
    return shade_frame(renderer, cast_frame(renderer, mesh, camera, transfer, supersampling), textures, lights)
