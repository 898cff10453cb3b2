"""The registry's ops (deface/render/kernels, with the ops of kernels.OP_MODULES): every registered op's fast
numba path against its torch reference, values and gradients in float64, on 1 and 2 threads; then the whole
render on both paths."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from test_render_gradients import SIZE, Loss

from deface.fit.fast_stage3 import TextureTerms
from deface.losses.texture import PAPER_WEIGHTS
from deface.render import kernels
from deface.render.camera import Camera
from deface.render.frame import render_frame
from deface.render.mesh import Textures
from deface.render.primitives import uv_sphere
from deface.render.renderer import RenderConfig, Renderer, _pixel_rays, vertex_irradiance
from deface.render.sh import cosine_lobe_coefficients
from deface.texture.pyramid import level_gates

pytestmark = pytest.mark.skipif(kernels.numba is None, reason="numba is not installed")
OPS = kernels.load_ops()


def both_paths(fn):
    """fn() under the numba kernels and under the torch reference path."""
    with kernels.backend("numba"):
        fast = fn()
    with kernels.backend("torch"):
        reference = fn()
    return fast, reference


def assert_close(fast, reference, rtol=1e-10, atol=1e-12):
    for a, b in zip(fast, reference, strict=True):
        torch.testing.assert_close(a, b, rtol=rtol, atol=atol)


def values_and_grads(fn, inputs):
    """fn(*inputs) and the gradients of a fixed random projection of it to every input."""
    inputs = [x.detach().clone().requires_grad_() for x in inputs]
    out = fn(*inputs)
    weights = torch.rand(out.shape, generator=torch.Generator().manual_seed(1), dtype=out.dtype)
    grads = torch.autograd.grad((out * weights).sum(), inputs)
    return [out.detach(), *grads]


# -- one case per registered op ---------------------------------------------------------------------
class Case:
    """Arguments of one call of an op; ``grads``: indices of the arguments to differentiate (float64)."""

    def __init__(self, *args, grads=(), rtol=1e-10, atol=1e-12):
        self.args, self.grads, self.rtol, self.atol = list(args), tuple(grads), rtol, atol


def _gen():
    return torch.Generator().manual_seed(0)


def _unit(rows: int, gen) -> torch.Tensor:
    return torch.nn.functional.normalize(torch.randn(rows, 3, generator=gen, dtype=torch.float64), dim=1)


def _interpolate_cases():
    gen = _gen()
    values = torch.randn(40, 6, generator=gen, dtype=torch.float64)
    corners = torch.randint(0, 40, (300, 3), generator=gen)
    return [Case(values, corners, torch.rand(300, 3, generator=gen, dtype=torch.float64), grads=(0, 2))]


def _filtered_interpolation_cases():
    gen = _gen()
    values = torch.randn(40, 4 * 6, generator=gen, dtype=torch.float64)  # U = 40, B = 4, C = 6
    corners = torch.randint(0, 40, (300, 3), generator=gen)
    bary = torch.rand(300, 3, generator=gen, dtype=torch.float64)
    lobe = torch.rand(300, 4, generator=gen, dtype=torch.float64)
    return [Case(values, corners, bary, lobe, grads=(0, 2, 3))]


def _projected_scene():
    """The gradient tests' scene: projected vertices, depths and the covered pixels of its camera."""
    loss = Loss()
    cam = loss.camera(loss.params)
    fragments = loss.renderer.rasterize(loss.mesh, cam)
    pixels, depth = cam.project(loss.mesh.vertices)
    return loss, cam, fragments, pixels.detach(), depth.detach()


def _barycentrics_cases():
    loss, cam, fragments, pixels, depth = _projected_scene()
    covered = (loss.mesh.triangles, fragments.covered_triangles, fragments.covered, (cam.height, cam.width))
    return [Case(pixels, depth, covered, grads=(0, 1))]


def _sh_basis_cases():
    dirs = _unit(300, _gen())
    dirs[0] = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)  # a pole
    return [Case(dirs, bands, bands % 2 == 0, grads=(0,)) for bands in (1, 2, 9, 18)]


def _sh_band_sums_cases():
    gen = _gen()
    return [Case(_unit(300, gen), torch.randn(16, 6, generator=gen, dtype=torch.float64), grads=(0, 1))]


def _sh_irradiance_cases():
    loss = Loss()
    gen = _gen()
    normals = loss.mesh.vertex_normals().detach()
    coeffs = torch.randn(9, 6, generator=gen, dtype=torch.float64)
    lobe = cosine_lobe_coefficients(3).double()
    subset = torch.arange(0, normals.shape[0], 3)
    return [
        Case(normals, coeffs, lobe, None, None, grads=(0, 1)),
        Case(normals, coeffs, lobe, loss.transfer, None, grads=(0, 1)),
        Case(normals[subset], coeffs, lobe, loss.transfer, subset, grads=(0, 1)),
    ]


def _vertex_normals_cases():
    mesh = Loss().mesh
    return [Case(mesh.vertices, mesh.triangles, grads=(0,))]


def _reflect_cases():
    gen = _gen()
    positions = torch.randn(60, 3, generator=gen, dtype=torch.float64)
    centre = torch.tensor([0.2, -0.1, 8.0], dtype=torch.float64)
    return [Case(positions, _unit(60, gen), centre, grads=(0, 1, 2))]


def _sample_texture_cases():
    gen = _gen()
    texture = torch.rand(7, 5, 3, generator=gen, dtype=torch.float64)
    uv = torch.rand(400, 2, generator=gen, dtype=torch.float64) * 1.4 - 0.2  # 30% outside [0, 1]: clamped
    return [Case(texture, uv, grads=(0, 1))]


def _shade_cases():
    """Random per-vertex values and maps on 60 covered pixels of a 9 x 11 image, 2 lights, 4 bands."""
    gen = _gen()
    used, lights, bands, num, size = 30, 2, 4, 60, (9, 11)
    plain = torch.rand(used, 3 * lights + 5, generator=gen, dtype=torch.float64)
    plain[:, 3 * lights : 3 * lights + 3] = torch.randn(used, 3, generator=gen, dtype=torch.float64)  # normals
    bands_v = torch.randn(used, bands, 3 * lights, generator=gen, dtype=torch.float64)
    uvs = torch.rand(20, 2, generator=gen, dtype=torch.float64)
    bary = torch.rand(num, 3, generator=gen, dtype=torch.float64) + 0.1
    bary = bary / bary.sum(1, keepdim=True)
    maps = [torch.rand(6, 5, c, generator=gen, dtype=torch.float64) for c in (3, 3, 1)]
    maps[2] = 0.05 + 0.9 * maps[2]  # roughness inside (1e-3, 1): the clamps pass gradients
    covered = torch.randperm(size[0] * size[1], generator=gen)[:num]
    pixels = (covered, torch.randint(0, used, (num, 3), generator=gen), torch.randint(0, 20, (num, 3), generator=gen))
    return [Case(plain, bands_v, uvs, bary, *maps, pixels, size, grads=(0, 1, 3, 4, 5, 6))]


def _renumber_cases():
    return [Case(torch.randint(0, 50, (40, 3), generator=_gen()), 60)]


def _triangle_box_pixels_cases():
    gen = _gen()
    pixels = torch.rand(30, 2, generator=gen, dtype=torch.float64) * torch.tensor([36.0, 26.0]) - 3.0
    pixels[4, 0] = float("nan")  # a degenerate vertex: its triangles mark nothing
    triangles = torch.randint(0, 30, (12, 3), generator=gen)
    _, cam, _, projected, _ = _projected_scene()
    loss_triangles = Loss().mesh.triangles
    return [Case(pixels, triangles, 20, 30), Case(projected, loss_triangles, cam.height, cam.width)]


def _pixel_directions_cases():
    cam = Camera(torch.tensor(150.0), torch.tensor([3.0, 0.4, -0.2]), torch.tensor([0.5, -1.0, 40.0]), 120, 90)
    rotation = cam.rotation_matrix.numpy().astype(np.float32)
    # float32 rays: the loop and numpy round differently (the length of a unit direction to 1e-6)
    return [Case(np.arange(0, 120 * 90, 7), (90, 120), 150.0, (60.0, 45.0), rotation, rtol=0, atol=1e-6),
            Case(np.arange(0, 120 * 90, 11), (90, 120), 150.0, (-210.5, 300.25), rotation, rtol=0, atol=1e-6)]


def _nearest_triangles_cases():
    """The gradient tests' scene, as seen and turned: no pixel centre on a shared edge, so the z-buffer finds
    exactly Embree's triangles (tests below bound the disagreements where some centre is)."""
    loss = Loss()
    turned = loss.params["rotation"] + torch.tensor([0.2, 0.5, 0.1], dtype=loss.params["rotation"].dtype)
    cases = []
    for params in (loss.params, {**loss.params, "rotation": turned}):
        cam = loss.camera(params).resolved()
        pixels, depth = (t.detach() for t in cam.project(loss.mesh.vertices))

        def trace(flat, cam=cam):
            return loss.renderer.ray_scene(loss.mesh).first_triangles(*_pixel_rays(cam, flat))

        cases.append(Case(pixels, depth, loss.mesh.triangles, cam.height, cam.width, trace))
    return cases


def _block_mean_cases():
    gen = _gen()
    return [Case(torch.rand(2, 4 * factor, 5 * factor, 3, generator=gen, dtype=torch.float64), factor, grads=(0,))
            for factor in (2, 3)]


def _pyramid_map_cases():
    """Odd gates, 4 levels of a 32² map, the clamped first taps at the border."""
    gen = _gen()
    initial = torch.rand(32, 32, 3, dtype=torch.float64, generator=gen)
    density = torch.rand(32, 32, generator=gen).numpy() * 1.5
    gates = [gate.double() for gate in level_gates(density, [32, 16, 8, 4], power=2.0)]
    levels = [torch.randn(3, *gate.shape, dtype=torch.float64, generator=gen) for gate in gates]
    return [Case(initial, gates, *levels, grads=tuple(range(2, 2 + len(levels))))]


def stage3_maps(size: int, seed: int, dtype=torch.float64) -> Textures:
    """Random diffuse, specular and roughness maps (roughness inside (0.05, 1))."""
    gen = torch.Generator().manual_seed(seed)

    def rand(*shape):
        return torch.rand(*shape, generator=gen, dtype=dtype)

    return Textures(rand(size, size, 3), rand(size, size, 3), 0.05 + 0.95 * rand(size, size, 1))


def soft_mask(height: int, width: int, seed: int, dtype=torch.float64) -> torch.Tensor:
    """A soft mask with zeros, ones and fractions, not symmetric in u."""
    values = torch.rand(height, width, generator=torch.Generator().manual_seed(seed), dtype=dtype)
    return torch.where(values < 0.3, torch.zeros_like(values), torch.where(values > 0.7, 1.0, values))


def _texture_terms_cases():
    """Sizes 9 (a middle column that is its own mirror image) and 16, with and without GP, the diffuse
    map's weights relative to a dark map's level (3.7) or not."""
    palette = torch.rand(16, 3, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    cases = []
    for size in (9, 16):
        for colours in (palette, None):
            for relative in (1.0, 3.7):
                map_weights = dict(PAPER_WEIGHTS, diffuse=PAPER_WEIGHTS["diffuse"].relative(relative))
                terms = TextureTerms(stage3_maps(size, 0), soft_mask(size, size, 2), colours, 0.2, 2e3, map_weights)
                current = stage3_maps(size, 1)
                cases.append(Case(current.diffuse, current.specular, current.roughness, terms, grads=(0, 1, 2),
                                  atol=1e-14))
    return cases


def _local_prior_l1_cases():
    cases = []
    for channels in (1, 3):
        gen = torch.Generator().manual_seed(8)
        current = torch.rand(12, 10, channels, generator=gen, dtype=torch.float64)
        reference = torch.rand(12, 10, channels, generator=gen, dtype=torch.float64)
        mask = soft_mask(12, 10, 9)
        mask[0, 0] = 1.0  # a corner pixel: replicate padding on two sides
        cases.append(Case(current, reference, mask, grads=(0,), atol=1e-14))
    return cases


CASES = {
    "interpolate": _interpolate_cases,
    "filtered_interpolation": _filtered_interpolation_cases,
    "barycentrics": _barycentrics_cases,
    "sh_basis": _sh_basis_cases,
    "sh_band_sums": _sh_band_sums_cases,
    "sh_irradiance": _sh_irradiance_cases,
    "vertex_normals": _vertex_normals_cases,
    "reflect": _reflect_cases,
    "sample_texture": _sample_texture_cases,
    "shade": _shade_cases,
    "renumber": _renumber_cases,
    "triangle_box_pixels": _triangle_box_pixels_cases,
    "pixel_directions": _pixel_directions_cases,
    "nearest_triangles": _nearest_triangles_cases,
    "block_mean": _block_mean_cases,
    "pyramid_map": _pyramid_map_cases,
    "texture_terms": _texture_terms_cases,
    "local_prior_l1": _local_prior_l1_cases,
}
"""Every op in kernels.OPS (load_ops) has its cases here: ``test_every_registered_op_has_cases`` fails
otherwise."""


def _outputs(function, case: Case) -> list[torch.Tensor]:
    """The op's outputs (as tensors) and the gradients of a fixed random projection of its floating outputs
    to the arguments ``case.grads``."""
    args = [a.detach().clone().requires_grad_() if i in case.grads else a for i, a in enumerate(case.args)]
    out = function(*args)
    outs = [torch.as_tensor(np.ascontiguousarray(o)) if isinstance(o, np.ndarray) else o for o in
            (out if isinstance(out, tuple | list) else (out,))]
    results = [o.detach() for o in outs]
    if case.grads:
        gen = torch.Generator().manual_seed(1)
        total = sum((o * torch.rand(o.shape, generator=gen, dtype=o.dtype)).sum() for o in outs if o.requires_grad)
        inputs = [args[i] for i in case.grads]
        grads = torch.autograd.grad(total, inputs, allow_unused=True)
        results += [torch.zeros_like(x) if g is None else g for x, g in zip(inputs, grads, strict=True)]
    return results


def test_only_listed_modules_register_ops():
    """An op registered outside the package and OP_MODULES would escape load_ops, and so this test."""
    with pytest.raises(ValueError, match="OP_MODULES"):
        kernels.register("unlisted", reference=abs, fast=abs, supports=lambda x: True)
    assert "unlisted" not in OPS


def test_every_registered_op_has_cases():
    """A new op cannot be registered without a case in CASES (and so without being tested)."""
    missing, stale = sorted(set(OPS) - set(CASES)), sorted(set(CASES) - set(OPS))
    assert not missing, f"ops without a test case in CASES: {missing}"
    assert not stale, f"CASES for ops that are not registered: {stale}"


@pytest.mark.parametrize("name", sorted(OPS))
def test_op_fast_path_matches_reference_on_1_and_2_threads(name):
    """Values and gradients of the fast path equal the reference's (float64 rounding), and are bit-identical
    on 1 and 2 threads."""
    op = OPS[name]
    assert name in CASES, f"op {name!r} has no test case in CASES"
    for case in CASES[name]():
        with kernels.backend("torch"):
            assert not op.use_fast(*case.args)
            reference = _outputs(op, case)
        fast = {}
        try:
            for threads in (1, 2):
                kernels.set_threads(threads)
                with kernels.backend("numba"):
                    assert op.use_fast(*case.args), f"{name}: the fast path does not take this case"
                    fast[threads] = _outputs(op, case)
        finally:
            kernels.set_threads(None)
        assert_close(fast[1], reference, rtol=case.rtol, atol=case.atol)
        for one, two in zip(fast[1], fast[2], strict=True):
            assert torch.equal(one, two), f"{name}: 1 and 2 threads differ"


# -- the whole render on both paths ------------------------------------------------------------------
def test_primary_rays_only_in_triangle_boxes_find_every_hit():
    """Tracing only the pixels inside some triangle's projected box misses no hit (same ids as every pixel)."""
    loss = Loss()
    for params in (loss.params, {**loss.params, "focal": torch.tensor(90.0, dtype=torch.float64)}):
        cam = loss.camera(params)
        with kernels.backend("torch"):  # the Embree path (the numba one is the z-buffer, below)
            ids = loss.renderer.rasterize(loss.mesh, cam).triangle_id.reshape(-1).numpy()
        every = loss.renderer.ray_scene(loss.mesh).first_triangles(*_pixel_rays(cam, np.arange(ids.shape[0])))
        assert np.array_equal(ids, every) and bool((ids >= 0).any())


def _min_barycentric(projected: np.ndarray, triangles: np.ndarray, flat: np.ndarray, ids: np.ndarray,
                     width: int) -> np.ndarray:
    """Smallest screen-space barycentric (float64) of the centres of pixels ``flat`` in triangles ``ids``."""
    ys, xs = np.divmod(flat, width)
    p = np.stack([xs + 0.5, ys + 0.5], -1)
    a, b, c = (projected[triangles[ids, k]] for k in range(3))

    def edge(u, v, q):
        return (v[:, 0] - u[:, 0]) * (q[:, 1] - u[:, 1]) - (v[:, 1] - u[:, 1]) * (q[:, 0] - u[:, 0])

    area = edge(a, b, c)
    return np.minimum(np.minimum(edge(b, c, p) / area, edge(c, a, p) / area), edge(a, b, p) / area)


def _zbuffer_disagreements(renderer: Renderer, mesh, cam: Camera) -> tuple[int, int]:
    """Asserts the z-buffer gives Embree's triangle except where a pixel centre lies on an edge (within
    float32 rounding) of the triangle one of the two picked; returns (covered pixels, disagreements)."""
    with kernels.backend("torch"):
        embree = renderer.rasterize(mesh, cam).triangle_id.reshape(-1).numpy()
    with kernels.backend("numba"):
        zbuffer = renderer.rasterize(mesh, cam).triangle_id.reshape(-1).numpy()
    differ = np.flatnonzero(zbuffer != embree)
    projected = cam.resolved().project(mesh.vertices)[0].detach().double().numpy()
    triangles = mesh.triangles.numpy()
    nearest_edge = np.full(differ.size, np.inf)
    for ids in (embree[differ], zbuffer[differ]):
        hit = ids >= 0
        inside = _min_barycentric(projected, triangles, differ[hit], ids[hit], cam.width)
        assert np.all(inside > -1e-4)  # whichever picked a triangle, the centre is in it (up to rounding)
        nearest_edge[hit] = np.minimum(nearest_edge[hit], np.abs(inside))
    assert np.all(nearest_edge < 1e-4)  # and it lies on the edge of one of them
    return int((embree >= 0).sum()), int(differ.size)


def test_zbuffer_finds_embree_s_triangles_except_on_edges():
    """The z-buffer (numba path of the primary visibility) against Embree's primary rays (its reference)."""
    loss = Loss()
    turned = loss.params["rotation"] + torch.tensor([0.2, 0.5, 0.1], dtype=loss.params["rotation"].dtype)
    for params in (loss.params, {**loss.params, "focal": torch.tensor(90.0, dtype=torch.float64)},
                   {**loss.params, "rotation": turned}):
        covered, differ = _zbuffer_disagreements(loss.renderer, loss.mesh, loss.camera(params))
        assert covered > 100 and differ <= 0.002 * covered


def test_zbuffer_on_the_face_mesh(shared):
    from deface.models import load_face_model
    from deface.render.mesh import Mesh

    model = load_face_model("ict")
    mesh = Mesh(torch.as_tensor(model.mean_shape), torch.as_tensor(model.triangles, dtype=torch.long),
                torch.as_tensor(model.uvs), torch.as_tensor(model.triangle_uvs, dtype=torch.long))
    renderer = Renderer(RenderConfig(shadow_rays=8), bands=3)
    for rotation in ([np.pi, 0.0, 0.0], [np.pi, 0.6, 0.1]):  # frontal, then turned (self-occlusion)
        cam = Camera(torch.tensor(700.0), torch.tensor(rotation), torch.tensor([0.0, 1.0, 60.0]), 256, 256)
        covered, differ = _zbuffer_disagreements(renderer, mesh, cam)
        assert covered > 10_000 and differ <= 0.001 * covered


def test_render_values_and_gradients_match_reference():
    """The whole shading path (fixed visibility and transfer) with every kernel against the torch path."""
    loss = Loss()
    inputs = [loss.mesh.vertices, loss.textures.diffuse, loss.textures.roughness, loss.sh, loss.params["focal"]]

    def run():
        def render(vertices, diffuse, roughness, sh, focal):
            textures = type(loss.textures)(diffuse, loss.textures.specular, roughness)
            return loss(vertices=vertices, textures=textures, sh=sh, params={**loss.params, "focal": focal})

        return values_and_grads(render, inputs)

    assert_close(*both_paths(run))


def test_every_screen_buffer_and_its_gradients_match_reference():
    """The fused pixel kernel writes all RenderOutput buffers; each one's gradients match the torch path."""
    loss = Loss()
    cam = loss.camera(loss.params)
    fragments = loss.renderer.fragments_for(loss.mesh, cam, loss.triangle_id)
    textures = loss.textures
    inputs = [loss.mesh.vertices, textures.diffuse, textures.specular, textures.roughness, loss.sh]
    names = ("images", "uv", "normals", "depth", "diffuse", "specular", "roughness")

    def run():
        def buffers(vertices, diffuse, specular, roughness, sh):
            mesh = type(loss.mesh)(vertices, loss.mesh.triangles, loss.mesh.uvs, loss.mesh.triangle_uvs)
            frags = loss.renderer.fragments_for(mesh, cam, fragments.triangle_id)
            out = loss.renderer.shade(mesh, cam, frags, type(textures)(diffuse, specular, roughness), sh, loss.transfer)
            return torch.cat([getattr(out, name).reshape(-1) for name in names])

        return values_and_grads(buffers, inputs)

    assert_close(*both_paths(run))


def _loss_values_and_grads():
    loss = Loss()
    inputs = [loss.mesh.vertices, loss.textures.diffuse, loss.sh]

    def render(vertices, diffuse, sh):
        textures = type(loss.textures)(diffuse, loss.textures.specular, loss.textures.roughness)
        return loss(vertices=vertices, textures=textures, sh=sh)

    return values_and_grads(render, inputs)


@pytest.fixture
def one_torch_thread():
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)
        kernels.set_threads(None)


def test_kernels_are_deterministic_and_independent_of_the_thread_count(one_torch_thread):
    """The renderer's own kernels (gradients gathered per vertex / per block) on 1 and 2 kernel threads, torch's
    ops on one: bit-identical, and the same again on a second run."""
    kernels.set_threads(1)
    serial, again = _loss_values_and_grads(), _loss_values_and_grads()
    kernels.set_threads(2)
    parallel = _loss_values_and_grads()
    for a, b, c in zip(serial, again, parallel, strict=True):
        assert torch.equal(a, b) and torch.equal(a, c)


def test_more_torch_threads_change_only_the_summation_order(one_torch_thread):
    """torch's reductions split over threads add in another order, so a value moves by rounding only: at most
    n * eps of the largest magnitude for a sum of n float64 terms (n: every pixel, channel and light summed)."""
    serial = _loss_values_and_grads()
    torch.set_num_threads(2)
    parallel = _loss_values_and_grads()
    summed = SIZE * SIZE * 3 * 2  # pixels x channels x lights of the loss's images
    for a, b in zip(serial, parallel, strict=True):
        bound = summed * torch.finfo(torch.float64).eps * float(a.abs().max())
        assert float((a - b).abs().max()) <= bound


def test_renderer_float32_close_to_reference():
    """The production dtype: the fast path stays within float32 rounding of the reference."""
    loss = Loss()
    mesh = type(loss.mesh)(
        loss.mesh.vertices.float(), loss.mesh.triangles, loss.mesh.uvs.float(), loss.mesh.triangle_uvs
    )
    textures = type(loss.textures)(
        *(t.float() for t in (loss.textures.diffuse, loss.textures.specular, loss.textures.roughness))
    )
    camera = loss.camera({k: v.float() for k, v in loss.params.items()})
    renderer = Renderer(RenderConfig(shadows=False), bands=3)

    def run():
        return [render_frame(renderer, mesh, camera, textures, loss.sh.float()).images]

    assert_close(*both_paths(run), rtol=1e-4, atol=1e-5)


def test_vertex_normals_follow_in_place_edits_of_the_triangles():
    """The kernels keep the per-vertex corner lists of the last triangles tensor; after an in-place edit
    that changes which vertices each triangle uses, values and gradients must still match the reference."""
    sphere = uv_sphere(1.0, 8, 16)
    vertices = sphere.vertices.detach().clone()

    def normals_and_grads():
        return values_and_grads(
            lambda v: type(sphere)(v, sphere.triangles, sphere.uvs, sphere.triangle_uvs).vertex_normals(), [vertices]
        )

    normals_and_grads()  # fills the cache for this triangles tensor
    sphere.triangles[:] = torch.roll(sphere.triangles, 1, dims=0).clone()  # other vertices at each slot
    assert_close(*both_paths(normals_and_grads))


def test_shadowed_vertex_irradiance_matches_the_reference_path():
    """The fused irradiance kernel (basis, shadowed transfer, product with the lights) on every vertex,
    values and gradients to vertices and lights, against the torch path."""
    loss = Loss()

    def run():
        def irradiance(vertices, sh):
            mesh = type(loss.mesh)(vertices, loss.mesh.triangles, loss.mesh.uvs, loss.mesh.triangle_uvs)
            return vertex_irradiance(mesh, sh, loss.transfer)

        return values_and_grads(irradiance, [loss.mesh.vertices, loss.sh])

    fast, reference = both_paths(run)
    assert_close(fast, reference)
    assert float(fast[0].abs().max()) > 0 and float(fast[1].abs().max()) > 0
