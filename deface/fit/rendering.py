"""How stages 2 and 3 render a frame of a :class:`~deface.fit.state.StageContext` and score it: the frame's
render through the one render path (deface/render/frame.py) composed with f's masks and M_o, and the terms
every stage adds per frame (L_pho, the scene-light terms; their maths in deface/losses/).

Shapes: H x W working pixels, K kept lights with B*B SH coefficients per colour.
"""

from __future__ import annotations

import torch

from deface.fit.scene import FrameGeometry
from deface.fit.state import FrameRender, LossTerms, StageContext
from deface.losses.illuminant import (
    colour_spread,
    front_directions,
    negative_radiance_loss,
    scene_light_colour_loss,
    scene_light_level_loss,
)
from deface.losses.photometric import photometric_loss
from deface.render.frame import FrameCast, render_frame, shade_frame
from deface.render.mesh import Mesh, Textures
from deface.render.renderer import RenderOutput, ShadowTransfer


def albedo_textures(context: StageContext, size: int | None = None) -> Textures:
    """The albedo model's maps at the fitted coefficients (and tone, when the tone is free), ``size`` texels
    square (default: ``config.stage2_texture_size``)."""
    size = size or context.config.stage2_texture_size
    ita = context.scene.tone if context.config.tone.free_tone else None
    diffuse, specular = context.model.albedo.textures(context.scene.albedo, size, ita)
    roughness = torch.full((*diffuse.shape[:2], 1), context.model.albedo.roughness_default)
    return Textures(diffuse.clamp(0, 1), specular.clamp(0, 1), roughness)


def render_posed(context: StageContext, frame: int, textures: Textures, refresh_shadows: bool,
                 geometry: FrameGeometry | None = None) -> FrameRender:
    """Stage 2's render of a frame at the parameters' current values (one sample per pixel), under the kept
    lights; the shadow transfer refreshed when ``refresh_shadows`` and the mesh moved."""
    geometry = geometry or context.geometry(frame)
    transfer = _transfer(context, frame, geometry.mesh, refresh_shadows)
    output = render_frame(context.renderer, geometry.mesh, geometry.camera, textures,
                          context.kept_lights, transfer)
    return compose(context, frame, output)


def render_cast(context: StageContext, frame: int, cast: FrameCast, textures: Textures,
                face_region: torch.Tensor | None = None) -> tuple[FrameRender, RenderOutput]:
    """A frame's cast (stage 3's frozen frames) shaded with ``textures`` under the kept lights, composed; M_o
    stays ``face_region`` when given. Also the render's buffers."""
    output = shade_frame(context.renderer, cast, textures, context.kept_lights)
    return compose(context, frame, output, face_region), output


def compose(context: StageContext, frame: int, output: RenderOutput,
            face_region: torch.Tensor | None = None) -> FrameRender:
    """The frame's render from its per-light images: f's masks, and M_o (``face_region`` when frozen)."""
    decoupling = context.decoupling
    light_masks = decoupling.light_masks(frame, output.mask)
    probability = None
    if face_region is None:
        probability = decoupling.region_probability(frame, output.mask)
        face_region = decoupling.face_region(frame, output.mask, context.inputs.face_classifier[frame], probability)
    return FrameRender.of(output, light_masks, face_region, probability)


def _transfer(context: StageContext, frame: int, mesh: Mesh, refresh: bool) -> ShadowTransfer | None:
    if not context.config.render.shadows:
        return None
    cache = context.shadow_caches[frame]
    return cache.get(mesh) if refresh or cache.transfer is None else cache.transfer


def photometric(context: StageContext, frame: int, rendered: FrameRender) -> torch.Tensor:
    """L_pho of a frame's render against its photo, over M_o."""
    config = context.config
    return photometric_loss(rendered.face, context.target.images[frame], rendered.face_region, rendered.coverage,
                            blur=config.decouple.render_blur, form=config.decouple.loss_form,
                            clipped=context.target.clipped[frame] if config.decouple.clipped_as_bound else None)


def kept_lights_read(context: StageContext, as_rendered: bool) -> torch.Tensor:
    """[K, B*B, 3] the kept lights as a light prior reads them: as the renderer renders them (negative radiance
    clamped, ``render.non_negative_lights``) or as their raw SH."""
    lights = context.kept_lights
    return context.renderer.rendered_lights(lights) if as_rendered else lights


def scene_light_colour(context: StageContext) -> torch.Tensor:
    """The scene-light colour term of the kept lights (0 when off or without an estimate): each photo's lights
    against its own white level (one for a photo or a clip), mean over the photos."""
    tone, light = context.config.tone, context.inputs.scene_light
    if not tone.scene_light_prior or light is None:
        return torch.zeros(())
    lights = kept_lights_read(context, tone.colour_as_rendered)
    terms = [scene_light_colour_loss(lights[context.decoupling.frame_lights(frame)], light.illuminants[frame].white,
                                     tone.weight, tone.colour_sigma) for frame in _light_photos(context)]
    return torch.stack(terms).mean()


def _light_photos(context: StageContext) -> list[int]:
    """The first frame of each group of frames with its own lights (one for a photo or a clip)."""
    groups = context.decoupling.light_groups or (0,) * context.target.num_frames
    return [groups.index(group) for group in sorted(set(groups))]


def light_colour_spread(context: StageContext) -> torch.Tensor:
    """How much the kept lights' colours change with direction, weighted (0 when off)."""
    weight = context.config.weights.light_colour_spread
    if weight <= 0:
        return torch.zeros(())
    return weight * colour_spread(kept_lights_read(context, context.config.tone.colour_as_rendered),
                                  front_directions())


def negative_radiance(context: StageContext) -> torch.Tensor:
    """The kept lights' negative radiance, weighted (0 when off)."""
    weight = context.config.weights.negative_radiance
    if weight <= 0:
        return torch.zeros(())
    return weight * negative_radiance_loss(context.kept_lights)


def with_light_priors(context: StageContext, total: torch.Tensor, terms: LossTerms) -> torch.Tensor:
    """``total`` plus the terms every stage holds the kept lights to (their colour spread, their negative
    radiance, the scene light's colour), each kept in ``terms`` by name; added one by one, in this order."""
    total = total + terms.add("light_colour_spread", light_colour_spread(context))
    total = total + terms.add("negative_radiance", negative_radiance(context))
    return total + terms.add("scene_light_colour", scene_light_colour(context))


def scene_light_level(context: StageContext, frame: int, rendered: FrameRender) -> torch.Tensor:
    """The scene-light level term of one frame: the brightest of its lights' level on the cheeks and forehead
    against its white level (0 when off)."""
    tone, light = context.config.tone, context.inputs.scene_light
    if not tone.scene_light_prior or light is None or light.regions is None or rendered.normals is None:
        return torch.zeros(())
    lights = kept_lights_read(context, tone.level_as_rendered)[context.decoupling.frame_lights(frame)]
    return scene_light_level_loss(lights, rendered.normals, light.regions[frame], light.illuminants[frame].white,
                                  tone.weight, tone.exposure_sigma)
