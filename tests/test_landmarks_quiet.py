"""MediaPipe's native notices are filtered from stderr; real errors and Python's own output still show."""

from __future__ import annotations

import subprocess
import sys

import pytest

from deface.landmarks.quiet import is_notice

SCRIPT = """
import os, sys
from deface.io.images import load_image
from deface.landmarks.detect import detect_landmarks
from deface.landmarks.quiet import native_log_filter
detect_landmarks(load_image(sys.argv[1]))
with native_log_filter():
    os.write(2, b"E0000 00:00:1.5  7 some.cc:3] a real native error\\n")
    os.write(2, b"W0000 00:00:1795457854.095205   23454 x.cc:114] a notice\\n")
print("python still talks", file=sys.stderr)
"""


def test_notice_patterns():
    assert is_notice("W0000 00:00:1795457854.137200   23453 landmark_projection_calculator.cc:186] Using NORM_RECT "
                     "without IMAGE_DIMENSIONS is only supported for the square ROI.")
    assert is_notice("WARNING: All log messages before absl::InitializeLog() is called are written to STDERR")
    assert is_notice("INFO: Created TensorFlow Lite XNNPACK delegate for CPU.")
    assert not is_notice("E0000 00:00:1795457854.137200   23453 graph.cc:1] calculator failed")
    assert not is_notice("Traceback (most recent call last):")


@pytest.mark.slow
def test_detection_prints_no_native_notices(photos):
    done = subprocess.run([sys.executable, "-c", SCRIPT, str(photos / "000031.jpg")], capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    lines = done.stderr.splitlines()
    assert lines == ["E0000 00:00:1.5  7 some.cc:3] a real native error", "python still talks"], lines
