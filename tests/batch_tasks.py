"""Tasks for the worker-pool tests (tests/test_batch.py): top-level functions that a spawned worker imports by
name. A job is (name, action, folder): "ok" returns the worker's pid, "sleep" waits for a file, "die-once"
kills its own process (SIGKILL) the first time and succeeds the second, "die" always kills it."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path


def task(job, report):
    name, action, folder = job
    folder = Path(folder)
    (folder / f"{name}.{os.getpid()}.started").touch()
    report(f"{name} running")
    if action == "die" or (action == "die-once" and not (folder / f"{name}.died").exists()):
        (folder / f"{name}.died").touch()
        os.kill(os.getpid(), signal.SIGKILL)
    if action == "sleep":
        while not (folder / "go").exists():
            time.sleep(0.02)
    return (name, os.getpid())


def warm(folder):
    (Path(folder) / f"warm.{os.getpid()}").touch()
