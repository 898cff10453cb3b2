"""Stage 1 on every photo of a folder: landmark detection + landmark fit, error in % of the
inter-ocular distance (outer eye corners, MediaPipe 33-263), time, and an overlay per face.

Usage: python benchmarks/stage1_report.py OUTPUT_DIR [--images DIR] [--iterations N]
Overlays: the fitted mesh as a wireframe (front-facing triangles, grey), detected landmarks (green)
and fitted model landmarks (red) on the original photo.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np
import torch

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from deface.fit.config import Iterations, Stage1Config  # noqa: E402
from deface.fit.stage1 import Stage1Result, fit_landmarks  # noqa: E402
from deface.io import list_inputs, load_image  # noqa: E402
from deface.landmarks import correspondence_for  # noqa: E402
from deface.landmarks.detect import FaceMeshDetector, Landmarks, NoFaceError  # noqa: E402
from deface.models.base import FaceModel  # noqa: E402
from deface.paths import shared_dir  # noqa: E402


def draw_overlay(image: np.ndarray, model: FaceModel, result: Stage1Result) -> np.ndarray:
    """uint8 [H, W, 3] photo with the fitted wireframe and landmarks."""
    import cv2

    canvas = np.ascontiguousarray((image * 255).astype(np.uint8)[..., ::-1])  # BGR for cv2
    with torch.no_grad():
        vertices = model.vertices(torch.as_tensor(result.identity), torch.as_tensor(result.expression[0]))
        camera = result.camera(0)
        pixels, _ = camera.project(vertices)
        cam = camera.to_camera(vertices)
    tri = torch.as_tensor(model.triangles)
    normals = torch.cross(cam[tri[:, 1]] - cam[tri[:, 0]], cam[tri[:, 2]] - cam[tri[:, 0]], dim=-1)
    front = (normals * cam[tri].mean(1)).sum(-1) < 0  # facing the camera (CCW seen from outside)
    polygons = (pixels[tri[front]].numpy() * 16).astype(np.int32)  # 4 fractional bits
    layer = canvas.copy()
    cv2.polylines(layer, list(polygons), True, (200, 200, 200), 1, cv2.LINE_AA, shift=4)
    canvas = cv2.addWeighted(layer, 0.45, canvas, 0.55, 0)
    radius = max(1, round(max(image.shape[:2]) / 400))
    for (x, y), (u, v) in zip(result.landmarks_2d[0], result.projected_2d[0], strict=True):
        cv2.circle(canvas, (round(x), round(y)), radius, (0, 220, 0), -1, cv2.LINE_AA)
        cv2.circle(canvas, (round(u), round(v)), radius, (0, 0, 255), -1, cv2.LINE_AA)
    return canvas[..., ::-1]


def detect_all(image: np.ndarray) -> list[Landmarks]:
    """Every face in the photo, largest first."""
    with FaceMeshDetector(static=True) as detector:
        faces = detector.detect_all(image)
    size = (image.shape[1], image.shape[0])
    return [Landmarks(points, depth, size, len(faces), i) for i, (points, depth) in enumerate(faces)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("output", type=Path, help="folder for the overlays")
    default_images = (shared_dir() / "data" / "images") if shared_dir() else None
    parser.add_argument("--images", type=Path, default=default_images, help="folder of photos")
    parser.add_argument("--iterations", type=int, default=Iterations.stage1)
    args = parser.parse_args()
    if args.images is None:
        parser.error("--images is required when ../shared is absent")
    if shared_dir() is not None:
        os.environ.setdefault("DEFACE_MODELS", str(shared_dir() / "models"))
    from PIL import Image

    from deface.models.ict import load_ict

    args.output.mkdir(parents=True, exist_ok=True)
    model = load_ict()
    corr = correspondence_for(model)
    config = Stage1Config()
    print(f"model {model.name}, {len(corr)} landmark correspondences, {args.iterations} Adam steps")
    print(
        "| image | faces found | face | error % IOD | error % frontal IOD | residual px | IOD px "
        "| detect s | stage 1 s |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    single_errors, single_times = [], []
    for item in list_inputs([args.images]):
        if item.kind != "image":
            continue
        image = load_image(item.path)
        start = time.perf_counter()
        try:
            faces = detect_all(image)
        except NoFaceError:
            faces = []
        detect_s = time.perf_counter() - start
        if not faces:
            print(f"| {item.path.name} | 0 | - | - | - | - | - | {detect_s:.2f} | - |")
            continue
        for landmarks in faces:
            start = time.perf_counter()
            result = fit_landmarks(model, corr, [landmarks], landmarks.image_size, config, args.iterations)
            fit_s = time.perf_counter() - start
            error = 100 * float(result.error_iod[0])
            frontal = 100 * float(result.error_iod_frontal[0])
            print(
                f"| {item.path.name} | {len(faces)} | {landmarks.face_index} | {error:.2f} | {frontal:.2f} | "
                f"{result.residual_px[0]:.2f} | {result.iod_px[0]:.1f} | {detect_s:.2f} | {fit_s:.2f} |"
            )
            if len(faces) == 1:
                single_errors.append(error)
                single_times.append(detect_s + fit_s)
            overlay = draw_overlay(image, model, result)
            Image.fromarray(overlay).save(args.output / f"{item.name}_face{landmarks.face_index}.png")
    if single_errors:
        print(
            f"\nsingle-face photos: {len(single_errors)}, error % IOD mean {np.mean(single_errors):.2f} "
            f"max {np.max(single_errors):.2f}; seconds per image (detect + stage 1) mean "
            f"{np.mean(single_times):.2f} max {np.max(single_times):.2f}"
        )


if __name__ == "__main__":
    main()
