"""The CPU hot loops as a registry of ops, each a pair of a torch reference and a fast numba path:
``OPS[name] = Op(reference, fast, supports)``; calling an op runs the fast path for CPU tensors when numba is
importable, ``DEFACE_RENDER_KERNELS`` is not ``torch`` and ``supports`` accepts the arguments (dtypes,
shapes), else the reference, which is the code path of a run without the fast paths. Call sites choose
through the op, never by a switch of their own. tests/test_render_kernels.py runs every registered op
against its reference (values and gradients in float64, on 1 and 2 threads) and fails for an op it has no
case for.

One module per op family, each holding its torch reference, its numba kernels, the ``autograd.Function``
around them and the registration (the dispatch rule):

    interpolation.py   interpolate, filtered_interpolation   per-vertex values at the covered pixels
    barycentrics.py    barycentrics                          perspective-correct, from projected corners
    sh_bands.py        sh_basis, sh_band_sums, sh_irradiance real SH rows, per-band sums, shadowed irradiance
    normals.py         vertex_normals                        area-weighted unit vertex normals
    reflection.py      reflect                               mirrored view directions per vertex
    texture.py         sample_texture (+ texel scatter)      bilinear lookup, grid_sample semantics
    shading.py         shade                                 the fused pixel stage (every screen buffer)
    selection.py       renumber, triangle_box_pixels,        used vertices, primary-ray pixels and directions,
                       pixel_directions, nearest_triangles   primary visibility (Embree's rays or a z-buffer)
    base.py            backend switch, threads, serial/parallel compilation, ``Op``, ``register``, ``OPS``

and, outside this package (``OP_MODULES``, imported by ``load_ops``; ``register`` refuses other modules):

    deface/render/fast_box.py       block_mean                  the supersampled buffers' block means
    deface/texture/fast_pyramid.py  pyramid_map                 the texture pyramid's map from its levels
    deface/fit/fast_stage3.py       texture_terms,              stage 3's texture regularisers + GP (and
                                    local_prior_l1              each part's value for the log), its LP

Why: the torch versions spend their time in hundreds of small ops, broadcasts and [N, B*C] temporaries;
one loop per pixel needs neither (figures in benchmarks/render.md).

Determinism: every output element is written by exactly one loop iteration in a fixed order. Gradients
that scatter to vertices are either computed in *gather* form (for each vertex, its entries in a fixed
order, from a counting sort) or, in the shade backward, scattered in pixel order into a fixed number
(shading._SCATTER_PARTS) of per-range buffers summed in order; so results are bit-identical for any
number of threads. The texture-gradient and barycentric-corner scatters run on one thread.

Threads: ``set_threads`` (or DEFACE_RENDER_THREADS) sets the kernels' threads independently of torch's;
by default they follow ``torch.get_num_threads()``.

numba's on-disk cache (``cache=True``) is per source file: after editing an inlined helper that another
module's kernel uses (texture.py's bilinear helpers in shading.py, say), delete ``__pycache__/*.nbi``.
"""

from deface.render.kernels.barycentrics import barycentrics, barycentrics_backward, barycentrics_forward
from deface.render.kernels.base import (
    OP_MODULES,
    OPS,
    Op,
    backend,
    enabled,
    load_ops,
    numba,
    on_reference,
    register,
    set_threads,
    thread_count,
)
from deface.render.kernels.interpolation import (
    filtered_interpolation,
    interpolate,
    interpolate_backward_corners,
    interpolate_backward_values,
    interpolate_forward,
)
from deface.render.kernels.normals import vertex_normals, vertex_normals_backward, vertex_normals_forward
from deface.render.kernels.reflection import reflect, reflect_backward, reflect_forward
from deface.render.kernels.selection import nearest_triangles, pixel_directions, renumber, triangle_box_pixels
from deface.render.kernels.sh_bands import (
    kernel_constants,
    sh_band_sums,
    sh_band_sums_backward,
    sh_band_sums_forward,
    sh_basis,
    sh_basis_backward,
    sh_basis_forward,
    sh_constants,
    sh_irradiance,
    sh_irradiance_backward,
    sh_irradiance_forward,
)
from deface.render.kernels.shading import (
    SCREEN_BUFFERS,
    SCREEN_CHANNELS,
    plain_slices,
    plain_values,
    radiance,
    shade,
    shade_backward,
    shade_forward,
    to_screen,
)
from deface.render.kernels.texture import bilinear_backward, bilinear_forward, sample_texture, sample_textures

__all__ = [
    "OPS",
    "OP_MODULES",
    "SCREEN_BUFFERS",
    "SCREEN_CHANNELS",
    "Op",
    "backend",
    "barycentrics",
    "barycentrics_backward",
    "barycentrics_forward",
    "bilinear_backward",
    "bilinear_forward",
    "enabled",
    "filtered_interpolation",
    "interpolate",
    "interpolate_backward_corners",
    "interpolate_backward_values",
    "interpolate_forward",
    "kernel_constants",
    "load_ops",
    "numba",
    "on_reference",
    "pixel_directions",
    "plain_slices",
    "plain_values",
    "radiance",
    "reflect",
    "reflect_backward",
    "reflect_forward",
    "register",
    "renumber",
    "sample_texture",
    "sample_textures",
    "set_threads",
    "sh_band_sums",
    "sh_band_sums_backward",
    "sh_band_sums_forward",
    "sh_basis",
    "sh_basis_backward",
    "sh_basis_forward",
    "sh_constants",
    "sh_irradiance",
    "sh_irradiance_backward",
    "sh_irradiance_forward",
    "shade",
    "shade_backward",
    "shade_forward",
    "thread_count",
    "to_screen",
    "triangle_box_pixels",
    "nearest_triangles",
    "vertex_normals",
    "vertex_normals_backward",
    "vertex_normals_forward",
]
