"""Quiet native logging: MediaPipe, TFLite and absl print several INFO/WARNING lines from C++ on every run
("All log messages before absl::InitializeLog() ...", "Feedback manager requires a model with a single
signature ...", "Using NORM_RECT without IMAGE_DIMENSIONS ...", "Created TensorFlow Lite XNNPACK delegate").
They bypass Python's logging, so :func:`native_log_filter` catches file descriptor 2 while MediaPipe runs and
writes back every line that is not such a notice: errors (``E``/``F`` lines) and anything unknown still show.
"""

from __future__ import annotations

import ctypes
import os
import re
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager

# glog/absl INFO and WARNING lines ("I0000 00:00:..." / "W0000 ..."), and TFLite's/absl's plain notices.
NOTICE = re.compile(r"^(?:[IW]\d{4} \d\d:\d\d:\d+\.\d+ +\d+ [\w./-]+:\d+\] .*"
                    r"|(?:WARNING: )?All log messages before absl::InitializeLog\(\) is called are written to STDERR"
                    r"|INFO: Created TensorFlow Lite XNNPACK delegate for CPU\.)$")


def quiet_environment() -> None:
    """Lower the native log levels before MediaPipe is imported (each only if the user has not set it)."""
    os.environ.setdefault("GLOG_minloglevel", "2")
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")


def is_notice(line: str) -> bool:
    return bool(NOTICE.match(line.strip()))


@contextmanager
def native_log_filter() -> Iterator[None]:
    """Inside: what native code writes to stderr is held back; on exit, all but the notices is written."""
    if os.environ.get("DEFACE_NATIVE_LOGS"):  # everything, for debugging MediaPipe itself
        yield
        return
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):  # no real fd 2 (embedded interpreters): nothing to filter
        yield
        return
    with tempfile.TemporaryFile(mode="w+b") as held:
        os.dup2(held.fileno(), 2)
        try:
            yield
        finally:
            sys.stderr.flush()
            _flush_c_streams()  # TFLite prints through C stdio, which may hold its lines in a buffer
            os.dup2(saved, 2)
            os.close(saved)
            held.seek(0)
            kept = [line for line in held.read().decode(errors="replace").splitlines() if not is_notice(line)]
            if kept:
                sys.stderr.write("\n".join(kept) + "\n")
                sys.stderr.flush()


def _flush_c_streams() -> None:
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):  # no C library handle on this platform: nothing buffered to flush
        pass
