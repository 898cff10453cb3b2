"""Renderer benchmark on the ICT-FaceKit face mesh (9,409 vertices, 18,460 triangles).

Prints forward / backward times at 256² and 512² with 5 SH lights (B = 9, 512² textures, gradients to
textures, SH and vertices), the time of one shadow-transfer refresh, the primary ray-cast time and the
peak memory. Usage:

    DEFACE_MODELS=../shared/models .venv/bin/python benchmarks/render_bench.py [--repeats 20] [--threads 1]
        [--kernels numba|torch] [--kernel-threads 2]

The machine is shared: the script reports the median and the minimum over repeats, and the load average;
for the 256² step also the CPU time of the calling thread (stable under load with --threads 1; numba's
and Embree's worker threads are not in it). ``--kernels torch`` measures the torch reference path.
``--threads 2`` runs torch and the kernels on both cores of the 2-core target machine (the 50 ms figure in
benchmarks/render.md); ``--threads 1`` is one core.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import time

import torch

from deface.models.ict import load_ict
from deface.render import kernels
from deface.render.camera import Camera
from deface.render.frame import render_frame
from deface.render.mesh import Mesh, Textures
from deface.render.renderer import RenderConfig, Renderer


def timed(fn, repeats: int, clock=time.perf_counter) -> tuple[float, float]:
    """(median, min) ms of fn() over repeats on ``clock`` (wall clock by default), after two warm-up calls."""
    for _ in range(2):
        fn()
    samples = []
    for _ in range(repeats):
        start = clock()
        fn()
        samples.append(1000 * (clock() - start))
    return statistics.median(samples), min(samples)


def scene(resolution: int):
    model = load_ict()
    vertices = torch.tensor(model.mean_shape, requires_grad=True)
    mesh = Mesh.create(vertices, model.triangles, model.uvs, model.triangle_uvs)
    # Framing like a portrait fit: the face fills most of the image height.
    camera = Camera.frontal(resolution, resolution, distance=60.0, fov_degrees=28.0)
    gen = torch.Generator().manual_seed(0)
    textures = Textures(
        diffuse=(0.3 + 0.4 * torch.rand(512, 512, 3, generator=gen)).requires_grad_(),
        specular=(0.05 * torch.rand(512, 512, 3, generator=gen)).requires_grad_(),
        roughness=(0.2 + 0.4 * torch.rand(512, 512, 1, generator=gen)).requires_grad_(),
    )
    sh = 0.3 * torch.randn(5, 81, 3, generator=gen)
    sh[:, 0] += 2.0
    return mesh, camera, textures, sh.requires_grad_()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--threads", type=int, default=0, help="torch threads (0: torch's default)")
    parser.add_argument("--kernels", choices=["numba", "torch"], default="numba", help="renderer kernels")
    parser.add_argument(
        "--kernel-threads", type=int, default=0, help="threads of the numba kernels (0: as many as torch)"
    )
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)  # on a busy shared machine 1 thread is far more stable
    kernels.set_threads(args.kernel_threads or None)
    with kernels.backend(args.kernels):
        run(args)


def run(args) -> None:
    print(
        f"torch {torch.__version__}, threads {torch.get_num_threads()}, kernels {args.kernels} "
        f"({args.kernel_threads or torch.get_num_threads()} threads) "
        f"(numba {'present' if kernels.numba is not None else 'missing'}), load average {os.getloadavg()}"
    )

    renderer = Renderer(RenderConfig(supersampling=1))  # one sample per pixel: the cost per rendered pixel
    mesh, _, _, _ = scene(256)
    median, best = timed(lambda: renderer.shadow_transfer(mesh), max(3, args.repeats // 5))
    print(
        f"shadow transfer refresh (V={mesh.num_vertices}, S={renderer.config.shadow_rays}): "
        f"median {median:.0f} ms, min {best:.0f} ms"
    )
    transfer = renderer.shadow_transfer(mesh)

    for resolution in (256, 512):
        mesh, camera, textures, sh = scene(resolution)
        fragments = renderer.rasterize(mesh, camera)
        covered = int(fragments.covered.numel())
        raster = timed(lambda: renderer.rasterize(mesh, camera), args.repeats)  # noqa: B023
        forward = timed(lambda: render_frame(renderer, mesh, camera, textures, sh, transfer), args.repeats)  # noqa: B023

        leaves = (mesh.vertices, textures.diffuse, textures.specular, textures.roughness, sh)

        def step():
            for leaf in leaves:  # noqa: B023 - as a fit's optimizer.zero_grad(): fresh gradients, no accumulation
                leaf.grad = None
            out = render_frame(renderer, mesh, camera, textures, sh, transfer)  # noqa: B023
            out.images.sum().backward()

        both = timed(step, args.repeats)
        print(
            f"{resolution}x{resolution}, 5 lights, {covered} covered pixels: "
            f"rasterize {raster[0]:.1f} ms (min {raster[1]:.1f}); forward {forward[0]:.1f} ms "
            f"(min {forward[1]:.1f}); forward+backward {both[0]:.1f} ms (min {both[1]:.1f})"
        )
        if resolution == 256:
            cpu = timed(step, args.repeats, clock=time.thread_time)
            print(f"    forward+backward CPU time of the calling thread {cpu[0]:.1f} ms (min {cpu[1]:.1f})")
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak resident memory {peak_mb:.0f} MB (ru_maxrss, whole process incl. torch)")


if __name__ == "__main__":
    main()
