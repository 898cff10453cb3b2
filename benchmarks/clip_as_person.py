"""A clip whose light changes between frames, fitted as a clip (one crop, the frames sharing their lights and white
level: the paper's video mode) and as several photos of one person (``deface fit --person NAME clip.mp4``: each
frame its own crop, lights and white level), both scored against the truth.

    .venv/bin/python benchmarks/clip_as_person.py FOLDER OUT SET[,SET...] [PATH=VALUE ...]
    .venv/bin/python benchmarks/clip_as_person.py --sheet SHEET.jpg FOLDER:OUT:SET [FOLDER:OUT:SET ...]

FOLDER is a truth folder of person sets (``benchmarks/blender/person_scenes.py``): each set's renders (the head
turning, a light and a cast shadow of its own per photo) are written as the frames of one clip (OUT/<set>.mp4, H.264
at quality 9), decoded back, and fitted both ways at the default preset (PATH=VALUE: config changes, as ``deface fit
--set``). Each way is scored over the texels any of its frames shows (deface/eval/person_benchmark.py), and OUT/<set>/
<way>/record.json keeps the scores and diffuse.npy the map; a way already recorded is not fitted again. ``--sheet``
puts each set's truth, clip map and person map side by side, one row per set.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

from deface.eval import albedo_measures as measures
from deface.eval.albedo_benchmark import score_fit, shown_texels
from deface.eval.person_benchmark import read_truth_sets, truth_inputs
from deface.fit import presets
from deface.fit.config import set_from_text
from deface.fit.log import FitLog
from deface.fit.pipeline import fit, fit_photos
from deface.io.images import LOAD_MAX_SIDE, load_image
from deface.io.video import read_spread_frames

COLUMNS = (("PSNR", ("face", "psnr")), ("CE", ("face", "colour_error")), ("noise", ("face", "colour_noise")),
           ("beard", ("beard", "darkness_kept")), ("birthmark", ("birthmark", "darkness_kept")))


def write_clip(paths: list[Path], clip: Path) -> None:
    import imageio.v2 as imageio

    with imageio.get_writer(str(clip), fps=2, quality=9, macro_block_size=1) as writer:
        for path in paths:
            writer.append_data((np.clip(load_image(path), 0, 1) * 255).round().astype(np.uint8))


def fit_way(way: str, frames: list[np.ndarray], clip: Path, config):
    """The fit of ``frames`` as a clip or as a person's photos."""
    if way == "clip":
        return fit(frames, config, source=str(clip), video=True, log=FitLog(quiet=True))
    sources = [f"{clip}#{index}" for index in range(len(frames))]
    return fit_photos(frames, sources, config, log=FitLog(quiet=True))[0]


def main(folder: Path, out: Path, names: list[str], settings: list[str]) -> None:
    config = presets.get("default")
    for assignment in settings:
        config = set_from_text(config, assignment)
    for truth_set in read_truth_sets(folder):
        if truth_set.stem not in names:
            continue
        clip = out / f"{truth_set.stem}.mp4"
        clip.parent.mkdir(parents=True, exist_ok=True)
        if not clip.exists():
            write_clip([folder / "images" / render.file for render in truth_set.renders], clip)
        frames, _ = read_spread_frames(clip, config.max_frames, max_side=LOAD_MAX_SIDE)
        truth, mesh, masks = truth_inputs(folder, truth_set)
        for way in ("clip", "person"):
            record = out / truth_set.stem / way / "record.json"
            if record.exists():
                continue
            started = time.perf_counter()
            result = fit_way(way, frames, clip, config)
            seconds = time.perf_counter() - started
            shown = np.zeros(truth.shape[:2], dtype=bool)
            for frame in range(len(result.frames)):
                shown |= shown_texels(result, mesh, frame=frame)
            fitted = measures.at_score_size(result.textures.diffuse.detach().clamp(0, 1).numpy().astype(np.float64))
            scores = score_fit(fitted, truth, shown, masks)
            record.parent.mkdir(parents=True, exist_ok=True)
            record.write_text(json.dumps({"scores": scores, "seconds": seconds, "settings": settings}, indent=1))
            np.save(record.parent / "diffuse.npy", result.textures.diffuse.detach().numpy().astype(np.float16))
            cells = " ".join(f"{name} {float(scores[region][key]):.2f}" for name, (region, key) in COLUMNS)
            print(truth_set.stem, way, cells, f"s {seconds:.0f}", flush=True)


def sheet(path: Path, rows: list[tuple[Path, Path, str]], tile: int = 256) -> None:
    from PIL import Image

    from deface.io.images import linear_to_srgb

    canvas = Image.new("RGB", (3 * tile, len(rows) * tile))
    for row, (folder, out, stem) in enumerate(rows):
        truth = Image.open(folder / "albedo" / f"{stem.split('_')[0]}.png").convert("RGB")
        maps = [np.load(out / stem / way / "diffuse.npy").astype(np.float32) for way in ("clip", "person")]
        images = [truth] + [Image.fromarray((linear_to_srgb(np.clip(m, 0, 1)) * 255).round().astype(np.uint8))
                            for m in maps]
        for column, image in enumerate(images):
            canvas.paste(image.resize((tile, tile)), (column * tile, row * tile))
    canvas.save(path, quality=88)


if __name__ == "__main__":
    if len(sys.argv) >= 4 and sys.argv[1] == "--sheet":
        sheet(Path(sys.argv[2]), [tuple(Path(p) if i < 2 else p for i, p in enumerate(arg.split(":")))
                                  for arg in sys.argv[3:]])
    elif len(sys.argv) >= 4:
        main(Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3].split(","), sys.argv[4:])
    else:
        sys.exit(__doc__)
