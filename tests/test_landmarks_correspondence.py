"""MediaPipe -> ICT correspondence: geometry helpers, symmetry, anchors, batching, caching."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from deface.landmarks import correspondence as C


@pytest.fixture(scope="module")
def ict(shared):
    from deface.models.ict import load_ict

    return load_ict()


@pytest.fixture(scope="module")
def corr(ict):
    return C.correspondence_for(ict)


def test_closest_point_on_triangles_matches_dense_sampling():
    rng = np.random.default_rng(1)
    triangles = rng.normal(size=(50, 3, 3))
    points = rng.normal(size=(50, 3)) * 2
    closest = C.closest_point_on_triangles(points, triangles)
    u = rng.random((20000, 2))
    u = np.where(u.sum(1, keepdims=True) > 1, 1 - u, u)  # uniform in the triangle
    samples = triangles[:, None, 0] + u[None, :, :1] * (triangles[:, None, 1] - triangles[:, None, 0])
    samples = samples + u[None, :, 1:] * (triangles[:, None, 2] - triangles[:, None, 0])
    sampled = np.linalg.norm(samples - points[:, None], axis=-1).min(1)
    exact = np.linalg.norm(closest - points, axis=1)
    assert (exact <= sampled + 1e-9).all()  # never worse than any sample
    assert np.abs(exact - sampled).max() < 0.1  # and close to the best sample
    bary = C.barycentric(closest, triangles)
    np.testing.assert_allclose(np.einsum("kj,kjc->kc", bary, triangles), closest, atol=1e-6)


def test_umeyama_recovers_a_similarity():
    rng = np.random.default_rng(2)
    source = rng.normal(size=(30, 3))
    angle = 0.7
    rotation = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    target = 1.7 * source @ rotation.T + [1, 2, 3]
    scale, estimated, translation = C.umeyama(source, target)
    assert (
        scale == pytest.approx(1.7)
        and np.allclose(estimated, rotation)
        and np.allclose(translation, [1, 2, 3])
    )


def test_counts_and_barycentrics(ict, corr):
    counts = C.describe(ict)
    assert counts["used_without_contour"] == len(corr) == 478 - 10 - 20 - 36 - counts["outside_excluded"]
    assert not set(corr.mediapipe_ids) & set(range(468, 478))  # no iris points
    assert not set(corr.mediapipe_ids) & set(C.face_oval_ids())  # contour excluded by default
    assert (corr.barycentrics >= 0).all() and np.allclose(corr.barycentrics.sum(1), 1, atol=1e-5)
    np.testing.assert_array_equal(corr.vertex_ids, ict.triangles[corr.triangle_ids])
    with_contour = C.correspondence_for(ict, contour_weight=0.2)
    assert len(with_contour) == len(corr) + 36 and np.isclose(with_contour.weights.min(), 0.2)


def _mirror_pairs(canonical: np.ndarray) -> np.ndarray:
    """[478] index of each canonical vertex's mirror image (x -> -x)."""
    from scipy.spatial import cKDTree

    distance, pairs = cKDTree(canonical).query(canonical * [-1, 1, 1])
    assert distance.max() < 1e-3  # the canonical mesh is exactly symmetric
    return pairs


def test_symmetric_points_map_to_mirror_positions(ict, corr):
    canonical, _ = C.load_canonical_mesh()
    pairs = _mirror_pairs(canonical)
    points = C.model_landmarks(torch.as_tensor(ict.mean_shape), corr).numpy()  # [N, 3]
    position = {int(m): p for m, p in zip(corr.mediapipe_ids, points, strict=True)}
    asymmetry = [
        np.linalg.norm(position[m] * [-1, 1, 1] - position[int(pairs[m])])
        for m in position
        if int(pairs[m]) in position
    ]
    assert len(asymmetry) == len(position)  # the selection itself is symmetric
    assert np.median(asymmetry) < 0.05 and max(asymmetry) < 0.3  # cm, on a ~18 cm wide face


def test_anchor_points_land_on_model_landmarks(ict, corr):
    points = C.model_landmarks(torch.as_tensor(ict.mean_shape), corr).numpy()
    position = {int(m): p for m, p in zip(corr.mediapipe_ids, points, strict=True)}
    for ibug, mediapipe in [
        (36, 33),
        (45, 263),
        (39, 133),
        (42, 362),
        (48, 61),
        (54, 291),
        (30, 4),
        (8, 152),
    ]:
        if mediapipe in position:
            assert np.linalg.norm(position[mediapipe] - ict.mean_shape[ict.landmarks_68[ibug]]) < 0.3


def test_model_landmarks_batched_and_linear(ict, corr):
    rng = np.random.default_rng(3)
    identity = torch.as_tensor(rng.normal(size=(2, ict.num_identity)), dtype=torch.float32)
    expression = torch.as_tensor(rng.random((2, ict.num_expression)) * 0.5, dtype=torch.float32)
    batched = C.model_landmarks(ict.vertices(identity, expression), corr)  # [2, N, 3]
    single = C.model_landmarks(ict.vertices(identity[1], expression[1]), corr)  # [N, 3]
    torch.testing.assert_close(batched[1], single, atol=1e-4, rtol=0)
    mean, id_basis, ex_basis = C.landmark_basis(ict, corr)
    restricted = mean + np.einsum("k,knc->nc", identity[1].numpy(), id_basis)
    restricted = restricted + np.einsum("k,knc->nc", expression[1].numpy(), ex_basis)
    np.testing.assert_allclose(restricted, single.numpy(), atol=1e-3)


def test_cache_file_round_trip(ict, tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.setattr(C, "_PROJECTIONS", {})
    built = C.projection_for(ict)
    files = list((tmp_path / "deface" / "correspondence").glob("ict-*.npz"))
    assert len(files) == 1
    monkeypatch.setattr(C, "_PROJECTIONS", {})
    loaded = C.projection_for(ict)
    np.testing.assert_array_equal(built.triangle_ids, loaded.triangle_ids)
    np.testing.assert_array_equal(built.barycentrics, loaded.barycentrics)
