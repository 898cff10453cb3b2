"""Process settings a fit runs with: ``torch_threads``, and ``keep_freed_memory`` (faster).

``keep_freed_memory``: every optimisation step allocates and frees the same ~100 MB of temporaries (f's
activations, per-light images, the supersampled buffers). glibc's malloc serves blocks above its mmap threshold
with fresh mmap'ed pages and gives freed memory back to the system, so each step paid ~9,000 page faults on
memory it had just released: 13 ms of a 116-ms stage-2 step and ~20 ms of a stage-3 step at 256²
(BENCHMARKS.md "Speed"). Raising the mmap threshold to its maximum (32 MB on 64-bit glibc) and the trim
threshold to 1 GB keeps those blocks in the heap for the next step. Peak memory is unchanged in kind (the same
blocks, reused); the process keeps its peak until it exits. Other C libraries (musl, macOS) are left alone.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import platform
from collections.abc import Iterator
from contextlib import contextmanager

import torch

_M_TRIM_THRESHOLD = -1  # glibc mallopt parameters (malloc.h)
_M_MMAP_THRESHOLD = -3
_MMAP_THRESHOLD_MAX = 32 * 1024 * 1024  # glibc's DEFAULT_MMAP_THRESHOLD_MAX on 64-bit
_TRIM_THRESHOLD = 1024 * 1024 * 1024

_applied: bool | None = None


def keep_freed_memory() -> bool:
    """Tune glibc's malloc as the module doc says (once per process); whether it applied."""
    global _applied
    if _applied is None:
        _applied = _mallopt()
    return _applied


def _mallopt() -> bool:
    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
    except OSError:
        return False
    # mallopt returns 1 on success; setting the mmap threshold also stops glibc adapting it
    return bool(libc.mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD_MAX)) and bool(
        libc.mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD))


@contextmanager
def torch_threads(count: int) -> Iterator[None]:
    """Run with ``count`` torch threads (0: leave torch's default), restoring the previous setting."""
    previous = torch.get_num_threads()
    if count > 0:
        torch.set_num_threads(count)
    try:
        yield
    finally:
        torch.set_num_threads(previous)
