"""Helpers of the batch tests (tests/test_batch*.py).

``task``/``warm``: tasks for the worker-pool tests, top-level functions that a spawned worker imports by name.
A job is (name, action, folder): "ok" returns the worker's pid, "sleep" waits for a file, "die-once" kills
its own process (SIGKILL) the first time and succeeds the second, "die" always kills it.
``recorded``: the work of a recorded task (deface/batch/recorded.py): its value and the worker's pid, or a failure.
``deface``/``wait_for_lock``/``arrays``: run the real command and watch or read its outputs.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
TINY = ["--preset", "fast", "--iterations", "20,30,5", "--resolution", "64", "--quiet"]


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


def recorded(value, fail=False):
    if fail:
        raise ValueError(f"task {value} fails")
    return {"value": value, "pid": os.getpid()}


def run_deface(*arguments, **popen) -> subprocess.Popen:
    command = [sys.executable, "-m", "deface.cli.main", *map(str, arguments)]
    return subprocess.Popen(command, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": str(REPO)}, **popen)


def arrays(folder: Path) -> dict:
    with np.load(folder / "params.npz") as data:
        return {key: data[key] for key in data.files}


def wait_for_lock(out: Path, process: subprocess.Popen, seconds: float = 300) -> tuple[Path, int]:
    """The first output lock that a worker holds (its pid is written in it) while it fits."""
    end = time.monotonic() + seconds
    while time.monotonic() < end and process.poll() is None:
        for lock in out.glob(".*.lock"):
            text = lock.read_text().strip() if lock.exists() else ""
            if text.isdigit():
                return lock, int(text)
        time.sleep(0.1)
    raise AssertionError(f"no worker took a lock; exit {process.poll()}: {process.stderr.read()}")
