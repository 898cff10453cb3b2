"""A person truth folder's photos as if taken by other cameras: for measuring a white level per photo
(``tone.white_per_photo``, docs/person.md).

    .venv/bin/python benchmarks/person_cameras.py FOLDER OUT

FOLDER is a truth folder of person sets (``benchmarks/blender/person_scenes.py``). OUT gets the same truth (linked)
and photos re-exposed in linear RGB, each set's photo n by ``CAMERAS[(n - 1) % 3]``: the first as rendered, the
second a stop under through a warmer white balance, the third brighter through a cooler one (clipped at the
encoding's top, as a camera clips). The albedo, the geometry and the lights are the renders'; only what each camera
made of them differs, so a fit that reads every photo against one white level is wrong on at least two of them.
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import numpy as np
from PIL import Image

from deface.io.images import linear_to_srgb, srgb_to_linear

CAMERAS = ((1.0, (1.0, 1.0, 1.0)), (0.5, (1.15, 1.0, 0.8)), (1.3, (0.9, 1.0, 1.15)))
"""(exposure, per-channel white balance gain) of the camera of a set's photos 1, 2, 3 (then again)."""


def camera_of(name: str) -> tuple[float, tuple[float, float, float]]:
    """The camera of ``<tone>_<set>_<n>.png``."""
    return CAMERAS[(int(Path(name).stem.rsplit("_", 1)[1]) - 1) % len(CAMERAS)]


def reexposed(srgb: np.ndarray, exposure: float, gain: tuple[float, float, float]) -> np.ndarray:
    """[H, W, 3] uint8: ``srgb`` (uint8) through a camera of ``exposure`` and white balance ``gain``."""
    linear = srgb_to_linear(srgb.astype(np.float32) / 255.0) * exposure * np.asarray(gain, dtype=np.float32)
    return np.round(linear_to_srgb(np.clip(linear, 0.0, 1.0)) * 255.0).astype(np.uint8)


def main(folder: Path, out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    for item in folder.iterdir():
        if item.name != "images" and not (out / item.name).exists():
            (out / item.name).symlink_to(item.resolve())
    (out / "images").mkdir(exist_ok=True)
    for photo in sorted((folder / "images").glob("*.png")):
        exposure, gain = camera_of(photo.name)
        if exposure == 1.0 and gain == (1.0, 1.0, 1.0):
            shutil.copyfile(photo, out / "images" / photo.name)
            continue
        Image.fromarray(reexposed(np.asarray(Image.open(photo).convert("RGB")), exposure, gain)).save(
            out / "images" / photo.name)
        print(photo.name, exposure, gain)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(Path(sys.argv[1]), Path(sys.argv[2]))
