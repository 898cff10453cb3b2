"""Writing outputs safely: a fit's files (PNGs by :func:`deface.io.images.save_png`, OBJ/MTL, params) are staged
in a temporary folder and moved into place only when complete, so an interrupted or failed run never leaves a
half-written result or destroys an earlier one. One process at a time writes an output folder
(:func:`claimed_output`, a lock released by the kernel even on ``kill -9``), and the holder of the lock removes
what a killed run left behind.
"""

from __future__ import annotations

import fcntl
import glob
import json
import os
import re
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

STAGING_SUFFIX = ".partial"
_MKDTEMP_NAME = re.compile(r"[a-z0-9_]+")  # the random part tempfile.mkdtemp puts in a name (no dots)


class OutputBusy(RuntimeError):
    """Another process is writing the same output folder."""


class OutputError(OSError):
    """An output folder cannot be written (permissions, not a folder, disk full); one line."""


def write_json(path: Path, data: dict) -> None:
    path.write_text(json.dumps(data, indent=2, sort_keys=False, default=_json_default) + "\n")


def _json_default(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


@contextmanager
def staged_directory(final: Path) -> Iterator[Path]:
    """Yield a temporary folder beside ``final``; on success it replaces ``final`` in one rename.

    On an exception the staging folder is removed and ``final`` (if it existed) is left untouched.
    """
    final.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{final.name}.", suffix=STAGING_SUFFIX, dir=final.parent))
    try:
        staging.chmod(0o777 & ~_umask())  # mkdtemp makes it private (0700); outputs get the usual mode
        yield staging
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    if final.exists():
        previous = _previous(final)
        shutil.rmtree(previous, ignore_errors=True)
        final.rename(previous)  # a kill between these renames is undone by remove_stale (previous restored)
        staging.rename(final)
        shutil.rmtree(previous, ignore_errors=True)
    else:
        staging.rename(final)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _previous(final: Path) -> Path:
    return final.with_name(f".{final.name}.previous")


def check_writable(folder: Path) -> None:
    """Create ``folder`` if needed and prove a file can be made in it; :class:`OutputError` otherwise."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as error:
        raise OutputError(f"{folder}: cannot write there ({error.strerror or error})") from None


@contextmanager
def claimed_output(final: Path) -> Iterator[None]:
    """Hold the lock of output folder ``final`` (``.NAME.lock`` beside it) and clean up after killed runs.

    Raises :class:`OutputBusy` at once when another live process holds it.
    """
    final.parent.mkdir(parents=True, exist_ok=True)
    lock = final.with_name(f".{final.name}.lock")
    handle = _lock(lock, final)
    try:
        remove_stale(final)
        yield
    finally:
        lock.unlink(missing_ok=True)  # before the release: a process waiting on this file will retry
        handle.close()


def _lock(lock: Path, final: Path):
    while True:
        handle = open(lock, "a+")
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            holder = handle.read().strip() or "?"
            handle.close()
            raise OutputBusy(f"{final}: another deface run (pid {holder}) is writing it; skipped") from None
        if lock.exists() and os.stat(lock).st_ino == os.fstat(handle.fileno()).st_ino:
            handle.truncate(0)
            handle.write(f"{os.getpid()}\n")
            handle.flush()
            return handle
        handle.close()  # the holder removed the file as we opened it: lock the new one


def remove_stale(final: Path) -> list[Path]:
    """Remove staging folders of ``final`` left by killed runs, and restore ``final`` from its previous
    version when a run died between the two renames of :func:`staged_directory`. Call with the lock held.
    Returns what was removed."""
    removed = []
    for path in final.parent.glob(f".{glob.escape(final.name)}.*{STAGING_SUFFIX}"):
        middle = path.name[len(final.name) + 2:-len(STAGING_SUFFIX)]
        if path.is_dir() and _MKDTEMP_NAME.fullmatch(middle):
            shutil.rmtree(path, ignore_errors=True)
            removed.append(path)
    previous = _previous(final)
    if previous.is_dir() and not final.exists():
        previous.rename(final)
    elif previous.exists():
        shutil.rmtree(previous, ignore_errors=True)
        removed.append(previous)
    return removed
