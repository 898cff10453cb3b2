"""MediaPipe Face Mesh points -> points on a face model's surface (triangle id + barycentrics).

How it is built (once per model, cached in ``~/.cache/deface/correspondence/<model>-<hash>.npz``):

1. The canonical MediaPipe mesh (``mediapipe-canonical/face_model_with_iris.obj``, 478 vertices in
   MediaPipe's landmark order, cm, +x subject's left, +y up, +z toward the viewer: the same frame as
   the face models) is aligned to the model's mean shape by a similarity transform (Umeyama) on
   anchor pairs (:func:`model_anchors`): the model's iBUG-68 landmark vertices (brows, nose, eye corners
   and lids, outer lips, chin; ICT) and the MediaPipe points with the same meaning
   (:data:`IBUG68_TO_MEDIAPIPE`), or the model's own named 3D landmarks (BFM 2017's
   ``metadata/landmarks/json``: eye corners and lids, brows, nose tip, subnasale, lip corners and
   contour, chin tip) and their MediaPipe equivalents (:data:`deface.models.landmark_names.NAMED_TO_MEDIAPIPE`),
   snapped onto the mean surface.
2. The similarity is refined by trimmed ICP (canonical vertices -> closest model surface points,
   the 20% worst pairs dropped each round).
3. A non-rigid step: a smoothed thin-plate-spline warp, fitted on the anchor pairs, moves the
   canonical vertices so that the anchors land on the model's own landmark vertices (the two meshes
   have different proportions; without it eye and mouth corners would land a few mm off).
4. Every warped MediaPipe point is projected onto the closest point of the model surface, giving
   (triangle id, barycentrics), so landmarks move with the mesh under identity and expression.

A model may instead come with a user-supplied correspondence file (``FaceModel.correspondence_file``,
:func:`read_correspondence_file`, format in docs/bfm.md): its points replace steps 1-4, and the point
choices below apply to them the same way (points the file does not list are not used).

Which points are used in L_lan (468 + 10 iris points detected):
- the 10 iris points are excluded: they lie on the eyeballs, which are not part of the model surface;
- points that fall outside the model surface are excluded: the vector from the surface point to the
  warped MediaPipe point is mostly tangent to the surface (more than 60 degrees from the normal) and
  longer than 1 mm, i.e. the point projects onto the rim of an opening (inner lips over the mouth
  opening, some eyelid points over the eye openings);
- the 20 inner-lip points are excluded: they border the mouth opening, and on a closed mouth an
  upper-inner-lip point and its lower partner project onto the same seam of the model, so when the
  mouth opens one of them would follow the wrong lip (the outer lip contour still drives the mouth);
- the 36 points of the outer face contour (``FACEMESH_FACE_OVAL``) get weight ``contour_weight``
  (default 0: excluded). In an image the detected contour is the silhouette of the cheek/jaw, which
  slides over the surface when the head turns, so no fixed surface point matches it; keeping them
  with a fixed correspondence biases yaw and face width. Give them a small weight to constrain the
  face width on frontal photos if wanted.
:func:`describe` reports the counts for a model (ICT: see ``benchmarks/stage1.md``).
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from deface.models.base import FaceModel
from deface.models.landmark_names import MIN_NAMED_ANCHORS, named_anchor_ids
from deface.paths import ModelFileError, find_model_file, user_cache_dir
from deface.priors.face_region import MEDIAPIPE_INNER_LIPS

CANONICAL_MESH = "mediapipe-canonical/face_model_with_iris.obj"
ALGORITHM_VERSION = "2"  # bump to invalidate cached correspondences when the construction changes
IRIS_IDS = np.arange(468, 478)
MAX_TANGENT_ANGLE_DEG = 60.0  # beyond this the projection lands on an opening's rim: outside
MIN_OUTSIDE_DISTANCE_CM = 0.1

# iBUG-68 index (0-based) -> MediaPipe index with the same meaning. Jaw points 0-16 (except the chin)
# and the inner lips 60-67 are left out: their positions depend on pose / mouth opening.
IBUG68_TO_MEDIAPIPE = {
    8: 152,  # chin
    17: 70,
    18: 63,
    19: 105,
    20: 66,
    21: 107,  # subject's right brow (upper edge), outer -> inner
    22: 336,
    23: 296,
    24: 334,
    25: 293,
    26: 300,  # subject's left brow, inner -> outer
    27: 168,
    28: 197,
    29: 5,
    30: 4,  # nose bridge -> tip
    31: 98,
    32: 97,
    33: 2,
    34: 326,
    35: 327,  # nose base
    36: 33,
    37: 160,
    38: 158,
    39: 133,
    40: 153,
    41: 144,  # subject's right eye
    42: 362,
    43: 385,
    44: 387,
    45: 263,
    46: 373,
    47: 380,  # subject's left eye
    48: 61,
    49: 39,
    50: 37,
    51: 0,
    52: 267,
    53: 269,
    54: 291,  # upper outer lip
    55: 405,
    56: 314,
    57: 17,
    58: 84,
    59: 181,  # lower outer lip
}


@dataclass(frozen=True)
class Correspondence:
    """N MediaPipe points as points on a model's surface."""

    triangle_ids: np.ndarray  # [N] int64 rows of model.triangles
    barycentrics: np.ndarray  # [N, 3] float32, sum to 1
    mediapipe_ids: np.ndarray  # [N] int64 MediaPipe landmark indices (0..477)
    weights: np.ndarray  # [N] float32 per-point weight in L_lan (> 0)
    vertex_ids: np.ndarray  # [N, 3] int64 the corners of each triangle (model.triangles[triangle_ids])

    def __len__(self) -> int:
        return int(self.triangle_ids.shape[0])


def model_landmarks(vertices: torch.Tensor, corr: Correspondence) -> torch.Tensor:
    """Surface points of the correspondence: vertices [V, 3] or [T, V, 3] -> [..., N, 3] (differentiable)."""
    ids = torch.as_tensor(corr.vertex_ids, device=vertices.device)  # [N, 3]
    bary = torch.as_tensor(corr.barycentrics, dtype=vertices.dtype, device=vertices.device)  # [N, 3]
    corners = vertices[..., ids, :]  # [..., N, 3, 3]
    return (corners * bary[..., None]).sum(-2)


def landmark_basis(model: FaceModel, corr: Correspondence) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The model restricted to the correspondence points (linear, so exact):
    mean [N, 3], identity basis [Ki, N, 3], expression basis [Ke, N, 3]."""
    ids = corr.vertex_ids  # [N, 3]
    bary = corr.barycentrics[..., None]  # [N, 3, 1]

    def restrict(field: np.ndarray) -> np.ndarray:  # [..., V, 3] -> [..., N, 3]
        return (field[..., ids, :] * bary).sum(-2).astype(np.float32)

    return restrict(model.mean_shape), restrict(model.identity_basis), restrict(model.expression_basis)


# --- construction -------------------------------------------------------------------------------


def load_canonical_mesh(models_dir: str | os.PathLike | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The MediaPipe canonical mesh with irises: vertices [478, 3] cm, triangles [F, 3]."""
    path = find_model_file(CANONICAL_MESH, models_dir)
    if path is None:
        raise ModelFileError(
            f"MediaPipe canonical mesh '{CANONICAL_MESH}' not found; pass --models DIR or set DEFACE_MODELS"
        )
    vertices, faces = [], []
    for line in path.read_text().splitlines():
        if line.startswith("v "):
            vertices.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("f "):
            faces.append([int(x.split("/")[0]) - 1 for x in line.split()[1:4]])
    return np.asarray(vertices, np.float64), np.asarray(faces, np.int64)


def face_oval_ids() -> np.ndarray:
    """MediaPipe indices of the outer face contour (36 points)."""
    from mediapipe.python.solutions import face_mesh

    return np.unique(np.asarray(list(face_mesh.FACEMESH_FACE_OVAL)).ravel())


# The inner lip contour, mouth corners excluded (they are on the outer contour too: 61, 291 are kept).
INNER_LIP_IDS = np.array(MEDIAPIPE_INNER_LIPS)


def inner_lip_ids() -> np.ndarray:
    """MediaPipe indices of the inner lip contour (20 points)."""
    return INNER_LIP_IDS


def umeyama(source: np.ndarray, target: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Least-squares similarity target ~ s R source + t for [K, 3] pairs -> (s, R [3, 3], t [3])."""
    mu_s, mu_t = source.mean(0), target.mean(0)
    src, tgt = source - mu_s, target - mu_t
    u, sigma, vt = np.linalg.svd(tgt.T @ src / len(source))
    d = np.ones(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        d[2] = -1.0
    rotation = u @ np.diag(d) @ vt
    scale = float((sigma * d).sum() / src.var(0).sum())
    return scale, rotation, mu_t - scale * rotation @ mu_s


def _apply(similarity: tuple[float, np.ndarray, np.ndarray], points: np.ndarray) -> np.ndarray:
    scale, rotation, translation = similarity
    return scale * points @ rotation.T + translation


class SurfaceQuery:
    """Closest points on a triangle mesh: candidates from a KD-tree over triangle centroids, then the
    exact point-triangle distance (Ericson, Real-Time Collision Detection 5.1.5) on each candidate."""

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray, candidates: int = 32):
        from scipy.spatial import cKDTree

        self.corners = vertices[triangles].astype(np.float64)  # [F, 3, 3]
        self.tree = cKDTree(self.corners.mean(1))
        self.candidates = min(candidates, len(triangles))
        normals = np.cross(self.corners[:, 1] - self.corners[:, 0], self.corners[:, 2] - self.corners[:, 0])
        self.normals = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)  # [F, 3]

    def closest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """points [K, 3] -> closest surface points [K, 3], distances [K], triangle ids [K]."""
        _, cand = self.tree.query(points, k=self.candidates)  # [K, C]
        cand = cand.reshape(len(points), -1)
        tri = self.corners[cand]  # [K, C, 3, 3]
        query = np.broadcast_to(points[:, None], cand.shape + (3,))
        on_tri = closest_point_on_triangles(query.reshape(-1, 3), tri.reshape(-1, 3, 3)).reshape(query.shape)
        dist = np.linalg.norm(on_tri - query, axis=-1)  # [K, C]
        best = dist.argmin(1)
        rows = np.arange(len(points))
        return on_tri[rows, best], dist[rows, best], cand[rows, best]


def closest_point_on_triangles(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Closest point of triangle tri[k] ([K, 3, 3]) to p[k] ([K, 3]) -> [K, 3]."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = (ab * ap).sum(1), (ac * ap).sum(1)
    bp, cp = p - b, p - c
    d3, d4 = (ab * bp).sum(1), (ac * bp).sum(1)
    d5, d6 = (ab * cp).sum(1), (ac * cp).sum(1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        # Interior by default; each Voronoi region then overrides (the later checks win, as in Ericson).
        denom = va + vb + vc
        v_in, w_in = vb / denom, vc / denom
        result = a + ab * v_in[:, None] + ac * w_in[:, None]
        w_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        result = np.where(
            ((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0))[:, None], b + (c - b) * w_bc[:, None], result
        )
        w_ac = d2 / (d2 - d6)
        result = np.where(((vb <= 0) & (d2 >= 0) & (d6 <= 0))[:, None], a + ac * w_ac[:, None], result)
        v_ab = d1 / (d1 - d3)
        result = np.where(((vc <= 0) & (d1 >= 0) & (d3 <= 0))[:, None], a + ab * v_ab[:, None], result)
        result = np.where(((d6 >= 0) & (d5 <= d6))[:, None], c, result)
        result = np.where(((d3 >= 0) & (d4 <= d3))[:, None], b, result)
        result = np.where(((d1 <= 0) & (d2 <= 0))[:, None], a, result)
    return result


def model_anchors(model: FaceModel) -> tuple[np.ndarray, np.ndarray]:
    """Anchor pairs of the alignment: MediaPipe ids [K] and model points [K, 3] (cm, on the mean surface)."""
    if model.landmarks_68 is not None:
        ibug = np.array(list(IBUG68_TO_MEDIAPIPE.keys()))
        mp_ids = np.array(list(IBUG68_TO_MEDIAPIPE.values()))
        return mp_ids, model.mean_shape[model.landmarks_68[ibug]].astype(np.float64)
    rows, mp_ids = named_anchor_ids(model.landmark_names)
    if model.landmark_points is None or len(rows) < MIN_NAMED_ANCHORS:
        raise ValueError(
            f"model '{model.name}' has {len(rows)} landmarks with a MediaPipe equivalent (iBUG-68 vertices or "
            f"named points, need {MIN_NAMED_ANCHORS}): cannot anchor the MediaPipe correspondence; "
            "supply a correspondence file (docs/bfm.md)"
        )
    surface = SurfaceQuery(model.mean_shape.astype(np.float64), model.triangles)
    snapped, _, _ = surface.closest(model.landmark_points[rows].astype(np.float64))
    return mp_ids, snapped


def align_canonical(model: FaceModel, canonical: np.ndarray, icp_rounds: int = 10) -> np.ndarray:
    """Canonical vertices [478, 3] moved onto the model's mean shape (similarity, ICP, TPS warp)."""
    from scipy.interpolate import RBFInterpolator

    mp_ids, anchors_model = model_anchors(model)
    surface = SurfaceQuery(model.mean_shape.astype(np.float64), model.triangles)
    similarity = umeyama(canonical[mp_ids], anchors_model)

    # Trimmed ICP on the face interior (no contour, no irises), anchors kept in the fit.
    interior = np.setdiff1d(np.arange(468), face_oval_ids())
    for _ in range(icp_rounds):
        moved = _apply(similarity, canonical[interior])
        closest, distance, _ = surface.closest(moved)
        keep = distance <= np.quantile(distance, 0.8)
        source = np.concatenate([canonical[interior][keep], canonical[mp_ids]])
        target = np.concatenate([closest[keep], anchors_model])
        similarity = umeyama(source, target)

    aligned = _apply(similarity, canonical)
    # Non-rigid: a smoothed TPS displacement field that takes aligned anchors to the model's anchors.
    warp = RBFInterpolator(
        aligned[mp_ids], anchors_model - aligned[mp_ids], kernel="thin_plate_spline", smoothing=1.0
    )
    return aligned + warp(aligned)


def barycentric(points: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Barycentrics [K, 3] of points [K, 3] in triangles [K, 3, 3] (points assumed on the plane)."""
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    v0, v1, v2 = b - a, c - a, points - a
    d00, d01, d11 = (v0 * v0).sum(1), (v0 * v1).sum(1), (v1 * v1).sum(1)
    d20, d21 = (v2 * v0).sum(1), (v2 * v1).sum(1)
    denom = d00 * d11 - d01 * d01
    v = (d11 * d20 - d01 * d21) / denom
    w = (d00 * d21 - d01 * d20) / denom
    bary = np.stack([1 - v - w, v, w], 1)
    bary = np.clip(bary, 0.0, 1.0)
    return bary / bary.sum(1, keepdims=True)


@dataclass(frozen=True)
class _Projection:
    """All 478 MediaPipe points projected onto a model (what is cached)."""

    triangle_ids: np.ndarray  # [478]
    barycentrics: np.ndarray  # [478, 3]
    distance: np.ndarray  # [478] cm from the warped point to the surface
    outside: np.ndarray  # [478] bool, projects onto an opening's rim
    listed: np.ndarray  # [478] bool, has a point at all (False: not in a user-supplied file)


def project_onto_model(model: FaceModel, points: np.ndarray) -> _Projection:
    """Closest surface points of [478, 3] model-frame points, with an 'outside the surface' flag."""
    surface = SurfaceQuery(model.mean_shape.astype(np.float64), model.triangles)
    closest, distance, triangle_ids = surface.closest(points)
    bary = barycentric(closest, surface.corners[triangle_ids])
    normals = surface.normals[triangle_ids]
    offset = points - closest
    cosine = np.abs((offset * normals).sum(1)) / np.maximum(distance, 1e-9)
    outside = (cosine < np.cos(np.radians(MAX_TANGENT_ANGLE_DEG))) & (distance > MIN_OUTSIDE_DISTANCE_CM)
    return _Projection(
        triangle_ids.astype(np.int64),
        bary.astype(np.float32),
        distance.astype(np.float32),
        outside,
        np.ones(len(points), bool),
    )


def read_correspondence_file(path: str | os.PathLike, model: FaceModel) -> _Projection:
    """A user-supplied MediaPipe -> model correspondence (text, docs/bfm.md) as a projection on ``model``.

    Each row: ``mediapipe_id vertex_id`` (NextFace's ``landmark_62_mp.txt`` layout), or ``mediapipe_id v0 v1 v2
    b0 b1 b2`` (a point inside a triangle by its corner vertex ids and barycentrics); whitespace-separated,
    ``#`` starts a comment. Vertex ids index the model's vertices (the h5 file's order).
    """
    path = Path(path)
    try:
        table = np.loadtxt(path, ndmin=2, comments="#")
    except (OSError, ValueError) as error:
        raise ValueError(f"{path}: not a whitespace-separated table of numbers ({error})") from None
    if table.shape[1] not in (2, 7) or len(table) == 0:
        raise ValueError(
            f"{path}: expected rows 'mediapipe_id vertex_id' or 'mediapipe_id v0 v1 v2 b0 b1 b2', "
            f"got {table.shape[1]} columns"
        )
    ids = np.rint(table[:, :-3] if table.shape[1] == 7 else table).astype(np.int64)
    corners = ids[:, 1:4] if table.shape[1] == 7 else np.repeat(ids[:, 1:2], 3, 1)
    bary = table[:, 4:7] if table.shape[1] == 7 else np.tile([1.0, 0.0, 0.0], (len(table), 1))
    _check_rows(path, ids[:, 0], corners, bary, model.num_vertices)
    triangle_ids, bary = _locate(path, model.triangles, corners, bary)
    projection = _Projection(
        np.zeros(478, np.int64),
        np.tile(np.array([1.0, 0.0, 0.0], np.float32), (478, 1)),
        np.zeros(478, np.float32),
        np.zeros(478, bool),
        np.zeros(478, bool),
    )
    projection.triangle_ids[ids[:, 0]] = triangle_ids
    projection.barycentrics[ids[:, 0]] = bary
    projection.listed[ids[:, 0]] = True
    return projection


def _check_rows(path: Path, mp_ids: np.ndarray, corners: np.ndarray, bary: np.ndarray, num_vertices: int):
    if mp_ids.min() < 0 or mp_ids.max() >= 478 or len(np.unique(mp_ids)) != len(mp_ids):
        raise ValueError(f"{path}: MediaPipe ids must be distinct and in 0..477")
    if corners.min() < 0 or corners.max() >= num_vertices:
        raise ValueError(f"{path}: vertex id {corners.max()} out of range (the model has {num_vertices})")
    if (bary < -1e-6).any() or not np.allclose(bary.sum(1), 1.0, atol=1e-3):
        raise ValueError(f"{path}: barycentrics must be >= 0 and sum to 1 per row")


def _locate(path: Path, triangles: np.ndarray, corners: np.ndarray, bary: np.ndarray):
    """For each row, a triangle holding its corners with non-zero weight -> (triangle ids [N], bary [N, 3])."""
    candidates = np.flatnonzero(np.isin(triangles, corners).any(1))
    local = triangles[candidates]  # [C, 3]
    triangle_ids, out = np.zeros(len(corners), np.int64), np.zeros((len(corners), 3), np.float32)
    for row, (vertices, weights) in enumerate(zip(corners, bary, strict=True)):
        needed = np.unique(vertices[weights > 0])
        holds = np.isin(local, needed).sum(1) == len(needed)
        if not holds.any():
            raise ValueError(f"{path}: row {row + 1}: vertices {vertices.tolist()} are not one triangle's corners")
        best = int(np.argmax(holds))
        triangle_ids[row] = candidates[best]
        for vertex, weight in zip(vertices, weights, strict=True):
            out[row, local[best] == vertex] += weight
    return triangle_ids, out


def _cache_path(model: FaceModel, canonical: np.ndarray) -> Path:
    digest = hashlib.sha1()
    anchors = (model.landmarks_68, model.landmark_points, np.array(model.landmark_names, dtype=str))
    for array in (model.mean_shape, model.triangles, *anchors, canonical):
        if array is not None:
            digest.update(np.ascontiguousarray(array).tobytes())
    digest.update(ALGORITHM_VERSION.encode())
    return user_cache_dir().parent / "correspondence" / f"{model.name}-{digest.hexdigest()[:16]}.npz"


_PROJECTIONS: dict[Path, _Projection] = {}  # in-process cache, keyed like the files


def projection_for(model: FaceModel, models_dir: str | os.PathLike | None = None) -> _Projection:
    """All 478 points on the model: the model's correspondence file, else built (about a second) and cached."""
    if model.correspondence_file:
        return read_correspondence_file(model.correspondence_file, model)
    canonical, _ = load_canonical_mesh(models_dir)
    path = _cache_path(model, canonical)
    if path not in _PROJECTIONS:
        _PROJECTIONS[path] = _load_or_build(model, canonical, path)
    return _PROJECTIONS[path]


def _load_or_build(model: FaceModel, canonical: np.ndarray, path: Path) -> _Projection:
    if path.exists():
        try:
            data = np.load(path)
            return _Projection(*(data[key] for key in _Projection.__dataclass_fields__))
        except (OSError, KeyError, ValueError):
            pass  # a broken cache file is rebuilt below
    projection = project_onto_model(model, align_canonical(model, canonical))
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, **projection.__dict__)
        os.replace(tmp, path)
    except OSError:
        pass  # read-only cache dir: the correspondence is simply rebuilt next time
    return projection


def correspondence_for(
    model: FaceModel, contour_weight: float = 0.0, models_dir: str | os.PathLike | None = None
) -> Correspondence:
    """The MediaPipe -> model correspondence used by L_lan (see the module docstring for the choices)."""
    if contour_weight < 0:
        raise ValueError(f"contour_weight must be >= 0, got {contour_weight}")
    projection = projection_for(model, models_dir)
    weights = np.ones(478, np.float32)
    weights[face_oval_ids()] = contour_weight
    weights[IRIS_IDS] = 0.0
    weights[inner_lip_ids()] = 0.0
    weights[projection.outside | ~projection.listed] = 0.0
    used = np.flatnonzero(weights > 0)
    return Correspondence(
        triangle_ids=projection.triangle_ids[used],
        barycentrics=projection.barycentrics[used],
        mediapipe_ids=used.astype(np.int64),
        weights=weights[used],
        vertex_ids=model.triangles[projection.triangle_ids[used]],
    )


def describe(model: FaceModel, models_dir: str | os.PathLike | None = None) -> dict[str, int]:
    """Counts of the choices above for a model: used, iris, outside, contour, unlisted points."""
    projection = projection_for(model, models_dir)
    oval = face_oval_ids()
    outside = np.flatnonzero(projection.outside)
    return {
        "detected": 478,
        "iris_excluded": len(IRIS_IDS),
        "inner_lip_excluded": len(INNER_LIP_IDS),
        "outside_excluded": int(len(np.setdiff1d(outside, np.concatenate([IRIS_IDS, oval, INNER_LIP_IDS])))),
        "contour": len(oval),
        "unlisted": int((~projection.listed).sum()),
        "used_without_contour": len(correspondence_for(model, 0.0, models_dir)),
    }
