"""A colour checker in the photo, found automatically: its grey patches of known reflectance give the white level W
(docs/skin-tone.md "When the light is known").

Detection is colour-checker-detection's segmentation detector (the colour-science project; the ``checker`` extra,
installed without its opencv-python and OpenImageIO requirements: deface uses opencv-python-headless and passes
arrays). It finds X-Rite ColorChecker Classic-layout charts (24 patches, 6 x 4; the Passport and Nano share it).
A detection counts only when its last row reads as the chart's neutral ramp: the six grey patches (white 9.5 to
black 2) of the reference reflectances (``colour.CCS_COLOURCHECKERS``, ColorChecker24 after November 2014) must
share one colour and one level over reflectance, within ``NEUTRAL_TOLERANCE`` and ``LEVEL_TOLERANCE`` (log), over
the bright patches (``MIN_REFLECTANCE``) that are not clipped; a face, a shirt's pattern or a tiled wall taken for a
chart does not pass. W is the median of those patches' linear colour over their reflectance, corrected for the
chart's facing the camera as a card's reading is (deface/fit/scene_light.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from deface.io.images import LUMINANCE, srgb_to_linear
from deface.priors.illuminant import IlluminantConfig, IlluminantEstimate, cct_of

GREY_PATCHES = slice(18, 24)
"""The chart's neutral row in the detector's order (white, neutral 8, 6.5, 5, 3.5, black)."""
NEUTRAL_TOLERANCE = 0.08
"""Largest log difference of a grey patch's red/green and blue/green from the grey row's median."""
LEVEL_TOLERANCE = 0.12
"""Largest log difference of a grey patch's level over its reflectance from the row's median."""
MIN_GREYS = 3
"""Fewest readable grey patches (not clipped, not nearly black) for a reading."""
MIN_REFLECTANCE = 0.15
"""Only the grey patches at least this reflective are read (white, neutral 8, 6.5, 5): a lens's flare and a
detector's sampling near the patch's edges lift the dark ones (neutral 3.5 and black read 12-25 % high on a
synthetic chart), the level of the bright ones is the light's."""
CLIPPED = 0.98
DARK = 0.01


class CheckerUnavailable(RuntimeError):
    """colour-checker-detection is not installed (the ``checker`` extra)."""


@dataclass(frozen=True)
class CheckerReading:
    """A colour checker found in a photo: W from its grey patches, and where it is."""

    white: np.ndarray  # [3] linear RGB a white surface facing the light as the chart faces shows
    box: tuple[float, float, float, float]  # left, top, right, bottom as fractions of the image
    greys_used: int  # grey patches read (not clipped, not black)
    spread: float  # largest log difference of a used patch's level over reflectance from their median


def grey_reflectances() -> np.ndarray:
    """[6] luminance reflectance of the ColorChecker's grey row (white 9.5 ... black 2), from colour-science's
    reference values."""
    import colour

    chart = colour.CCS_COLOURCHECKERS["ColorChecker24 - After November 2014"]
    xyy = np.array(list(chart.data.values()))[GREY_PATCHES]
    return xyy[:, 2]


def detector():
    """colour-checker-detection's segmentation detector, or CheckerUnavailable naming the extra."""
    try:
        from colour_checker_detection import detect_colour_checkers_segmentation
    except ImportError as error:
        raise CheckerUnavailable("colour checker detection is unavailable: colour-checker-detection is not installed "
                                 "(pip install --no-deps colour-checker-detection==0.2.3; scripts/setup.sh does)"
                                 ) from error
    return detect_colour_checkers_segmentation


def available() -> bool:
    """Whether colour-checker-detection can be imported."""
    try:
        detector()
    except CheckerUnavailable:
        return False
    return True


def find_checker(frame_srgb: np.ndarray) -> CheckerReading | None:
    """The colour checker in ``frame_srgb`` [H, W, 3] (sRGB in [0, 1]) whose grey row reads as a neutral ramp of
    the known reflectances, or None; CheckerUnavailable without the package."""
    detect = detector()
    image = np.ascontiguousarray(np.clip(frame_srgb, 0, 1), dtype=np.float32)
    try:
        found = detect(image, additional_data=True, apply_cctf_decoding=False)
    except (ValueError, IndexError, ZeroDivisionError):  # the detector's own failures on charts it half sees
        return None
    height, width = image.shape[:2]
    scale = width / _working_width(width)
    readings = [reading for data in found
                if (reading := read_checker(np.asarray(data.swatch_colours), data.quadrilateral * scale, width,
                                            height)) is not None]
    return min(readings, key=lambda r: r.spread) if readings else None


def _working_width(width: int) -> int:
    """The width the detector resizes images to (its ``working_width`` setting)."""
    from colour_checker_detection.detection.segmentation import SETTINGS_SEGMENTATION_COLORCHECKER_CLASSIC

    return int(SETTINGS_SEGMENTATION_COLORCHECKER_CLASSIC["working_width"])


def read_checker(swatches_srgb: np.ndarray, corners: np.ndarray, width: int, height: int) -> CheckerReading | None:
    """W from a detected chart's 24 swatch colours [24, 3] (sRGB means) and its corners [4, 2] (pixels of a
    ``width`` x ``height`` image), or None when its grey row is not a neutral ramp of the known reflectances."""
    if swatches_srgb.shape != (24, 3):
        return None
    greys_srgb = swatches_srgb[GREY_PATCHES]
    greys = srgb_to_linear(np.clip(greys_srgb, 0, 1))
    readable = (greys_srgb.max(-1) < CLIPPED) & (greys @ LUMINANCE > DARK) & (grey_reflectances() >= MIN_REFLECTANCE)
    if readable.sum() < MIN_GREYS:
        return None
    greys, reflectance = greys[readable], grey_reflectances()[readable]
    log_ratios = np.log(np.maximum(greys, 1e-6)) - np.log(np.maximum(greys[:, 1:2], 1e-6))
    if np.abs(log_ratios - np.median(log_ratios, axis=0)).max() > NEUTRAL_TOLERANCE:
        return None
    levels = np.log(greys @ LUMINANCE / reflectance)
    spread = float(np.abs(levels - np.median(levels)).max())
    if spread > LEVEL_TOLERANCE:
        return None
    white = np.median(greys / reflectance[:, None], axis=0)
    xs, ys = corners[:, 0] / width, corners[:, 1] / height
    box = (float(xs.min()), float(ys.min()), float(xs.max()), float(ys.max()))
    return CheckerReading(white.astype(np.float64), tuple(round(v, 4) for v in np.clip(box, 0, 1)),
                          int(readable.sum()), spread)


def checker_illuminant(reading: CheckerReading, config: IlluminantConfig) -> IlluminantEstimate:
    """The white level a found chart gives (not yet corrected for how it faces: deface/fit/scene_light.py)."""
    box = ",".join(f"{v:.2f}" for v in reading.box)
    return IlluminantEstimate(reading.white, cct_of(reading.white, config), "colour checker", 1.0, 0,
                              config.reference_sigma, detail=f"a colour checker at {box} ({reading.greys_used} grey "
                                                             "patches)")
