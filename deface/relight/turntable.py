"""A turntable: the textured mesh of one fitted frame turning about its vertical axis under a light that stays
fixed relative to the camera, written as MP4 (the bundled ffmpeg of imageio-ffmpeg) or GIF."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from deface.fit.output import FitOutput
from deface.io.images import to_uint8
from deface.relight.lights import rotate_lights, yaw_matrix
from deface.render.camera import Camera

BACKGROUND = (0.18, 0.18, 0.2)  # sRGB grey behind the face


def yaw_angles(yaw_range: float, count: int) -> list[float]:
    """``count`` yaws (degrees) swinging smoothly over ``yaw_range`` (-range/2 .. +range/2) and back, a loop."""
    return [0.5 * yaw_range * math.sin(2 * math.pi * i / count) for i in range(count)]


def turned_camera(camera: Camera, centre: torch.Tensor, degrees: float, scale: float = 1.0) -> Camera:
    """``camera`` seeing the mesh turned by ``degrees`` about the model's +y axis through ``centre`` [3]:
    x -> R (Ry (x - c) + c) + t, and the image ``scale`` x larger."""
    rotation = camera.rotation_matrix.detach().double().numpy()
    turn = yaw_matrix(degrees)
    combined = rotation @ turn
    centre = centre.double().numpy()
    translation = camera.translation.detach().double().numpy() + rotation @ centre - combined @ centre
    turned = Camera(camera.focal.detach().clone(), torch.as_tensor(Rotation.from_matrix(combined).as_rotvec(),
                    dtype=torch.float32), torch.as_tensor(translation, dtype=torch.float32), camera.width,
                    camera.height, camera.principal_point)
    return turned.scaled(scale)


def turntable_frames(fit: FitOutput, lights: torch.Tensor, yaw_range: float = 90.0, count: int = 36,
                     frame: int = 0, scale: float = 1.0) -> list[np.ndarray]:
    """[count] x [H, W, 3] uint8 sRGB images of frame ``frame``'s mesh turning, lit by ``lights``
    [K, B*B, 3] (model frame at yaw 0) held fixed relative to the camera."""
    one = _single_frame(fit, frame)
    geometry = one.frames[0].geometry
    centre = geometry.mesh.vertices.mean(0)
    background = torch.as_tensor(BACKGROUND) ** 2.2
    images = []
    for yaw in yaw_angles(yaw_range, count):
        camera = turned_camera(geometry.camera, centre, yaw, scale)
        turned = rotate_lights(lights, yaw_matrix(yaw).T)  # the light stays where the camera sees it
        rendered = one.render(lights=turned, camera=camera)[0]
        alpha = rendered.coverage[..., None]
        images.append(to_uint8((rendered.face + background * (1 - alpha)).numpy(), srgb=True))
    return images


def _single_frame(fit: FitOutput, frame: int) -> FitOutput:
    import dataclasses

    if not 0 <= frame < fit.num_frames:
        raise ValueError(f"--frame must be from 0 to {fit.num_frames - 1}, got {frame}")
    return dataclasses.replace(fit, frames=(fit.frames[frame],))


def write_animation(images: list[np.ndarray], path: Path, fps: float) -> None:
    """MP4 (H.264 through imageio-ffmpeg's bundled ffmpeg) or GIF (Pillow), by ``path``'s suffix."""
    suffix = path.suffix.lower()
    path.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".gif":
        import imageio.v3 as iio

        iio.imwrite(path, np.stack(images), extension=".gif", duration=1000.0 / fps, loop=0)
        return
    if suffix not in (".mp4", ".mov", ".mkv"):
        raise ValueError(f"{path}: the turntable is written as .mp4 (or .mov, .mkv) or .gif")
    import imageio.v2 as imageio

    even = [_even(image) for image in images]
    with imageio.get_writer(str(path), format="FFMPEG", fps=fps, codec="libx264", quality=8,
                            macro_block_size=1, pixelformat="yuv420p") as writer:
        for image in even:
            writer.append_data(image)


def _even(image: np.ndarray) -> np.ndarray:
    """Pad to even width and height (H.264 with 4:2:0 chroma needs them)."""
    height, width = image.shape[:2]
    return np.pad(image, ((0, height % 2), (0, width % 2), (0, 0)), mode="edge")
