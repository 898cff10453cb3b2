"""The synthetic cast-shadow check of tests/test_fit_end_to_end.py as a table, for several presets.

    DEFACE_MODELS=../shared/models .venv/bin/python benchmarks/synthetic_shadow.py [--presets default,paper,nextface]

A hat brim casts a ray-traced shadow on the ICT face with a known random albedo (deface.eval.synthetic); prints
per preset the lights ACE kept and the mean |recovered - true| diffuse albedo at the texels seen by shadowed
and by lit pixels, with the test's short schedule (stages 100/120/60, ACE at 40, 128-px textures, 64 rays).
"""

from __future__ import annotations

import argparse
import time

import torch

from deface.eval.synthetic import make_shadowed_face
from deface.fit import presets
from deface.fit.config import override
from deface.fit.log import FitLog
from deface.fit.pipeline import fit_target
from deface.fit.target import FitTarget
from deface.models import load_face_model
from deface.render.mesh import sample_texture

SHORT = {"iterations.stage1": 100, "iterations.stage2": 120, "iterations.stage3": 60,
         "decouple.ace_iteration": 40, "resolution": 96, "texture_size": 128, "render.shadow_rays": 64}


def diffuse_error(face, diffuse: torch.Tensor, region) -> float:
    uv = torch.as_tensor(face.uv[region])
    return float((sample_texture(diffuse.detach(), uv) - sample_texture(face.textures.diffuse, uv)).abs().mean())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--presets", default="default,paper,nextface")
    args = parser.parse_args()
    torch.set_num_threads(1)
    face = make_shadowed_face(load_face_model("ict"), size=96, seed=0, rays=64)
    lit = (face.coverage > 0) & ~face.shadow
    print("| preset | lights kept | diffuse error in shadow | diffuse error lit | wall time |")
    print("|---|---|---|---|---|")
    for name in args.presets.split(","):
        started = time.perf_counter()
        result = fit_target(FitTarget([face.image_srgb], [face.landmarks], 1.0),
                            override(presets.get(name), **SHORT), log=FitLog(quiet=True))
        kept = result.lights.kept
        print(f"| {name} | {len(kept)} | {diffuse_error(face, result.textures.diffuse, face.shadow):.3f} | "
              f"{diffuse_error(face, result.textures.diffuse, lit):.3f} | {time.perf_counter() - started:.1f} s |")


if __name__ == "__main__":
    main()
