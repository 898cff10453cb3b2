"""The web app's pieces that need neither Gradio nor a fit (deface/web): staging uploads, the grey card's box, the
skin tone in words, failures named by the uploaded file, and which job folders a hosted demo removes."""

from __future__ import annotations

from pathlib import Path

import pytest

from deface.io.images import InputError
from deface.io.inputs import InputItem
from deface.web.jobs import FitService, InputState, WebJob, page_error
from deface.web.results import tone_words, zip_folders
from deface.web.uploads import UploadError, draw_box, parse_box, preview, safe_stem, stage_uploads


def test_uploads_get_unique_safe_names_and_unsupported_ones_one_line(tmp_path):
    uploads = tmp_path / "uploads"
    for folder in ("a", "b"):
        (uploads / folder).mkdir(parents=True)
        (uploads / folder / "My photo.JPG").write_bytes(b"jpeg")
    (uploads / "a" / "clip.MP4").write_bytes(b"mp4")
    (uploads / "a" / "scan.gif").write_bytes(b"gif")
    (uploads / "a" / "README").write_bytes(b"text")
    staged = stage_uploads([uploads / "a" / "My photo.JPG", uploads / "b" / "My photo.JPG", uploads / "a" / "clip.MP4",
                            uploads / "a" / "scan.gif", uploads / "a" / "README"], tmp_path / "job", max_files=8)
    assert [item.path.name for item in staged.items] == ["My_photo.jpg", "My_photo-2.jpg", "clip.mp4"]
    assert [item.kind for item in staged.items] == ["image", "image", "video"]
    assert staged.files == ["My photo.JPG", "My photo.JPG", "clip.MP4"]
    assert all(item.path.parent == tmp_path / "job" / "inputs" for item in staged.items)
    assert staged.refused[0].startswith("scan.gif: unsupported file type '.gif' (photos .jpg")
    assert staged.refused[1].startswith("README: unsupported file type without an extension")
    with pytest.raises(UploadError, match="at most 2 per job"):
        stage_uploads([uploads / "a" / "clip.MP4"] * 3, tmp_path / "job2", max_files=2)
    assert safe_stem("../../etc/passwd") == "etc_passwd" and safe_stem("...") == "input"


def test_the_card_box_from_text_and_its_drawing(tmp_path):
    assert parse_box("") is None and parse_box(" 0.1, 0.2 ,0.3,0.4") == (0.1, 0.2, 0.3, 0.4)
    for text in ("0.1, 0.2, 0.3", "a, b, c, d", "0.3, 0.2, 0.1, 0.4", "0, 0, 1.5, 1"):
        with pytest.raises(ValueError, match="grey card box"):
            parse_box(text)
    import numpy as np

    image = np.zeros((40, 60, 3), np.uint8)
    drawn = draw_box(image, (0.25, 0.25, 0.75, 0.75))
    assert drawn[10, 30].any() and not drawn[20, 30].any()  # the outline, not the inside
    (tmp_path / "broken.png").write_bytes(b"\x89PNG not really")
    with pytest.raises(InputError, match=r"^broken.png: "):
        preview(tmp_path / "broken.png")


def test_the_skin_tone_in_words():
    open_range = tone_words({"texture_ita": 45.2, "ita_interval": [17.0, 59.0]}, {"source": "grey world"})
    assert open_range.startswith("**Skin tone: light** (ITA 45°")
    assert "tan (ITA 17°) to very light (59°)" in open_range and "grey card" in open_range
    card = tone_words({"texture_ita": 12.0, "ita_interval": [12.0, 12.0]}, {"source": "reference card"})
    assert "**Skin tone: tan**" in card and "grey card marked in the photo" in card
    held = tone_words({"texture_ita": 12.0, "ita_interval": [8.0, 16.0]}, {"source": "colour checker"})
    assert "colour checker found in the photo" in held and "ITA 8° to 16°" in held
    baseline = tone_words({"texture_ita": -40.0, "ita_interval": None}, None)
    assert "**Skin tone: dark**" in baseline and "no range" in baseline
    assert tone_words(None, None) == "Skin tone: not recorded for this fit."


def test_a_failure_names_the_uploaded_file_not_the_server_path(tmp_path):
    state = InputState("My photo.JPG", InputItem(tmp_path / "inputs" / "My_photo.jpg", "image"))
    assert page_error(f"{tmp_path}/inputs/My_photo.jpg: no face found", state) == "My photo.JPG: no face found"
    assert page_error("worker process died: SIGKILL", state) == "My photo.JPG: worker process died: SIGKILL"


def test_a_hosted_demo_keeps_only_the_newest_jobs_it_made(tmp_path):
    (tmp_path / "mine-not").mkdir()
    service = FitService(tmp_path, workers=1, keep_jobs=1)
    try:
        jobs = []
        for _ in range(3):
            job_id, folder = service.new_folder()
            jobs.append(service.submit(WebJob(job_id, folder, "fast", None, [])))  # nothing to fit: finished
        service._forget_old()
        assert [job.status for job in jobs] == ["removed", "removed", "finished"]
        assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["mine-not", jobs[2].id])
    finally:
        service.close()


def test_the_zip_holds_each_folder_under_its_name_and_appears_whole(tmp_path):
    import zipfile

    for name in ("a", "b"):
        (tmp_path / name / "textures").mkdir(parents=True)
        (tmp_path / name / "textures" / "diffuse.png").write_bytes(name.encode())
    path = zip_folders([tmp_path / "a", tmp_path / "b"], tmp_path / "all.zip")
    with zipfile.ZipFile(path) as archive:
        assert sorted(archive.namelist()) == ["a/textures/diffuse.png", "b/textures/diffuse.png"]
        assert archive.read("b/textures/diffuse.png") == b"b"
    assert not list(tmp_path.glob(".*partial"))
    with pytest.raises(OSError):
        zip_folders([tmp_path / "a"], tmp_path / "missing" / "x.zip")
    assert not (tmp_path / "missing").exists()
    assert Path(path).is_file()
