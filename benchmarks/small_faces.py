"""Faces small in large photos (a half-body shot, a group): are they found, and where do their landmarks land?

Each photo of ../shared/data/images named below is pasted, scaled so its landmarks span W pixels, into a plain
6000 x 4000 canvas; the landmarks found there, mapped back to the photo, are compared with those found on the photo
itself (mean distance over the inter-ocular distance). With ``--write DIR`` the canvas of the first photo at 400 px
is also saved as a JPEG, for `deface fit DIR/small_face.jpg -o OUT` (time and memory: `/usr/bin/time -v`).

    .venv/bin/python benchmarks/small_faces.py [--write DIR]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from PIL import Image

from deface.landmarks.detect import NoFaceError, detect_landmarks

PHOTOS = ("nextface-s1.png", "facenet-paul_rudd.png", "vd092.png")
WIDTHS = (400, 300, 200, 150, 100, 70)
CANVAS = (6000, 4000)
CORNER = (4100, 2500)


def canvas_with(photo: Image.Image, scale: float) -> np.ndarray:
    small = photo.resize((round(photo.size[0] * scale), round(photo.size[1] * scale)), Image.LANCZOS)
    canvas = Image.new("RGB", CANVAS, (120, 110, 100))
    canvas.paste(small, CORNER)
    return np.asarray(canvas)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", type=Path)
    args = parser.parse_args()
    data = Path(__file__).resolve().parents[2] / "shared" / "data" / "images"
    print("| photo | " + " | ".join(f"{w} px (1/{CANVAS[0] // w})" for w in WIDTHS) + " |")
    print("|---|" + "---|" * len(WIDTHS))
    for name in PHOTOS:
        photo = Image.open(data / name).convert("RGB")
        reference = detect_landmarks(np.asarray(photo)).points
        iod = np.linalg.norm(reference[33] - reference[263])
        cells = []
        for width in WIDTHS:
            scale = width / np.ptp(reference[:, 0])
            canvas = canvas_with(photo, scale)
            started = time.perf_counter()
            try:
                points = detect_landmarks(canvas).points
            except NoFaceError:
                cells.append("not found")
                continue
            error = np.linalg.norm((points - CORNER) / scale - reference, axis=1).mean() / iod
            cells.append(f"{100 * error:.1f} % ({time.perf_counter() - started:.1f} s)")
        print(f"| {name} | " + " | ".join(cells) + " |")
    if args.write:
        photo = Image.open(data / PHOTOS[0]).convert("RGB")
        scale = 400 / photo.size[0]
        args.write.mkdir(parents=True, exist_ok=True)
        Image.fromarray(canvas_with(photo, scale)).save(args.write / "small_face.jpg", quality=90)


if __name__ == "__main__":
    main()
