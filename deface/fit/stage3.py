"""Stage 3 (Alg. 1): per-texel refinement.

Geometry, g and M_o are frozen at their stage-2 values (authors' code), so each frame is ray cast once and
its shadow transfer computed once. Optimised: diffuse, specular and roughness UV maps T (initialised from
the albedo model, T^0), the kept lights gamma and f, with
    w0 L_pho + w4 L_bin + w5 L_GP + w6 L_LP + w7 L_HP + texture regularisers.
With ``Iterations.stage3_holdout`` it fits the photometric term on all but a share of the pixels and keeps
the step that predicts the held-out ones best (deface/fit/holdout.py).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import torch

from deface.fit import fast_stage3, rendering
from deface.fit.convergence import converged
from deface.fit.frame_register import frame_uvs, registers, with_uvs
from deface.fit.guard import StepGuard
from deface.fit.holdout import BestStep, HeldOutPixels
from deface.fit.scene import FrameGeometry
from deface.fit.state import FrameRender, LossTerms, StageContext
from deface.fit.texels import frame_views
from deface.losses import decouple as decouple_losses
from deface.losses.texture import PAPER_WEIGHTS, SmoothDeparture
from deface.priors.global_prior import kmeans_palette
from deface.render.frame import FrameCast, cast_frame, shade_frame
from deface.render.mesh import Mesh, Textures
from deface.render.renderer import RenderOutput
from deface.texture.confidence import TexelView
from deface.texture.pyramid import TexturePyramid, level_gates, level_sizes

MIN_LEVEL = 0.01
"""Floor of the diffuse map's level in :func:`map_level` (a darkest skin's green is about 0.03)."""


@dataclass(frozen=True)
class AlbedoReference:
    """Screen-space renders of T^0's maps (LP's reference), working resolution."""

    diffuse: torch.Tensor  # [H, W, 3]
    specular: torch.Tensor  # [H, W, 3]
    roughness: torch.Tensor  # [H, W, 1]


@dataclass(frozen=True)
class FrozenFrame:
    """A frame's stage-3 constants: geometry, its cast (fragments and shadow transfer), M_o, reference albedo."""

    index: int  # frame number
    geometry: FrameGeometry  # detached posed mesh and the working-resolution camera
    cast: FrameCast  # cast at config.render.supersampling samples per pixel, with the frame's shadow transfer
    face_region: torch.Tensor  # [H, W] M_o from stage 2
    reference: AlbedoReference


@dataclass(frozen=True)
class FrameTerms:
    """What stage 3's per-frame terms need besides the frame."""

    human_prior: object | None  # HP's network (None: no HP)
    held_out: HeldOutPixels | None  # pixels the photometric term leaves out and scores (None: none)
    local_prior: tuple[float, float, float]  # LP's (diffuse, specular, roughness) weights, diffuse relative


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
    """The pyramid's gates from the frames' texel density (pixels per texel; several frames: ``frames``)."""
    config = context.config.texture_pyramid
    combine = {"best": np.max, "sum": np.sum}[config.frames]
    density = combine([view.density for view in views], axis=0)
    return level_gates(density, level_sizes(size, config), config.gated, config.gate_power)


def initial_textures(context: StageContext) -> Textures:
    """T^0 at the output resolution from the fitted albedo coefficients."""
    with torch.no_grad():
        return rendering.albedo_textures(context, context.texture_size)


@dataclass(frozen=True)
class Stage3Result:
    textures: Textures  # refined UV maps
    initial: Textures  # T^0
    frozen: list[FrozenFrame]  # per-frame constants, reused to re-render with any textures
    history: list[float]  # loss per iteration
    terms: list[dict[str, float]]  # the named terms per iteration (they sum to the total)
    views: list[TexelView]  # per frame: how the frozen camera sees each texel


def run_stage3(context: StageContext, human_prior=None) -> Stage3Result:
    """Refine textures from T^0 with the frames' geometry frozen."""
    initial = initial_textures(context)
    frozen = freeze_frames(context, initial)
    views = frame_views(context.model, frozen, initial.diffuse.shape[0])
    if registers(context):  # several frames: each samples the maps where its own detail belongs
        uvs = frame_uvs(context, frozen, views, initial, render_frozen)
        frozen = [_referenced(context, with_uvs(frame, moved), initial)
                  for frame, moved in zip(frozen, uvs, strict=True)]
        views = frame_views(context.model, frozen, initial.diffuse.shape[0])
    parameters = TextureParameters(initial, texture_gates(context, views, initial.diffuse.shape[0]))
    optimiser = torch.optim.Adam(_parameter_groups(context, parameters, initial))
    guard = StepGuard(optimiser, "stage 3", context.log)  # NaN/Inf rollback (deface/fit/guard.py)
    iterations = context.config.iterations
    held_out = HeldOutPixels.draw([tuple(f.face_region.shape) for f in frozen], iterations.stage3_holdout) \
        if iterations.stage3_holdout > 0 else None
    best = BestStep(_optimised(context, parameters), iterations.convergence_window) if held_out else None
    loss_of = objective(context, frozen, initial, human_prior, held_out)
    history, term_history = [], []
    for step in range(iterations.stage3):
        optimiser.zero_grad(set_to_none=True)
        terms, errors = LossTerms(), []
        loss = loss_of(parameters.textures(), terms, errors)
        loss.backward()
        if best is not None and best.update(step, sum(errors)):
            break
        optimiser.step()
        guard.check(loss)
        value = float(loss.detach())
        history.append(value)
        term_history.append(terms.values)
        context.log.step("stage 3", step, iterations.stage3, value, terms.values)
        if step + 1 < iterations.stage3 and converged(history, iterations.convergence_window,
                                                      iterations.stage3_tolerance):
            context.log.info(f"stage 3 converged after {step + 1} of {iterations.stage3} steps "
                             f"(tolerance {iterations.stage3_tolerance} per {iterations.convergence_window} steps)")
            break
    if best is not None:
        _keep_best(context, best, len(history))
    with torch.no_grad():
        return Stage3Result(parameters.textures(), initial, frozen, history, term_history, views)


def _optimised(context: StageContext, parameters: TextureParameters) -> list[torch.Tensor]:
    """Every tensor stage 3 optimises: the maps' pyramids, the kept lights' SH and f."""
    tensors = list(parameters.parameters()) + [context.scene.lights]
    if context.decoupling.light_field is not None:
        tensors += list(context.decoupling.light_field.parameters())
    return tensors


def _keep_best(context: StageContext, best: BestStep, steps: int) -> None:
    """Return to the step whose maps predicted the held-out pixels best, and say so."""
    best.restore()
    context.log.info(f"stage 3 keeps step {best.step} of the {steps} it ran: the held-out pixels' error was "
                     f"lowest there ({context.config.iterations.stage3_holdout:.0%} of the face held out)")


def objective(context: StageContext, frozen: list[FrozenFrame], initial: Textures, human_prior=None,
              held_out: HeldOutPixels | None = None):
    """The stage-3 loss as a function of the textures; its texture-space constants are computed once. With
    ``held_out`` the photometric term fits the other pixels and each frame's error on the held-out ones is
    appended to the ``errors`` list the loss is called with."""
    palette, uv_mask = _palette(context, initial), _uv_mask(context, initial)
    weights = context.config.weights
    relative = relative_scale(weights, initial.diffuse, uv_mask)
    texture_terms = _texture_terms_of(context, initial, palette, uv_mask, relative)
    smooth = SmoothDeparture(initial.diffuse, uv_mask, weights.smooth_departure_cells) \
        if weights.smooth_departure else None
    diffuse, specular, roughness = context.config.priors.local_prior_weights
    setup = FrameTerms(human_prior, held_out, (diffuse * relative, specular, roughness))

    def loss_of(textures: Textures, terms: LossTerms | None = None, errors: list | None = None) -> torch.Tensor:
        terms = terms or LossTerms()
        loss = sum(_frame_loss(context, f, textures, setup, terms, 1.0 / len(frozen), errors)
                   for f in frozen) / len(frozen)
        loss = loss + texture_terms(textures, terms)
        if smooth is not None:
            loss = loss + terms.add("smooth_departure", weights.smooth_departure * smooth(textures.diffuse))
        return rendering.with_light_priors(context, loss, terms)

    return loss_of


def render_frozen(context: StageContext, frame: FrozenFrame, textures: Textures) -> tuple[FrameRender, RenderOutput]:
    """Shade a frozen frame with ``textures`` and the current kept lights; M_o stays frozen."""
    return rendering.render_cast(context, frame.index, frame.cast, textures, frame.face_region)


def freeze_frames(context: StageContext, initial: Textures) -> list[FrozenFrame]:
    return [_freeze(context, frame, initial) for frame in range(context.target.num_frames)]


@torch.no_grad()
def _freeze(context: StageContext, frame: int, initial: Textures) -> FrozenFrame:
    geometry = context.geometry(frame)
    geometry = FrameGeometry(
        mesh=Mesh(geometry.mesh.vertices.detach(), *_topology(context)),
        camera=geometry.camera.detached(),
    )
    transfer = context.shadow_caches[frame].get(geometry.mesh) if context.config.render.shadows else None
    cast = cast_frame(context.renderer, geometry.mesh, geometry.camera, transfer, context.config.render.supersampling)
    output = shade_frame(context.renderer, cast, initial, context.kept_lights)
    face_region = context.decoupling.face_region(frame, output.mask, context.inputs.face_classifier[frame])
    return FrozenFrame(frame, geometry, cast, face_region.detach(), _albedo_reference(output))


def _albedo_reference(output: RenderOutput) -> AlbedoReference:
    return AlbedoReference(output.diffuse, output.specular, output.roughness)


@torch.no_grad()
def _referenced(context: StageContext, frame: FrozenFrame, initial: Textures) -> FrozenFrame:
    """``frame`` with LP's reference rendered again (its mesh's UVs moved)."""
    output = shade_frame(context.renderer, frame.cast, initial, context.kept_lights)
    return dataclasses.replace(frame, reference=_albedo_reference(output))


def _topology(context: StageContext):
    topology = context.topology
    return topology["triangles"], topology["uvs"], topology["triangle_uvs"]


def map_level(diffuse: torch.Tensor, uv_mask: torch.Tensor) -> float:
    """A diffuse map's level: its median linear green [Ht, Wt, 3] over the face texels (``uv_mask`` [Ht, Wt]
    > 0.5), at least MIN_LEVEL."""
    face = uv_mask > 0.5
    level = float(diffuse[face][:, 1].median()) if bool(face.any()) else 0.0
    return max(level, MIN_LEVEL)


def diffuse_step(rates, diffuse: torch.Tensor, uv_mask: torch.Tensor) -> float:
    """Stage 3's Adam step for the diffuse map: ``rates.stage3_diffuse``, scaled by the map's level over
    ``rates.stage3_diffuse_level`` when that is set (:class:`~deface.fit.config.LearningRates`). Adam's steps
    do not scale with the gradient, so with a step proportional to the map, a map and the same map times c
    (the same face, a darker skin) are refined alike up to the factor c."""
    if rates.stage3_diffuse_level <= 0:
        return rates.stage3_diffuse
    return rates.stage3_diffuse * map_level(diffuse, uv_mask) / rates.stage3_diffuse_level


def relative_scale(weights, diffuse: torch.Tensor, uv_mask: torch.Tensor) -> float:
    """``weights.diffuse_level`` over the diffuse map's level (1 when that is 0): the factor on the weights of
    the diffuse map's degree-1 terms (its L1 regularisers, LP), squared on its degree-2 ones (smoothness, GP), so
    that a map and the same map times c (the same face, a darker skin, under lights 1 / c as bright: the same
    photo) cost alike (:class:`~deface.fit.config.Weights`)."""
    if weights.diffuse_level <= 0:
        return 1.0
    return weights.diffuse_level / map_level(diffuse, uv_mask)


def _parameter_groups(context: StageContext, parameters: TextureParameters, initial: Textures) -> list[dict]:
    rates = context.config.learning_rates
    step = diffuse_step(rates, initial.diffuse, _uv_mask(context, initial))
    groups = [
        {"params": parameters.diffuse.parameters(), "lr": step},
        {"params": parameters.specular.parameters(), "lr": rates.stage3_specular},
        {"params": parameters.roughness.parameters(), "lr": rates.stage3_roughness},
        {"params": [context.scene.lights], "lr": rates.stage3_lights},
    ]
    if context.decoupling.light_field is not None:
        groups.append({"params": context.decoupling.light_field.parameters(), "lr": rates.stage3_light_masks})
    return groups


def _frame_loss(context: StageContext, frame: FrozenFrame, textures: Textures, setup: FrameTerms, terms: LossTerms,
                scale: float, errors: list | None = None) -> torch.Tensor:
    weights, priors, form = context.config.weights, context.config.priors, context.config.decouple.loss_form
    rendered, output = render_frozen(context, frame, textures)
    loss = terms.add("photometric", weights.photometric * _photometric(context, frame.index, rendered,
                                                                       setup.held_out, errors), scale)
    loss = loss + terms.add("scene_light_level", rendering.scene_light_level(context, frame.index, rendered), scale)
    if context.decoupling.light_field is not None and rendered.light_masks.shape[0] > 1:
        loss = loss + terms.add("binary", weights.binary * decouple_losses.binary_loss(
            rendered.light_masks, rendered.coverage, form=form), scale)
    if priors.local_prior:
        loss = loss + terms.add("local_prior", weights.local_prior * _local_prior(
            output, frame.reference, rendered.coverage, setup.local_prior), scale)
    if priors.human_prior and setup.human_prior is not None:
        loss = loss + terms.add("human_prior", weights.human_prior * setup.human_prior(
            rendered.light_images, rendered.coverage), scale)
    return loss


def _photometric(context: StageContext, frame: int, rendered: FrameRender, held_out: HeldOutPixels | None,
                 errors: list | None) -> torch.Tensor:
    """L_pho of a frame; with ``held_out``, over the fitted pixels, and the held-out ones' error appended to
    ``errors``."""
    if held_out is None:
        return rendering.photometric(context, frame, rendered)
    if errors is not None:
        with torch.no_grad():
            errors.append(float(rendering.photometric(context, frame, held_out.scored(frame, rendered))))
    return rendering.photometric(context, frame, held_out.fitted(frame, rendered))


def _local_prior(output: RenderOutput, reference: AlbedoReference, coverage: torch.Tensor,
                 weights: tuple[float, float, float]) -> torch.Tensor:
    """LP on screen-space albedo, ``weights`` x (diffuse, specular, roughness) (the authors' 5 / 6 / 1)."""
    diffuse, specular, roughness = weights
    prior = fast_stage3.local_prior_l1  # the op: local_prior (5x5, L1) or, on the CPU, fused with its gradient
    return (diffuse * prior(output.diffuse, reference.diffuse, coverage)
            + specular * prior(output.specular, reference.specular, coverage)
            + roughness * prior(output.roughness, reference.roughness, coverage))


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


def _texture_terms_of(context: StageContext, initial: Textures, palette, uv_mask, relative: float):
    """(textures, terms) -> the texture-space terms, the diffuse map's relative to its level (``relative``,
    :func:`relative_scale`): the op ``texture_terms`` (deface/fit/fast_stage3.py; the torch reference,
    deface/losses/texture.py and GP, or fused kernels on the CPU). Both log the same terms: the regularisers,
    and GP when there is a palette."""
    weights = context.config.weights
    map_weights = dict(PAPER_WEIGHTS, diffuse=PAPER_WEIGHTS["diffuse"].relative(relative))
    global_weight = weights.global_prior * relative ** 2  # GP is a squared distance
    constants = fast_stage3.TextureTerms(initial, uv_mask, palette, weights.texture_regulariser, global_weight,
                                         map_weights)

    def texture_terms(textures: Textures, terms: LossTerms) -> torch.Tensor:
        total, regularisers, prior = constants(textures)
        terms.add("texture_regularisers", regularisers)
        if palette is not None:
            terms.add("global_prior", prior)
        return total

    return texture_terms
