"""Video clips: frames as sRGB float images, with imageio's bundled ffmpeg (imageio-ffmpeg)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from deface.io.images import InputError, one_line


def read_video_frames(
    path: str | os.PathLike, max_frames: int | None = None, stride: int = 1
) -> tuple[list[np.ndarray], float]:
    """Decode frames 0, stride, 2*stride, ... (at most max_frames of them) -> (frames [H, W, 3] float32
    sRGB in [0, 1], frames per second of the source clip)."""
    import imageio.v2 as imageio

    path = Path(path)
    if stride < 1:
        raise ValueError(f"stride must be >= 1, got {stride}")
    if max_frames is not None and max_frames < 1:
        raise ValueError(f"max_frames must be >= 1 or None, got {max_frames}")
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    try:
        reader = imageio.get_reader(str(path), format="FFMPEG")
    except Exception as err:  # imageio raises several types for unreadable files
        raise InputError(f"{path}: cannot open video ({one_line(err)})") from err
    frames: list[np.ndarray] = []
    try:
        fps = float(reader.get_meta_data().get("fps", 0.0) or 0.0)
        for index, frame in enumerate(reader):
            if index % stride:
                continue
            frames.append(np.asarray(frame[..., :3], dtype=np.float32) / 255.0)
            if max_frames is not None and len(frames) >= max_frames:
                break
    except Exception as err:
        if not frames:
            raise InputError(f"{path}: cannot decode video ({one_line(err)})") from err
    finally:
        reader.close()
    if not frames:
        raise InputError(f"{path}: video has no frames")
    return frames, fps
