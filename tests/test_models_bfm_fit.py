"""`--model bfm` end to end on BFM 2017 / AlbedoMM-layout files written from ICT geometry (tests/bfm_layout.py):
named landmarks, the correspondence built from them alone or read from a user file, one-line errors,
stage 1 on photos, and a short fit writing every output."""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch
import trimesh
from bfm_layout import NAMED_FROM_IBUG, write_bfm_layout
from PIL import Image
from typer.testing import CliRunner

from deface.cli.main import app
from deface.landmarks import correspondence as C
from deface.models.bfm import BFM_FILE, BFMConfig, load_bfm, read_named_landmarks
from deface.models.landmark_names import named_anchor_ids
from deface.paths import ModelFileError

runner = CliRunner()


@pytest.fixture(scope="module")
def ict(shared):
    from deface.models.ict import load_ict_geometry

    return load_ict_geometry()


@pytest.fixture(scope="module")
def bfm_files(ict, tmp_path_factory):
    folder = tmp_path_factory.mktemp("bfm-models")
    # --models DIR is the only folder searched: it also needs the MediaPipe canonical mesh beside BFM.
    (folder / "mediapipe-canonical").symlink_to(Path(os.environ["DEFACE_MODELS"]) / "mediapipe-canonical")
    return folder, write_bfm_layout(folder, ict)


@pytest.fixture(scope="module")
def bfm(bfm_files):
    return load_bfm(bfm_files[0], BFMConfig(texture_size=64))


@pytest.fixture(scope="module")
def corr(bfm):
    return C.correspondence_for(bfm)


def _positions(model, corr) -> dict[int, np.ndarray]:
    points = C.model_landmarks(torch.as_tensor(model.mean_shape), corr).numpy()
    return {int(m): p for m, p in zip(corr.mediapipe_ids, points, strict=True)}


def test_named_landmarks_read_from_the_file(bfm, bfm_files, ict):
    _, info = bfm_files
    assert bfm.landmarks_68 is None and bfm.correspondence_file is None
    assert bfm.landmark_names == tuple(NAMED_FROM_IBUG)
    expected = np.array([info["named_mm"][name] for name in bfm.landmark_names]) * 0.1
    np.testing.assert_allclose(bfm.landmark_points, expected, atol=1e-4)
    np.testing.assert_allclose(bfm.mean_shape, ict.mean_shape[info["order"]], atol=1e-4)  # mm -> cm


@pytest.mark.parametrize("storage", ["fixed", "uint8"])
def test_landmark_json_in_other_string_storages(tmp_path, storage):
    text = json.dumps([{"id": "center.nose.tip", "coordinates": [1.0, 2.0, 30.0]}])
    data = np.bytes_(text.encode()) if storage == "fixed" else np.frombuffer(text.encode(), np.uint8)
    with h5py.File(tmp_path / "m.h5", "w") as h5:
        h5["metadata/landmarks/json"] = data
    with h5py.File(tmp_path / "m.h5", "r") as h5:
        names, points = read_named_landmarks(h5)
    assert names == ("center.nose.tip",) and np.allclose(points, [[0.1, 0.2, 3.0]])


def test_correspondence_built_from_the_metadata_alone(bfm, corr, ict):
    """Anchors land on the named points; the rest agrees with ICT's own iBUG-68-anchored correspondence."""
    position = _positions(bfm, corr)
    rows, mp_ids = named_anchor_ids(bfm.landmark_names)
    assert len(rows) == 21  # the ear and the inner lip are ignored
    for row, mediapipe in zip(rows, mp_ids, strict=True):
        if mediapipe in position:
            assert np.linalg.norm(position[mediapipe] - bfm.landmark_points[row]) < 0.3  # cm
    reference = _positions(ict, C.correspondence_for(ict))
    common = sorted(set(position) & set(reference))
    assert len(common) > 350 and len(position) > 350
    gaps = np.array([np.linalg.norm(position[m] - reference[m]) for m in common])
    assert np.median(gaps) < 0.15 and np.percentile(gaps, 95) < 0.5, (np.median(gaps), gaps.max())


def _models_with(folder, files: dict[str, str], tmp_path):
    """A models directory linking ``folder``'s h5 files, plus extra text files."""
    for relative in (BFM_FILE, "albedomm/albedoModel2020_face12_albedoPart.h5"):
        (tmp_path / relative).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / relative).symlink_to(folder / relative)
    for relative, text in files.items():
        (tmp_path / relative).write_text(text)
    return tmp_path


def test_user_correspondence_file_vertex_rows(bfm_files, bfm, tmp_path):
    """NextFace's two-column layout, found in the models directory; the usual point choices apply."""
    chosen = {152: 11, 33: 12, 263: 13, 61: 14, 291: 15, 4: 16, 13: 17, 468: 18}  # contour, inner lip, iris: out
    text = "# mediapipe bfm\n" + "".join(f"{m}\t\t{v}\n" for m, v in chosen.items())
    models = _models_with(bfm_files[0], {"bfm2017/mediapipe_correspondence.txt": text}, tmp_path)
    model = load_bfm(models, BFMConfig(texture_size=32))
    assert model.correspondence_file.endswith("mediapipe_correspondence.txt")
    user = C.correspondence_for(model)
    assert user.mediapipe_ids.tolist() == [4, 33, 61, 263, 291]
    for mediapipe, point in _positions(model, user).items():
        np.testing.assert_allclose(point, model.mean_shape[chosen[mediapipe]], atol=1e-6)


def test_user_correspondence_file_barycentric_rows(bfm, corr, tmp_path):
    """Seven-column rows (corners in any order) reproduce the built correspondence exactly."""
    rng = np.random.default_rng(0)
    lines = []
    for mediapipe, corners, bary in zip(corr.mediapipe_ids, corr.vertex_ids, corr.barycentrics, strict=True):
        turn = rng.permutation(3)
        numbers = [*map(str, corners[turn]), *(f"{b:.8f}" for b in bary[turn])]
        lines.append(f"{mediapipe} " + " ".join(numbers))
    path = tmp_path / "corr.txt"
    path.write_text("\n".join(lines))
    user = C.correspondence_for(dataclasses.replace(bfm, correspondence_file=str(path)))
    np.testing.assert_array_equal(user.mediapipe_ids, corr.mediapipe_ids)
    for mediapipe, point in _positions(bfm, user).items():
        np.testing.assert_allclose(point, _positions(bfm, corr)[mediapipe], atol=1e-5)
    path.write_text("4 1 2 999999 0.2 0.3 0.5\n")
    with pytest.raises(ValueError, match="out of range"):
        C.read_correspondence_file(path, bfm)
    path.write_text("4 0 0\n")
    with pytest.raises(ValueError, match="expected rows"):
        C.read_correspondence_file(path, bfm)


def test_missing_metadata_is_a_one_line_error(ict, tmp_path, photos, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    models = tmp_path / "models"
    write_bfm_layout(models, ict, identity=4, expression=4, landmarks=False)
    with pytest.raises(ModelFileError, match="lacks metadata/landmarks/json") as info:
        load_bfm(models)
    assert "\n" not in str(info.value) and "mediapipe_correspondence.txt" in str(info.value)
    check = runner.invoke(app, ["models", "check", "bfm", "--models", str(models)])
    assert check.exit_code == 1 and "metadata/landmarks/json" in check.output
    result = runner.invoke(app, ["fit", str(photos / "000031.jpg"), "-o", str(tmp_path / "out"), "--models",
                                 str(models), "--model", "bfm", "--quiet"])
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert result.exit_code == 1 and len(errors) == 1 and "docs/bfm.md" in errors[0]


def test_models_check_reports_the_metadata(bfm_files):
    result = runner.invoke(app, ["models", "check", "bfm", "--models", str(bfm_files[0])])
    assert result.exit_code == 0, result.output
    assert "23 named points, 21 with a MediaPipe equivalent" in result.output
    assert "computed cylindrical layout" in result.output


@pytest.mark.slow
def test_stage1_landmark_error_on_photos(bfm, corr, photos):
    from deface.fit import presets
    from deface.fit.pipeline import detect_target
    from deface.fit.stage1 import fit_landmarks

    config = presets.get("default")
    errors = []
    for name in ("000031.jpg", "015270.jpg", "nextface-s1.png"):
        image = np.asarray(Image.open(photos / name).convert("RGB"), np.float32) / 255.0
        target = detect_target([image], config, name, video=False)
        result = fit_landmarks(bfm, corr, target.landmarks, target.size, config.stage1, config.iterations.stage1,
                               principal_point=target.principal_point, photo_side=max(target.framing.scene_size))
        errors.append(float(result.error_iod[0]))
    assert max(errors) <= 0.03, errors


@pytest.mark.slow
def test_fit_writes_every_output_with_working_textures(bfm_files, tmp_path):
    from deface.cli.fit import run
    from deface.eval.benchmark import SCHEDULES
    from deface.fit import presets
    from deface.fit.config import override
    from deface.io.inputs import list_inputs
    from deface.paths import shared_dir

    models, _ = bfm_files
    config = override(presets.get("fast"), **SCHEDULES["smoke"], model="bfm")
    items = list_inputs([shared_dir() / "data" / "images" / "000031.jpg"])
    assert run(items, tmp_path, config, models, quiet=True) == 0
    folder = tmp_path / "000031"
    params = json.loads((folder / "params.json").read_text())
    assert params["model"]["name"] == "bfm" and len(params["albedo_coefficients"]) == 4
    for name in ("textures/diffuse.png", "textures/specular.png", "textures/roughness.png", "mesh.obj",
                 "mesh.mtl", "mesh.glb", "params.npz", "render.png", "render_face.png", "masks/face.png"):
        assert (folder / name).is_file(), name
    model = load_bfm(models, BFMConfig(texture_size=64))
    obj = trimesh.load(folder / "mesh.obj", process=False, force="mesh")
    glb = next(iter(trimesh.load(folder / "mesh.glb").geometry.values()))
    diffuse = np.asarray(Image.open(folder / "textures/diffuse.png").convert("RGB"), np.float32)
    # Each vertex's UV lands on the painted face in both exports, and both read the same colour there.
    for mesh in (obj, glb):
        colours = _sample(diffuse, mesh.visual.uv)
        inside = _sample(model.albedo.face_mask[..., None], mesh.visual.uv)[:, 0]
        assert inside.mean() > 0.9 and colours[inside > 0.5].min() > 10
    # The GLB (metres, corners split at seams) puts the same UV at the same place as the OBJ (cm).
    from scipy.spatial import cKDTree

    distance, nearest = cKDTree(obj.vertices).query(glb.vertices * 100.0)
    assert distance.max() < 1e-3
    np.testing.assert_allclose(glb.visual.uv, obj.visual.uv[nearest], atol=1e-4)


def _sample(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Nearest texel of ``image`` [H, W, C] at UVs [N, 2] (v up: row 0 is v = 1)."""
    height, width = image.shape[:2]
    cols = np.clip((uv[:, 0] * width).astype(int), 0, width - 1)
    rows = np.clip(((1 - uv[:, 1]) * height).astype(int), 0, height - 1)
    return image[rows, cols].astype(np.float64)
