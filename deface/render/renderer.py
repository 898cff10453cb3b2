"""Differentiable CPU renderer: Embree primary visibility, torch shading under K SH lights at once.

Pipeline (one call renders every light condition; the geometry is visited once):
1. ``rasterize``: Embree casts one ray per pixel centre (only inside the mesh's projected bounding box)
   and returns the hit triangle id. Barycentrics are then *recomputed in torch* from the projected
   triangle corners (2-D edge functions at the pixel centre, then perspective-corrected with the
   corners' camera depths), so gradients reach vertex positions and every camera parameter.
2. ``shade``: per-vertex SH irradiance [V, K*3] (analytic unshadowed term minus the ray-traced occluded
   transfer, see shadow.py) is interpolated to the covered pixels; diffuse radiance = albedo / pi * E.
   A Phong specular lobe filtered in SH (see ``_specular_bands``): per-band SH sums at each vertex's
   reflected view direction are interpolated like the irradiance and filtered per pixel with the
   texel's roughness, then scaled by the interpolated vertex visibility (specular shadow approximation).
Background pixels are 0 in every output. Everything runs on the tensors' device; CPU is the reference.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import torch

from deface.render import kernels
from deface.render.camera import Camera
from deface.render.mesh import Mesh, Textures, sample_textures
from deface.render.raycast import RayScene
from deface.render.sh import (
    cosine_lobe_coefficients,
    kernel_constants,
    phong_lobe_filter,
    sh_band_sums,
    sh_basis_rows,
)
from deface.render.shadow import ShadowTransfer, compute_shadow_transfer


@dataclass(frozen=True)
class RenderConfig:
    """Renderer settings."""

    bands: int = 9
    """SH bands B of the lights (B² coefficients per colour) and of the shadow transfer."""
    shadows: bool = True
    """Ray-traced self-shadowing: ``render`` refreshes/uses its transfer cache when no transfer is given."""
    shadow_rays: int = 256
    """Shadow rays per vertex S for one transfer refresh (cost ~ V x S Embree any-hit queries)."""
    specular: bool = True
    """Add the roughness-driven Phong specular lobe; off gives a purely Lambertian render."""
    shadow_tolerance_cm: float = 0.05
    """The transfer cache recomputes when any vertex moved more than this (cm) since the last refresh."""
    seed: int = 0
    """Seed of the per-vertex random rotations of the shadow-ray pattern (renders are deterministic)."""
    shadow_ray_offset: float = 1e-3
    """Shadow-ray origins move along the normal by this fraction of the mesh's bounding-box diagonal."""


@dataclass(frozen=True)
class Fragments:
    """What covers each pixel: the triangle from ray casting, barycentrics from torch."""

    triangle_id: torch.Tensor  # [H, W] long, -1 on background
    mask: torch.Tensor  # [H, W] float, 1 where a triangle covers the pixel centre
    covered: torch.Tensor  # [N] long, flat indices (y * W + x) of the covered pixels
    covered_barycentrics: torch.Tensor  # [N, 3] perspective-correct, differentiable
    covered_triangles: torch.Tensor  # [N] long, triangle id of each covered pixel

    @cached_property
    def barycentrics(self) -> torch.Tensor:
        """[H, W, 3] image of ``covered_barycentrics`` (same graph), 0 on background; built on first use
        (shading reads only the covered pixels)."""
        bary = self.covered_barycentrics
        full = bary.new_zeros(self.triangle_id.numel(), 3).index_copy(0, self.covered, bary)
        return full.reshape(*self.triangle_id.shape, 3)


@dataclass(frozen=True)
class RenderOutput:
    """Images under each light plus screen-space buffers; background pixels are 0."""

    images: torch.Tensor  # [K, H, W, 3] linear RGB radiance
    mask: torch.Tensor  # [H, W] coverage M_R
    uv: torch.Tensor  # [H, W, 2]
    normals: torch.Tensor  # [H, W, 3] unit, model frame
    depth: torch.Tensor  # [H, W] camera-frame z (cm)
    triangle_id: torch.Tensor  # [H, W] long, -1 on background
    diffuse: torch.Tensor  # [H, W, 3] screen-space diffuse albedo
    specular: torch.Tensor  # [H, W, 3] screen-space specular albedo
    roughness: torch.Tensor  # [H, W, 1] screen-space roughness


class Renderer:
    """Renders meshes under K SH lights; see the module docstring for the pipeline."""

    def __init__(self, config: RenderConfig = RenderConfig()):
        if config.bands < 1 or config.shadow_rays < 1:
            raise ValueError("RenderConfig: bands and shadow_rays must be >= 1")
        self.config = config
        self.cache = ShadowTransferCache(self)
        self._scene_key: tuple[np.ndarray, np.ndarray] | None = None
        self._scene: RayScene | None = None

    # -- visibility -------------------------------------------------------------------------------
    def ray_scene(self, mesh: Mesh) -> RayScene:
        """The Embree scene of ``mesh``, rebuilt only when vertices or triangles changed."""
        verts = mesh.vertices.detach().cpu().numpy().astype(np.float32)
        tris = mesh.triangles.cpu().numpy()
        key = self._scene_key
        if (
            key is None
            or key[0].shape != verts.shape
            or key[1].shape != tris.shape
            or not np.array_equal(key[0], verts)
            or not np.array_equal(key[1], tris)
        ):
            self._scene = RayScene(verts, tris)
            self._scene_key = (verts, tris)
        return self._scene

    def rasterize(self, mesh: Mesh, camera: Camera) -> Fragments:
        """Triangle id per pixel by Embree ray casting; perspective-correct barycentrics in torch."""
        camera = camera.resolved()
        projected = camera.project(mesh.vertices)  # one projection serves the ray boxes and the barycentrics
        triangle_id = torch.from_numpy(self._cast_primary(mesh, camera, projected))
        return self.fragments_for(mesh, camera, triangle_id.reshape(camera.height, camera.width), projected)

    @staticmethod
    def fragments_for(
        mesh: Mesh, camera: Camera, triangle_id: torch.Tensor, projected: tuple | None = None
    ) -> Fragments:
        """Fragments for given per-pixel triangle ids [H, W] (-1 background), no ray casting.

        Barycentrics are recomputed from ``mesh`` and ``camera`` (or from ``projected`` = camera.project(
        mesh.vertices) when the caller has it): use it to keep visibility fixed while geometry changes
        slightly (finite differences, several shading passes).
        """
        camera = camera.resolved()
        height, width = camera.height, camera.width
        if tuple(triangle_id.shape) != (height, width):
            raise ValueError(f"fragments_for: triangle_id must be [{height}, {width}], got {tuple(triangle_id.shape)}")
        device, dtype = mesh.vertices.device, mesh.vertices.dtype
        tid = triangle_id.to(device=device, dtype=torch.long)
        flat = tid.reshape(-1)
        covered = torch.nonzero(flat >= 0)[:, 0]  # [N]
        triangles = flat.index_select(0, covered)  # [N]
        bary = _barycentrics(mesh, camera, triangles, covered, projected)  # [N, 3]
        return Fragments(
            triangle_id=tid,
            mask=(tid >= 0).to(dtype),
            covered=covered,
            covered_barycentrics=bary,
            covered_triangles=triangles,
        )

    def _cast_primary(self, mesh: Mesh, camera: Camera, projected: tuple) -> np.ndarray:
        """[H*W] triangle ids; only pixels inside the projected bounding box of the mesh (with the numba
        kernels: of some triangle) are traced. projected = camera.project(mesh.vertices)."""
        height, width = camera.height, camera.width
        pixels, depth = (t.detach() for t in projected)
        triangle_id = np.full(height * width, -1, dtype=np.int64)
        in_front = bool((depth > 0).all())
        if not in_front:  # a vertex behind the camera: the projected box is meaningless
            x0, y0, x1, y1 = 0, 0, width, height
        else:
            lo = pixels.min(0).values.floor().long().tolist()
            hi = pixels.max(0).values.ceil().long().tolist()
            x0, y0 = max(lo[0], 0), max(lo[1], 0)
            x1, y1 = min(hi[0] + 1, width), min(hi[1] + 1, height)
        if x0 >= x1 or y0 >= y1:
            return triangle_id
        if in_front and kernels.enabled(pixels):
            # only pixels inside some triangle's projected box (a ray elsewhere cannot hit): ~half as many rays
            flat = kernels.triangle_box_pixels(pixels, mesh.triangles, height, width)
        else:
            ys, xs = np.meshgrid(np.arange(y0, y1), np.arange(x0, x1), indexing="ij")
            flat = (ys * width + xs).reshape(-1)
        origins, directions = _pixel_rays(camera, flat)
        triangle_id[flat] = self.ray_scene(mesh).first_triangles(origins, directions)
        return triangle_id

    def shadow_transfer(self, mesh: Mesh) -> ShadowTransfer:
        """One refresh of the occluded SH transfer (V x shadow_rays Embree rays; see shadow.py)."""
        cfg = self.config
        return compute_shadow_transfer(
            mesh.vertices,
            mesh.triangles,
            mesh.vertex_normals(),
            cfg.bands,
            cfg.shadow_rays,
            seed=cfg.seed,
            offset=cfg.shadow_ray_offset,
            scene=self.ray_scene(mesh),
        )

    # -- shading ----------------------------------------------------------------------------------
    def shade(
        self,
        mesh: Mesh,
        camera: Camera,
        fragments: Fragments,
        textures: Textures,
        sh_lights: torch.Tensor,
        transfer: ShadowTransfer | None,
    ) -> RenderOutput:
        """Shade covered pixels under every light ``sh_lights`` [K, B², 3]; ``transfer`` None = no shadows."""
        camera = camera.resolved()
        bands = _bands_of(sh_lights)
        num_lights = sh_lights.shape[0]
        height, width = camera.height, camera.width
        covered, bary = fragments.covered, fragments.covered_barycentrics  # [N], [N, 3]
        corners = mesh.triangles.index_select(0, fragments.covered_triangles)  # [N, 3]
        dtype = sh_lights.dtype
        coeffs = sh_lights.permute(1, 0, 2).reshape(bands * bands, num_lights * 3)  # [B², K*3]

        # Only vertices of covered triangles are shaded: corners are renumbered into that subset.
        used, local = _renumber(corners, mesh.num_vertices)  # [U], [N, 3]
        normals_v = mesh.vertex_normals().index_select(0, used).to(dtype)  # [U, 3]
        irradiance_v = _vertex_irradiance(normals_v, coeffs, bands, transfer, used)  # [U, K*3]

        uv_corners = mesh.triangle_uvs.index_select(0, fragments.covered_triangles)  # [N, 3]
        camera_z = camera.to_camera(mesh.vertices.index_select(0, used))[:, 2:]  # [U, 1]
        if self._fused(sh_lights, textures, mesh, bary):
            positions = mesh.vertices.index_select(0, used).to(dtype)  # [U, 3]
            bands_v = _specular_bands(positions, normals_v, camera, coeffs, bands)  # [U, B*K*3]
            visibility = (
                transfer.visibility.to(dtype).index_select(0, used)[:, None]
                if transfer is not None
                else normals_v.new_ones(normals_v.shape[0], 1)
            )
            plain = torch.cat([irradiance_v, normals_v, camera_z.to(dtype), visibility], 1)  # [U, K*3 + 5]
            images, *buffers = _KernelShade.apply(
                plain,
                bands_v.reshape(-1, bands, num_lights * 3),
                mesh.uvs.to(dtype),
                bary,
                textures.diffuse,
                textures.specular,
                textures.roughness,
                (covered, local, uv_corners),
                (height, width),
            )
            return RenderOutput(images, fragments.mask, *buffers[:3], fragments.triangle_id, *buffers[3:])

        # One gather for every per-vertex quantity (index_select's backward is a fast index_add).
        per_vertex = [irradiance_v, normals_v, camera_z.to(dtype)]
        if self.config.specular:
            positions = mesh.vertices.index_select(0, used).to(dtype)  # [U, 3]
            bands_v = _specular_bands(positions, normals_v, camera, coeffs, bands)  # [U, B*K*3]
            if transfer is not None:
                per_vertex.append(transfer.visibility.to(dtype).index_select(0, used)[:, None])
        sizes = [t.shape[1] for t in per_vertex]
        pixel_values = _interpolate(torch.cat(per_vertex, 1), local, bary).split(sizes, 1)
        irradiance, normals, depth = pixel_values[:3]  # [N, K*3], [N, 3], [N, 1]
        normals = normals / normals.norm(dim=-1, keepdim=True).clamp_min(1e-12)

        uv = _interpolate(mesh.uvs.to(dtype), uv_corners, bary)  # [N, 2]
        diffuse, specular, roughness = sample_textures([textures.diffuse, textures.specular, textures.roughness], uv)

        if self.config.specular:
            lobe = phong_lobe_filter(roughness[:, 0], bands).to(dtype)  # [N, B], per-texel roughness
            lit = _filtered_interpolation(bands_v, local, bary, lobe)  # [N, K*3]
            visibility = pixel_values[3] if transfer is not None else lit.new_ones(lit.shape[0], 1)
            radiance = _radiance(irradiance, diffuse, lit, visibility, specular)  # [N, K*3]
        else:
            radiance = (irradiance.reshape(-1, num_lights, 3) * (diffuse / math.pi)[:, None]).flatten(1)

        def screen(values: torch.Tensor) -> torch.Tensor:  # [N, C] -> [H, W, C], zeros elsewhere
            full = torch.zeros(height * width, values.shape[1], dtype=values.dtype, device=values.device)
            return full.index_copy(0, covered, values).reshape(height, width, -1)

        images = screen(radiance).reshape(height, width, num_lights, 3).permute(2, 0, 1, 3)
        return RenderOutput(
            images=images,
            mask=fragments.mask,
            uv=screen(uv),
            normals=screen(normals),
            depth=screen(depth)[..., 0],
            triangle_id=fragments.triangle_id,
            diffuse=screen(diffuse),
            specular=screen(specular),
            roughness=screen(roughness),
        )

    def _fused(self, sh_lights, textures: Textures, mesh: Mesh, bary: torch.Tensor) -> bool:
        """Whether ``shade`` runs the fused numba pixel kernel (specular on, one dtype and size, fixed uvs)."""
        maps = (textures.diffuse, textures.specular, textures.roughness)
        return (
            self.config.specular
            and not mesh.uvs.requires_grad
            and kernels.enabled(sh_lights, bary, *maps)
            and len({t.dtype for t in (sh_lights, bary, *maps)}) == 1
            and len({t.shape[:2] for t in maps}) == 1  # one bilinear set-up serves the three maps
        )

    def render(
        self,
        mesh: Mesh,
        camera: Camera,
        textures: Textures,
        sh_lights: torch.Tensor,
        transfer: ShadowTransfer | None = None,
    ) -> RenderOutput:
        """rasterize + shade. With ``config.shadows`` and no ``transfer``, uses ``self.cache`` (refreshes
        when the mesh moved more than ``shadow_tolerance_cm``); with ``shadows=False`` nothing is occluded."""
        if self.config.shadows and transfer is None:
            transfer = self.cache.get(mesh)
        elif not self.config.shadows:
            transfer = None
        camera = camera.resolved()
        return self.shade(mesh, camera, self.rasterize(mesh, camera), textures, sh_lights, transfer)


def vertex_irradiance(mesh: Mesh, sh_lights: torch.Tensor, transfer: ShadowTransfer | None = None) -> torch.Tensor:
    """Per-vertex SH irradiance [V, K, 3]: analytic unshadowed term minus the occluded transfer (if given).

    E_v = sum_lm A_l c_lm Y_lm(n_v) - sum_lm c_lm O_v[lm]; Lambertian radiance is albedo / pi * E.
    """
    bands = _bands_of(sh_lights)
    num_lights = sh_lights.shape[0]
    coeffs = sh_lights.permute(1, 0, 2).reshape(bands * bands, num_lights * 3)
    normals = mesh.vertex_normals().to(sh_lights.dtype)
    return _vertex_irradiance(normals, coeffs, bands, transfer).reshape(-1, num_lights, 3)


def _vertex_irradiance(
    normals: torch.Tensor,
    coeffs: torch.Tensor,
    bands: int,
    transfer: ShadowTransfer | None,
    subset: torch.Tensor | None = None,
) -> torch.Tensor:
    """normals [U, 3], coeffs [B², K*3] -> irradiance [U, K*3].

    ``subset`` [U] (long) are the mesh vertices the normals belong to (None: all V vertices, U = V).
    """
    lobe = cosine_lobe_coefficients(bands).to(coeffs)  # [B²]
    if transfer is not None:
        _check_transfer(transfer, bands, normals.shape[0] if subset is None else None)
    if kernels.enabled(normals, coeffs) and normals.dtype == coeffs.dtype:
        occluded = None if transfer is None else transfer.occluded
        return _KernelIrradiance.apply(normals, coeffs, lobe, occluded, subset)
    # transfer A_l Y_lm(n) - O[lm] per vertex, channel-first [B², U] like the basis rows (mixed layouts make
    # the element-wise ops slow), then one product with the lights: fewer [U, B²] x [B², K*3] products
    # forward and backward than filtering the lights and subtracting a second product
    transfer_rows = sh_basis_rows(normals, bands) * lobe[:, None]  # [B², U]
    if transfer is not None:
        occluded = transfer.occluded_rows  # [B²', V]
        if subset is not None:
            occluded = occluded.index_select(1, subset)
        transfer_rows = transfer_rows - occluded[: bands * bands].to(coeffs.dtype)
    return transfer_rows.T @ coeffs


def _check_transfer(transfer: ShadowTransfer, bands: int, num_vertices: int | None) -> None:
    """The transfer covers ``bands`` bands and (when given) ``num_vertices`` vertices."""
    vertices = transfer.occluded.shape[0]
    if transfer.bands < bands or (num_vertices is not None and vertices != num_vertices):
        wanted = f"{bands} bands" + ("" if num_vertices is None else f" for {num_vertices} vertices")
        raise ValueError(f"shadow transfer has {transfer.bands} bands for {vertices} vertices, need >= {wanted}")


class _KernelIrradiance(torch.autograd.Function):
    """The numba path of ``_vertex_irradiance``: SH basis, shadowed transfer and the product with the lights
    per block of normals (no [B², U] rows, no serial matmuls); gradients to normals and coeffs."""

    @staticmethod
    def forward(ctx, normals, coeffs, lobe, occluded, subset):
        ctx.save_for_backward(normals, coeffs)
        ctx.inputs = (lobe, occluded, subset, kernel_constants(math.isqrt(lobe.shape[0])))
        return kernels.sh_irradiance_forward(normals, coeffs, *ctx.inputs)

    @staticmethod
    def backward(ctx, grad):
        normals, coeffs = ctx.saved_tensors
        lobe, occluded, subset, constants = ctx.inputs
        need = ctx.needs_input_grad[:2]
        grads = kernels.sh_irradiance_backward(normals, coeffs, lobe, occluded, subset, grad, constants, *need)
        return *grads, None, None, None


class ShadowTransferCache:
    """Holds a Renderer's shadow transfer and refreshes it when the geometry moved.

    Trigger: ``get(mesh)`` recomputes when there is no transfer yet, when the vertex count changed, or
    when max_v |x_v - x_v(last refresh)| > ``config.shadow_tolerance_cm``. Between refreshes the stored
    occluded transfer is reused as a constant (the analytic unshadowed term still follows the current
    normals). Cost of a refresh: V x ``shadow_rays`` Embree any-hit rays plus SH of the occluded ones,
    about 0.5-1 s for the 9,409-vertex ICT mesh at 256 rays (see benchmarks/render.md); a hit costs a
    max-abs over the vertices.
    """

    def __init__(self, renderer: Renderer):
        self.renderer = renderer
        self.transfer: ShadowTransfer | None = None
        self.refreshes = 0  # how many times the transfer was recomputed

    def needs_refresh(self, mesh: Mesh) -> bool:
        """Whether ``get(mesh)`` would recompute the transfer."""
        if self.transfer is None or self.transfer.vertices.shape != mesh.vertices.shape:
            return True
        moved = (mesh.vertices.detach() - self.transfer.vertices.to(mesh.vertices)).abs().max()
        return bool(moved > self.renderer.config.shadow_tolerance_cm)

    def get(self, mesh: Mesh) -> ShadowTransfer:
        """The current transfer for ``mesh``, recomputed first if the mesh moved beyond the tolerance."""
        if self.needs_refresh(mesh):
            self.transfer = self.renderer.shadow_transfer(mesh)
            self.refreshes += 1
        return self.transfer


def _specular_bands(
    positions: torch.Tensor, normals: torch.Tensor, camera: Camera, coeffs: torch.Tensor, bands: int
) -> torch.Tensor:
    """Per-vertex, per-band reflected radiance S_l(v) = sum_m c_lm Y_lm(r_v), [U, B*K*3] (band-major).

    The Phong specular radiance per unit k_s is L_spec = sum_l Lambda_l(alpha) S_l(r), r = 2 (n.v) n - v
    the mirrored view direction, with the Phong SH filter Lambda_l = exp(-l²/(2s)), s = 2/alpha² - 2
    (Ramamoorthi & Hanrahan 2001, "A signal-processing framework for inverse rendering"; Walter et al.
    2007 for s(alpha)); see ``sh.phong_lobe_filter``. A constant environment L gives k_s L.

    Approximation: the band sums S_l are evaluated at the *vertices'* reflected directions (vertex
    normal, view from the camera centre to the vertex) and interpolated to the pixels with the
    barycentrics, as Gouraud shading does; the roughness filter Lambda_l is then applied per pixel, so
    the per-texel roughness stays exact. Highlights narrower than a triangle are blurred across it, in
    exchange for ~4-5x fewer SH evaluations (ICT at 256²: 6.2k used vertices, 29k pixels). Since
    Lambda_0 = 1 and barycentrics sum to 1, a constant environment still gives exactly k_s L.
    """
    centre = camera.center_in_model().to(positions)
    if kernels.enabled(positions, normals, centre) and positions.dtype == normals.dtype:
        reflected = _KernelReflection.apply(positions, normals, centre)
    else:
        view = centre - positions
        view = view / view.norm(dim=-1, keepdim=True).clamp_min(1e-12)  # [U, 3] towards the camera
        reflected = 2 * (normals * view).sum(-1, keepdim=True) * normals - view  # [U, 3]
        reflected = reflected / reflected.norm(dim=-1, keepdim=True).clamp_min(1e-12)  # unit for the SH
    return sh_band_sums(reflected.to(coeffs.dtype), coeffs).reshape(positions.shape[0], -1)


class _KernelReflection(torch.autograd.Function):
    """The numba path of the mirrored view directions in ``_specular_bands`` (the same formulas, one loop
    per vertex instead of ~12 small ops and their backward): positions, normals [U, 3], centre [3]."""

    @staticmethod
    def forward(ctx, positions, normals, centre):
        ctx.save_for_backward(positions, normals, centre)
        return kernels.reflect_forward(positions, normals, centre)

    @staticmethod
    def backward(ctx, grad):
        return kernels.reflect_backward(*ctx.saved_tensors, grad)


def _radiance(irradiance, diffuse, lit, visibility, specular) -> torch.Tensor:
    """Diffuse plus shadowed specular radiance of the covered pixels, [N, K*3]:
    irradiance [N, K*3] * diffuse [N, 3] / pi + lit [N, K*3] * visibility [N, 1] * specular [N, 3]."""
    num = irradiance.shape[0]
    diffuse_part = irradiance.reshape(num, -1, 3) * (diffuse / math.pi)[:, None]
    return (diffuse_part + (lit * visibility).reshape(num, -1, 3) * specular[:, None]).reshape(num, -1)


class _KernelShade(torch.autograd.Function):
    """The numba path of ``Renderer.shade``'s pixel stage, fused: per covered pixel it interpolates the
    per-vertex values, looks up the three maps, applies the Phong filter and writes every screen buffer;
    the backward is one pass over the pixels that also scatters the per-vertex gradients (kernels.shade_backward).

    Inputs: plain [U, K*3 + 5] (irradiance, normal, camera z, visibility per used vertex), bands_v
    [U, B, K*3], uvs [Nuv, 2], bary [N, 3], the diffuse / specular / roughness maps; pixels = (covered
    [N], corners [N, 3] into U, uv corners [N, 3]); size = (H, W). The formulas are those of the torch
    path of ``shade`` (the reference, compared in tests/test_render_kernels.py).
    """

    @staticmethod
    def forward(ctx, plain, bands_v, uvs, bary, diffuse, specular, roughness, pixels, size):
        ctx.set_materialize_grads(False)
        ctx.save_for_backward(plain, bands_v, uvs, bary, diffuse, specular, roughness)
        maps = (diffuse, specular, roughness)
        outputs, ctx.lit = kernels.shade_forward(plain, bands_v, uvs, bary, maps, pixels, size)
        ctx.pixels, ctx.width = pixels, size[1]
        return tuple(outputs)

    @staticmethod
    def backward(ctx, *grads):
        plain, bands_v, uvs, bary, *maps = ctx.saved_tensors
        grad_plain, grad_bands, grad_bary, grad_maps = kernels.shade_backward(
            plain, bands_v, uvs, bary, maps, ctx.pixels, ctx.width, grads, ctx.needs_input_grad[4:7], ctx.lit
        )
        return grad_plain, grad_bands, None, grad_bary, *grad_maps, None, None


def _filtered_interpolation(
    values: torch.Tensor, corners: torch.Tensor, bary: torch.Tensor, lobe: torch.Tensor
) -> torch.Tensor:
    """out[p] = sum_i sum_l bary[p, i] lobe[p, l] S[corner_i(p), l]: values S [U, B*C] (band-major),
    corners [N, 3], bary [N, 3], lobe [N, B] -> [N, C]. numba kernel on the CPU, sparse torch elsewhere."""
    if kernels.enabled(values, bary, lobe) and values.dtype == bary.dtype == lobe.dtype:
        return _KernelInterpolation.apply(values, corners, bary, lobe)
    return _FilteredInterpolation.apply(values, corners, bary, lobe)


class _KernelInterpolation(torch.autograd.Function):
    """The numba path of ``_filtered_interpolation`` (kernels.py); no sparse matrices, no [N, B*C] buffers."""

    @staticmethod
    def forward(ctx, values, corners, bary, lobe):
        ctx.save_for_backward(values, corners, bary, lobe)
        return kernels.interpolate_forward(values.reshape(values.shape[0], lobe.shape[1], -1), corners, bary, lobe)

    @staticmethod
    def backward(ctx, grad):
        values, corners, bary, lobe = ctx.saved_tensors
        per_band = values.reshape(values.shape[0], lobe.shape[1], -1)  # [U, B, C]
        grad_values = grad_bary = grad_lobe = None
        if ctx.needs_input_grad[2] or ctx.needs_input_grad[3]:
            grad_bary, grad_lobe = kernels.interpolate_backward_corners(per_band, corners, bary, lobe, grad)
        if ctx.needs_input_grad[0]:
            grad_values = kernels.interpolate_backward_values(per_band.shape[0], corners, bary, lobe, grad)
            grad_values = grad_values.reshape(values.shape)
        return grad_values, None, grad_bary, grad_lobe


class _FilteredInterpolation(torch.autograd.Function):
    """Reference (torch) path of ``_filtered_interpolation``: a sparse [N, U*B] matrix with 3B weights
    bary[p, i] lobe[p, l] per pixel times S viewed as [U*B, C].

    No [N, B*C] per-pixel buffer is materialised in the forward pass (such buffers cost more in page
    faults than in arithmetic).
    """

    @staticmethod
    def forward(ctx, values, corners, bary, lobe):
        num, bands = lobe.shape
        channels = values.shape[1] // bands
        weights = (bary[:, :, None] * lobe[:, None, :]).reshape(-1)  # [N*3*B]
        columns = (corners[:, :, None] * bands + torch.arange(bands, device=corners.device)).reshape(-1)
        rows = torch.arange(0, weights.numel() + 1, 3 * bands, device=corners.device)
        matrix = _csr(rows, columns, weights, size=(num, values.shape[0] * bands))
        flat = values.reshape(-1, channels)  # [U*B, C]
        ctx.save_for_backward(values, corners, bary, lobe, rows, columns)
        return matrix @ flat

    @staticmethod
    def backward(ctx, grad):
        values, corners, bary, lobe, rows, columns = ctx.saved_tensors
        num, bands = lobe.shape
        grad = grad.contiguous()
        grad_values = grad_bary = grad_lobe = None
        if ctx.needs_input_grad[2] or ctx.needs_input_grad[3]:
            pattern = _csr(rows, columns, grad.new_zeros(columns.numel()), size=(num, values.shape[0] * bands))
            flat = values.reshape(-1, grad.shape[1])
            # d out[p] / d weight[p, i, l] = S[corner_i, l]: (grad @ S^T) sampled at the sparsity pattern
            grad_weights = torch.sparse.sampled_addmm(pattern, grad, flat.T, beta=0.0).values()
            grad_weights = grad_weights.reshape(num, 3, bands)
            grad_bary = (grad_weights * lobe[:, None, :]).sum(-1)
            grad_lobe = (grad_weights * bary[:, :, None]).sum(1)
        if ctx.needs_input_grad[0]:
            # grad S[v, l] = sum_{(p, i): corner_i(p) = v} bary[p, i] lobe[p, l] grad[p]: a [U, N] CSR
            # matrix of barycentrics (3 per pixel, sorted by vertex) times [N, B*C] lobe-weighted grads
            corner_flat = corners.reshape(-1)
            order = torch.argsort(corner_flat, stable=True)
            counts = torch.bincount(corner_flat, minlength=values.shape[0])
            crow = torch.cat([counts.new_zeros(1), counts.cumsum(0)])
            transpose = _csr(crow, order // 3, bary.reshape(-1)[order], size=(values.shape[0], num))
            weighted = (lobe[:, :, None] * grad[:, None, :]).reshape(num, -1)  # [N, B*C]
            grad_values = transpose @ weighted
        return grad_values, None, grad_bary, grad_lobe


def _csr(rows: torch.Tensor, columns: torch.Tensor, values: torch.Tensor, size: tuple) -> torch.Tensor:
    """A sparse CSR matrix; indices are built by this module, so torch's invariant checks are skipped."""
    with warnings.catch_warnings():  # torch warns that CSR support is "beta" on every construction
        warnings.filterwarnings("ignore", message="Sparse CSR tensor support is in beta state")
        return torch.sparse_csr_tensor(rows, columns, values, size=size, check_invariants=False)


def _renumber(corners: torch.Tensor, num_vertices: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The vertices used by ``corners`` [N, 3] (sorted, [U]) and the corners renumbered into them."""
    if kernels.enabled(corners):
        return kernels.renumber(corners, num_vertices)
    flags = torch.zeros(num_vertices, dtype=torch.bool, device=corners.device)
    flags[corners.reshape(-1)] = True
    used = torch.nonzero(flags)[:, 0]  # [U]
    new_index = torch.cumsum(flags, 0) - 1  # [V], valid where flags
    return used, new_index[corners]


def _barycentrics(mesh: Mesh, camera: Camera, tri: torch.Tensor, covered: torch.Tensor, projected=None) -> torch.Tensor:
    """Perspective-correct barycentrics [N, 3] of the pixel centres ``covered`` in triangles ``tri``
    (``projected``: camera.project(mesh.vertices) if already computed)."""
    pixels, depth = camera.project(mesh.vertices) if projected is None else projected  # [V, 2], [V]
    width = camera.width
    if kernels.enabled(pixels, depth) and pixels.dtype == depth.dtype:
        return _KernelBarycentrics.apply(pixels, depth, (mesh.triangles, tri, covered, (camera.height, width)))
    corners = mesh.triangles.index_select(0, tri)  # [N, 3]
    q = torch.stack([covered % width, covered // width], -1).to(pixels.dtype) + 0.5  # [N, 2]
    flat = corners.reshape(-1)
    p = pixels.index_select(0, flat).reshape(-1, 3, 2)  # [N, 3, 2]
    z = depth.index_select(0, flat).reshape(-1, 3)  # [N, 3]

    def cross2(a, b):
        return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]

    d0, d1, d2 = p[:, 0] - q, p[:, 1] - q, p[:, 2] - q
    screen = torch.stack([cross2(d1, d2), cross2(d2, d0), cross2(d0, d1)], -1)  # [N, 3] ~ 2 x areas
    area = screen.sum(-1, keepdim=True)
    tiny = torch.finfo(p.dtype).tiny
    area = torch.where(area.abs() < tiny, torch.full_like(area, tiny), area)
    weights = screen / area / z  # perspective correction: screen barycentrics / depth
    return weights / weights.sum(-1, keepdim=True)


class _KernelBarycentrics(torch.autograd.Function):
    """The numba path of ``_barycentrics``: projected vertices [V, 2], their depths [V], and the pixels =
    (triangles [F, 3], triangle id [N] and flat index [N] of each covered pixel, image (H, W)); corners and
    pixel centres are looked up (and the corner gradients scattered) in the kernels."""

    @staticmethod
    def forward(ctx, pixels, depth, covered):
        ctx.save_for_backward(pixels, depth)
        ctx.covered = covered
        return kernels.barycentrics_forward(pixels, depth, covered)

    @staticmethod
    def backward(ctx, grad):
        return (*kernels.barycentrics_backward(*ctx.saved_tensors, ctx.covered, grad), None)


def _interpolate(values: torch.Tensor, corners: torch.Tensor, bary: torch.Tensor) -> torch.Tensor:
    """sum_i bary_i values[corners_i]: values [V, C], corners [N, 3], bary [N, 3] -> [N, C]."""
    if kernels.enabled(values, bary) and values.dtype == bary.dtype:
        return _KernelInterpolation.apply(values, corners, bary, bary.new_ones(bary.shape[0], 1))
    out = values.index_select(0, corners[:, 0]) * bary[:, :1]
    out = out + values.index_select(0, corners[:, 1]) * bary[:, 1:2]
    return out + values.index_select(0, corners[:, 2]) * bary[:, 2:3]


def _pixel_rays(camera: Camera, flat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Model-frame rays through the centres of the pixels ``flat`` (y * W + x; x right, y down): origins
    [N, 3], unit directions [N, 3], in float32, Embree's precision (a numba loop on the fast path)."""
    focal = float(camera.focal.detach())
    rot = camera.rotation_matrix.detach().cpu().numpy().astype(np.float32)
    origin = camera.center_in_model().detach().cpu().numpy().astype(np.float32)
    if kernels.enabled(camera.focal):
        dirs = kernels.pixel_directions(flat, (camera.height, camera.width), focal, rot)
        return np.broadcast_to(origin, dirs.shape), dirs
    ys, xs = np.divmod(flat, camera.width)
    dirs_cam = np.empty((xs.shape[0], 3), dtype=np.float32)
    dirs_cam[:, 0] = (xs + 0.5 - camera.width / 2) / focal
    dirs_cam[:, 1] = (ys + 0.5 - camera.height / 2) / focal
    dirs_cam[:, 2] = 1.0
    dirs = dirs_cam @ rot  # camera -> model: R^T d
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    return np.broadcast_to(origin, dirs.shape), dirs


def _bands_of(sh_lights: torch.Tensor) -> int:
    if sh_lights.ndim != 3 or sh_lights.shape[2] != 3:
        raise ValueError(f"sh_lights must be [K, B², 3], got {tuple(sh_lights.shape)}")
    bands = math.isqrt(sh_lights.shape[1])
    if bands * bands != sh_lights.shape[1] or bands < 1:
        raise ValueError(f"sh_lights: {sh_lights.shape[1]} coefficients is not a square number of bands")
    return bands
