"""ICT-FaceKit (MIT), the embedded default face model: face area, 9,409 vertices, 100 identity + 53 expr.

The pack ``ict-facekit/ict_face_area_v9409_f16.npz`` is found through :mod:`deface.paths`
(``--models DIR``, ``DEFACE_MODELS``, the user cache). Quads are split into two triangles each.
ICT-FaceKit has no albedo model; :func:`load_ict` attaches the project's own prior
(:mod:`deface.models.albedo_prior`, docs/albedo-prior.md).
"""

from __future__ import annotations

import dataclasses
import os
from functools import lru_cache

import numpy as np

from deface.models.albedo_prior import AlbedoPriorConfig, build_albedo_prior
from deface.models.base import AlbedoModel, FaceModel
from deface.paths import ModelFileError, find_model_file

ICT_PACK = "ict-facekit/ict_face_area_v9409_f16.npz"


def quads_to_triangles(faces: np.ndarray) -> np.ndarray:
    """[F, 4] faces (column 3 == -1 marks a triangle) -> [T, 3] triangles, quads split along 0-2."""
    first = faces[:, [0, 1, 2]]
    quads = faces[faces[:, 3] >= 0]
    second = quads[:, [0, 2, 3]]
    # row-major: the renderer gathers triangle corners row by row every step
    return np.ascontiguousarray(np.concatenate([first, second]), dtype=np.int64)


def _key(models_dir: str | os.PathLike | None) -> str | None:
    return None if models_dir is None else str(models_dir)


@lru_cache(maxsize=4)
def _load_geometry(models_dir: str | None) -> FaceModel:
    path = find_model_file(ICT_PACK, models_dir)
    if path is None:
        raise ModelFileError(
            f"ICT-FaceKit pack '{ICT_PACK}' not found; run `deface models fetch ict` (online) or "
            "`deface models build ict --from <ICT-FaceKit checkout>`, or pass --models DIR / set "
            "DEFACE_MODELS"
        )
    pack = np.load(path)
    return FaceModel(
        name="ict",
        mean_shape=pack["neutral"].astype(np.float32),
        identity_basis=pack["identity_deltas"].astype(np.float32),
        expression_basis=pack["expression_deltas"].astype(np.float32),
        expression_prior="blendshape",
        expression_names=tuple(str(n) for n in pack["expression_names"]),
        triangles=quads_to_triangles(pack["faces_v"]),
        uvs=pack["uv"].astype(np.float32),
        triangle_uvs=quads_to_triangles(pack["faces_uv"]),
        albedo=None,
        landmarks_68=pack["landmarks_multipie68"].astype(np.int64),
    )


def load_ict_geometry(models_dir: str | os.PathLike | None = None) -> FaceModel:
    """The ICT-FaceKit face area (geometry, UVs, landmarks) without an albedo model."""
    return _load_geometry(_key(models_dir))


@lru_cache(maxsize=4)
def _load_with_albedo(models_dir: str | None) -> FaceModel:
    return dataclasses.replace(_load_geometry(models_dir), albedo=ict_albedo_prior(models_dir))


@lru_cache(maxsize=4)
def ict_albedo_prior(models_dir: str | None = None, config: AlbedoPriorConfig | None = None) -> AlbedoModel:
    """The (cached) project albedo prior for the ICT-FaceKit face area (docs/albedo-prior.md)."""
    model = load_ict_geometry(models_dir)
    return build_albedo_prior(
        model.uvs, model.triangle_uvs, model.triangles, model.mean_shape, model.landmarks_68, config
    )


def load_ict(models_dir: str | os.PathLike | None = None) -> FaceModel:
    """Load the ICT-FaceKit face area with the project's albedo prior attached (cached per models_dir)."""
    return _load_with_albedo(_key(models_dir))
