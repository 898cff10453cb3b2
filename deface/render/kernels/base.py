"""What every op module of the kernels package shares: the backend switch, the thread setting, the
serial/parallel numba compilation, and the registry of ops (torch reference, fast kernel, dispatch rule)."""

from __future__ import annotations

import importlib
import os
import sys
import types
from collections.abc import Callable
from contextlib import contextmanager
from typing import NamedTuple

import numpy as np
import torch

try:  # numba is a regular dependency; the torch path keeps the renderer working without it
    import numba
    from numba import njit, prange
except ImportError:  # pragma: no cover - exercised only where numba is missing
    numba = None
    prange = range

    def njit(*args, **kwargs):
        """Without numba the kernels stay plain Python functions (never called: ``enabled`` is False)."""
        if args and callable(args[0]):
            return args[0]
        return lambda function: function


_backend = os.environ.get("DEFACE_RENDER_KERNELS", "numba")


def enabled(*tensors: torch.Tensor) -> bool:
    """Whether the numba kernels handle these tensors (all on the CPU, numba present and selected)."""
    return numba is not None and _backend != "torch" and all(t.device.type == "cpu" for t in tensors)


@contextmanager
def backend(name: str):
    """Temporarily select the kernels: "numba" (fast path where possible) or "torch" (reference path)."""
    global _backend
    if name not in ("numba", "torch"):
        raise ValueError(f"kernels.backend: expected 'numba' or 'torch', got {name!r}")
    previous, _backend = _backend, name
    try:
        yield
    finally:
        _backend = previous


_on_reference: frozenset[str] = frozenset()


@contextmanager
def on_reference(*names: str):
    """Temporarily run the ops ``names`` on their torch reference, the others as selected (a benchmark's
    "what do these fast paths save")."""
    global _on_reference
    unknown = sorted(set(names) - set(load_ops()))
    if unknown:
        raise ValueError(f"kernels.on_reference: no op named {unknown}")
    previous, _on_reference = _on_reference, _on_reference | frozenset(names)
    try:
        yield
    finally:
        _on_reference = previous


def _array(tensor: torch.Tensor) -> np.ndarray:
    return tensor.detach().contiguous().numpy()


def _thread_setting() -> int | None:
    value = os.environ.get("DEFACE_RENDER_THREADS", "")
    return int(value) if value.strip() else None


_threads = _thread_setting()


def set_threads(count: int | None) -> None:
    """Threads of the numba kernels and of Embree's primary and shadow rays; None (the default) follows
    ``torch.get_num_threads()``.

    The renderer's time is mostly in these kernels, so e.g. 2 kernel threads with 1 torch thread keep
    torch's small ops free of thread hand-offs while the pixel passes run on both cores. The environment
    variable DEFACE_RENDER_THREADS sets the initial value. Results do not depend on it (see the package
    docstring).
    """
    global _threads
    if count is not None and count < 1:
        raise ValueError(f"kernels.set_threads: need a count >= 1 or None, got {count}")
    _threads = count


def thread_count() -> int:
    """Threads the renderer's CPU loops use: the numba kernels and the Embree ray batches (raycast.py)."""
    threads = torch.get_num_threads() if _threads is None else _threads
    return threads if numba is None else min(threads, numba.config.NUMBA_NUM_THREADS)


def _pick(kernel):
    """The serial or the parallel compilation of ``kernel`` for the thread setting (``set_threads``).

    With 1 thread the serial build runs on the calling thread (no thread pool at all).
    """
    threads = thread_count()
    if threads <= 1:
        return kernel.serial
    if numba.get_num_threads() != threads:
        numba.set_num_threads(threads)
    return kernel.parallel


if numba is not None and "NUMBA_THREADING_LAYER" not in os.environ:
    # OpenMP first: the calling thread joins each kernel and the workers stay warm between the ~15 kernels of
    # a render. workqueue (the fallback where libgomp is missing) parks the calling thread and wakes its
    # workers for every kernel: 2-thread 256² step 48-53 ms wall median vs 44-45 with OpenMP and 1 torch
    # thread, 63 vs 32 ms with 2 torch threads (benchmarks/render.md, round 4). An idle OpenMP worker spins
    # briefly after each kernel; on a machine shared with other jobs NUMBA_THREADING_LAYER=workqueue avoids
    # that (an explicit NUMBA_THREADING_LAYER always wins). With 1 thread no layer is used at all.
    numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]
    numba.config.THREADING_LAYER = "default"

# reassociation lets LLVM vectorise the channel sums; results stay deterministic for a given build
_FAST = {"reassoc", "contract"}


class serial_and_parallel:  # noqa: N801 - used as a decorator
    """One loop body compiled twice: ``serial`` (prange runs as range) and ``parallel``."""

    def __init__(self, function):
        if numba is None:  # pragma: no cover
            self.serial = self.parallel = function
            return
        self.serial = njit(cache=True, fastmath=_FAST)(function)
        # numba's on-disk cache is keyed by the function's name, not by its compile flags
        twin = types.FunctionType(function.__code__, function.__globals__, function.__name__)
        twin.__qualname__ = function.__qualname__ + "_parallel"
        self.parallel = njit(parallel=True, cache=True, fastmath=_FAST)(twin)


# -- the registry -----------------------------------------------------------------------------------
class Op(NamedTuple):
    """One renderer op: its torch ``reference`` (the definition, any device), its ``fast`` numba path
    (an ``autograd.Function``'s apply; same arguments, same results up to rounding, same gradients) and
    ``supports(*args)``, the rule for when the fast path applies beyond the backend switch (dtypes,
    shapes). Calling the op runs the fast path where ``enabled`` and ``supports`` allow, else the
    reference: every ``kernels.<op>(...)`` call site dispatches through here."""

    name: str
    reference: Callable
    fast: Callable
    supports: Callable[..., bool]

    def use_fast(self, *args) -> bool:
        """Whether a call with these arguments runs the fast path."""
        return numba is not None and _backend != "torch" and self.name not in _on_reference and self.supports(*args)

    def __call__(self, *args):
        return (self.fast if self.use_fast(*args) else self.reference)(*args)


OPS: dict[str, Op] = {}
"""Every registered op by name (tests/test_render_kernels.py runs each one against its reference); the ops
of OP_MODULES appear once those are imported (``load_ops``)."""

OP_MODULES = ("deface.render.fast_box", "deface.texture.fast_pyramid", "deface.fit.fast_stage3")
"""The modules outside this package that register ops (fast paths of the supersampling, the texture pyramid
and stage 3's terms). ``register`` refuses any other module, so no op escapes ``load_ops`` and the test."""


def register(name: str, reference: Callable, fast: Callable, supports: Callable[..., bool]) -> Op:
    """Add an op to ``OPS`` and return it (the module-level callable of the op)."""
    module = sys._getframe(1).f_globals.get("__name__", "")
    if not module.startswith(__package__ + ".") and module not in OP_MODULES:
        raise ValueError(f"kernels.register: {module} registers op {name!r} but is not in kernels.OP_MODULES "
                         "(add it there so that load_ops and tests/test_render_kernels.py see its ops)")
    if name in OPS:
        raise ValueError(f"kernels.register: an op named {name!r} is already registered")
    OPS[name] = op = Op(name, reference, fast, supports)
    return op


def load_ops() -> dict[str, Op]:
    """``OPS`` with every op registered: imports OP_MODULES (they import this package, so it cannot import
    them itself)."""
    for module in OP_MODULES:
        importlib.import_module(module)
    return OPS
