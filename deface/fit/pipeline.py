"""The whole fit for one input (an image, or the frames of a clip), as a list of stage runners:

    landmarks (detect, whole frames) -> crop around the face (frame_target) -> prepare (stage 1, texture
    size, face region h, scene light) -> stage 2 (at most stage2_resolution) -> stage 3 -> FitOutput

Each runner takes the state so far and returns its result (deface/fit/state.py, docs/design.md);
:func:`run_stages` keeps them all (:class:`FitState`, for tests and tools that look inside), :func:`fit` and
:func:`fit_target` return the frozen :class:`~deface.fit.output.FitOutput` that export, eval, relight and the
report consume.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from deface.fit.coarse import coarse_context
from deface.fit.config import FitConfig
from deface.fit.decoupling import Decoupling
from deface.fit.face_region import face_classifier
from deface.fit.log import FitLog
from deface.fit.output import FinishedTextures, FitOutput, RunRecord
from deface.fit.person import PhotoCrop, person_target, photos_of_one_person
from deface.fit.scene import SceneParameters, initial_lights
from deface.fit.scene_light import start_from_scene
from deface.fit.scene_white import scene_illuminants
from deface.fit.stage1 import fit_landmarks
from deface.fit.stage2 import Stage2Result, run_stage2
from deface.fit.stage3 import Stage3Result, render_frozen, run_stage3
from deface.fit.state import FitInputs, LandmarkTarget, PosedFace, StageContext, first_of_each
from deface.fit.target import FitTarget, frame_target
from deface.fit.texels import (
    complete_textures,
    filtered_chroma,
    pigment_gamut_textures,
    seen_texels,
    shade_levelled_textures,
    skin_chroma_matched,
    texture_confidence,
)
from deface.fit.texture_size import choose_texture_size
from deface.fit.tone_start import initial_tone, log_tone, supported_tone
from deface.landmarks.correspondence import correspondence_for
from deface.landmarks.detect import NoFaceError, detect_landmarks, track_video
from deface.models.registry import load_face_model
from deface.priors.human import load_human_prior
from deface.runtime import keep_freed_memory, torch_threads


@dataclass(frozen=True)
class FitState:
    """Every stage's result of one fit. Users and the exporters take :meth:`output`; the context is here for
    tests and benchmarks that look inside a stage."""

    context: StageContext  # inputs, posed face, trained scene and decoupling
    stage2: Stage2Result
    stage3: Stage3Result
    finished: FinishedTextures  # stage 3's maps completed, and what the frames tell about each texel
    optional_networks: dict[str, str]  # name -> "used" or the reason it was not

    def output(self) -> FitOutput:
        record = RunRecord.from_log(self.context.log, self.optional_networks)
        return FitOutput.from_stages(self.context, self.stage3, self.finished, record)


def detect(frames: list[np.ndarray], config: FitConfig, source: str, video: bool, found=None):
    """Landmarks per frame on the whole input frames, and the positions of the frames that have a face (a
    clip's frames without one are dropped); ``found``: a photo's landmarks already detected on ``frames[0]``."""
    if found is not None and not video:
        found = [found]
    elif video:
        found = track_video(frames, face_index=config.face_index, source=source)
    else:
        found = [detect_landmarks(frames[0], face_index=config.face_index, source=source)]
    keep = [i for i, item in enumerate(found) if item is not None]
    return [found[i] for i in keep], keep


def detect_target(frames: list[np.ndarray], config: FitConfig, source: str, video: bool,
                  log: FitLog | None = None, found=None) -> FitTarget:
    """The target of input ``frames``: landmarks on the whole frames (``found``: a photo's, already detected on
    it), then the crop around the face (:func:`deface.fit.target.frame_target`), said in ``log``."""
    log = log or FitLog(quiet=True)
    landmarks, kept = detect(frames, config, source, video, found)
    if landmarks[0].num_faces > 1:
        log.info(f"{landmarks[0].num_faces} faces found; fitting face {config.face_index} (0 = largest)")
    if len(kept) < len(frames):
        log.info(f"frames without a face were left out: {sorted(set(range(len(frames))) - set(kept))}")
    target = frame_target([frames[i] for i in kept], landmarks, config, kept_frames=kept)
    _log_framing(target, log)
    return target


def fit(frames: list[np.ndarray], config: FitConfig, *, models_dir=None, source: str = "input",
        video: bool = False, log: FitLog | None = None, landmarks=None) -> FitOutput:
    """Fit frames (sRGB float [H, W, 3] in [0, 1]; one for a photo) with ``config``; ``landmarks``: a photo's,
    when the caller has already detected them on this very frame (not found twice)."""
    log = log or FitLog(name=source)
    log.start("landmarks")
    target = detect_target(frames, config, source, video, log, landmarks)
    log.stop("landmarks")
    return fit_target(target, config, models_dir=models_dir, log=log)


def fit_photos(photos: list[np.ndarray], sources: list[str], config: FitConfig, *, models_dir=None,
               log: FitLog | None = None, landmarks: list | None = None) -> tuple[FitOutput, list[PhotoCrop]]:
    """One fit of several photos of one person (sRGB [H, W, 3] of any sizes; deface/fit/person.py): a photo without
    a face, or with another person's (:func:`~deface.fit.person.photos_of_one_person`), is left out, said in one
    line; :class:`NoFaceError` when none has a face. ``landmarks``: per photo, those already found on it, or None.
    Returns the fit and where each kept photo's working frame lies in it."""
    if config.tone.illuminant.reference_box is not None:
        raise ValueError("--card with several photos of one person: each photo is cut to its own square around the "
                         "face, so one box does not say where the card is; fit the card's photo alone with --card and "
                         "give its fit to --white (one session's light), or leave the white level to each photo")
    log = log or FitLog(name=sources[0])
    log.start("landmarks")
    found = landmarks or [None] * len(photos)
    kept = []
    for index, (photo, source) in enumerate(zip(photos, sources, strict=True)):
        try:
            points = found[index] or detect_landmarks(photo, face_index=config.face_index, source=source)
        except NoFaceError as error:
            log.info(f"{error}; left out of the fit")
            continue
        kept.append((photo, points, source))
    if not kept:
        raise NoFaceError(f"none of the {len(photos)} photos has a face")
    kept = photos_of_one_person(kept, config.same_person, log)
    target, crops = person_target(*(list(column) for column in zip(*kept, strict=True)), config)
    log.info(f"{len(kept)} photos, each cut to the square around its face at {target.size[0]} pixels")
    log.stop("landmarks")
    return fit_target(target, config, models_dir=models_dir, log=log), crops


def _log_framing(target: FitTarget, log: FitLog) -> None:
    """Say which part of the photo the fit works on, and at what scale."""
    framing = target.framing
    size = "x".join(map(str, framing.size))
    if framing.is_whole:
        log.info(f"working image: the whole frame at {size} pixels (scale {framing.scale:.3g})")
        return
    left, top, right, bottom = (round(v) for v in framing.box)
    log.info(f"working image: the face's crop ({left}, {top}) to ({right}, {bottom}) of the "
             f"{'x'.join(map(str, framing.input_size))} frame, at {size} pixels (scale {framing.scale:.3g})")


def fit_target(target: FitTarget, config: FitConfig, *, models_dir=None, log: FitLog | None = None) -> FitOutput:
    """Stages 1-3 on frames whose landmarks are known (``fit`` detects them; tests give them)."""
    return run_stages(target, config, models_dir=models_dir, log=log).output()


def run_stages(target: FitTarget, config: FitConfig, *, models_dir=None, log: FitLog | None = None) -> FitState:
    """:func:`fit_target` keeping every stage's result."""
    keep_freed_memory()  # no page faults on each step's temporaries (deface/runtime.py)
    with torch_threads(config.threads):
        return _run_stages(target, config, models_dir, log or FitLog())


def stage2_context(context: StageContext) -> StageContext:
    """The level stage 2 runs at: the working frames halved (deface/fit/coarse.py) until their longer side is at
    most ``config.stage2_resolution``; stage 3 refines the maps at the full working size."""
    limit, level = context.config.stage2_resolution, context
    while limit > 0 and max(level.target.size) > limit:
        level = coarse_context(level)
    if level is not context:
        context.log.info(f"stage 2 at {'x'.join(map(str, level.target.size))} pixels (stage2_resolution {limit}), "
                         f"stage 3 at {'x'.join(map(str, context.target.size))}")
    return level


def _run_stages(target: FitTarget, config: FitConfig, models_dir, log: FitLog) -> FitState:
    torch.manual_seed(config.seed)
    np.random.seed(config.seed)
    context, optional = prepare(target, config, models_dir=models_dir, log=log)
    log.start("stage 2")
    stage2 = run_stage2(stage2_context(context))
    log.stop("stage 2")
    human_prior, reason = (load_human_prior(models_dir) if context.config.priors.human_prior
                           else (None, "off in config"))
    optional["facenet"] = "used" if human_prior is not None else reason
    if human_prior is None and context.config.priors.human_prior:
        log.info(f"human prior (FaceNet) not used: {reason}")
    log.start("stage 3")
    stage3 = run_stage3(context, human_prior)
    log.stop("stage 3")
    log.start("textures")
    finished = finish_textures(context, stage3)
    log.stop("textures")
    log_tone(context, finished, log)
    return FitState(context, stage2, stage3, finished, optional)


@torch.no_grad()
def finish_textures(context: StageContext, stage3: Stage3Result) -> FinishedTextures:
    """Complete the texels no frame showed, and measure how well the frames constrain each texel."""
    # One render serves both maps: M_o is frozen, and the confidence's light fraction is a ratio of per-light
    # renders at a pixel, in which the albedo (and so the completion of texels no frame showed) cancels.
    renders = [render_frozen(context, frame, stage3.textures)[0] for frame in stage3.frozen]
    seen = seen_texels(stage3.views, [rendered.face_region for rendered in renders])
    textures = stage3.textures
    if context.config.shade_level.enabled:
        textures = shade_levelled_textures(textures, seen, stage3.views, renders, context.config.shade_level)
    if context.config.chroma.enabled:
        textures = filtered_chroma(textures, seen, stage3.views, context.config.chroma)
    if context.config.pigment_gamut.enabled:
        textures = pigment_gamut_textures(textures, seen, context.config.pigment_gamut, context.log)
    if context.config.completion.enabled:
        textures = complete_textures(context.model, textures, stage3.initial, seen, context.config.completion)
    light = context.inputs.scene_light
    if context.config.tone.skin_chroma and light is not None and light.skin is not None:
        textures, gain = skin_chroma_matched(context.model, textures, seen, light.skin, context.scene.lights)
        if gain is not None:
            context.log.info(f"the map's skin takes the photo's skin chroma (gain {np.round(gain, 3).tolist()}); "
                             "the lights the inverse")
    return FinishedTextures(textures, seen, texture_confidence(stage3.views, renders))


def prepare(target: FitTarget, config: FitConfig, *, models_dir=None,
            log: FitLog | None = None) -> tuple[StageContext, dict[str, str]]:
    """Stage 1 and what stages 2-3 fit to besides the photos (h, the scene's light): the context stage 2
    starts from, and which optional networks were used. Seed torch/numpy first for a reproducible fit."""
    log = log or FitLog(quiet=True)
    model = load_face_model(config.model, models_dir)
    config = supported_tone(model, config, log)
    log.start("stage 1")
    corr = correspondence_for(model, models_dir=models_dir)
    result = fit_landmarks(model, corr, target.landmarks, target.size, config.stage1, config.iterations.stage1,
                           principal_point=target.principal_point, photo_side=max(target.framing.scene_size))
    log.stop("stage 1")
    groups = target.light_groups if config.lights.per_photo else None
    landmarks = LandmarkTarget(corr, torch.as_tensor(result.landmarks_2d, dtype=torch.float32),
                               torch.as_tensor(corr.weights, dtype=torch.float32),
                               face_size=_face_sizes(target), units=config.weights.landmark_units)
    scene = SceneParameters(
        identity=torch.as_tensor(result.identity), expression=torch.as_tensor(result.expression),
        rotation=torch.as_tensor(result.rotation), translation=torch.as_tensor(result.translation),
        focal=torch.as_tensor(result.focal), albedo=torch.zeros(model.albedo.num_coeffs),
        lights=initial_lights(config.lights).repeat(len(set(groups or [0])), 1, 1), tone=initial_tone(model, config),
    )
    decoupling = Decoupling(config.decouple, scene.lights.shape[0], target.num_frames, target.size, groups)
    face = PosedFace.create(model, scene, config, target)
    texture_size = choose_texture_size(face, target, config, log)
    classifier, note = face_classifier(face, target, config, models_dir, log)
    scene_light = None
    if config.tone.scene_light_prior:
        illuminants = scene_illuminants(face, target, config, log)
        log_illuminants(illuminants, log)
        scene_light = start_from_scene(face, target, classifier, illuminants, config, log)
    elif config.tone.illuminant.white is not None or config.tone.illuminant.reference_box is not None:
        log.info(f"tone.illuminant's white level is not used: the {config.preset} preset does not hold the lights "
                 "to the scene (tone.scene_light_prior off)")
    inputs = FitInputs(target, landmarks, classifier, scene_light)
    return StageContext.create(inputs, face, decoupling, config, log, texture_size), {"face_parsing": note}


def log_illuminants(illuminants: tuple, log: FitLog) -> None:
    """Say each distinct white level (one per photo of a several-photo fit: "photo 2: ...")."""
    firsts = first_of_each(illuminants)
    for index, illuminant in enumerate(illuminants[first] for first in firsts):
        photo = f"photo {index + 1}: " if len(firsts) > 1 else ""
        where = f" ({illuminant.detail})" if illuminant.detail else ""
        log.info(f"{photo}scene illuminant: {illuminant.source}{where}, white level "
                 f"{np.round(illuminant.white, 3).tolist()}, {illuminant.cct:.0f} K")


def _face_sizes(target: FitTarget) -> torch.Tensor:
    """[T] each frame's detected face size in working pixels: the diagonal of its landmarks' box."""
    boxes = [np.ptp(landmarks.points[:, :2], axis=0) for landmarks in target.landmarks]
    return torch.tensor([float(np.hypot(*box)) for box in boxes], dtype=torch.float32)
