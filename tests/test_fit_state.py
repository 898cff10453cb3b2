"""A fit as a reusable artifact: the typed stage state, FitOutput, load_fit, transfer, relight, turntable.

One tiny real fit of a synthetic face (the benchmark's 'smoke' schedule) is written once per module; the
tests reload it from its files and check properties against independent references (the PNGs written at
fit time, SH identities, OpenCV's HDR writer)."""

from __future__ import annotations

import csv
import dataclasses
import json
import math

import numpy as np
import pytest
import torch
from PIL import Image
from typer.testing import CliRunner

from deface.cli.main import app
from deface.eval.benchmark import SCHEDULES
from deface.eval.synthetic import make_shadowed_face
from deface.export.load import FitFormatError, load_fit
from deface.export.outputs import write_fit
from deface.fit import presets
from deface.fit.config import override
from deface.fit.log import FitLog
from deface.fit.pipeline import run_stages
from deface.fit.target import FitTarget
from deface.io.images import to_uint8
from deface.models import load_face_model
from deface.relight import lights as light_sources
from deface.relight.transfer import transfer_renders
from deface.relight.turntable import turntable_frames
from deface.render.sh import sh_basis
from deface.report.html import write_index, write_report


@pytest.fixture(scope="module")
def state(shared):
    face = make_shadowed_face(load_face_model("ict"), size=64, seed=0, rays=16)
    config = override(presets.get("default"), **SCHEDULES["smoke"])
    return run_stages(FitTarget([face.image_srgb], [face.landmarks], 1.0), config, log=FitLog(quiet=True))


@pytest.fixture(scope="module")
def written(state, tmp_path_factory):
    folder = tmp_path_factory.mktemp("fit") / "face"
    write_fit(state.output(), folder, {"path": "synthetic", "kind": "image", "frames": [0]}, page=write_report)
    return folder


def test_stage_results_carry_named_terms_that_sum_to_the_total(state):
    for result in (state.stage2, state.stage3):
        assert len(result.terms) == len(result.history)
        for terms, total in zip(result.terms, result.history, strict=True):
            assert "photometric" in terms
            assert sum(terms.values()) == pytest.approx(total, rel=1e-4, abs=1e-6)
    assert {"landmarks", "area", "binary"} <= set().union(*state.stage2.terms)
    names = set().union(*state.stage3.terms)
    assert "local_prior" not in names  # the default has no LP (deface/fit/presets.py): no term for it
    assert "texture_regularisers" in names


def test_a_stage_runs_alone_from_the_prepared_state(shared):
    """Stage 2 as a runner: the prepared context in, its result out; only the trainable parameters change."""
    import dataclasses

    from deface.fit.pipeline import prepare
    from deface.fit.stage2 import run_stage2

    face = make_shadowed_face(load_face_model("ict"), size=48, seed=1, rays=8)
    config = override(presets.get("default"), **{**SCHEDULES["smoke"], "iterations.stage2": 6,
                                                   "decouple.ace_iteration": 3})
    context, optional = prepare(FitTarget([face.image_srgb], [face.landmarks], 1.0), config)
    assert "face_parsing" in optional and dataclasses.is_dataclass(context) and len(context.inputs.face_classifier) == 1
    with pytest.raises(dataclasses.FrozenInstanceError):
        context.config = config
    before = context.scene.lights.detach().clone()
    result = run_stage2(context)
    assert len(result.history) == len(result.terms) == 6 and result.kept == context.decoupling.kept
    assert not torch.equal(before, context.scene.lights)


def test_loss_log_has_a_column_per_term(written):
    rows = list(csv.DictReader((written / "loss_log.csv").open()))
    assert {"stage", "step", "loss", "photometric", "landmarks"} <= set(rows[0])
    assert "texture_regularisers" in rows[0]
    for row in rows[:: max(1, len(rows) // 10)]:
        terms = [float(v) for k, v in row.items() if k not in ("stage", "step", "loss") and v]
        assert sum(terms) == pytest.approx(float(row["loss"]), rel=1e-3, abs=1e-5)


def test_output_is_frozen_and_renders_what_was_written(state, written):
    output = state.output()
    with pytest.raises(AttributeError):
        output.textures = None  # frozen dataclass
    face = to_uint8(output.render()[0].face.numpy(), srgb=True)
    assert np.array_equal(face, np.asarray(Image.open(written / "render_face.png")))
    own, again = output.renders[0], output.render()[0]  # the renders written are the re-render's, exactly
    for name in ("face", "light_masks", "face_region", "light_images"):
        assert torch.equal(getattr(own, name), getattr(again, name)), name


def test_load_fit_re_renders_the_fit_within_one_level(written):
    fit = load_fit(written)
    rendered = fit.render()[0]
    assert torch.equal(fit.renders[0].face, rendered.face)
    for image, name in ((rendered.face, "render_face.png"), (fit.composite(rendered, 0), "render.png")):
        ours = to_uint8(image.numpy(), srgb=True).astype(int)
        reference = np.asarray(Image.open(written / name)).astype(int)
        assert np.abs(ours - reference).max() <= 1, name
    params = json.loads((written / "params.json").read_text())
    assert list(fit.lights.kept) == params["lights"]["kept"]
    assert np.allclose(fit.pose.identity.numpy(), params["identity"])


def test_a_frames_registered_uvs_are_written_and_reloaded(state, tmp_path):
    """A frame whose UVs were moved into register (deface/fit/frame_register.py) is reloaded sampling the maps
    where it did, and re-renders as it was written."""
    import dataclasses

    from deface.fit.frame_register import with_uvs

    output = state.output()
    uvs = (output.frames[0].geometry.mesh.uvs + torch.tensor([0.01, -0.005])).clamp(0, 1)
    moved = dataclasses.replace(output, frames=(with_uvs(output.frames[0], uvs),))
    moved = dataclasses.replace(moved, renders=tuple(moved.render()))
    assert not torch.equal(moved.renders[0].face, output.renders[0].face)
    folder = tmp_path / "moved"
    write_fit(moved, folder, {"path": "synthetic", "kind": "image", "frames": [0]})
    fit = load_fit(folder)
    assert torch.allclose(fit.frames[0].geometry.mesh.uvs, uvs)
    assert torch.allclose(fit.render()[0].face, moved.renders[0].face, atol=2e-3)
    plain = tmp_path / "plain"
    write_fit(output, plain, {"path": "synthetic", "kind": "image", "frames": [0]})
    with np.load(plain / "params.npz") as arrays:
        assert "frame_uvs" not in arrays.files  # unmoved frames store nothing


def test_an_older_output_says_what_is_missing(written, tmp_path):
    old = tmp_path / "old"
    old.mkdir()
    (old / "params.json").write_text((written / "params.json").read_text())
    with np.load(written / "params.npz") as npz:  # format 1: the mesh, textures and masks only
        np.savez(old / "params.npz", **{k: npz[k] for k in ("vertices", "diffuse", "light_masks", "face_region")})
    with pytest.raises(FitFormatError, match="older deface .*format 1.* lacks the pose, lights"):
        load_fit(old)
    with pytest.raises(FitFormatError, match="not a deface fit"):
        load_fit(tmp_path)


def test_transfer_is_the_evaluation_swap_and_own_textures_give_the_fit(written, tmp_path):
    fit = load_fit(written)
    swapped = transfer_renders(fit, fit)[0]
    assert torch.equal(swapped.face, fit.render()[0].face)
    grey = type(fit.textures)(torch.full_like(fit.textures.diffuse, 0.5), fit.textures.specular,
                              fit.textures.roughness)
    other = dataclasses.replace(fit, textures=grey)
    assert not torch.equal(transfer_renders(other, fit)[0].face, swapped.face)
    result = CliRunner().invoke(app, ["transfer", str(written), str(written), "-o", str(tmp_path / "swap")])
    assert result.exit_code == 0, result.output
    rgba = np.asarray(Image.open(tmp_path / "swap" / "render_face.png"))
    assert rgba.shape[-1] == 4 and rgba[..., 3].max() == 255 and rgba[..., 3].min() == 0


def test_sh_rotation_moves_a_light_and_back():
    light = light_sources.preset_lights("sun", 5)
    turn = light_sources.yaw_matrix(70.0)
    turned = light_sources.rotate_lights(light, turn)
    direction = torch.tensor([[0.3, 0.5, 0.81]], dtype=torch.float64)
    direction = direction / direction.norm()
    basis = sh_basis(direction, 5)
    moved = sh_basis(direction @ torch.as_tensor(turn.T), 5)  # R d as a row vector
    assert torch.allclose(moved.float() @ turned[0], basis.float() @ light[0], atol=1e-4)
    back = light_sources.rotate_lights(turned, turn.T)
    assert torch.allclose(back, light, atol=1e-5)
    assert light_sources.yaw_matrix(90.0) @ np.array([0, 0, 1.0]) == pytest.approx([1.0, 0.0, 0.0])


def test_presets_are_normalised_and_point_where_documented():
    for name in light_sources.PRESETS:
        lights = light_sources.preset_lights(name, 4)
        assert lights.shape == (1, 16, 3) and torch.isfinite(lights).all()
        if name != "neutral":
            assert light_sources.diffuse_peak(lights) == pytest.approx(light_sources.LEVEL, rel=1e-3)
    y_index, z_index = 1, 2  # Y_1,-1 ~ y, Y_1,0 ~ z
    assert light_sources.preset_lights("sun", 3)[0, y_index].min() > 0  # from above
    assert light_sources.preset_lights("rim", 3)[0, z_index].max() < 0  # from behind
    with pytest.raises(light_sources.LightSourceError, match="neither a preset"):
        light_sources.light_source("candle", 3)


def test_environment_map_projection(tmp_path):
    directions, solid = light_sources.equirect_directions(64, 128)
    assert solid.sum() == pytest.approx(4 * math.pi, rel=1e-3)
    uniform = light_sources.project_to_sh(directions.reshape(-1, 3), np.ones((64 * 128, 3)), solid.reshape(-1), 3)
    assert uniform[0] == pytest.approx(torch.full((3,), math.sqrt(4 * math.pi)), rel=1e-3)
    assert uniform[1:].abs().max() < 1e-3
    image = np.full((32, 64, 3), 0.05, dtype=np.float32)
    image[12:20, 28:36] = 20.0  # a bright patch at the centre column: light from the camera's side (+z)
    cv2 = pytest.importorskip("cv2")
    assert cv2.imwrite(str(tmp_path / "env.hdr"), image[..., ::-1].copy())  # OpenCV's Radiance writer
    read = light_sources.read_environment_map(tmp_path / "env.hdr")
    assert read.shape == image.shape and np.allclose(read, image, rtol=0.02)
    lights = light_sources.light_source(str(tmp_path / "env.hdr"), 3)
    assert lights[0, 2].min() > 0 and lights[0, 2].min() > 5 * lights[0, [1, 3]].abs().max()


def test_relight_command_writes_composite_face_and_lights(written, tmp_path):
    fit = load_fit(written)
    sh_file = tmp_path / "light.npy"
    np.save(sh_file, light_sources.preset_lights("neutral", 2).numpy())  # fewer bands: padded with zeros
    for source in ("sun", str(sh_file), str(written / "params.json")):
        out = tmp_path / f"relit{len(source)}"
        result = CliRunner().invoke(app, ["relight", str(written), "-o", str(out), "--light", source,
                                          "--rotate-light", "30"])
        assert result.exit_code == 0, result.output
        assert (out / "render.png").is_file() and (out / "render_face.png").is_file()
        assert np.load(out / "lights.npy").shape[1:] == (fit.lights.bands**2, 3)
    own = CliRunner().invoke(app, ["relight", str(written), "-o", str(tmp_path / "own"), "--light",
                                   str(written / "params.json")])
    assert own.exit_code == 0
    # the fit's own lights, summed without masks, equal the fit's render where one light was kept
    if len(fit.lights.kept) == 1:
        face = np.asarray(Image.open(tmp_path / "own" / "render_face.png"))[..., :3].astype(int)
        assert np.abs(face - np.asarray(Image.open(written / "render_face.png")).astype(int)).max() <= 1
    bad = CliRunner().invoke(app, ["relight", str(written), "-o", str(tmp_path / "x"), "--light", "candle"])
    assert bad.exit_code == 2 and "neither a preset" in bad.output


def test_turntable_starts_at_the_fit_view_and_writes_video(written, tmp_path):
    fit = load_fit(written)
    lights = light_sources.preset_lights("studio", fit.lights.bands)
    first = turntable_frames(fit, lights, yaw_range=60.0, count=4)
    relit = fit.render(lights=lights)[0]
    alpha = relit.coverage[..., None]
    background = torch.tensor((0.18, 0.18, 0.2)) ** 2.2
    expected = to_uint8((relit.face + background * (1 - alpha)).numpy(), srgb=True).astype(int)
    assert np.abs(first[0].astype(int) - expected).max() <= 1  # yaw 0 is the fitted camera
    assert not np.array_equal(first[0], first[1])
    for suffix in (".mp4", ".gif"):
        path = tmp_path / f"spin{suffix}"
        result = CliRunner().invoke(app, ["turntable", str(written), "-o", str(path), "--frames", "4"])
        assert result.exit_code == 0, result.output
        if suffix == ".mp4":
            import imageio.v2 as imageio

            assert sum(1 for _ in imageio.get_reader(str(path), format="FFMPEG")) == 4
        else:
            import imageio.v3 as iio

            assert iio.imread(path).shape[0] == 4


def test_report_renders_in_chromium_with_every_image_and_no_console_message(written, tmp_path):
    """Debian's chromium (installed by .ci/run) opens report.html offline: all images decode (the page's own
    check sets data-images), the console stays silent, and a screenshot is taken."""
    import re
    import shutil
    import subprocess

    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        pytest.skip("chromium is not installed (.ci/run installs it)")
    page = (written / "report.html").resolve().as_uri()
    flags = [browser, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars", "--enable-logging=stderr",
             "--v=0", "--virtual-time-budget=8000", f"--user-data-dir={tmp_path / 'profile'}"]
    dom = subprocess.run([*flags, "--dump-dom", page], capture_output=True, text=True, timeout=180)
    images = len(re.findall(r"<img ", (written / "report.html").read_text()))
    assert f'data-images="ok {images}"' in dom.stdout, re.findall(r'data-images="[^"]*"', dom.stdout)
    assert not [line for line in dom.stderr.splitlines() if ":CONSOLE" in line], dom.stderr
    shot = tmp_path / "report.png"
    subprocess.run([*flags, "--window-size=1200,2400", f"--screenshot={shot}", page], capture_output=True,
                   timeout=180)
    pixels = np.asarray(Image.open(shot).convert("RGB"))
    assert pixels.shape[:2] == (2400, 1200) and pixels.std() > 10  # a page with content, not a blank one
    for part in ("report/losses.png", "report/turntable.gif", "report/neutral.png", "textures/diffuse.png"):
        assert (written / part).is_file(), part


def test_report_command_rewrites_the_report_of_a_loaded_fit(written, tmp_path):
    import shutil

    shutil.copytree(written, tmp_path / "copy")
    (tmp_path / "copy" / "report.html").unlink()
    result = CliRunner().invoke(app, ["report", str(tmp_path / "copy")])
    assert result.exit_code == 0, result.output
    page = (tmp_path / "copy" / "report.html").read_text()
    assert "report/losses.png" in page and "textures/diffuse.png" in page
    # the loaded fit's tone: the one params.json records, with the range its light level leaves open
    tone = json.loads((written / "params.json").read_text())["skin_tone"]
    darker, lighter = tone["ita_interval"]
    assert f"skin ITA {tone['texture_ita']:.0f}; {darker:.0f} to {lighter:.0f} for the light level" in page


def test_report_says_how_to_keep_a_beard_only_where_the_fit_weighed_it_as_shading(written):
    """The default weighs a beard's texture as shading evidence (it cannot tell a photo without cast shadows), so
    its page names the preset that keeps more of it; a fit with that preset's strength, or less, is not told."""
    from types import SimpleNamespace

    from deface.report.html import _detail_hint

    assert "--preset no-cast-shadows" in (written / "report.html").read_text()
    for name in ("no-cast-shadows", "paper"):
        assert _detail_hint(SimpleNamespace(config=presets.get(name))) == ""
    assert "no-cast-shadows" in _detail_hint(SimpleNamespace(config=presets.get("fast")))


def test_batch_index_links_each_report(photos, tmp_path, written):
    import shutil

    shutil.copytree(written, tmp_path / "a")
    index = write_index(tmp_path, ["a", "missing"]).read_text()
    assert 'href="a/report.html"' in index and "missing" not in index
    assert write_index(tmp_path, ["missing"]) is None
