"""The frozen result of a fit, :class:`FitOutput`: what export, eval, relight, transfer, turntable and the report
consume (nothing outside deface/fit reaches into the stages). :func:`deface.export.load.load_fit` rebuilds
the same object from an output folder.

Shapes: T frames of H x W working pixels (a crop around the face of the input's frames, whose whole frame at
the working scale is the Hs x Ws *scene*: deface/fit/framing.py), V vertices, n initial lights, K kept, B*B
SH coefficients.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import torch

from deface.fit.config import FitConfig
from deface.fit.framing import Framing
from deface.fit.log import FitLog
from deface.fit.rendering import render_cast
from deface.fit.scene import FrameGeometry, topology_tensors
from deface.fit.stage3 import Stage3Result
from deface.fit.state import FrameRender, StageContext, fit_renderer
from deface.io.images import srgb_to_linear
from deface.models.base import FaceModel
from deface.models.ita import texture_tone
from deface.priors.illuminant import IlluminantEstimate
from deface.render.camera import Camera
from deface.render.frame import FrameCast, cast_frame, shade_frame
from deface.render.mesh import Mesh, Textures
from deface.render.renderer import Renderer, ShadowTransfer
from deface.texture.confidence import TexelView


@dataclass(frozen=True)
class RunRecord:
    """How the fit went: per-stage times and loss curves (total and named terms), notes, optional networks."""

    seconds: dict[str, float]  # stage -> wall seconds
    losses: dict[str, list[float]]  # stage -> total loss per step
    terms: dict[str, list[dict[str, float]]]  # stage -> per step {term name: value}; they sum to the total
    notes: list[str]  # what the log said (faces found, frames dropped, ACE, substitutes)
    optional_networks: dict[str, str]  # name -> "used" or why not

    @classmethod
    def from_log(cls, log: FitLog, optional_networks: dict[str, str]) -> RunRecord:
        return cls(dict(log.seconds), {k: list(v) for k, v in log.losses.items()},
                   {k: list(v) for k, v in log.terms.items()}, list(log.notes), dict(optional_networks))


@dataclass(frozen=True)
class FinishedTextures:
    """Stage 3's maps after texture completion, and what the frames tell about each texel (deface/fit/texels.py)."""

    textures: Textures  # the final UV maps (completed where no frame saw the texel, when completion is on)
    seen: np.ndarray  # [Ht, Wt] visible x h x facing, best frame (what completion went by)
    confidence: np.ndarray  # [Ht, Wt] how well the frames constrain each texel


@dataclass(frozen=True)
class OutputFrame:
    """One fitted frame: frozen geometry, shadow transfer, the photo and the masks of the fit."""

    geometry: FrameGeometry  # posed mesh (detached) and the working-resolution camera
    cast: FrameCast  # the mesh cast at config.render.supersampling samples per pixel, with its shadow transfer
    photo_srgb: np.ndarray  # [H, W, 3] float32 working-resolution input, sRGB in [0, 1]
    face_classifier: torch.Tensor  # [H, W] h
    light_masks: torch.Tensor  # [K, H, W] M_L of the kept lights
    face_region: torch.Tensor  # [H, W] M_o
    landmarks: np.ndarray  # [P, 2] the detected MediaPipe points, working pixels
    scene_srgb: np.ndarray | None = None  # [Hs, Ws, 3] the whole input frame at the working scale, sRGB;
    # None when the working frame is the whole frame

    @property
    def transfer(self) -> ShadowTransfer | None:
        """The mesh's self-shadowing (None without shadows)."""
        return self.cast.transfer

    @property
    def photo(self) -> torch.Tensor:
        """[H, W, 3] the input, linear RGB."""
        return torch.as_tensor(srgb_to_linear(self.photo_srgb), dtype=torch.float32)


@dataclass(frozen=True)
class FitPose:
    """The fitted shape and pose: what :func:`frozen_geometry` reads."""

    identity: torch.Tensor  # [Ki]
    expression: torch.Tensor  # [T, Ke]
    rotation: torch.Tensor  # [T, 3] axis-angle, model -> camera
    translation: torch.Tensor  # [T, 3] cm
    focal: torch.Tensor  # [] pixels at working resolution

    def camera(self, frame: int, width: int, height: int,
               principal_point: tuple[float, float] | None = None) -> Camera:
        return Camera(self.focal, self.rotation[frame], self.translation[frame], width, height, principal_point)


@dataclass(frozen=True)
class FitAlbedo:
    """Where the albedo model put the person (T^0's source)."""

    coefficients: torch.Tensor  # [Ka] albedo-model coefficients
    tone: float  # ITA degrees on the albedo model's tone axis (its start value when the tone is not free)


@dataclass(frozen=True)
class FitLights:
    """The fitted lights: every initial light's SH (stage-3 values), and those ACE kept."""

    sh: torch.Tensor  # [n, B*B, 3]
    kept: tuple[int, ...]  # indices of the lights ACE kept; only these are rendered

    @property
    def kept_sh(self) -> torch.Tensor:
        """[K, B*B, 3] the lights the fit renders with."""
        return self.sh[list(self.kept)]

    @property
    def bands(self) -> int:
        return int(round(self.sh.shape[1] ** 0.5))


@dataclass(frozen=True)
class FitTexels:
    """What the frames tell about each texel of the maps (deface/fit/texels.py)."""

    initial: Textures | None  # T^0 from the albedo model (None when loaded from files)
    seen: np.ndarray | None  # [Ht, Wt] how squarely some frame saw each texel inside h (None: unknown)
    confidence: np.ndarray | None  # [Ht, Wt] how well the frames constrain each texel (None: unknown)
    views: tuple[TexelView, ...]  # per frame: where each texel lands and how it is seen


@dataclass(frozen=True)
class FitOutput:
    """A finished fit, with its own renders (``renders``). ``render`` re-renders it with other textures, lights
    or a camera."""

    model: FaceModel
    config: FitConfig  # the config the fit ran with
    frames: tuple[OutputFrame, ...]  # T
    pose: FitPose
    albedo: FitAlbedo
    lights: FitLights
    textures: Textures  # the final UV maps
    texels: FitTexels
    illuminant: IlluminantEstimate | None  # the scene's illuminant as recorded (None when not estimated)
    framing: Framing  # where the working frames lie in the input's (crop, scale, principal point)
    kept_frames: list[int] | None  # positions of the fitted frames among the input's (None: all)
    record: RunRecord
    renders: tuple[FrameRender, ...]  # T: the fit's I_R, each frame under its kept lights with M_L and M_o,
    # rendered once when the fit finishes (what the outputs write)
    photo_illuminants: tuple[IlluminantEstimate, ...] = ()  # each photo's own white level, as recorded, in a
    # several-photo fit with ``tone.white_per_photo`` (empty: ``illuminant`` is every frame's)

    def illuminant_record(self) -> dict | None:
        """params.json's ``illuminant``: the first photo's estimate, with every photo's (``per_photo``) when they
        have their own."""
        if self.illuminant is None:
            return None
        per_photo = {"per_photo": [e.record() for e in self.photo_illuminants]} if self.photo_illuminants else {}
        return {**self.illuminant.record(), **per_photo}

    @cached_property
    def renderer(self) -> Renderer:
        """The fit's renderer: its render settings, the lights' bands and the seed."""
        return fit_renderer(self.config)

    def skin_tone(self) -> dict:
        """The diffuse map's ITA and its interval over the white level's spread
        (:func:`~deface.models.ita.texture_tone`; no interval without a white level: a preset without the
        scene-light prior, or a fit saved before it)."""
        illuminant = self.illuminant
        return {**texture_tone(self.textures.diffuse.detach().numpy(), illuminant and illuminant.level_sigma,
                               self.frames[0].photo_srgb),
                "light_level": illuminant and illuminant.source}

    @property
    def num_frames(self) -> int:
        return len(self.frames)

    @property
    def scale(self) -> float:
        """Working pixels per input pixel."""
        return self.framing.scale

    @property
    def size(self) -> tuple[int, int]:
        """(W, H) working resolution."""
        camera = self.frames[0].geometry.camera
        return camera.width, camera.height

    @classmethod
    @torch.no_grad()
    def from_stages(cls, context: StageContext, stage3: Stage3Result, finished: FinishedTextures,
                    record: RunRecord) -> FitOutput:
        """The output of stages 2-3 (``stage3``: :class:`~deface.fit.stage3.Stage3Result`) and of the texture
        completion (``finished``)."""
        scene, target, config = context.scene, context.target, context.config
        frames, renders = [], []
        for frozen in stage3.frozen:
            rendered, _ = render_cast(context, frozen.index, frozen.cast, finished.textures, frozen.face_region)
            renders.append(rendered)
            frames.append(OutputFrame(
                frozen.geometry, frozen.cast, np.asarray(target.frames_srgb[frozen.index], dtype=np.float32),
                context.inputs.face_classifier[frozen.index], rendered.light_masks.detach(),
                rendered.face_region.detach(), np.asarray(target.landmarks[frozen.index].points),
                None if target.scene_srgb is None else np.asarray(target.scene_srgb[frozen.index], np.float32)))
        light = context.inputs.scene_light
        pose = FitPose(*(p.detach().clone() for p in (scene.identity, scene.expression, scene.rotation,
                                                      scene.translation, scene.focal)))
        return cls(
            model=context.model, config=config, frames=tuple(frames), pose=pose,
            albedo=FitAlbedo(scene.albedo.detach().clone(), float(scene.tone.detach())),
            lights=FitLights(scene.lights.detach().clone(), tuple(context.decoupling.kept)),
            textures=finished.textures,
            texels=FitTexels(stage3.initial, finished.seen, finished.confidence, tuple(stage3.views)),
            illuminant=None if light is None else _as_recorded(light.illuminant),
            framing=target.framing, kept_frames=target.kept_frames, record=record, renders=tuple(renders),
            photo_illuminants=() if light is None or len(light.distinct()) < 2 else tuple(
                _as_recorded(light.illuminants[frame]) for frame in light.distinct()))

    def export_vertices(self) -> np.ndarray:
        """[V, 3] cm: a photo's fitted mesh, or a clip's identity with a neutral expression."""
        expression = self.pose.expression
        expression = expression[0] if self.num_frames == 1 else torch.zeros_like(expression[0])
        with torch.no_grad():
            return self.model.vertices(self.pose.identity, expression).numpy()

    @torch.no_grad()
    def render(self, textures: Textures | None = None, lights: torch.Tensor | None = None,
               camera: Camera | Callable | None = None) -> list[FrameRender]:
        """Per-frame renders with the fit's geometry and shadows.

        - ``textures``: UV maps (default: the fit's own);
        - ``lights`` [K', B*B, 3] in the model frame (default: the kept lights with their masks M_L);
        - ``camera``: a working-resolution :class:`Camera` for every frame, or a function
          ``frame -> Camera`` (default: each frame's fitted camera, with M_o).

        With the fit's own lights and cameras this is the fit's I_R. With other lights or cameras the light
        masks (which belong to the fit's pixels) are not used: every light counts fully (M_L = 1), and M_o is
        the coverage when the camera differs.
        """
        textures = textures or self.textures
        own_lights = lights is None
        lights = self.lights.kept_sh if own_lights else lights.to(torch.float32)
        renders = []
        for index, frame in enumerate(self.frames):
            view = camera(index) if callable(camera) else camera
            cast = frame.cast if view is None else cast_frame(self.renderer, frame.geometry.mesh, view, frame.transfer,
                                                              self.config.render.supersampling)
            output = shade_frame(self.renderer, cast, textures, lights)
            if own_lights and view is None:
                masks = frame.light_masks
            else:
                masks = torch.ones(output.images.shape[:3])
            renders.append(FrameRender.of(output, masks, frame.face_region if view is None else output.mask))
        return renders

    def composite(self, rendered: FrameRender, frame: int) -> torch.Tensor:
        """I_out [H, W, 3] linear over the working frame: the face where M_o says so, the input elsewhere."""
        weight = rendered.face_region[..., None]
        return rendered.face * weight + self.frames[frame].photo * (1 - weight)

    def composite_photo(self, rendered: FrameRender, frame: int) -> torch.Tensor:
        """I_out [Hs, Ws, 3] linear over the whole photo at the working scale: :meth:`composite` pasted into
        the frame's scene (what ``render.png`` shows)."""
        working = self.composite(rendered, frame)
        scene = self.frames[frame].scene_srgb
        if scene is None:
            return working
        photo = torch.as_tensor(srgb_to_linear(scene), dtype=torch.float32)
        (left, top), (width, height) = self.framing.scene_offset, self.framing.size
        photo[top:top + height, left:left + width] = working
        return photo


def frozen_geometry(model: FaceModel, pose: FitPose, frame: int, framing: Framing) -> FrameGeometry:
    """A frame's detached geometry from stored parameters (what stage 3 froze), at the working frames of
    ``framing``."""
    topology = topology_tensors(model)
    with torch.no_grad():
        vertices = model.vertices(pose.identity, pose.expression[frame])
    mesh = Mesh(vertices, topology["triangles"], topology["uvs"], topology["triangle_uvs"])
    principal = None if framing.is_whole else framing.principal_point
    return FrameGeometry(mesh, pose.camera(frame, *framing.size, principal))


def _as_recorded(estimate: IlluminantEstimate) -> IlluminantEstimate:
    """``estimate`` as params.json records it (rounded), so a fit and its reload report the same tone interval."""
    return IlluminantEstimate.from_record(estimate.record())
