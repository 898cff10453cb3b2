"""Light sources for re-rendering a fit, as SH lights ``[K, B*B, 3]`` in the project's convention (real
orthonormal SH, index ``l*l + l + m``, radiance towards the light, model frame: +x the subject's left, +y up,
+z towards the camera; docs/design.md).

- named presets (:data:`PRESETS`): ``studio`` (three-point: key above camera right, fill, back light),
  ``sun`` (a small, hard key from above with a weak blue sky: the ray-traced self-shadows show), ``overcast``
  (a bright sky dome, soft), ``rim`` (two lights behind the head, edges only), ``neutral`` (uniform white
  plus a frontal lobe, :func:`deface.render.sh.white_light`: shows the albedo);
- an SH file: ``.npy`` or ``.json`` holding ``[K, B*B, 3]`` or ``[B*B, 3]`` (JSON: a list, ``{"sh": ...}``,
  or a deface ``params.json``, whose kept lights are used);
- an equirectangular environment map (``.hdr``, ``.exr``, or an 8-bit image taken as sRGB), projected to SH.
  Row 0 is straight up (+y); the centre column looks from the face towards the camera (+z, the light that
  falls on the front of the face), and columns to the right turn towards +x (the subject's left).

Presets and maps are windowed against ringing (:func:`windowed`). Sources other than an SH file are scaled
so the brightest diffuse response of a white surface is :data:`LEVEL` (the neutral light's frontal response
is 1); ``--exposure`` (EV) scales any of them. :func:`rotate_lights` turns lights about the vertical axis
(``--rotate-light``).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

from deface.io.images import load_image, srgb_to_linear
from deface.render.sh import cosine_lobe_coefficients, fibonacci_sphere, sh_basis, white_light

LEVEL = 0.9
"""Peak diffuse response of a white surface under a preset or an environment map (after scaling)."""

SPHERE_SAMPLES = 20000  # directions of the numeric SH projection of presets (exact enough for 16 bands)
ENV_MAX_WIDTH = 512  # environment maps are box-downsampled to at most this width before projection


class LightSourceError(ValueError):
    """A light source that cannot be used (unknown name, unreadable file, wrong shape); one line."""


def project_to_sh(directions: np.ndarray, radiance: np.ndarray, solid_angles: np.ndarray, bands: int) -> torch.Tensor:
    """SH coefficients [B*B, 3] of radiance [N, 3] sampled at unit ``directions`` [N, 3] with the solid angle
    of each sample [N]: c = sum_i L_i Y(w_i) dOmega_i."""
    basis = sh_basis(torch.as_tensor(directions, dtype=torch.float64), bands)  # [N, B*B]
    weighted = torch.as_tensor(radiance * solid_angles[:, None], dtype=torch.float64)  # [N, 3]
    return (basis.T @ weighted).to(torch.float32)


def diffuse_peak(lights: torch.Tensor, samples: int = 4000) -> float:
    """The largest diffuse radiance E(n) / pi of a white Lambertian surface over all normals n (luminance-free:
    the largest channel), summed over the lights [K, B*B, 3]."""
    bands = int(round(lights.shape[1] ** 0.5))
    basis = sh_basis(torch.as_tensor(fibonacci_sphere(samples), dtype=torch.float32), bands)  # [N, B*B]
    irradiance = basis @ (cosine_lobe_coefficients(bands)[:, None] * lights.sum(0)) / math.pi  # [N, 3]
    return float(irradiance.max())


def windowed(lights: torch.Tensor) -> torch.Tensor:
    """``lights`` [K, B*B, 3] with band l scaled by the Hann window (1 + cos(pi l / B)) / 2: a light sharper
    than B bands can hold rings (negative radiance opposite a small sun); the window trades that for a
    softer edge (Sloan 2008, "Stupid spherical harmonics tricks", windowing)."""
    bands = int(round(lights.shape[1] ** 0.5))
    degree = torch.tensor([float(math.isqrt(i)) for i in range(bands * bands)], dtype=lights.dtype)
    return lights * (0.5 * (1.0 + torch.cos(math.pi * degree / bands)))[None, :, None]


def normalised(lights: torch.Tensor, level: float = LEVEL) -> torch.Tensor:
    peak = diffuse_peak(lights)
    return lights * (level / peak) if peak > 0 else lights


def _cone(direction, radius_degrees: float, colour=(1.0, 1.0, 1.0), soft_degrees: float = 2.0):
    """Radiance function of a disc light (angular radius, soft edge) towards ``direction``."""
    axis = np.asarray(direction, dtype=np.float64)
    axis = axis / np.linalg.norm(axis)

    def radiance(w: np.ndarray) -> np.ndarray:
        angle = np.degrees(np.arccos(np.clip(w @ axis, -1.0, 1.0)))
        weight = np.clip((radius_degrees + soft_degrees - angle) / (2 * soft_degrees), 0.0, 1.0)
        return weight[:, None] * np.asarray(colour)[None] / (2 * math.pi * (1 - math.cos(math.radians(radius_degrees))))

    return radiance


def _sky(colour=(1.0, 1.0, 1.0), ground: float = 0.15):
    """CIE overcast sky: radiance (1 + 2 sin(elevation)) / 3 above the horizon, a dim ground below."""
    def radiance(w: np.ndarray) -> np.ndarray:
        up = w[:, 1]
        level = np.where(up >= 0, (1 + 2 * up) / 3, ground)
        return level[:, None] * np.asarray(colour)[None]

    return radiance


def _sum(*parts: tuple[float, Callable]):
    def radiance(w: np.ndarray) -> np.ndarray:
        return sum(weight * part(w) for weight, part in parts)

    return radiance


PRESETS: dict[str, Callable | None] = {
    "studio": _sum((1.0, _cone((-0.55, 0.45, 0.70), 18.0)), (0.35, _cone((0.65, 0.05, 0.75), 25.0)),
                   (0.45, _cone((0.25, 0.55, -0.80), 15.0)), (0.05, _sky())),
    "sun": _sum((1.0, _cone((0.45, 0.65, 0.60), 3.0, colour=(1.0, 0.93, 0.82), soft_degrees=1.0)),
                (0.10, _sky(colour=(0.75, 0.85, 1.0), ground=0.3))),
    "overcast": _sky(colour=(0.97, 0.98, 1.0), ground=0.25),
    "rim": _sum((1.0, _cone((0.80, 0.25, -0.55), 12.0)), (1.0, _cone((-0.80, 0.25, -0.55), 12.0)),
                (0.04, _sky())),
    "neutral": None,  # white_light: uniform plus a frontal lobe
}
"""Named light presets (see the module docstring); ``None`` marks the neutral light."""


def preset_lights(name: str, bands: int) -> torch.Tensor:
    """[1, B*B, 3] the named preset."""
    if name not in PRESETS:
        raise LightSourceError(f"unknown light preset '{name}' (known: {', '.join(PRESETS)})")
    if PRESETS[name] is None:
        return white_light(bands)
    directions = fibonacci_sphere(SPHERE_SAMPLES)
    radiance = PRESETS[name](directions)
    coeffs = project_to_sh(directions, radiance, np.full(len(directions), 4 * math.pi / len(directions)), bands)
    return normalised(windowed(coeffs[None]))


def equirect_directions(height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Pixel-centre directions [H, W, 3] of an equirectangular map (layout in the module docstring) and the
    solid angle of each pixel [H, W]."""
    theta = (np.arange(height) + 0.5) / height * math.pi  # from +y
    phi = ((np.arange(width) + 0.5) / width - 0.5) * 2 * math.pi  # 0 at the centre column (+z)
    sin_t = np.sin(theta)[:, None]
    directions = np.stack(np.broadcast_arrays(sin_t * np.sin(phi)[None], np.cos(theta)[:, None] + 0 * phi[None],
                                              sin_t * np.cos(phi)[None]), -1)
    solid = np.broadcast_to(sin_t * (math.pi / height) * (2 * math.pi / width), (height, width))
    return directions, np.ascontiguousarray(solid)


def environment_lights(image: np.ndarray, bands: int) -> torch.Tensor:
    """[1, B*B, 3] an equirectangular linear-RGB map [H, W, 3] projected to SH (then normalised)."""
    image = _downsample(np.asarray(image, dtype=np.float64), ENV_MAX_WIDTH)
    directions, solid = equirect_directions(*image.shape[:2])
    coeffs = project_to_sh(directions.reshape(-1, 3), image.reshape(-1, 3), solid.reshape(-1), bands)
    return normalised(windowed(coeffs[None]))


def _downsample(image: np.ndarray, max_width: int) -> np.ndarray:
    factor = math.ceil(image.shape[1] / max_width)
    if factor <= 1:
        return image
    height, width = image.shape[0] // factor * factor, image.shape[1] // factor * factor
    blocks = image[:height, :width].reshape(height // factor, factor, width // factor, factor, 3)
    return blocks.mean((1, 3))


def read_environment_map(path: Path) -> np.ndarray:
    """[H, W, 3] float linear RGB from ``.hdr`` / ``.exr`` (OpenCV's readers) or an 8-bit image (sRGB)."""
    suffix = path.suffix.lower()
    if suffix in (".hdr", ".exr"):
        os.environ.setdefault("OPENCV_IO_ENABLE_OPENEXR", "1")
        import cv2

        image = cv2.imread(str(path), cv2.IMREAD_ANYDEPTH | cv2.IMREAD_COLOR)
        if image is None:
            raise LightSourceError(f"{path}: cannot read this {suffix} environment map")
        return np.ascontiguousarray(image[..., ::-1], dtype=np.float32)
    return srgb_to_linear(load_image(path))


def read_sh_file(path: Path, bands: int) -> torch.Tensor:
    """[K, B*B, 3] from ``.npy`` or ``.json`` (module docstring), padded/truncated to ``bands``."""
    try:
        if path.suffix.lower() == ".npy":
            values = np.load(path)
        else:
            data = json.loads(path.read_text())
            if isinstance(data, dict) and "lights" in data and "sh" in data["lights"]:  # a deface params.json
                data = [data["lights"]["sh"][str(k)] for k in data["lights"]["kept"]]
            elif isinstance(data, dict):
                data = data.get("sh")
            values = np.asarray(data, dtype=np.float64)
    except (OSError, ValueError) as error:
        raise LightSourceError(f"{path}: cannot read SH lights ({error})") from None
    if values.ndim == 2:
        values = values[None]
    size = values.shape[1] if values.ndim == 3 else 0
    if values.ndim != 3 or values.shape[2] != 3 or round(size ** 0.5) ** 2 != size:
        raise LightSourceError(f"{path}: SH lights must have shape [K, B*B, 3] or [B*B, 3], got {values.shape}")
    return fit_bands(torch.as_tensor(values, dtype=torch.float32), bands)


def fit_bands(lights: torch.Tensor, bands: int) -> torch.Tensor:
    """``lights`` [K, b*b, 3] with ``bands`` bands: higher bands dropped, missing ones zero."""
    out = lights.new_zeros(lights.shape[0], bands * bands, 3)
    count = min(bands * bands, lights.shape[1])
    out[:, :count] = lights[:, :count]
    return out


def light_source(source: str, bands: int) -> torch.Tensor:
    """Lights [K, B*B, 3] from a preset name, an SH file (.npy/.json) or an environment map."""
    if source in PRESETS:
        return preset_lights(source, bands)
    path = Path(source)
    if not path.is_file():
        raise LightSourceError(f"--light {source}: neither a preset ({', '.join(PRESETS)}) nor an existing file")
    if path.suffix.lower() in (".npy", ".json"):
        return read_sh_file(path, bands)
    return environment_lights(read_environment_map(path), bands)


def yaw_matrix(degrees: float) -> np.ndarray:
    """[3, 3] rotation about +y by ``degrees`` (positive turns +z towards +x, the subject's left)."""
    angle = math.radians(degrees)
    cos, sin = math.cos(angle), math.sin(angle)
    return np.array([[cos, 0.0, sin], [0.0, 1.0, 0.0], [-sin, 0.0, cos]])


def rotate_lights(lights: torch.Tensor, rotation: np.ndarray) -> torch.Tensor:
    """``lights`` [K, B*B, 3] turned by the rotation matrix [3, 3]: L'(w) = L(R^T w). Exact for band-limited
    lights (rotations keep each band): least squares on sphere samples."""
    bands = int(round(lights.shape[1] ** 0.5))
    directions = torch.as_tensor(fibonacci_sphere(max(8 * bands * bands, 200)), dtype=torch.float64)
    basis = sh_basis(directions, bands)  # [N, B*B]
    turned = sh_basis(directions @ torch.as_tensor(rotation, dtype=torch.float64), bands)  # Y(R^T w)
    matrix = torch.linalg.lstsq(basis, turned).solution  # [B*B, B*B]: c' = M c
    return torch.einsum("ij,kjc->kic", matrix, lights.to(torch.float64)).to(lights.dtype)
