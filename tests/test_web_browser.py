"""The web app in a real browser: `deface serve` on a free port, Debian's chromium driven headless by Playwright
(through its executable path: nothing downloads a browser), a photo uploaded and fitted on a very short schedule.
Checks that the page shows the fit's progress, draws the textured head in the 3D viewer (pixels read from the
canvas), shows the maps, relights on a preset change and downloads the zip; that the page asks for nothing but
the server (every other request is blocked and recorded); and that the server writes only inside its output
folder. A screenshot of the page is written beside the test's files (``page.png``)."""

from __future__ import annotations

import io
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.request
import zipfile
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

pytest.importorskip("gradio", reason="the web extra is not installed (pip install 'deface[web]'; .ci/run installs it)")
pytest.importorskip("playwright", reason="playwright is not installed (the dev extra; .ci/run installs it)")

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
         "--disable-component-update", "--disable-sync"]
SCHEDULE = ["--iterations", "10,10,4", "--resolution", "64", "--texture-size", "128"]
PHOTO = "nextface-s1.png"
VIEWER_BACKGROUND = np.array([0.16, 0.16, 0.18]) * 255  # the viewer's clear colour (deface/web/app.py)


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


# A real browser against a running server: slow (deface/web is covered without one by test_web_app.py).
pytestmark = pytest.mark.slow

@pytest.fixture(scope="module")
def server(tmp_path_factory, shared):
    """`deface serve` in its own process, in an empty working directory with its own temp directory."""
    if CHROMIUM is None:
        pytest.skip("chromium is not installed (apt-get install chromium; .ci/run installs it)")
    root = tmp_path_factory.mktemp("serve")
    for name in ("cwd", "tmp"):
        (root / name).mkdir()
    port = free_port()
    env = {**os.environ, "TMPDIR": str(root / "tmp"), "PYTHONUNBUFFERED": "1"}
    log = (root / "server.log").open("w")
    process = subprocess.Popen([sys.executable, "-m", "deface.cli.main", "serve", "-o", str(root / "out"),
                                "--port", str(port), "--workers", "1", *SCHEDULE],
                               cwd=root / "cwd", env=env, stdout=log, stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 120
    while True:
        try:
            urllib.request.urlopen(url, timeout=2).close()
            break
        except OSError:
            assert process.poll() is None, (root / "server.log").read_text()
            assert time.monotonic() < deadline, "deface serve did not answer in 120 s"
            time.sleep(0.5)
    yield url, root, process
    if process.poll() is None:
        process.send_signal(signal.SIGTERM)
        process.wait(90)
    log.close()


@pytest.fixture(scope="module")
def browser_page(server, tmp_path_factory):
    from playwright.sync_api import sync_playwright

    url, _root, _process = server
    profile = tmp_path_factory.mktemp("profile")
    with sync_playwright() as playwright:
        context = playwright.chromium.launch_persistent_context(
            str(profile), executable_path=CHROMIUM, headless=True, args=FLAGS, accept_downloads=True,
            viewport={"width": 1400, "height": 1000})
        page = context.pages[0] if context.pages else context.new_page()
        external, errors = [], []

        def only_the_server(route):
            request = route.request.url
            if request.startswith((url, "data:", "blob:")):
                route.continue_()
            else:
                external.append(request)
                route.abort()

        page.route("**/*", only_the_server)
        page.on("pageerror", lambda error: errors.append(str(error)))
        page.goto(url)
        page.wait_for_selector("#fit", timeout=60_000)
        yield page, external, errors
        context.close()


@pytest.fixture(scope="module")
def fitted(browser_page, photos):
    """Upload the photo, try the grey-card box (then clear it), pick the fast preset, fit; the status texts seen."""
    page, _, _ = browser_page
    page.locator("#uploads input[type=file]").set_input_files(str(photos / PHOTO))
    page.get_by_text("Grey card (optional)").click()
    card = page.locator("#card img")
    card.wait_for(timeout=30_000)
    card.click(position=on_image(card, 0.2, 0.7))
    page.wait_for_timeout(1500)
    card.click(position=on_image(card, 0.4, 0.9))
    box_field = page.locator("#card-box textarea")
    page.wait_for_function("() => document.querySelector('#card-box textarea').value.split(',').length === 4",
                           timeout=30_000)
    card_box = [float(v) for v in box_field.input_value().split(",")]
    page.get_by_role("button", name="Clear the box").click()
    page.wait_for_function("() => document.querySelector('#card-box textarea').value === ''", timeout=30_000)
    page.locator("#preset input").click()
    page.get_by_role("option", name="fast: a quick preview").click()
    page.locator("#fit").click()
    seen, deadline = [], time.monotonic() + 300
    while "finished" not in (text := page.locator("#status").inner_text()):
        seen.append(text)
        assert time.monotonic() < deadline, seen[-5:]
        page.wait_for_timeout(500)
    seen.append(text)
    page.locator("#download").wait_for(state="visible", timeout=60_000)
    return page, seen, card_box


def on_image(image, x: float, y: float) -> dict:
    """The point at fractions (x, y) of the picture an ``<img>`` shows, in the element's own coordinates (the
    picture is letterboxed in its element: object-fit contain)."""
    width, height, natural_width, natural_height = image.evaluate(
        "i => [i.clientWidth, i.clientHeight, i.naturalWidth, i.naturalHeight]")
    scale = min(width / natural_width, height / natural_height)
    left, top = (width - natural_width * scale) / 2, (height - natural_height * scale) / 2
    return {"x": left + x * natural_width * scale, "y": top + y * natural_height * scale}


def test_the_grey_card_box_is_drawn_by_two_clicks(fitted):
    _, _, card_box = fitted
    left, top, right, bottom = card_box
    assert left == pytest.approx(0.2, abs=0.03) and right == pytest.approx(0.4, abs=0.03)
    assert top == pytest.approx(0.7, abs=0.03) and bottom == pytest.approx(0.9, abs=0.03)


def test_the_page_shows_the_progress_and_the_result(fitted):
    _, seen, _ = fitted
    assert any("Job 1 (1 file, preset fast)" in text for text in seen)
    assert any(word in text for text in seen[:-1] for word in ("starting", "stage", "waiting", "writing"))
    assert "finished, 1 done, 0 failed" in seen[-1] and "nextface-s1.png: done in" in seen[-1]


def test_the_3d_viewer_draws_the_head(fitted, tmp_path):
    page, _, _ = fitted
    canvas = page.locator("#viewer canvas")
    canvas.wait_for(timeout=60_000)
    deadline, drawn = time.monotonic() + 90, 0.0
    while time.monotonic() < deadline:
        pixels = np.asarray(Image.open(io.BytesIO(canvas.screenshot())).convert("RGB"), dtype=np.float64)
        # share of pixels that are not the viewer's background: the head (babylon draws once the GLB is loaded)
        drawn = float((np.abs(pixels - VIEWER_BACKGROUND).max(-1) > 30).mean())
        if drawn > 0.05:
            break
        page.wait_for_timeout(1000)
    Image.fromarray(pixels.astype(np.uint8)).save(tmp_path / "viewer.png")
    assert drawn > 0.05, f"the 3D viewer's canvas is blank ({drawn:.1%} drawn; {tmp_path / 'viewer.png'})"
    height, width = pixels.shape[:2]
    centre = pixels[height // 3: 2 * height // 3, width // 3: 2 * width // 3]
    assert centre.std() > 10  # a textured face in the middle, not a flat fill


def test_the_maps_are_shown(fitted):
    page, _, _ = fitted
    page.wait_for_function("() => document.querySelectorAll('#maps img').length >= 4 && Array.from("
                           "document.querySelectorAll('#maps img')).every(i => i.complete && i.naturalWidth > 0)",
                           timeout=60_000)
    captions = page.locator("#maps").inner_text()
    for name in ("diffuse", "specular", "roughness", "confidence"):
        assert name in captions


def relit_image(page) -> np.ndarray:
    source = page.locator("#relit img").get_attribute("src")
    return np.asarray(Image.open(io.BytesIO(page.request.get(source).body())).convert("RGB"), dtype=np.int32)


def test_a_relight_preset_changes_the_relit_image(fitted):
    page, _, _ = fitted
    page.locator("#relit img").wait_for(timeout=60_000)
    before_source = page.locator("#relit img").get_attribute("src")
    studio = relit_image(page)
    page.locator("#light input").click()
    page.get_by_role("option", name="sun", exact=True).click()
    page.wait_for_function(f"() => document.querySelector('#relit img') && "
                           f"document.querySelector('#relit img').getAttribute('src') !== {before_source!r}",
                           timeout=60_000)
    sun = relit_image(page)
    assert sun.shape == studio.shape
    assert np.abs(sun - studio).mean() > 1.0


def test_the_zip_downloads_with_the_fit_files(fitted, tmp_path):
    page, _, _ = fitted
    with page.expect_download(timeout=60_000) as download:
        page.locator("#download").click()
    path = tmp_path / "result.zip"
    download.value.save_as(path)
    with zipfile.ZipFile(path) as archive:
        names = set(archive.namelist())
    stem = Path(PHOTO).stem
    for part in ("mesh.glb", "mesh.obj", "mesh.mtl", "params.json", "params.npz", "textures/diffuse.png",
                 "render.png", "report.html"):
        assert f"{stem}/{part}" in names


def test_a_screenshot_of_the_page(fitted, browser_page, tmp_path_factory):
    page, external, errors = browser_page
    page.wait_for_timeout(1000)
    shot = tmp_path_factory.getbasetemp() / "page.png"
    page.screenshot(path=str(shot), full_page=True)
    pixels = np.asarray(Image.open(shot).convert("RGB"))
    assert pixels.shape[0] > 1000 and pixels.std() > 20
    assert external == [], f"the page asked for other hosts: {external}"
    assert errors == [], errors


def test_the_server_writes_only_inside_its_output_folder_and_stops_cleanly(fitted, server):
    _url, root, process = server
    process.send_signal(signal.SIGTERM)
    assert process.wait(90) == 0, (root / "server.log").read_text()
    assert list((root / "cwd").iterdir()) == []
    # torch makes its (empty) compile-cache folder in the temp folder on import, as under `deface fit`
    assert [p.name for p in (root / "tmp").iterdir() if not p.name.startswith("torchinductor_")] == []
    output = root / "out"
    jobs = [p for p in output.iterdir() if not p.name.startswith(".")]
    assert len(jobs) == 1 and (jobs[0] / "nextface-s1" / "params.json").is_file()
    assert (output / ".gradio").is_dir()  # Gradio's uploads and the copies it served
