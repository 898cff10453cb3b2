"""The skin tone a several-photo fit starts from (and keeps: ``tone.learning_rate`` 0), with a white level per photo
(``tone.white_per_photo``) and with one for all the photos, against the truth albedo's ITA.

    .venv/bin/python benchmarks/person_white.py FOLDER CAMERAS [FOLDER CAMERAS ...]

FOLDER is a truth folder of person sets (``benchmarks/blender/person_scenes.py``), CAMERAS the same photos as if from
other cameras (``benchmarks/person_cameras.py FOLDER CAMERAS``). Per set and way: the start's ITA less the truth's
(the albedo's cheeks and forehead, deface.models.ita). Then, per way: the mean and worst absolute error over every
set, and how far the start moves when the photos come from other cameras (the same light and albedo). Each set runs
stage 1 and the scene's reading only (about 20 s a set and way).
"""

from __future__ import annotations

import csv
import sys
from collections import defaultdict
from dataclasses import replace
from pathlib import Path

import numpy as np

from deface.fit import presets
from deface.fit.person import person_target
from deface.fit.pipeline import prepare
from deface.io.images import load_image, srgb_to_linear
from deface.landmarks.detect import detect_landmarks
from deface.models.ita import texture_tone

WAYS = {"per photo": True, "shared": False}


def person_sets(folder: Path) -> dict[str, tuple[str, list[Path]]]:
    """``<tone>_<set>`` -> (its tone, its photos) from the folder's MANIFEST.tsv."""
    sets = defaultdict(list)
    tones = {}
    with open(folder / "MANIFEST.tsv") as table:
        for row in csv.DictReader(table, delimiter="\t"):
            stem = f"{row['tone']}_{row['set']}"
            sets[stem].append(folder / "images" / row["file"])
            tones[stem] = row["tone"]
    return {stem: (tones[stem], sorted(paths)) for stem, paths in sorted(sets.items())}


def truth_ita(folder: Path, tone: str) -> float:
    albedo = srgb_to_linear(load_image(folder / "albedo" / f"{tone}.png"))
    return float(texture_tone(albedo, None, None)["texture_ita"])


def start_tone(paths: list[Path], per_photo: bool) -> float:
    """The ITA a ``--person`` fit of ``paths`` starts from at the default preset."""
    config = presets.get("default")
    config = replace(config, tone=replace(config.tone, white_per_photo=per_photo))
    photos = [load_image(path) for path in paths]
    found = [detect_landmarks(photo, source=str(path)) for photo, path in zip(photos, paths, strict=True)]
    target, _ = person_target(photos, found, [str(path) for path in paths], config)
    context, _ = prepare(target, config)
    return float(context.scene.tone.detach())


def errors(folder: Path) -> dict[str, dict[str, float]]:
    """``<tone>_<set>`` -> way -> start ITA less the truth's."""
    result = {}
    for stem, (tone, paths) in person_sets(folder).items():
        truth = truth_ita(folder, tone)
        result[stem] = {way: start_tone(paths, flag) - truth for way, flag in WAYS.items()}
        print(folder.name, stem, " ".join(f"{way} {value:+.1f}" for way, value in result[stem].items()), flush=True)
    return result


def main(folders: list[Path]) -> None:
    if len(folders) % 2:
        sys.exit(__doc__)
    found = {folder: errors(folder) for folder in folders}
    for way in WAYS:
        every = [abs(sets[stem][way]) for sets in found.values() for stem in sets]
        moved = [abs(found[camera][stem][way] - found[plain][stem][way])
                 for plain, camera in zip(folders[::2], folders[1::2], strict=True) for stem in found[plain]]
        print(f"{way}: |error| mean {np.mean(every):.2f}, worst {np.max(every):.1f} over {len(every)} sets; "
              f"moved by other cameras: mean {np.mean(moved):.2f}, worst {np.max(moved):.1f}")


if __name__ == "__main__":
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    main([Path(arg) for arg in sys.argv[1:]])
