"""Video clips: frames as sRGB float images, with imageio's bundled ffmpeg (imageio-ffmpeg).

Only the frames asked for are kept, shrunk while decoding when ``max_side`` is given, so a long or 4K clip
never sits in memory whole.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import numpy as np
from PIL import Image

from deface.io.images import InputError, one_line


def read_video_frames(
    path: str | os.PathLike, max_frames: int | None = None, stride: int = 1
) -> tuple[list[np.ndarray], float]:
    """Decode frames 0, stride, 2*stride, ... (at most max_frames of them) -> (frames [H, W, 3] float32
    sRGB in [0, 1], frames per second of the source clip)."""
    if stride < 1:
        raise ValueError(f"stride must be >= 1, got {stride}")
    if max_frames is not None and max_frames < 1:
        raise ValueError(f"max_frames must be >= 1 or None, got {max_frames}")
    limit = max_frames if max_frames is not None else float("inf")
    frames, _indices, fps = _decode(Path(path), lambda index: index % stride == 0, limit)
    return frames, fps


def read_spread_frames(path: str | os.PathLike, count: int, stride: int = 1,
                       max_side: int | None = None) -> tuple[list[np.ndarray], list[int]]:
    """``count`` frames evenly spread over frames 0, stride, 2*stride, ... of the clip (first and last
    included) -> (frames [H, W, 3] float32 sRGB in [0, 1], their indices in the clip)."""
    path = Path(path)
    if stride < 1 or count < 1:
        raise ValueError(f"stride and count must be >= 1, got {stride} and {count}")
    strided = -(-_count_frames(path) // stride)
    chosen = np.linspace(0, max(strided - 1, 0), min(count, max(strided, 1))).round().astype(int) * stride
    wanted = set(chosen.tolist())
    frames, indices, _fps = _decode(path, wanted.__contains__, len(wanted), max_side)
    return frames, indices


def _open(path: Path):
    import imageio.v2 as imageio

    if not path.is_file():
        raise InputError(f"{path}: no such file")
    try:
        return imageio.get_reader(str(path), format="FFMPEG")
    except Exception as err:  # imageio raises several types for unreadable files
        raise InputError(f"{path}: cannot open video ({one_line(err)})") from err


def _count_frames(path: Path) -> int:
    reader = _open(path)
    try:
        return int(reader.count_frames())
    except Exception as err:
        raise InputError(f"{path}: cannot decode video ({one_line(err)})") from err
    finally:
        reader.close()


def _decode(path: Path, keep: Callable[[int], bool], limit: float,
            max_side: int | None = None) -> tuple[list[np.ndarray], list[int], float]:
    """Frames whose index passes ``keep`` (at most ``limit``), their indices, and the clip's fps."""
    reader = _open(path)
    frames: list[np.ndarray] = []
    indices: list[int] = []
    try:
        fps = float(reader.get_meta_data().get("fps", 0.0) or 0.0)
        for index, frame in enumerate(reader):
            if keep(index):
                frames.append(_to_float(frame, max_side))
                indices.append(index)
                if len(frames) >= limit:
                    break
    except Exception as err:
        if not frames:
            raise InputError(f"{path}: cannot decode video ({one_line(err)})") from err
    finally:
        reader.close()
    if not frames:
        raise InputError(f"{path}: video has no frames")
    return frames, indices, fps


def _to_float(frame: np.ndarray, max_side: int | None) -> np.ndarray:
    """uint8 [H, W, C] -> float32 RGB in [0, 1], shrunk (aspect kept) when longer than ``max_side``."""
    rgb = np.ascontiguousarray(frame[..., :3])
    if max_side and max(rgb.shape[:2]) > max_side:
        image = Image.fromarray(rgb)
        image.thumbnail((max_side, max_side), Image.LANCZOS)
        rgb = np.asarray(image)
    return rgb.astype(np.float32) / 255.0
