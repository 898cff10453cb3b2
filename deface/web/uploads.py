"""Uploads -> a job's inputs, and the grey-card box drawn on the first photo.

Each upload of a supported type is copied into ``OUT/<job>/inputs/`` under a safe name that is unique in the job
(its output folder is named after it, as `deface fit` names outputs by stem); every other upload is refused with
one line. Copying keeps a job's inputs with its results (params.json names them) even after Gradio's upload cache
is cleaned.
"""

from __future__ import annotations

import re
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from deface.io.images import InputError, load_image, one_line
from deface.io.inputs import IMAGE_EXTENSIONS, VIDEO_EXTENSIONS, InputItem, classify, person_input
from deface.io.video import read_spread_frames

INPUTS_DIR = "inputs"
PREVIEW_SIDE = 640
"""Longest side of the photo the grey card is drawn on (the box is in fractions: any size will do). Smaller photos
are enlarged to it: Gradio maps a click to image pixels assuming the page never shows the image enlarged."""
_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")
SUPPORTED = f"photos {' '.join(IMAGE_EXTENSIONS)}; clips {' '.join(VIDEO_EXTENSIONS)}"


class UploadError(ValueError):
    """A job that cannot be queued as uploaded (too many files, none usable); one line."""


@dataclass(frozen=True)
class StagedInputs:
    """The inputs of one job."""

    items: list[InputItem]  # copied into the job's inputs folder, in upload order
    files: list[str]  # the name each item was uploaded as
    refused: list[str]  # one line per upload that is not queued


def stage_uploads(uploads: list[str | Path], folder: Path, max_files: int) -> StagedInputs:
    """Copy the supported ``uploads`` into ``folder/inputs``; refuse the rest (one line each)."""
    if not uploads:
        raise UploadError("no file: drop one or more photos, or a clip, first")
    if len(uploads) > max_files:
        raise UploadError(f"{len(uploads)} files: at most {max_files} per job")
    items, files, refused, taken = [], [], [], set()
    for upload in map(Path, uploads):
        original = upload.name
        kind = classify(upload)
        if kind is None:
            suffix = f"'{upload.suffix}'" if upload.suffix else "without an extension"
            refused.append(f"{original}: unsupported file type {suffix} ({SUPPORTED})")
            continue
        name = unique_name(safe_stem(upload.stem), taken)
        taken.add(name)
        target = folder / INPUTS_DIR / f"{name}{upload.suffix.lower()}"
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(upload, target)
        items.append(InputItem(target, kind))
        files.append(original)
    return StagedInputs(items, files, refused)


PERSON = "person"
"""The output name of a job's photos fitted as one person."""


def one_person(staged: StagedInputs) -> list[tuple[str, InputItem]]:
    """(name shown, input) of a job whose photos are one person: its photos as one input (with two or more),
    a clip on its own."""
    photos = [(file, item) for file, item in zip(staged.files, staged.items, strict=True) if item.kind == "image"]
    others = [(file, item) for file, item in zip(staged.files, staged.items, strict=True) if item.kind != "image"]
    if len(photos) < 2:
        return photos + others
    person = person_input(PERSON, [item for _, item in photos])
    return [(" + ".join(file for file, _ in photos), person), *others]


def safe_stem(stem: str) -> str:
    """A file stem reduced to letters, digits, ``._-`` (never empty, never hidden)."""
    return _UNSAFE.sub("_", stem).strip("._") or "input"


def unique_name(name: str, taken: set[str]) -> str:
    """``name``, else ``name-2``, ``name-3``, ... (two uploads called photo.jpg get two output folders)."""
    if name not in taken:
        return name
    number = 2
    while f"{name}-{number}" in taken:
        number += 1
    return f"{name}-{number}"


def preview(upload: str | Path) -> np.ndarray:
    """The photo (or a clip's first frame) to draw the grey card on: [H, W, 3] uint8, at most PREVIEW_SIDE px.
    Raises InputError (one line) for a file that cannot be read."""
    path = Path(upload)
    kind = classify(path)
    if kind is None:
        raise InputError(f"{path.name}: unsupported file type ({SUPPORTED})")
    try:
        frame = (load_image(path, max_side=PREVIEW_SIDE) if kind == "image"
                 else read_spread_frames(path, 1, max_side=PREVIEW_SIDE)[0][0])
    except InputError as error:
        raise InputError(str(error).replace(str(path), path.name)) from None
    except (OSError, ValueError) as error:
        raise InputError(f"{path.name}: cannot read it ({one_line(error)})") from None
    picture = Image.fromarray(np.round(np.clip(frame, 0, 1) * 255).astype(np.uint8))
    scale = PREVIEW_SIDE / max(picture.size)
    if scale > 1:
        picture = picture.resize((round(picture.width * scale), round(picture.height * scale)), Image.BICUBIC)
    return np.asarray(picture)


def box_from_corners(first: tuple[float, float], second: tuple[float, float],
                     size: tuple[int, int]) -> tuple[float, float, float, float]:
    """Two opposite corners in pixels of an image of ``size`` (W, H) -> (left, top, right, bottom) as fractions
    of the image (tone.illuminant.reference_box); the corners' pixels are inside the box."""
    width, height = size
    left, right = sorted((first[0], second[0]))
    top, bottom = sorted((first[1], second[1]))
    box = (left / width, top / height, (right + 1) / width, (bottom + 1) / height)
    return tuple(float(np.clip(value, 0.0, 1.0)) for value in box)


def parse_box(text: str | None) -> tuple[float, float, float, float] | None:
    """``"left, top, right, bottom"`` as fractions -> the box; empty -> None; ValueError (one line) otherwise."""
    if text is None or not text.strip():
        return None
    try:
        values = tuple(float(part) for part in text.replace(";", ",").split(","))
    except ValueError:
        values = ()
    if len(values) != 4:
        raise ValueError(f"grey card box: four fractions left, top, right, bottom expected, got '{text.strip()}'")
    left, top, right, bottom = values
    if not (0.0 <= left < right <= 1.0 and 0.0 <= top < bottom <= 1.0):
        raise ValueError("grey card box: 0 <= left < right <= 1 and 0 <= top < bottom <= 1 (fractions of the "
                         f"photo), got '{text.strip()}'")
    return values


def box_text(box: tuple[float, float, float, float] | None) -> str:
    return "" if box is None else ", ".join(f"{value:.3f}" for value in box)


def draw_box(image: np.ndarray, box: tuple[float, float, float, float] | None = None,
             corner: tuple[float, float] | None = None) -> np.ndarray:
    """``image`` [H, W, 3] uint8 with the box (fractions) outlined and a first corner (pixels) marked."""
    picture = Image.fromarray(image)
    draw = ImageDraw.Draw(picture)
    height, width = image.shape[:2]
    line = max(2, round(max(width, height) / 200))
    if box is not None:
        left, top, right, bottom = box
        outline = [left * width, top * height, right * width - 1, bottom * height - 1]
        draw.rectangle(outline, outline=(0, 0, 0), width=line + 2)
        draw.rectangle(outline, outline=(255, 215, 0), width=line)
    if corner is not None:
        x, y = corner
        radius = 3 * line
        draw.ellipse([x - radius, y - radius, x + radius, y + radius], outline=(255, 215, 0), width=line)
    return np.asarray(picture)
