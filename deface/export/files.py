"""Writing outputs safely: images, OBJ/MTL, params, all staged in a temporary folder and moved into place
only when complete, so an interrupted or failed run never leaves a half-written result or destroys an
earlier one.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from PIL import Image

SRGB_GAMMA = 2.2  # NextFace's linearisation; see deface.io


def to_uint8(image: np.ndarray, srgb: bool) -> np.ndarray:
    """[H, W] or [H, W, C] linear float -> uint8, gamma-encoded when ``srgb``."""
    image = np.clip(np.nan_to_num(np.asarray(image, dtype=np.float32)), 0.0, 1.0)
    if srgb:
        image = image ** (1.0 / SRGB_GAMMA)
    return np.round(image * 255.0).astype(np.uint8)


def save_png(path: Path, image: np.ndarray, srgb: bool = True) -> None:
    """Save a float image; ``srgb`` gamma-encodes linear colour, False stores data maps as they are."""
    array = to_uint8(image, srgb)
    if array.ndim == 3 and array.shape[2] == 1:
        array = array[..., 0]
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(array).save(path)


def write_json(path: Path, data: dict) -> None:
    path.write_text(json.dumps(data, indent=2, sort_keys=False, default=_json_default) + "\n")


def _json_default(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


@contextmanager
def staged_directory(final: Path) -> Iterator[Path]:
    """Yield a temporary folder beside ``final``; on success it replaces ``final`` in one rename.

    On an exception the staging folder is removed and ``final`` (if it existed) is left untouched.
    """
    final.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{final.name}.", suffix=".partial", dir=final.parent))
    try:
        yield staging
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    if final.exists():
        previous = final.with_name(f".{final.name}.previous")
        shutil.rmtree(previous, ignore_errors=True)
        final.rename(previous)
        staging.rename(final)
        shutil.rmtree(previous, ignore_errors=True)
    else:
        staging.rename(final)
