"""The face-region classifier h: skin-colour model (synthetic + a real shadowed photo) and BiSeNet."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from deface.priors.bisenet import (
    CELEBAMASK_CLASSES,
    FACE_CLASSES,
    BiSeNet,
    BiSeNetFaceParser,
    MissingWeightsError,
    parsing_box,
)
from deface.priors.face_region import (
    SkinClassifierConfig,
    SkinColourClassifier,
    _hull_mask,
    _mahalanobis,
    beard_zone_mask,
    chromaticity,
    clipped_chroma_distance,
    enclosed_patches,
    load_face_region_classifier,
)

SKIN = np.array([0.85, 0.64, 0.53])
HAIR = np.array([0.30, 0.20, 0.10])
BACKGROUND = np.array([0.2, 0.6, 0.3])


def synthetic_face(seed: int = 0):
    """96x96: skin disk with a dark shadow band (rows 52-62) and a hair band (rows 18-28) inside it."""
    rng = np.random.default_rng(seed)
    size = 96
    ys, xs = np.mgrid[:size, :size]
    disk = (ys - 48) ** 2 + (xs - 48) ** 2 <= 40**2
    linear = np.where(disk[..., None], SKIN**2.2, BACKGROUND**2.2)
    shadow = disk & (ys >= 52) & (ys < 62)
    linear[shadow] *= np.array([0.22, 0.23, 0.26])  # darker and slightly bluer (sky-lit shadow)
    hair = disk & (ys >= 18) & (ys < 28)
    linear[hair] = HAIR**2.2
    srgb = np.clip(linear ** (1 / 2.2) + rng.normal(0, 0.01, linear.shape), 0, 1)
    return srgb.astype(np.float32), disk.astype(np.float32), shadow, hair


def test_skin_classifier_keeps_shadowed_skin_and_drops_hair():
    image, coverage, shadow, hair = synthetic_face()
    h = SkinColourClassifier()(image, coverage)
    assert h.shape == (96, 96) and h.dtype == np.float32 and h.min() >= 0 and h.max() <= 1
    lit = (coverage > 0) & ~shadow & ~hair
    inner_shadow = shadow.copy()
    inner_shadow[:, :20] = inner_shadow[:, 76:] = False  # away from the disk's rim
    assert h[lit].mean() > 0.9
    assert h[inner_shadow].mean() > 0.8
    assert h[hair].mean() < 0.2
    assert h[coverage == 0].max() == 0


def test_skin_classifier_accepts_torch_and_feature_masks():
    image, coverage, _, hair = synthetic_face(1)
    features = np.zeros_like(coverage)
    features[20:26, 40:56] = 1.0  # pretend the model projects a brow into the hair band
    h = SkinColourClassifier()(torch.from_numpy(image), torch.from_numpy(coverage), features=features)
    assert h[21:25, 42:54].mean() > 0.9
    assert h[hair & (features == 0)].mean() < 0.3
    with pytest.raises(ValueError):
        SkinColourClassifier()(image, np.zeros((96, 96)))


def test_clipped_chroma_distance_is_the_closest_value_the_clipped_channels_could_have():
    mean, precision = chromaticity(SKIN**2.2), np.linalg.inv(np.diag([0.015, 0.015]) ** 2)
    rng = np.random.default_rng(0)
    true = SKIN**2.2 * rng.uniform(1.0, 3.0, (200, 1))  # skin brighter than the encoding can hold
    clipped = true > 0.9
    shown = np.where(clipped, 0.9, true)
    assert clipped[:, 0].any() and (clipped.sum(-1) == 2).any() and (~clipped.any(-1)).any()
    distance = clipped_chroma_distance(shown, clipped, mean, precision)
    plain = _mahalanobis(chromaticity(shown), mean, precision)
    assert np.all(distance <= plain + 1e-9)  # raising nothing is one of the values tried
    assert np.allclose(distance[~clipped.any(-1)], plain[~clipped.any(-1)])
    assert distance.max() < 0.5 and np.median(plain[clipped.any(-1)]) > 3.5  # skin again, not skin as shown
    # a clipped red raises r only: a yellow-green whose green/blue is far from skin's stays far at any red
    cloth = np.array([[0.9, 0.7, 0.05]])
    assert clipped_chroma_distance(cloth, np.array([[True, False, False]]), mean, precision)[0] > 5


def test_skin_classifier_keeps_key_lit_skin_whose_red_is_clipped():
    image, coverage, shadow, hair = synthetic_face(2)
    key_lit = (coverage > 0) & ~shadow & ~hair & (np.arange(96)[None, :] >= 56)
    image[key_lit] = np.clip(image[key_lit] * 1.25, 0, 1)  # red reaches the white point, green and blue do not
    assert (image[key_lit][:, 0] >= 0.98).mean() > 0.9 and (image[key_lit][:, 1:] < 0.98).all()
    h = SkinColourClassifier()(image, coverage)
    inner = key_lit & (np.arange(96)[None, :] < 80)
    assert h[inner].mean() > 0.9
    assert h[hair].mean() < 0.2


def _mediapipe_landmarks(image: np.ndarray) -> np.ndarray:
    face_mesh = pytest.importorskip("mediapipe.python.solutions.face_mesh")
    with face_mesh.FaceMesh(static_image_mode=True, max_num_faces=1) as mesh:
        result = mesh.process(image)
    if not result.multi_face_landmarks:
        pytest.skip("MediaPipe found no face")
    height, width = image.shape[:2]
    return np.array([[p.x * width, p.y * height] for p in result.multi_face_landmarks[0].landmark])


def test_skin_classifier_on_a_real_shadowed_photo(photos):
    import cv2
    import imageio.v3 as iio

    image = iio.imread(photos / "real-foliage-shadow-9177-004.png")[..., :3]
    landmarks = _mediapipe_landmarks(image)
    hull = _hull_mask(landmarks, image.shape[:2])
    h = SkinColourClassifier()(image / 255.0, hull.astype(np.float32), landmarks)
    assert (h[hull] > 0.5).mean() > 0.9  # the half-shadowed face counts as face
    # a coverage spilling 30 px past the face: the green foliage it takes in is rejected
    grown = cv2.dilate(hull.astype(np.uint8), np.ones((61, 61), np.uint8)).astype(bool)
    h_grown = SkinColourClassifier()(image / 255.0, grown.astype(np.float32))
    foliage = grown & ~hull & (image[..., 1].astype(int) > image[..., 0].astype(int) + 10)
    assert foliage.sum() > 300
    assert (h_grown[foliage] > 0.5).mean() < 0.1
    assert (h_grown[hull] > 0.5).mean() > 0.85


def test_bisenet_shapes_and_state_dict_round_trip(tmp_path):
    torch.manual_seed(0)
    network = BiSeNet(19).eval()
    state = network.state_dict()
    assert state["cp.resnet.layer4.0.downsample.0.weight"].shape == (512, 256, 1, 1)
    assert state["ffm.conv1.weight"].shape == (64, 256, 1, 1)
    assert state["conv_out.conv_out.weight"].shape == (19, 256, 1, 1)
    assert state["conv_out16.conv_out.weight"].shape == (19, 64, 1, 1)
    assert state["cp.arm32.conv.conv.weight"].shape == (128, 512, 3, 3)
    with torch.no_grad():
        outputs = network(torch.randn(1, 3, 64, 64))
    assert [tuple(o.shape) for o in outputs] == [(1, 19, 64, 64)] * 3
    path = tmp_path / "79999_iter.pth"
    torch.save(state, path)
    parser = BiSeNetFaceParser(path, input_size=128)
    loaded = parser.network.state_dict()
    for key, value in state.items():
        assert torch.equal(loaded[key], value), key
    image = np.random.default_rng(0).random((90, 70, 3)).astype(np.float32)
    h = parser(image, None, np.array([[20.0, 30.0], [50.0, 70.0]]))
    top, left, bottom, right = parsing_box(np.array([[20.0, 30.0], [50.0, 70.0]]), (90, 70))
    assert (top, left, bottom, right) == (25, 18, 75, 52)
    assert h.shape == (90, 70) and h.min() >= 0 and h.max() <= 1
    assert h[:top].max() == 0 and h[top:bottom, left:right].min() > 0
    assert len(FACE_CLASSES) == 9


@pytest.fixture(scope="module")
def parser_checkpoint(tmp_path_factory):
    """A randomly initialised BiSeNet saved as the checkpoint's state dict."""
    path = tmp_path_factory.mktemp("bisenet") / "79999_iter.pth"
    torch.save(BiSeNet(19).state_dict(), path)
    return path


@pytest.mark.parametrize("label", range(19))
def test_bisenet_classes_map_to_the_face_region_as_documented(parser_checkpoint, label):
    """A parser loaded from a checkpoint in the project's format, its network's output set to one CelebAMask-HQ
    class everywhere: h is 1 for the face's classes (skin, brows, eyes, nose, mouth, lips) and 0 for the rest
    (background, eyeglasses, ears, earring, neck, necklace, cloth, hair, hat): what covers the face is not face."""
    parser = BiSeNetFaceParser(parser_checkpoint, input_size=32)

    def one_class(crop):
        logits = torch.full((crop.shape[0], 19, *crop.shape[2:]), -20.0)
        logits[:, label] = 20.0
        return logits, logits, logits

    parser.network = one_class
    h = parser(np.full((40, 40, 3), 0.5, np.float32), None, np.array([[10.0, 10.0], [30.0, 30.0]]))
    inside = h[h > 0] if label in FACE_CLASSES else h
    face = CELEBAMASK_CLASSES[label] in ("skin", "l_brow", "r_brow", "l_eye", "r_eye", "nose", "mouth", "u_lip",
                                         "l_lip")
    assert face == (label in FACE_CLASSES)
    assert (inside.min() > 0.99) if face else (h.max() < 1e-6)


def test_bisenet_missing_checkpoint(tmp_path, monkeypatch):
    monkeypatch.setenv("DEFACE_MODELS", str(tmp_path))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    with pytest.raises(MissingWeightsError, match="79999_iter.pth"):
        BiSeNetFaceParser(tmp_path / "79999_iter.pth")
    classifier, description = load_face_region_classifier(tmp_path)
    assert isinstance(classifier, SkinColourClassifier) and "BiSeNet off" in description


def test_enclosed_pigment_is_face_and_hair_from_the_border_is_not():
    """A birthmark and moles enclosed by skin are face (face parsers label them skin); a hair band that reaches
    the region's border is not; a patch larger than ``enclosed_area`` of the face is not either."""
    image, coverage, _, hair = synthetic_face()
    ys, xs = np.mgrid[:96, :96]
    mark = (ys - 40) ** 2 + (xs - 60) ** 2 <= 4**2  # a reddish-brown birthmark inside the skin
    mole = (ys - 70) ** 2 + (xs - 36) ** 2 <= 2**2
    image[mark] = np.array([0.55, 0.25, 0.18])
    image[mole] = np.array([0.2, 0.12, 0.08])
    h = SkinColourClassifier()(image, coverage)
    assert h[mark].mean() > 0.8 and h[mole].mean() > 0.8
    assert h[hair].mean() < 0.2
    small = SkinColourClassifier(SkinClassifierConfig(enclosed_area=0.001))(image, coverage)
    assert small[mark].mean() < 0.3


def test_enclosed_patches_topology():
    region = np.zeros((40, 40), bool)
    region[5:35, 5:35] = True
    skin = region.copy()
    skin[15:19, 15:19] = False  # enclosed
    skin[5:10, 25:30] = False  # reaches the region's border
    patches = enclosed_patches(skin, region, 0.05)
    assert patches[15:19, 15:19].all() and not patches[5:10, 25:30].any()
    assert not enclosed_patches(skin, region, 0.01).any()  # 16 texels > 1 % of 900


def test_beard_zone_is_the_lower_face_below_the_nose(photos):
    from deface.io.images import load_image
    from deface.landmarks.detect import detect_landmarks

    image = load_image(photos / "nextface-s1.png")
    points = detect_landmarks(image).points[:, :2]
    zone = beard_zone_mask(points, image.shape[:2])
    chin, nose_tip, forehead = points[152], points[1], points[10]
    assert zone[int(chin[1]) - 3, int(chin[0])]  # just above the chin's bottom
    assert not zone[int(nose_tip[1]) - 3, int(nose_tip[0])]  # the nose is above the zone
    assert not zone[int(forehead[1]) + 3, int(forehead[0])]
    assert not beard_zone_mask(points[:68], image.shape[:2]).any()  # not a MediaPipe layout: no zone


@pytest.mark.parametrize(("mouth_opening", "eye_opening"), [(True, True), (False, True), (True, False)])
def test_bisenet_leaves_the_openings_out_as_the_skin_classifier_does(parser_checkpoint, tmp_path, monkeypatch,
                                                                     mouth_opening, eye_opening):
    from deface.priors.bisenet import EYE_CLASSES, MOUTH_CLASS, PARSER_RELATIVE

    target = tmp_path / PARSER_RELATIVE[0]
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_bytes(parser_checkpoint.read_bytes())
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    skin = SkinClassifierConfig(mouth_opening=mouth_opening, eye_opening=eye_opening)
    parser, description = load_face_region_classifier(tmp_path, skin=skin)
    assert isinstance(parser, BiSeNetFaceParser) and "BiSeNet" in description
    assert (MOUTH_CLASS in parser.face_classes) != mouth_opening
    assert all((eye in parser.face_classes) != eye_opening for eye in EYE_CLASSES)
    assert set(parser.face_classes) | {MOUTH_CLASS, *EYE_CLASSES} == set(FACE_CLASSES)
