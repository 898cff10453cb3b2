"""The diffuse map's chroma guided by its luminance (deface/texture/chroma.py), by its properties: what two lights
of different colours leave at a mask edge and per-texel colour noise go; a mole's luminance and its own chroma stay;
the luminance is never changed."""

from __future__ import annotations

import numpy as np
import pytest

from deface.eval.albedo_measures import colour_noise
from deface.io.images import LUMINANCE
from deface.texture.chroma import ChromaConfig, filter_chroma, skin_chroma_gain, texels_per_pixel

SIZE = 256
SKIN = np.array([0.55, 0.38, 0.30])


def _skin(seed: int = 0, noise: float = 0.0) -> np.ndarray:
    """A smooth skin albedo with a slow tone gradient and, optionally, per-texel colour noise at a fixed luminance."""
    rng = np.random.default_rng(seed)
    v = np.linspace(0.9, 1.1, SIZE)[:, None, None]
    albedo = np.broadcast_to(SKIN * v, (SIZE, SIZE, 3)).copy()
    if noise:
        albedo *= np.exp(noise * rng.standard_normal((SIZE, SIZE, 3)))
    return albedo


def _chroma(image: np.ndarray) -> np.ndarray:
    """log(R/G), log(B/G) per texel."""
    logs = np.log(image)
    return np.stack([logs[..., 0] - logs[..., 1], logs[..., 2] - logs[..., 1]], -1)


def _lights_edge(albedo: np.ndarray) -> np.ndarray:
    """The map a fit leaves where a warm and a cool light meet at a sharp mask edge with the same luminance: each
    side tinted by its light's colour relative to the other."""
    warm, cool = np.array([1.06, 1.0, 0.90]), np.array([0.94, 1.0, 1.12])
    tinted = albedo.copy()
    tinted[:, : SIZE // 2] *= warm
    tinted[:, SIZE // 2:] *= cool
    y = albedo @ LUMINANCE
    return tinted * (y / (tinted @ LUMINANCE))[..., None]


def _mole(albedo: np.ndarray, radius: int = 6) -> tuple[np.ndarray, np.ndarray]:
    rows, cols = np.indices((SIZE, SIZE))
    inside = (rows - 100) ** 2 + (cols - 90) ** 2 <= radius ** 2
    mole = albedo.copy()
    mole[inside] *= np.array([0.45, 0.36, 0.30])  # darker and slightly browner than the skin
    return mole, inside


@pytest.mark.parametrize("radius", [0.008, 0.03])
def test_a_chroma_step_at_a_mask_edge_across_even_skin_becomes_a_ramp(radius):
    """The two lights' colours still differ (the filter does not know which is right), but no texel-to-texel step
    is left: the step is spread over the window, its steepest slope at most the step over the window's side."""
    seen = np.ones((SIZE, SIZE))
    stepped = _lights_edge(_skin())
    out = filter_chroma(stepped, seen, ChromaConfig(radius=radius))
    step = np.abs(np.diff(_chroma(stepped), axis=1)).max()
    side = 2 * round(radius * SIZE) + 1
    assert step > 0.2
    assert np.abs(np.diff(_chroma(out), axis=1)).max() <= 1.05 * step / side
    np.testing.assert_allclose(out @ LUMINANCE, stepped @ LUMINANCE, rtol=1e-6)


def test_per_texel_colour_noise_goes_and_the_luminance_is_kept():
    noisy = _skin(noise=0.04)
    seen = np.ones((SIZE, SIZE))
    out = filter_chroma(noisy, seen, ChromaConfig())
    region = np.ones((SIZE, SIZE), bool)
    assert colour_noise(out, region) < 0.3 * colour_noise(noisy, region)
    np.testing.assert_allclose(out @ LUMINANCE, noisy @ LUMINANCE, rtol=1e-6)


@pytest.mark.parametrize("noise", [0.0, 0.03])
def test_a_mole_keeps_its_darkness_and_its_own_chroma(noise):
    skin = _skin(seed=1, noise=noise)
    mole, inside = _mole(skin)
    out = filter_chroma(mole, np.ones((SIZE, SIZE)), ChromaConfig())
    core = inside & (np.hypot(*np.indices((SIZE, SIZE)) - np.array([100, 90])[:, None, None]) <= 3)
    truth = _chroma(_mole(_skin(seed=1))[0])[core].mean(0)
    kept = _chroma(out)[core].mean(0)
    assert np.abs(kept - truth).max() < 0.03  # the mole's brown, within 3 % of a channel ratio
    np.testing.assert_allclose(out @ LUMINANCE, mole @ LUMINANCE, rtol=1e-6)


def test_texels_no_photo_saw_do_not_bleed_into_seen_ones():
    seen = np.ones((SIZE, SIZE))
    seen[:, : SIZE // 2] = 0.0
    albedo = _skin()
    albedo[:, : SIZE // 2] = np.array([0.2, 0.5, 0.2])  # green garbage where nothing was seen
    out = filter_chroma(albedo, seen, ChromaConfig(radius=0.03))
    right = slice(SIZE // 2, None)
    np.testing.assert_allclose(_chroma(out)[:, right], _chroma(albedo)[:, right], atol=2e-3)


def test_a_constant_map_is_a_fixed_point():
    flat = np.broadcast_to(SKIN, (SIZE, SIZE, 3)).copy()
    np.testing.assert_allclose(filter_chroma(flat, np.ones((SIZE, SIZE)), ChromaConfig()), flat, rtol=1e-9)


def _pixel_noise(texels_a_pixel: int, seed: int = 2) -> np.ndarray:
    """Skin whose colour noise comes from a photo with fewer pixels than the map has texels: one random chroma per
    photo pixel, spread over its ``texels_a_pixel``² texels (the map's luminance stays smooth)."""
    rng = np.random.default_rng(seed)
    cells = -(-SIZE // texels_a_pixel)
    noise = np.kron(rng.standard_normal((cells, cells, 3)), np.ones((texels_a_pixel, texels_a_pixel, 1)))[:SIZE, :SIZE]
    albedo = _skin() * np.exp(0.04 * noise)
    return albedo * (_skin() @ LUMINANCE / (albedo @ LUMINANCE))[..., None]


def test_the_window_grows_to_the_photos_pixels_where_the_map_has_more_texels_than_the_photo():
    """Colour noise one photo pixel wide, at 3 texels a pixel, survives a window of 2 texels but not one of two
    pixels; the luminance is kept either way."""
    noisy, seen, region = _pixel_noise(3), np.ones((SIZE, SIZE)), np.ones((SIZE, SIZE), bool)
    config = ChromaConfig(radius=2 / SIZE, pixels=2.0)
    texel_window = filter_chroma(noisy, seen, config)
    pixel_window = filter_chroma(noisy, seen, config, texels_a_pixel=3.0)
    assert colour_noise(pixel_window, region) < 0.5 * colour_noise(texel_window, region)
    np.testing.assert_allclose(pixel_window @ LUMINANCE, noisy @ LUMINANCE, rtol=1e-6)


def test_where_a_pixel_spans_fewer_texels_than_the_window_the_map_is_as_before():
    noisy, seen = _pixel_noise(2), np.ones((SIZE, SIZE))
    config = ChromaConfig()  # 2 texels at 256²: more than 2 pixels of half a texel
    np.testing.assert_array_equal(filter_chroma(noisy, seen, config, texels_a_pixel=0.5),
                                  filter_chroma(noisy, seen, config))


def test_texels_per_pixel_reads_the_seen_texels_density():
    """A pixel per 4 texels (area) is 2 texels across; texels seen less than half squarely do not count."""
    density, weight = np.full((8, 8), 0.25), np.ones((8, 8))
    density[:, :2], weight[:, :2] = 0.01, 0.2
    assert texels_per_pixel(density, weight) == pytest.approx(2.0)
    assert texels_per_pixel(density, np.zeros((8, 8))) == 0.0


def test_the_skin_chroma_gain_gives_the_skin_the_readings_chroma_and_keeps_everything_else():
    """The map's median skin takes the reading's chroma at its own luminance; every texel is scaled by the same
    gain, so each texel's chroma relative to the skin (a mole, a brow) and the skin's luminance are kept."""
    albedo, mole = _mole(_skin(seed=3, noise=0.02))
    reading = np.array([0.62, 0.36, 0.22])  # a warmer skin than the map's, at another level
    everywhere = np.ones(albedo.shape[:2], bool)
    gain = skin_chroma_gain(albedo, everywhere, reading)
    matched = albedo * gain
    median, after = np.median(albedo.reshape(-1, 3), 0), np.median(matched.reshape(-1, 3), 0)
    np.testing.assert_allclose(_chroma(after[None, None])[0, 0], _chroma(reading[None, None])[0, 0], atol=0.02)
    assert after @ LUMINANCE == pytest.approx(median @ LUMINANCE, rel=0.02)
    relative = _chroma(albedo) - _chroma(albedo).mean((0, 1))
    np.testing.assert_allclose(_chroma(matched) - _chroma(matched).mean((0, 1)), relative, atol=1e-9)
    assert skin_chroma_gain(albedo, np.zeros_like(everywhere), reading) is None  # no skin seen: no reading
    assert mole.any()
