"""The fit works on the face at its own resolution (issue 39): the crop around the face and its working size
(deface/fit/framing.py), the photo's principal point seen through the crop (deface/render/camera.py), and fits
of a small face in a large canvas, whose outputs refer back to the canvas's pixels and whose maps are those of
the same face cropped by hand.

The canvas is rendered with the project's renderer (a known face, camera and landmarks), so every check has an
independent reference: the canvas's own pixels, the true camera, the true landmarks.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch
from PIL import Image

from deface.eval.synthetic import directional_sh, true_landmarks
from deface.export.load import load_fit
from deface.export.outputs import write_fit
from deface.fit import presets
from deface.fit.config import override
from deface.fit.framing import Framing, choose_framing, decode_side, face_box, texture_size_for
from deface.fit.log import FitLog
from deface.fit.pipeline import fit_target
from deface.fit.target import FitTarget, frame_target
from deface.io.images import linear_to_srgb, resize_max, to_uint8
from deface.landmarks.detect import Landmarks, detect_landmarks
from deface.models import load_face_model
from deface.render import kernels
from deface.render.camera import Camera
from deface.render.mesh import Mesh, Textures
from deface.render.renderer import RenderConfig, Renderer

FRONTAL = (math.pi, 0.0, 0.0)


# -- where the working frame lies (pure geometry) -------------------------------------------------------------
def _box(centre, side):
    return centre[0] - side / 2, centre[1] - side / 2, centre[0] + side / 2, centre[1] + side / 2


@pytest.mark.parametrize("side", [30, 100, 200, 400])
def test_the_working_size_follows_the_face_up_to_the_cap_and_never_upsamples(side):
    framing = choose_framing((2000, 1500), _box((1000, 700), side), resolution=512, margin=2.0)
    crop = 2 * side  # input pixels
    assert framing.scale == pytest.approx(min(1.0, 512 / crop), rel=1e-3)
    assert max(framing.size) == pytest.approx(min(crop, 512), abs=1)
    assert max(framing.size) <= 512 and framing.scale <= 1.0
    # the face's own pixels: the working frame holds the face at the photo's scale, up to the cap
    assert side * framing.scale == pytest.approx(min(side, 256), rel=1e-2)


def test_the_cap_bounds_the_working_size_and_a_larger_cap_gives_the_face_more_pixels():
    box = _box((1000, 700), 400)
    sizes = [max(choose_framing((2000, 1500), box, cap, 2.0).size) for cap in (128, 256, 512, 1024)]
    assert sizes == [128, 256, 512, 800]  # 800: the crop's own pixels, not upsampled to the cap


def test_the_crop_is_a_square_moved_inside_the_frame_and_cut_to_it():
    near_edge = choose_framing((1000, 800), _box((60, 400), 100), 512, 2.0)
    left, top, right, bottom = near_edge.box
    assert left == 0 and right == pytest.approx(200) and bottom - top == pytest.approx(200)
    assert top == pytest.approx(300)  # centred vertically on the face
    tall = choose_framing((1000, 300), _box((500, 150), 200), 512, 2.0)  # a 400-px crop in a 300-px high frame
    left, top, right, bottom = tall.box
    assert (top, bottom) == (0, 300) and right - left == pytest.approx(400)


@pytest.mark.parametrize("size", [(640, 480), (300, 1000), (200, 150)])
def test_without_a_crop_the_working_frame_is_the_whole_frame_resized_as_before(size):
    framing = choose_framing(size, None, resolution=256, margin=2.0)
    image = np.zeros((size[1], size[0], 3), np.float32)
    resized, scale = resize_max(image, 256)
    assert framing.is_whole and framing.size == (resized.shape[1], resized.shape[0])
    assert framing.scale == pytest.approx(scale) and framing.principal_point == pytest.approx(
        (framing.size[0] / 2, framing.size[1] / 2), abs=0.5)


def test_positions_round_trip_and_the_principal_point_is_the_input_centre():
    framing = choose_framing((1531, 977), _box((400, 300), 180), 256, 2.0)
    points = np.random.default_rng(0).uniform(0, 256, (20, 2))
    assert np.allclose(framing.from_input(framing.to_input(points)), points)
    assert np.allclose(framing.to_input(np.array(framing.principal_point)), [1531 / 2, 977 / 2])
    left, top = framing.scene_offset
    assert np.allclose(framing.to_input(np.zeros(2)), np.array([left, top]) / np.array(framing.factors))
    assert Framing.from_record(json.loads(json.dumps(framing.record()))) == framing


def test_a_small_face_is_decoded_at_the_size_its_crop_needs_within_the_file_and_the_pixel_budget():
    file, decoded = (6000, 4000), (2048, 1365)
    # a face box of 100 decoded pixels: a 200-px crop, 512 wanted, so 2.56 times the decoded size
    assert decode_side(_box((1000, 700), 100), decoded, file, 512, 2.0, 10**9) == int(2048 * 512 / 200)
    # the file's own size and the pixel budget bound it; a face already large keeps the decoded size
    assert decode_side(_box((1000, 700), 20), decoded, file, 512, 2.0, 10**9) == 6000
    assert decode_side(_box((1000, 700), 20), decoded, file, 512, 2.0, 6_000_000) == int(6000 * 0.5)
    assert decode_side(_box((1000, 700), 400), decoded, file, 512, 2.0, 10**9) == 2048
    # what it asks for puts the crop at the cap: the framing of the larger decode holds the face at 512 pixels
    side = decode_side(_box((1000, 700), 100), decoded, file, 512, 2.0, 10**9)
    factor = side / 2048
    larger = (round(2048 * factor), round(1365 * factor))
    framing = choose_framing(larger, _box((1000 * factor, 700 * factor), 100 * factor), 512, 2.0)
    assert max(framing.size) == pytest.approx(512, abs=2) and framing.scale == pytest.approx(1.0, abs=0.01)


@pytest.mark.slow
def test_a_photo_whose_face_is_small_is_decoded_larger_for_it(photos, tmp_path):
    """deface/batch/task.py load_photo: a 160-px face in a 4000 x 3000 JPEG is 82 px at the decoder's 2048; the photo
    is decoded at the size that gives the face's crop the fit's resolution, and the face keeps the file's pixels."""
    from deface.batch.task import load_photo
    from deface.io.images import LOAD_MAX_SIDE

    face = (np.asarray(Image.open(photos / "facenet-paul_rudd.png").convert("RGB")))  # 160 x 160
    canvas = np.full((3000, 4000, 3), (110, 120, 100), np.uint8)
    canvas[1400:1560, 2900:3060] = face
    path = tmp_path / "group.jpg"
    Image.fromarray(canvas).save(path, quality=95)
    config = presets.get("default")
    frame, found = load_photo(path, config)
    assert max(frame.shape[:2]) > 1.5 * LOAD_MAX_SIDE
    assert found is None  # found on the smaller decode: the fit finds them again on this frame
    scale = frame.shape[1] / 4000
    landmarks = detect_landmarks(frame)
    crop = choose_framing((frame.shape[1], frame.shape[0]), face_box([landmarks.points], frame.shape[1::-1]),
                          config.resolution, config.crop.margin)
    assert max(crop.size) >= 0.9 * min(config.resolution, 2 * 160 * 0.8)  # the face's crop, not 82 px of it
    assert np.abs(landmarks.points.mean(0) / scale - (2980, 1480)).max() < 20
    whole, found = load_photo(path, override(config, **{"crop.enabled": False}))  # no crop: the photo at the cap
    assert max(whole.shape[:2]) == LOAD_MAX_SIDE and found is None


@pytest.mark.slow
def test_landmarks_found_to_size_a_photo_are_passed_on_when_the_frame_is_kept(photos, tmp_path):
    """A large photo whose face is large: its landmarks are found once, to size the decode, and passed to the fit
    with the frame they were found on, equal to what the fit would find on it."""
    from deface.batch.task import load_photo
    from deface.io.images import LOAD_MAX_SIDE

    face = np.asarray(Image.open(photos / "facenet-paul_rudd.png").convert("RGB").resize((1600, 1600)))
    canvas = np.full((3000, 4000, 3), (110, 120, 100), np.uint8)
    canvas[700:2300, 1200:2800] = face
    path = tmp_path / "close.jpg"
    Image.fromarray(canvas).save(path, quality=95)
    frame, found = load_photo(path, presets.get("default"))
    assert max(frame.shape[:2]) == LOAD_MAX_SIDE and found is not None
    np.testing.assert_array_equal(found.points, detect_landmarks(frame).points)


def test_the_texture_size_is_the_power_of_two_nearest_what_the_face_supports_within_the_range():
    assert [texture_size_for(t, (256, 1024)) for t in (90, 300, 400, 700, 800, 5000, 0.0)] == [
        256, 256, 512, 512, 1024, 1024, 256]


# -- the principal point through a window of the image -------------------------------------------------------
def _camera(width=200, height=160, focal=300.0, shift=(-6.0, 3.0)) -> Camera:
    return Camera(torch.tensor(focal), torch.tensor(FRONTAL), torch.tensor([shift[0], shift[1], 60.0]), width, height)


def test_a_window_camera_projects_where_the_whole_camera_does_minus_the_corner():
    points = torch.tensor([[0.0, 0.0, 0.0], [4.0, -3.0, 2.0], [-6.0, 5.0, -1.0]])
    whole = _camera()
    window = whole.window(37, 22, 90, 70)
    assert torch.allclose(window.project(points)[0], whole.project(points)[0] - torch.tensor([37.0, 22.0]))
    fine = window.scaled(2)
    assert torch.allclose(fine.project(points)[0], 2 * window.project(points)[0], atol=1e-4)
    assert window.detached().principal == window.principal == (100 - 37, 80 - 22)


@pytest.mark.parametrize("backend", ["numba", "torch"])  # z-buffer, and Embree's primary rays
def test_rendering_through_a_window_is_that_window_of_the_whole_render(shared, backend):
    model = load_face_model("ict")
    mesh = Mesh.create(model.mean_shape, model.triangles, model.uvs, model.triangle_uvs)
    renderer = Renderer(RenderConfig(shadows=False))
    whole = _camera()
    window = whole.window(30, 25, 100, 90)
    with kernels.backend(backend):
        full = renderer.rasterize(mesh, whole).triangle_id
        part = renderer.rasterize(mesh, window).triangle_id
    expected = full[25:115, 30:130]
    assert (expected >= 0).sum() > 2000  # the window holds much of the face
    assert (part != expected).float().mean() < 0.002  # pixel centres on an edge may go either way


# -- a small face at a known place in a large canvas ----------------------------------------------------------
CANVAS = (256, 224)  # (W, H)
FACE_CENTRE = (84.0, 92.0)  # where the face's landmarks centre lands in the canvas (pixels)
BACKGROUND = np.array([0.30, 0.34, 0.26], np.float32)  # linear


class Canvas:
    """A synthetic face about 64 px wide (a quarter of the canvas) off the canvas's centre, its true camera,
    landmarks, textures and coverage."""

    def __init__(self, model):
        generator = torch.Generator().manual_seed(3)
        self.mesh = Mesh.create(model.mean_shape, model.triangles, model.uvs, model.triangle_uvs)
        focal, depth = 220.0, 60.0
        probe = Camera(torch.tensor(focal), torch.tensor(FRONTAL), torch.tensor([0.0, 0.0, depth]), *CANVAS)
        centre = true_landmarks(model, self.mesh, probe).points.mean(0)
        shift = (np.array(FACE_CENTRE) - centre) * depth / focal
        self.camera = Camera(torch.tensor(focal), torch.tensor(FRONTAL),
                             torch.tensor([shift[0], shift[1], depth], dtype=torch.float32), *CANVAS)
        coeffs = 0.7 * torch.randn(model.albedo.num_coeffs, generator=generator)
        diffuse, specular = model.albedo.textures(coeffs, 128)
        self.textures = Textures(diffuse.clamp(0, 1), specular.clamp(0, 1), torch.full((128, 128, 1), 0.45))
        renderer = Renderer(RenderConfig(shadow_rays=16), seed=0)
        fragments = renderer.rasterize(self.mesh, self.camera)
        with torch.no_grad():
            shaded = renderer.shade(self.mesh, self.camera, fragments, self.textures,
                                    directional_sh((0.3, 0.5, 0.8), strength=1.6, ambient=0.35),
                                    renderer.shadow_transfer(self.mesh))
        self.coverage = shaded.mask.numpy()
        image = shaded.images[0].numpy() * self.coverage[..., None] + BACKGROUND * (1 - self.coverage[..., None])
        self.image = linear_to_srgb(np.clip(image, 0, 1)).astype(np.float32)
        self.landmarks = true_landmarks(model, self.mesh, self.camera)


@pytest.fixture(scope="module")
def canvas(shared):
    return Canvas(load_face_model("ict"))


def _config(**changes):
    short = {"resolution": 256, "texture_size": 128, "render.shadow_rays": 16, "iterations.stage1": 150,
             "iterations.stage2": 60, "iterations.stage3": 40, "decouple.ace_iteration": 20}
    return override(presets.get("default"), **{**short, **changes})


def test_the_crop_is_the_canvas_around_the_face_and_its_landmarks_and_camera_are_the_canvas_s(canvas):
    target = frame_target([canvas.image], [canvas.landmarks], _config())
    framing = target.framing
    assert not framing.is_whole and framing.scale == 1.0  # a 64-px face: its own pixels, no resize
    left, top = framing.scene_offset
    width, height = framing.size
    assert np.array_equal(target.frames_srgb[0], canvas.image[top:top + height, left:left + width])
    assert np.array_equal(target.scene_frames()[0], canvas.image)
    assert np.allclose(framing.to_input(target.landmarks[0].points), canvas.landmarks.points, atol=1e-4)
    # the crop's camera is the canvas's camera seen through the window: the photo's principal point, off-centre
    window = canvas.camera.window(left, top, width, height)
    assert target.principal_point == pytest.approx(window.principal)
    assert abs(target.principal_point[0] - width / 2) > 20


@pytest.fixture(scope="module")
def cropped_fit(canvas):
    """A short fit of the canvas through the crop."""
    return fit_target(frame_target([canvas.image], [canvas.landmarks], _config()), _config(),
                      log=FitLog(quiet=True))


@pytest.mark.slow
def test_the_fit_of_the_crop_has_the_camera_of_a_fit_of_the_whole_canvas(canvas, cropped_fit):
    """In the canvas's pixels, the crop's camera is the one a fit of the whole canvas (at the same scale, 1)
    finds: the same landmarks, the same principal point, so the same pose and focal length. A crop that put
    the principal point at its own centre would turn and move the head to make up for it."""
    whole = _config(**{"crop.enabled": False})
    reference = fit_target(frame_target([canvas.image], [canvas.landmarks], whole), whole, log=FitLog(quiet=True))
    assert reference.framing.is_whole and reference.framing.scale == 1.0
    ours, theirs = (fit.framing.input_camera(fit.frames[0].geometry.camera) for fit in (cropped_fit, reference))
    assert (ours.width, ours.height) == CANVAS and ours.principal == (CANVAS[0] / 2, CANVAS[1] / 2)
    assert float(ours.focal) == pytest.approx(float(theirs.focal), rel=1e-3)
    assert torch.allclose(ours.rotation, theirs.rotation, atol=2e-3)
    assert torch.allclose(ours.translation, theirs.translation, atol=0.02 * float(theirs.translation[2]))
    # and the fitted model's landmarks land on the canvas's (to stage 1's accuracy, about a pixel)
    model = cropped_fit.model
    projected = true_landmarks(model, cropped_fit.frames[0].geometry.mesh, ours).points
    assert np.linalg.norm(projected - canvas.landmarks.points, axis=1).mean() < 1.5


@pytest.mark.slow
def test_the_fit_of_the_crop_lands_on_the_canvas_pixels(canvas, cropped_fit, tmp_path):
    fit = cropped_fit
    camera = fit.framing.input_camera(fit.frames[0].geometry.camera)
    # the fitted face seen by the input's camera covers the canvas's face (up to the ears and neck, which the
    # landmarks do not fix)
    fitted = Renderer(RenderConfig(shadows=False)).rasterize(fit.frames[0].geometry.mesh, camera).mask.numpy() > 0
    truth = canvas.coverage > 0.5
    assert (fitted & truth).sum() / (fitted | truth).sum() > 0.8
    folder = write_fit(fit, tmp_path / "canvas", {"path": "canvas", "kind": "image", "frames": [0]})
    written = np.asarray(Image.open(folder / "render.png")).astype(int)
    assert written.shape[:2] == (CANVAS[1], CANVAS[0])  # the whole canvas at the working scale (1)
    left, top, right, bottom = (round(v) for v in fit.framing.box)
    outside = np.ones(written.shape[:2], bool)
    outside[top:bottom, left:right] = False
    photo = to_uint8(canvas.image, srgb=False).astype(int)
    assert np.abs(written - photo)[outside].max() <= 1
    face = fit.composite_photo(fit.render()[0], 0).numpy()  # where the face is, the render matches the canvas
    error = np.abs(linear_to_srgb(np.clip(face, 0, 1)) - canvas.image).mean(-1)
    assert error[truth].mean() < 0.05
    params = json.loads((folder / "params.json").read_text())
    assert params["camera"]["principal_point"] == [CANVAS[0] / 2, CANVAS[1] / 2]
    assert params["camera"]["focal_px"] == pytest.approx(float(camera.focal), rel=1e-5)
    loaded = load_fit(folder)
    again = to_uint8(loaded.composite_photo(loaded.render()[0], 0).numpy(), srgb=True).astype(int)
    assert np.abs(again - written).max() <= 1
    assert loaded.framing.scene_offset == fit.framing.scene_offset
    # the commands that re-use a fit write the whole photo too
    from typer.testing import CliRunner

    from deface.cli.main import app

    result = CliRunner().invoke(app, ["relight", str(folder), "-o", str(tmp_path / "relit"), "--light", "studio"])
    assert result.exit_code == 0, result.output
    relit = np.asarray(Image.open(tmp_path / "relit" / "render.png")).astype(int)
    assert relit.shape[:2] == (CANVAS[1], CANVAS[0]) and np.abs(relit - photo)[outside].max() <= 1
    assert np.asarray(Image.open(tmp_path / "relit" / "render_face.png")).shape[:2] == tuple(fit.framing.size[::-1])


def _by_hand(canvas: Canvas, box: tuple[int, int, int, int]) -> tuple[np.ndarray, Landmarks]:
    left, top, right, bottom = box
    image = np.ascontiguousarray(canvas.image[top:bottom, left:right])
    found = canvas.landmarks
    return image, Landmarks(found.points - np.array([left, top], np.float32), found.depth,
                            (right - left, bottom - top), 1, 0)


def _uv_psnr(first: torch.Tensor, second: torch.Tensor, seen: np.ndarray) -> float:
    """PSNR (dB) of two sRGB-encoded diffuse maps over the texels both fits saw squarely."""
    a, b = (linear_to_srgb(np.clip(t.detach().numpy(), 0, 1)) for t in (first, second))
    error = float(np.mean((a - b)[seen] ** 2))
    return 10 * math.log10(1.0 / max(error, 1e-12))


@pytest.mark.slow
def test_a_small_face_in_a_large_canvas_gives_the_maps_of_the_face_cropped_by_hand(canvas, cropped_fit):
    """The canvas through the crop against a hand crop of the face (a tighter square, a little off the auto
    crop): the same pixels of the face, another principal point and another scene around it. Tolerance 33 dB
    over the texels both fits saw squarely (measured 38.6: the pose makes up for the other principal point, the
    white level is read from other background pixels of the same colour); the whole canvas fitted as before the
    crop, at the 128-px working size that held the whole photo (a face of 32 px), is 35.6, so the crop must
    also beat it by 1.5 dB."""
    x, y = (round(v) for v in FACE_CENTRE)
    image, landmarks = _by_hand(canvas, (x - 55, y - 60, x + 60, y + 62))
    hand = fit_target(frame_target([image], [landmarks], _config()), _config(), log=FitLog(quiet=True))
    assert hand.framing.is_whole  # the hand crop is tighter than the automatic one: all of it is fitted
    seen = (cropped_fit.texels.seen > 0.5) & (hand.texels.seen > 0.5)
    assert seen.sum() > 1500
    matched = _uv_psnr(cropped_fit.textures.diffuse, hand.textures.diffuse, seen)
    whole = _config(resolution=128, **{"crop.enabled": False})
    before = fit_target(frame_target([canvas.image], [canvas.landmarks], whole), whole, log=FitLog(quiet=True))
    assert before.framing.is_whole and before.framing.scale == pytest.approx(0.5)
    unmatched = _uv_psnr(before.textures.diffuse, hand.textures.diffuse, seen & (before.texels.seen > 0.5))
    assert matched > 33.0 and matched > unmatched + 1.5, (matched, unmatched)


def test_a_target_built_by_hand_is_the_whole_frame(canvas):
    target = FitTarget([canvas.image], [canvas.landmarks], 0.5)
    assert target.framing.is_whole and target.principal_point is None
    assert target.framing.input_size == (CANVAS[0] * 2, CANVAS[1] * 2)
    assert target.scene_frames()[0] is canvas.image


def test_a_clip_has_one_crop_around_every_frame_s_face(canvas):
    """A clip's frames share one pixel grid (f's (x, y, t), the batched frames): one crop holding each face."""
    moved = np.roll(canvas.image, (30, 50), axis=(0, 1))
    shifted = Landmarks(canvas.landmarks.points + np.array([50, 30], np.float32), canvas.landmarks.depth,
                        CANVAS, 1, 0)
    target = frame_target([canvas.image, moved], [canvas.landmarks, shifted], _config())
    framing = target.framing
    for found in (canvas.landmarks, shifted):
        left, top, right, bottom = framing.box
        assert (found.points.min(0) >= np.array([left, top]) - 1e-3).all()
        assert (found.points.max(0) <= np.array([right, bottom]) + 1e-3).all()
    assert len(target.frames_srgb) == 2 and target.frames_srgb[0].shape == target.frames_srgb[1].shape
    assert np.allclose(framing.to_input(target.landmarks[1].points), shifted.points, atol=1e-4)
    # every frame's pixels cost the fit again: a clip has its own cap, a photo does not
    capped = _config(clip_resolution=64)
    assert max(frame_target([canvas.image, moved], [canvas.landmarks, shifted], capped).size) == 64
    assert frame_target([canvas.image], [canvas.landmarks], capped).framing.scale == 1.0


@pytest.mark.parametrize("setting", ["crop.margin=0.5", "texture_size_range=1024,512", "stage2_resolution=-1"])
def test_a_bad_crop_or_size_setting_is_one_line(setting):
    from deface.fit.config import set_from_text

    with pytest.raises(ValueError, match=setting.split("=")[0].split(".")[-1]):
        set_from_text(presets.get("default"), setting)


@pytest.fixture(scope="module")
def brief_cropped_fit(canvas):
    """The fit of the canvas through the crop, a few steps long: what a fit writes of its camera."""
    brief = _config(**{"iterations.stage1": 10, "iterations.stage2": 2, "iterations.stage3": 1,
                       "decouple.ace_iteration": 1, "render.shadow_rays": 4})
    return fit_target(frame_target([canvas.image], [canvas.landmarks], brief), brief, log=FitLog(quiet=True))


def test_a_photo_decoded_smaller_than_its_file_also_gets_the_file_s_camera(brief_cropped_fit, tmp_path):
    from deface.export.outputs import _camera
    from deface.io.images import image_size

    cropped_fit = brief_cropped_fit

    camera = _camera(cropped_fit, [CANVAS[0] * 4, CANVAS[1] * 4])
    assert camera["file"]["focal_px"] == pytest.approx(4 * camera["focal_px"])
    assert camera["file"]["principal_point"] == [CANVAS[0] * 2, CANVAS[1] * 2]
    assert "file" not in _camera(cropped_fit, list(CANVAS))
    rotated = Image.new("RGB", (40, 30))
    exif = rotated.getexif()
    exif[0x0112] = 6  # stored landscape, shown portrait
    rotated.save(tmp_path / "rotated.jpg", exif=exif)
    assert image_size(tmp_path / "rotated.jpg") == (30, 40)


@pytest.mark.slow
def test_the_texture_size_follows_the_face_s_pixels_and_an_explicit_size_wins(canvas):
    """The same face at its own pixels and at half of them: maps of twice the side (a power of two within the
    range), unless texture_size is given."""
    from deface.fit.pipeline import prepare

    sizes = []
    for cap in (256, 64):  # the 128-px crop at scale 1, then at scale 1/2
        config = _config(resolution=cap, texture_size=None, texture_size_range=(16, 4096),
                         **{"iterations.stage1": 60})
        context, _ = prepare(frame_target([canvas.image], [canvas.landmarks], config), config)
        sizes.append(context.texture_size)
    assert sizes[0] == 2 * sizes[1] and sizes[1] >= 32, sizes
    config = _config(resolution=256, texture_size=96, **{"iterations.stage1": 60})
    assert prepare(frame_target([canvas.image], [canvas.landmarks], config), config)[0].texture_size == 96
