"""The typed state that stages 2 and 3 share (see the data-flow drawing in docs/design.md).

Shapes: T frames of H x W working pixels, V mesh vertices, N landmark correspondences, n initial lights
and K kept lights with B*B SH coefficients per colour.

- :class:`FitInputs` (frozen): what the fit is fitted to once stage 1 has run: the frames
  (:class:`~deface.fit.target.FitTarget`), the landmark targets of L_lan, the face-region classifier h and
  the scene's light (illuminant estimate and the cheek/forehead pixels of its level term).
- :class:`PosedFace` (frozen): the face model posed by the trainable scene parameters, with the renderer;
  the geometry and coverage of each frame at the parameters' current values.
- the trainable parameters: :class:`~deface.fit.scene.SceneParameters` (coefficients, pose, focal, lights,
  tone) and :class:`~deface.fit.decoupling.Decoupling` (fields f and g, kept lights). Optimisers change
  them in place; nothing else does.
- :class:`StageContext` (frozen): the above plus config, log and the per-frame shadow-transfer caches. It is
  data: how a stage renders a frame of it and scores it is deface/fit/rendering.py.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from deface.decouple.compose import compose_face
from deface.fit.config import FitConfig
from deface.fit.decoupling import Decoupling
from deface.fit.log import FitLog
from deface.fit.scene import FrameGeometry, SceneParameters, frame_geometry, topology_tensors
from deface.fit.target import FitTarget
from deface.landmarks.correspondence import Correspondence, model_landmarks
from deface.losses.landmarks import landmark_loss
from deface.models.base import FaceModel
from deface.priors.illuminant import IlluminantEstimate
from deface.render.renderer import Fragments, Renderer, RenderOutput, ShadowTransferCache


@dataclass(frozen=True)
class LandmarkTarget:
    """L_lan's target: the detected points in the correspondence's order."""

    correspondence: Correspondence  # MediaPipe point -> model surface point
    detected: torch.Tensor  # [T, N, 2] detected points in the frame's pixels
    weights: torch.Tensor  # [N] per-point weights of the correspondence
    pixel_scale: float = 1.0  # the frame's pixels per working pixel (0.5 at stage 2's half-size level)
    face_size: torch.Tensor | None = None  # [T] the detected face's size in working pixels (its landmarks' box
    # diagonal)
    units: str = "pixels"  # distances in working pixels, or in units of face_size ("face")

    def loss(self, geometry: FrameGeometry, frame: int) -> torch.Tensor:
        """L_lan as in the authors' code: weighted mean squared distance of the projected points of ``geometry``
        (the frame's posed mesh and camera), in working pixels or in units of the face's size."""
        points, _ = geometry.camera.project(model_landmarks(geometry.mesh.vertices, self.correspondence))
        scale = self.pixel_scale * self.face_size[frame] if self.units == "face" else self.pixel_scale
        return landmark_loss(points, self.detected[frame], scale, self.weights, squared=True)


@dataclass(frozen=True)
class SceneLight:
    """The scene's light as the scene-light terms see it (``tone.scene_light_prior``)."""

    illuminants: tuple[IlluminantEstimate, ...]  # T: each frame's white level and colour temperature (frames
    # that share one, a clip's or one session's photos, share the object)
    regions: tuple[torch.Tensor, ...] | None  # T x [H, W] bool cheek/forehead skin (None: too little skin)
    skin: np.ndarray | None = None  # [3] linear RGB: the skin in the key light over W (None: not read)

    @property
    def illuminant(self) -> IlluminantEstimate:
        """The first frame's estimate: what params.json's ``illuminant`` and the tone's interval say."""
        return self.illuminants[0]

    def distinct(self) -> list[int]:
        """The first frame of each distinct white level."""
        return first_of_each(self.illuminants)


def first_of_each(items: tuple | list) -> list[int]:
    """The position of the first of each distinct object in ``items`` (by identity)."""
    return [t for t, item in enumerate(items) if all(item is not other for other in items[:t])]


@dataclass(frozen=True)
class FitInputs:
    """Everything stages 2 and 3 fit to; fixed once stage 1 and the face-region classifier have run."""

    target: FitTarget  # frames (sRGB and linear), detected landmarks, working scale
    landmarks: LandmarkTarget  # L_lan's target
    face_classifier: tuple[torch.Tensor, ...]  # T x [H, W] h in [0, 1]
    scene_light: SceneLight | None = None  # None without the scene-light prior

    @property
    def num_frames(self) -> int:
        return self.target.num_frames


@dataclass(frozen=True)
class PosedFace:
    """The face model posed by ``scene``'s current values, and the renderer that draws it."""

    model: FaceModel
    scene: SceneParameters  # trainable, changed in place by the optimisers
    topology: dict[str, torch.Tensor]  # triangles [F, 3], uvs [Vt, 2], triangle_uvs [F, 3]
    renderer: Renderer
    size: tuple[int, int]  # (W, H) of the frames it is drawn at (the working resolution but in
    # stage 2's half-size steps, deface/fit/coarse.py)
    pixel_scale: float = 1.0  # those frames' pixels per working pixel (scales the focal length)
    principal_point: tuple[float, float] | None = None  # (x, y) in those frames' pixels: the photo's centre
    # as a crop around the face sees it (deface/fit/framing.py); None: the frames' centre

    @classmethod
    def create(cls, model: FaceModel, scene: SceneParameters, config: FitConfig, target: FitTarget):
        """The face drawn at ``target``'s working frames (their size and the photo's principal point)."""
        return cls(model, scene, topology_tensors(model), fit_renderer(config), target.size,
                   principal_point=target.principal_point)

    def geometry(self, frame: int) -> FrameGeometry:
        return frame_geometry(self.model, self.scene, self.topology, frame, self.size, self.pixel_scale,
                              self.principal_point)

    def fragments(self, frame: int) -> tuple[FrameGeometry, Fragments]:
        """The frame's geometry and what covers each working pixel."""
        geometry = self.geometry(frame)
        return geometry, self.renderer.rasterize(geometry.mesh, geometry.camera)


@dataclass(frozen=True)
class FrameRender:
    """One frame's render: per-light images, buffers, masks and the composed face."""

    light_images: torch.Tensor  # [K, H, W, 3] I_Rs (kept lights)
    coverage: torch.Tensor  # [H, W] M_R
    light_masks: torch.Tensor  # [K, H, W] M_L
    face_region: torch.Tensor  # [H, W] M_o
    face: torch.Tensor  # [H, W, 3] I_R
    region_probability: torch.Tensor | None = None  # [H, W] g (None without the field g or when M_o is frozen)
    normals: torch.Tensor | None = None  # [H, W, 3] unit normals of the render (model frame)

    @classmethod
    def of(cls, output: RenderOutput, light_masks: torch.Tensor, face_region: torch.Tensor,
           region_probability: torch.Tensor | None = None) -> FrameRender:
        """A render's per-light images composed with ``light_masks`` [K, H, W] (M_L) into I_R."""
        return cls(output.images, output.mask, light_masks, face_region, compose_face(output.images, light_masks),
                   region_probability, output.normals)


def fit_renderer(config: FitConfig) -> Renderer:
    """The renderer of a fit: ``config.render`` with the lights' bands and the fit's seed."""
    return Renderer(config.render, config.lights.bands, config.seed)


@dataclass(frozen=True)
class StageContext:
    """What stages 2 and 3 share: inputs, the posed face, the trainable parameters, config, log, caches."""

    inputs: FitInputs
    face: PosedFace
    decoupling: Decoupling  # trainable: f, g and the kept lights
    config: FitConfig
    log: FitLog
    shadow_caches: tuple[ShadowTransferCache, ...]  # one per frame
    texture_size: int  # side of stage 3's UV maps: config.texture_size, or what the face's pixels support

    @classmethod
    def create(cls, inputs: FitInputs, face: PosedFace, decoupling: Decoupling, config: FitConfig,
               log: FitLog, texture_size: int | None = None) -> StageContext:
        """The context of ``inputs``; ``texture_size`` defaults to ``config.texture_size``."""
        caches = tuple(ShadowTransferCache(face.renderer) for _ in range(inputs.num_frames))
        size = texture_size or config.texture_size
        if size is None:
            raise ValueError("StageContext: config.texture_size is None (from the face) and no size was given")
        return cls(inputs, face, decoupling, config, log, caches, size)

    @property
    def model(self) -> FaceModel:
        return self.face.model

    @property
    def scene(self) -> SceneParameters:
        return self.face.scene

    @property
    def renderer(self) -> Renderer:
        return self.face.renderer

    @property
    def kept_lights(self) -> torch.Tensor:
        """[K, B*B, 3] the SH coefficients of the lights ACE kept, in f's mask order."""
        return self.face.scene.lights[self.decoupling.kept]

    @property
    def topology(self) -> dict[str, torch.Tensor]:
        return self.face.topology

    @property
    def target(self) -> FitTarget:
        return self.inputs.target

    def geometry(self, frame: int) -> FrameGeometry:
        return self.face.geometry(frame)


class LossTerms:
    """Named loss terms of one step: ``add`` passes a term through (the total is summed by the caller in
    its own order, so totals stay bit-identical) and keeps its value under its name."""

    def __init__(self):
        self.values: dict[str, float] = {}

    def add(self, name: str, value: torch.Tensor, scale: float = 1.0) -> torch.Tensor:
        self.values[name] = self.values.get(name, 0.0) + float(value.detach()) * scale
        return value
