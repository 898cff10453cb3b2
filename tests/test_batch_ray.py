"""`deface fit --engine ray` on a real local Ray cluster that each command starts (ray.init on this machine),
with real tiny fits: outputs returned to the driver, outputs written in place with a worker killed mid-task
(retried), an input a node cannot see, and Ray missing. Needs the extra: pip install 'deface[ray]'.
"""

from __future__ import annotations

import json
import os
import signal
import sys
from pathlib import Path

import numpy as np
import pytest
from batch_helpers import TINY, arrays, run_deface, wait_for_lock

from deface.batch.ray_engine import RayUnavailable, _ray, ray_task
from deface.batch.record import latest_states, read_records
from deface.batch.task import Job
from deface.fit import presets
from deface.io.inputs import InputItem

pytest.importorskip("ray")


@pytest.fixture(scope="module")
def two_photos(photos, tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("ray-in")
    for name in ("vd006.png", "vd092.png"):
        (folder / name).symlink_to(photos / name)
    return folder


@pytest.mark.slow
def test_outputs_returned_to_the_driver_match_a_local_fit(two_photos, tmp_path):
    ray_out, local_out = tmp_path / "ray", tmp_path / "local"
    process = run_deface("fit", two_photos, "-o", ray_out, *TINY, "--engine", "ray")
    assert process.wait(900) == 0, process.stderr.read()
    local = run_deface("fit", two_photos / "vd006.png", "-o", local_out, *TINY)
    assert local.wait(600) == 0, local.stderr.read()
    states = latest_states(read_records(ray_out))
    assert sorted(Path(p).name for p in states) == ["vd006.png", "vd092.png"]
    assert {(r.status, r.engine) for r in states.values()} == {("done", "ray")}
    one, two = arrays(local_out / "vd006"), arrays(ray_out / "vd006")
    for key in one:
        np.testing.assert_array_equal(one[key], two[key], err_msg=key)
    params = json.loads((ray_out / "vd006" / "params.json").read_text())
    assert params["input"]["path"] == str(two_photos / "vd006.png")  # not the node's scratch copy
    assert not [p for p in ray_out.iterdir() if p.name.startswith(".")]


@pytest.mark.slow
def test_shared_outputs_with_a_worker_killed_mid_task_are_retried(two_photos, tmp_path):
    out = tmp_path / "out"
    process = run_deface("fit", two_photos, "-o", out, *TINY, "--engine", "ray", "--ray-outputs", "shared")
    lock, pid = wait_for_lock(out, process, seconds=600)
    os.kill(pid, signal.SIGKILL)
    assert process.wait(900) == 0, process.stderr.read()
    name = lock.name[1:-len(".lock")]
    records = [r for r in read_records(out) if r.output == name]
    assert [(r.status, r.attempt) for r in records] == [("failed", 1), ("done", 2)]
    assert records[0].error.startswith("Ray worker died: ")
    assert {r.status for r in latest_states(read_records(out)).values()} == {"done"}
    assert sorted(p.name for p in out.iterdir() if p.is_dir()) == ["vd006", "vd092"]


def test_shared_mode_names_an_input_the_node_cannot_see(tmp_path):
    job = Job(InputItem(tmp_path / "driver-only" / "a.png", "image"), tmp_path, presets.get("fast"))
    outcome, archive = ray_task(job, None)
    assert outcome.status == "failed" and archive is None
    assert outcome.error.startswith(f"{job.item.path}: not visible on Ray node ")
    assert "--ray-outputs driver" in outcome.error


def test_a_models_folder_missing_on_the_node_is_named(tmp_path):
    photo = tmp_path / "a.png"
    photo.write_bytes(b"not read")
    job = Job(InputItem(photo, "image"), tmp_path, presets.get("fast"), models=tmp_path / "driver-models")
    outcome, _ = ray_task(job, b"not read")
    assert outcome.status == "failed" and outcome.error.startswith(f"--models {tmp_path / 'driver-models'}: not a "
                                                                   "folder on Ray node ")


def test_missing_ray_is_one_line_naming_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)
    with pytest.raises(RayUnavailable, match=r"pip install 'deface\[ray\]'"):
        _ray()
