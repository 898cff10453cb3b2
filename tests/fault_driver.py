"""Runs `deface fit` in a subprocess with a slow stand-in for the fit or the write, so that tests can send
signals at a known moment. The command-line code, the locks and the staging folders are the real ones.

Usage: python tests/fault_driver.py MODE SECONDS -- <deface fit arguments>
MODE "fit": the fit sleeps SECONDS (after printing "PAUSED in fit"), then the write is quick.
MODE "write": the fit is quick; the write stages params.json, prints "PAUSED in write", sleeps SECONDS, then commits.
"""

from __future__ import annotations

import os
import sys
import time
from types import SimpleNamespace

import deface.batch.task as task
from deface.export.files import staged_directory


def _pause(mode: str, wanted: str, seconds: float) -> None:
    """Sleep ``seconds``, or less once the file named by $DRIVER_GO exists."""
    if mode == wanted:
        print(f"PAUSED in {wanted}", file=sys.stderr, flush=True)
        go, end = os.environ.get("DRIVER_GO"), time.monotonic() + seconds
        while time.monotonic() < end and not (go and os.path.exists(go)):
            time.sleep(0.05)


def main() -> None:
    mode, seconds, separator, *arguments = sys.argv[1:]
    assert separator == "--"

    def slow_fit(frames, config, **_):
        _pause(mode, "fit", float(seconds))
        # what the record reads of a result (FitOutput.lights.kept and .skin_tone())
        return SimpleNamespace(frames=len(frames), lights=SimpleNamespace(kept=(0,)),
                               skin_tone=lambda: {"texture_ita": 40.0, "ita_interval": [30.0, 50.0]})

    def slow_write(result, folder, record, page=None):
        with staged_directory(folder) as staging:
            (staging / "params.json").write_text(f'{{"frames": {result.frames}}}\n')
            _pause(mode, "write", float(seconds))

    task.fit, task.write_fit = slow_fit, slow_write
    sys.argv = ["deface", "fit", *arguments]
    from deface.cli.main import main as deface_main

    deface_main()


if __name__ == "__main__":
    main()
