"""Supersampling: render s x s samples per pixel and box-filter them to the image grid.

A pixel of a photo integrates the light over its area; a renderer that samples one point per pixel
aliases any texture finer than the pixel grid. Where the UV map has ~2 texels per pixel, the photometric
gradient reaches each texel through the bilinear taps of a few pixel centres only, so texel refinement
leaves a checkerboard the loss cannot see (the path tracer the paper used averaged several samples per
pixel instead). Rendering at s x the resolution and averaging each s x s block makes the render the
pixel's area integral, and spreads the gradient over every texel the pixel covers.
"""

from __future__ import annotations

import torch

from deface.render import fast_box
from deface.render.camera import Camera
from deface.render.renderer import RenderOutput


def supersampled_camera(camera: Camera, factor: int) -> Camera:
    """The same view on a grid ``factor`` x finer: sample (i, j) of pixel (x, y) sits at
    x + (i + 0.5) / factor, y + (j + 0.5) / factor in the original pixel units (stratified)."""
    if factor < 1:
        raise ValueError(f"supersampling factor must be >= 1, got {factor}")
    if factor == 1:
        return camera
    return camera.scaled(factor, camera.width * factor, camera.height * factor)


def box_filter(output: RenderOutput, factor: int) -> RenderOutput:
    """Average each ``factor`` x ``factor`` block of a supersampled render.

    Shaded buffers are averaged over the block's *covered* samples (so an edge pixel keeps the surface's
    colour, not a blend with the black background) and ``mask`` becomes the covered fraction in [0, 1];
    the photometric loss weights pixels by it. ``triangle_id`` keeps each block's centre sample.
    """
    if factor == 1:
        return output
    coverage = _pool(output.mask[..., None], factor)[..., 0]  # [H, W]
    count = coverage.clamp_min(1.0 / factor**2)[..., None]

    def mean_over_covered(values: torch.Tensor) -> torch.Tensor:  # [..., sH, sW, C] zeros off-surface
        return _pool(values, factor) / count

    normals = mean_over_covered(output.normals)
    normals = normals / normals.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    centre = factor // 2
    return RenderOutput(
        images=mean_over_covered(output.images),
        mask=coverage,
        uv=mean_over_covered(output.uv),
        normals=normals * (coverage > 0)[..., None],
        depth=mean_over_covered(output.depth[..., None])[..., 0],
        triangle_id=output.triangle_id[centre::factor, centre::factor],
        diffuse=mean_over_covered(output.diffuse),
        specular=mean_over_covered(output.specular),
        roughness=mean_over_covered(output.roughness),
    )


def _pool(values: torch.Tensor, factor: int) -> torch.Tensor:
    """Block mean of [..., sH, sW, C] -> [..., H, W, C] (the op deface/render/fast_box.py registers)."""
    return fast_box.block_mean(values, factor)
