"""BFM 2017 + AlbedoMM loader on synthetic h5 files written in the upstream layout (tiny mesh)."""

from __future__ import annotations

import json
import pickle

import h5py
import numpy as np
import pytest
import torch

from deface.models.bfm import BFMConfig, cylindrical_uvs, load_bfm, standard_normal_basis
from deface.models.registry import load_face_model
from deface.paths import ModelFileError


def _grid_face(n: int = 9):
    """A curved face-like grid (mm), +z toward the viewer; triangles wound clockwise (tests re-orienting)."""
    xs, ys = np.meshgrid(np.linspace(-70, 70, n), np.linspace(-90, 90, n))
    zs = 60.0 * np.cos(xs / 90.0) + 20.0
    verts = np.stack([xs, ys, zs], -1).reshape(-1, 3)
    tris = []
    for r in range(n - 1):
        for c in range(n - 1):
            a, b, d, e = r * n + c, r * n + c + 1, (r + 1) * n + c, (r + 1) * n + c + 1
            tris += [[a, d, b], [b, d, e]]  # clockwise seen from +z
    return verts, np.array(tris)


def _orthonormal(rng, rows, cols):
    q, _ = np.linalg.qr(rng.standard_normal((rows, cols)))
    return q.astype(np.float32)


@pytest.fixture
def bfm_dir(tmp_path):
    rng = np.random.default_rng(0)
    verts, tris = _grid_face()
    v3 = verts.size
    (tmp_path / "bfm2017").mkdir()
    (tmp_path / "albedomm").mkdir()
    with h5py.File(tmp_path / "bfm2017/model2017-1_face12_nomouth.h5", "w") as f:
        f["shape/model/mean"] = verts.reshape(-1).astype(np.float32)
        f["shape/model/pcaBasis"] = _orthonormal(rng, v3, 7)
        f["shape/model/pcaVariance"] = np.linspace(400.0, 10.0, 7).astype(np.float32)  # mm^2
        f["expression/model/pcaBasis"] = _orthonormal(rng, v3, 5)
        f["expression/model/pcaVariance"] = np.linspace(100.0, 5.0, 5).astype(np.float32)
        f["shape/representer/cells"] = tris.T.astype(np.uint32)
        # Named landmarks as in the real file (positions arbitrary here: grid vertices).
        names = ["center.nose.tip", "center.chin.tip", "right.eye.corner_outer", "left.eye.corner_outer",
                 "right.lips.corner", "left.lips.corner"]
        entries = [{"id": n, "coordinates": verts[i * 7].tolist()} for i, n in enumerate(names)]
        f.create_dataset("metadata/landmarks/json", data=json.dumps(entries), dtype=h5py.string_dtype())
    colour = np.tile([0.6, 0.4, 0.3], len(verts)) * (1 + 0.2 * verts[:, 0:1].repeat(3, 1).reshape(-1) / 70)
    with h5py.File(tmp_path / "albedomm/albedoModel2020_face12_albedoPart.h5", "w") as f:
        for kind, scale in (("diffuseAlbedo", 1.0), ("specularAlbedo", 0.1)):
            f[f"{kind}/model/mean"] = (colour * scale).astype(np.float32)
            f[f"{kind}/model/pcaBasis"] = _orthonormal(rng, v3, 4)
            f[f"{kind}/model/pcaVariance"] = np.array([0.04, 0.02, 0.01, 0.005], np.float32)
    return tmp_path, verts, tris


def test_round_trip(bfm_dir):
    path, verts, tris = bfm_dir
    model = load_bfm(path, BFMConfig(texture_size=64))
    assert model.name == "bfm" and model.expression_prior == "pca"
    assert np.allclose(model.mean_shape, verts * 0.1, atol=1e-4)  # mm -> cm
    assert model.identity_basis.shape == (7, len(verts), 3) and model.expression_basis.shape == (
        5,
        len(verts),
        3,
    )
    # N(0, 1) coefficients: each component's basis has norm sqrt(variance) (in cm).
    norms = np.linalg.norm(model.identity_basis.reshape(7, -1), axis=1)
    assert np.allclose(norms, np.sqrt(np.linspace(400.0, 10.0, 7)) * 0.1, rtol=1e-4)
    # Re-oriented: normals toward the viewer.
    v = model.mean_shape
    t = model.triangles
    normals = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    assert (normals[:, 2] > 0).all()
    assert sorted(map(sorted, t.tolist())) == sorted(map(sorted, tris.tolist()))
    # Vertices follow the FaceModel formula.
    ident = torch.zeros(7, dtype=torch.float64)
    ident[0] = 2.0
    out = model.vertices(ident, torch.zeros(5, dtype=torch.float64)).numpy()
    assert np.allclose(out, model.mean_shape + 2 * model.identity_basis[0], atol=1e-5)


def test_albedo_splat_matches_per_vertex_values(bfm_dir):
    path, verts, tris = bfm_dir
    model = load_bfm(path, BFMConfig(texture_size=64))
    albedo = model.albedo
    assert albedo.diffuse_mean.shape == (64, 64, 3) and albedo.diffuse_basis.shape == (4, 64, 64, 3)
    assert albedo.specular_basis.shape == (4, 64, 64, 3)
    # Sampling the UV map at each vertex's UV gives back the per-vertex AlbedoMM mean (linear in x here).
    uv = model.uvs  # cylindrical: one UV per vertex
    cols = np.clip((uv[:, 0] * 64 - 0.5).round().astype(int), 0, 63)
    rows = np.clip(((1 - uv[:, 1]) * 64 - 0.5).round().astype(int), 0, 63)
    with h5py.File(path / "albedomm/albedoModel2020_face12_albedoPart.h5") as f:
        per_vertex = np.asarray(f["diffuseAlbedo/model/mean"]).reshape(-1, 3)
    sampled = albedo.diffuse_mean[rows, cols]
    inner = (uv[:, 0] > 0.1) & (uv[:, 0] < 0.9) & (uv[:, 1] > 0.1) & (uv[:, 1] < 0.9)
    assert np.abs(sampled[inner] - per_vertex[inner]).max() < 0.03
    assert albedo.face_mask.mean() > 0.8
    # Shared coefficients: one vector drives both maps.
    diffuse, specular = albedo.textures(torch.ones(4), 64)
    assert diffuse.shape == specular.shape == (64, 64, 3)


def test_nextface_pickle_uvs(bfm_dir, tmp_path):
    path, verts, tris = bfm_dir
    uv = np.stack([(verts[:, 0] + 80) / 160, (verts[:, 1] + 100) / 200], -1)
    pickle_path = tmp_path / "uvParametrization.256.pickle"
    with open(pickle_path, "wb") as handle:
        pickle.dump({"uvVertices": uv, "uvResolution": 256}, handle)
    model = load_bfm(path, BFMConfig(texture_size=32, uv_file=str(pickle_path)))
    assert np.allclose(model.uvs, uv, atol=1e-6)


def test_standard_normal_basis_detects_prescaled():
    rng = np.random.default_rng(2)
    q = _orthonormal(rng, 30, 4)
    var = np.array([9.0, 4.0, 1.0, 0.25])
    from_orthonormal = standard_normal_basis(q, var)
    from_scaled = standard_normal_basis(q * np.sqrt(var), var)
    assert np.allclose(from_orthonormal, from_scaled, atol=1e-6)


def test_cylindrical_uvs_seam_free():
    verts, tris = _grid_face()
    uv = cylindrical_uvs(verts)
    assert uv.min() >= 0 and uv.max() <= 1
    # No triangle spans a wrap: all UV edges are short.
    edges = np.abs(uv[tris] - uv[np.roll(tris, 1, axis=1)]).max()
    assert edges < 0.3  # a grid cell is 1/8 wide; a wrap-around would be ~1
    # No fold-overs: every UV triangle has the same orientation.
    a, b, c = uv[tris[:, 0]], uv[tris[:, 1]], uv[tris[:, 2]]
    signed = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    assert (signed > 0).all() or (signed < 0).all()


def test_missing_files_one_line_error(tmp_path, monkeypatch):
    monkeypatch.setenv("DEFACE_MODELS", str(tmp_path))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    with pytest.raises(ModelFileError, match="faces.dmi.unibas.ch") as info:
        load_face_model("bfm", tmp_path)
    assert "\n" not in str(info.value)
    with pytest.raises(ValueError, match="choose 'ict' or 'bfm'"):
        load_face_model("flame")
