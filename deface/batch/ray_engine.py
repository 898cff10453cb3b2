"""`deface fit --engine ray`: the same per-input task (:func:`deface.batch.task.run_job`) as one Ray task per
input, each declaring 1 CPU and :data:`TASK_MEMORY` bytes so Ray packs them onto the cluster's nodes.

Where outputs go (``--ray-outputs``):
- ``driver`` (default, safe anywhere): the driver ships each input file's bytes with its task; the task fits
  into a scratch folder on its node and returns the finished output folder as a tar archive, which the
  driver unpacks into ``OUT/<name>`` under the output's lock, staged and renamed like every other output.
  Needs no shared filesystem; costs the transfer of the outputs (a few MB per photo).
- ``shared``: tasks read the inputs and write ``OUT/<name>`` themselves (locks and staging as in a local
  run), so the inputs and OUT must be on a filesystem every node mounts at the same path. A task that cannot
  see them fails its input with a one-line error naming the node; nothing is shipped.
Model files: each task searches the driver's ``--models``/``DEFACE_MODELS`` path (passed on), then the node's
own cache; a node without them fails its inputs with the usual one-line "model file not found".

A task whose worker process or node dies is recorded ``failed`` (attempt 1) and submitted once more, as in the
local pool; Ray's own retries are off so that the record sees every attempt. Ctrl-C cancels the tasks.
"""

from __future__ import annotations

import io
import json
import os
import shutil
import signal
import socket
import tarfile
import tempfile
from dataclasses import replace
from pathlib import Path

from deface.batch.task import Job, Outcome, run_job
from deface.export.files import OutputBusy, claimed_output, staged_directory
from deface.fit.log import FitLog

# Bytes a fit may use: a `--preset fast` batch worker held ~1.0 GB RSS here (ps, the 26 shared photos); the
# default preset's larger working image and texture need more, hence the margin.
TASK_MEMORY = 2 * 1024**3
RETRIES = 1  # extra attempts for a task whose worker or node died
POLL_SECONDS = 1.0


class RayUnavailable(RuntimeError):
    """Ray is not installed or the cluster cannot be reached (one line)."""


def _ray():
    try:
        import ray
    except ImportError:
        raise RayUnavailable("--engine ray needs Ray: pip install 'deface[ray]'") from None
    return ray


def run_on_ray(jobs: list[Job], listener, options) -> None:
    """Run every job as a Ray task; results and deaths go to ``listener`` like the local pool's."""
    ray = _ray()
    started_here = not ray.is_initialized()
    if started_here:
        handler = signal.getsignal(signal.SIGTERM)
        try:
            ray.init(address=options.ray_address, log_to_driver=False, logging_level="ERROR",
                     include_dashboard=False, runtime_env=_runtime_env())
        except (ConnectionError, RuntimeError, ValueError) as error:
            where = options.ray_address or os.environ.get("RAY_ADDRESS") or "a local Ray"
            raise RayUnavailable(f"cannot start or join Ray at {where}: {str(error).splitlines()[0]}") from None
        signal.signal(signal.SIGTERM, handler)  # ray.init installs its own; SIGTERM stops the batch cleanly
    task = ray.remote(num_cpus=1, memory=TASK_MEMORY, max_retries=0)(ray_task)
    shared = options.ray_outputs == "shared"
    window = 2 * max(1, int(ray.cluster_resources().get("CPU", 1)))  # tasks in flight: the cluster's CPUs, twice
    pending = list(range(len(jobs)))[::-1]
    running: dict = {}  # object ref -> (index, attempt)

    def submit(index: int, attempt: int) -> None:
        job = jobs[index]
        shipped = None if shared else ray.put([path.read_bytes() for path in job.item.files])
        running[task.remote(job, shipped)] = (index, attempt)
        listener.started(index, index, attempt)

    try:
        while running or pending:
            while pending and len(running) < window:
                submit(pending.pop(), 1)
            ready, _ = ray.wait(list(running), num_returns=1, timeout=POLL_SECONDS)
            for ref in ready:
                index, attempt = running.pop(ref)
                try:
                    outcome, archive = ray.get(ref)
                except (ray.exceptions.WorkerCrashedError, ray.exceptions.NodeDiedError,
                        ray.exceptions.OwnerDiedError, ray.exceptions.ObjectLostError) as error:
                    retry = attempt <= RETRIES
                    listener.died(index, index, f"Ray worker died: {type(error).__name__}", attempt, retry)
                    if retry:
                        submit(index, attempt + 1)
                    continue
                except ray.exceptions.RayTaskError as error:
                    reason = f"Ray task failed: {str(error).splitlines()[0]}"
                    outcome, archive = Outcome("failed", 0.0, error=reason), None
                if archive is not None:
                    outcome = _unpack(jobs[index], archive, outcome)
                listener.finished(index, index, outcome, attempt)
    finally:
        for ref in running:
            try:
                ray.cancel(ref, force=True)
            except Exception:  # noqa: BLE001 - a local Ray that Ctrl-C reached is gone already, with its tasks
                pass
        if started_here:
            ray.shutdown()


def _runtime_env() -> dict:
    """What tasks inherit from the driver: the model folder it searches."""
    models = os.environ.get("DEFACE_MODELS")
    return {"env_vars": {"DEFACE_MODELS": models}} if models else {}


def ray_task(job: Job, input_bytes: list[bytes] | None) -> tuple[Outcome, bytes | None]:
    """One input on a Ray worker: in place (shared filesystem) or in a scratch folder returned as a tar."""
    if job.models is not None and not Path(job.models).is_dir():
        return Outcome("failed", 0.0, error=f"--models {job.models}: not a folder on Ray node {socket.gethostname()}; "
                       "every node needs the model files at that path (or in its ~/.cache/deface/models, without "
                       "--models)"), None
    if input_bytes is None:
        missing = next((p for p in (*job.item.files, job.output) if not Path(p).exists()), None)
        if missing is not None:
            return Outcome("failed", 0.0, error=f"{missing}: not visible on Ray node {socket.gethostname()}; "
                           "--ray-outputs shared needs the inputs and OUT on a filesystem every node mounts at the "
                           "same path (the default --ray-outputs driver ships them)"), None
        return run_job(job, FitLog(name=job.item.name, quiet=True)), None
    scratch = Path(tempfile.mkdtemp(prefix="deface-ray-"))
    try:
        files = []
        for position, (path, data) in enumerate(zip(job.item.files, input_bytes, strict=True)):
            local = scratch / "in" / str(position) / path.name  # a person's photos may share a file name
            local.parent.mkdir(parents=True)
            local.write_bytes(data)
            files.append(local)
        item = job.item.moved(files)
        outcome = run_job(replace(job, item=item, output=scratch / "out", overwrite=True),
                          FitLog(name=job.item.name, quiet=True))
        if outcome.status != "done":
            return outcome, None
        buffer = io.BytesIO()
        with tarfile.open(fileobj=buffer, mode="w") as archive:
            archive.add(scratch / "out" / item.name, arcname=".")
        return outcome, buffer.getvalue()
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def _unpack(job: Job, archive: bytes, outcome: Outcome) -> Outcome:
    """Write a task's returned output folder to ``OUT/<name>`` (locked, staged, renamed) on the driver."""
    try:
        with claimed_output(job.folder):
            if (job.folder / "params.json").exists() and not job.overwrite:
                return Outcome("skipped", 0.0)
            with staged_directory(job.folder) as folder:
                with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
                    tar.extractall(folder, filter="data")
                params = folder / "params.json"
                data = json.loads(params.read_text())
                data["input"]["path"] = str(job.item.path)  # the driver's path, not the node's scratch copy
                params.write_text(json.dumps(data, indent=2) + "\n")
    except OutputBusy as busy:
        return Outcome("busy", 0.0, error=str(busy))
    except OSError as error:
        return Outcome("failed", outcome.seconds, error=f"{job.folder}: cannot write the returned output ({error})")
    return outcome
