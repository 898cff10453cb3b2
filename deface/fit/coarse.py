"""Stage 2's first steps on the frames at half size (``iterations.stage2_coarse_share``), and stage 2 as a whole
on frames halved until they are within ``stage2_resolution`` (deface/fit/pipeline.py: a level of a level).

Stage 2 fits few, smooth unknowns: pose, shape, expression and albedo coefficients, the SH lights, and the
fields f and g over normalised image coordinates. None of them is tied to the pixel grid, so the first steps
can see the frames at half size, for about a quarter of the per-pixel work (f's MLP, the shading, the
barycentrics and their gradients), and the remaining steps refine at the working size.

What the half-size level changes (:func:`coarse_context`), everything else is shared (the trainable
parameters, the renderer and its per-vertex shadow transfer, config, log):
- the frames, h and the cheek/forehead regions are resampled at the half-size pixel centres with the
  footprint of two working pixels (a 2 x 2 box where a size is even, a [1/4, 1/2, 1/4] tent where it is
  odd; at a border a missing pair of pixels takes the nearest pair's mean), so every working pixel counts;
- the camera's focal length is halved (same pose); the principal point (each frame's centre, or the photo's
  centre seen from a crop around the face) moves to its place on the half-size grid;
- L_lan still measures working pixels: its detected points are mapped to the half-size frame and its
  distances divided by the pixel scale, so its weight against the other terms is unchanged;
- f and g see the coordinates of the half-size pixel centres (the same normalised range).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import torch

from deface.fit.framing import Framing
from deface.fit.state import FitInputs, LandmarkTarget, SceneLight, StageContext
from deface.fit.target import FitTarget
from deface.io.images import linear_to_srgb
from deface.landmarks.detect import Landmarks

SCALE = 0.5  # half-size pixels per working pixel


def half_size(size: tuple[int, int]) -> tuple[int, int]:
    """(W, H) of the half-size level of a (W, H) working frame."""
    return (size[0] + 1) // 2, (size[1] + 1) // 2


def can_coarsen(size: tuple[int, int], min_side: int) -> bool:
    """Whether a (W, H) frame has a half-size level of at least ``min_side`` pixels on its longer side."""
    return max(half_size(size)) >= min_side


def to_half(points, size: tuple[int, int]):
    """Working-frame pixel positions [..., 2] (numpy or torch) -> the same points in half-size pixels (the
    frame's centre stays the half-size frame's centre)."""
    coarse = half_size(size)
    working_centre = [size[0] / 2, size[1] / 2]
    coarse_centre = [coarse[0] / 2, coarse[1] / 2]
    if isinstance(points, torch.Tensor):
        return (points - points.new_tensor(working_centre)) * SCALE + points.new_tensor(coarse_centre)
    return (np.asarray(points) - working_centre) * SCALE + coarse_centre


def resample_half(images: torch.Tensor) -> torch.Tensor:
    """[T, H, W, C] -> [T, Hc, Wc, C] at the half-size pixel centres, each the mean of the working pixels
    within one working pixel of it (box for an even size, tent for an odd one; see the module doc)."""
    return _resample_axis(_resample_axis(images, 1), 2)


def _resample_axis(images: torch.Tensor, axis: int) -> torch.Tensor:
    length = images.shape[axis]
    coarse = (length + 1) // 2
    # working position (pixel centres at i + 0.5) of each half-size centre: 2 (j + 0.5 - Wc / 2) + W / 2
    positions = 2.0 * (torch.arange(coarse, dtype=torch.float64) + 0.5 - coarse / 2) + length / 2
    # the mean of the two working pixels i, i + 1 sits at position i + 1; interpolate those means linearly
    index = positions - 1.0
    lower = index.floor()
    frac = (index - lower).to(images.dtype)
    pairs = _pair_means(images, axis)  # [..., length - 1 (at least 1), ...]

    def gather(at: torch.Tensor) -> torch.Tensor:
        return pairs.index_select(axis, at.long().clamp(0, pairs.shape[axis] - 1))

    shape = [1] * images.dim()
    shape[axis] = coarse
    frac = frac.reshape(shape)
    return gather(lower) * (1 - frac) + gather(lower + 1) * frac


def _pair_means(images: torch.Tensor, axis: int) -> torch.Tensor:
    if images.shape[axis] == 1:
        return images
    first = images.narrow(axis, 0, images.shape[axis] - 1)
    second = images.narrow(axis, 1, images.shape[axis] - 1)
    return 0.5 * (first + second)


def coarse_context(context: StageContext) -> StageContext:
    """``context`` at half size: see the module doc for what changes."""
    target, inputs = context.target, context.inputs
    size = target.size
    linear = resample_half(target.images).numpy()
    frames = [np.clip(linear_to_srgb(frame), 0.0, 1.0).astype(np.float32) for frame in linear]
    landmarks = [Landmarks(to_half(found.points, size).astype(np.float32), found.depth * SCALE, half_size(size),
                           found.num_faces, found.face_index) for found in target.landmarks]
    # no scene frames: stage 2 does not read them (the illuminant was estimated before it)
    coarse_target = FitTarget(frames, landmarks, target.scale * SCALE, target.kept_frames,
                              half_framing(target.framing))
    detected = to_half(inputs.landmarks.detected, size)
    pixel_scale = inputs.landmarks.pixel_scale * SCALE
    coarse_inputs = FitInputs(
        coarse_target,
        LandmarkTarget(inputs.landmarks.correspondence, detected, inputs.landmarks.weights, pixel_scale=pixel_scale,
                       face_size=inputs.landmarks.face_size, units=inputs.landmarks.units),
        tuple(_resample_map(h) for h in inputs.face_classifier),
        _coarse_scene_light(inputs.scene_light),
    )
    principal = context.face.principal_point
    face = replace(context.face, size=half_size(size), pixel_scale=context.face.pixel_scale * SCALE,
                   principal_point=None if principal is None else tuple(float(v) for v in to_half(principal, size)))
    return replace(context, inputs=coarse_inputs, face=face)


def half_framing(framing: Framing) -> Framing:
    """Where the half-size level of frames of ``framing`` lies in the input: half the factors, and the corner
    moved by (W / 2 - Wc) working pixels, since a half-size position q is the working position
    2 (q - Wc / 2) + W / 2 (:func:`to_half`)."""
    size = framing.size
    coarse = half_size(size)
    origin = tuple(o + (length / 2 - half) / factor for o, length, half, factor in
                   zip(framing.origin, size, coarse, framing.factors, strict=True))
    return Framing(framing.input_size, coarse, tuple(f * SCALE for f in framing.factors), origin)


def _resample_map(values: torch.Tensor) -> torch.Tensor:
    """[H, W] -> [Hc, Wc]."""
    return resample_half(values.float()[None, ..., None])[0, ..., 0]


def _coarse_scene_light(light: SceneLight | None) -> SceneLight | None:
    if light is None or light.regions is None:
        return light
    return replace(light, regions=tuple(_resample_map(region) >= 0.5 for region in light.regions))
