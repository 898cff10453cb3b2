"""The known light as an input (docs/skin-tone.md "When the light is known"): ``deface fit --card``, ``--white``,
``--checker``, and the colour checker found in a photo, on synthetic images of known light."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from deface.cli.main import app
from deface.fit.user_options import UsageError, fit_config
from deface.io.images import LUMINANCE, linear_to_srgb, srgb_to_linear
from deface.priors import checker
from deface.priors.illuminant import IlluminantConfig, known_illuminant, planckian_rgb

LIGHT = 0.85 * planckian_rgb(4500.0)


def chart_texture(swatch: int = 30, gap: int = 6) -> np.ndarray:
    """The ColorChecker's 24 patches (linear sRGB reflectances from colour-science's reference, adapted to D65)
    on a black frame, 6 x 4."""
    import colour

    reference = colour.CCS_COLOURCHECKERS["ColorChecker24 - After November 2014"]
    xyz = colour.xyY_to_XYZ(np.array(list(reference.data.values())))
    rgb = np.clip(colour.XYZ_to_RGB(xyz, colour.RGB_COLOURSPACES["sRGB"], reference.illuminant,
                                    chromatic_adaptation_transform="Bradford"), 0, 1)
    texture = np.full((4 * swatch + 5 * gap, 6 * swatch + 7 * gap, 3), 0.01)
    for index, value in enumerate(rgb):
        row, column = divmod(index, 6)
        texture[gap + row * (swatch + gap):][:swatch, gap + column * (swatch + gap):][:, :swatch] = value
    return texture


def photo_with_chart(light: np.ndarray, chart: bool = True, size: int = 384) -> np.ndarray:
    """A mid-grey room under ``light`` (linear RGB, the white level) with a chart, seen a little askew, at its
    lower right; sRGB."""
    import cv2

    image = np.zeros((size, size, 3)) + 0.2
    if chart:
        texture = chart_texture()
        height, width = texture.shape[:2]
        source = np.float32([[0, 0], [width, 0], [width, height], [0, height]])
        target = np.float32([[220, 240], [350, 244], [348, 330], [222, 326]])
        warp = cv2.getPerspectiveTransform(source, target)
        warped = cv2.warpPerspective(texture.astype(np.float32), warp, (size, size))
        inside = cv2.warpPerspective(np.ones((height, width), np.float32), warp, (size, size))[..., None]
        image = image * (1 - inside) + warped * inside
    return linear_to_srgb(np.clip(image * light, 0, 1))


needs_detector = pytest.mark.skipif(not checker.available(), reason="colour-checker-detection not installed")


@needs_detector
def test_a_colour_checker_gives_the_lights_level_and_colour():
    reading = checker.find_checker(photo_with_chart(LIGHT))
    assert reading is not None and reading.greys_used >= 3
    assert reading.white == pytest.approx(LIGHT, rel=0.04)
    left, top, right, bottom = reading.box
    assert left == pytest.approx(220 / 384, abs=0.02) and bottom == pytest.approx(330 / 384, abs=0.02)


@pytest.mark.slow
@needs_detector
def test_no_chart_and_a_blown_out_chart_give_nothing():
    assert checker.find_checker(photo_with_chart(LIGHT, chart=False)) is None
    assert checker.find_checker(photo_with_chart(3.0 * LIGHT)) is None  # its bright greys clipped: W >= so much


def test_a_grey_row_that_is_not_a_neutral_ramp_is_not_a_chart():
    """A detection whose greys are not one colour, or not one level over the chart's reflectances, is refused."""
    greys = checker.grey_reflectances()[:, None] * LIGHT
    swatches = np.full((24, 3), 0.3)
    swatches[checker.GREY_PATCHES] = linear_to_srgb(greys)
    corners = np.array([[10.0, 10.0], [50.0, 10.0], [50.0, 40.0], [10.0, 40.0]])
    found = checker.read_checker(swatches, corners, 100, 100)
    assert found is not None and found.white == pytest.approx(LIGHT, rel=0.02)
    tinted = swatches.copy()
    tinted[19] = linear_to_srgb(greys[1] * [1.3, 1.0, 0.8])
    assert checker.read_checker(tinted, corners, 100, 100) is None
    flat = swatches.copy()
    flat[checker.GREY_PATCHES] = linear_to_srgb(np.full((6, 3), 0.3) * LIGHT)  # a uniform grey card's tiles
    assert checker.read_checker(flat, corners, 100, 100) is None


def test_without_the_package_the_checker_says_it_is_unavailable(monkeypatch):
    import builtins

    real_import = builtins.__import__

    def without_detector(name, *args, **kwargs):
        if name.startswith("colour_checker_detection"):
            raise ImportError(name)
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", without_detector)
    assert not checker.available()
    with pytest.raises(checker.CheckerUnavailable, match="colour-checker-detection is not installed"):
        checker.find_checker(photo_with_chart(LIGHT))


def test_a_card_box_in_pixels_reads_as_its_fractions():
    """``--card`` takes pixels of the input image as well as fractions; a fit's working frame is a scaled copy."""
    image = srgb_to_linear(photo_with_chart(LIGHT, chart=False))
    image[40:80, 30:90] = 0.18 * LIGHT  # the card
    srgb = linear_to_srgb(image)
    fractions = known_illuminant([srgb], IlluminantConfig(reference_box=(30 / 384, 40 / 384, 90 / 384, 80 / 384)))
    working = srgb[::2, ::2]  # the fit's frame at half the input's size
    pixels = known_illuminant([working], IlluminantConfig(reference_box=(30, 40, 90, 80)), scale=0.5)
    assert fractions.white == pytest.approx(LIGHT, rel=0.02)
    assert pixels.white == pytest.approx(fractions.white, rel=0.01)
    assert pixels.source == "reference card" and "18 %" in pixels.detail
    with pytest.raises(ValueError, match="beyond the 384 x 384 image") as error:
        known_illuminant([working], IlluminantConfig(reference_box=(300, 300, 500, 400)), scale=0.5)
    assert "\n" not in str(error.value)


def test_card_options_map_to_the_settings():
    config = fit_config(card="0.1,0.2,0.3,0.4", card_reflectance=0.9, card_facing="light", checker="off")
    settings = config.tone.illuminant
    assert settings.reference_box == (0.1, 0.2, 0.3, 0.4) and settings.reference_reflectance == 0.9
    assert settings.reference_facing == "light" and settings.checker == "off"
    assert fit_config(white="0.8,0.7,0.6").tone.illuminant.white == (0.8, 0.7, 0.6)
    # --set still comes last
    assert fit_config(card="0.1,0.2,0.3,0.4", sets=["tone.illuminant.reference_reflectance=0.5"]
                      ).tone.illuminant.reference_reflectance == 0.5


def test_white_reuses_a_finished_fits_level(tmp_path):
    """A batch under one setup: W from the fit of one photo with a card applies to the rest."""
    run = tmp_path / "card_photo"
    run.mkdir()
    recorded = {"illuminant": {"white": [0.91, 0.8, 0.62], "source": "reference card"}}
    (run / "params.json").write_text(json.dumps(recorded))
    assert fit_config(white=str(run)).tone.illuminant.white == pytest.approx((0.91, 0.8, 0.62))
    assert fit_config(white=str(run / "params.json")).tone.illuminant.white == pytest.approx((0.91, 0.8, 0.62))
    (tmp_path / "no_light").mkdir()
    (tmp_path / "no_light" / "params.json").write_text(json.dumps({"illuminant": None}))
    with pytest.raises(UsageError, match="not a finished fit with a white level"):
        fit_config(white=str(tmp_path / "no_light"))


@pytest.mark.parametrize(("options", "message"), [
    (["--card", "0.5,0.2,0.3,0.4"], "--card: tone.illuminant.reference_box"),
    (["--card", "0.1,0.2,0.3"], "--card: tone.illuminant.reference_box takes 4"),
    (["--card", "0.1,0.2,0.3,0.4", "--white", "1,1,1"], "not both"),
    (["--card-reflectance", "1.5"], "reference_reflectance must be in (0, 1]"),
    (["--card-facing", "sideways"], "--card-facing"),
    (["--checker", "maybe"], "--checker"),
    (["--white", "1,1"], "--white: tone.illuminant.white takes 3"),
])
def test_bad_light_options_are_one_line_usage_errors(tmp_path, options, message):
    photo = tmp_path / "photo.png"
    photo.write_bytes(b"")
    result = CliRunner().invoke(app, ["fit", str(photo), "-o", str(tmp_path / "out"), *options],
                                env={"COLUMNS": "200"})
    assert result.exit_code == 2, result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and message in lines[0], result.output


def test_fit_help_shows_the_card_options():
    result = CliRunner().invoke(app, ["fit", "--help"], env={"COLUMNS": "200"})
    for option in ("--card", "--card-reflectance", "--card-facing", "--white", "--checker"):
        assert option in result.output


def test_the_light_level_is_read_where_the_log_says():
    """The estimate's record names its source and how it was read (params.json's illuminant)."""
    image = srgb_to_linear(photo_with_chart(LIGHT, chart=False))
    image[40:80, 30:90] = 0.18 * LIGHT
    card = known_illuminant([linear_to_srgb(image)], IlluminantConfig(reference_box=(30, 40, 90, 80)))
    record = card.facing_corrected(1.2).record()
    assert record["source"] == "reference card" and record["orientation"] == pytest.approx(1.2)
    assert "x1.20 for facing the camera" in record["detail"]
    assert float(np.asarray(record["white"]) @ LUMINANCE) == pytest.approx(1.2 * float(LIGHT @ LUMINANCE), rel=0.03)
