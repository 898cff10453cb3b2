"""The offline occluder finder (deface/priors/occluders.py) and what h does with it: a thin dark ring around the
eyes and a strand over the forehead leave the face region (where they are not on a feature: a rim over a brow
stays with the brow), a mole of the same darkness stays."""

from __future__ import annotations

import re

import cv2
import numpy as np
import pytest

from deface.priors.face_region import (
    MEDIAPIPE_FEATURES,
    SkinClassifierConfig,
    SkinColourClassifier,
    _hull_mask,
    feature_mask_from_landmarks,
)
from deface.priors.occluders import OccluderConfig, darkness, disk, thin_structures


def test_darkness_is_the_log_ratio_to_the_surroundings_on_thin_lines_only():
    luma = np.full((60, 60), 0.5, np.float32)
    luma[30:32, 5:55] = 0.15  # a line two pixels wide, 0.3 of its surroundings
    luma[5:25, 5:25] = 0.15  # a patch wider than the closing's disk
    dark = darkness(luma, radius=3)
    assert dark[30:32, 10:50] == pytest.approx(np.log(1 / 0.3), rel=1e-4)
    assert dark[8:22, 8:22].max() < 1e-5  # the closing does not reach across a wide patch's body
    assert np.abs(dark[40:, :]).max() < 1e-6


def test_thin_structures_keeps_long_thin_parts_by_their_skeleton():
    mask = np.zeros((80, 80), bool)
    mask[10:12, 5:75] = True  # a strand: 70 long, 2 wide
    mask[40:46, 40:46] = True  # a mole: compact
    mask[55:75, 5:15] = True  # a patch: 20 long but 10 wide
    cv2.circle(ring := np.zeros((80, 80), np.uint8), (50, 62), 12, 1, 2)  # a rim: short across, long around
    mask |= ring > 0
    found = thin_structures(mask, least_length=30, most_width=4)
    assert found[10:12, 5:75].all() and found[ring > 0].all()
    assert not found[40:46, 40:46].any() and not found[55:75, 5:15].any()


def _face(photos):
    from deface.io.images import load_image
    from deface.landmarks.detect import detect_landmarks

    image = load_image(photos / "nextface-s1.png")
    points = detect_landmarks(image).points[:, :2]
    return image.copy(), points


def _features(points, shape):
    diagonal = float(np.hypot(*np.ptp(points, axis=0)))
    return feature_mask_from_landmarks(points, shape, round(OccluderConfig().feature_margin * diagonal) + 2)


def _h(image, points, enabled=True):
    coverage = cv2.dilate(_hull_mask(points, image.shape[:2]).astype(np.uint8), np.ones((15, 15), np.uint8))
    config = SkinClassifierConfig(occluders=OccluderConfig(enabled=enabled))
    return SkinColourClassifier(config)(image, coverage.astype(np.float32), points)


def test_a_thin_dark_ring_around_the_eyes_leaves_h_and_a_mole_as_dark_stays(photos):
    image, points = _face(photos)
    frame = _draw_frame(image, points)
    cheek = points[205]  # MediaPipe's right cheek
    mole = np.zeros_like(frame)
    cv2.circle(mole, (round(cheek[0]), round(cheek[1])), 2, 1, -1)
    image[mole > 0] = np.array([0.08, 0.08, 0.09], np.float32)  # as dark as the frame
    h, without = _h(image, points), _h(image, points, enabled=False)
    ring = frame > 0
    assert without[ring].mean() > 0.6  # the skin model alone keeps the frame, enclosed by skin
    off_features = ring & ~_features(points, image.shape[:2])  # a rim over a brow stays with the brow
    assert off_features.sum() > 0.6 * ring.sum() and h[off_features].mean() < 0.2
    assert np.median(h[off_features]) == 0.0  # not half in: at half weight the fit paints a trace of the frame
    assert h[mole > 0].mean() > 0.8


def test_the_fit_says_what_share_of_the_face_the_finder_left_out(photos):
    """The fit's log says how much of the face the finder took (and what it leaves in): a drawn frame raises the
    share by about its own area (the clean photo's hairline strands are found too); the classifier's h is the same
    whether it is asked for what it found or not."""
    from deface.fit.face_region import say_occluders
    from deface.fit.log import FitLog

    image, points = _face(photos)
    coverage = cv2.dilate(_hull_mask(points, image.shape[:2]).astype(np.uint8), np.ones((15, 15), np.uint8))
    classifier = SkinColourClassifier()
    framed = image.copy()
    frame = _draw_frame(framed, points) > 0
    shares = []
    for picture in (image, framed):
        h, found = classifier.with_occluders(picture, coverage.astype(np.float32), points)
        np.testing.assert_array_equal(h, classifier(picture, coverage.astype(np.float32), points))
        log = FitLog(quiet=True)
        say_occluders(found, coverage, log, 0)
        assert len(log.notes) == 1 and "of the face; left out of h" in log.notes[0]
        shares.append(float(re.search(r"cover ([0-9.]+) %", log.notes[0]).group(1)))
    drawn = 100 * (frame & (coverage > 0)).sum() / (coverage > 0).sum()
    assert shares[1] - shares[0] > 0.5 * drawn
    log = FitLog(quiet=True)
    say_occluders(None, coverage, log, 0)  # the finder did not look (off, or not MediaPipe's landmarks)
    assert log.notes == []


def test_a_strand_over_the_forehead_leaves_h(photos):
    image, points = _face(photos)
    top, brow = points[10], points[9]  # the forehead's top and the point between the brows
    strand = np.zeros(image.shape[:2], np.uint8)
    curve = np.array([[top[0] - 25, top[1] + 4], [top[0] - 5, (top[1] + brow[1]) / 2],
                      [top[0] + 20, brow[1] - 4]], np.int32)
    cv2.polylines(strand, [curve], False, 1, 2)
    image[strand > 0] = np.array([0.10, 0.07, 0.05], np.float32)  # dark brown hair
    h = _h(image, points)
    assert h[(strand > 0) & ~_features(points, image.shape[:2])].mean() < 0.2
    assert (h[_hull_mask(points, image.shape[:2]) & (strand == 0)] > 0.5).mean() > 0.9  # the rest stays face


def test_the_finder_abstains_when_thin_dark_lines_cover_the_face():
    """Deep wrinkles over a whole dark face are its own texture: past ``most_area`` of the region nothing is
    left out, while one line of the same kind is."""
    from deface.priors.occluders import find_occluders

    size = 120
    region = np.zeros((size, size), bool)
    region[10:110, 10:110] = True
    none = np.zeros_like(region)
    one = np.full((size, size, 3), 0.6, np.float32)
    one[60:62, 15:105] = 0.1
    net = one.copy()
    net[12:108:6, 12:108] = 0.1  # a line every 6 rows and columns: a third of the face
    net[12:108, 12:108:6] = 0.1
    config = OccluderConfig()
    found = find_occluders(one, region, none, none, 100.0, config)
    assert found[60:62, 20:100].all() and found.sum() < 0.05 * region.sum()
    assert not find_occluders(net, region, none, none, 100.0, config).any()
    assert find_occluders(net, region, none, none, 100.0, OccluderConfig(most_area=1.0)).sum() > 0.2 * region.sum()


def test_thin_stripes_of_shade_are_found_and_a_mole_as_dark_is_not():
    """Blinds' shade keeps part of the light (here 65 %): with ``contrast`` 0.75 its stripes, long and thin, are
    found, while a mole of the same darkness is compact and is not; at the default 0.55 neither is (the board's
    figures for each: docs/occluders.md)."""
    from deface.priors.occluders import find_occluders

    size = 120
    region = np.zeros((size, size), bool)
    region[10:110, 10:110] = True
    none = np.zeros_like(region)
    stripes = np.zeros_like(region)
    for x in range(16, 104, 14):
        stripes[12:108, x:x + 2] = True  # seven stripes, 2 pixels wide (the thickness limit is 3)
    image = np.full((size, size, 3), 0.6, np.float32)
    shade = 0.6 * 0.65 ** (1 / 2.2)  # sRGB of 65 % of the skin's linear light
    image[stripes] = shade
    image[60:64, 22:26] = shade  # a mole between two stripes
    found = find_occluders(image, region, none, none, 100.0, OccluderConfig(contrast=0.75, most_area=0.3))
    assert found[14:106][stripes[14:106]].mean() > 0.9 and not found[60:64, 22:26].any()
    assert not find_occluders(image, region, none, none, 100.0, OccluderConfig()).any()


def _draw_frame(image, points):
    """A dark grey glasses frame, 2 pixels wide, around both eyes: [H, W] uint8, 1 on the frame."""
    frame = np.zeros(image.shape[:2], np.uint8)
    for name in ("left_eye", "right_eye"):
        eye = points[list(MEDIAPIPE_FEATURES[name])]
        centre, half = eye.mean(0), np.ptp(eye[:, 0]) / 2
        cv2.ellipse(frame, (round(centre[0]), round(centre[1])), (round(1.8 * half), round(1.3 * half)), 0, 0, 360,
                    1, 2)
    image[frame > 0] = np.array([0.08, 0.08, 0.09], np.float32)
    return frame


def _texels_on(view, mask: np.ndarray) -> np.ndarray:
    """[Ht, Wt] bool: the visible texels whose pixel lies on ``mask`` [H, W]."""
    pixel = np.floor(view.pixel).astype(int)
    inside = view.visible & (pixel[..., 0] >= 0) & (pixel[..., 1] >= 0)
    inside &= (pixel[..., 0] < mask.shape[1]) & (pixel[..., 1] < mask.shape[0])
    on = np.zeros(inside.shape, bool)
    on[inside] = mask[pixel[..., 1][inside], pixel[..., 0][inside]] > 0
    return on


@pytest.mark.slow
@pytest.mark.parametrize("enabled", [True, False])
def test_a_frame_is_not_in_the_map_its_texels_are_filled_and_marked_low(photos, enabled):
    """A fit of a photo with a dark frame drawn around the eyes: off the features, the frame's texels are nearly
    as light as the skin around them in diffuse.png (the photo there is a fifth as light), and their confidence
    is under half of the skin's. Without the occluder finder (the reference) the frame is painted in."""
    from deface.fit import presets
    from deface.fit.config import override
    from deface.fit.pipeline import fit

    image, points = _face(photos)
    frame = _draw_frame(image, points) * ~_features(points, image.shape[:2])
    config = override(presets.get("default"), **{"iterations.stage1": 60, "iterations.stage2": 60,
                                                 "iterations.stage3": 60,
                                                 "skin_classifier.occluders.enabled": enabled})
    result = fit([image], config, source="frame")
    assert result.framing.is_whole  # working pixels are the photo's
    view = result.texels.views[0]
    on_frame = _texels_on(view, frame)
    around = _texels_on(view, cv2.dilate(frame, np.ones((9, 9), np.uint8)))
    around &= ~_texels_on(view, cv2.dilate(frame, np.ones((3, 3), np.uint8))) & (result.texels.seen > 0.5)
    luma = result.textures.diffuse.numpy() @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    confidence = result.texels.confidence
    assert on_frame.sum() > 20 and around.sum() > 50
    clean = luma[on_frame].mean() > 0.85 * luma[around].mean()
    low = np.median(confidence[on_frame]) < 0.5 * np.median(confidence[around])
    assert (clean and low) if enabled else not (clean or low)


def test_the_mouths_opening_leaves_h_and_the_lips_stay(photos):
    """A smile showing teeth: the opening between the inner lips is not the face's surface (h 0 there), the lips
    around it are face; with ``mouth_opening`` off the lips' hull keeps the teeth as face."""
    from deface.io.images import load_image
    from deface.landmarks.detect import detect_landmarks
    from deface.priors.face_region import mouth_opening_mask

    image = load_image(photos / "nextface-s3.png")
    points = detect_landmarks(image).points[:, :2]
    shape = image.shape[:2]
    opening = mouth_opening_mask(points, shape)
    lips = _hull_mask(points[list(MEDIAPIPE_FEATURES["lips"])], shape)
    band = lips & ~cv2.dilate(opening.astype(np.uint8), np.ones((7, 7), np.uint8)).astype(bool)
    assert opening.sum() > 0.1 * lips.sum()  # the photo's mouth is open
    coverage = cv2.dilate(_hull_mask(points, shape).astype(np.uint8), np.ones((15, 15), np.uint8))
    h = SkinColourClassifier()(image, coverage.astype(np.float32), points)
    kept = SkinColourClassifier(SkinClassifierConfig(mouth_opening=False))(image, coverage.astype(np.float32), points)
    assert h[opening].max() == 0.0 and kept[opening].mean() > 0.9
    assert h[band].mean() > 0.9
    assert not mouth_opening_mask(points[:68], shape).any()  # not a MediaPipe layout


def test_the_eyes_openings_leave_h_and_the_lids_stay(photos):
    """Open eyes: between the lid margins (the white, the iris, the inner corner) is not the face's surface (h 0);
    the lids and the rest of h are as without it beyond the blur's reach; with ``eye_opening`` off the eyes' hulls
    keep the opening as face."""
    from deface.priors.face_region import eye_openings_mask

    image, points = _face(photos)
    shape = image.shape[:2]
    openings = eye_openings_mask(points, shape)
    eyes = np.zeros(shape, bool)
    for name in ("left_eye", "right_eye"):
        eyes |= _hull_mask(points[list(MEDIAPIPE_FEATURES[name])], shape)
    assert openings.sum() > 0.8 * eyes.sum()  # the photo's eyes are open; the polygon is the hull, nearly
    coverage = cv2.dilate(_hull_mask(points, shape).astype(np.uint8), np.ones((15, 15), np.uint8))
    h = SkinColourClassifier()(image, coverage.astype(np.float32), points)
    kept = SkinColourClassifier(SkinClassifierConfig(eye_opening=False))(image, coverage.astype(np.float32), points)
    assert h[openings].max() == 0.0 and kept[openings].mean() > 0.9
    beyond = ~cv2.dilate(openings.astype(np.uint8), disk(4)).astype(bool)
    assert np.abs(h - kept)[beyond].max() < 0.05
    assert not eye_openings_mask(points[:68], shape).any()  # not a MediaPipe layout


def test_a_beards_edge_past_the_outline_is_not_taken_for_an_occluder(photos):
    """nextface-s1's stubble runs past the face outline's points onto the jaw's underside: the finder leaves the
    beard zone grown below the alae's line alone, so the dark band along the jaw stays face; nothing above that
    line is added to the zone."""
    from deface.priors.face_region import MEDIAPIPE_CHIN, beard_reach_mask, beard_zone_mask

    image, points = _face(photos)
    shape = image.shape[:2]
    margin = 12
    zone, reach = beard_zone_mask(points, shape), beard_reach_mask(points, shape, margin)
    chin = np.round(points[MEDIAPIPE_CHIN]).astype(int)
    assert (reach >= zone).all() and reach[chin[1] + margin // 2, chin[0]] and not zone[chin[1] + margin // 2, chin[0]]
    nose = np.round(points[1]).astype(int)  # the nose's tip is above the alae's line
    assert not reach[nose[1], nose[0]]
    h, without = _h(image, points), _h(image, points, enabled=False)
    band = reach & ~zone & (without > 0.5)
    assert band.sum() > 100 and np.abs(h[band] - without[band]).mean() < 0.02  # the finder took nothing there
