"""Basel Face Model 2017 (face12, no mouth) + AlbedoMM, read from the user's own files.

Files (not redistributable; see ``deface models list``):
- ``bfm2017/model2017-1_face12_nomouth.h5``: ``shape/model/{mean, pcaBasis, pcaVariance}`` ([3V], [3V, 199],
  [199]), ``expression/model/{pcaBasis, pcaVariance}`` ([3V, 100], [100]), ``shape/representer/cells``
  ([3, F] triangle vertex ids); positions flattened x, y, z per vertex, in millimetres. Its named 3D landmarks
  are ``metadata/landmarks/json``: one UTF-8 JSON string, a list of ``{"id": "center.nose.tip",
  "coordinates": [x, y, z], ...}`` in mm on the mean face (read by :func:`read_named_landmarks`); they anchor
  the MediaPipe correspondence (:mod:`deface.landmarks.correspondence`).
- optional, beside it: ``bfm2017/mediapipe_correspondence.txt`` (a user-supplied correspondence, used instead
  of building one; format in docs/bfm.md) and ``bfm2017/uv_layout.obj`` (a UV layout on the BFM vertices).
- ``albedomm/albedoModel2020_face12_albedoPart.h5``: ``diffuseAlbedo/model/{mean, pcaBasis, pcaVariance}`` and
  ``specularAlbedo/model/{...}``, per-vertex linear RGB on the same topology (145 components).

Conversions to the :class:`FaceModel` conventions:
- millimetres -> centimetres (x 0.1); BFM's frame already has +y up, +z toward the viewer, +x to the subject's
  left.
- N(0, 1) coefficients: statismo stores an orthonormal ``pcaBasis`` U with ``pcaVariance`` lambda; NextFace
  multiplies its coefficients by U directly with a prior weighted by lambda (its coefficients ~ N(0, lambda)).
  We store U * sqrt(lambda) so our coefficients are N(0, 1). If a file's basis is already scaled (column norms
  squared ~ lambda), it is used as is. Which case applies is decided per basis from the column norms.
- triangles are re-oriented if needed so they are counter-clockwise seen from outside (normals toward +z).
- UVs: NextFace's ``uvParametrization.<res>.pickle`` (``uvVertices`` per vertex), an OBJ with ``vt`` on the
  same vertices, or (default) a cylindrical projection around the vertical axis, seam-free for a face mesh.
- Per-vertex albedo is splatted into UV space (barycentric interpolation over the rasterised UV triangles).
"""

from __future__ import annotations

import json
import os
import pickle
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from deface.models.base import AlbedoModel, FaceModel
from deface.models.landmark_names import MIN_NAMED_ANCHORS, named_anchor_ids
from deface.models.uvmap import coverage, rasterize_uv
from deface.paths import ModelFileError, find_model_file, models_dir_candidates

BFM_FILE = "bfm2017/model2017-1_face12_nomouth.h5"
ALBEDOMM_FILE = "albedomm/albedoModel2020_face12_albedoPart.h5"
CORRESPONDENCE_FILE = "bfm2017/mediapipe_correspondence.txt"
UV_LAYOUT_FILE = "bfm2017/uv_layout.obj"
LANDMARKS_DATASET = "metadata/landmarks/json"
MM_TO_CM = 0.1
ALBEDOMM_ROUGHNESS = (
    0.4  # AlbedoMM has no roughness model; same default as the ICT prior (Weyrich et al. 2006)
)


@dataclass(frozen=True)
class BFMConfig:
    """Options of the BFM 2017 + AlbedoMM loader."""

    texture_size: int = 256
    """Size of the UV maps AlbedoMM is splatted into (memory ~ 2*145*3*size^2*4 bytes)."""
    uv_file: str | None = None
    """NextFace uvParametrization pickle or an OBJ with vt; None: ``bfm2017/uv_layout.obj`` from the models
    directory if present, else the computed cylindrical projection."""
    correspondence_file: str | None = None
    """MediaPipe -> BFM correspondence (docs/bfm.md); None: ``bfm2017/mediapipe_correspondence.txt`` from the
    models directory if present, else built from the file's landmark metadata."""
    num_identity: int | None = None
    """Keep the first N identity components (None: all)."""
    num_expression: int | None = None
    """Keep the first N expression components (None: all)."""
    num_albedo: int | None = None
    """Keep the first N albedo components (None: all)."""


def _require(relative: str, models_dir, what: str, where: str) -> Path:
    path = find_model_file(relative, models_dir)
    if path is None:
        raise ModelFileError(
            f"{what} '{relative}' not found under --models/DEFACE_MODELS/cache; get it from {where}"
        )
    return path


def standard_normal_basis(basis: np.ndarray, variance: np.ndarray) -> np.ndarray:
    """A statismo basis [3V, K] and variances [K] -> basis [K, V, 3] for N(0, 1) coefficients."""
    if basis.ndim != 2 or variance.shape != (basis.shape[1],):
        raise ValueError(f"pcaBasis {basis.shape} and pcaVariance {variance.shape} do not match")
    norms2 = (basis.astype(np.float64) ** 2).sum(0)
    variance = np.maximum(variance.astype(np.float64), 1e-30)
    # Orthonormal columns have norm 1; pre-scaled columns have norm^2 = variance. Pick the closer in log.
    orthonormal = np.median(np.abs(np.log(norms2 + 1e-30))) <= np.median(
        np.abs(np.log((norms2 + 1e-30) / variance))
    )
    scaled = basis * np.sqrt(variance)[None, :] if orthonormal else basis
    return np.ascontiguousarray(scaled.T.reshape(basis.shape[1], -1, 3))


def orient_outward(triangles: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """Flip the winding if most area-weighted normals point toward the mesh centre (open face shell: -z)."""
    a, b, c = (vertices[triangles[:, i]] for i in range(3))
    normals = np.cross(b - a, c - a)
    centroid = vertices.mean(0)
    outward = (a + b + c) / 3.0 - centroid
    outward[:, 2] += np.ptp(vertices[:, 2])  # a face shell opens backwards: bias toward the viewer
    return triangles if (normals * outward).sum() >= 0 else triangles[:, [0, 2, 1]]


def cylindrical_uvs(vertices: np.ndarray, margin: float = 0.02) -> np.ndarray:
    """Per-vertex UVs [V, 2] from the angle around a vertical axis behind the face (x centre, z min) and y.

    All vertices lie in front of the axis, so the angle stays in (-pi/2, pi/2): no seam on a face mesh.
    """
    cx = 0.5 * (vertices[:, 0].min() + vertices[:, 0].max())
    cz = vertices[:, 2].min() - 0.25 * np.ptp(vertices[:, 2])
    angle = np.arctan2(vertices[:, 0] - cx, vertices[:, 2] - cz)
    height = vertices[:, 1]
    u = (angle - angle.min()) / max(np.ptp(angle), 1e-12)
    v = (height - height.min()) / max(np.ptp(height), 1e-12)
    return (margin + (1 - 2 * margin) * np.stack([u, v], -1)).astype(np.float32)


def load_uv_file(path: str | Path, num_vertices: int, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """UVs [U, 2] and triangle_uvs [F, 3] from a NextFace pickle (per-vertex ``uvVertices``) or an OBJ."""
    path = Path(path)
    if not path.is_file():
        raise ModelFileError(f"UV file {path} not found")
    if path.suffix == ".obj":
        from deface.models.ict_build import read_obj

        obj = read_obj(path)
        if "uv" not in obj or (obj["faces_uv"][:, :3] < 0).any() or (obj["faces_v"][:, 3] >= 0).any():
            raise ValueError(f"{path}: needs vt coordinates and triangle faces with v/vt indices")
        if len(obj["positions"]) != num_vertices:
            raise ValueError(f"{path}: {len(obj['positions'])} vertices, the model has {num_vertices}")
        return obj["uv"].astype(np.float32), _match_faces(obj, triangles, path)
    with open(path, "rb") as handle:
        data = pickle.load(handle)  # the user's own NextFace file  # noqa: S301
    if not isinstance(data, dict) or "uvVertices" not in data:
        raise ValueError(f"{path}: expected NextFace's uvParametrization pickle with a 'uvVertices' entry")
    uvs = np.asarray(data["uvVertices"], np.float32).reshape(-1, 2)
    if len(uvs) != num_vertices:
        raise ValueError(f"{path}: {len(uvs)} uvVertices, the model has {num_vertices} vertices")
    return uvs, triangles.copy()


def _match_faces(obj: dict, triangles: np.ndarray, path: Path) -> np.ndarray:
    """triangle_uvs [F, 3] aligned with our (possibly re-oriented) triangles, from the OBJ's faces."""
    lookup = {}
    for fv, fuv in zip(obj["faces_v"][:, :3], obj["faces_uv"][:, :3], strict=True):
        for k in range(3):
            lookup[(fv[k], fv[(k + 1) % 3], fv[(k + 2) % 3])] = np.roll(fuv, -k)
            lookup[(fv[k], fv[(k + 2) % 3], fv[(k + 1) % 3])] = np.roll(fuv[[0, 2, 1]], -k)
    try:
        return np.array([lookup[tuple(t)] for t in triangles.tolist()], np.int64)
    except KeyError as error:
        raise ValueError(f"{path}: its faces differ from the BFM triangles (missing {error})") from error


def splat_albedo(
    raster, triangles: np.ndarray, mean: np.ndarray, basis: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per-vertex mean [V, 3] and basis [K, V, 3] -> UV maps [H, W, 3] and [K, H, W, 3]."""
    mean_map = raster.interpolate_vertices(mean, triangles).astype(np.float32)
    basis_maps = np.stack([raster.interpolate_vertices(b, triangles).astype(np.float32) for b in basis])
    return mean_map, basis_maps


def load_bfm(models_dir: str | os.PathLike | None = None, config: BFMConfig | None = None) -> FaceModel:
    """BFM 2017 face12 geometry + AlbedoMM albedo, converted to the FaceModel conventions."""
    config = config or BFMConfig()
    bfm_path = _require(
        BFM_FILE,
        models_dir,
        "Basel Face Model 2017",
        "https://faces.dmi.unibas.ch/bfm/bfm2017.html (registration)",
    )
    albedo_path = _require(
        ALBEDOMM_FILE, models_dir, "AlbedoMM", "https://github.com/waps101/AlbedoMM/releases"
    )
    geometry = _read_geometry(bfm_path)
    mean, triangles = geometry["mean"], geometry["triangles"]
    correspondence = _optional_file(config.correspondence_file, CORRESPONDENCE_FILE, models_dir)
    if correspondence is None:
        _check_anchors(bfm_path, geometry["landmark_names"], models_dir)
    uv_file = _optional_file(config.uv_file, UV_LAYOUT_FILE, models_dir)
    if uv_file:
        uvs, triangle_uvs = load_uv_file(uv_file, len(mean), triangles)
    else:
        uvs, triangle_uvs = cylindrical_uvs(mean), triangles.copy()
    albedo = _load_albedomm(albedo_path, len(mean), triangles, uvs, triangle_uvs, config)
    expression = geometry["expression"][: config.num_expression]
    return FaceModel(
        name="bfm",
        mean_shape=mean.astype(np.float32),
        identity_basis=geometry["identity"][: config.num_identity].astype(np.float32),
        expression_basis=expression.astype(np.float32),
        expression_prior="pca",
        expression_names=tuple(f"pca{i:03d}" for i in range(len(expression))),
        triangles=triangles,
        uvs=uvs,
        triangle_uvs=triangle_uvs,
        albedo=albedo,
        landmarks_68=None,
        landmark_names=geometry["landmark_names"],
        landmark_points=geometry["landmark_points"],
        correspondence_file=None if correspondence is None else str(correspondence),
    )


def _read_geometry(path: Path) -> dict:
    """Mean [V, 3] cm, identity [Ki, V, 3], expression [Ke, V, 3], outward triangles [F, 3], named landmarks."""
    with h5py.File(path, "r") as bfm:
        mean = np.asarray(bfm["shape/model/mean"], np.float64).reshape(-1, 3) * MM_TO_CM
        identity = standard_normal_basis(
            np.asarray(bfm["shape/model/pcaBasis"]), np.asarray(bfm["shape/model/pcaVariance"])
        )
        expression = standard_normal_basis(
            np.asarray(bfm["expression/model/pcaBasis"]), np.asarray(bfm["expression/model/pcaVariance"])
        )
        cells = np.asarray(bfm["shape/representer/cells"], np.int64)
        names, points = read_named_landmarks(bfm, path)
    triangles = cells.T if cells.shape[0] == 3 else cells
    if triangles.max() >= len(mean):
        raise ValueError(f"{path}: cells index vertex {triangles.max()} of {len(mean)}")
    return {
        "mean": mean,
        "identity": identity * MM_TO_CM,
        "expression": expression * MM_TO_CM,
        "triangles": orient_outward(np.ascontiguousarray(triangles), mean),
        "landmark_names": names,
        "landmark_points": points,
    }


def read_named_landmarks(h5: h5py.File, path: Path | str = "") -> tuple[tuple[str, ...], np.ndarray | None]:
    """Names and points [L, 3] (cm) of ``metadata/landmarks/json``; ((), None) when the file has none.

    The dataset is one UTF-8 JSON string (variable- or fixed-length, or raw bytes): a list of objects
    ``{"id": name, "coordinates": [x, y, z], ...}`` in mm.
    """
    if LANDMARKS_DATASET not in h5:
        return (), None
    try:
        entries = json.loads(_as_text(h5[LANDMARKS_DATASET][()]))
        names = tuple(str(entry["id"]) for entry in entries)
        points = np.asarray([entry["coordinates"] for entry in entries], np.float64).reshape(len(names), 3)
    except (ValueError, TypeError, KeyError, UnicodeDecodeError) as error:
        raise ValueError(
            f"{path}: {LANDMARKS_DATASET} is not a JSON list of {{'id', 'coordinates': [x, y, z]}} ({error})"
        ) from None
    return names, (points * MM_TO_CM).astype(np.float32)


def _as_text(raw) -> str:
    """A scalar HDF5 string as read by h5py (bytes, str, or an array of bytes / uint8) -> str."""
    if isinstance(raw, np.ndarray):
        raw = raw.tobytes() if raw.dtype.kind in "iu" else raw.ravel()[0]
    if isinstance(raw, bytes):
        raw = bytes(raw).decode("utf-8")
    return str(raw).rstrip("\x00")


def _optional_file(explicit: str | None, relative: str, models_dir) -> Path | None:
    """An explicitly given file (must exist), else ``relative`` under the models directories, else None."""
    if explicit is None:
        return find_model_file(relative, models_dir)
    if not Path(explicit).is_file():
        raise ModelFileError(f"file {explicit} not found")
    return Path(explicit)


def _check_anchors(path: Path, names: tuple[str, ...], models_dir) -> None:
    """One-line error when the correspondence cannot be built from the file's landmark metadata."""
    usable = len(named_anchor_ids(names)[0])
    if usable >= MIN_NAMED_ANCHORS:
        return
    what = (
        f"lacks {LANDMARKS_DATASET}"
        if not names
        else f"has {len(names)} named landmarks but only {usable} with a MediaPipe equivalent "
        f"(need {MIN_NAMED_ANCHORS})"
    )
    target = models_dir_candidates(models_dir)[0] / CORRESPONDENCE_FILE
    raise ModelFileError(
        f"{path} {what}: no MediaPipe-to-BFM correspondence can be built; supply one at {target} "
        "(format: docs/bfm.md)"
    )


def _load_albedomm(path, num_vertices, triangles, uvs, triangle_uvs, config: BFMConfig) -> AlbedoModel:
    raster = rasterize_uv(uvs, triangle_uvs, config.texture_size)
    maps = {}
    with h5py.File(path, "r") as albedo:
        for kind in ("diffuseAlbedo", "specularAlbedo"):
            mean = np.asarray(albedo[f"{kind}/model/mean"], np.float64).reshape(-1, 3)
            if len(mean) != num_vertices:
                raise ValueError(f"{path}: {kind} has {len(mean)} vertices, BFM has {num_vertices}")
            basis = standard_normal_basis(
                np.asarray(albedo[f"{kind}/model/pcaBasis"])[:, : config.num_albedo],
                np.asarray(albedo[f"{kind}/model/pcaVariance"])[: config.num_albedo],
            )
            vertex_uv_triangles = triangles  # per-vertex values follow the position triangles
            maps[kind] = splat_albedo(raster, vertex_uv_triangles, mean, basis)
    if maps["diffuseAlbedo"][1].shape[0] != maps["specularAlbedo"][1].shape[0]:
        raise ValueError(f"{path}: diffuse and specular have different numbers of components")
    return AlbedoModel(
        diffuse_mean=maps["diffuseAlbedo"][0],
        diffuse_basis=maps["diffuseAlbedo"][1],
        specular_mean=maps["specularAlbedo"][0],
        specular_basis=maps["specularAlbedo"][1],
        roughness_default=ALBEDOMM_ROUGHNESS,
        face_mask=coverage(uvs, triangle_uvs, config.texture_size, supersample=2),
        description=f"AlbedoMM (Smith et al. 2020) per-vertex model splatted to {config.texture_size}^2 UV",
    )


def setup_report(models_dir: str | os.PathLike | None = None) -> tuple[list[str], str | None]:
    """What ``deface fit --model bfm`` would use (landmark metadata, correspondence, UV layout), as lines, and
    a one-line problem when the correspondence could not be had (None when it can)."""
    target = models_dir_candidates(models_dir)[0]
    correspondence = find_model_file(CORRESPONDENCE_FILE, models_dir)
    uv_layout = find_model_file(UV_LAYOUT_FILE, models_dir)
    lines = [
        "BFM correspondence: "
        + (f"your file {correspondence}" if correspondence else
           f"built from the landmark metadata and cached (or put your own at {target / CORRESPONDENCE_FILE})"),
        "BFM UV layout: " + (f"your file {uv_layout}" if uv_layout else
                             f"computed cylindrical layout (or put an OBJ with vt at {target / UV_LAYOUT_FILE})"),
    ]
    bfm_path = find_model_file(BFM_FILE, models_dir)
    if bfm_path is None:
        return [f"BFM landmark metadata: unknown ({BFM_FILE} not found)", *lines], None
    with h5py.File(bfm_path, "r") as h5:
        names, _ = read_named_landmarks(h5, bfm_path)
    usable = len(named_anchor_ids(names)[0])
    found = f"found, {len(names)} named points, {usable} with a MediaPipe equivalent" if names else "not found"
    lines.insert(0, f"BFM landmark metadata ({LANDMARKS_DATASET} in {bfm_path}): {found}")
    if correspondence is None and usable < MIN_NAMED_ANCHORS:
        try:
            _check_anchors(bfm_path, names, models_dir)
        except ModelFileError as error:
            return lines, str(error)
    return lines, None
