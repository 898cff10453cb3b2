"""The maps' gauges after stage 3 (deface/fit/texels.py): the skin's chroma set to the photo's reading
(``skin_chroma_matched``) and each light given one colour (``one_colour_lights``); the lights take the inverse of
what the map takes, so the renders are the same."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import torch
from scipy import ndimage

from deface.fit.texels import one_colour_lights, skin_chroma_matched
from deface.io.images import LUMINANCE
from deface.models.ict import load_ict
from deface.models.uvmap import rasterize_uv
from deface.render.camera import Camera
from deface.render.frame import cast_frame, render_frame, shade_frame
from deface.render.mesh import Mesh, Textures
from deface.render.primitives import grid_plane, uv_sphere
from deface.render.renderer import RenderConfig, Renderer
from deface.render.sh import cosine_lobe_coefficients, radiance, sh_basis
from deface.texture.confidence import texel_view

SIZE = 128


def _maps(rng) -> Textures:
    diffuse = torch.as_tensor(np.array([0.45, 0.33, 0.28]) * (1 + 0.1 * rng.standard_normal((SIZE, SIZE, 1))))
    specular = torch.full((SIZE, SIZE, 3), 0.04, dtype=torch.float64)
    return Textures(diffuse, specular, torch.full((SIZE, SIZE, 1), 0.4, dtype=torch.float64))


def _lights() -> torch.Tensor:
    light = torch.zeros(2, 9, 3, dtype=torch.float64)
    light[0, 0], light[0, 2] = torch.tensor([2.2, 1.9, 1.6]), torch.tensor([0.8, 0.7, 0.5])  # a warm key from the front
    light[1, 0], light[1, 1] = torch.tensor([0.9, 1.0, 1.2]), torch.tensor([0.3, 0.3, 0.4])  # a cool fill from above
    return light


def _render(textures: Textures, light: torch.Tensor) -> torch.Tensor:
    """The plane under one light [1, 9, 3]."""
    camera = Camera(torch.tensor(110.0, dtype=torch.float64), torch.tensor([math.pi, 0.0, 0.0], dtype=torch.float64),
                    torch.tensor([0.0, 0.0, 5.0], dtype=torch.float64), 48, 48)
    renderer = Renderer(RenderConfig(shadows=False, specular=True))
    return render_frame(renderer, grid_plane((-1, 1), (-1, 1), cells=4), camera, textures, light).images


def test_the_skin_takes_the_readings_chroma_and_every_render_is_unchanged(shared):
    textures, lights = _maps(np.random.default_rng(0)), _lights()
    before = [_render(textures, lights[k:k + 1]) for k in range(2)]
    reading = np.array([0.60, 0.34, 0.22])
    seen = np.ones((SIZE, SIZE))
    matched, gain = skin_chroma_matched(load_ict(), textures, seen, reading, lights)
    assert gain is not None and gain[0] > 1 > gain[2]  # the reading is warmer than the map
    skin = np.median(matched.diffuse.numpy().reshape(-1, 3), 0)
    np.testing.assert_allclose(skin / skin[1], reading / reading[1], rtol=0.03)
    torch.testing.assert_close(lights, _lights() / torch.as_tensor(gain))  # divided in place
    for k in range(2):  # each light alone: the diffuse and the specular terms both unchanged
        torch.testing.assert_close(_render(matched, lights[k:k + 1]), before[k], rtol=1e-9, atol=1e-9)


def test_with_no_skin_seen_nothing_changes(shared):
    textures, lights = _maps(np.random.default_rng(1)), _lights()
    matched, gain = skin_chroma_matched(load_ict(), textures, np.zeros((SIZE, SIZE)), np.ones(3), lights)
    assert gain is None and matched is textures
    torch.testing.assert_close(lights, _lights())


# --- Each light one colour, the map the change (``one_colour_lights``) ---------------------------------------------

def _ball():
    """A unit sphere, poles on +-y so the camera on +z sees its equator, the camera, and its texel view at 128²."""
    sphere = uv_sphere(rings=24, segments=48)
    turned = sphere.vertices @ torch.tensor([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]], dtype=torch.float64)
    mesh = Mesh(turned, sphere.triangles, sphere.uvs, sphere.triangle_uvs)
    camera = Camera(torch.tensor(220.0, dtype=torch.float64), torch.tensor([math.pi, 0.0, 0.0], dtype=torch.float64),
                    torch.tensor([0.0, 0.0, 5.0], dtype=torch.float64), 96, 96)
    raster = rasterize_uv(mesh.uvs.numpy(), mesh.triangle_uvs.numpy(), SIZE)
    return mesh, camera, raster, texel_view(raster, mesh, camera)


def _light(colour, ambient: float = 4.0) -> torch.Tensor:
    """[1, 9, 3] a light of one colour: uniform plus a lobe towards the camera (+z), nowhere negative."""
    light = torch.zeros(1, 9, 3, dtype=torch.float64)
    light[0, 0], light[0, 2] = ambient, 1.5
    return light * torch.as_tensor(colour, dtype=torch.float64)


def _tinted_lights() -> torch.Tensor:
    """Two lights [2, 9, 3] whose colours change with direction: redder from above and bluer from below, and
    greener from the left."""
    lights = torch.cat([_light([1.1, 1.0, 0.85]), _light([0.9, 1.0, 1.2], 3.0)])
    lights[0, 1] += torch.tensor([0.5, 0.0, -0.5], dtype=torch.float64)  # Y_1,-1 ∝ y
    lights[1, 3] += torch.tensor([-0.2, 0.2, -0.1], dtype=torch.float64)  # Y_1,1 ∝ x
    assert bool((radiance(lights) > 0).all())  # the renderer's clamp leaves them as they are
    return lights


def _irradiance(normals: np.ndarray, light: torch.Tensor) -> np.ndarray:
    """[..., 3] the analytic irradiance E(n) = sum_lm A_l c_lm Y_lm(n) of one light [9, 3]."""
    basis = sh_basis(torch.as_tensor(normals), 3)  # [..., 9]
    lobe = cosine_lobe_coefficients(3).to(basis)[[0, 1, 1, 1, 2, 2, 2, 2, 2]]
    return ((basis * lobe) @ light.to(basis)).numpy()


def _stand_in(masks: torch.Tensor, region: torch.Tensor) -> SimpleNamespace:
    return SimpleNamespace(light_masks=masks, face_region=region)


def test_a_lights_colour_that_changes_with_direction_leaves_the_map():
    """A uniform skin seen under a light whose colour turns with direction, fitted with the map taking the turn
    (the analytic irradiance, independent of the renderer): after the gauge the map's chroma is even again."""
    mesh, camera, raster, view = _ball()
    true_light = _light([1.1, 1.0, 0.85])[0]
    fitted = _tinted_lights()[:1]
    normals = raster.interpolate_vertices(mesh.vertices.numpy(), mesh.triangles.numpy(), fill=True)
    normals /= np.maximum(np.linalg.norm(normals, axis=-1, keepdims=True), 1e-12)
    skin = np.array([0.55, 0.38, 0.30])
    compensated = skin * _irradiance(normals, true_light) / _irradiance(normals, fitted[0])
    textures = Textures(torch.as_tensor(compensated), torch.zeros(SIZE, SIZE, 3, dtype=torch.float64),
                        torch.full((SIZE, SIZE, 1), 0.4, dtype=torch.float64))
    renderer = Renderer(RenderConfig(shadows=False, specular=False))
    cast = cast_frame(renderer, mesh, camera, None)
    coverage = shade_frame(renderer, cast, textures, fitted).mask
    out, lights = one_colour_lights(renderer, [cast], [view], [_stand_in(coverage[None], coverage)], textures, fitted)
    seen = view.seen() > 0.3
    spread = lambda maps: np.log(maps[seen] / skin).std(0).max()  # noqa: E731
    assert spread(compensated) > 0.05
    assert spread(out.diffuse.numpy()) < 0.15 * spread(compensated)  # what is left: the renderer's per-vertex E
    colours = radiance(lights)[0]
    np.testing.assert_allclose((colours / colours[:, 1:2]).std(0), 0.0, atol=1e-9)  # one colour in every direction


def test_every_frames_render_is_unchanged_and_the_lights_luminance_kept():
    """Two lights under soft masks: the frame's composed diffuse render with the new map and lights equals the
    old one (up to the texels' bilinear sampling), and each light's luminance SH is the one it had."""
    mesh, camera, raster, view = _ball()
    rng = np.random.default_rng(3)
    textures = _maps(rng)
    textures = Textures(textures.diffuse * torch.as_tensor(np.exp(0.03 * rng.standard_normal((SIZE, SIZE, 3)))),
                        textures.specular, textures.roughness)
    lights = _tinted_lights()
    renderer = Renderer(RenderConfig(shadows=False, specular=False))
    cast = cast_frame(renderer, mesh, camera, None)
    before = shade_frame(renderer, cast, textures, lights)
    side = torch.sigmoid(torch.linspace(-6, 6, 96, dtype=torch.float64))[None, :].expand(96, 96)
    masks = torch.stack([side, 1 - side]) * before.mask
    out, new_lights = one_colour_lights(renderer, [cast], [view], [_stand_in(masks, before.mask)], textures, lights)
    after = shade_frame(renderer, cast, out, new_lights)
    composed = [(masks[..., None] * render.images).sum(0) for render in (before, after)]
    inside = torch.as_tensor(ndimage.binary_erosion(before.mask.numpy() > 0.999, iterations=3))
    error = (composed[1][inside] / composed[0][inside] - 1).abs()
    assert float(error.median()) < 0.005 and float(error.max()) < 0.03
    luminance = torch.as_tensor(LUMINANCE, dtype=torch.float64)
    torch.testing.assert_close(new_lights @ luminance, lights @ luminance)
