"""deface/runtime.py: with the allocator setting, a step's freed temporaries are reused without page faults."""

from __future__ import annotations

import platform
import subprocess
import sys

import pytest

from deface import runtime

_STEPS = """
import resource, sys
import numpy as np
if sys.argv[1] == "tuned":
    from deface.runtime import keep_freed_memory
    assert keep_freed_memory() and keep_freed_memory()  # applies, and again as a no-op
def step():  # allocate, touch and free four 8-MB temporaries, as a fit step does
    blocks = [np.ones((1 << 20) + k * 1000) for k in range(4)]
    return sum(float(b[-1]) for b in blocks)
step()
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(20):
    step()
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def _faults(mode: str) -> int:
    out = subprocess.run([sys.executable, "-c", _STEPS, mode], capture_output=True, text=True, check=True)
    return int(out.stdout.strip())


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="the setting is glibc's")
def test_freed_temporaries_are_reused_without_page_faults():
    default, tuned = _faults("default"), _faults("tuned")
    assert default > 20 * 1000  # glibc gives freed blocks back and faults them in again at every step
    assert tuned < default / 100


def test_other_c_libraries_are_left_alone(monkeypatch):
    monkeypatch.setattr(runtime, "_applied", None)
    monkeypatch.setattr(platform, "libc_ver", lambda: ("musl", "1.2"))
    assert runtime.keep_freed_memory() is False
