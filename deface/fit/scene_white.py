"""The scene's white level a fit holds its lights to: the one the user gives (or points a reference card at), a
colour checker's in the photo, else the estimate from the whole frames outside the stage-1 face
(deface/priors/illuminant.py, docs/skin-tone.md). Several photos of one person each get their own
(``tone.white_per_photo``, docs/person.md)."""

from __future__ import annotations

import numpy as np
import torch

from deface.fit.config import FitConfig
from deface.fit.log import FitLog
from deface.fit.state import PosedFace
from deface.fit.target import FitTarget
from deface.io.images import LOAD_MAX_SIDE, resize_max
from deface.priors.checker import CheckerUnavailable, checker_illuminant, find_checker
from deface.priors.illuminant import IlluminantEstimate, estimate_illuminant, known_illuminant


@torch.no_grad()
def scene_illuminants(face: PosedFace, target: FitTarget, config: FitConfig,
                      log: FitLog) -> tuple[IlluminantEstimate, ...]:
    """Each frame's white level: the user's (or a reference card's) for every frame, else each photo's own
    (:func:`white_groups`), else one read off all the frames: a colour checker's in the first frame, or the
    estimate from every frame's pixels outside the stage-1 face (the whole frames, not only the crop around the
    face). Frames that share a white level share the estimate (the same object)."""
    scene = target.scene_frames()
    known = known_illuminant(scene, config.tone.illuminant, target.scale)
    if known is not None:
        return (known,) * target.num_frames
    # Statistics of the whole frame: a photo decoded large for a small face (deface/batch/task.py) is read smaller.
    reading = [resize_max(frame, LOAD_MAX_SIDE)[0] for frame in scene]
    faces = [scene_face(face, target, frame, reading[frame].shape[:2]) for frame in range(target.num_frames)]
    estimates: list[IlluminantEstimate | None] = [None] * target.num_frames
    for index, frames in enumerate(white_groups(target, config)):
        where = f"photo {index + 1}" if len(frames) < target.num_frames else "the photo"
        said = log if index == 0 else FitLog(quiet=True)  # a missing detector is said once, not per photo
        estimate = checker_white(reading[frames[0]], config.tone.illuminant, said, where)
        if estimate is None:
            estimate = estimate_illuminant([reading[f] for f in frames], [faces[f] for f in frames],
                                           config.tone.illuminant)
        for frame in frames:
            estimates[frame] = estimate
    return tuple(estimates)


def white_groups(target: FitTarget, config: FitConfig) -> list[list[int]]:
    """The frames that share a white level: each photo's of a several-photo fit with its own lights and
    ``tone.white_per_photo``, else all of them."""
    groups = target.lights_of_frames(config.lights.per_photo and config.tone.white_per_photo)
    return [[frame for frame, g in enumerate(groups) if g == group] for group in sorted(set(groups))]


def checker_white(photo: np.ndarray, settings, log: FitLog, where: str = "the photo"):
    """W from a colour checker in ``photo`` (a frame, whole; ``tone.illuminant.checker``), or None, said in the
    log; ValueError (one line) when it is required ("on") and unavailable or not found (``where``: which photo,
    said in the error)."""
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
            raise ValueError(f"tone.illuminant.checker=on: no colour checker found in {where} (its six "
                             "grey patches must show, unclipped; with one checker for several photos of one session, "
                             "--set tone.white_per_photo=false)")
        return None
    return checker_illuminant(reading, settings)


def scene_face(face: PosedFace, target: FitTarget, frame: int, size: tuple[int, int]) -> np.ndarray:
    """[H, W] bool (``size``): the stage-1 face's coverage of the whole frame resized to ``size``."""
    geometry = face.geometry(frame)
    camera = geometry.camera if target.framing.is_whole else target.framing.scene_camera(geometry.camera)
    if (camera.height, camera.width) != tuple(size):
        camera = camera.scaled(size[1] / camera.width, width=size[1], height=size[0])
    return face.renderer.rasterize(geometry.mesh, camera).mask.numpy() > 0
