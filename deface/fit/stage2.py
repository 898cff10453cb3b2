"""Stage 2 (Alg. 1): statistical fit with light decoupling.

Optimises identity, expression, pose, albedo coefficients delta, the n SH lights gamma and the fields f, g
with  w0 L_pho + w1 L_lan + w2 L_seg + (w3 L_area before iter_0 | w4 L_bin after)  plus small coefficient
priors; at iter_0 ACE keeps the lights whose masks are large enough. Focal length is frozen (authors' code).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from deface.decouple.ace import light_areas
from deface.fit.config import FitConfig
from deface.fit.convergence import converged
from deface.fit.decoupling import Decoupling
from deface.fit.guard import StepGuard
from deface.fit.scene import SceneParameters, frame_geometry
from deface.fit.target import FitTarget
from deface.io.images import LUMINANCE
from deface.losses import decouple as decouple_losses
from deface.losses.illuminant import (
    exposure_term,
    front_directions,
    key_light_level,
    light_colour_term,
)
from deface.losses.photometric import photometric_loss
from deface.priors.illuminant import IlluminantEstimate
from deface.render.mesh import Textures
from deface.render.renderer import Renderer, ShadowTransferCache


@dataclass
class FrameRender:
    """One frame's stage-2 products: per-light renders, buffers, masks and the composed face."""

    light_images: torch.Tensor  # [K, H, W, 3] I_Rs (kept lights)
    coverage: torch.Tensor  # [H, W] M_R
    light_masks: torch.Tensor  # [K, H, W] M_L
    face_region: torch.Tensor  # [H, W] M_o
    face: torch.Tensor  # [H, W, 3] I_R
    region_probability: torch.Tensor | None = None  # [H, W] g (None without the field g)
    normals: torch.Tensor | None = None  # [H, W, 3] unit normals of the render (model frame)


class StageContext:
    """What stages 2 and 3 share: model, target, scene, decoupling, renderer, shadow cache, logger."""

    def __init__(self, model, target: FitTarget, scene: SceneParameters, decoupling: Decoupling,
                 config: FitConfig, topology: dict, log):
        self.model, self.target, self.scene, self.decoupling = model, target, scene, decoupling
        self.config, self.topology, self.log = config, topology, log
        self.renderer = Renderer(target.render_config(config))
        self.shadow_caches = [ShadowTransferCache(self.renderer) for _ in range(target.num_frames)]
        self.illuminant: IlluminantEstimate | None = None  # the scene's light, set after stage 1
        self.tone_regions: list[torch.Tensor] = []  # per frame [H, W] bool: skin of the cheeks and forehead
        self._directions = front_directions()

    def geometry(self, frame: int):
        return frame_geometry(self.model, self.scene, self.topology, frame, self.target.size)

    def albedo_textures(self, size: int | None = None) -> Textures:
        """The albedo model's maps at the fitted coefficients (and tone, when the tone is free), ``size``
        texels square (default: ``config.stage2_texture_size``)."""
        size = size or self.config.stage2_texture_size
        ita = self.scene.tone if self.config.tone.free_tone else None
        diffuse, specular = self.model.albedo.textures(self.scene.albedo, size, ita)
        roughness = torch.full((*diffuse.shape[:2], 1), self.model.albedo.roughness_default)
        return Textures(diffuse.clamp(0, 1), specular.clamp(0, 1), roughness)

    def scene_light_prior(self) -> torch.Tensor:
        """The scene-light colour term for the kept lights (0 when off or without an estimate)."""
        tone = self.config.tone
        if not tone.scene_light_prior or self.illuminant is None:
            return torch.zeros(())
        white = torch.as_tensor(self.illuminant.white, dtype=torch.float32)
        colour = light_colour_term(self.scene.lights[self.decoupling.kept], white, self._directions)
        return tone.weight * colour / tone.colour_sigma**2

    def key_light_exposure(self, frame: int, rendered: FrameRender) -> torch.Tensor:
        """The scene-light level term of one frame: the brightest light's level on the cheeks and forehead
        (0 when off)."""
        tone, region = self.config.tone, self.tone_regions[frame] if self.tone_regions else None
        if not tone.scene_light_prior or self.illuminant is None or region is None or rendered.normals is None:
            return torch.zeros(())
        level = key_light_level(self.scene.lights[self.decoupling.kept], rendered.normals, region)
        target = float(self.illuminant.white @ LUMINANCE)
        return tone.weight * exposure_term(level, target) / tone.exposure_sigma**2

    def render_frame(self, frame: int, textures: Textures, refresh_shadows: bool, geometry=None) -> FrameRender:
        geometry = geometry or self.geometry(frame)
        fragments = self.renderer.rasterize(geometry.mesh, geometry.camera)
        transfer = self._transfer(frame, geometry.mesh, refresh_shadows)
        kept = self.decoupling.kept
        output = self.renderer.shade(geometry.mesh, geometry.camera, fragments, textures,
                                     self.scene.lights[kept], transfer)
        return self.compose(frame, output.images, output.mask, output.normals)

    def compose(self, frame: int, light_images: torch.Tensor, coverage: torch.Tensor,
                normals: torch.Tensor | None = None) -> FrameRender:
        light_masks = self.decoupling.light_masks(frame, coverage)
        probability = self.decoupling.region_probability(frame, coverage)
        face_region = self.decoupling.face_region(frame, coverage, self.target.face_classifier[frame], probability)
        face = (light_images * light_masks[..., None]).sum(0)
        return FrameRender(light_images, coverage, light_masks, face_region, face, probability, normals)

    def _transfer(self, frame: int, mesh, refresh: bool):
        if not self.config.render.shadows:
            return None
        cache = self.shadow_caches[frame]
        return cache.get(mesh) if refresh or cache.transfer is None else cache.transfer

    def photometric(self, frame: int, rendered: FrameRender) -> torch.Tensor:
        return photometric_loss(rendered.face, self.target.images[frame], rendered.face_region,
                                rendered.coverage, blur=self.config.render.render_blur,
                                form=self.config.decouple.loss_form)


def run_stage2(context: StageContext) -> list[float]:
    """Run stage 2 in place on ``context.scene`` / ``context.decoupling``; returns the loss per iteration."""
    config, scene, decoupling = context.config, context.scene, context.decoupling
    optimiser = torch.optim.Adam(_parameter_groups(context))
    guard = StepGuard(optimiser, "stage 2", context.log)  # NaN/Inf rollback (deface/fit/guard.py)
    history = []
    ace_at = min(config.decouple.ace_iteration, config.iterations.stage2 - 1)
    for step in range(config.iterations.stage2):
        if step == ace_at and decoupling.light_field is not None:
            _apply_ace(context)
        optimiser.zero_grad(set_to_none=True)
        refresh = step % config.render.shadow_refresh_every == 0
        loss = _stage2_loss(context, before_ace=step < ace_at, refresh_shadows=refresh)
        loss.backward()
        optimiser.step()
        scene.clamp_(context.model.expression_prior)
        if config.tone.free_tone:
            context.model.albedo.tone.clamp_(scene.tone, config.tone.ita_range)
        guard.check(loss)
        value = float(loss.detach())
        history.append(value)
        context.log.step("stage 2", step, config.iterations.stage2, value)
        iterations = config.iterations
        if step + 1 < iterations.stage2 and converged(history, iterations.convergence_window,
                                                      iterations.stage2_tolerance, start=ace_at + 1):
            context.log.info(f"stage 2 converged after {step + 1} of {iterations.stage2} steps "
                             f"(tolerance {iterations.stage2_tolerance} per {iterations.convergence_window} steps)")
            break
    return history


def _parameter_groups(context: StageContext) -> list[dict]:
    rates, scene = context.config.learning_rates, context.scene
    groups = [
        {"params": [scene.lights], "lr": rates.lights},
        {"params": [scene.identity], "lr": rates.identity},
        {"params": [scene.albedo], "lr": rates.albedo},
        {"params": [scene.expression], "lr": rates.expression},
        {"params": [scene.rotation, scene.translation], "lr": rates.pose},
    ]
    if context.config.tone.free_tone:
        groups.append({"params": [scene.tone], "lr": context.config.tone.learning_rate})
    if context.decoupling.light_field is not None:
        groups.append({"params": context.decoupling.light_field.parameters(), "lr": rates.light_masks})
    if context.decoupling.region_field is not None:
        groups.append({"params": context.decoupling.region_field.parameters(), "lr": rates.face_region})
    return groups


def _stage2_loss(context: StageContext, before_ace: bool, refresh_shadows: bool) -> torch.Tensor:
    weights, scene = context.config.weights, context.scene
    textures = context.albedo_textures()
    total = torch.zeros(())
    for frame in range(context.target.num_frames):
        geometry = context.geometry(frame)  # once per step: shared by the render and L_lan
        rendered = context.render_frame(frame, textures, refresh_shadows, geometry=geometry)
        total = total + weights.photometric * context.photometric(frame, rendered)
        total = total + weights.landmarks * context.target.landmark_loss(geometry, frame)
        total = total + _decoupling_terms(context, frame, rendered, before_ace)
        total = total + context.key_light_exposure(frame, rendered)
    total = total / context.target.num_frames
    total = total + weights.sh_regulariser * scene.lights[context.decoupling.kept].pow(2).mean()
    total = total + weights.albedo_prior * scene.albedo.pow(2).mean()
    total = total + weights.identity_prior * scene.identity.pow(2).mean()
    total = total + weights.expression_prior * scene.expression.pow(2).mean()
    return total + context.scene_light_prior()


def _decoupling_terms(context: StageContext, frame: int, rendered: FrameRender, before_ace: bool) -> torch.Tensor:
    weights, form = context.config.weights, context.config.decouple.loss_form
    decoupling, total = context.decoupling, torch.zeros(())
    if rendered.region_probability is not None and context.target.face_classifier[frame] is not None:
        total = total + weights.segmentation * decouple_losses.segmentation_loss(
            rendered.region_probability, context.target.face_classifier[frame], rendered.coverage, form=form)
    if decoupling.light_field is not None and rendered.light_masks.shape[0] > 1:
        if before_ace:
            total = total + weights.area * decouple_losses.area_loss(rendered.light_masks, rendered.coverage,
                                                                     form=form)
        else:
            total = total + weights.binary * decouple_losses.binary_loss(rendered.light_masks,
                                                                         rendered.coverage, form=form)
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
