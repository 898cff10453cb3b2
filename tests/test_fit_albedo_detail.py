"""The person's dark albedo stays in the albedo, and only shadows go into the lights (issue 38): short fits of
synthetic faces rendered with the project's renderer, whose albedo carries a textured dark patch on the chin (a
goatee: dark strokes over half its texels) and is known exactly.

- under one light, the map keeps most of the patch's darkness, and the preset for photos without cast shadows
  more of it;
- with a brim's cast shadow over the forehead as well, more than a third of it stays in the map and the shadow goes
  into a dark light's mask, not into the forehead's albedo;
- under two lights of different colours split by a sharp edge, the map has no colour step at the edge;
- in three photos of one person, the third with the brim's shadow, the goatee stays and the shadow stays out.

Scored with the albedo benchmark's measures (deface/eval/albedo_measures.py) over the texels the camera sees.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from deface.eval import albedo_measures as measures
from deface.eval.synthetic import _brim_transfer, directional_sh, true_landmarks
from deface.fit import presets
from deface.fit.config import override
from deface.fit.log import FitLog
from deface.fit.pipeline import run_stages
from deface.fit.target import FitTarget
from deface.io.images import linear_to_srgb
from deface.models import load_face_model
from deface.models.uvmap import rasterize_uv
from deface.render.camera import Camera
from deface.render.mesh import Mesh, Textures
from deface.render.renderer import RenderConfig, Renderer
from deface.texture.confidence import texel_view

SIZE = 160
SHORT = {"iterations.stage1": 100, "iterations.stage2": 150, "iterations.stage3": 60,
         "decouple.ace_iteration": 50, "resolution": SIZE, "texture_size": 256, "render.shadow_rays": 48}
SKIN = np.array([0.50, 0.33, 0.24])
GOATEE = (slice(166, 192), slice(108, 148))  # rows, columns of the 256² UV layout: the chin below the lower lip
FOREHEAD = (slice(30, 60), slice(95, 161))


def albedo(patch: bool = True) -> np.ndarray:
    """[256, 256, 3] linear: the model's mean pattern scaled to SKIN, with the goatee's strokes."""
    model = load_face_model("ict")
    mean = torch.nn.functional.interpolate(torch.as_tensor(np.asarray(model.albedo.diffuse_mean)).permute(2, 0, 1)
                                           [None], size=(256, 256), mode="bilinear")[0].permute(1, 2, 0).numpy()
    skin = mean / mean[128, 40] * SKIN
    if patch:
        strokes = np.random.default_rng(0).random((26, 40)) < 0.5
        skin[GOATEE] *= np.where(strokes, 0.12, 0.9)[..., None]
    return skin.astype(np.float32)


def render(albedo_map: np.ndarray, brim: bool = False, split_colours: bool = False,
           direction: tuple[float, float, float] = (0.0, 0.45, 0.9)):
    """sRGB photo and exact landmarks of the mean face with ``albedo_map``; one light from ``direction`` (the
    front and above; with ``brim`` a hat brim shadows the forehead; with ``split_colours`` the face's left half is
    lit by a warm and its right half by a cool version of the light, switching at a sharp vertical edge)."""
    model = load_face_model("ict")
    renderer = Renderer(RenderConfig(shadow_rays=48))
    face = Mesh.create(model.mean_shape, model.triangles, model.uvs, model.triangle_uvs)
    camera = Camera.frontal(SIZE, SIZE, distance=60.0, fov_degrees=34.0)
    textures = Textures(torch.as_tensor(albedo_map), torch.full((256, 256, 3), 0.04), torch.full((256, 256, 1), 0.45))
    light = directional_sh(direction, strength=1.6, ambient=0.45)
    fragments = renderer.rasterize(face, camera)
    transfer = _brim_transfer(renderer, face) if brim else renderer.shadow_transfer(face)
    with torch.no_grad():
        image = renderer.shade(face, camera, fragments, textures, light, transfer).images[0].numpy()
        if split_colours:
            warm = renderer.shade(face, camera, fragments, textures, light * torch.tensor([1.15, 1.0, 0.8]),
                                  transfer).images[0].numpy()
            cool = renderer.shade(face, camera, fragments, textures, light * torch.tensor([0.85, 1.0, 1.2]),
                                  transfer).images[0].numpy()
            image = np.where((np.arange(SIZE) < SIZE // 2)[None, :, None], warm, cool)
    coverage = fragments.mask.numpy()[..., None]
    photo = image * coverage + np.array([0.2, 0.2, 0.2]) * (1 - coverage)
    return linear_to_srgb(np.clip(photo, 0, 1)), true_landmarks(model, face, camera), face, camera


def shown_texels(face, camera) -> np.ndarray:
    """[256, 256] bool: the texels ``camera`` sees facing it within about 66 degrees."""
    model = load_face_model("ict")
    view = texel_view(rasterize_uv(model.uvs, model.triangle_uvs, 256), face, camera)
    return view.visible & (view.facing > 0.4)


def fit(albedo_map: np.ndarray, preset: str = "default", **scene):
    photo, landmarks, face, camera = render(albedo_map, **scene)
    state = run_stages(FitTarget([photo], [landmarks], 1.0), override(presets.get(preset), **SHORT),
                       log=FitLog(quiet=True))
    return state, shown_texels(face, camera)


def kept(state, shown: np.ndarray, truth: np.ndarray) -> float:
    fitted = state.finished.textures.diffuse.numpy().astype(np.float64)
    region, reference = np.zeros_like(shown), np.zeros_like(shown)
    region[GOATEE], reference[FOREHEAD] = True, True
    matched = measures.gain_matched(fitted, truth, reference & shown)
    return measures.darkness_kept(matched, truth, region & shown, reference & shown)


@pytest.fixture(scope="module")
def one_light_default_kept(shared) -> float:
    """The default's darkness kept of the goatee under one light (one fit for the tests that read it)."""
    truth = albedo()
    return kept(*fit(truth), truth.astype(np.float64))


@pytest.mark.slow
def test_a_goatee_under_one_light_stays_in_the_albedo(one_light_default_kept):
    # 0.58 with the shading evidence in the hair zone (the default since 2026-11-28), 0.60 with it over the whole
    # face; detail-synth's truth renders keep more with the zone (beard 0.41 against 0.36, BENCHMARKS.md).
    assert one_light_default_kept > 0.55


@pytest.mark.slow
def test_the_no_cast_shadows_preset_keeps_more_of_a_goatee_under_one_light(one_light_default_kept):
    # Its lights fit fewer of the finely textured pixels (stage 2's shading evidence at 0.4, over the whole face),
    # so less of the goatee's darkness is explained as light (0.67 against the default's 0.58 here; report split
    # 1's unshadowed renders 0.97 against 0.43, docs/textures.md "Photos without cast shadows").
    truth = albedo()
    preset = kept(*fit(truth, preset="no-cast-shadows"), truth.astype(np.float64))
    assert preset > one_light_default_kept + 0.03


@pytest.mark.slow
def test_a_goatee_stays_and_a_brim_shadow_goes_into_a_light(shared):
    truth = albedo()
    state, shown = fit(truth, brim=True)
    # The brim's light takes part of the goatee's darkness too (docs/textures.md "The person's detail": the
    # benchmark's brim renders keep 0.14-0.38); main before issue 38 kept none (about 0 or below).
    assert kept(state, shown, truth.astype(np.float64)) > 0.35
    fitted = state.finished.textures.diffuse.numpy()
    cheek = (slice(120, 150), slice(40, 80))
    ratio = (fitted[FOREHEAD].mean() / fitted[cheek].mean()) / (truth[FOREHEAD].mean() / truth[cheek].mean())
    assert ratio > 0.8, "the brim's shadow went into the forehead's albedo"
    assert len(state.context.decoupling.kept) >= 2, "no light took the shadow"


@pytest.mark.slow
def test_two_coloured_lights_split_by_a_sharp_edge_leave_no_colour_step(shared):
    truth = albedo(patch=False)
    state, shown = fit(truth, split_colours=True)
    fitted = state.finished.textures.diffuse.numpy()
    rows = slice(60, 200)
    left, right = fitted[rows, 110:124], fitted[rows, 132:146]  # either side of the face's midline (u = 0.5)
    chroma = lambda x: np.log(x.mean((0, 1)) / x.mean())  # noqa: E731
    true_step = chroma(truth[rows, 132:146]) - chroma(truth[rows, 110:124])
    step = chroma(right) - chroma(left) - true_step
    assert np.abs(step).max() < 0.05, f"colour step across the lights' edge: {step}"


@pytest.mark.slow
def test_three_photos_keep_the_goatee_and_leave_one_photos_brim_shadow_out(shared):
    """Several photos of one person (issue 59): a goatee in all three, lit from the left, the right and the front,
    a brim's shadow over the forehead in the third. Fitted as one person (each photo its own lights), the goatee
    stays in the map and the shadow does not enter it. Measured: goatee kept 0.77, forehead over cheek 1.01 against
    the truth's; each photo alone 0.96 / 0.65 / 0.50 (the brim's) and 1.08 / 1.01 / 0.97: more than the shadowed
    photo and the photos' mean keep, less than the best photo alone."""
    truth = albedo()
    shots = [render(truth, direction=(-0.35, 0.45, 0.85)), render(truth, direction=(0.35, 0.45, 0.85)),
             render(truth, brim=True)]
    target = FitTarget([shot[0] for shot in shots], [shot[1] for shot in shots], 1.0, light_groups=(0, 1, 2))
    state = run_stages(target, override(presets.get("default"), **SHORT), log=FitLog(quiet=True))
    shown = shown_texels(*shots[2][2:])
    goatee = kept(state, shown, truth.astype(np.float64))
    fitted = state.finished.textures.diffuse.numpy()
    cheek = (slice(120, 150), slice(40, 80))
    ratio = (fitted[FOREHEAD].mean() / fitted[cheek].mean()) / (truth[FOREHEAD].mean() / truth[cheek].mean())
    assert goatee > 0.6
    assert ratio > 0.95, "the brim's shadow went into the forehead's albedo"
