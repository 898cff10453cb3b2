"""The face region h a fit uses as M_o: which classifier makes it (the user's BiSeNet weights, else the offline
skin classifier), and h per frame from the stage-1 face, less the hands MediaPipe finds over it."""

from __future__ import annotations

import numpy as np
import torch

from deface.fit.config import FitConfig
from deface.fit.log import FitLog
from deface.fit.state import PosedFace
from deface.fit.target import FitTarget
from deface.priors.face_region import SkinColourClassifier, load_face_region_classifier
from deface.priors.occluders import HandConfig, hand_mask, reaches_in


@torch.no_grad()
def face_classifier(face: PosedFace, target: FitTarget, config: FitConfig, models_dir,
                    log: FitLog) -> tuple[tuple[torch.Tensor, ...], str]:
    """h per frame from the stage-1 face, and which parser made it (for the run record)."""
    classifier, note = region_classifier(config.decouple.face_region_source, models_dir, config.skin_classifier)
    log.info(f"face region h: {note}")
    found = []
    for frame in range(target.num_frames):
        _, fragments = face.fragments(frame)
        image, points = target.frames_srgb[frame], target.landmarks[frame].points
        coverage = fragments.mask.numpy()
        if isinstance(classifier, SkinColourClassifier):
            h, occluders = classifier.with_occluders(image, coverage, points)
            say_occluders(occluders, coverage, log, frame)
        else:
            h = classifier(image, coverage, points)
        h = np.asarray(h)
        found.append(torch.as_tensor(without_hands(h, image, points, config.hands, log, frame), dtype=torch.float32))
    return tuple(found), note


SAID_OCCLUDERS = 0.005
"""The occluder finder's share of the face from which the fit says it (half a percent: a frame, a strand)."""


def say_occluders(occluders: np.ndarray | None, coverage: np.ndarray, log: FitLog, frame: int) -> None:
    """Say in ``log`` what share of the face (``coverage`` [H, W]) the occluder finder left out of h, and what it
    leaves in (docs/occluders.md "Limits")."""
    if occluders is None:
        return
    face = coverage > 0.5
    share = float((occluders & face).sum() / max(face.sum(), 1))
    if share >= SAID_OCCLUDERS:
        log.info(f"frame {frame}: thin dark structures (strands of hair, a glasses frame, thin stripes of shade) cover "
                 f"{100 * share:.1f} % of the face; left out of h and filled. A frame's rim along a brow, a tinted "
                 "lens it does not enclose and fingers without their hand stay (docs/occluders.md)")


def without_hands(h: np.ndarray, image: np.ndarray, face: np.ndarray, config: HandConfig, log: FitLog,
                  frame: int) -> np.ndarray:
    """``h`` [H, W] with the hands MediaPipe finds in ``image`` that reach in over the face (its landmarks ``face``
    [N, 2]) set to 0 (said in ``log``)."""
    if not config.enabled:
        return h
    from deface.landmarks.hands import detect_hands

    covered = np.zeros(h.shape, bool)
    for points in detect_hands(image, min_confidence=config.min_confidence):
        if reaches_in(points, face, config.wrist_beyond):
            covered |= hand_mask(points, h.shape, config)
    share = float(h[covered].sum() / max(h.sum(), 1e-6))
    if share > 0:
        log.info(f"frame {frame}: a hand covers {100 * share:.0f} % of the face region; left out of h")
    return np.where(covered, 0.0, h).astype(np.float32)


def region_classifier(source: str, models_dir, skin=None):
    """The face-region classifier h for a config's ``face_region_source`` and a note for the run record."""
    if source == "none":
        return (lambda image, coverage, landmarks: coverage), "none (h = render mask)"
    if source == "bisenet":
        from deface.priors.bisenet import BiSeNetFaceParser

        return BiSeNetFaceParser.from_models_dir(models_dir), "BiSeNet face parsing (79999_iter.pth)"
    return load_face_region_classifier(models_dir, prefer="bisenet" if source == "auto" else "skin", skin=skin)
