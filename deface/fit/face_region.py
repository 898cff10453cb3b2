"""The face region h a fit uses as M_o: which classifier makes it (the user's BiSeNet weights, else the offline
skin classifier), and h per frame from the stage-1 face."""

from __future__ import annotations

import numpy as np
import torch

from deface.fit.config import FitConfig
from deface.fit.log import FitLog
from deface.fit.state import PosedFace
from deface.fit.target import FitTarget
from deface.priors.face_region import load_face_region_classifier


@torch.no_grad()
def face_classifier(face: PosedFace, target: FitTarget, config: FitConfig, models_dir,
                    log: FitLog) -> tuple[tuple[torch.Tensor, ...], str]:
    """h per frame from the stage-1 face, and which parser made it (for the run record)."""
    classifier, note = region_classifier(config.decouple.face_region_source, models_dir, config.skin_classifier)
    log.info(f"face region h: {note}")
    found = []
    for frame in range(target.num_frames):
        _, fragments = face.fragments(frame)
        h = classifier(target.frames_srgb[frame], fragments.mask.numpy(), target.landmarks[frame].points)
        found.append(torch.as_tensor(np.asarray(h), dtype=torch.float32))
    return tuple(found), note


def region_classifier(source: str, models_dir, skin=None):
    """The face-region classifier h for a config's ``face_region_source`` and a note for the run record."""
    if source == "none":
        return (lambda image, coverage, landmarks: coverage), "none (h = render mask)"
    if source == "bisenet":
        from deface.priors.bisenet import BiSeNetFaceParser

        return BiSeNetFaceParser.from_models_dir(models_dir), "BiSeNet face parsing (79999_iter.pth)"
    return load_face_region_classifier(models_dir, prefer="bisenet" if source == "auto" else "skin", skin=skin)
