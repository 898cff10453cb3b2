"""End to end: the pipeline on a synthetic face with a real cast shadow, and `deface fit` on a photo."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from PIL import Image
from typer.testing import CliRunner

from deface.batch.record import read_records
from deface.cli.main import app
from deface.eval.synthetic import make_shadowed_face
from deface.fit import presets
from deface.fit.config import override
from deface.fit.log import FitLog
from deface.fit.pipeline import fit_target
from deface.fit.target import FitTarget
from deface.models import load_face_model
from deface.models.ita import ita_group
from deface.render.mesh import sample_texture

SHORT = {"iterations.stage1": 100, "iterations.stage2": 120, "iterations.stage3": 60,
         "decouple.ace_iteration": 40, "resolution": 96, "texture_size": 128, "render.shadow_rays": 64}


@pytest.fixture(scope="module")
def shadowed_face(shared):
    model = load_face_model("ict")
    return make_shadowed_face(model, size=96, seed=0, rays=64)


def _diffuse_error(face, diffuse: torch.Tensor, region: np.ndarray) -> float:
    """Mean absolute error of the recovered diffuse albedo at the texels seen by ``region``'s pixels, after
    one scale per channel that matches the lit texels' medians: this scene's background is not lit by the
    face's light, so it says nothing of the light's strength and the albedo's absolute scale is not
    identifiable from it (docs/skin-tone.md); a baked shadow shows as a darker patch at any scale."""
    def seen(texture, mask):
        return sample_texture(texture.detach(), torch.as_tensor(face.uv[mask]))

    lit = (face.coverage > 0.5) & ~face.shadow
    scale = seen(face.textures.diffuse, lit).median(0).values / seen(diffuse, lit).median(0).values
    return float((seen(diffuse, region) * scale - seen(face.textures.diffuse, region)).abs().mean())


def _fit(face, preset: str):
    config = override(presets.get(preset), **SHORT)
    target = FitTarget([face.image_srgb], [face.landmarks], 1.0)
    return fit_target(target, config, log=FitLog(quiet=True))


@pytest.mark.slow
def test_decoupling_keeps_cast_shadow_out_of_texture(shadowed_face):
    """The default preset's diffuse texture is clearly closer to the truth inside the brim's shadow than
    the single-light baseline's, which bakes the shadow in."""
    assert shadowed_face.shadow.sum() > 500  # the scene really has a sizeable cast shadow
    ours = _fit(shadowed_face, "default")
    baseline = _fit(shadowed_face, "nextface")
    ours_error = _diffuse_error(shadowed_face, ours.textures.diffuse, shadowed_face.shadow)
    baseline_error = _diffuse_error(shadowed_face, baseline.textures.diffuse, shadowed_face.shadow)
    assert len(ours.lights.kept) >= 2  # ACE kept a separate light for the shadow
    assert ours_error < 0.7 * baseline_error, (ours_error, baseline_error)


@pytest.mark.slow
def test_fits_are_deterministic_for_a_seed(shadowed_face):
    short = {**SHORT, "iterations.stage1": 30, "iterations.stage2": 12, "iterations.stage3": 4,
             "decouple.ace_iteration": 6, "resolution": 64, "texture_size": 64, "render.shadow_rays": 16}
    config = override(presets.get("default"), **short)
    small = [shadowed_face.image_srgb[::3, ::3].copy()]
    landmarks = shadowed_face.landmarks
    scaled = type(landmarks)(landmarks.points / 3, landmarks.depth / 3, (32, 32), 1, 0)
    runs = [fit_target(FitTarget(small, [scaled], 1 / 3), config, log=FitLog(quiet=True)) for _ in range(2)]
    assert torch.equal(runs[0].textures.diffuse, runs[1].textures.diffuse)
    assert torch.equal(runs[0].lights.sh, runs[1].lights.sh)


@pytest.mark.slow
def test_fit_command_writes_all_outputs(photos, tmp_path):
    """`deface fit` on a real photo (tiny iteration counts) writes every documented output."""
    result = CliRunner().invoke(app, ["fit", str(photos / "real-foliage-shadow-9177-004.png"), "-o", str(tmp_path),
                                      "--preset", "fast", "--iterations", "30,12,4", "--quiet"])
    assert result.exit_code == 0, result.output
    folder = tmp_path / "real-foliage-shadow-9177-004"
    params = json.loads((folder / "params.json").read_text())
    kept = params["lights"]["kept"]
    assert kept and set(params["lights"]["sh"]) == {str(k) for k in kept}
    assert params["preset"] == "fast" and params["optional_networks"]["facenet"].startswith("HP off")
    assert params["iterations_run"] == {"stage 2": 12, "stage 3": 4}
    expected = ["textures/diffuse.png", "textures/specular.png", "textures/roughness.png",
                "textures/confidence.png", "mesh.obj", "mesh.mtl",
                "mesh.glb", "params.npz", "render.png", "render_face.png", "masks/face.png", "loss_log.csv"]
    expected += [f"lights/{k}.png" for k in kept] + [f"masks/light_{k}.png" for k in kept]
    for name in expected:
        assert (folder / name).is_file(), name
    assert Image.open(folder / "textures/diffuse.png").size == (256, 256)
    confidence = np.load(folder / "params.npz")["confidence"].astype(np.float32)
    assert confidence.shape == (256, 256) and 0 <= confidence.min() and confidence.max() <= 1
    assert (confidence > 0.05).mean() > 0.05  # the photo shows a good part of the layout...
    assert confidence[:8].mean() < 0.1 * confidence[96:160].mean()  # ...but hardly the top of the head
    mtl = (folder / "mesh.mtl").read_text()
    assert "map_Kd textures/diffuse.png" in mtl and "map_Pr textures/roughness.png" in mtl
    assert not list(tmp_path.glob(".*partial"))  # no staging folder left behind
    # The batch record carries the texture's tone as params.json has it, and `deface batch status` counts it.
    tone = params["skin_tone"]
    keys = ("texture_ita", "ita_interval", "ita_interval_2sigma", "light_level")
    assert [r.skin_tone for r in read_records(tmp_path)] == [{k: tone[k] for k in keys}]
    status = CliRunner().invoke(app, ["batch", "status", str(tmp_path)])
    assert f"{ita_group(tone['texture_ita'])} 1" in status.output and "skin tones of 1 fit(s)" in status.output
    # A second run skips the finished input instead of redoing or destroying it.
    again = CliRunner().invoke(app, ["fit", str(photos / "real-foliage-shadow-9177-004.png"), "-o", str(tmp_path),
                                     "--preset", "fast", "--iterations", "30,12,4"])
    assert again.exit_code == 0 and "already done" in again.output
    assert "1 of 1 input(s) done, 0 failed" in again.output.splitlines()[-1]  # counted once, not twice


@pytest.mark.slow
def test_bad_inputs_fail_in_one_line_and_the_batch_goes_on(tmp_path, photos):
    broken = tmp_path / "broken.jpg"
    broken.write_bytes(b"not an image")
    blank = tmp_path / "blank.png"
    Image.fromarray(np.full((64, 64, 3), 127, np.uint8)).save(blank)
    out = tmp_path / "out"
    result = CliRunner().invoke(app, ["fit", str(broken), str(blank), "-o", str(out), "--preset", "fast",
                                      "--iterations", "5,3,2", "--quiet"])
    assert result.exit_code == 1
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 2 and "broken.jpg" in errors[0] and "no face" in errors[1]
    written = {p.name for p in out.iterdir()} if out.exists() else set()
    assert written <= {"batch.jsonl", "index.html", "batch-workers.log"}  # the record, nothing half-written


def test_unknown_preset_is_a_clear_error(tmp_path, photos):
    result = CliRunner().invoke(app, ["fit", str(photos / "000031.jpg"), "-o", str(tmp_path), "--preset", "nope"])
    assert result.exit_code == 2 and "unknown preset 'nope'" in result.output


@pytest.mark.slow
def test_fit_command_on_a_clip_shares_textures_and_writes_frames(shared, tmp_path):
    clip = shared / "data" / "videos" / "d18.mp4"
    result = CliRunner().invoke(app, ["fit", str(clip), "-o", str(tmp_path), "--preset", "fast",
                                      "--iterations", "20,4,2", "--max-frames", "2", "--quiet"])
    assert result.exit_code == 0, result.output
    folder = tmp_path / "d18"
    params = json.loads((folder / "params.json").read_text())
    assert len(params["frames"]) == 2 and params["frames"][0] == 0
    assert len(params["expression"]) == 2 and len(params["pose"]["rotation_axis_angle"]) == 2
    assert len(params["identity"]) == 100  # one shared identity
    for frame in ("000", "001"):
        assert (folder / "frames" / frame / "render.png").is_file()
        assert (folder / "frames" / frame / "masks" / "face.png").is_file()
    assert (folder / "textures" / "diffuse.png").is_file() and (folder / "mesh.obj").is_file()


def test_missing_bfm_files_are_reported_in_one_line(tmp_path, photos, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    result = CliRunner().invoke(app, ["fit", str(photos / "000031.jpg"), "-o", str(tmp_path / "out"),
                                      "--model", "bfm", "--quiet"])
    assert result.exit_code == 1
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "model2017-1_face12_nomouth.h5" in errors[0] and "bfm2017" in errors[0]
