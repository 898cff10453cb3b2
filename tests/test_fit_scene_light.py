"""The tone's start: the skin's colour in the key light (deface.fit.scene_light.lit_skin_albedo), on synthetic
skin pixels of known albedo: a Lambertian hemisphere of normals under a key light plus ambient, with the
things a photo adds: a cast shadow over the cheeks, a specular highlight, a clipped red channel, hair and a
white turban classified as skin. Each must leave the estimate where the clean skin puts it."""

from __future__ import annotations

import sys

import numpy as np
import pytest
from skimage.color import lab2rgb

from deface.fit import scene_light
from deface.fit.scene_light import SKIN_F0, SkinPixels, lit_skin_albedo
from deface.io.images import linear_to_srgb, srgb_to_linear
from deface.models.ita import ita_of_srgb
from deface.priors.illuminant import IlluminantConfig, planckian_rgb

KEY = np.array([0.45, 0.35, 0.82]) / np.linalg.norm([0.45, 0.35, 0.82])
AMBIENT = 0.25


def skin_albedo(ita: float) -> np.ndarray:
    angle = np.radians(ita)
    lab = np.array([50 + 20 * np.sin(angle), 11.0, 20 * np.cos(angle)])
    return lab2rgb(lab[None, None])[0, 0] ** 2.2


def hemisphere(count: int = 6000, seed: int = 0) -> np.ndarray:
    """Unit normals facing the camera (+z), denser towards it like a face's."""
    rng = np.random.default_rng(seed)
    normals = rng.normal(size=(count, 3))
    normals[:, 2] = np.abs(normals[:, 2]) + 0.3
    return normals / np.linalg.norm(normals, axis=-1, keepdims=True)


def photo(albedo: np.ndarray, white: np.ndarray, normals: np.ndarray, *, shadow=None, specular=0.0,
          exposure=1.0, sheen=SKIN_F0) -> SkinPixels:
    """Skin pixels lit by the key light (peak white response ``white``) plus ambient; the surface mirrors
    ``sheen`` of the ambient light (a uniform sky on a rough dielectric at normal incidence), as skin does."""
    shading = AMBIENT + (1 - AMBIENT) * np.clip(normals @ KEY, 0, None)
    if shadow is not None:  # a cast shadow keeps the ambient and a fraction of the key light
        shading = np.where(shadow, AMBIENT + 0.3 * (shading - AMBIENT), shading)
    half = (KEY + [0, 0, 1]) / np.linalg.norm(KEY + [0, 0, 1])
    highlight = specular * np.clip(normals @ half, 0, 1) ** 60
    highlight = highlight + sheen * AMBIENT
    linear = exposure * white * (albedo * shading[:, None] + highlight[:, None])
    in_boxes = np.abs(normals[:, 0]) > 0.35  # "the cheeks"
    to_camera = np.broadcast_to([0.0, 0.0, 1.0], normals.shape)
    return SkinPixels(linear_to_srgb(np.clip(linear, 0, 1)), normals, to_camera, in_boxes)


def estimated_ita(pixels: SkinPixels, white: np.ndarray) -> float:
    albedo = lit_skin_albedo(pixels, white)
    assert albedo is not None
    return ita_of_srgb(linear_to_srgb(np.clip(albedo, 0, 1))[None])


@pytest.mark.parametrize("ita", [-30.0, 10.0, 50.0])
@pytest.mark.parametrize("cct", [2700.0, 6504.0])
def test_recovers_the_albedo_under_the_scene_light(ita, cct):
    """The colour exactly; the level is the skin at the key quantile of the lit pixels, a surface within
    about 25 degrees of the light (the level the scene-light term holds the key light to), so 85-100 %."""
    white = 0.9 * planckian_rgb(cct)
    ratio = lit_skin_albedo(photo(skin_albedo(ita), white, hemisphere()), white) / skin_albedo(ita)
    assert ratio == pytest.approx(np.full(3, ratio.mean()), rel=0.02)
    assert 0.85 <= ratio.mean() <= 1.0


@pytest.mark.parametrize(("ita", "lighter"), [(-30.0, 1.06), (50.0, 1.01)])
def test_the_skins_sheen_is_not_taken_for_a_lighter_skin(ita, lighter, monkeypatch):
    """Skin mirrors F0 = 2.8 % of the ambient light over the whole face, a tenth of a dark skin's own level:
    the start takes it off, so skin with its sheen gives the albedo that skin without it gives; read as albedo,
    it would make a dark skin's level ``lighter`` times brighter (and a light skin's by little)."""
    white, normals = np.ones(3), hemisphere()
    albedo = skin_albedo(ita)
    with_sheen = lit_skin_albedo(photo(albedo, white, normals), white)
    monkeypatch.setattr(scene_light, "SKIN_F0", 0.0)
    without = lit_skin_albedo(photo(albedo, white, normals, sheen=0.0), white)
    read_as_albedo = lit_skin_albedo(photo(albedo, white, normals), white)
    assert with_sheen == pytest.approx(without, rel=0.05)  # the photo's ambient is 0.25 of W, the start takes 0.3
    assert read_as_albedo[1] / without[1] > lighter


def test_no_ambient_light_no_sheen_taken_off(monkeypatch):
    """A hard key light in a dark room: the envelope shows no ambient light, so there is no ambient sheen to take
    off and the start is what it is without the correction."""
    monkeypatch.setitem(globals(), "AMBIENT", 0.0)  # photo() reads it from this module
    white, normals = np.ones(3), hemisphere()
    pixels = photo(skin_albedo(-10.0), white, normals, sheen=0.0)
    corrected = lit_skin_albedo(pixels, white)
    monkeypatch.setattr(scene_light, "SKIN_F0", 0.0)
    assert corrected == pytest.approx(lit_skin_albedo(pixels, white), rel=1e-6)


def test_a_cast_shadow_over_the_cheeks_leaves_the_start_alone():
    white, normals = np.ones(3), hemisphere()
    clean_photo = photo(skin_albedo(10.0), white, normals)
    cheeks = clean_photo.in_boxes
    shadow = cheeks & (np.random.default_rng(1).random(len(normals)) < 0.8)  # most of the measured skin
    shadowed_photo = photo(skin_albedo(10.0), white, normals, shadow=shadow)
    assert estimated_ita(shadowed_photo, white) == pytest.approx(estimated_ita(clean_photo, white), abs=2.0)
    # the shadow is there: the cheeks' own pixels are much darker
    assert np.median(shadowed_photo.srgb[cheeks, 1]) < 0.85 * np.median(clean_photo.srgb[cheeks, 1])


@pytest.mark.parametrize("share", [0.2, 0.4])
def test_a_shadow_over_the_skin_facing_the_light_leaves_the_start_alone(share):
    """A brim over the forehead, leaves over the middle of the face: the shadow takes the skin that faces the key
    light, the brightest lit skin, and ``share`` of all of it. The level read from the envelope over all the
    skin's normals does not depend on which of them the shadow leaves lit (the lit pixels' own 90th percentile
    read a skin 5-25 degrees darker here; with more than about half of the skin shadowed the envelope
    follows the shadow too)."""
    white, normals = np.ones(3), hemisphere()
    clean = estimated_ita(photo(skin_albedo(10.0), white, normals), white)
    facing = normals @ KEY >= np.quantile(normals @ KEY, 1.0 - share)
    assert estimated_ita(photo(skin_albedo(10.0), white, normals, shadow=facing), white) == pytest.approx(
        clean, abs=2.0)


@pytest.mark.parametrize("brighter", [1.5, 2.0, 3.0])
@pytest.mark.parametrize("ita", [-30.0, 10.0])
def test_bright_skin_coloured_pixels_at_the_faces_edge_leave_the_start_alone(ita, brighter):
    """A grey beard mixed with skin along the jaw, rim-lit hair: pixels of the skin's colour but ``brighter`` at
    the grazing edge of the face (5 % of the skin). The upper envelope's quantile regression sits on them and
    rises away from the camera, which no light in front of the face does; the start then comes from least
    squares, as before the quantile regression (without that: 8-13 degrees lighter at twice the level)."""
    white, normals = np.ones(3), hemisphere()
    clean = photo(skin_albedo(ita), white, normals)
    edge = normals[:, 2] <= np.quantile(normals[:, 2], 0.05)
    linear = srgb_to_linear(clean.srgb)
    linear[edge] *= brighter
    with_edge = SkinPixels(linear_to_srgb(np.clip(linear, 0, 1)), normals, clean.to_camera, clean.in_boxes)
    assert estimated_ita(with_edge, white) == pytest.approx(estimated_ita(clean, white), abs=1.0)


def test_a_highlight_does_not_lighten_dark_skin():
    white, normals = np.ones(3), hemisphere()
    clean = estimated_ita(photo(skin_albedo(-30.0), white, normals), white)
    shiny = photo(skin_albedo(-30.0), white, normals, specular=0.25)
    assert np.median(shiny.srgb[:, 2]) > 0  # the highlight is there
    assert estimated_ita(shiny, white) == pytest.approx(clean, abs=1.5)


def test_a_clipped_red_channel_keeps_the_colour():
    white, normals = np.ones(3), hemisphere()
    albedo = skin_albedo(50.0)
    clean = estimated_ita(photo(albedo, white, normals), white)
    bright = photo(albedo, white, normals, exposure=2.2)
    assert (bright.srgb[:, 0] >= 0.98).mean() > 0.2  # much of the lit skin is clipped in red
    albedo_bright = lit_skin_albedo(bright, white)
    ratio = albedo_bright / lit_skin_albedo(photo(albedo, white, normals), white)
    assert ratio == pytest.approx(np.full(3, 2.2), rel=0.05)  # the exposure, in every channel alike
    assert estimated_ita(photo(albedo, 1.5 * white, normals, exposure=1.0), 1.5 * white) == pytest.approx(clean)


def test_hair_and_a_white_turban_taken_for_skin_are_left_out():
    white, normals = np.ones(3), hemisphere()
    skin = photo(skin_albedo(-10.0), white, normals)
    rng = np.random.default_rng(2)
    others = rng.random(len(normals))
    srgb = skin.srgb.copy()
    srgb[others < 0.15] = 0.93  # a white turban
    srgb[(others >= 0.15) & (others < 0.3)] = [0.12, 0.1, 0.09]  # dark hair
    mixed = SkinPixels(srgb, skin.normals, skin.to_camera, skin.in_boxes)
    assert estimated_ita(mixed, white) == pytest.approx(estimated_ita(skin, white), abs=1.5)


def test_too_little_skin_gives_no_start():
    normals = hemisphere(8)
    assert lit_skin_albedo(photo(skin_albedo(10.0), np.ones(3), normals), np.ones(3)) is None


def test_a_grayscale_photo_keeps_the_model_tone():
    from deface.models.ita import grayscale

    skin = photo(skin_albedo(10.0), np.ones(3), hemisphere())
    grey = np.repeat(skin.srgb.mean(-1, keepdims=True), 3, axis=-1)
    assert grayscale(grey) and not grayscale(skin.srgb)


def test_red_clipped_on_all_the_lit_skin_takes_the_colour_from_the_rest():
    """An overexposed photo of a red-brown skin: the red of every key-lit pixel is clipped; the colour comes from
    the skin whose red is not (the ratio does not depend on the shading), the level from green."""
    white, normals = np.ones(3), hemisphere()
    albedo = np.array([0.25, 0.1, 0.05])
    # a surface facing the light: green 0.9, red 2.25; no sheen (under nine times the light W says it would be
    # nine times what the start takes off: this test is about the clipped red)
    over = photo(albedo, white, normals, exposure=9.0, sheen=0.0)
    green = over.srgb[:, 1] ** 2.2
    lit = green >= 0.5 * np.quantile(green, 0.9)  # the candidates for the key light's envelope
    assert (over.srgb[lit, 0] >= 0.98).mean() > 0.99
    ratio = lit_skin_albedo(over, white) / albedo
    assert ratio == pytest.approx(np.full(3, ratio.mean()), rel=0.05)  # the colour, in every channel alike


def card_facing_camera_ratio(normals: np.ndarray) -> float:
    """The truth of ``facing_camera_ratio`` for ``photo``'s light: the light's white response at the key quantile
    of the skin's normals over its response at the camera's direction (+z), where a card facing the camera is."""
    shading = AMBIENT + (1 - AMBIENT) * np.clip(normals @ KEY, 0, None)
    return float(np.quantile(shading, scene_light.KEY_QUANTILE) / (AMBIENT + (1 - AMBIENT) * KEY[2]))


@pytest.mark.parametrize("ita", [-30.0, 10.0, 50.0])
def test_a_card_facing_the_camera_is_corrected_to_the_light_facing_the_key(ita):
    """A card beside the face, facing the camera, gets less of a key light 35 degrees off the camera than the skin
    facing it; the ratio comes from the face's own shading, whatever the skin's tone (within 4 %)."""
    normals = hemisphere()
    truth = card_facing_camera_ratio(normals)
    assert truth > 1.05  # the key light is well off the camera
    ratio = scene_light.facing_camera_ratio(photo(skin_albedo(ita), 0.8 * np.ones(3), normals), np.ones(3))
    assert ratio == pytest.approx(truth, rel=0.04)


def test_a_key_light_at_the_camera_needs_almost_no_card_correction(monkeypatch):
    """The card then gets the light's peak, a little above W, which is the light at the skin's key quantile."""
    monkeypatch.setattr(sys.modules[__name__], "KEY", np.array([0.0, 0.0, 1.0]))
    normals = hemisphere()
    ratio = scene_light.facing_camera_ratio(photo(skin_albedo(30.0), 0.8 * np.ones(3), normals), np.ones(3))
    assert ratio == pytest.approx(card_facing_camera_ratio(normals), rel=0.03)
    assert 0.9 < ratio <= 1.0


def test_the_card_correction_scales_w_and_says_so():
    from deface.fit.log import FitLog
    from deface.priors.illuminant import IlluminantEstimate

    card = IlluminantEstimate(np.array([0.5, 0.5, 0.5]), 6504.0, "reference card", 1.0, 100, detail="a card")
    pixels, log = photo(skin_albedo(30.0), 0.8 * np.ones(3), hemisphere()), FitLog(quiet=True)
    corrected = scene_light.facing_illuminant(card, pixels, IlluminantConfig(), log)
    ratio = corrected.orientation
    assert ratio > 1.05 and corrected.white == pytest.approx(card.white * ratio)
    assert corrected.record()["orientation"] == pytest.approx(ratio, abs=1e-4)
    assert "facing the camera" in corrected.detail
    assert any("facing the camera" in note for note in log.notes)
    towards_light = IlluminantConfig(reference_facing="light")
    assert scene_light.facing_illuminant(card, pixels, towards_light, log) is card  # held towards the light: as read
    given = IlluminantEstimate(np.ones(3), 6504.0, "given", 1.0, 0)
    assert scene_light.facing_illuminant(given, pixels, IlluminantConfig(), log) is given


def test_the_scenes_reading_is_corrected_before_the_white_point_weighs_in():
    """A grey world's level (surfaces facing the camera) is corrected like a card's, then combined with the photo's
    white point by the same inverse variances as before: the correction's share of W is the scene's weight."""
    from deface.fit.log import FitLog
    from deface.priors.illuminant import IlluminantEstimate, _with_exposure_prior

    level, sigma, exposure_sigma = 0.6, 0.7, 0.7
    combined, spread = _with_exposure_prior(level, sigma, exposure_sigma)
    estimate = IlluminantEstimate(combined * planckian_rgb(4000.0), 4000.0, "grey world", 1.0, 100, spread,
                                  scene_reading=(level, sigma, exposure_sigma))
    pixels = photo(skin_albedo(30.0), 0.8 * np.ones(3), hemisphere())
    corrected = scene_light.facing_illuminant(estimate, pixels, IlluminantConfig(scene_facing=True),
                                              FitLog(quiet=True))
    ratio = corrected.orientation
    assert ratio > 1.05
    assert corrected.white == pytest.approx(estimate.white * ratio**0.5, rel=1e-6)  # equal weights: the square root
    assert corrected.level_sigma == estimate.level_sigma
    off = scene_light.facing_illuminant(estimate, pixels, IlluminantConfig(), FitLog(quiet=True))
    assert off is estimate  # off by default (docs/skin-tone.md)
