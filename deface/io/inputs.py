"""Command-line inputs: files and folders -> a sorted list of images and videos."""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from deface.io.images import InputError

IMAGE_EXTENSIONS = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp")
VIDEO_EXTENSIONS = (".mp4", ".mov", ".avi", ".mkv", ".webm")


@dataclass(frozen=True)
class InputItem:
    """One input: a still image, a video clip, or several photos of one person (one fit)."""

    path: Path  # the image or clip; a person's first photo
    kind: str  # "image", "video" or "person"
    photos: tuple[Path, ...] = ()  # a person's photos, ``path`` first
    label: str | None = None  # a person's name

    @property
    def name(self) -> str:
        """What names the outputs: the file's stem, or the person's name."""
        return self.label or self.path.stem

    @property
    def files(self) -> tuple[Path, ...]:
        """Every file the input reads."""
        return self.photos or (self.path,)

    def moved(self, files: list[Path]) -> InputItem:
        """The same input read from ``files`` (copies of :attr:`files`, in order)."""
        photos = tuple(files) if self.photos else ()
        return InputItem(Path(files[0]), self.kind, photos, self.label)


def person_input(name: str, items: list[InputItem]) -> InputItem:
    """Several photos of one person, named ``name``, as one input (a clip's frames count as photos); an unusable
    name is refused."""
    if not name or name in (".", "..") or any(c in name for c in "/\\\0"):
        raise InputError(f"--person {name!r}: a name for the output folder (no slashes) expected")
    return InputItem(items[0].path, "person", tuple(item.path for item in items), name)


def classify(path: Path) -> str | None:
    """'image', 'video' or None from the file extension (case-insensitive)."""
    suffix = path.suffix.lower()
    if suffix in IMAGE_EXTENSIONS:
        return "image"
    if suffix in VIDEO_EXTENSIONS:
        return "video"
    return None


def list_inputs(paths: Iterable[str | os.PathLike]) -> list[InputItem]:
    """Expand files and folders (non-recursive, sorted by name) into images and videos.

    Explicit files with an unknown extension and missing paths raise :class:`InputError`; files in a
    folder with other extensions are skipped. A folder with no usable file raises too.
    """
    items: list[InputItem] = []
    for raw in paths:
        path = Path(raw)
        if path.is_dir():
            found = [
                InputItem(p, kind) for p in sorted(path.iterdir()) if p.is_file() and (kind := classify(p))
            ]
            if not found:
                raise InputError(
                    f"{path}: folder has no image or video files ({', '.join(IMAGE_EXTENSIONS)} ...)"
                )
            items.extend(found)
        elif path.is_file():
            kind = classify(path)
            if kind is None:
                raise InputError(f"{path}: unsupported file type '{path.suffix}' (images or videos expected)")
            items.append(InputItem(path, kind))
        else:
            raise InputError(f"{path}: no such file or folder")
    return items
