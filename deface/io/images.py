"""Image files: load (EXIF orientation, RGBA/grey), save as PNG, sRGB <-> linear (gamma 2.2), resize.

Gamma: like NextFace, the sRGB transfer curve is approximated by a pure power law with gamma 2.2
(``linear = srgb ** 2.2``), not the piecewise IEC 61966-2-1 curve; the two differ by < 1% of full
scale above 0.05 and the power law keeps the optimiser's image formation identical to the paper's.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from PIL import Image, ImageOps, UnidentifiedImageError

GAMMA = 2.2  # NextFace's display gamma
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])  # Rec. 709 / sRGB luminance of linear RGB
CLIPPED = 0.98
"""sRGB value at which a channel counts as clipped (the sensor or the encoding's top)."""


# Larger photos are shrunk while they are decoded (JPEG: at a fraction of the full size) so that an
# 8000 x 6000 photo never exists as a float image whole; the fit works at --resolution <= 2048 anyway.
LOAD_MAX_SIDE = 2048
# A photo whose face is small in it is decoded larger, so that the face keeps the pixels the fit's resolution asks
# for (deface/batch/task.py load_photo), up to this many pixels: 8 MP, 96 MB as float RGB; the fit of a 6000 x 4000
# photo decoded at 8 MP peaks at 1.43 GB (BENCHMARKS.md), from the copies of the whole photo that render.png and
# params.npz are written from.
LOAD_MAX_PIXELS = 8_000_000
# Pillow's decompression-bomb guard would allow ~179 MP; a photo above this is refused before decoding.
MAX_PIXELS = 120_000_000


class InputError(ValueError):
    """An input file cannot be used (missing, unreadable, corrupt, wrong kind); one line, names the file."""


def one_line(error: BaseException) -> str:
    """``Type: first line of the message`` (libraries such as ffmpeg give pages); at most 200 characters."""
    lines = [line.strip() for line in str(error).splitlines() if line.strip()]
    text = f"{type(error).__name__}: {lines[0]}" if lines else type(error).__name__
    return text if len(text) <= 200 else text[:197] + "..."


def load_image(path: str | os.PathLike, max_side: int | None = None) -> np.ndarray:
    """Read an image file -> [H, W, 3] float32 sRGB in [0, 1], EXIF orientation applied.

    Grey images are repeated to 3 channels; an alpha channel is dropped (faces are opaque; transparent
    pixels keep their stored colour). 16-bit greys are scaled by 65535. With ``max_side`` a larger image
    is shrunk while it is decoded (keeping its aspect), before the float image is made.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    try:
        with Image.open(path) as img:
            _check_pixels(path, img)
            if max_side:
                img.draft("RGB", (max_side, max_side))  # JPEG: decode at 1/2, 1/4 or 1/8 scale
            img = ImageOps.exif_transpose(img)
            img.load()
            array = _to_rgb_array(_shrink(img, max_side))
    except InputError:
        raise
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError, Image.DecompressionBombError) as err:
        raise InputError(f"{path}: cannot read image ({one_line(err)})") from err
    return array


def image_size(path: str | os.PathLike) -> tuple[int, int]:
    """(width, height) of an image file as :func:`load_image` orients it (EXIF), before any shrinking, without
    decoding its pixels. InputError (one line) when the file cannot be read."""
    try:
        with Image.open(path) as img:
            width, height = img.size
            transposed = img.getexif().get(0x0112) in (5, 6, 7, 8)  # EXIF orientations that swap the axes
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as err:
        raise InputError(f"{path}: cannot read image ({one_line(err)})") from err
    return (height, width) if transposed else (width, height)


def _check_pixels(path: Path, img: Image.Image) -> None:
    width, height = img.size
    if width < 1 or height < 1 or width * height > MAX_PIXELS:
        raise InputError(f"{path}: {width} x {height} pixels is outside 1 .. {MAX_PIXELS // 1_000_000} MP")


def _shrink(img: Image.Image, max_side: int | None) -> Image.Image:
    if not max_side or max(img.size) <= max_side:
        return img
    if img.mode not in ("I;16", "I;16B", "I;16L", "I", "F"):
        img = img.convert("RGB")
    img = img.copy()
    img.thumbnail((max_side, max_side), Image.LANCZOS)
    return img


def _to_rgb_array(img: Image.Image) -> np.ndarray:
    """PIL image of any mode -> [H, W, 3] float32 in [0, 1]."""
    if img.mode in ("I;16", "I;16B", "I;16L", "I"):
        grey = np.asarray(img, dtype=np.float32)
        scale = 65535.0 if grey.max() > 255 else 255.0
        grey = np.clip(grey / scale, 0.0, 1.0)
        return np.repeat(grey[..., None], 3, axis=2)
    if img.mode == "F":
        grey = np.clip(np.asarray(img, dtype=np.float32), 0.0, 1.0)
        return np.repeat(grey[..., None], 3, axis=2)
    rgb = img.convert("RGB")
    return np.asarray(rgb, dtype=np.float32) / 255.0


def to_uint8(image: np.ndarray, srgb: bool) -> np.ndarray:
    """[H, W] or [H, W, C] linear float -> uint8, gamma-encoded when ``srgb``."""
    image = np.array(image, dtype=np.float32)  # one copy, then in place: a photo decoded large is up to 8 MP
    np.clip(np.nan_to_num(image, copy=False), 0.0, 1.0, out=image)
    if srgb:
        np.power(image, 1.0 / GAMMA, out=image)
    image *= 255.0
    return np.rint(image, out=image).astype(np.uint8)


def save_png(path: Path, image: np.ndarray, srgb: bool = True) -> None:
    """Save a float image; ``srgb`` gamma-encodes linear colour, False stores data maps as they are."""
    array = to_uint8(image, srgb)
    if array.ndim == 3 and array.shape[2] == 1:
        array = array[..., 0]
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(array).save(path)


def srgb_to_linear(image: np.ndarray) -> np.ndarray:
    """sRGB-encoded values in [0, 1] -> linear, power law gamma 2.2 (NextFace's convention)."""
    linear = np.clip(image, 0.0, None).astype(np.float32, copy=False)  # a copy, then in place (a 8 MP photo)
    return np.power(linear, GAMMA, out=linear if isinstance(linear, np.ndarray) else None)


def linear_to_srgb(image: np.ndarray) -> np.ndarray:
    """Linear values -> sRGB-encoded in [0, 1], power law 1/2.2 (inverse of :func:`srgb_to_linear`)."""
    return np.power(np.clip(image, 0.0, 1.0), 1.0 / GAMMA).astype(np.float32)


def resize_max(image: np.ndarray, max_size: int) -> tuple[np.ndarray, float]:
    """Shrink [H, W, C] so that max(H, W) <= max_size, keeping aspect -> (image, scale = new / old).

    Images already small enough are returned unchanged with scale 1.0 (never upscaled).
    """
    if max_size <= 0:
        raise ValueError(f"max_size must be positive, got {max_size}")
    height, width = image.shape[:2]
    longest = max(height, width)
    if longest <= max_size:
        return image, 1.0
    scale = max_size / longest
    new_w, new_h = max(1, round(width * scale)), max(1, round(height * scale))
    channels = [
        np.asarray(
            Image.fromarray(image[..., c].astype(np.float32), mode="F").resize((new_w, new_h), Image.LANCZOS)
        )
        for c in range(image.shape[2])
    ]
    return np.stack(channels, axis=-1).astype(np.float32), scale
