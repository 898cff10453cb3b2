"""Time one stage-2 or stage-3 step (render K lights + f (+ g) + losses + backward) of a real photo fit.

    DEFACE_MODELS=../shared/models .venv/bin/python benchmarks/fit_step_bench.py [PHOTO] [--resolution 256]
        [--stage 2|3] [--supersampling S] [--threads 1] [--reference-terms]

Prints the median wall and thread-CPU time of a step at the default preset with 1 torch thread (the
default of `deface fit`; --threads as `deface fit --threads`): stage 2 before ACE (all n lights); stage 3
with all n lights kept (an upper bound: ACE usually keeps fewer) at `--supersampling` samples per pixel side;
`--reference-terms`: stage 3 with the torch references of the fused terms (deface/fit/fast_stage3.py).
"""

from __future__ import annotations

import argparse
import statistics
import time
from contextlib import nullcontext

import torch

from deface.fit import pipeline, presets, stage2, stage3
from deface.fit.config import override
from deface.fit.log import FitLog
from deface.fit.texels import frame_views
from deface.io.images import load_image
from deface.paths import shared_dir
from deface.render import kernels


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    default_photo = shared_dir() / "data/images/real-foliage-shadow-9177-004.png" if shared_dir() else None
    parser.add_argument("photo", nargs="?", default=default_photo)
    parser.add_argument("--resolution", type=int, default=256)
    parser.add_argument("--repeats", type=int, default=10)
    parser.add_argument("--stage", type=int, choices=(2, 3), default=2)
    parser.add_argument("--supersampling", type=int, default=None, help="stage 3 (default: the preset's)")
    parser.add_argument("--threads", type=int, default=1, help="torch threads (as `deface fit --threads`)")
    parser.add_argument("--reference-terms", action="store_true",
                        help="stage 3: torch reference terms instead of the fused kernels")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    config = override(presets.get("default"), resolution=args.resolution)
    if args.supersampling:
        config = override(config, **{"render.supersampling": args.supersampling})
    log = FitLog(quiet=True)
    target = pipeline.detect_target([load_image(args.photo)], config, str(args.photo), False)
    context, _ = pipeline.prepare(target, config, log=log)
    stage2.objective(context, True, True).backward()  # shadow transfer and caches
    step = _stage2_step(context) if args.stage == 2 else _stage3_step(context, args.reference_terms)
    walls, cpus = [], []
    for _ in range(args.repeats):
        wall, cpu = time.perf_counter(), time.thread_time()
        step()
        walls.append(time.perf_counter() - wall)
        cpus.append(time.thread_time() - cpu)
    samples = config.render.supersampling
    detail = f", {samples}x{samples} samples per pixel" if args.stage == 3 else ""
    print(f"{args.resolution}² stage-{args.stage} step, {config.lights.num_lights} lights{detail}: wall median "
          f"{statistics.median(walls) * 1000:.0f} ms, thread CPU median {statistics.median(cpus) * 1000:.0f} ms")


def _stage2_step(context):
    return lambda: stage2.objective(context, True, False).backward()


def _stage3_step(context, reference_terms: bool = False):
    initial = stage3.initial_textures(context)
    frozen = stage3.freeze_frames(context, initial)
    views = frame_views(context.model, frozen, initial.diffuse.shape[0])
    parameters = stage3.TextureParameters(initial, stage3.texture_gates(context, views, initial.diffuse.shape[0]))

    def switch():  # the ops choose their path per call
        return kernels.on_reference("texture_terms", "local_prior_l1") if reference_terms else nullcontext()

    with switch():
        loss_of = stage3.objective(context, frozen, initial)

    def step():
        with switch():
            loss_of(parameters.textures()).backward()

    return step


if __name__ == "__main__":
    main()
