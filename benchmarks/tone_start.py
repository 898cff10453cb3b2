"""The skin tone a fit starts from (before stage 2), without fitting: the part of the skin-tone figures that the
scene's white level and the key-lit skin decide (stage 2 keeps the start in the default preset).

    DEFACE_MODELS=../shared/models .venv/bin/python benchmarks/tone_start.py synth [--resolution 256] [--known-white]
    DEFACE_MODELS=../shared/models .venv/bin/python benchmarks/tone_start.py pairs PAIRS_DIR [--resolution 128]
    DEFACE_MODELS=../shared/models .venv/bin/python benchmarks/tone_start.py photos

``synth``: the renders of known albedo (../shared/data/skin-tone-synth), start ITA against ``gt_ita``, errors per
light; ``pairs``: the pairs of ``deface bench make-shadows``, start ITA of the shadowed source against the clean
target (the same person: the gap is what the shadow does to the start); ``photos``: the starts of
../shared/data/skin-tone. ``--known-white`` gives each render its light's white level (``RENDER_WHITE`` in the
light's Planckian colour, as ``tone.illuminant.white``), so what remains is the reading of the skin, not W.
Two processes, one thread each; about 10 s a set. The fits' own figures come from
``deface bench skin-tone`` and ``deface bench run`` (the start is where stage 2 begins, not the fitted tone).
"""

from __future__ import annotations

import argparse
import csv
import statistics
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from deface.paths import shared_dir

RENDER_WHITE = {"4500": 1.30, "2700": 1.69, "6500": 1.04}
"""Luminance of W for the renders' three lights (kelvin), as measured for BENCHMARKS.md ("Skin tone": their grey
world says 1.39 / 1.80 / 0.92). Blender's light strengths were not set by a camera's exposure, so W = 1 is not
theirs."""


def render_white(kelvin: str) -> str:
    """``tone.illuminant.white=...`` for a render under the light at ``kelvin``."""
    from deface.priors.illuminant import planckian_rgb

    white = RENDER_WHITE[kelvin] * planckian_rgb(float(kelvin))
    return "tone.illuminant.white=" + ",".join(f"{v:.4f}" for v in white)


def start_ita(path: str, resolution: int, preset: str, settings: tuple[str, ...] = ()) -> float:
    import torch

    from deface.fit import pipeline, presets
    from deface.fit.config import override, set_from_text
    from deface.fit.log import FitLog
    from deface.io.images import load_image

    torch.set_num_threads(1)
    config = override(presets.get(preset), resolution=resolution)
    for assignment in settings:
        config = set_from_text(config, assignment)
    target = pipeline.detect_target([load_image(path)], config, path, False)
    context, _ = pipeline.prepare(target, config, log=FitLog(quiet=True))
    return float(context.scene.tone.detach())


def manifest(name: str) -> tuple[Path, list[dict]]:
    """A shared dataset's folder and its MANIFEST.tsv rows."""
    root = shared_dir() / "data" / name
    return root, list(csv.DictReader(open(root / "MANIFEST.tsv"), delimiter="\t"))


def starts_of(pool, paths: list[str], resolution: int, args, extra: list[tuple[str, ...]] | None = None) -> list[float]:
    """The start ITA of every photo, two at a time (``extra``: more settings per photo)."""
    count = len(paths)
    settings = [tuple(args.settings) + (extra[i] if extra else ()) for i in range(count)]
    return list(pool.map(start_ita, paths, [resolution] * count, [args.preset] * count, settings))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("set", choices=("synth", "pairs", "photos"))
    parser.add_argument("pairs_dir", nargs="?")
    parser.add_argument("--resolution", type=int)
    parser.add_argument("--preset", default="default")
    parser.add_argument("--known-white", action="store_true", help="synth: each render's true white level")
    parser.add_argument("--set", dest="settings", action="append", default=[], help="PATH=VALUE (deface fit --set)")
    args = parser.parse_args()
    with ProcessPoolExecutor(2) as pool:
        if args.set == "synth":
            root, rows = manifest("skin-tone-synth")
            known = [(render_white(r["kelvin"]),) for r in rows] if args.known_white else None
            starts = starts_of(pool, [str(root / "images" / r["file"]) for r in rows], args.resolution or 256, args,
                               known)
            errors: dict[str, list[float]] = {}
            for row, start in zip(rows, starts, strict=True):
                error = start - float(row["gt_ita"])
                errors.setdefault(row["kelvin"] + ("brim" if row["shadow"] == "1" else ""), []).append(error)
                print(f"{row['file']:24s} truth {float(row['gt_ita']):6.1f} start {start:6.1f} error {error:+6.1f}")
            every = [e for group in errors.values() for e in group]
            for light, group in errors.items():
                print(f"{light:9s} mean {statistics.mean(group):+5.1f}  MAE {statistics.mean(map(abs, group)):4.1f}")
            print(f"all       MAE {statistics.mean(map(abs, every)):4.1f}  max {max(map(abs, every)):4.1f}")
        elif args.set == "photos":
            root, rows = manifest("skin-tone")
            starts = starts_of(pool, [str(root / "images" / r["file"]) for r in rows], args.resolution or 256, args)
            for row, start in zip(rows, starts, strict=True):
                print(f"{row['file']:40s} {row['tone_group']:7s} start {start:6.1f}")
        else:
            pairs = sorted(p for p in Path(args.pairs_dir).iterdir() if (p / "source.png").exists())
            paths = [str(p / name) for p in pairs for name in ("source.png", "target.png")]
            starts = starts_of(pool, paths, args.resolution or 128, args)
            gaps = []
            for index, pair in enumerate(pairs):
                source, target = starts[2 * index], starts[2 * index + 1]
                gaps.append(abs(source - target))
                print(f"{pair.name:22s} source {source:6.1f} target {target:6.1f} gap {gaps[-1]:5.1f}")
            print(f"mean gap {statistics.mean(gaps):.2f} over {len(gaps)} pairs; "
                  f"first 8 {statistics.mean(gaps[:8]):.2f}")


if __name__ == "__main__":
    main()
