"""Basel Face Model 2017 (face12, no mouth) + AlbedoMM, read from the user's own files.

Files (not redistributable; see ``deface models list``):
- ``bfm2017/model2017-1_face12_nomouth.h5``: ``shape/model/{mean, pcaBasis, pcaVariance}`` ([3V], [3V, 199],
  [199]), ``expression/model/{pcaBasis, pcaVariance}`` ([3V, 100], [100]), ``shape/representer/cells``
  ([3, F] triangle vertex ids); positions flattened x, y, z per vertex, in millimetres.
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

import os
import pickle
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from deface.models.base import AlbedoModel, FaceModel
from deface.models.uvmap import coverage, rasterize_uv
from deface.paths import ModelFileError, find_model_file

BFM_FILE = "bfm2017/model2017-1_face12_nomouth.h5"
ALBEDOMM_FILE = "albedomm/albedoModel2020_face12_albedoPart.h5"
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
    """NextFace uvParametrization pickle or an OBJ with vt; None: cylindrical projection."""
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
    with h5py.File(bfm_path, "r") as bfm:
        mean = np.asarray(bfm["shape/model/mean"], np.float64).reshape(-1, 3) * MM_TO_CM
        identity = (
            standard_normal_basis(
                np.asarray(bfm["shape/model/pcaBasis"]), np.asarray(bfm["shape/model/pcaVariance"])
            )
            * MM_TO_CM
        )
        expression = (
            standard_normal_basis(
                np.asarray(bfm["expression/model/pcaBasis"]), np.asarray(bfm["expression/model/pcaVariance"])
            )
            * MM_TO_CM
        )
        cells = np.asarray(bfm["shape/representer/cells"], np.int64)
    triangles = cells.T if cells.shape[0] == 3 else cells
    if triangles.max() >= len(mean):
        raise ValueError(f"{bfm_path}: cells index vertex {triangles.max()} of {len(mean)}")
    triangles = orient_outward(np.ascontiguousarray(triangles), mean)
    if config.uv_file:
        uvs, triangle_uvs = load_uv_file(config.uv_file, len(mean), triangles)
    else:
        uvs, triangle_uvs = cylindrical_uvs(mean), triangles.copy()
    albedo = _load_albedomm(albedo_path, len(mean), triangles, uvs, triangle_uvs, config)
    return FaceModel(
        name="bfm",
        mean_shape=mean.astype(np.float32),
        identity_basis=identity[: config.num_identity].astype(np.float32),
        expression_basis=expression[: config.num_expression].astype(np.float32),
        expression_prior="pca",
        expression_names=tuple(f"pca{i:03d}" for i in range(len(expression[: config.num_expression]))),
        triangles=triangles,
        uvs=uvs,
        triangle_uvs=triangle_uvs,
        albedo=albedo,
        landmarks_68=None,
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
