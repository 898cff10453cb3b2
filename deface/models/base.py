"""The face-model interface every model implements.

Units and frames: vertex positions in centimetres, model frame +x to the subject's left (viewer's right),
+y up, +z toward the viewer (ICT-FaceKit's frame; other models are converted to it on load).
Identity coefficients are standard-normal (N(0, 1) prior); expression coefficients are described by
``expression_prior`` ("blendshape": weights in [0, 1], "pca": N(0, 1)).
Albedo lives in UV space (row 0 of a texture image is v = 1, the OBJ convention).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from deface.models.skin_tone import SkinToneAxis


@dataclass(frozen=True)
class AlbedoModel:
    """A linear UV-space albedo model: T = mean + sum_k coeff_k * basis_k (diffuse and specular share coeffs).

    Coefficients are standard-normal. Maps are linear reflectance in [0, 1].
    """

    diffuse_mean: np.ndarray  # [Ht, Wt, 3]
    diffuse_basis: np.ndarray  # [Ka, Ht, Wt, 3]
    specular_mean: np.ndarray  # [Ht, Wt, 3]
    specular_basis: np.ndarray  # [Ka, Ht, Wt, 3]
    roughness_default: float  # a constant roughness map value (Beckmann/GGX alpha)
    face_mask: np.ndarray  # [Ht, Wt] float in [0, 1], texels covered by the face's UV layout
    description: str  # where the numbers come from (shown in params.json)
    component_names: tuple[str, ...] = ()  # optional name per coefficient (e.g. "melanin:s0v0")
    tone: SkinToneAxis | None = None  # the skin-tone axis through the mean skin (None: the model has none)

    @property
    def num_coeffs(self) -> int:
        return int(self.diffuse_basis.shape[0])

    def textures(self, coeffs: torch.Tensor, size: int, ita: torch.Tensor | None = None
                 ) -> tuple[torch.Tensor, torch.Tensor]:
        """Diffuse and specular UV maps [size, size, 3] for coeffs [Ka], differentiable in coeffs; with a
        skin tone ``ita`` (degrees, scalar tensor) the diffuse map is moved along :attr:`tone` to it."""
        diffuse = _combine(self.diffuse_mean, self.diffuse_basis, coeffs)
        if ita is not None:
            if self.tone is None:
                raise ValueError("this albedo model has no skin-tone axis")
            diffuse = diffuse * self.tone.scale(ita.to(diffuse.dtype))
        specular = _combine(self.specular_mean, self.specular_basis, coeffs)
        return _resize(diffuse, size), _resize(specular, size)


def _combine(mean: np.ndarray, basis: np.ndarray, coeffs: torch.Tensor) -> torch.Tensor:
    mean_t = torch.as_tensor(mean, dtype=coeffs.dtype)
    basis_t = torch.as_tensor(basis, dtype=coeffs.dtype)
    return mean_t + torch.einsum("k,khwc->hwc", coeffs, basis_t)


def _resize(image: torch.Tensor, size: int) -> torch.Tensor:
    if image.shape[0] == size and image.shape[1] == size:
        return image
    resized = torch.nn.functional.interpolate(
        image.permute(2, 0, 1)[None], size=(size, size), mode="bilinear", align_corners=False
    )
    return resized[0].permute(1, 2, 0)


@dataclass(frozen=True)
class FaceModel:
    """A morphable face: geometry bases, topology with UV seams, albedo prior, landmark vertices."""

    name: str
    mean_shape: np.ndarray  # [V, 3] float32, cm
    identity_basis: np.ndarray  # [Ki, V, 3] float32, cm per unit (N(0,1)) coefficient
    expression_basis: np.ndarray  # [Ke, V, 3] float32, cm per unit coefficient
    expression_prior: str  # "blendshape" (weights in [0, 1]) or "pca" (N(0, 1))
    expression_names: tuple[str, ...]
    triangles: np.ndarray  # [F, 3] int64 vertex indices, counter-clockwise seen from outside
    uvs: np.ndarray  # [U, 2] float32 in [0, 1]
    triangle_uvs: np.ndarray  # [F, 3] int64 indices into uvs (a vertex may have several UVs: seams)
    albedo: AlbedoModel | None
    landmarks_68: np.ndarray | None = None  # [68] vertex ids of the iBUG/Multi-PIE 68 points, if known
    landmark_names: tuple[str, ...] = ()  # the model's own named 3D landmarks (BFM: "center.nose.tip", ...)
    landmark_points: np.ndarray | None = None  # [L, 3] float32 cm, model frame: where landmark_names are
    correspondence_file: str | None = None  # user-supplied MediaPipe -> model file, used instead of building one

    @property
    def num_vertices(self) -> int:
        return int(self.mean_shape.shape[0])

    @property
    def num_identity(self) -> int:
        return int(self.identity_basis.shape[0])

    @property
    def num_expression(self) -> int:
        return int(self.expression_basis.shape[0])

    def vertices(self, identity: torch.Tensor, expression: torch.Tensor) -> torch.Tensor:
        """Vertex positions [V, 3] (cm, model frame) for identity [Ki] and expression [Ke] coefficients.

        Batched coefficients [N, Ki], [N, Ke] give [N, V, 3].
        """
        dtype = identity.dtype
        mean = torch.as_tensor(self.mean_shape, dtype=dtype)
        id_basis = torch.as_tensor(self.identity_basis, dtype=dtype)
        ex_basis = torch.as_tensor(self.expression_basis, dtype=dtype)
        return (
            mean
            + torch.einsum("...k,kvc->...vc", identity, id_basis)
            + torch.einsum("...k,kvc->...vc", expression, ex_basis)
        )
