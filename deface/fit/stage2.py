"""Stage 2 (Alg. 1): statistical fit with light decoupling.

Optimises identity, expression, pose, albedo coefficients delta, the n SH lights gamma and the fields f, g
with  w0 L_pho + w1 L_lan + w2 L_seg + (w3 L_area before iter_0 | w4 L_bin after)  plus small coefficient
priors; at iter_0 ACE keeps the lights whose masks are large enough. Focal length is frozen (authors' code).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import torch

from deface.decouple.ace import light_areas
from deface.fit import rendering
from deface.fit.coarse import can_coarsen, coarse_context, half_size
from deface.fit.convergence import converged
from deface.fit.frame_turns import FrameTurns
from deface.fit.guard import StepGuard
from deface.fit.state import FrameRender, LossTerms, StageContext
from deface.losses import decouple as decouple_losses
from deface.models.tone_neutral import ToneBoxColours, keep_tone_
from deface.priors.shading_evidence import texture_weight


@dataclass(frozen=True)
class Stage2Result:
    """What stage 2 did; its parameters are the context's scene and decoupling (trained in place)."""

    history: list[float]  # total loss per iteration
    terms: list[dict[str, float]]  # the named terms per iteration (they sum to the total)
    kept: list[int]  # the lights ACE kept


def run_stage2(context: StageContext) -> Stage2Result:
    """Run stage 2 in place on ``context.scene`` / ``context.decoupling``."""
    context = _weighted_by_evidence(context)
    config, scene, decoupling = context.config, context.scene, context.decoupling
    optimiser = torch.optim.Adam(_parameter_groups(context))
    guard = StepGuard(optimiser, "stage 2", context.log)  # NaN/Inf rollback (deface/fit/guard.py)
    history, term_history = [], []
    ace_at = min(config.decouple.ace_iteration, config.iterations.stage2 - 1)
    coarse_steps, coarse = _coarse_level(context)
    tone_boxes = (ToneBoxColours.of(context.model.albedo) if config.tone.free_tone and config.tone.neutral_albedo
                  else None)
    turns = _frame_turns(context)
    for step in range(config.iterations.stage2):
        level = coarse if step < coarse_steps else context
        if step == ace_at and decoupling.light_field is not None:
            _apply_ace(level)
        optimiser.zero_grad(set_to_none=True)
        frames = turns.at(step)
        refresh = frozenset(frame for frame in frames if turns.refresh(frame, step))
        terms = LossTerms()
        loss = objective(level, before_ace=step < ace_at, refresh_shadows=refresh, terms=terms, frames=frames)
        loss.backward()
        optimiser.step()
        scene.clamp_(context.model.expression_prior)
        if config.tone.free_tone:
            context.model.albedo.tone.clamp_(scene.tone, config.tone.ita_range)
        if tone_boxes is not None:
            keep_tone_(scene.albedo, tone_boxes, context.model.albedo.tone.scale(scene.tone.detach()))
        guard.check(loss)
        value = float(loss.detach())
        history.append(value)
        term_history.append(terms.values)
        context.log.step("stage 2", step, config.iterations.stage2, value, terms.values)
        iterations = config.iterations
        if step + 1 < iterations.stage2 and converged(history, iterations.convergence_window,
                                                      iterations.stage2_tolerance,
                                                      start=max(ace_at + 1, coarse_steps)):
            context.log.info(f"stage 2 converged after {step + 1} of {iterations.stage2} steps "
                             f"(tolerance {iterations.stage2_tolerance} per {iterations.convergence_window} steps)")
            break
    return Stage2Result(history, term_history, decoupling.kept)


def _frame_turns(context: StageContext) -> FrameTurns:
    """The frames of each step (deface/fit/frame_turns.py), said in the log when a step renders fewer than all:
    in turns only where each photo has its own lights (shared lights stepped on a turn chase its frames)."""
    iterations, frames = context.config.iterations, context.target.num_frames
    groups = context.decoupling.light_groups
    per_step = iterations.stage2_frames_per_step if groups is not None and len(set(groups)) == frames else 0
    turns = FrameTurns(frames, per_step, iterations.shadow_refresh_every, context.config.seed)
    if not turns.every_step:
        context.log.info(f"stage 2: {turns.per_step} of the {frames} frames per step, in turn")
    return turns


def _weighted_by_evidence(context: StageContext) -> StageContext:
    """Stage 2's context whose face region h is weighted by how much each pixel tells about the shading
    (deface/priors/shading_evidence.py); the same context when that is off. Stage 3 keeps h itself. The weighted
    h is also handed to the decoupling, whose masks it fills with ``decouple.mask_fill``."""
    evidence = context.config.shading_evidence
    if evidence.strength <= 0:
        return context
    inputs = context.inputs
    sizes = inputs.landmarks.face_size if inputs.landmarks.face_size is not None else \
        torch.full((inputs.num_frames,), float(max(context.target.size)) / 2)
    target = context.target
    weighted = tuple(h * torch.as_tensor(texture_weight(target.images[frame].numpy(), h.numpy(), float(sizes[frame]),
                                                        evidence, target.landmarks[frame].points))
                     for frame, h in enumerate(inputs.face_classifier))
    context.decoupling.set_evidence(torch.stack(weighted))
    return replace(context, inputs=replace(inputs, face_classifier=weighted))


def _coarse_level(context: StageContext) -> tuple[int, StageContext | None]:
    """How many first steps run at half size, and that level (deface/fit/coarse.py)."""
    iterations = context.config.iterations
    steps = min(round(iterations.stage2_coarse_share * iterations.stage2), iterations.stage2)
    if steps <= 0 or not can_coarsen(context.target.size, iterations.coarse_min_side):
        return 0, None
    context.log.info(f"stage 2: the first {steps} of {iterations.stage2} steps at half size "
                     f"({'x'.join(map(str, half_size(context.target.size)))} pixels)")
    return steps, coarse_context(context)


def _parameter_groups(context: StageContext) -> list[dict]:
    rates, scene = context.config.learning_rates, context.scene
    groups = [
        {"params": [scene.lights], "lr": rates.lights},
        {"params": [scene.identity], "lr": rates.identity},
        {"params": [scene.albedo], "lr": rates.albedo},
        {"params": [scene.expression], "lr": rates.expression},
        {"params": [scene.rotation, scene.translation], "lr": rates.pose},
    ]
    if context.config.tone.free_tone and context.config.tone.learning_rate > 0:
        groups.append({"params": [scene.tone], "lr": context.config.tone.learning_rate})
    if context.decoupling.light_field is not None:
        groups.append({"params": context.decoupling.light_field.parameters(), "lr": rates.light_masks})
    if context.decoupling.region_field is not None:
        groups.append({"params": context.decoupling.region_field.parameters(), "lr": rates.face_region})
    return groups


def objective(context: StageContext, before_ace: bool, refresh_shadows: bool | frozenset[int],
              terms: LossTerms | None = None, frames: tuple[int, ...] | None = None) -> torch.Tensor:
    """The stage-2 loss (the total) over ``frames`` (default: every frame; frame terms as their mean over them);
    ``refresh_shadows``: whether the frames' shadow transfers refresh, or the frames whose do. ``terms`` collects
    the loss by name."""
    weights, scene = context.config.weights, context.scene
    frames = tuple(range(context.target.num_frames)) if frames is None else frames
    terms = terms or LossTerms()
    per_frame = 1.0 / len(frames)
    textures = rendering.albedo_textures(context)
    total = torch.zeros(())
    for frame in frames:
        geometry = context.geometry(frame)  # once per step: shared by the render and L_lan
        refresh = refresh_shadows if isinstance(refresh_shadows, bool) else frame in refresh_shadows
        rendered = rendering.render_posed(context, frame, textures, refresh, geometry=geometry)
        total = total + terms.add("photometric", weights.photometric * rendering.photometric(context, frame, rendered),
                                  per_frame)
        total = total + terms.add("landmarks", weights.landmarks * context.inputs.landmarks.loss(geometry, frame),
                                  per_frame)
        total = total + _decoupling_terms(context, frame, rendered, before_ace, terms, per_frame)
        total = total + terms.add("scene_light_level", rendering.scene_light_level(context, frame, rendered), per_frame)
    total = total / len(frames)
    total = total + terms.add("sh_regulariser",
                              weights.sh_regulariser * context.kept_lights.pow(2).mean())
    total = total + terms.add("albedo_prior", weights.albedo_prior * scene.albedo.pow(2).mean())
    total = total + terms.add("identity_prior", weights.identity_prior * scene.identity.pow(2).mean())
    total = total + terms.add("expression_prior", weights.expression_prior * scene.expression.pow(2).mean())
    return rendering.with_light_priors(context, total, terms)


def _decoupling_terms(context: StageContext, frame: int, rendered: FrameRender, before_ace: bool,
                      terms: LossTerms, scale: float) -> torch.Tensor:
    weights, form = context.config.weights, context.config.decouple.loss_form
    decoupling, total = context.decoupling, torch.zeros(())
    classifier = context.inputs.face_classifier[frame]
    if rendered.region_probability is not None:
        total = total + terms.add("segmentation", weights.segmentation * decouple_losses.segmentation_loss(
            rendered.region_probability, classifier, rendered.coverage, form=form), scale)
    if decoupling.light_field is not None and rendered.light_masks.shape[0] > 1:
        if before_ace:
            total = total + terms.add("area", weights.area * decouple_losses.area_loss(
                rendered.light_masks, rendered.coverage, form=form), scale)
        else:
            total = total + terms.add("binary", weights.binary * decouple_losses.binary_loss(
                rendered.light_masks, rendered.coverage, form=form), scale)
        if weights.mask_variation > 0:
            total = total + terms.add("mask_variation", weights.mask_variation * decouple_losses.variation_loss(
                rendered.light_masks, rendered.coverage), scale)
    return total


@torch.no_grad()
def _apply_ace(context: StageContext) -> None:
    masks, coverages = [], []
    for frame in range(context.target.num_frames):
        geometry = context.geometry(frame)
        coverage = context.renderer.rasterize(geometry.mesh, geometry.camera).mask
        masks.append(context.decoupling.light_masks(frame, coverage))
        coverages.append(coverage)
    masks, coverages = torch.stack(masks), torch.stack(coverages)
    areas = light_areas(masks, coverages, context.config.decouple.area_normaliser)
    kept = context.decoupling.run_ace(masks, coverages)
    shown = ", ".join(f"{float(area):.2f}" for area in areas)
    context.log.info(f"ACE kept {len(kept)} of {len(areas)} lights: {kept} (mask areas {shown}, "
                     f"eps {context.config.decouple.epsilon})")
