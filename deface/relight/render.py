"""Writing re-renders of a fit: the face composited into the photo, and the face alone with alpha."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from deface.fit.output import FitOutput
from deface.fit.state import FrameRender
from deface.io.images import save_png, to_uint8


def face_rgba(rendered: FrameRender) -> np.ndarray:
    """[H, W, 4] uint8: the face (sRGB) with the render's coverage as alpha."""
    colour = to_uint8(rendered.face.numpy(), srgb=True)
    alpha = to_uint8(rendered.coverage.numpy(), srgb=False)
    return np.concatenate([colour, alpha[..., None]], -1)


def write_renders(fit: FitOutput, renders: list[FrameRender], folder: Path, lights: torch.Tensor | None = None) -> None:
    """``render.png`` (the face where M_o says so, the whole photo elsewhere, as the fit's) and
    ``render_face.png`` (RGBA, the working frame: the crop around the face) per frame (a clip's under
    ``frames/<i>/``), and the SH lights used as ``lights.npy`` [K, B*B, 3]."""
    from PIL import Image

    for frame, rendered in enumerate(renders):
        base = folder if len(renders) == 1 else folder / "frames" / f"{frame:03d}"
        save_png(base / "render.png", fit.composite_photo(rendered, frame).numpy())
        Image.fromarray(face_rgba(rendered)).save(base / "render_face.png")
    if lights is not None:
        np.save(folder / "lights.npy", lights.numpy())
