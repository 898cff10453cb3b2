"""Several photos of one person as one fit (deface/fit/person.py, `deface fit --person`)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from deface.cli.main import app
from deface.fit.config import FitConfig
from deface.fit.log import FitLog
from deface.fit.person import (
    PhotoCrop,
    crop_landmarks,
    cut_square,
    one_person,
    person_target,
    photos_of_one_person,
    square_box,
    working_side,
)
from deface.io.images import InputError
from deface.io.inputs import InputItem, person_input
from deface.landmarks.detect import Landmarks
from deface.landmarks.identity import SamePersonConfig
from deface.landmarks.identity import available as identity_available


def _dot_photo(width: int, height: int, at: tuple[float, float]) -> np.ndarray:
    """A grey photo with a small bright Gaussian dot centred at pixel position ``at`` (centres at +0.5)."""
    y, x = np.mgrid[0:height, 0:width] + 0.5
    dot = np.exp(-((x - at[0]) ** 2 + (y - at[1]) ** 2) / (2 * 2.0 ** 2))
    return np.repeat((0.2 + 0.7 * dot)[..., None], 3, axis=2).astype(np.float32)


def _peak(image: np.ndarray) -> np.ndarray:
    """The intensity-weighted centre (pixel positions, centres at +0.5) of the image's bright part."""
    weight = np.clip(image[..., 0] - 0.3, 0, None)
    y, x = np.mgrid[0:image.shape[0], 0:image.shape[1]] + 0.5
    return np.array([(weight * x).sum(), (weight * y).sum()]) / weight.sum()


def _landmarks(points: np.ndarray, size: tuple[int, int]) -> Landmarks:
    return Landmarks(points.astype(np.float32), np.zeros(len(points), np.float32), size, 1, 0)


@pytest.mark.parametrize("photo_size, box, side", [((400, 300), (100.0, 50.0, 300.0, 250.0), 100),  # shrink
                                                    ((120, 90), (30.0, 10.0, 90.0, 70.0), 128),  # enlarge
                                                    ((200, 200), (-40.0, -20.0, 160.0, 180.0), 64)])  # past edge
def test_a_point_of_the_photo_lands_where_its_landmark_is_moved(photo_size, box, side):
    at = (box[0] + 0.55 * (box[2] - box[0]), box[1] + 0.4 * (box[3] - box[1]))
    at = (max(at[0], 8.0), max(at[1], 8.0))
    crop = cut_square(_dot_photo(*photo_size, at), box, side)
    assert crop.shape == (side, side, 3)
    moved = crop_landmarks(_landmarks(np.array([at]), photo_size), box, side)
    assert moved.image_size == (side, side)
    np.testing.assert_allclose(_peak(crop), moved.points[0], atol=0.03 * side)


def test_outside_the_photo_its_edge_is_repeated():
    photo = np.zeros((50, 50, 3), np.float32)
    photo[:, -1] = 1.0  # the right edge column is white
    crop = cut_square(photo, (0.0, 0.0, 100.0, 100.0), 100)
    assert crop[:, 60:].min() > 0.99 and crop[:, :45].max() < 0.01


def test_photos_of_different_sizes_become_frames_of_one_size():
    sizes = [(640, 480), (300, 400), (1000, 1000)]
    photos = [np.full((h, w, 3), 0.5, np.float32) for w, h in sizes]
    boxes = [np.array([[200.0, 150.0], [400.0, 350.0]]), np.array([[50.0, 100.0], [150.0, 200.0]]),
             np.array([[300.0, 300.0], [700.0, 700.0]])]
    config = FitConfig()
    target, crops = person_target(photos, [_landmarks(b, s) for b, s in zip(boxes, sizes, strict=True)],
                                  ["a", "b", "c"], config)
    side = working_side(crops, config)
    assert target.num_frames == 3 and target.size == (side, side)
    assert side == min(config.resolution, config.clip_resolution)  # the largest face's pixels reach the cap
    for found in target.landmarks:
        # every face's landmark box lands in the middle of its frame, 1 / margin of its side
        extent = found.points.max(0) - found.points.min(0)
        assert extent.max() == pytest.approx(side / config.crop.margin, rel=1e-4)
        np.testing.assert_allclose((found.points.max(0) + found.points.min(0)) / 2, side / 2, atol=1e-3)


def test_square_box_is_centred_and_records_the_photo_camera():
    box = square_box(np.array([[10.0, 20.0], [30.0, 60.0]]), margin=2.0)
    assert box == (-20.0, 0.0, 60.0, 80.0)  # a square of 2 x 40 around (20, 40)
    assert square_box(np.array([[10.0, 20.0], [30.0, 60.0]]), 2.0, (100, 70)) == (0.0, 0.0, 80.0, 80.0)
    # moved right into the photo; taller than the photo (70): left where it was along y
    record = PhotoCrop("a.jpg", (100, 100), box).record(focal=500.0, side=200)
    assert record["camera"] == {"focal_px": 200.0, "principal_point": [20.0, 40.0]}


def test_a_person_input_takes_photos_and_a_plain_name(tmp_path):
    photos = [InputItem(tmp_path / f"{n}.jpg", "image") for n in "ab"]
    item = person_input("ada", photos)
    assert item.name == "ada" and item.files == (tmp_path / "a.jpg", tmp_path / "b.jpg")
    moved = item.moved([tmp_path / "x" / "a.jpg", tmp_path / "y" / "a.jpg"])
    assert moved.photos == (tmp_path / "x" / "a.jpg", tmp_path / "y" / "a.jpg") and moved.name == "ada"
    with pytest.raises(InputError, match="no slashes"):
        person_input("a/b", photos)
    with_clip = person_input("ada", [*photos, InputItem(tmp_path / "c.mp4", "video")])
    assert with_clip.files[-1] == tmp_path / "c.mp4"


def test_a_clips_frames_are_photos_of_the_person(tmp_path):
    """``--person NAME clip.mp4 photo.png``: the clip's frames, spread over it as a clip's fit takes them, are
    photos of their own, named by their index in the clip."""
    import imageio.v2 as imageio

    from deface.batch.task import person_photos

    clip = tmp_path / "c.mp4"
    with imageio.get_writer(str(clip), fps=5, quality=9, macro_block_size=1) as writer:
        for level in range(10):
            writer.append_data(np.full((32, 48, 3), 20 * level, dtype=np.uint8))
    config = FitConfig(max_frames=4)
    photos = person_photos(clip, config)
    assert [source for source, _ in photos] == [f"{clip}#{index}" for index in (0, 3, 6, 9)]
    levels = [float(photo.mean()) for _, (photo, found) in photos]
    assert all(found is None for _, (_, found) in photos) and levels == sorted(levels)  # in the clip's order
    assert photos[0][1][0].shape == (32, 48, 3)


def test_the_person_is_the_photos_most_others_are_close_to():
    close, far = 0.3, 0.9
    three = np.array([[0, far, close], [far, 0, far], [close, far, 0]])  # photos 0 and 2 alike, 1 someone else
    assert one_person(three, 0.7) == (0, [1])
    assert one_person(np.array([[0, far], [far, 0]]), 0.7) == (0, [1])  # two people: the first given is the person
    assert one_person(np.full((4, 4), close) - np.eye(4) * close, 0.7) == (0, [])
    majority = np.array([[0, far, far], [far, 0, close], [far, close, 0]])  # the first photo is the odd one out
    assert one_person(majority, 0.7) == (1, [0])


class _Said(FitLog):
    def __init__(self):
        super().__init__(quiet=True)
        self.said = []

    def info(self, message: str) -> None:
        self.said.append(message)


@pytest.mark.slow  # MediaPipe and dlib on three photos: about 5 s
def test_a_photo_of_another_person_is_left_out_in_one_line():
    """Two photos of Obama and one of Biden (benchmarks/board/photos, SOURCES.md there): Biden's is left out and
    said; with the check off all three stay."""
    pytest.importorskip("dlib")
    from pathlib import Path

    from deface.io.images import load_image
    from deface.landmarks.detect import detect_landmarks

    folder = Path(__file__).parents[1] / "benchmarks" / "board" / "photos"
    photos = []
    for name in ("obama.jpg", "biden.jpg", "obama_speech.jpg"):
        image = load_image(folder / name)
        photos.append((image, detect_landmarks(image), name))
    log = _Said()
    kept = photos_of_one_person(photos, SamePersonConfig(), log)
    assert [name for *_, name in kept] == ["obama.jpg", "obama_speech.jpg"]
    assert len(log.said) == 1 and log.said[0].startswith("biden.jpg: another person's face than in obama.jpg")
    assert photos_of_one_person(photos, SamePersonConfig(enabled=False), log) == photos


def test_without_dlib_the_photos_are_kept_and_the_fit_says_they_were_not_checked(monkeypatch):
    from deface.landmarks import identity

    monkeypatch.setattr(identity, "unavailable_reason", lambda: "dlib is not installed")
    photos = [(np.zeros((8, 8, 3)), None, name) for name in "ab"]
    log = _Said()
    assert photos_of_one_person(photos, SamePersonConfig(), log) == photos
    assert log.said == ["the photos are not checked for another person's face: dlib is not installed"]
    with pytest.raises(ValueError, match="same_person.distance"):
        SamePersonConfig(distance=0)


@pytest.mark.slow
def test_fit_person_leaves_out_a_photo_without_a_face_and_reloads(shared, photos, tmp_path):
    """Two renders of one albedo, a blank photo and another person's photo: one fit of the two, the blank one and
    the other person's said and recorded; the fit reloads and relights."""
    from PIL import Image

    from deface.eval.benchmark import SCHEDULES
    from deface.export.load import load_fit

    images = shared / "data" / "detail-synth" / "images"
    Image.new("RGB", (200, 150), (128, 128, 128)).save(tmp_path / "blank.png")
    other = [str(photos / "nextface-s5.png")] if identity_available() else []  # told apart by dlib's descriptor
    args = ["fit", "--person", "ada", str(images / "ita30_even.png"), str(images / "ita30_key.png"),
            str(tmp_path / "blank.png"), *other, "-o", str(tmp_path / "out")]
    args += [f"--set={path}={value}" for path, value in SCHEDULES["smoke"].items()]
    args += ["--set=registration.enabled=true"]  # the photos' UVs brought into register, written and reloaded
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    folder = tmp_path / "out" / "ada"
    params = json.loads((folder / "params.json").read_text())
    assert sum("registered to the others" in note for note in params["notes"]) == 2
    record = params["input"]
    assert record["kind"] == "person" and [p["path"] for p in record["photos"]] == [
        str(images / "ita30_even.png"), str(images / "ita30_key.png")]
    assert record["left_out"] == [str(tmp_path / "blank.png"), *other]
    assert ("another person's face" in result.output) == bool(other)
    side = params["camera"]["width"]
    assert params["camera"]["principal_point"] == [side / 2, side / 2] and "input.photos" in params["camera"]["pixels"]
    for photo in record["photos"]:  # each frame's camera in its photo's pixels: the working focal x square / side
        square = photo["box"][2] - photo["box"][0]
        assert photo["camera"]["focal_px"] == pytest.approx(params["camera"]["focal_px"] * square / side, rel=1e-3)
    page = (folder / "report.html").read_text()
    for frame, photo in (("000", "report/input.png"), ("001", "report/input_001.png")):
        assert (folder / "frames" / frame / "render.png").is_file() and (folder / photo).is_file()
        assert f"frames/{frame}/render.png" in page and photo in page  # every photo beside its fit
    per_photo = params["illuminant"]["per_photo"]  # each photo's own white level (tone.white_per_photo)
    assert len(per_photo) == 2 and params["illuminant"]["white"] == per_photo[0]["white"]
    fit = load_fit(folder)
    assert len(fit.frames) == 2 and [e.record() for e in fit.photo_illuminants] == per_photo
    relit = CliRunner().invoke(app, ["relight", str(folder), "--light", "studio", "-o", str(tmp_path / "relit")])
    assert relit.exit_code == 0, relit.output
    assert any((tmp_path / "relit").rglob("*.png"))


@pytest.mark.slow
def test_a_person_with_no_face_in_any_photo_is_one_line(tmp_path):
    from PIL import Image

    for name in "ab":
        Image.new("RGB", (120, 90), (90, 90, 90)).save(tmp_path / f"{name}.png")
    result = CliRunner().invoke(app, ["fit", "--person", "bob", str(tmp_path / "a.png"), str(tmp_path / "b.png"),
                                      "-o", str(tmp_path / "out")])
    assert result.exit_code == 1
    assert "none of the 2 photos has a face" in result.output
    assert not (tmp_path / "out" / "bob" / "params.json").exists()


def test_a_card_box_with_several_photos_is_one_line(tmp_path):
    """A box in one photo's pixels says nothing of where a card is in the others' crops: refused, with the way that
    works (the card's photo fitted alone, its white level given with --white)."""
    from PIL import Image

    for name in "ab":
        Image.new("RGB", (120, 90), (90, 90, 90)).save(tmp_path / f"{name}.png")
    result = CliRunner().invoke(app, ["fit", "--person", "bob", str(tmp_path / "a.png"), str(tmp_path / "b.png"),
                                      "--card", "0,0,10,10", "-o", str(tmp_path / "out")])
    assert result.exit_code == 1
    assert "--card with several photos" in result.output and "--white" in result.output
    assert not (tmp_path / "out" / "bob" / "params.json").exists()


def test_people_are_folders_and_person_takes_every_photo(tmp_path):
    from deface.cli.fit import people_inputs
    from deface.fit.user_options import UsageError

    for person, names in (("ada", "ab"), ("bob", "c")):
        (tmp_path / person).mkdir()
        for name in names:
            (tmp_path / person / f"{name}.jpg").write_bytes(b"")
    people = people_inputs([tmp_path / "ada", tmp_path / "bob"], None, True)
    assert [(item.name, [p.name for p in item.photos]) for item in people] == [("ada", ["a.jpg", "b.jpg"]),
                                                                                ("bob", ["c.jpg"])]
    one = people_inputs([tmp_path / "ada", tmp_path / "bob" / "c.jpg"], "eve", False)
    assert len(one) == 1 and one[0].name == "eve" and len(one[0].photos) == 3
    assert [item.name for item in people_inputs([tmp_path / "ada"], None, False)] == ["a", "b"]
    with pytest.raises(InputError, match="folders, one per person"):
        people_inputs([tmp_path / "bob" / "c.jpg"], None, True)
    with pytest.raises(UsageError, match="give one"):
        people_inputs([tmp_path / "ada"], "eve", True)


def test_the_web_page_fits_a_jobs_photos_as_one_person_and_a_clip_on_its_own(tmp_path):
    from deface.web.uploads import PERSON, one_person, stage_uploads

    uploads = []
    for name in ("front.jpg", "side.png", "walk.mp4"):
        (tmp_path / name).write_bytes(b"x")
        uploads.append(tmp_path / name)
    staged = stage_uploads(uploads, tmp_path / "job", 10)
    pairs = one_person(staged)
    assert [(shown, item.kind, item.name) for shown, item in pairs] == [
        ("front.jpg + side.png", "person", PERSON), ("walk.mp4", "video", "walk")]
    assert [path.name for path in pairs[0][1].photos] == ["front.jpg", "side.png"]
    alone = one_person(stage_uploads(uploads[:1], tmp_path / "job2", 10))
    assert [(shown, item.kind) for shown, item in alone] == [("front.jpg", "image")]  # one photo: a plain fit


def test_each_photo_chooses_among_its_own_lights_only():
    import torch

    from deface.fit.config import DecoupleConfig
    from deface.fit.decoupling import Decoupling

    torch.manual_seed(0)
    coverage = torch.ones(12, 10)
    grouped = Decoupling(DecoupleConfig(), num_lights=6, num_frames=2, size=(10, 12), light_groups=(0, 1))
    shared = Decoupling(DecoupleConfig(), num_lights=6, num_frames=2, size=(10, 12))
    shared.load_state_dict(grouped.state_dict())
    for frame, own in ((0, slice(0, 3)), (1, slice(3, 6))):
        masks = grouped.light_masks(frame, coverage).detach()
        others = torch.ones(6, dtype=torch.bool)
        others[own] = False
        assert masks.shape == (6, 12, 10) and float(masks[others].abs().max()) == 0.0
        torch.testing.assert_close(masks.sum(0), coverage)
        # within its group, the shared field's masks renormalised over the group (softmax over a subset)
        plain = shared.light_masks(frame, coverage).detach()[own]
        torch.testing.assert_close(masks[own], plain / plain.sum(0, keepdim=True))


def test_ace_judges_each_photos_lights_on_its_own_frames():
    import torch

    from deface.fit.config import DecoupleConfig
    from deface.fit.decoupling import Decoupling

    frames, lights = 4, 8  # four photos of two lights each
    decoupling = Decoupling(DecoupleConfig(epsilon=0.3, light_masks=False), lights, frames, (4, 4),
                            light_groups=(0, 1, 2, 3))
    masks = torch.zeros(frames, lights, 4, 4)
    for frame in range(frames):
        masks[frame, 2 * frame] = 0.8  # each photo: its first light lit most of the face
        masks[frame, 2 * frame + 1] = 0.2
    kept = decoupling.run_ace(masks, torch.ones(frames, 4, 4))
    # pooled over all frames each light covers at most 0.2 of the face and none would pass epsilon 0.3
    assert kept == [0, 2, 4, 6]
    for frame in range(frames):
        masks_now = decoupling.light_masks(frame, torch.ones(4, 4))
        assert masks_now.shape[0] == 4 and float(masks_now[frame].min()) == 1.0  # its one kept light, whole


def _truth_folder(tmp_path, rows: list[str], header: str):
    from PIL import Image

    for sub in ("images", "albedo"):
        (tmp_path / sub).mkdir(parents=True)
    for row in rows:
        file = row.split("\t")[0]
        Image.new("RGB", (8, 8)).save(tmp_path / "images" / file)
        Image.new("RGB", (8, 8)).save(tmp_path / "albedo" / f"{file.split('_')[0]}.png")
    (tmp_path / "MANIFEST.tsv").write_text("\n".join([header, *rows]) + "\n")
    return tmp_path


def test_a_truth_folders_sets_are_its_albedos_and_set_column(tmp_path):
    from deface.eval.person_benchmark import read_truth_sets

    sets = read_truth_sets(_truth_folder(tmp_path / "a", ["x_s1_1.png\tx\tone", "x_s1_2.png\tx\tone",
                                                          "x_s2_1.png\tx\ttwo", "y_s1_1.png\ty\tone"],
                                         "file\ttone\tset"))
    assert [(s.stem, [r.file for r in s.renders]) for s in sets] == [
        ("x_one", ["x_s1_1.png", "x_s1_2.png"]), ("x_two", ["x_s2_1.png"]), ("y_one", ["y_s1_1.png"])]
    plain = read_truth_sets(_truth_folder(tmp_path / "b", ["x_even.png\tx", "x_key.png\tx", "y_even.png\ty"],
                                          "file\ttone"))
    assert [(s.stem, len(s.renders)) for s in plain] == [("x_all", 2), ("y_all", 1)]


def test_a_sets_table_row_holds_the_set_beside_its_photos_alone():
    from deface.eval.person_benchmark import set_line, sets_markdown

    def scores(psnr, kept):
        return {"face": {"psnr": psnr, "colour_error": 2.0}, "beard": {"darkness_kept": kept, "fine_structure": 0.1}}

    record = {"scores": scores(30.0, 0.9), "alone": {"a": scores(27.0, 0.5), "b": scores(28.0, 0.7)},
              "photos": ["a.png", "b.png"], "seconds": 12.0, "surface_cm": 0.2,
              "alone_surface_cm": {"a": 0.4, "b": 0.3}}
    row = [line for line in sets_markdown({"default": {"x_one": record}}, "t", "cmd").splitlines()
           if line.startswith("| default")][0]
    assert "| 30.00 | 28.00 / 27.50 |" in row and "0.90 (0.60)" in row and "0.20 (0.35)" in row
    assert "best 28.00, mean 27.50" in set_line("x", record)
