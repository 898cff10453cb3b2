"""The scene's white level a fit holds its lights to: the one the user gives (or points a reference card at), a
colour checker's in the photo, else the estimate from the whole frames outside the stage-1 face
(deface/priors/illuminant.py, docs/skin-tone.md)."""

from __future__ import annotations

import numpy as np
import torch

from deface.fit.config import FitConfig
from deface.fit.log import FitLog
from deface.fit.state import PosedFace
from deface.fit.target import FitTarget
from deface.io.images import LOAD_MAX_SIDE, resize_max
from deface.priors.checker import CheckerUnavailable, checker_illuminant, find_checker
from deface.priors.illuminant import estimate_illuminant, known_illuminant


@torch.no_grad()
def scene_illuminant(face: PosedFace, target: FitTarget, config: FitConfig, log: FitLog):
    """The white level the user gives (or points a reference card at), else a colour checker's in the photo,
    else the estimate from every frame's pixels outside the stage-1 face: the whole frames, not only the crop
    around the face."""
    scene = target.scene_frames()
    known = known_illuminant(scene, config.tone.illuminant, target.scale)
    if known is not None:
        return known
    # Statistics of the whole frame: a photo decoded large for a small face (deface/batch/task.py) is read smaller.
    reading = [resize_max(frame, LOAD_MAX_SIDE)[0] for frame in scene]
    checker = checker_white(reading[0], config.tone.illuminant, log)
    if checker is not None:
        return checker
    faces = [scene_face(face, target, frame, reading[frame].shape[:2]) for frame in range(target.num_frames)]
    return estimate_illuminant(reading, faces, config.tone.illuminant)


def checker_white(photo: np.ndarray, settings, log: FitLog):
    """W from a colour checker in ``photo`` (the first frame, whole; ``tone.illuminant.checker``), or None, said
    in the log; ValueError (one line) when it is required ("on") and unavailable or not found."""
    if settings.checker == "off":
        return None
    try:
        reading = find_checker(photo)
    except CheckerUnavailable as error:
        if settings.checker == "on":
            raise ValueError(f"tone.illuminant.checker=on: {error}") from None
        log.info(f"{error}; the light's level is estimated from the scene")
        return None
    if reading is None:
        if settings.checker == "on":
            raise ValueError("tone.illuminant.checker=on: no colour checker found in the photo (its six grey "
                             "patches must show, unclipped)")
        return None
    return checker_illuminant(reading, settings)


def scene_face(face: PosedFace, target: FitTarget, frame: int, size: tuple[int, int]) -> np.ndarray:
    """[H, W] bool (``size``): the stage-1 face's coverage of the whole frame resized to ``size``."""
    geometry = face.geometry(frame)
    camera = geometry.camera if target.framing.is_whole else target.framing.scene_camera(geometry.camera)
    if (camera.height, camera.width) != tuple(size):
        camera = camera.scaled(size[1] / camera.width, width=size[1], height=size[0])
    return face.renderer.rasterize(geometry.mesh, camera).mask.numpy() > 0
