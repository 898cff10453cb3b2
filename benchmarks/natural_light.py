"""How much dimmer natural light is towards a chin than towards the front of a face, against the fits' lights.

Issue 38: on real photos a single fitted light is dimmer towards the chin's downward normals and bleaches a beard.
A prior on natural illumination could only tell the two apart if such lights were unnatural. This reads the
irradiance a white Lambertian surface gets at a few of a face's normals (relative to the one facing the camera)
from real environment maps, turned about the vertical axis, and from the kept lights of finished fits.

    OPENCV_IO_ENABLE_OPENEXR=1 python benchmarks/natural_light.py [--maps EXR...] [--fits RUN...]

Maps default to Blender's studio-light HDRIs (/usr/share/blender/datafiles/studiolights/world, Poly Haven, CC0):
equirectangular, the top row the zenith. Fits: run folders (their params.json; lights in the model frame, y up,
z towards the camera).
"""

from __future__ import annotations

import argparse
import glob
import json
import os
from pathlib import Path

import numpy as np

os.environ.setdefault("OPENCV_IO_ENABLE_OPENEXR", "1")

BLENDER_MAPS = "/usr/share/blender/datafiles/studiolights/world/*.exr"
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
NORMALS = {  # (elevation, azimuth) in degrees; y up, z towards the camera
    "forehead (30 up)": (30, 0),
    "chin (45 down)": (-45, 0),
    "under the jaw (70 down)": (-70, 0),
    "cheek (50 left)": (0, -50),
    "cheek (50 right)": (0, 50),
}


def unit(elevation: float, azimuth: float) -> np.ndarray:
    e, a = np.radians(elevation), np.radians(azimuth)
    return np.array([np.sin(a) * np.cos(e), np.sin(e), np.cos(a) * np.cos(e)])


def face_normals() -> np.ndarray:
    """[1 + len(NORMALS), 3]: the front first."""
    return np.stack([unit(0, 0)] + [unit(*angles) for angles in NORMALS.values()])


def map_ratios(path: str, yaws: int = 12, step: int = 4) -> np.ndarray:
    """[yaws, len(NORMALS)] irradiance at each normal over the front's, the map turned by each yaw."""
    import cv2

    radiance = cv2.imread(path, cv2.IMREAD_UNCHANGED)[::step, ::step, ::-1] @ LUMINANCE
    rows, cols = radiance.shape
    polar = (np.arange(rows) + 0.5) / rows * np.pi
    solid_angle = np.sin(polar)[:, None] * (np.pi / rows) * (2 * np.pi / cols)
    ratios = []
    for yaw in np.linspace(0, 2 * np.pi, yaws, endpoint=False):
        azimuth = (np.arange(cols) + 0.5) / cols * 2 * np.pi + yaw
        t, p = np.meshgrid(polar, azimuth, indexing="ij")
        directions = np.stack([np.sin(t) * np.sin(p), np.cos(t), np.sin(t) * np.cos(p)], -1)
        irradiance = (radiance * solid_angle)[..., None] * np.maximum(directions @ face_normals().T, 0)
        totals = irradiance.sum(axis=(0, 1))
        ratios.append(totals[1:] / totals[0])
    return np.array(ratios)


def fit_ratios(run: Path) -> dict[str, np.ndarray]:
    """Kept light -> [len(NORMALS)] irradiance ratios of a finished fit's light (negative radiance clamped as the
    renderer does)."""
    import torch

    from deface.render.sh import cosine_lobe_coefficients, non_negative, sh_basis

    lights = json.loads((run / "params.json").read_text())["lights"]
    bands = int(lights["bands"])
    basis = sh_basis(torch.tensor(face_normals()), bands) * cosine_lobe_coefficients(bands).double()
    out = {}
    for key, coefficients in lights["sh"].items():
        light = non_negative(torch.tensor(coefficients, dtype=torch.float32)[None])[0].double()
        irradiance = (basis @ light).numpy() @ LUMINANCE
        out[key] = irradiance[1:] / irradiance[0]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--maps", nargs="*", default=sorted(glob.glob(BLENDER_MAPS)))
    parser.add_argument("--fits", nargs="*", default=[], type=Path)
    args = parser.parse_args()
    print("| source | " + " | ".join(NORMALS) + " |")
    print("|---|" + "---|" * len(NORMALS))
    for path in args.maps:
        r = map_ratios(path)
        spread = zip(r.min(0), np.median(r, 0), r.max(0), strict=True)
        cells = [f"{lo:.2f}-{mid:.2f}-{hi:.2f}" for lo, mid, hi in spread]
        print(f"| {Path(path).stem} (min-median-max over 12 turns) | " + " | ".join(cells) + " |")
    for run in args.fits:
        for key, r in fit_ratios(run).items():
            print(f"| {run.parent.name}/{run.name} light {key} | " + " | ".join(f"{v:.2f}" for v in r) + " |")


if __name__ == "__main__":
    main()
