"""Fault injection: bad option values, a full disk and denied permissions at write time, signals mid-fit and
mid-write with a resume, concurrent writers, stale staging folders, NaN in a stage, fuzzed input files.

Every case must end in one line per problem (no traceback) and leave earlier outputs intact. Tests about the
command line replace the fit by a real, tiny fit made once (``tiny_result``), so they take a second each.
"""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image
from typer.testing import CliRunner

import deface.batch.task as task
import deface.export.outputs as outputs
import deface.fit.stage2 as stage2
from deface.cli.main import app
from deface.eval.benchmark import SCHEDULES
from deface.eval.synthetic import make_shadowed_face
from deface.export.files import claimed_output, remove_stale, staged_directory
from deface.fit import presets
from deface.fit.config import override
from deface.fit.guard import NonFiniteError, StepGuard
from deface.fit.log import FitLog
from deface.fit.pipeline import fit_target
from deface.fit.target import FitTarget
from deface.io.images import load_image
from deface.io.inputs import IMAGE_EXTENSIONS, VIDEO_EXTENSIONS
from deface.models import load_face_model
from deface.paths import find_model_file

DRIVER = Path(__file__).with_name("fault_driver.py")
REPO = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def tiny_fit(shared):
    """A real fit of a synthetic face with the benchmark's 'smoke' schedule (a few seconds)."""
    face = make_shadowed_face(load_face_model("ict"), size=64, seed=0, rays=16)
    config = override(presets.get("default"), **SCHEDULES["smoke"])
    return face, config


@pytest.fixture(scope="module")
def tiny_result(tiny_fit):
    face, config = tiny_fit
    return fit_target(FitTarget([face.image_srgb], [face.landmarks], 1.0), config, log=FitLog(quiet=True))


@pytest.fixture
def photo(tmp_path) -> Path:
    path = tmp_path / "in" / "face.png"
    path.parent.mkdir()
    Image.fromarray(np.full((40, 30, 3), 120, np.uint8)).save(path)
    return path


@pytest.fixture
def fake_fit(monkeypatch, tiny_result):
    """`deface fit` with the fit itself replaced by the tiny real result (loading and writing are real)."""
    monkeypatch.setattr(task, "fit", lambda frames, config, **_: tiny_result)


def _fit(*arguments) -> tuple[int, list[str]]:
    result = CliRunner().invoke(app, ["fit", *map(str, arguments), "--quiet", "--jobs", "1"])
    assert "Traceback" not in result.output, result.output
    return result.exit_code, result.output.splitlines()


def _errors(lines: list[str]) -> list[str]:
    return [line for line in lines if line.startswith("error:")]


# --- options --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("option, value", [
    ("--resolution", "-5"), ("--resolution", "100000"), ("--lights", "0"), ("--lights", "100"),
    ("--bands", "0"), ("--bands", "30"), ("--max-frames", "0"), ("--frame-stride", "0"),
    ("--face-index", "-1"), ("--threads", "-2"), ("--seed", "-1"), ("--iterations", "5,0,5"),
    ("--iterations", "a,b,c"), ("--model", "flame"),
])
def test_bad_option_values_are_usage_errors_naming_the_option(photo, tmp_path, option, value):
    out = tmp_path / "out"
    code, lines = _fit(photo, "-o", out, option, value)
    assert code == 2 and _errors(lines) == lines and len(lines) == 1
    assert option in lines[0] and not out.exists()  # rejected before any work


def test_eval_uses_the_same_option_checks(tmp_path):
    result = CliRunner().invoke(app, ["eval", "pairs", str(tmp_path), "-o", str(tmp_path / "o"), "--lights", "0"])
    assert result.exit_code == 2 and "--lights must be" in result.output


def test_output_naming_a_file_is_a_one_line_usage_error(photo, tmp_path):
    existing = tmp_path / "taken.txt"
    existing.write_text("keep me")
    code, lines = _fit(photo, "-o", existing)
    assert code == 2 and len(lines) == 1 and "not a folder" in lines[0]
    assert existing.read_text() == "keep me"


def test_models_dir_is_the_only_folder_searched(photo, tmp_path, monkeypatch, shared):
    monkeypatch.setenv("DEFACE_MODELS", str(shared / "models"))  # has the files: must not be used
    empty = tmp_path / "models"
    empty.mkdir()
    assert find_model_file("ict-facekit/ict_face_area_v9409_f16.npz", empty) is None
    code, lines = _fit(photo, "-o", tmp_path / "out", "--models", empty)
    assert code == 1 and len(lines) == 1 and str(empty) in lines[0] and "ict_face_area" in lines[0]
    code, lines = _fit(photo, "-o", tmp_path / "out", "--models", tmp_path / "nowhere")
    assert code == 2 and lines == [f"error: --models {tmp_path / 'nowhere'}: no such folder"]


# --- disk full, permissions -----------------------------------------------------------------------------


def _first_run(photo, out) -> dict:
    code, lines = _fit(photo, "-o", out)
    assert code == 0, lines
    return json.loads((out / "face" / "params.json").read_text())


def test_disk_full_during_the_write_keeps_the_previous_outputs(photo, tmp_path, fake_fit, monkeypatch):
    out = tmp_path / "out"
    before = _first_run(photo, out)
    files_before = sorted(p.relative_to(out) for p in out.rglob("*"))

    def full(*_args, **_kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(outputs.np, "savez_compressed", full)
    code, lines = _fit(photo, "-o", out, "--overwrite")
    assert code == 1 and len(_errors(lines)) == 1
    assert "No space left on device" in _errors(lines)[0] and "unchanged" in _errors(lines)[0]
    assert json.loads((out / "face" / "params.json").read_text()) == before
    assert sorted(p.relative_to(out) for p in out.rglob("*")) == files_before  # no staging left


def test_permission_denied_is_one_line(photo, tmp_path, fake_fit, monkeypatch):
    def denied(*_args, **kwargs):
        raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(kwargs.get("dir")))

    probe = tempfile.TemporaryFile
    monkeypatch.setattr(tempfile, "TemporaryFile", denied)  # the up-front probe of -o
    code, lines = _fit(photo, "-o", tmp_path / "out")
    assert code == 1 and lines == [f"error: {tmp_path / 'out'}: cannot write there (Permission denied)"]
    monkeypatch.setattr(tempfile, "TemporaryFile", probe)
    monkeypatch.setattr(tempfile, "mkdtemp", denied)  # the staging folder of one input
    code, lines = _fit(photo, "-o", tmp_path / "out")
    assert code == 1 and len(_errors(lines)) == 1 and "Permission denied" in _errors(lines)[0]


# --- concurrent writers, stale staging ------------------------------------------------------------------


def test_a_second_writer_of_the_same_output_skips_it(photo, tmp_path, fake_fit):
    out = tmp_path / "out"
    with claimed_output(out / "face"):  # another run is fitting this input
        code, lines = _fit(photo, "-o", out)
    assert code == 0 and any(f"another deface run (pid {os.getpid()})" in line for line in lines)
    assert not (out / "face").exists()
    assert "0 of 1 input(s) done, 0 failed, 1 left to another run" in lines[-1]
    code, lines = _fit(photo, "-o", out)  # the lock is gone with its holder
    assert code == 0 and (out / "face" / "params.json").is_file()
    assert sorted(p.name for p in out.iterdir()) == ["batch.jsonl", "face", "index.html"]


@pytest.mark.slow
def test_two_processes_writing_the_same_output(photo, tmp_path):
    out = tmp_path / "out"
    go = tmp_path / "go"
    first = _driver("fit", 600, photo, "-o", out, go=go)  # until `go`: the second run may take a minute to start
    _wait_for(first, "PAUSED in fit")
    second = _driver("fit", 0, photo, "-o", out)
    assert second.wait(120) == 0 and "is writing it; skipped" in second.stderr.read()
    go.touch()
    assert first.wait(120) == 0 and json.loads((out / "face" / "params.json").read_text()) == {"frames": 1}


def test_remove_stale_cleans_only_this_outputs_leftovers(tmp_path):
    final = tmp_path / "face"
    mine, other = tmp_path / ".face.k2j_9x1q.partial", tmp_path / ".face.b.k2j_9x1q.partial"
    for folder in (mine, other, tmp_path / ".face.previous"):
        folder.mkdir()
    (tmp_path / ".face.previous" / "params.json").write_text("old")
    assert remove_stale(final) == [mine]  # killed between the renames: the previous result comes back
    assert (final / "params.json").read_text() == "old" and other.is_dir()
    (tmp_path / ".face.previous").mkdir()
    assert remove_stale(final) == [tmp_path / ".face.previous"] and final.is_dir()


def test_staged_directory_keeps_the_previous_result_on_interrupt(tmp_path):
    final = tmp_path / "result"
    with staged_directory(final) as folder:
        (folder / "a.txt").write_text("first")
    with pytest.raises(KeyboardInterrupt), staged_directory(final) as folder:
        (folder / "a.txt").write_text("half")
        raise KeyboardInterrupt
    assert (final / "a.txt").read_text() == "first" and [p.name for p in tmp_path.iterdir()] == ["result"]


# --- signals and resume ---------------------------------------------------------------------------------


def _driver(mode: str, seconds: float, *arguments, go: Path | None = None) -> subprocess.Popen:
    """tests/fault_driver.py: `deface fit ARGUMENTS` pausing in the fit or the write (until ``go`` exists)."""
    command = [sys.executable, str(DRIVER), mode, str(seconds), "--", *map(str, arguments), "--quiet", "--jobs", "1"]
    env = {**os.environ, "PYTHONPATH": str(REPO), "DRIVER_GO": str(go or "")}
    return subprocess.Popen(command, cwd=REPO, stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)


def _wait_for(process: subprocess.Popen, text: str) -> None:
    seen = []
    for line in process.stderr:
        if text in line:
            return
        seen.append(line)
    raise AssertionError(f"{text!r} never printed; exit {process.wait()}: {''.join(seen)}")


def _two_photos(photo: Path) -> Path:
    Image.open(photo).save(photo.with_name("other.png"))
    return photo.parent


@pytest.mark.slow
@pytest.mark.parametrize("mode, sent, code", [("fit", signal.SIGINT, 130), ("write", signal.SIGINT, 130),
                                              ("fit", signal.SIGTERM, 143), ("write", signal.SIGTERM, 143)])
def test_signal_ends_the_run_in_one_line_and_a_rerun_resumes(photo, tmp_path, mode, sent, code):
    folder, out = _two_photos(photo), tmp_path / "out"
    process = _driver(mode, 60, folder, "-o", out)
    _wait_for(process, "PAUSED")
    process.send_signal(sent)
    assert process.wait(120) == code
    lines = [line for line in process.stderr.read().splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith(f"interrupted ({sent.name}) during ")
    assert "0 of 2 input(s) done, 0 failed, 2 not done; run the same command again" in lines[0]
    assert not out.exists() or os.listdir(out) == []  # nothing partial, no lock left
    rerun = _driver(mode, 0, folder, "-o", out)
    assert rerun.wait(120) == 0 and sorted(os.listdir(out)) == ["batch.jsonl", "face", "other"]


@pytest.mark.slow
def test_sigint_during_a_real_fit(photos, tmp_path):
    """The real pipeline (no stand-in) stops within seconds of Ctrl-C in stage 2, leaving no output."""
    out = tmp_path / "out"
    command = [sys.executable, "-m", "deface.cli.main", "fit", str(photos / "000031.jpg"), "-o", str(out),
               "--preset", "fast", "--iterations", "20,400,3", "--resolution", "64"]
    process = subprocess.Popen(command, cwd=REPO, stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                               env={**os.environ, "PYTHONPATH": str(REPO)})
    _wait_for(process, "stage 2    1/400")
    process.send_signal(signal.SIGINT)
    assert process.wait(60) == 130
    rest = process.stderr.read()
    assert "Traceback" not in rest and rest.strip().splitlines()[-1].startswith("interrupted (SIGINT) during ")
    assert not out.exists() or os.listdir(out) == []


@pytest.mark.slow
def test_kill_9_mid_write_leaves_staging_that_the_rerun_removes(photo, tmp_path):
    out = tmp_path / "out"
    process = _driver("write", 60, photo, "-o", out)
    _wait_for(process, "PAUSED in write")
    process.kill()
    process.wait(120)
    assert [p for p in out.iterdir() if p.name.endswith(".partial")]  # what a kill leaves
    rerun = _driver("write", 0, photo, "-o", out)
    assert rerun.wait(120) == 0 and sorted(os.listdir(out)) == ["batch.jsonl", "face"]


# --- NaN / Inf ------------------------------------------------------------------------------------------


def _toy(steps: int, poison: set[int]) -> tuple[torch.Tensor, StepGuard, FitLog]:
    """Minimise |x - 3|^2 with Adam; the loss is NaN at the steps in ``poison``."""
    x = torch.zeros(4, requires_grad=True)
    optimiser = torch.optim.Adam([{"params": [x], "lr": 0.1}])
    log = FitLog(quiet=True)
    guard = StepGuard(optimiser, "toy", log)
    for step in range(steps):
        optimiser.zero_grad()
        loss = (x - 3).pow(2).sum() * (float("nan") if step in poison else 1.0)
        loss.backward()
        optimiser.step()
        guard.check(loss)
    return x, guard, log


def test_guard_rolls_back_a_nan_step_and_halves_the_rate():
    x, guard, log = _toy(300, {5})
    assert torch.isfinite(x).all() and torch.allclose(x, torch.full((4,), 3.0), atol=1e-2)
    assert guard.events == 1 and guard.optimiser.param_groups[0]["lr"] == pytest.approx(0.05)
    assert len(log.notes) == 1 and "toy: non-finite" in log.notes[0]


def test_guard_fails_the_input_when_nan_repeats():
    with pytest.raises(NonFiniteError, match="toy: .*NaN/Inf at 4 steps in a row"):
        _toy(10, {2, 3, 4, 5})


def test_nan_in_stage2_loss_is_recovered_and_recorded(tiny_fit, monkeypatch):
    face, config = tiny_fit
    original, calls = stage2.objective, []

    def poisoned(*args, **kwargs):
        calls.append(1)
        loss = original(*args, **kwargs)
        return loss * float("nan") if len(calls) == 3 else loss

    monkeypatch.setattr(stage2, "objective", poisoned)
    log = FitLog(quiet=True)
    result = fit_target(FitTarget([face.image_srgb], [face.landmarks], 1.0), config, log=log)
    assert all(torch.isfinite(t).all() for t in (result.pose.identity, result.lights.sh, result.albedo.coefficients,
                                                  result.pose.expression))
    assert torch.isfinite(result.textures.diffuse).all()
    assert [n for n in log.notes if n.startswith("stage 2: non-finite loss or parameters at step 3")]


def test_nan_that_repeats_fails_the_input_in_one_line(photo, tmp_path, monkeypatch):
    def diverging(*_args, **_kwargs):
        raise NonFiniteError("stage 3: loss or parameters became NaN/Inf at 4 steps in a row (step 9)")

    monkeypatch.setattr(task, "fit", diverging)
    code, lines = _fit(photo, "-o", tmp_path / "out")
    assert code == 1 and _errors(lines) == [f"error: {photo}: stage 3: loss or parameters became NaN/Inf at 4 "
                                            "steps in a row (step 9)"]


# --- fuzzed inputs --------------------------------------------------------------------------------------


def _fuzzed_inputs(folder: Path, shared: Path) -> list[Path]:
    """Random bytes, empty files and truncated real files for every extension deface accepts."""
    rng = np.random.default_rng(0)
    folder.mkdir()
    clip = (shared / "data" / "videos" / "d18.mp4").read_bytes()
    paths = []
    for extension in IMAGE_EXTENSIONS + VIDEO_EXTENSIONS:
        stem = extension.lstrip(".")
        (folder / f"random_{stem}{extension}").write_bytes(rng.bytes(int(rng.integers(1, 5000))))
        (folder / f"empty_{stem}{extension}").write_bytes(b"")
        real = folder / f"truncated_{stem}{extension}"
        if extension in IMAGE_EXTENSIONS:
            Image.fromarray(rng.integers(0, 255, (64, 48, 3), dtype=np.uint8)).save(real)
            real.write_bytes(real.read_bytes()[: len(real.read_bytes()) // 3])
        else:
            real.write_bytes(clip[: len(clip) // 50])
        paths += [folder / f"random_{stem}{extension}", folder / f"empty_{stem}{extension}", real]
    return paths


def test_fuzzed_files_of_every_extension_fail_in_one_line_each(tmp_path, shared, monkeypatch):
    paths = _fuzzed_inputs(tmp_path / "in", shared)
    monkeypatch.setattr(task, "fit", lambda *a, **k: pytest.fail("a corrupt file reached the fit"))
    code, lines = _fit(tmp_path / "in", "-o", tmp_path / "out")
    errors = _errors(lines)
    assert code == 1 and len(errors) == len(paths) and len(lines) == len(paths) + 1
    for path in paths:
        assert sum(f"{path}:" in line for line in errors) == 1, path
    assert f"0 of {len(paths)} input(s) done, {len(paths)} failed" in lines[-1]
    assert not any(p.name.startswith(".") for p in (tmp_path / "out").iterdir())


def test_large_photo_is_shrunk_while_decoding(tmp_path):
    path = tmp_path / "big.jpg"
    Image.fromarray(np.full((1500, 2000, 3), 90, np.uint8)).save(path, quality=80)
    image = load_image(path, max_side=500)
    assert image.shape == (375, 500, 3) and image.dtype == np.float32
    assert load_image(path).shape == (1500, 2000, 3)  # no limit asked: the full image


# --- clips ----------------------------------------------------------------------------------------------


def _clip(path: Path, frames: list[np.ndarray]) -> Path:
    import imageio.v2 as imageio

    with imageio.get_writer(str(path), fps=10, macro_block_size=1) as writer:
        for frame in frames:
            writer.append_data(frame)
    return path


@pytest.fixture(scope="module")
def face_frame(photos) -> np.ndarray:
    return np.asarray(Image.open(photos / "000031.jpg").convert("RGB").resize((160, 160)))


def test_clip_whose_middle_frames_have_no_face_keeps_the_others(tmp_path, face_frame):
    from deface.fit.pipeline import detect
    from deface.io.inputs import InputItem

    blank = np.full_like(face_frame, 128)
    clip = _clip(tmp_path / "gap.mp4", [face_frame, blank, blank, face_frame])
    config = override(presets.get("fast"), max_frames=4, resolution=64)
    frames, indices, _ = task.load_frames(InputItem(clip, "video"), config)
    landmarks, kept = detect(frames, config, str(clip), video=True)
    assert indices == [0, 1, 2, 3] and kept == [0, 3] and len(landmarks) == 2


def test_one_frame_clip_is_one_frame(tmp_path, face_frame):
    from deface.fit.pipeline import detect
    from deface.io.inputs import InputItem

    clip = _clip(tmp_path / "single.mp4", [face_frame])
    config = override(presets.get("fast"), resolution=64)
    frames, indices, _ = task.load_frames(InputItem(clip, "video"), config)
    assert indices == [0] and len(frames) == 1
    assert detect(frames, config, str(clip), video=True)[1] == [0]


def test_clip_without_any_face_fails_in_one_line(tmp_path, face_frame):
    clip = _clip(tmp_path / "empty.mp4", [np.full_like(face_frame, 128)] * 2)
    code, lines = _fit(clip, "-o", tmp_path / "out")
    assert code == 1 and _errors(lines) == [f"error: {clip}: no face found in any of 2 frame(s)"]


def test_demo_with_an_unknown_preset_is_a_usage_error(tmp_path, shared):
    result = CliRunner().invoke(app, ["demo", "-o", str(tmp_path), "--preset", "nope"])
    assert result.exit_code == 2 and result.output.splitlines() == [
        f"error: unknown preset 'nope' (choose from: {', '.join(presets.names())})"]


def test_disk_full_at_the_lock_is_one_line_not_a_bug_report(photo, tmp_path, fake_fit, monkeypatch):
    def full(*_args, **_kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), "lock")

    monkeypatch.setattr("deface.export.files._lock", full)
    code, lines = _fit(photo, "-o", tmp_path / "out")
    assert code == 1 and _errors(lines) == [f"error: {photo}: [Errno 28] No space left on device: 'lock'"]


def test_multi_line_and_unexpected_errors_are_one_line_with_details_under_verbose(photo, tmp_path, monkeypatch):
    def ffmpeg_like(*_args, **_kwargs):
        raise ValueError("cannot decode\n=== stderr ===\nframe 3: invalid NAL unit\n")

    monkeypatch.setattr(task, "fit", ffmpeg_like)
    code, lines = _fit(photo, "-o", tmp_path / "out")
    assert code == 1 and _errors(lines) == [f"error: {photo}: cannot decode (more with --verbose)"]
    verbose = CliRunner().invoke(app, ["fit", str(photo), "-o", str(tmp_path / "out"), "--verbose"])
    assert "Traceback" in verbose.output and "invalid NAL unit" in verbose.output
    monkeypatch.setattr(task, "fit", lambda *a, **k: {}["bug"])
    code, lines = _fit(photo, "-o", tmp_path / "out")
    assert code == 1 and _errors(lines) == [f"error: {photo}: unexpected KeyError: 'bug' (a bug: please report it "
                                            "with the output of --verbose)"]
