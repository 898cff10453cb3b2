"""Every model file deface knows about: where it goes under the models dir, what it is, where it comes from.

Files are looked up by :func:`deface.paths.find_model_file` (``--models DIR``, ``DEFACE_MODELS``, user cache).
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from pathlib import Path

from deface.models.base import FaceModel
from deface.paths import ModelFileError, find_model_file, models_dir_candidates


@dataclass(frozen=True)
class ModelFile:
    """One known model file."""

    key: str
    """Short name used on the command line (``deface models check bfm2017``)."""
    relative_path: str
    """Location under a models directory."""
    description: str
    """What the file is and what uses it."""
    source: str
    """Where to get it (URL, registration page, or a deface command)."""
    licence: str
    """Licence / terms of use."""
    sha256: str | None
    """SHA-256 of the file, None when unknown (not published and not available to us)."""
    required: bool
    """Needed by the default pipeline (``check`` fails without it)."""
    group: str = ""
    """Feature the file belongs to (``ict``, ``bfm``, ``facenet``, ``face-parsing``)."""
    content_sha256: str | None = None
    """For npz packs: SHA-256 over the arrays (see ict_build.content_sha256), accepted instead of sha256."""


ICT_PACK_SHA256 = "7b7cfa94d59a690d931f27ab0a018cf3bcd03f554c499f269c681a08dfe83089"
ICT_PACK_CONTENT_SHA256 = "14a3fb09ae882290c587ed3fcf1527ebab0baf819785acfbc318b456834f3933"

MODEL_FILES: tuple[ModelFile, ...] = (
    ModelFile(
        key="ict",
        relative_path="ict-facekit/ict_face_area_v9409_f16.npz",
        description="ICT-FaceKit face area pack (default face model: geometry, UVs, landmarks)",
        source="`deface models fetch ict` (downloads github.com/ICT-VGL/ICT-FaceKit) or "
        "`deface models build ict --from <checkout>`",
        licence="MIT (ICT-FaceKit, USC Institute for Creative Technologies)",
        sha256=ICT_PACK_SHA256,
        required=True,
        group="ict",
        content_sha256=ICT_PACK_CONTENT_SHA256,
    ),
    ModelFile(
        key="bfm2017",
        relative_path="bfm2017/model2017-1_face12_nomouth.h5",
        description="Basel Face Model 2017, face12 without mouth (shape + expression) for `deface fit --model bfm`",
        source="register at https://faces.dmi.unibas.ch/bfm/bfm2017.html; get model2017-1_face12_nomouth.h5",
        licence="BFM 2017 licence: non-commercial research, no redistribution",
        sha256=None,
        required=False,
        group="bfm",
    ),
    ModelFile(
        key="albedomm",
        relative_path="albedomm/albedoModel2020_face12_albedoPart.h5",
        description="AlbedoMM diffuse + specular albedo model on BFM face12 (for `deface fit --model bfm`)",
        source="https://github.com/waps101/AlbedoMM/releases (albedoModel2020_face12_albedoPart.h5)",
        licence="AlbedoMM: academic/non-commercial use (see its repository)",
        sha256=None,
        required=False,
        group="bfm",
    ),
    ModelFile(
        key="bfm-correspondence",
        relative_path="bfm2017/mediapipe_correspondence.txt",
        description="your own MediaPipe-to-BFM correspondence for `--model bfm` (else built from the h5 file's "
        "landmark metadata; format in docs/bfm.md)",
        source="optional; e.g. NextFace's baselMorphableModel/landmark_62_mp.txt (github.com/abdallahdib/NextFace)",
        licence="yours / its source's",
        sha256=None,
        required=False,
        group="bfm-options",
    ),
    ModelFile(
        key="bfm-uv",
        relative_path="bfm2017/uv_layout.obj",
        description="your own UV layout for `--model bfm`: an OBJ with vt on the BFM vertices (else a computed "
        "cylindrical layout)",
        source="optional; export the BFM mean with UVs from your tool of choice",
        licence="yours",
        sha256=None,
        required=False,
        group="bfm-options",
    ),
    ModelFile(
        key="facenet",
        relative_path="facenet/20180402-114759-vggface2.pt",
        description="FaceNet InceptionResnetV1 VGGFace2 classifier weights (human prior HP, optional)",
        source="https://github.com/timesler/facenet-pytorch/releases (20180402-114759-vggface2.pt)",
        licence="facenet-pytorch MIT; weights trained on VGGFace2 (research use)",
        sha256=None,
        required=False,
        group="facenet",
    ),
    ModelFile(
        key="face-parsing",
        relative_path="face-parsing/79999_iter.pth",
        description="BiSeNet face parsing, 19 CelebAMask-HQ classes (segmentation loss, eval mask; optional)",
        source="https://github.com/zllrunning/face-parsing.PyTorch (README: Drive link to 79999_iter.pth)",
        licence="MIT code; weights trained on CelebAMask-HQ (non-commercial research)",
        sha256=None,
        required=False,
        group="face-parsing",
    ),
)


def model_file(key: str) -> ModelFile:
    """The registry entry for ``key``; one-line error listing the known keys."""
    for entry in MODEL_FILES:
        if entry.key == key:
            return entry
    raise KeyError(f"unknown model file '{key}'; known: {', '.join(e.key for e in MODEL_FILES)}")


def select(names: list[str] | tuple[str, ...]) -> list[ModelFile]:
    """Entries for keys or groups (``bfm`` = bfm2017 + albedomm); all entries when ``names`` is empty."""
    if not names:
        return list(MODEL_FILES)
    chosen: list[ModelFile] = []
    for name in names:
        group = [e for e in MODEL_FILES if e.group == name or e.key == name]
        if not group:
            known = sorted({e.key for e in MODEL_FILES} | {e.group for e in MODEL_FILES})
            raise KeyError(f"unknown model file or group '{name}'; known: {', '.join(known)}")
        chosen.extend(e for e in group if e not in chosen)
    return chosen


def sha256_file(path: str | Path, chunk: int = 1 << 20) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        while block := handle.read(chunk):
            digest.update(block)
    return digest.hexdigest()


@dataclass(frozen=True)
class FileStatus:
    """Result of looking for (and optionally verifying) one registry file."""

    entry: ModelFile
    path: Path | None  # where it was found, None if missing
    checksum: str  # "ok", "ok (content)", "mismatch", "unknown", "not checked", "missing"
    target: Path  # where the file belongs (first models directory searched)

    @property
    def problem(self) -> str | None:
        """One-line, actionable description of what is wrong, or None."""
        if self.path is None:
            return (
                f"missing {self.entry.relative_path} ({self.entry.description}); "
                f"get it: {self.entry.source}; "
                f"put it at {self.target}"
            )
        if self.checksum == "mismatch":
            expected = self.entry.sha256
            return f"checksum mismatch for {self.path}: expected sha256 {expected}; re-download or rebuild"
        return None


def status(entry: ModelFile, models_dir: str | os.PathLike | None = None, verify: bool = False) -> FileStatus:
    """Find ``entry``; with ``verify`` compare its SHA-256 (file bytes, or npz content) to the registry."""
    path = find_model_file(entry.relative_path, models_dir)
    target = models_dir_candidates(models_dir)[0] / entry.relative_path
    if path is None:
        return FileStatus(entry, None, "missing", target)
    if not verify:
        return FileStatus(entry, path, "not checked", target)
    if entry.sha256 is None:
        return FileStatus(entry, path, "unknown", target)
    if sha256_file(path) == entry.sha256:
        return FileStatus(entry, path, "ok", target)
    if entry.content_sha256 and path.suffix == ".npz":
        from deface.models.ict_build import content_sha256

        try:
            if content_sha256(path) == entry.content_sha256:
                return FileStatus(entry, path, "ok (content)", target)
        except (OSError, ValueError):
            pass
    return FileStatus(entry, path, "mismatch", target)


def require_face_model(name: str, models_dir: str | os.PathLike | None = None) -> None:
    """Raise :class:`ModelFileError` (one line: what, where to get it, where to put it) when a file of face
    model ``name`` is missing; with ``models_dir`` only that folder counts."""
    for entry in select([name]):
        problem = status(entry, models_dir).problem
        if problem:
            raise ModelFileError(problem)


TONE_AXIS = {"ict": True, "bfm": False}
"""Whether a model's albedo prior has a skin-tone axis (docs/skin-tone.md; AlbedoMM has none, docs/bfm.md).
Known without loading the model, so a batch can compare a rerun's settings with the fits' own."""


def load_face_model(name: str, models_dir: str | os.PathLike | None = None) -> FaceModel:
    """The face model called ``name`` ("ict" or "bfm"), with its albedo model."""
    if name == "ict":
        from deface.models.ict import load_ict

        return load_ict(models_dir)
    if name == "bfm":
        from deface.models.bfm import load_bfm

        return load_bfm(models_dir)
    raise ValueError(f"unknown face model '{name}'; choose 'ict' or 'bfm'")
