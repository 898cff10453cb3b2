"""Where the fitted surface's error comes from: the landmark detector or the views (issue 59).

``../shared/data/detail-synth/mesh.obj`` is a face of the model's own topology, so stage 1 can be given that face's
landmarks exactly (each MediaPipe point's place on the model, :func:`deface.eval.synthetic.true_landmarks`) or as
MediaPipe detects them on a render of it. The mesh is turned by each yaw and rendered with the project's renderer
(a soft frontal light, a grey background) under one albedo: the truth's own (``albedo/<tone>.png``: brows, stubble
beard, freckles, moles) and, to tell the texture's share from the geometry's, the truth's median skin colour
everywhere ("flat").

Printed, per albedo and yaw:
- where MediaPipe's points land on the known surface, against the correspondence's points: the detected pixel is
  cast onto the true mesh (its triangle and barycentrics there), carried to the model's mean shape, and compared
  with the correspondence's point on the mean shape (mm; median by band of the face from the brows to the chin,
  with the mean vertical shift, + up);
- stage 1's surface (median cm from the truth after the best similarity, as ``deface bench albedo``'s
  ``surface_cm``) from exact and from detected landmarks, each yaw alone and all yaws as one fit.

    .venv/bin/python benchmarks/landmark_bias.py [--yaws -30,0,30] [--tone ita30] [--size 512]
"""

from __future__ import annotations

import argparse
import math

import numpy as np
import torch

from deface.eval.albedo_benchmark import similarity_aligned
from deface.eval.synthetic import directional_sh, true_landmarks
from deface.fit.config import Stage1Config
from deface.fit.stage1 import fit_landmarks
from deface.io.images import linear_to_srgb, load_image, srgb_to_linear
from deface.landmarks.correspondence import correspondence_for
from deface.landmarks.detect import detect_landmarks
from deface.models.ict_build import read_obj
from deface.models.registry import load_face_model
from deface.paths import shared_dir
from deface.render.camera import Camera
from deface.render.frame import render_frame
from deface.render.mesh import Mesh, Textures
from deface.render.renderer import RenderConfig, Renderer

BANDS = ("brows", "eyes", "nose", "mouth", "chin")
BAND_EDGES = (0.8, 0.6, 0.35, 0.15)  # quantiles of the points' height on the mean shape, top down
BACKGROUND = 0.3  # linear grey


def turned(vertices: np.ndarray, yaw: float) -> np.ndarray:
    """``vertices`` [V, 3] turned by ``yaw`` degrees about the vertical axis through their box's centre."""
    a = math.radians(yaw)
    rotation = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
    return (vertices - (vertices.max(0) + vertices.min(0)) / 2) @ rotation.T


def render(model, renderer, vertices: np.ndarray, textures: Textures, camera: Camera) -> tuple[Mesh, np.ndarray]:
    """The posed mesh and its render [H, W, 3] sRGB under a soft frontal light."""
    mesh = Mesh.create(torch.as_tensor(vertices, dtype=torch.float32), model.triangles, model.uvs,
                       model.triangle_uvs)
    light = directional_sh((0.2, 0.3, 0.93), strength=1.2, ambient=0.5)
    with torch.no_grad():
        out = render_frame(renderer, mesh, camera, textures, light)
    coverage = out.mask.numpy()[..., None]
    linear = out.images[0].numpy() * coverage + BACKGROUND * (1 - coverage)
    return mesh, linear_to_srgb(np.clip(linear, 0, 1))


def on_mean_shape(model, triangle_ids: np.ndarray, barycentrics: np.ndarray) -> np.ndarray:
    """[N, 3] the points (triangle, barycentrics) on the model's mean shape."""
    corners = np.asarray(model.mean_shape)[np.asarray(model.triangles)[triangle_ids]]
    return (corners * barycentrics[..., None]).sum(1)


def detected_on_surface(model, renderer, mesh: Mesh, camera: Camera, points: np.ndarray) -> np.ndarray:
    """[N, 3] the detected pixels ``points`` [N, 2] cast onto ``mesh`` and carried to the mean shape (NaN off it)."""
    triangle_id = renderer.rasterize(mesh, camera).triangle_id.numpy()
    projected = camera.project(mesh.vertices)[0].numpy()
    x = np.clip(np.floor(points[:, 0]).astype(int), 0, camera.width - 1)
    y = np.clip(np.floor(points[:, 1]).astype(int), 0, camera.height - 1)
    out = np.full((len(points), 3), np.nan)
    for k, triangle in enumerate(triangle_id[y, x]):
        if triangle < 0:
            continue
        corners = projected[np.asarray(model.triangles)[triangle]]  # [3, 2]
        edges = np.stack([corners[0] - corners[2], corners[1] - corners[2]], 1)
        first_two = np.linalg.solve(edges, points[k] - corners[2])
        barycentric = np.array([first_two[0], first_two[1], 1 - first_two.sum()])
        out[k] = on_mean_shape(model, np.array([triangle]), barycentric[None])[0]
    return out


def surface_cm(model, result, truth: np.ndarray) -> list[float]:
    """Per frame, the fitted shape's median distance (cm) from ``truth`` after the best similarity."""
    identity = torch.as_tensor(result.identity)
    errors = []
    for expression in result.expression:
        fitted = model.vertices(identity, torch.as_tensor(expression)).detach().numpy().astype(np.float64)
        errors.append(float(np.median(np.linalg.norm(similarity_aligned(fitted, truth) - truth, axis=1))))
    return errors


def band_masks(reference: np.ndarray) -> dict[str, np.ndarray]:
    height = reference[:, 1]
    edges = [np.inf] + [np.quantile(height, q) for q in BAND_EDGES] + [-np.inf]
    return {name: (height <= top) & (height > bottom) for name, top, bottom
            in zip(BANDS, edges, edges[1:], strict=False)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--yaws", default="-30,0,30")
    parser.add_argument("--tone", default="ita30")
    parser.add_argument("--size", type=int, default=512)
    args = parser.parse_args()
    folder = shared_dir() / "data" / "detail-synth"
    model = load_face_model("ict")
    corr = correspondence_for(model)
    renderer = Renderer(RenderConfig(shadow_rays=16), seed=0)
    truth = read_obj(folder / "mesh.obj", with_faces=False)["positions"].astype(np.float64)
    albedo = srgb_to_linear(load_image(folder / "albedo" / f"{args.tone}.png")[..., :3]).astype(np.float32)
    flat = np.broadcast_to(np.median(albedo.reshape(-1, 3), 0), albedo.shape).astype(np.float32)
    camera = Camera.frontal(args.size, args.size, distance=60.0, fov_degrees=30.0)
    yaws = [float(y) for y in args.yaws.split(",")]
    reference = on_mean_shape(model, corr.triangle_ids, corr.barycentrics)
    bands = band_masks(reference)
    for name, image in (("truth's", albedo), ("flat", flat)):
        diffuse = torch.as_tensor(np.ascontiguousarray(image))
        textures = Textures(diffuse, torch.full_like(diffuse, 0.03), torch.full(diffuse.shape[:2] + (1,), 0.45))
        exact, detected = [], []
        for yaw in yaws:
            mesh, srgb = render(model, renderer, turned(truth, yaw), textures, camera)
            exact.append(true_landmarks(model, mesh, camera))
            detected.append(detect_landmarks(srgb))
            offset = detected_on_surface(model, renderer, mesh, camera, detected[-1].points[corr.mediapipe_ids])
            offset = (offset - reference) * 10.0  # mm
            cells = [f"{band} {np.nanmedian(np.linalg.norm(offset[m], axis=1)):.1f} ({np.nanmean(offset[m, 1]):+.1f})"
                     for band, m in bands.items()]
            print(f"{name} albedo, yaw {yaw:+.0f}: detected - correspondence, mm (vertical): " + " | ".join(cells))
        for views in [[i] for i in range(len(yaws))] + [list(range(len(yaws)))]:
            label = ",".join(f"{yaws[i]:+.0f}" for i in views)
            cells = []
            for kind, landmarks in (("exact", exact), ("MediaPipe", detected)):
                result = fit_landmarks(model, corr, [landmarks[i] for i in views], (args.size, args.size),
                                       Stage1Config(), 300)
                cells.append(f"{kind} {np.round(surface_cm(model, result, truth), 3).tolist()}")
            print(f"{name} albedo, stage 1 from yaw {label}: surface cm " + "; ".join(cells))


if __name__ == "__main__":
    main()
