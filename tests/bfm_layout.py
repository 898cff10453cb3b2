"""Writes BFM 2017 / AlbedoMM-layout h5 files from the ICT-FaceKit geometry, for tests (real files are licensed).

The ICT mean and some of its components are stored in the statismo layout (mm, orthonormal ``pcaBasis`` +
``pcaVariance``, ``[3, F]`` clockwise ``cells``) with the vertices shuffled, so nothing can lean on ICT's
vertex order; ``metadata/landmarks/json`` names points at ICT's iBUG-68 landmark vertices (the mean of two
lid vertices for the eye top/bottom), plus names without a MediaPipe equivalent, as in the real file.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np

from deface.models.bfm import ALBEDOMM_FILE, BFM_FILE

NAMED_FROM_IBUG = {
    "center.chin.tip": (8,),
    "center.nose.tip": (30,),
    "center.nose.attachement_to_philtrum": (33,),
    "center.lips.upper.outer": (51,),
    "center.lips.lower.outer": (57,),
    "right.lips.corner": (48,),
    "left.lips.corner": (54,),
    "right.lips.philtrum_ridge": (50,),
    "left.lips.philtrum_ridge": (52,),
    "right.eye.corner_outer": (36,),
    "right.eye.corner_inner": (39,),
    "left.eye.corner_inner": (42,),
    "left.eye.corner_outer": (45,),
    "right.eye.top": (37, 38),
    "right.eye.bottom": (40, 41),
    "left.eye.top": (43, 44),
    "left.eye.bottom": (46, 47),
    "right.eyebrow.inner_upper": (21,),
    "left.eyebrow.inner_upper": (22,),
    "right.eyebrow.bend.upper": (19,),
    "left.eyebrow.bend.upper": (24,),
    "right.ear.lobule.attachement": (0,),  # no MediaPipe equivalent: must be ignored
    "center.lips.upper.inner": (62,),  # inner lips: left out on purpose
}


def statismo_basis(deltas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Deltas [K, V, 3] (mm per unit N(0, 1) coefficient) -> unit-norm pcaBasis [3V, K], pcaVariance [K]."""
    flat = deltas.reshape(len(deltas), -1).T.astype(np.float64)
    norms = np.linalg.norm(flat, axis=0)
    return (flat / norms).astype(np.float32), (norms**2).astype(np.float32)


def write_bfm_layout(folder: Path, ict, *, identity: int = 40, expression: int = 30, albedo: int = 4,
                     landmarks: bool = True, seed: int = 0) -> dict:
    """BFM + AlbedoMM files under ``folder`` (a models directory); returns the vertex order and landmarks."""
    rng = np.random.default_rng(seed)
    order = rng.permutation(ict.num_vertices)  # new vertex i is ICT vertex order[i]
    new_index = np.empty_like(order)
    new_index[order] = np.arange(len(order))
    mean_mm = ict.mean_shape[order] * 10.0
    named = {name: ict.mean_shape[ict.landmarks_68[list(ids)]].mean(0) * 10.0 for name, ids in NAMED_FROM_IBUG.items()}
    bfm = folder / BFM_FILE
    bfm.parent.mkdir(parents=True, exist_ok=True)
    with h5py.File(bfm, "w") as f:
        f["shape/model/mean"] = mean_mm.reshape(-1).astype(np.float32)
        f["shape/model/pcaBasis"], f["shape/model/pcaVariance"] = statismo_basis(
            ict.identity_basis[:identity, order] * 10.0)
        f["expression/model/pcaBasis"], f["expression/model/pcaVariance"] = statismo_basis(
            ict.expression_basis[:expression, order] * 10.0)
        f["shape/representer/cells"] = new_index[ict.triangles][:, [0, 2, 1]].T.astype(np.uint32)  # clockwise
        if landmarks:
            entries = [{"id": name, "coordinates": point.tolist(), "uncertainty": [1.0, 1.0, 1.0]}
                       for name, point in named.items()]
            f.create_dataset("metadata/landmarks/json", data=json.dumps(entries), dtype=h5py.string_dtype())
    _write_albedomm(folder / ALBEDOMM_FILE, mean_mm, albedo, rng)
    return {"order": order, "new_index": new_index, "named_mm": named}


def _write_albedomm(path: Path, vertices_mm: np.ndarray, count: int, rng) -> None:
    """Per-vertex skin-coloured means and smooth orthonormal components (linear RGB)."""
    x = (vertices_mm[:, 0] - vertices_mm[:, 0].mean()) / np.ptp(vertices_mm[:, 0])
    y = (vertices_mm[:, 1] - vertices_mm[:, 1].mean()) / np.ptp(vertices_mm[:, 1])
    skin = np.array([0.55, 0.38, 0.30]) * (1.0 + 0.1 * y[:, None])
    fields = [np.ones_like(x), x, y, x * y, x**2, y**2][:count]
    columns = [np.outer(field, rng.uniform(0.5, 1.0, 3)).reshape(-1) for field in fields]
    basis, _ = np.linalg.qr(np.stack(columns, 1))
    path.parent.mkdir(parents=True, exist_ok=True)
    with h5py.File(path, "w") as f:
        for kind, mean, variance in (("diffuseAlbedo", skin, 0.2), ("specularAlbedo", np.full_like(skin, 0.08), 0.01)):
            f[f"{kind}/model/mean"] = mean.reshape(-1).astype(np.float32)
            f[f"{kind}/model/pcaBasis"] = basis.astype(np.float32)
            f[f"{kind}/model/pcaVariance"] = (variance * 0.5 ** np.arange(count)).astype(np.float32)
