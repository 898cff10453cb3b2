"""Time one stage-2 step (render K lights + f + g + losses + backward) of a real photo fit.

    DEFACE_MODELS=../shared/models .venv/bin/python benchmarks/fit_step_bench.py [PHOTO] [--resolution 256]

Prints the median wall and thread-CPU time of a stage-2 step before ACE (all n lights) at the default
preset, with 1 torch thread (the default of `deface fit`).
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

from deface.fit import pipeline, presets
from deface.fit.config import override
from deface.fit.log import FitLog
from deface.fit.stage2 import _stage2_loss
from deface.fit.target import FitTarget
from deface.io.images import load_image
from deface.models import load_face_model
from deface.paths import shared_dir


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    default_photo = shared_dir() / "data/images/real-foliage-shadow-9177-004.png" if shared_dir() else None
    parser.add_argument("photo", nargs="?", default=default_photo)
    parser.add_argument("--resolution", type=int, default=256)
    parser.add_argument("--repeats", type=int, default=10)
    args = parser.parse_args()
    torch.set_num_threads(1)
    config = override(presets.get("default"), resolution=args.resolution)
    log = FitLog(quiet=True)
    work, landmarks, scale, _ = pipeline.detect([load_image(args.photo)], config, str(args.photo), False)
    context = pipeline._stage1(load_face_model("ict"), FitTarget(work, landmarks, scale), config, log)
    pipeline._face_classifier(context, config, None, log)
    _stage2_loss(context, True, True).backward()  # shadow transfer and caches
    walls, cpus = [], []
    for _ in range(args.repeats):
        wall, cpu = time.perf_counter(), time.thread_time()
        _stage2_loss(context, True, False).backward()
        walls.append(time.perf_counter() - wall)
        cpus.append(time.thread_time() - cpu)
    print(f"{args.resolution}² stage-2 step, {config.lights.num_lights} lights: wall median "
          f"{statistics.median(walls) * 1000:.0f} ms, thread CPU median {statistics.median(cpus) * 1000:.0f} ms")


if __name__ == "__main__":
    main()
