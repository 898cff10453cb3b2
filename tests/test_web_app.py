"""The web app's handlers without a browser (deface/web): a photo through the page's own functions gives the zip of
what `deface fit` writes for the same settings; a faceless photo, a broken file and an unsupported type each give
one line while the app goes on serving; a second job waits behind the first and says so; the relight handler
re-renders the loaded fit; the grey card's box reaches the fit's config. The fits use a very short schedule."""

from __future__ import annotations

import json
import os
import re
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

pytest.importorskip("gradio", reason="the web extra is not installed (pip install 'deface[web]'; .ci/run installs it)")

from typer.testing import CliRunner  # noqa: E402

from deface.cli.main import app as cli  # noqa: E402
from deface.web.config import WebConfig  # noqa: E402
from deface.web.serve import offline_environment  # noqa: E402
from deface.web.uploads import box_from_corners, parse_box  # noqa: E402

SCHEDULE = {"iterations": "10,10,4", "resolution": 64, "texture_size": 128}
CLI_SCHEDULE = ["--iterations", "10,10,4", "--resolution", "64", "--texture-size", "128"]
PHOTO, PHOTO2 = "nextface-s1.png", "nextface-s2.png"
CARD = "grey card (18 %)"
BAD = ("coffee.png", "cups.mp4", "broken.jpg", "notes.txt")
VOLATILE = re.compile(r"\d+(\.\d+)? s\b")  # durations in the log's notes and the report


@pytest.fixture(scope="module")
def web(tmp_path_factory, shared):
    output = tmp_path_factory.mktemp("web")
    saved = dict(os.environ)
    offline_environment(output)  # before Gradio is imported: its uploads and copies go under OUT
    from deface.web.app import WebApp

    page = WebApp(WebConfig(output, workers=1, **SCHEDULE))
    yield page
    page.service.close()
    os.environ.clear()
    os.environ.update(saved)


def wait(page, jobs: list[str], seconds: float = 300) -> None:
    deadline = time.monotonic() + seconds
    while page._unfinished(jobs):
        assert time.monotonic() < deadline, page.status_text(jobs)
        time.sleep(0.5)


@pytest.fixture(scope="module")
def bad_files(tmp_path_factory):
    import imageio.v2 as imageio
    from skimage import data

    folder = tmp_path_factory.mktemp("bad")
    Image.fromarray(data.coffee()).save(folder / "coffee.png")  # a real photo without a face
    with imageio.get_writer(str(folder / "cups.mp4"), format="FFMPEG", fps=4, macro_block_size=1) as clip:
        for shift in range(4):  # a clip without a face in any frame
            clip.append_data(np.roll(data.coffee()[:256, :384], 8 * shift, axis=1))
    (folder / "broken.jpg").write_bytes(b"\xff\xd8\xff\xe0 not really a jpeg")
    (folder / "notes.txt").write_text("not a photo")
    return [str(folder / name) for name in BAD]


@pytest.fixture(scope="module")
def jobs(web, photos, bad_files):
    """A job of bad files, and a job of two photos queued behind it."""
    bad = web.submit(bad_files, "fast", "", CARD, [])
    good = web.submit([str(photos / PHOTO), str(photos / PHOTO2)], "fast", "", CARD, bad[web.jobs])
    ids = good[web.jobs]
    waiting = good[web.status]
    wait(web, ids)
    return ids, waiting


@pytest.mark.slow  # a module fixture of whole fits
def test_the_second_job_waits_and_the_page_says_so(jobs):
    _, waiting = jobs
    assert "**Job 2** (2 files, preset fast): waiting, 1 job ahead of yours" in waiting


@pytest.mark.slow  # a module fixture of whole fits
def test_faceless_broken_and_unsupported_files_get_one_line_each(web, jobs):
    ids, _ = jobs
    status = web.status_text(ids)
    job = status.split("**Job 2**")[0]
    lines = {name: next(line for line in job.splitlines() if name in line) for name in BAD}
    assert "no face" in lines["coffee.png"].lower() and "no face" in lines["cups.mp4"].lower()
    assert "broken.jpg" in lines["broken.jpg"] and "✗" in lines["broken.jpg"]
    assert "unsupported file type" in lines["notes.txt"]
    assert "finished, 0 done, 3 failed" in job
    assert str(web.config.output) not in status  # the uploaded names, never the server's paths
    for line in lines.values():
        assert "\n" not in line and len(line) < 400


@pytest.mark.slow  # a module fixture of whole fits
def test_a_photo_gives_the_zip_of_deface_fit(web, jobs, photos, tmp_path):
    ids, _ = jobs
    update = web.refresh(ids, {}, None)
    key = dict(update[web.result].choices)[f"{PHOTO} (job 2)"]
    shown = web.show(key, "studio", 0, 0, 0, ids)
    archive = Path(shown[web.download].value["path"])  # Gradio's copy, served from OUT/.gradio
    assert archive.is_file() and archive.is_relative_to(web.config.output / ".gradio")

    result = CliRunner().invoke(cli, ["fit", str(photos / PHOTO), "-o", str(tmp_path), "--preset", "fast",
                                      *CLI_SCHEDULE, "--jobs", "1", "--quiet"])
    assert result.exit_code == 0, result.output
    reference = tmp_path / Path(PHOTO).stem
    expected = sorted(str(p.relative_to(tmp_path)) for p in reference.rglob("*") if p.is_file())
    with zipfile.ZipFile(archive) as zipped:
        assert sorted(zipped.namelist()) == expected
        for name in expected:
            compare(name, zipped.read(name), (tmp_path / name).read_bytes())


def compare(name: str, ours: bytes, theirs: bytes) -> None:
    """Equal files, up to what differs between any two runs: durations, the input's path, npz zip dates."""
    if name.endswith(".npz"):
        import io

        with np.load(io.BytesIO(ours)) as a, np.load(io.BytesIO(theirs)) as b:
            assert sorted(a.files) == sorted(b.files), name
            for key in a.files:
                assert np.array_equal(a[key], b[key]), f"{name}: {key}"
    elif name.endswith("params.json"):
        a, b = json.loads(ours), json.loads(theirs)
        for record in (a, b):
            record.pop("seconds_per_stage")
            record["input"].pop("path")
            record["notes"] = [VOLATILE.sub("", note) for note in record["notes"]]
        assert a == b
    elif name.endswith(".html"):
        assert VOLATILE.sub("", ours.decode()) == VOLATILE.sub("", theirs.decode()), name
    else:
        assert ours == theirs, name


@pytest.mark.slow  # a module fixture of whole fits
def test_a_batch_lists_its_results_and_zips_them_all(web, jobs):
    ids, _ = jobs
    update = web.refresh(ids, {}, None)
    assert "**Job 2** (2 files, preset fast): finished, 2 done, 0 failed" in update[web.status]
    assert [label for label, _ in update[web.result].choices] == [f"{PHOTO} (job 2)", f"{PHOTO2} (job 2)"]
    assert update[web.result].value == update[web.result].choices[0][1] and update[web.results].visible
    assert update[web.timer].active is False  # nothing left to follow
    with zipfile.ZipFile(update[web.download_all].value["path"]) as archive:
        folders = {name.split("/")[0] for name in archive.namelist()}
    assert folders == {Path(PHOTO).stem, Path(PHOTO2).stem}
    again = web.refresh(ids, update[web.known], update[web.result].value)
    assert again[web.result] == {"__type__": "update"}  # unchanged: the page keeps its selection


@pytest.mark.slow  # a module fixture of whole fits
def test_the_page_shows_the_fit_and_relights_it(web, jobs):
    ids, _ = jobs
    key = web.refresh(ids, {}, None)[web.result].value
    shown = web.show(key, "studio", 0, 0, 0, ids)
    assert Path(shown[web.mesh]).name == "mesh.glb"
    assert [caption.split(":")[0] for _, caption in shown[web.maps]] == ["diffuse", "specular", "roughness",
                                                                         "confidence"]
    assert len(shown[web.lights]) % 2 == 0 and "lit sphere" in shown[web.lights][0][1]
    assert "Skin tone:" in shown[web.tone] and "ITA" in shown[web.tone]
    studio = shown[web.relit]
    sun = web.relight(key, "sun", 0, 0, 0, ids)[web.relit]
    turned = web.relight(key, "studio", 90, 30, 0, ids)[web.relit]
    assert studio.shape == sun.shape and studio.dtype == np.uint8
    assert np.abs(studio.astype(int) - sun.astype(int)).mean() > 1
    assert np.abs(studio.astype(int) - turned.astype(int)).mean() > 1
    assert web.relight(key, "studio", 0, 0, 0, ids)[web.relit].tobytes() == studio.tobytes()
    other_page = web.show(key, "studio", 0, 0, 0, [])  # a key from another page shows nothing
    assert all(value == {"__type__": "update"} for value in other_page.values())


@pytest.mark.slow  # a module fixture of whole fits
def test_a_job_folder_is_a_deface_fit_output_with_its_inputs_and_zips(web, jobs):
    output = web.config.output
    job = output / jobs[0][1]
    assert {p.name for p in job.iterdir()} >= {"inputs", "nextface-s1", "nextface-s1.zip", "nextface-s2",
                                               "nextface-s2.zip", "all.zip", "batch.jsonl", "index.html"}
    records = [json.loads(line) for line in (job / "batch.jsonl").read_text().splitlines()]
    assert [r["status"] for r in records] == ["done", "done"] and records[0]["engine"] == "local"


def test_bad_requests_are_one_line(web):
    update = web.submit(None, "fast", "", CARD, [])
    assert "no file" in update[web.status]
    update = web.submit(["x.png"], "fast", "0.5, 0.1", CARD, [])
    assert "four fractions" in update[web.status]
    update = web.submit(["x.png"], "nonsense", "", CARD, [])
    assert "preset must be one of" in update[web.status]


def test_the_grey_card_box_reaches_the_fit(web):
    box = box_from_corners((100, 300), (20, 260), (200, 400))
    assert box == pytest.approx((0.1, 0.65, 0.505, 0.7525))
    assert parse_box("0.1, 0.65, 0.505, 0.7525") == pytest.approx(box)
    config = web.config.fit_config("default", box, 0.9)
    assert config.tone.illuminant.reference_box == pytest.approx(box, abs=1e-4)
    assert config.tone.illuminant.reference_reflectance == 0.9
    assert config.iterations.stage2 == 10 and config.resolution == 64


def hosted_module():
    import importlib.util

    spec = importlib.util.spec_from_file_location("hosted_app", Path(__file__).resolve().parents[1] / "app.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
def test_app_py_is_the_hosted_demo_on_localhost_unless_on_a_space(monkeypatch, tmp_path, shared):
    import signal
    import socket
    import subprocess
    import sys
    import urllib.error
    import urllib.request

    for name in ("SPACE_ID", "GRADIO_SERVER_NAME", "GRADIO_SERVER_PORT"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("DEFACE_WEB_OUTPUT", str(tmp_path / "out"))
    config = hosted_module().hosted_config()
    assert (config.host, config.port, config.workers, config.presets[0]) == ("127.0.0.1", 7860, 1, "fast")
    assert config.keep_jobs and config.max_file_mb <= 20
    config.check()
    monkeypatch.setenv("SPACE_ID", "someone/deface")
    assert hosted_module().hosted_config().host == "0.0.0.0"

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    env = {**os.environ, "GRADIO_SERVER_PORT": str(port)}
    env.pop("SPACE_ID")
    process = subprocess.Popen([sys.executable, str(Path(__file__).resolve().parents[1] / "app.py")], cwd=tmp_path,
                               env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 120
        while True:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/config", timeout=2) as response:
                    page = json.loads(response.read())
                break
            except OSError:
                assert process.poll() is None, process.stdout.read()
                assert time.monotonic() < deadline
                time.sleep(0.5)
        assert page["title"] == "deface" and "3D face" in json.dumps(page["components"])
        oversized = b"--edge\r\nContent-Disposition: form-data; name=\"files\"; filename=\"big.png\"\r\n\r\n" + \
            bytes(21 * 1024 * 1024) + b"\r\n--edge--\r\n"
        request = urllib.request.Request(f"http://127.0.0.1:{port}/gradio_api/upload", data=oversized,
                                         headers={"Content-Type": "multipart/form-data; boundary=edge"})
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(request, timeout=30)
        assert refused.value.code == 413  # the hosted demo's 20 MB limit, enforced by the server
    finally:
        process.send_signal(signal.SIGTERM)
        assert process.wait(60) == 0, process.stdout.read()
    assert (tmp_path / "out" / ".gradio").is_dir() and sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_serve_usage_errors_are_one_line(tmp_path):
    runner = CliRunner()
    for arguments, expected in ((["--set", "nonsense=1"], "nonsense"), (["--port", "0"], "--port must be"),
                                (["--workers", "999"], "--jobs must be"), (["--keep-jobs", "0"], "--keep-jobs")):
        result = runner.invoke(cli, ["serve", "-o", str(tmp_path / "out"), *arguments])
        assert result.exit_code == 2 and expected in result.output, result.output
        assert len(result.output.strip().splitlines()) == 1


def test_serve_without_the_web_extra_says_how_to_get_it(monkeypatch, tmp_path):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "gradio" else real(name, *a))
    result = CliRunner().invoke(cli, ["serve", "-o", str(tmp_path)])
    assert result.exit_code == 1 and "pip install 'deface[web]'" in result.output


def test_serve_on_a_taken_port_is_one_line(tmp_path, shared, monkeypatch):
    import socket

    monkeypatch.setattr(os, "environ", dict(os.environ))  # serve sets Gradio's environment: this test's only
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = CliRunner().invoke(cli, ["serve", "-o", str(tmp_path / "out"), "--port", str(port)])
    assert result.exit_code == 1, result.output
    assert f"cannot serve on 127.0.0.1:{port}" in result.output and len(result.output.strip().splitlines()) == 1
