"""The scene's illuminant estimate on synthetic scenes with a known light, and the scene-light terms."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from deface.io.images import LUMINANCE, linear_to_srgb, srgb_to_linear
from deface.losses.illuminant import (
    RINGING_SHARE,
    colour_spread,
    exposure_term,
    front_directions,
    key_light_level,
    light_colour_term,
    negative_radiance_loss,
    negative_share,
    peak_white,
    white_response,
)
from deface.priors.illuminant import (
    IlluminantConfig,
    _scene_pixels,
    estimate_illuminant,
    known_illuminant,
    planckian_rgb,
    plausible_cct,
)
from deface.render.sh import fibonacci_sphere, sh_basis, white_light

SIZE = 96


def face_mask() -> np.ndarray:
    yy, xx = np.mgrid[:SIZE, :SIZE]
    return (xx - SIZE / 2) ** 2 / 20**2 + (yy - SIZE / 2) ** 2 / 26**2 <= 1


def grey_world_scene(cct: float, level: float, seed: int = 0) -> np.ndarray:
    """A room of neutral surfaces averaging 18 % under a Planckian light; the face is dark red (ignored). None
    looks near white (a white patch would decide instead: tests below)."""
    rng = np.random.default_rng(seed)
    reflectance = np.clip(rng.lognormal(np.log(0.16), 0.5, (SIZE, SIZE, 1)), 0.01, 0.5 / max(level, 1.0))
    reflectance *= 0.18 / reflectance.mean()
    image = reflectance * level * planckian_rgb(cct)
    image[face_mask()] = [0.3, 0.02, 0.02]
    return linear_to_srgb(np.clip(image, 0, 1))


@pytest.mark.parametrize("cct", [2700.0, 4000.0, 6504.0, 9000.0])
def test_grey_world_recovers_the_lights_colour_temperature(cct):
    estimate = estimate_illuminant([grey_world_scene(cct, 1.0)], [face_mask()])
    assert estimate.source == "grey world"
    assert estimate.cct == pytest.approx(cct, rel=0.04)
    assert estimate.white / estimate.white.sum() == pytest.approx(planckian_rgb(cct) / planckian_rgb(cct).sum(),
                                                                  abs=0.02)


def test_level_follows_the_scene_part_way_from_the_photos_white_point():
    """Grey world's level moves W from 1 by the weight its spread earns against the exposure prior."""
    config = IlluminantConfig()
    weight = config.grey_world_sigma**-2 / (config.grey_world_sigma**-2 + config.exposure_sigma**-2)
    for level in (0.5, 2.0):
        estimate = estimate_illuminant([grey_world_scene(6504.0, level)], [face_mask()], config)
        luminance = float(estimate.white @ np.array([0.2126, 0.7152, 0.0722]))
        assert luminance == pytest.approx(level**weight, rel=0.08)
    bright = estimate_illuminant([grey_world_scene(6504.0, 2.0)], [face_mask()]).white
    dim = estimate_illuminant([grey_world_scene(6504.0, 0.5)], [face_mask()]).white
    assert (bright > dim).all()


def test_the_face_does_not_change_the_estimate():
    """Only pixels away from the face count: a darker or lighter skin gives the same light."""
    scene = grey_world_scene(5000.0, 1.0)
    lighter = scene.copy()
    lighter[face_mask()] = [0.9, 0.7, 0.6]
    first, second = (estimate_illuminant([s], [face_mask()]).white for s in (scene, lighter))
    assert first == pytest.approx(second, rel=1e-6)


def test_a_white_backdrop_sets_the_white_level():
    image = np.full((SIZE, SIZE, 3), 0.9) * planckian_rgb(6000.0) / planckian_rgb(6000.0).max()
    image[face_mask()] = [0.3, 0.15, 0.1]
    estimate = estimate_illuminant([linear_to_srgb(image)], [face_mask()])
    assert estimate.source == "white patch" and estimate.cct == pytest.approx(6000.0, rel=0.05)
    assert float(estimate.white.max()) == pytest.approx(0.9 / 0.9, rel=0.05)  # level / white reflectance


def backdrop_with_white_object(share: float, level: float = 1.0) -> np.ndarray:
    """A bright turquoise backdrop (60 % green reflectance: grey world would take the light for 3x stronger)
    with a white object (90 %) covering ``share`` of the scene, under a neutral light of ``level``."""
    image = np.zeros((SIZE, SIZE, 3)) + np.array([0.35, 0.6, 0.55]) * level
    outside_face = np.flatnonzero(~face_mask().ravel())
    image.reshape(-1, 3)[outside_face[: int(round(share * outside_face.size))]] = 0.9 * level
    image[face_mask()] = [0.3, 0.15, 0.1]
    return linear_to_srgb(np.clip(image, 0, 1))


def luminance_of(white: np.ndarray) -> float:
    return float(white @ LUMINANCE)


def test_a_small_white_object_outweighs_a_bright_backdrops_grey_world():
    """A white shirt over 3 % of the scene sets the level; without it the backdrop's grey world overestimates."""
    with_shirt = estimate_illuminant([backdrop_with_white_object(0.03)], [face_mask()])
    without = estimate_illuminant([backdrop_with_white_object(0.0)], [face_mask()])
    assert with_shirt.source == "white patch" and without.source == "grey world"
    assert luminance_of(with_shirt.white) == pytest.approx(1.0, abs=0.05)
    assert luminance_of(without.white) > 1.4


def test_a_white_patch_counts_less_the_smaller_it_is():
    """Its log level is pulled towards the photo's white point (W = 1) by a weight falling with its share, and
    below about 0.8 % of the scene the grey world is the surer."""
    config = IlluminantConfig()
    scene_size = len(_scene_pixels(np.zeros((SIZE, SIZE, 3)), face_mask(), config))
    outside = int((~face_mask()).sum())
    pulls = []
    for share in (0.3, 0.1, 0.04, 0.015):
        estimate = estimate_illuminant([backdrop_with_white_object(share, 0.9)], [face_mask()], config)
        assert estimate.source == "white patch"
        seen = min(round(share * outside) / scene_size, config.white_fraction)  # of the pixels the estimate reads
        sigma = config.white_patch_sigma * math.sqrt(config.white_fraction / seen)
        weight = sigma**-2 / (sigma**-2 + config.exposure_sigma**-2)
        assert luminance_of(estimate.white) == pytest.approx(0.9**weight, rel=0.005)
        # the posterior spread of two independent log-normal readings, narrower than either
        assert estimate.level_sigma == pytest.approx((sigma**-2 + config.exposure_sigma**-2) ** -0.5, rel=1e-6)
        assert estimate.level_sigma < min(sigma, config.exposure_sigma)
        pulls.append(luminance_of(estimate.white))
    assert pulls == sorted(pulls)  # ever nearer 1 as the patch shrinks
    tiny = estimate_illuminant([backdrop_with_white_object(0.006, 0.9)], [face_mask()], config)
    assert tiny.source == "grey world"


def test_a_coloured_wall_is_not_taken_for_a_coloured_light():
    """A green wall lies far off the Planckian locus: the estimate stays near the photo's white point."""
    image = np.zeros((SIZE, SIZE, 3)) + [0.05, 0.3, 0.08]
    estimate = estimate_illuminant([linear_to_srgb(image)], [face_mask()])
    assert estimate.colour_weight < 0.05
    assert estimate.cct == pytest.approx(6504.0, rel=0.05)


def dim_room_behind_black(readable: float) -> np.ndarray:
    """A dim room (grey world level 0.3) of which only ``readable`` of the scene is seen; the rest is a black
    backdrop, too dark to read."""
    image = srgb_to_linear(grey_world_scene(6504.0, 0.3))
    outside = np.flatnonzero(~face_mask().ravel())
    image.reshape(-1, 3)[outside[int(round(readable * outside.size)):]] = 0.002
    return linear_to_srgb(image)


def test_a_scene_mostly_too_dark_to_read_counts_less():
    """The grey world of the few readable pixels is pulled towards the photo's white point the smaller their
    share (its spread grows as 1 / sqrt(share)), reaching the fallback's W = 1 without a jump."""
    config = IlluminantConfig()
    levels, spreads = [], []
    for readable in (1.0, 0.5, 0.2, 0.08):
        image = dim_room_behind_black(readable)
        estimate = estimate_illuminant([image], [face_mask()], config)
        assert estimate.source == "grey world"
        share = len(_readable(image, config)) / len(_scene_pixels(image, face_mask(), config))
        sigma = config.grey_world_sigma / math.sqrt(share)
        weight = sigma**-2 / (sigma**-2 + config.exposure_sigma**-2)
        assert luminance_of(estimate.white) == pytest.approx(0.3**weight, rel=0.03)
        levels.append(luminance_of(estimate.white))
        spreads.append(estimate.level_sigma)
    assert levels == sorted(levels) and levels[-1] > 0.8  # ever nearer the fallback's 1 as less is readable
    assert spreads == sorted(spreads)  # and the less sure
    fallback = estimate_illuminant([dim_room_behind_black(0.02)], [face_mask()], config)
    assert fallback.source == "fallback"
    assert fallback.level_sigma == config.exposure_sigma > spreads[-1]  # the white point alone: the widest


def _readable(image: np.ndarray, config: IlluminantConfig) -> np.ndarray:
    pixels = _scene_pixels(image, face_mask(), config)
    return pixels[srgb_to_linear(pixels) @ LUMINANCE >= config.dark]


def test_too_little_scene_falls_back_to_the_white_point():
    mask = np.ones((SIZE, SIZE), bool)
    estimate = estimate_illuminant([grey_world_scene(3000.0, 2.0)], [mask])
    assert estimate.source == "fallback" and estimate.white == pytest.approx(np.ones(3))


def test_clips_pool_their_frames():
    frames = [grey_world_scene(3500.0, 1.0, seed) for seed in range(3)]
    pooled = estimate_illuminant(frames, [face_mask()] * 3)
    single = estimate_illuminant(frames[:1], [face_mask()])
    assert pooled.cct == pytest.approx(3500.0, rel=0.04)
    assert pooled.scene_pixels == pytest.approx(3 * single.scene_pixels, rel=0.02)


def scene_with_card(cct: float, level: float, card: float = 0.18) -> np.ndarray:
    """grey_world_scene with a card of reflectance ``card`` over its left tenth (the light's level and colour)."""
    image = srgb_to_linear(grey_world_scene(cct, level))
    image[:, : SIZE // 10] = card * level * planckian_rgb(cct)
    return linear_to_srgb(np.clip(image, 0, 1))


@pytest.mark.parametrize(("cct", "level"), [(2700.0, 0.6), (6504.0, 2.5), (9000.0, 0.4)])
def test_a_reference_card_gives_the_lights_level_and_colour(cct, level):
    """A grey card of known reflectance reads W itself, where the scene's grey world is pulled towards the photo's
    white point; the clip's frames pool, and a box given as fractions does not depend on the image's size."""
    config = IlluminantConfig(reference_box=(0.0, 0.2, 0.1, 0.8))
    card = known_illuminant([scene_with_card(cct, level)], config)
    truth = level * planckian_rgb(cct)
    assert card.source == "reference card" and card.white == pytest.approx(truth, rel=0.02)
    assert card.cct == pytest.approx(cct, rel=0.03)
    scene = estimate_illuminant([scene_with_card(cct, level)], [face_mask()])
    assert abs(np.log(luminance_of(card.white) / level)) < abs(np.log(luminance_of(scene.white) / level)) - 0.1
    larger = np.repeat(np.repeat(scene_with_card(cct, level), 3, axis=0), 3, axis=1)
    assert known_illuminant([larger, larger], config).white == pytest.approx(card.white, rel=1e-3)
    white_paper = IlluminantConfig(reference_box=(0.0, 0.2, 0.1, 0.8), reference_reflectance=0.9)
    assert known_illuminant([scene_with_card(cct, level / 5, 0.9)], white_paper).white == pytest.approx(
        truth / 5, rel=0.02)


def test_a_given_white_level_is_used_as_it_is():
    given = known_illuminant([grey_world_scene(6504.0, 1.0)], IlluminantConfig(white=(0.5, 0.6, 0.7)))
    assert given.source == "given" and given.white == pytest.approx([0.5, 0.6, 0.7])
    assert given.cct > 6504.0  # bluer than the white point
    assert given.level_sigma == 0.0 and given.record()["level_sigma"] == 0.0  # the user's W is not doubted
    assert known_illuminant([grey_world_scene(6504.0, 1.0)], IlluminantConfig()) is None


def test_a_clipped_reference_card_is_a_one_line_error():
    """A card brighter than the white point says only that W is at least that much: refused, not guessed."""
    config = IlluminantConfig(reference_box=(0.0, 0.2, 0.1, 0.8), reference_reflectance=0.9)
    with pytest.raises(ValueError, match="clipped or nearly black") as error:
        known_illuminant([scene_with_card(6504.0, 1.5, 0.9)], config)
    assert "\n" not in str(error.value)
    with pytest.raises(ValueError, match="not both"):
        IlluminantConfig(white=(1.0, 1.0, 1.0), reference_box=(0.0, 0.0, 0.5, 0.5))


def test_planckian_colours_round_trip():
    for cct in (2500.0, 3300.0, 5000.0, 6504.0, 10000.0):
        found, weight = plausible_cct(planckian_rgb(cct), IlluminantConfig())
        assert found == pytest.approx(cct, rel=1e-3) and weight == pytest.approx(1.0)
    assert planckian_rgb(6504.0) == pytest.approx(np.ones(3), abs=1e-6)


def test_white_response_is_the_cosine_weighted_radiance_over_pi():
    """Monte Carlo: W(n) = (1/pi) * integral of L(w) max(n.w, 0) dw for a random band-limited light."""
    torch.manual_seed(0)
    lights = torch.randn(1, 9, 3, dtype=torch.float64) * 0.3
    lights[0, 0] += 2.0
    normal = torch.tensor([[0.3, -0.2, 0.93]], dtype=torch.float64)
    normal = normal / normal.norm()
    directions = torch.randn(400_000, 3, dtype=torch.float64)
    directions = directions / directions.norm(dim=1, keepdim=True)
    radiance = sh_basis(directions, 3) @ lights[0]  # [N, 3]
    cosine = (directions @ normal[0]).clamp_min(0)[:, None]
    monte_carlo = 4 * math.pi * (radiance * cosine).mean(0) / math.pi
    assert white_response(lights, normal)[0, 0].numpy() == pytest.approx(monte_carlo.numpy(), rel=0.01)


def test_white_light_shows_the_albedo_facing_the_viewer():
    light = white_light(9)
    facing = white_response(light, torch.tensor([[0.0, 0.0, 1.0]]))[0, 0]
    sideways = white_response(light, torch.tensor([[1.0, 0.0, 0.0]]))[0, 0]
    assert facing.numpy() == pytest.approx(np.ones(3), abs=1e-5)
    assert sideways.numpy() == pytest.approx(np.full(3, 0.7), abs=1e-5)


def test_terms_vanish_at_the_estimate_and_pull_towards_it():
    white = torch.tensor([1.2, 1.0, 0.7])
    lights = white_light(3) * white  # its peak white response is `white`, facing the viewer
    directions = front_directions()
    assert peak_white(lights, directions)[0].numpy() == pytest.approx(white.numpy(), rel=1e-3)
    assert float(light_colour_term(lights, white, directions)) == pytest.approx(0.0, abs=1e-8)
    bluish = (lights * torch.tensor([0.8, 1.0, 1.3])).requires_grad_(True)
    term = light_colour_term(bluish, white, directions)
    term.backward()
    assert float(term.detach()) > 0 and float(bluish.grad[0, 0, 2]) > 0  # less blue lowers the term
    normals = torch.zeros(4, 4, 3)
    normals[..., 2] = 1.0
    region = torch.ones(4, 4, dtype=torch.bool)
    level = key_light_level(lights, normals, region)
    assert float(level) == pytest.approx(float(white @ torch.tensor([0.2126, 0.7152, 0.0722])), rel=1e-4)
    assert float(exposure_term(level, float(level))) == pytest.approx(0.0, abs=1e-10)
    assert float(exposure_term(level * 2, float(level))) == pytest.approx(math.log(2) ** 2, rel=1e-3)


def test_colour_spread_is_zero_for_one_colour_and_grows_with_a_tinted_lobe():
    """One colour in every direction costs nothing whatever its level; a light bluer to one side costs, and
    a gradient step on the spread makes its colour more uniform."""
    directions = front_directions()
    warm = white_light(3) * torch.tensor([1.2, 1.0, 0.7])
    assert float(colour_spread(warm, directions)) == pytest.approx(0.0, abs=1e-8)
    assert float(colour_spread(warm * 3.0, directions)) == pytest.approx(0.0, abs=1e-8)
    tinted = warm.clone()
    tinted[0, 1:3, 2] += 0.4  # blue on two of the linear (l = 1) terms: bluer towards one side
    spread = colour_spread(tinted, directions)
    assert float(spread) > 1e-3
    assert float(colour_spread(tinted * 2.0, directions)) == pytest.approx(float(spread), rel=1e-4)  # level-free
    lights = tinted.clone().requires_grad_(True)
    colour_spread(lights, directions).backward()
    stepped = (lights - 0.05 * lights.grad).detach()
    assert float(colour_spread(stepped, directions)) < float(spread)


def test_negative_share_is_the_negative_part_of_the_radiance():
    """0 for a physical light at any level, 1 for one negative everywhere, a Monte Carlo estimate over random
    directions for a light with a negative lobe; a gradient step lowers it."""
    light = white_light(5) * torch.tensor([1.2, 1.0, 0.7])
    assert float(negative_share(light)[0]) == pytest.approx(0.0, abs=1e-8)
    assert float(negative_share(-light)[0]) == pytest.approx(1.0, abs=1e-6)
    lobed = light.clone()
    lobed[0, 1:4] -= 2.0 * light[0, 0] * torch.tensor([1.0, 0.5, 0.7])[:, None]  # l = 1 lobes beyond the ambient
    directions = torch.nn.functional.normalize(torch.randn(200_000, 3, generator=torch.Generator().manual_seed(0),
                                                           dtype=torch.float64), dim=-1)
    values = torch.einsum("nj,kjc->knc", sh_basis(directions, 5), lobed.double())
    expected = (values.clamp_max(0).pow(2).mean(1) / values.pow(2).mean(1)).mean()
    share = negative_share(lobed)[0]
    assert 0.05 < float(share) < 0.95
    assert float(share) == pytest.approx(float(expected), rel=0.02)
    assert float(negative_share(lobed * 4.0)[0]) == pytest.approx(float(share), rel=1e-5)  # level-free
    lights = lobed.clone().requires_grad_(True)
    negative_share(lights).sum().backward()
    assert float(negative_share((lights - 0.05 * lights.grad).detach())[0]) < float(share)


def test_the_negative_radiance_loss_allows_a_sharp_lights_ringing():
    """A 14-degree lobe (cos^32) fitted by 9 SH bands rings below 0 and costs nothing; a light mostly negative
    costs its share beyond the ringing."""
    directions = torch.as_tensor(fibonacci_sphere(4096))
    lobe = (directions[:, 2].clamp_min(0) ** 32)[:, None].repeat(1, 3)
    sharp = torch.linalg.lstsq(sh_basis(directions, 9), lobe).solution[None].float()
    assert 0.0 < float(negative_share(sharp)[0]) <= RINGING_SHARE
    assert float(negative_radiance_loss(sharp)) == 0.0
    mostly_negative = -sharp
    share = float(negative_share(mostly_negative)[0])
    assert share > 0.5
    loss = negative_radiance_loss(torch.cat([sharp, mostly_negative]))
    assert float(loss) == pytest.approx((share - RINGING_SHARE) / 2, rel=1e-5)


def test_the_level_prior_can_read_the_light_the_renderer_renders():
    """A fitted SH light may have a negative lobe, which the renderer clamps (render.non_negative_lights). With
    ``tone.level_as_rendered`` the level term holds the light as rendered: its level facing the camera is the
    irradiance of the clamped radiance (a Monte Carlo integral here); the raw SH, which the default holds, reads far
    less (a fit can hold the raw SH at W and render a light twice as bright)."""
    from types import SimpleNamespace

    from deface.fit import rendering
    from deface.fit.config import ToneConfig
    from deface.losses.illuminant import exposure_term
    from deface.render.renderer import RenderConfig, Renderer

    light = torch.zeros(1, 81, 3)
    light[0, 0] = 20.0
    light[0, 2] = -20.0  # radiance 20 (0.28 - 0.49 z): negative towards the camera
    rng = np.random.default_rng(0)
    directions = rng.normal(size=(400_000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    radiance = 20.0 * np.maximum(0.5 / math.sqrt(math.pi) - math.sqrt(3 / (4 * math.pi)) * directions[:, 2], 0.0)
    # E(+z) / pi = (1 / pi) * integral of L max(cos, 0) over the sphere = 4 * mean(L max(z, 0))
    rendered_level = 4.0 * float(np.mean(radiance * np.maximum(directions[:, 2], 0.0)))

    def level_term(as_rendered: bool, white: float) -> float:
        tone = ToneConfig(level_as_rendered=as_rendered)
        context = SimpleNamespace(
            config=SimpleNamespace(tone=tone), renderer=Renderer(RenderConfig()),
            kept_lights=light, decoupling=SimpleNamespace(frame_lights=lambda frame: torch.ones(1, dtype=torch.bool)),
            inputs=SimpleNamespace(scene_light=SimpleNamespace(
                regions=[torch.ones(4, 4, dtype=torch.bool)], illuminants=[SimpleNamespace(white=np.full(3, white))])))
        rendered = SimpleNamespace(normals=torch.tensor([0.0, 0.0, 1.0]).expand(4, 4, 3))
        return float(rendering.scene_light_level(context, 0, rendered))

    expected = ToneConfig().weight * float(exposure_term(torch.tensor(rendered_level), 0.4)) / 0.1**2
    assert level_term(True, 0.4) == pytest.approx(expected, rel=0.1, abs=1e-3)
    assert level_term(True, rendered_level) < 0.01  # held where the rendered light is
    assert level_term(False, rendered_level) > 1.0  # the raw SH's level is far below it


def test_the_colour_prior_can_read_the_light_the_renderer_renders():
    """A light neutral at its raw SH peak can render coloured: here green and blue have a negative lobe towards the
    camera, which the renderer clamps, so the face facing the camera gets more green and blue than red. The raw
    colour term sees a white light; with ``tone.colour_as_rendered`` the term sees the cyan one, and the colour
    spread over directions reads the same light."""
    from types import SimpleNamespace

    from deface.fit import rendering
    from deface.fit.config import ToneConfig
    from deface.render.renderer import RenderConfig, Renderer

    light = torch.zeros(1, 81, 3)
    light[0, 0] = 20.0
    light[0, 2, 1:] = -20.0  # green and blue: radiance 20 (0.28 - 0.49 z), negative towards the camera

    def context(as_rendered: bool, spread: float = 0.0):
        return SimpleNamespace(
            config=SimpleNamespace(tone=ToneConfig(colour_as_rendered=as_rendered),
                                   weights=SimpleNamespace(light_colour_spread=spread)),
            renderer=Renderer(RenderConfig()), kept_lights=light, target=SimpleNamespace(num_frames=1),
            decoupling=SimpleNamespace(light_groups=None, frame_lights=lambda frame: torch.ones(1, dtype=torch.bool)),
            inputs=SimpleNamespace(scene_light=SimpleNamespace(illuminants=[SimpleNamespace(white=np.ones(3))])))

    raw, rendered = (float(rendering.scene_light_colour(context(as_rendered))) for as_rendered in (False, True))
    assert raw < 0.01  # neutral at the raw peak (grazing normals)
    assert rendered > 0.2  # its peak's chroma 2-3 % off white (the term is 1 at the prior's sigma, 5 %)
    from deface.losses.illuminant import colour_spread, front_directions

    for as_rendered in (False, True):
        read = Renderer(RenderConfig()).rendered_lights(light) if as_rendered else light
        assert float(rendering.light_colour_spread(context(as_rendered, 1.0))) == pytest.approx(
            float(colour_spread(read, front_directions())), rel=1e-6)
