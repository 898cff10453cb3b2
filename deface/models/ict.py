"""ICT-FaceKit (MIT), the embedded default face model: face area, 9,409 vertices, 100 identity + 53 expressions.

The pack ``ict-facekit/ict_face_area_v9409_f16.npz`` is found through :mod:`deface.paths`
(``--models DIR``, ``DEFACE_MODELS``, the user cache). Quads are split into two triangles each.
"""

from __future__ import annotations

import os
from functools import lru_cache

import numpy as np

from deface.models.base import FaceModel
from deface.paths import ModelFileError, find_model_file

ICT_PACK = "ict-facekit/ict_face_area_v9409_f16.npz"


def quads_to_triangles(faces: np.ndarray) -> np.ndarray:
    """[F, 4] faces (column 3 == -1 marks a triangle) -> [T, 3] triangles, quads split along 0-2."""
    first = faces[:, [0, 1, 2]]
    quads = faces[faces[:, 3] >= 0]
    second = quads[:, [0, 2, 3]]
    return np.concatenate([first, second]).astype(np.int64)


@lru_cache(maxsize=4)
def load_ict(models_dir: str | os.PathLike | None = None) -> FaceModel:
    """Load the ICT-FaceKit face area (geometry, UVs, landmarks) from the pack."""
    path = find_model_file(ICT_PACK, models_dir)
    if path is None:
        raise ModelFileError(
            f"ICT-FaceKit pack '{ICT_PACK}' not found; run `deface models fetch ict` (online) or "
            "`deface models build ict --from <ICT-FaceKit checkout>`, or pass --models DIR / set DEFACE_MODELS"
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
