"""Stage 3 (Alg. 1): per-texel refinement.

Geometry, g and M_o are frozen at their stage-2 values (authors' code), so each frame is ray cast once and
its shadow transfer computed once. Optimised: diffuse, specular and roughness UV maps T (initialised from
the albedo model, T^0), the kept lights gamma and f, with
    w0 L_pho + w4 L_bin + w5 L_GP + w6 L_LP + w7 L_HP + texture regularisers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from deface.fit import fast_stage3
from deface.fit.convergence import converged
from deface.fit.guard import StepGuard
from deface.fit.stage2 import FrameRender, StageContext
from deface.fit.texels import frame_views
from deface.losses import decouple as decouple_losses
from deface.losses.texture import texture_regularisers
from deface.priors.global_prior import global_prior, kmeans_palette
from deface.priors.local_prior import local_prior
from deface.render.mesh import Textures
from deface.render.supersample import box_filter, supersampled_camera
from deface.texture.confidence import TexelView
from deface.texture.pyramid import TexturePyramid, level_gates, level_sizes


@dataclass
class FrozenFrame:
    """A frame's stage-3 constants: geometry, ray-cast fragments, shadow transfer, M_o, reference albedo."""

    index: int  # frame number
    geometry: object  # posed mesh and the working-resolution camera
    camera: object  # the camera the fragments were cast with (config.render.supersampling x finer)
    fragments: object
    transfer: object
    face_region: torch.Tensor  # [H, W] M_o from stage 2
    reference: dict  # screen-space albedo renders of T^0: diffuse [H,W,3], specular [H,W,3], roughness [H,W,1]


class TextureParameters(torch.nn.Module):
    """The stage-3 UV maps as gated pyramids over T^0 (deface/texture/pyramid.py), mapped to valid ranges by
    clamping in :meth:`textures`."""

    def __init__(self, initial: Textures, gates: list[torch.Tensor]):
        super().__init__()
        self.diffuse = TexturePyramid(initial.diffuse, gates)  # [Ht, Wt, 3]
        self.specular = TexturePyramid(initial.specular, gates)  # [Ht, Wt, 3]
        self.roughness = TexturePyramid(initial.roughness, gates)  # [Ht, Wt, 1]

    def textures(self) -> Textures:
        return Textures(self.diffuse().clamp(0, 1), self.specular().clamp(0, 1), self.roughness().clamp(0.05, 1))


def texture_gates(context: StageContext, views: list[TexelView], size: int) -> list[torch.Tensor]:
    """The pyramid's gates from the frames' texel density (pixels per texel, summed over frames)."""
    config = context.config.texture_pyramid
    density = np.sum([view.density for view in views], axis=0)
    return level_gates(density, level_sizes(size, config), config.gated, config.gate_power)


def initial_textures(context: StageContext) -> Textures:
    """T^0 at the output resolution from the fitted albedo coefficients."""
    with torch.no_grad():
        return context.albedo_textures(context.config.texture_size)


@dataclass(frozen=True)
class Stage3Result:
    textures: Textures  # refined UV maps
    initial: Textures  # T^0
    frozen: list[FrozenFrame]  # per-frame constants, reused to re-render with any textures
    history: list[float]  # loss per iteration
    views: list[TexelView]  # per frame: how the frozen camera sees each texel


def run_stage3(context: StageContext, human_prior=None) -> Stage3Result:
    """Refine textures from T^0 with the frames' geometry frozen."""
    initial = initial_textures(context)
    frozen = freeze_frames(context, initial)
    views = frame_views(context.model, frozen, initial.diffuse.shape[0])
    parameters = TextureParameters(initial, texture_gates(context, views, initial.diffuse.shape[0]))
    optimiser = torch.optim.Adam(_parameter_groups(context, parameters))
    guard = StepGuard(optimiser, "stage 3", context.log)  # NaN/Inf rollback (deface/fit/guard.py)
    loss_of = objective(context, frozen, initial, human_prior)
    history, iterations = [], context.config.iterations
    for step in range(iterations.stage3):
        optimiser.zero_grad(set_to_none=True)
        loss = loss_of(parameters.textures())
        loss.backward()
        optimiser.step()
        guard.check(loss)
        value = float(loss.detach())
        history.append(value)
        context.log.step("stage 3", step, iterations.stage3, value)
        if step + 1 < iterations.stage3 and converged(history, iterations.convergence_window,
                                                      iterations.stage3_tolerance):
            context.log.info(f"stage 3 converged after {step + 1} of {iterations.stage3} steps "
                             f"(tolerance {iterations.stage3_tolerance} per {iterations.convergence_window} steps)")
            break
    with torch.no_grad():
        return Stage3Result(parameters.textures(), initial, frozen, history, views)


def objective(context: StageContext, frozen: list[FrozenFrame], initial: Textures, human_prior=None):
    """The stage-3 loss as a function of the textures; its texture-space constants are computed once."""
    palette, uv_mask = _palette(context, initial), _uv_mask(context, initial)
    texture_terms = _texture_terms_of(context, initial, palette, uv_mask)

    def loss_of(textures: Textures) -> torch.Tensor:
        loss = sum(_frame_loss(context, f, textures, human_prior) for f in frozen) / len(frozen)
        return loss + texture_terms(textures) + context.scene_light_prior()

    return loss_of


def render_frozen(context: StageContext, frame: FrozenFrame, textures: Textures) -> tuple[FrameRender, object]:
    """Shade a frozen frame with ``textures`` and the current kept lights; M_o stays frozen."""
    output = _shade(context, frame.geometry.mesh, frame.camera, frame.fragments, textures, frame.transfer)
    rendered = context.compose(frame.index, output.images, output.mask, output.normals)
    rendered.face_region = frame.face_region
    return rendered, output


def freeze_frames(context: StageContext, initial: Textures) -> list[FrozenFrame]:
    return [_freeze(context, frame, initial) for frame in range(context.target.num_frames)]


@torch.no_grad()
def _freeze(context: StageContext, frame: int, initial: Textures) -> FrozenFrame:
    geometry = context.geometry(frame)
    geometry = type(geometry)(
        mesh=type(geometry.mesh)(geometry.mesh.vertices.detach(), *_topology(context)),
        camera=type(geometry.camera)(
            geometry.camera.focal.detach(), geometry.camera.rotation.detach(),
            geometry.camera.translation.detach(), geometry.camera.width, geometry.camera.height),
    )
    camera = supersampled_camera(geometry.camera, context.config.render.supersampling)
    fragments = context.renderer.rasterize(geometry.mesh, camera)
    transfer = context.shadow_caches[frame].get(geometry.mesh) if context.config.render.shadows else None
    output = _shade(context, geometry.mesh, camera, fragments, initial, transfer)
    coverage = output.mask
    face_region = context.decoupling.face_region(frame, coverage, context.target.face_classifier[frame])
    reference = {"diffuse": output.diffuse, "specular": output.specular, "roughness": output.roughness}
    return FrozenFrame(frame, geometry, camera, fragments, transfer, face_region.detach(), reference)


def _shade(context: StageContext, mesh, camera, fragments, textures: Textures, transfer, lights=None):
    """Shade under ``lights`` [K, B*B, 3] (default: the kept lights), box-filtered to the working resolution."""
    lights = context.scene.lights[context.decoupling.kept] if lights is None else lights
    output = context.renderer.shade(mesh, camera, fragments, textures, lights, transfer)
    return box_filter(output, context.config.render.supersampling)


def relight_frozen(context: StageContext, frame: FrozenFrame, textures: Textures, lights: torch.Tensor):
    """The face of a frozen frame under other ``lights`` [K, B*B, 3], summed (no light masks): [H, W, 3]."""
    output = _shade(context, frame.geometry.mesh, frame.camera, frame.fragments, textures, frame.transfer, lights)
    return output.images.sum(0)


def _topology(context: StageContext):
    topology = context.topology
    return topology["triangles"], topology["uvs"], topology["triangle_uvs"]


def _parameter_groups(context: StageContext, parameters: TextureParameters) -> list[dict]:
    rates = context.config.learning_rates
    groups = [
        {"params": parameters.diffuse.parameters(), "lr": rates.stage3_diffuse},
        {"params": parameters.specular.parameters(), "lr": rates.stage3_specular},
        {"params": parameters.roughness.parameters(), "lr": rates.stage3_roughness},
        {"params": [context.scene.lights], "lr": rates.stage3_lights},
    ]
    if context.decoupling.light_field is not None:
        groups.append({"params": context.decoupling.light_field.parameters(), "lr": rates.stage3_light_masks})
    return groups


def _frame_loss(context: StageContext, frame: FrozenFrame, textures: Textures, human_prior) -> torch.Tensor:
    weights, priors, form = context.config.weights, context.config.priors, context.config.decouple.loss_form
    rendered, output = render_frozen(context, frame, textures)
    loss = weights.photometric * context.photometric(frame.index, rendered)
    loss = loss + context.key_light_exposure(frame.index, rendered)
    if context.decoupling.light_field is not None and rendered.light_masks.shape[0] > 1:
        loss = loss + weights.binary * decouple_losses.binary_loss(rendered.light_masks, rendered.coverage,
                                                                   form=form)
    if priors.local_prior:
        loss = loss + weights.local_prior * _local_prior(output, frame.reference, rendered.coverage,
                                                         priors.local_prior_weights)
    if priors.human_prior and human_prior is not None:
        loss = loss + weights.human_prior * human_prior(rendered.light_images, rendered.coverage)
    return loss


def _local_prior(output, reference: dict, coverage: torch.Tensor, weights: tuple[float, float, float]) -> torch.Tensor:
    """LP on screen-space albedo, ``weights`` x (diffuse, specular, roughness) (the authors' 5 / 6 / 1)."""
    diffuse, specular, roughness = weights
    prior = local_prior
    if fast_stage3.enabled(output.diffuse, reference["diffuse"], coverage):
        prior = fast_stage3.local_prior_l1  # the same LP (5x5, L1), fused with its gradient
    return (diffuse * prior(output.diffuse, reference["diffuse"], coverage)
            + specular * prior(output.specular, reference["specular"], coverage)
            + roughness * prior(output.roughness, reference["roughness"], coverage))


def _palette(context: StageContext, initial: Textures):
    priors = context.config.priors
    if not priors.global_prior:
        return None
    return kmeans_palette(initial.diffuse, _uv_mask(context, initial), k=priors.palette_size,
                          seed=context.config.seed, max_samples=priors.palette_samples, n_init=priors.palette_restarts)


def _uv_mask(context: StageContext, initial: Textures) -> torch.Tensor:
    mask = torch.as_tensor(context.model.albedo.face_mask, dtype=torch.float32)
    size = initial.diffuse.shape[0]
    return torch.nn.functional.interpolate(mask[None, None], size=(size, size), mode="bilinear")[0, 0]


def _texture_terms_of(context: StageContext, initial: Textures, palette, uv_mask):
    """textures -> the texture-space terms: the fused kernels (deface/fit/fast_stage3.py) on the CPU, else
    the torch reference :func:`_texture_terms`."""
    weights = context.config.weights
    if fast_stage3.enabled(initial.diffuse, initial.specular, initial.roughness, uv_mask):
        return fast_stage3.TextureTerms(initial, uv_mask, palette, weights.texture_regulariser,
                                        weights.global_prior)
    return lambda textures: _texture_terms(context, textures, initial, palette, uv_mask)


def _texture_terms(context: StageContext, textures: Textures, initial: Textures, palette, uv_mask) -> torch.Tensor:
    weights = context.config.weights
    loss = weights.texture_regulariser * texture_regularisers(textures, initial, uv_mask)
    if palette is not None:
        loss = loss + weights.global_prior * global_prior(textures.diffuse, palette, uv_mask)
    return loss
