"""ICT-FaceKit pack loader and the pack builder (against raw-sample, the upstream OBJs)."""

from __future__ import annotations

import numpy as np
import pytest

from deface.models.ict import ICT_PACK, load_ict_geometry
from deface.models.ict_build import build_ict_pack, content_sha256, read_obj, save_pack


@pytest.fixture(scope="module")
def ict(shared):
    return load_ict_geometry(shared / "models")


def test_shapes_and_units(ict):
    assert ict.mean_shape.shape == (9409, 3)
    assert ict.identity_basis.shape == (100, 9409, 3)
    assert ict.expression_basis.shape == (53, 9409, 3)
    assert ict.triangles.shape[1] == 3 and ict.triangles.max() < 9409
    assert ict.triangle_uvs.shape == ict.triangles.shape
    assert ict.landmarks_68.shape == (68,)
    # Centimetres: an adult face area is ~15-25 cm wide and tall (it would be ~150+ in mm, ~0.2 in m).
    extent = np.ptp(ict.mean_shape, axis=0)
    assert 12 < extent[0] < 25 and 20 < extent[1] < 40
    # Landmark 36 (subject's right eye corner) has x < 0, 45 (left) x > 0; chin (8) below nose (30).
    lm = ict.mean_shape[ict.landmarks_68]
    assert lm[36, 0] < 0 < lm[45, 0] and lm[8, 1] < lm[30, 1] and lm[30, 2] > lm[0, 2]


def test_normals_point_outward(ict):
    v, t = ict.mean_shape.astype(np.float64), ict.triangles
    normals = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    centres = v[t].mean(1)
    area = np.linalg.norm(normals, axis=1)
    # Outward = away from a vertical axis behind the head; concave bits (nostrils, lip insides) disagree.
    away = centres - np.array([0.0, 0.0, v[:, 2].min() - 5.0])
    away[:, 1] = 0.0
    agree = (normals * away).sum(1) > 0
    assert (area * agree).sum() / area.sum() > 0.9
    # Nose-tip triangle normals point along +z strongly.
    tip = np.argmin(np.linalg.norm(centres - v[ict.landmarks_68[30]], axis=1))
    assert normals[tip, 2] / np.linalg.norm(normals[tip]) > 0.7


def test_uv_ranges_and_symmetry_axis(ict):
    used = ict.uvs[np.unique(ict.triangle_uvs)]
    assert used.min() >= 0.0 and used.max() <= 1.0
    midline = np.abs(ict.mean_shape[:, 0]) < 1e-4
    first_uv = np.zeros(ict.num_vertices, np.int64)
    first_uv[ict.triangles.ravel()] = ict.triangle_uvs.ravel()
    assert np.allclose(ict.uvs[first_uv[midline], 0], 0.5, atol=1e-4)


def test_vertices_linear_in_coefficients(ict):
    import torch

    ident = torch.zeros(100, dtype=torch.float64)
    ident[3] = 1.0
    expr = torch.zeros(53, dtype=torch.float64)
    expr[26] = 0.5
    out = ict.vertices(ident, expr).numpy()
    expected = ict.mean_shape + ict.identity_basis[3] + 0.5 * ict.expression_basis[26]
    assert np.allclose(out, expected, atol=1e-5)


def test_builder_reproduces_pack_entries(shared, tmp_path):
    raw = shared / "models" / "ict-facekit" / "raw-sample"
    arrays = build_ict_pack(raw, require_complete=False)
    path = save_pack(arrays, tmp_path / "pack.npz")
    built = np.load(path)
    shipped = np.load(shared / "models" / ICT_PACK)
    for key in ("neutral", "uv", "faces_v", "faces_uv", "landmarks_multipie68", "units"):
        assert built[key].dtype == shipped[key].dtype and np.array_equal(built[key], shipped[key]), key
    assert list(built["identity_names"]) == ["identity000", "identity001"]
    assert list(built["expression_names"]) == ["eyeBlink_L", "jawOpen"]
    for kind in ("identity", "expression"):
        names = list(shipped[f"{kind}_names"])
        for i, name in enumerate(built[f"{kind}_names"]):
            mine = built[f"{kind}_deltas"][i].astype(np.float32)
            theirs = shipped[f"{kind}_deltas"][names.index(name)].astype(np.float32)
            # float16 has a 2^-11 relative step: allow one ulp of rounding difference.
            assert np.allclose(mine, theirs, rtol=2**-10, atol=1e-4), name
            assert np.abs(theirs).max() > 0.1  # a real morph, not zeros
    # Deterministic packaging: same arrays -> same bytes and same content hash.
    again = save_pack(arrays, tmp_path / "again.npz")
    assert path.read_bytes() == again.read_bytes()
    assert content_sha256(path) == content_sha256(again)


def test_builder_complete_mode_reports_missing(shared):
    from deface.models.ict_build import BuildError

    with pytest.raises(BuildError, match="identity OBJs missing"):
        build_ict_pack(shared / "models" / "ict-facekit" / "raw-sample", require_complete=True)


def test_read_obj_triangles_and_quads(tmp_path):
    obj = tmp_path / "m.obj"
    obj.write_text(
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
        "f 1/1 2/2 3/3 4/4\nf 1/1 3/3 4/4\n"
    )
    data = read_obj(obj)
    assert data["faces_v"].tolist() == [[0, 1, 2, 3], [0, 2, 3, -1]]
    assert data["faces_uv"].tolist() == [[0, 1, 2, 3], [0, 2, 3, -1]]
    assert data["uv"].shape == (4, 2)
