"""Stage 2's merge test: gather each frame's evidence pixels with the render of every SH coefficient, and join
kept lights that one light explains (the test's maths in deface/decouple/merge.py)."""

from __future__ import annotations

from dataclasses import replace

import torch

from deface.decouple.merge import MergeEvidence, cheapest_merge, region_errors
from deface.fit import rendering
from deface.fit.state import StageContext
from deface.render.frame import render_frame
from deface.render.renderer import Renderer

MAX_PIXELS = 40_000
"""Evidence pixels the test reads at most (all frames; evenly strided beyond)."""

MIN_WEIGHT = 1e-3
"""Pixels whose evidence weight is below this say nothing about the light."""


@torch.no_grad()
def merge_evidence(context: StageContext) -> MergeEvidence:
    """The evidence pixels of every frame: the photo, their weight h, the kept light whose mask is largest,
    and the render of each SH coefficient alone (the render is linear in them without the clamp of negative
    radiance, which the test leaves out)."""
    linear = Renderer(replace(context.renderer.config, non_negative_lights=False), context.renderer.bands,
                      context.renderer.seed)
    bands = context.renderer.bands
    unit_lights = torch.eye(bands * bands)[:, :, None].expand(-1, -1, 3).contiguous()  # [J, J, 3]
    textures = rendering.albedo_textures(context)
    parts = []
    for frame in range(context.target.num_frames):
        geometry = context.geometry(frame)
        transfer = rendering.transfer_of(context, frame, geometry.mesh)
        output = render_frame(linear, geometry.mesh, geometry.camera, textures, unit_lights, transfer)
        masks = context.decoupling.light_masks(frame, output.mask)  # [G, H, W]
        weight = context.inputs.face_classifier[frame] * output.mask
        chosen = weight > MIN_WEIGHT
        parts.append((output.images[:, chosen].permute(1, 0, 2), context.target.images[frame][chosen],
                      weight[chosen], masks[:, chosen].argmax(dim=0)))
    basis, target, weight, label = (torch.cat(values) for values in zip(*parts, strict=True))
    stride = max(1, -(-weight.numel() // MAX_PIXELS))
    return MergeEvidence(basis[::stride].float(), target[::stride].float(), weight[::stride].float(),
                         label[::stride])


def merge_lights(context: StageContext) -> None:
    """Join the cheapest pair of kept lights while its cost is below ``decouple.merge_tolerance``; log each test."""
    tolerance = context.config.decouple.merge_tolerance
    decoupling = context.decoupling
    while len(decoupling.kept) > 1:
        evidence = merge_evidence(context)
        first, second, cost = cheapest_merge(evidence, len(decoupling.kept))
        kept = decoupling.kept
        errors = region_errors(evidence, first, second)
        if errors is None:
            context.log.info(f"merge test: lights {kept[first]} and {kept[second]} stay apart (one of them is the "
                             "largest mask at no evidence pixel)")
            return
        shown = ", ".join(f"{own:.3f} -> {joint:.3f}" for own, joint in errors)
        context.log.info(f"merge test: relative errors of one light each -> one light for both: {shown}")
        if cost >= tolerance:
            context.log.info(f"merge test: lights {kept[first]} and {kept[second]} stay apart (cost {cost:.4f}, "
                             f"tolerance {tolerance})")
            return
        decoupling.merge_lights(kept[first], kept[second])
        context.log.info(f"merge test: light {kept[second]} joined light {kept[first]} (cost {cost:.4f}, "
                         f"tolerance {tolerance}); kept {decoupling.kept}")
