"""The project's own albedo prior for ICT-FaceKit (which ships no albedo model): AlbedoMM's role, built from
the mesh, its landmarks and published skin measurements. Full rationale and sources: docs/albedo-prior.md.

- Mean diffuse map (T^0): a skin colour with region tints (lips, brows, eye surroundings, nostrils, cheeks,
  ears, neck) painted from region masks derived from the 68 landmark vertices and the geometry, with
  Gaussian-blurred (soft) boundaries.
- Basis: colour directions (melanin-like, haemoglobin-like, brightness; and a specular "oiliness" term) times
  low-order cosines over the left-right symmetric parameterisation (s = |u - 0.5| * 2, v). The basis maps are
  smooth by construction, so a fit with them cannot reproduce a sharp cast-shadow edge: Stage 2 must explain
  shadows with the lights, as AlbedoMM forces it to.
- Diffuse and specular share the coefficient vector (components are either diffuse or specular).

Numbers (linear reflectance):
- Skin base colour: the mean of the two skin samples' total diffuse reflectance Rd in Jensen, Marschner, Levoy
  and Hanrahan, "A Practical Model for Subsurface Light Transport", SIGGRAPH 2001, Table 1 (skin1: 0.44, 0.22,
  0.13; skin2: 0.63, 0.44, 0.34).
- Specular: 0.04-0.08 with the T-zone highest, following the regional specular analysis of Weyrich et al.,
  "Analysis of Human Faces using a Measurement-Based Skin Reflectance Model", SIGGRAPH 2006 (forehead and nose
  are the most specular regions); the Fresnel reflectance of skin at normal incidence (n ~ 1.4) is ~0.028.
- Roughness default 0.4: within the per-region Torrance-Sparrow roughness fits of Weyrich et al. 2006.
Region tints and variation amplitudes are this project's design choices (documented in docs/albedo-prior.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from deface.models.base import AlbedoModel
from deface.models.skin_tone import SkinToneAxis
from deface.models.uvmap import coverage, fill_outside, polygon_mask, rasterize_uv, texel_centres

# Jensen et al. 2001, Table 1, total diffuse reflectance Rd (R, G, B) of two skin samples.
JENSEN2001_SKIN1_RD = (0.44, 0.22, 0.13)
JENSEN2001_SKIN2_RD = (0.63, 0.44, 0.34)


@dataclass(frozen=True)
class AlbedoPriorConfig:
    """How the ICT albedo prior is built (defaults are the shipped prior; see docs/albedo-prior.md)."""

    size: int = 128
    """Texture size of the stored maps (AlbedoModel.textures upsamples)."""
    skin_rgb: tuple[float, float, float] = (0.535, 0.33, 0.235)
    """Mean linear skin albedo (mean of Jensen et al. 2001 skin1/skin2 Rd)."""
    lip_tint: tuple[float, float, float] = (0.85, 0.55, 0.62)
    """Multiplier on skin for lips: redder (more haemoglobin, thinner epidermis), darker in G and B."""
    brow_rgb: tuple[float, float, float] = (0.09, 0.055, 0.04)
    """Dark-brown hair colour of the brows; blended with skin by ``brow_coverage``."""
    brow_coverage: float = 0.6
    """Fraction of brow texels covered by hair (brows are sparse)."""
    eye_tint: tuple[float, float, float] = (0.86, 0.8, 0.84)
    """Multiplier around the eyes (eyelids, sockets): darker, slightly violet-brown."""
    nostril_rgb: tuple[float, float, float] = (0.10, 0.045, 0.035)
    """Nostril openings: dark cavity."""
    cheek_tint: tuple[float, float, float] = (1.0, 0.92, 0.94)
    """Multiplier on the cheeks: a haemoglobin blush."""
    ear_tint: tuple[float, float, float] = (1.0, 0.9, 0.92)
    """Multiplier on the ears: redder (thin, well-perfused skin)."""
    neck_tint: tuple[float, float, float] = (1.04, 1.06, 1.06)
    """Multiplier on the neck: less sun and blood than the face, slightly lighter and less red."""
    boundary_blur: float = 1.2
    """Gaussian sigma (texels at ``size``) softening region boundaries of the mean map."""
    specular_skin: float = 0.05
    """Mean specular reflectance of skin (grey)."""
    specular_tzone: float = 0.08
    """Specular reflectance on forehead and nose (the T-zone, most specular in Weyrich et al. 2006)."""
    specular_brow: float = 0.035
    """Specular reflectance of the brows (hair scatters, fewer sharp highlights)."""
    roughness: float = 0.4
    """Default roughness (in the range of Weyrich et al. 2006's per-region Torrance-Sparrow fits)."""
    max_order: int = 3
    """Spatial cosines cos(pi a s) cos(pi b v) with a + b <= max_order (melanin and haemoglobin)."""
    brightness_order: int = 2
    """Maximum order a + b for the brightness direction."""
    melanin_std: float = 0.22
    """Std of the log-reflectance change of the constant melanin component (darker and browner)."""
    haemoglobin_std: float = 0.1
    """Std of the log-reflectance change of the constant haemoglobin component (redder)."""
    brightness_std: float = 0.08
    """Std of the log-reflectance change of the constant brightness component (grey)."""
    oiliness_std: float = 0.3
    """Std of the relative change of the constant specular ("oiliness") component."""
    order_decay: float = 0.5
    """Each extra spatial order multiplies a component's amplitude by this (mostly global variation)."""
    basis_blur: float = 3.0
    """Gaussian sigma (texels) of the mean map that the basis is multiplied by (keeps the basis smooth)."""
    symmetric: bool = True
    """Left-right symmetric basis; False adds odd-in-u components (sin(pi (u - 0.5)) cos(pi b v))."""
    range_sigmas: float = 3.0
    """Mean +- this many per-texel stds stays in [min_albedo, max_albedo] (else the basis is scaled down)."""
    min_albedo: float = 0.02
    max_albedo: float = 0.95


# Colour directions: log-reflectance change per unit (R, G, B), before amplitude.
# Melanin absorbs more at short wavelengths (darker and browner); haemoglobin absorbs green most, then blue.
COLOUR_DIRECTIONS = {
    "melanin": np.array([-0.55, -0.8, -1.0]),
    "haemoglobin": np.array([-0.05, -1.0, -0.55]),
    "brightness": np.array([1.0, 1.0, 1.0]),
}


def vertex_uvs(triangles: np.ndarray, uvs: np.ndarray, triangle_uvs: np.ndarray, count: int) -> np.ndarray:
    """One UV [V, 2] per vertex (the mean of its UVs; seam vertices get an average)."""
    out = np.zeros((count, 2))
    hits = np.zeros(count)
    np.add.at(out, triangles.ravel(), uvs[triangle_uvs.ravel()])
    np.add.at(hits, triangles.ravel(), 1.0)
    return out / np.maximum(hits, 1.0)[:, None]


def _to_pixels(uv: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """UV [N, 2] -> (row, col) float pixel coordinates of a size² map (row 0 = v 1)."""
    return (1.0 - uv[:, 1]) * size - 0.5, uv[:, 0] * size - 0.5


def _ellipse_mask(centre_uv, radii_uv, size: int) -> np.ndarray:
    u, v = texel_centres(size, size)
    du = (u[None, :] - centre_uv[0]) / radii_uv[0]
    dv = (v[:, None] - centre_uv[1]) / radii_uv[1]
    return (du**2 + dv**2 <= 1.0).astype(np.float64)


def _polyline_band(points_uv: np.ndarray, half_width: float, size: int) -> np.ndarray:
    """Texels within half_width (UV units) of a polyline."""
    u, v = texel_centres(size, size)
    grid = np.stack(np.meshgrid(u, v, indexing="xy"), -1)  # [H, W, 2]
    best = np.full((size, size), np.inf)
    for a, b in zip(points_uv[:-1], points_uv[1:], strict=True):
        ab = b - a
        t = np.clip(((grid - a) @ ab) / max(float(ab @ ab), 1e-12), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(grid - (a + t[..., None] * ab), axis=-1))
    return (best <= half_width).astype(np.float64)


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _symmetrise(image: np.ndarray) -> np.ndarray:
    """Average with the u-mirrored map (texel centres are symmetric about u = 0.5)."""
    return 0.5 * (image + image[:, ::-1])


@dataclass(frozen=True)
class _Layout:
    """What the prior needs of a face model, in UV space."""

    landmarks_uv: np.ndarray  # [68, 2]
    position: np.ndarray  # [H, W, 3] cm, interpolated neutral positions (filled outside the layout)
    mask: np.ndarray  # [H, W] coverage in [0, 1]


def region_masks(layout: _Layout, config: AlbedoPriorConfig) -> dict[str, np.ndarray]:
    """Soft [H, W] masks in [0, 1] of the tinted regions (symmetrised, blurred)."""
    size = config.size
    lm = layout.landmarks_uv
    x, y, z = layout.position[..., 0], layout.position[..., 1], layout.position[..., 2]
    u, v = texel_centres(size, size)
    masks: dict[str, np.ndarray] = {}
    masks["lips"] = polygon_mask(lm[48:60], size)
    brow_height = 0.25 * (lm[37:39, 1].mean() - lm[19, 1])  # brow landmarks sit on the brow's upper half
    brows = [lm[17:22] + [0.0, brow_height], lm[22:27] + [0.0, brow_height]]
    masks["brows"] = np.maximum(*[_polyline_band(b, 0.018, size) for b in brows])
    eyes = np.zeros((size, size))
    for ids in (slice(36, 42), slice(42, 48)):
        pts = lm[ids]
        width = np.ptp(pts[:, 0])
        eyes = np.maximum(eyes, _ellipse_mask(pts.mean(0), (0.85 * width, 0.05), size))
    masks["eyes"] = eyes
    # Nostrils: the openings lie just inside the alar base (landmarks 31 and 35) toward 32 and 34.
    nostrils = np.zeros((size, size))
    for outer, inner in ((31, 32), (35, 34)):
        centre = 0.5 * (lm[outer] + lm[inner]) + [0.0, 0.012]
        nostrils = np.maximum(nostrils, _ellipse_mask(centre, (0.016, 0.009), size))
    masks["nostrils"] = nostrils
    cheeks = np.zeros((size, size))
    for jaw, nose, mouth in ((2, 31, 48), (14, 35, 54)):
        centre = (lm[jaw] + lm[nose] + lm[mouth]) / 3.0 + [0.0, 0.04]
        cheeks = np.maximum(cheeks, _ellipse_mask(centre, (0.09, 0.08), size))
    masks["cheeks"] = cheeks
    # Ears from geometry: lateral (|x| beyond the jaw's top corners) and behind the cheeks.
    jaw_x = 0.5 * (abs(_landmark_x(layout, 0)) + abs(_landmark_x(layout, 16)))
    masks["ears"] = (
        _smoothstep((np.abs(x) - (jaw_x - 0.6)) / 0.6)
        * _smoothstep((2.5 - z) / 0.8)
        * _smoothstep((y + 3.5) / 1.0)
        * _smoothstep((5.0 - y) / 1.0)
    )
    # Neck: below the jawline polyline (landmarks 0..16), by v per column, soft over 0.04 in v.
    jaw = lm[0:17]
    jaw_v = np.interp(u, jaw[:, 0], jaw[:, 1])  # [W], ends extend flat
    masks["neck"] = _smoothstep((jaw_v[None, :] - 0.03 - v[:, None]) / 0.06)
    # T-zone (specular): forehead above the brows plus the nose bridge and tip.
    brow_top = lm[17:27, 1].max() + 0.02
    central = _smoothstep((0.3 - np.abs(u - 0.5)) / 0.1)[None, :]  # forehead between the temples
    forehead = _smoothstep((v[:, None] - brow_top) / 0.05) * central
    nose = polygon_mask(lm[[27, 31, 33, 35]] + [[0.0, 0.0], [-0.01, 0.0], [0.0, -0.0], [0.01, 0.0]], size)
    nose = np.maximum(nose, _polyline_band(lm[27:31], 0.03, size))
    masks["tzone"] = np.maximum(forehead, nose)
    for key, mask in masks.items():
        masks[key] = np.clip(_symmetrise(ndimage.gaussian_filter(mask, config.boundary_blur)), 0.0, 1.0)
    return masks


def _landmark_x(layout: _Layout, index: int) -> float:
    """x (cm) of a landmark, read from the position map at its UV."""
    rows, cols = _to_pixels(layout.landmarks_uv[index : index + 1], layout.position.shape[0])
    r = int(np.clip(round(float(rows[0])), 0, layout.position.shape[0] - 1))
    c = int(np.clip(round(float(cols[0])), 0, layout.position.shape[1] - 1))
    return float(layout.position[r, c, 0])


def mean_maps(masks: dict[str, np.ndarray], config: AlbedoPriorConfig) -> tuple[np.ndarray, np.ndarray]:
    """Mean diffuse [H, W, 3] and specular [H, W, 3] maps painted from the region masks."""
    size = config.size
    diffuse = np.ones((size, size, 3)) * np.asarray(config.skin_rgb)

    def tint(name, factor):
        m = masks[name][..., None]
        return diffuse * (1.0 - m + m * np.asarray(factor))

    for name, factor in (
        ("neck", config.neck_tint),
        ("cheeks", config.cheek_tint),
        ("ears", config.ear_tint),
        ("eyes", config.eye_tint),
        ("lips", config.lip_tint),
    ):
        diffuse = tint(name, factor)
    for name, colour, weight in (
        ("brows", config.brow_rgb, config.brow_coverage),
        ("nostrils", config.nostril_rgb, 1.0),
    ):
        m = weight * masks[name][..., None]
        diffuse = diffuse * (1.0 - m) + m * np.asarray(colour)
    spec = config.specular_skin + (config.specular_tzone - config.specular_skin) * masks["tzone"]
    spec = spec * (1.0 - masks["brows"]) + config.specular_brow * masks["brows"]
    specular = np.repeat(spec[..., None], 3, axis=-1)
    return diffuse, specular


def spatial_functions(config: AlbedoPriorConfig, max_order: int, weights: np.ndarray) -> list:
    """Low-order cosines over (s, v) as (name, order, [H, W] map) with unit RMS under ``weights``.

    s = |u - 0.5| * 2 makes every function left-right symmetric; cos has zero slope at s = 0, so the
    mirrored function has no crease on the midline.
    """
    size = config.size
    u, v = texel_centres(size, size)
    s = np.abs(u - 0.5) * 2.0
    funcs = []
    for order in range(max_order + 1):
        for a in range(order + 1):
            b = order - a
            f = np.cos(np.pi * b * v)[:, None] * np.cos(np.pi * a * s)[None, :]
            funcs.append((f"s{a}v{b}", order, f))
            if not config.symmetric and a == 1:
                g = np.cos(np.pi * b * v)[:, None] * np.sin(np.pi * (u - 0.5))[None, :]
                funcs.append((f"odd{a}v{b}", order, g))
    out = []
    for name, order, f in funcs:
        rms = np.sqrt((weights * f * f).sum() / weights.sum())
        out.append((name, order, f / rms))
    return out


def build_albedo_prior(
    uvs: np.ndarray,
    triangle_uvs: np.ndarray,
    triangles: np.ndarray,
    vertices: np.ndarray,
    landmarks_68: np.ndarray,
    config: AlbedoPriorConfig | None = None,
) -> AlbedoModel:
    """Build the prior for a mesh with a face UV layout (uvs [U, 2], triangle_uvs/triangles [F, 3],
    vertices [V, 3] cm, landmarks_68 [68] vertex ids). Deterministic."""
    config = config or AlbedoPriorConfig()
    size = config.size
    raster = rasterize_uv(uvs, triangle_uvs, size)
    mask = coverage(uvs, triangle_uvs, size, supersample=2)
    layout = _Layout(
        landmarks_uv=vertex_uvs(triangles, uvs, triangle_uvs, len(vertices))[landmarks_68],
        position=raster.interpolate_vertices(vertices.astype(np.float64), triangles),
        mask=mask,
    )
    masks = region_masks(layout, config)
    diffuse_mean, specular_mean = mean_maps(masks, config)
    weights = np.maximum(mask, 1e-6)
    smooth_diffuse = ndimage.gaussian_filter(diffuse_mean, (config.basis_blur, config.basis_blur, 0))
    smooth_specular = ndimage.gaussian_filter(specular_mean, (config.basis_blur, config.basis_blur, 0))
    diffuse_basis, specular_basis, names = [], [], []
    zeros = np.zeros_like(diffuse_mean)
    for direction, colour in COLOUR_DIRECTIONS.items():
        max_order = config.brightness_order if direction == "brightness" else config.max_order
        colour = colour / np.linalg.norm(colour) * np.sqrt(3.0)  # unit RMS per channel
        for name, order, f in spatial_functions(config, max_order, weights):
            amplitude = getattr(config, f"{direction}_std") * config.order_decay**order
            # First-order (linear) version of mean * exp(amplitude * f * colour).
            diffuse_basis.append(smooth_diffuse * colour * (amplitude * f)[..., None])
            specular_basis.append(zeros)
            names.append(f"{direction}:{name}")
    for name, order, f in spatial_functions(config, 1, weights):
        amplitude = config.oiliness_std * config.order_decay**order
        diffuse_basis.append(zeros)
        specular_basis.append(smooth_specular * (amplitude * f)[..., None])
        names.append(f"oiliness:{name}")
    diffuse_basis = _fit_range(diffuse_mean, np.stack(diffuse_basis), config)
    specular_basis = _fit_range(specular_mean, np.stack(specular_basis), config)
    return AlbedoModel(
        diffuse_mean=diffuse_mean.astype(np.float32),
        diffuse_basis=diffuse_basis.astype(np.float32),
        specular_mean=specular_mean.astype(np.float32),
        specular_basis=specular_basis.astype(np.float32),
        roughness_default=float(config.roughness),
        face_mask=mask.astype(np.float32),
        description=(
            "deface ICT albedo prior v1: skin = mean Rd of Jensen et al. 2001 (Table 1) skin samples, region "
            "tints from landmarks, melanin/haemoglobin/brightness x low-order symmetric cosines, specular "
            "T-zone and roughness after Weyrich et al. 2006; see docs/albedo-prior.md"
        ),
        component_names=tuple(names),
        tone=SkinToneAxis.through(config.skin_rgb),
    )


def _fit_range(mean: np.ndarray, basis: np.ndarray, config: AlbedoPriorConfig) -> np.ndarray:
    """Scale the basis down (never up) so mean +- range_sigmas * per-texel std stays in range."""
    std = np.sqrt((basis**2).sum(0))
    reach = config.range_sigmas * np.maximum(std, 1e-12)
    room = np.minimum(config.max_albedo - mean, mean - config.min_albedo)
    scale = min(1.0, float((room / reach).min()))
    if scale <= 0.0:
        raise ValueError(
            "albedo prior: the mean map leaves [min_albedo, max_albedo]; check the region colours"
        )
    return basis * scale


__all__ = ["AlbedoPriorConfig", "build_albedo_prior", "fill_outside", "vertex_uvs"]
