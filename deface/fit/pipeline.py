"""The whole fit for one input (an image, or the frames of a clip): landmarks -> stage 1 -> face region h
-> stage 2 -> stage 3, returning everything the exporters and the evaluation need.
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
import torch

from deface.fit.config import FitConfig, override
from deface.fit.decoupling import Decoupling
from deface.fit.log import FitLog
from deface.fit.scene import SceneParameters, initial_lights, topology_tensors
from deface.fit.scene_light import start_from_scene
from deface.fit.stage1 import fit_landmarks
from deface.fit.stage2 import FrameRender, StageContext, run_stage2
from deface.fit.stage3 import FrozenFrame, relight_frozen, render_frozen, run_stage3
from deface.fit.target import FitTarget, scale_landmarks, working_frames
from deface.fit.texels import complete_textures, seen_texels, texture_confidence
from deface.landmarks.correspondence import correspondence_for
from deface.landmarks.detect import detect_landmarks, track_video
from deface.models.registry import load_face_model
from deface.priors.face_region import load_face_region_classifier
from deface.priors.human import load_human_prior
from deface.priors.illuminant import estimate_illuminant
from deface.render.mesh import Textures


@dataclass
class FitResult:
    """A finished fit: textures, kept lights, per-frame geometry and renders, and the run record."""

    context: StageContext
    frozen: list[FrozenFrame]
    textures: Textures  # final UV maps (stage 3)
    initial_textures: Textures  # T^0 from the albedo model
    log: FitLog
    optional_networks: dict  # name -> "used" or the reason it was not
    confidence: np.ndarray | None = None  # [Ht, Wt] how well the frames constrain each texel (deface/fit/texels.py)
    seen: np.ndarray | None = None  # [Ht, Wt] visible x h x facing, best frame (what completion went by)
    views: list | None = None  # per frame TexelView: where each texel lands and how it is seen

    def render(self, textures: Textures | None = None) -> list[FrameRender]:
        """Per-frame renders with the fit's geometry, lights and M_o, using ``textures`` (default: own)."""
        textures = textures or self.textures
        with torch.no_grad():
            return [render_frozen(self.context, frame, textures)[0] for frame in self.frozen]

    def relight(self, lights: torch.Tensor, textures: Textures | None = None) -> list[torch.Tensor]:
        """Per-frame faces [H, W, 3] (linear, 0 off the face) under ``lights`` [K, B*B, 3], summed."""
        with torch.no_grad():
            return [relight_frozen(self.context, frame, textures or self.textures, lights) for frame in self.frozen]

    def composite(self, rendered: FrameRender, frame: int) -> torch.Tensor:
        """I_out [H, W, 3] linear: the face where M_o says so, the input elsewhere."""
        weight = rendered.face_region[..., None]
        return rendered.face * weight + self.context.target.images[frame] * (1 - weight)


def detect(frames: list[np.ndarray], config: FitConfig, source: str, video: bool):
    """Landmarks per frame at working resolution; frames without a face are dropped (video)."""
    work, scale = working_frames(frames, config.resolution)
    size = (work[0].shape[1], work[0].shape[0])
    if video:
        found = track_video(frames, face_index=config.face_index, source=source)
    else:
        found = [detect_landmarks(frames[0], face_index=config.face_index, source=source)]
    keep = [i for i, item in enumerate(found) if item is not None]
    return [work[i] for i in keep], [scale_landmarks(found[i], scale, size) for i in keep], scale, keep


def fit(frames: list[np.ndarray], config: FitConfig, *, models_dir=None, source: str = "input",
        video: bool = False, log: FitLog | None = None) -> FitResult:
    """Fit frames (sRGB float [H, W, 3] in [0, 1]; one for a photo) with ``config``."""
    log = log or FitLog(name=source)
    log.start("landmarks")
    work, landmarks, scale, kept = detect(frames, config, source, video)
    if landmarks[0].num_faces > 1:
        log.info(f"{landmarks[0].num_faces} faces found; fitting face {config.face_index} (0 = largest)")
    if len(kept) < len(frames):
        log.info(f"frames without a face were left out: {sorted(set(range(len(frames))) - set(kept))}")
    log.stop("landmarks")
    target = FitTarget(work, landmarks, scale, kept_frames=kept)
    return fit_target(target, config, models_dir=models_dir, log=log)


def fit_target(target: FitTarget, config: FitConfig, *, models_dir=None, log: FitLog | None = None) -> FitResult:
    """Stages 1-3 on frames whose landmarks are known (``fit`` detects them; tests give them)."""
    with torch_threads(config.threads):
        return _fit_target(target, config, models_dir, log)


@contextmanager
def torch_threads(count: int):
    """Run with ``count`` torch threads (0: leave torch's default), restoring the previous setting."""
    previous = torch.get_num_threads()
    if count > 0:
        torch.set_num_threads(count)
    try:
        yield
    finally:
        torch.set_num_threads(previous)


def _fit_target(target: FitTarget, config: FitConfig, models_dir, log: FitLog | None) -> FitResult:
    torch.manual_seed(config.seed)
    np.random.seed(config.seed)
    log = log or FitLog()
    model = load_face_model(config.model, models_dir)
    config = _supported_tone(model, config, log)
    context = _stage1(model, target, config, log, models_dir)
    optional = _face_classifier(context, config, models_dir, log)
    if config.tone.scene_light_prior:
        context.illuminant = _scene_illuminant(context, config)
        log.info(f"scene illuminant: {context.illuminant.source}, white level "
                 f"{np.round(context.illuminant.white, 3).tolist()}, {context.illuminant.cct:.0f} K")
        start_from_scene(context)
    log.start("stage 2")
    run_stage2(context)
    log.stop("stage 2")
    human_prior, reason = load_human_prior(models_dir) if config.priors.human_prior else (None, "off in config")
    optional["facenet"] = "used" if human_prior is not None else reason
    if human_prior is None and config.priors.human_prior:
        log.info(f"human prior (FaceNet) not used: {reason}")
    log.start("stage 3")
    stage3 = run_stage3(context, human_prior)
    log.stop("stage 3")
    result = FitResult(context, stage3.frozen, stage3.textures, stage3.initial, log, optional, views=stage3.views)
    return _finish_textures(result, config, log)


def _finish_textures(result: FitResult, config: FitConfig, log: FitLog) -> FitResult:
    """Complete the texels no frame showed, and measure how well the frames constrain each texel."""
    log.start("textures")
    result.seen = seen_texels(result.views, [rendered.face_region for rendered in result.render()])
    if config.completion.enabled:
        result.textures = complete_textures(result.context.model, result.textures, result.initial_textures,
                                            result.seen, config.completion)
    result.confidence = texture_confidence(result.views, result.render())
    log.stop("textures")
    return result


def _stage1(model, target: FitTarget, config: FitConfig, log: FitLog, models_dir=None) -> StageContext:
    log.start("stage 1")
    corr = correspondence_for(model, models_dir=models_dir)
    result = fit_landmarks(model, corr, target.landmarks, target.size, config.stage1, config.iterations.stage1)
    log.stop("stage 1")
    target.attach_landmarks(corr, result)
    scene = SceneParameters(
        identity=torch.as_tensor(result.identity), expression=torch.as_tensor(result.expression),
        rotation=torch.as_tensor(result.rotation), translation=torch.as_tensor(result.translation),
        focal=torch.as_tensor(result.focal), albedo=torch.zeros(model.albedo.num_coeffs),
        lights=initial_lights(config.lights), tone=_initial_tone(model, config),
    )
    decoupling = Decoupling(config.decouple, config.lights.num_lights, target.num_frames, target.size)
    return StageContext(model, target, scene, decoupling, config, topology_tensors(model), log)


def _supported_tone(model, config: FitConfig, log: FitLog) -> FitConfig:
    """``config`` without ``tone.free_tone`` for a model with no tone axis (BFM's AlbedoMM), said in the log."""
    if not config.tone.free_tone or model.albedo.tone is not None:
        return config
    log.info(f"the {model.name} albedo model has no skin-tone axis: the tone is not free (docs/skin-tone.md)")
    return override(config, **{"tone.free_tone": False})


def _initial_tone(model, config: FitConfig) -> float:
    """The tone a free-tone fit starts from before the scene is read: the model's own mean skin."""
    return model.albedo.tone.reference_ita if config.tone.free_tone else 0.0


@torch.no_grad()
def _face_classifier(context: StageContext, config: FitConfig, models_dir, log: FitLog) -> dict:
    """h per frame from the stage-1 face; returns which optional parser was used (for the run record)."""
    classifier, note = _classifier(config.decouple.face_region_source, models_dir)
    log.info(f"face region h: {note}")
    target = context.target
    for frame in range(target.num_frames):
        geometry = context.geometry(frame)
        coverage = context.renderer.rasterize(geometry.mesh, geometry.camera).mask
        h = classifier(target.frames_srgb[frame], coverage.numpy(), target.landmarks[frame].points)
        target.face_classifier[frame] = torch.as_tensor(np.asarray(h), dtype=torch.float32)
    return {"face_parsing": note}


@torch.no_grad()
def _scene_illuminant(context: StageContext, config: FitConfig):
    """The illuminant estimate from every frame's pixels outside the stage-1 face."""
    faces = []
    for frame in range(context.target.num_frames):
        geometry = context.geometry(frame)
        faces.append(context.renderer.rasterize(geometry.mesh, geometry.camera).mask.numpy() > 0)
    return estimate_illuminant(context.target.frames_srgb, faces, config.tone.illuminant)


def _classifier(source: str, models_dir):
    """The face-region classifier h for a config's ``face_region_source`` and a note for the run record."""
    if source == "none":
        return (lambda image, coverage, landmarks: coverage), "none (h = render mask)"
    if source == "bisenet":
        from deface.priors.bisenet import BiSeNetFaceParser

        return BiSeNetFaceParser.from_models_dir(models_dir), "BiSeNet face parsing (79999_iter.pth)"
    return load_face_region_classifier(models_dir, prefer="bisenet" if source == "auto" else "skin")
