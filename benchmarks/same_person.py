"""How far apart dlib's descriptors put one person's photos and different people's, as a several-photo fit reads
them (:meth:`deface.landmarks.identity.IdentityScorer.descriptor_of_face`, in the box of MediaPipe's landmarks):
what ``same_person.distance`` is chosen from.

    .venv/bin/python benchmarks/same_person.py [--sets FOLDER] [--pairs DIR]

One person: the board's two photos of Obama; with ``--sets``, every set of a person truth folder
(``benchmarks/blender/person_scenes.py``: one albedo, the head turned by up to 35 degrees, cast shadows); with
``--pairs``, every shadow pair under DIR (``deface bench make-shadows`` or a board's ``pairs/``: a photo and its
shadowed copy). Different people: every pair among ../shared/data/skin-tone/images, ../shared/data/images'
nextface-* and facenet-* photos and the board's photos, Obama's second photo left out. Then each group of one
person as a fit takes it (:func:`deface.fit.person.photos_of_one_person`): how many of its own photos it leaves
out, and whether it leaves out a stranger (``STRANGER``) added to it.
"""

from __future__ import annotations

import argparse
import itertools
from collections import defaultdict
from pathlib import Path

import numpy as np

from deface.fit.log import FitLog
from deface.fit.person import photos_of_one_person
from deface.io.images import load_image
from deface.landmarks.detect import NoFaceError, detect_landmarks
from deface.landmarks.identity import IdentityScorer, SamePersonConfig
from deface.paths import shared_dir

BOARD_PHOTOS = Path(__file__).parent / "board" / "photos"
STRANGER = ("images", "nextface-s2.png")  # under ../shared/data: someone in none of the groups


def distances(scorer: IdentityScorer, paths: list[Path]) -> list[float]:
    """The identity distances between every two of ``paths`` whose face is found."""
    found = []
    for path in paths:
        image = load_image(path)
        try:
            found.append(scorer.descriptor_of_face(image, detect_landmarks(image).points))
        except NoFaceError:
            continue
    return [float(np.linalg.norm(a - b)) for a, b in itertools.combinations(found, 2)]


def one_person_groups(sets: Path | None, pairs: Path | None) -> dict[str, list[Path]]:
    groups = {"obama": [BOARD_PHOTOS / "obama.jpg", BOARD_PHOTOS / "obama_speech.jpg"]}
    if sets is not None:
        by_set = defaultdict(list)
        for path in sorted((sets / "images").glob("*.png")):
            by_set[path.stem.rpartition("_")[0]].append(path)
        groups.update(by_set)
    if pairs is not None:
        for folder in sorted(path.parent for path in pairs.rglob("source.png")):
            groups[str(folder.relative_to(pairs))] = [folder / "source.png", folder / "target.png"]
    return groups


def different_people() -> list[Path]:
    shared = shared_dir() / "data"
    images = sorted((shared / "skin-tone" / "images").iterdir())
    images += sorted((shared / "images").glob("nextface-*.png")) + sorted((shared / "images").glob("facenet-*.png"))
    return images + [path for path in sorted(BOARD_PHOTOS.iterdir())
                     if path.suffix in (".jpg", ".png") and path.name != "obama_speech.jpg"]


def as_a_fit_takes_them(groups: dict[str, list[Path]]) -> tuple[int, int, int]:
    """(own photos left out, strangers left out, groups) over ``groups``: each with a stranger added."""
    def photo(path: Path):
        image = load_image(path)
        return image, detect_landmarks(image), str(path)

    stranger = photo(shared_dir() / "data" / STRANGER[0] / STRANGER[1])
    own_out = strangers_out = 0
    for paths in groups.values():
        photos = [photo(path) for path in paths]
        own_out += len(photos) - len(photos_of_one_person(photos, SamePersonConfig(), FitLog(quiet=True)))
        kept = photos_of_one_person([*photos, stranger], SamePersonConfig(), FitLog(quiet=True))
        strangers_out += stranger[2] not in [source for *_, source in kept]
    return own_out, strangers_out, len(groups)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sets", type=Path)
    parser.add_argument("--pairs", type=Path)
    args = parser.parse_args()
    scorer = IdentityScorer()
    within, groups = [], one_person_groups(args.sets, args.pairs)
    for name, paths in groups.items():
        found = distances(scorer, paths)
        within += found
        print(f"one person, {name}: {' '.join(f'{d:.2f}' for d in found)}")
    across = distances(scorer, different_people())
    print(f"one person: {len(within)} distances, median {np.median(within):.2f}, largest {max(within):.2f}")
    print(f"different people: {len(across)} distances, smallest {min(across):.2f}, 5th percentile "
          f"{np.quantile(across, 0.05):.2f}, median {np.median(across):.2f}")
    own_out, strangers_out, count = as_a_fit_takes_them(groups)
    print(f"as a fit takes them: {own_out} of the groups' own photos left out; a stranger added to each of the "
          f"{count} groups left out {strangers_out} times")


if __name__ == "__main__":
    main()
