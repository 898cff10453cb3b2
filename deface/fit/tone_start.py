"""The skin tone's part of a fit's set-up: whether the model can free its tone, where the tone starts, and what
the log says of the finished texture's tone (docs/skin-tone.md)."""

from __future__ import annotations

from deface.fit.config import FitConfig, supports_free_tone
from deface.fit.log import FitLog
from deface.fit.output import FinishedTextures
from deface.fit.state import StageContext
from deface.models.ita import texture_tone
from deface.priors.illuminant import CARD_SOURCES


def supported_tone(model, config: FitConfig, log: FitLog) -> FitConfig:
    """``config`` without ``tone.free_tone`` for a model with no tone axis (BFM's AlbedoMM), said in the log."""
    supported = supports_free_tone(config)
    if supported is not config:
        log.info(f"the {model.name} albedo model has no skin-tone axis: the tone is not free (docs/skin-tone.md)")
    return supported


def initial_tone(model, config: FitConfig) -> float:
    """The tone a free-tone fit starts from before the scene is read: the model's own mean skin."""
    return model.albedo.tone.reference_ita if config.tone.free_tone else 0.0


def log_tone(context: StageContext, finished: FinishedTextures, log: FitLog) -> None:
    """Say the texture's skin tone and how far the unknown strength of the light leaves it open."""
    light = context.inputs.scene_light
    if light is None:
        return
    illuminant = light.illuminant
    tone = texture_tone(finished.textures.diffuse.detach().numpy(), illuminant.level_sigma,
                        context.target.frames_srgb[0])
    if tone["texture_ita"] is None:
        log.info(f"skin tone of the texture: not measured ({tone['note']})")
        return
    if illuminant.level_sigma == 0:
        where = "as given" if illuminant.source == "given" else f"from the {illuminant.source}"
        log.info(f"skin tone of the texture: ITA {tone['texture_ita']:.1f} (white level {where})")
        return
    darker, lighter = tone["ita_interval"]
    text = (f"skin tone of the texture: ITA {tone['texture_ita']:.1f}, {darker:.0f} to {lighter:.0f} for the light "
            f"level's one-sigma spread ({illuminant.source})")
    if illuminant.source not in CARD_SOURCES and context.target.light_groups is None:
        text += "; a grey card in the photo (--card) or the light's white level (--white) narrows it"
    elif illuminant.source not in CARD_SOURCES:
        text += "; the light's white level (--white: a fit of one photo with a grey card, --card) narrows it"
    log.info(text)
