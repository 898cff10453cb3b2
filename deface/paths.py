"""Where model files and shared data are found.

Model files (face models, optional network weights) are looked up in an explicit directory (the CLI's
``--models DIR``) and there only: a user who names a folder gets that folder or a clear error, never a
silent fallback. Without one they are looked up, in order, in:
1. the ``DEFACE_MODELS`` environment variable,
2. the user's cache directory (``$XDG_CACHE_HOME/deface/models``, default ``~/.cache/deface/models``).
The repository never contains model files; the demo and CI point ``DEFACE_MODELS`` at ``../shared/models``.
"""

from __future__ import annotations

import os
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parent.parent


class ModelFileError(FileNotFoundError):
    """A model file is missing; the message says where to get it (one line, actionable)."""


def user_cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "deface" / "models"


def models_dir_candidates(explicit: str | os.PathLike | None = None) -> list[Path]:
    """Directories searched for model files, highest priority first (only ``explicit`` when given)."""
    if explicit:
        return [Path(explicit).expanduser()]
    candidates = []
    env = os.environ.get("DEFACE_MODELS")
    if env:
        candidates.append(Path(env).expanduser())
    candidates.append(user_cache_dir())
    return candidates


def find_model_file(relative: str, explicit: str | os.PathLike | None = None) -> Path | None:
    """First existing ``<dir>/<relative>`` over :func:`models_dir_candidates`, or None."""
    for directory in models_dir_candidates(explicit):
        path = directory / relative
        if path.exists():
            return path
    return None


def shared_dir() -> Path | None:
    """The workplace's ``shared/`` folder beside the checkout (``DEFACE_SHARED`` overrides), if present."""
    env = os.environ.get("DEFACE_SHARED")
    path = Path(env) if env else REPO_ROOT.parent / "shared"
    return path if path.is_dir() else None
