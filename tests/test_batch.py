"""Batches (deface/batch): the record, the resume plan and its settings check, the worker pool surviving dead
workers, and real `deface fit --jobs 2` runs: identical to one process, a worker killed with SIGKILL, Ctrl-C
and a resume.

The pool tests use tiny tasks (tests/batch_tasks.py) run by the real pool in real spawned processes; the
end-to-end tests run real tiny fits (64 px, a few dozen steps).
"""

from __future__ import annotations

import functools
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import batch_helpers
import numpy as np
import pytest
from batch_helpers import TINY, arrays, run_deface, wait_for_lock
from PIL import Image
from typer.testing import CliRunner

import deface.batch.task as task
from deface.batch.pool import LocalPool
from deface.batch.record import (
    BatchRecord,
    append_record,
    latest_states,
    read_records,
    record_path,
    summarise,
    tone_text,
)
from deface.batch.recorded import RecordedTask, TaskFailed, run_recorded
from deface.batch.resume import config_record, finished_record, plan_batch, settings_differences
from deface.cli.main import app
from deface.export.files import write_json
from deface.fit import presets
from deface.fit.config import override, to_dict
from deface.io.inputs import list_inputs

REPO = Path(__file__).resolve().parent.parent


def _record(path: str, status: str, attempt: int = 1, error: str | None = None, seconds: float = 1.0):
    return BatchRecord(path=path, output=Path(path).stem, status=status, seconds=seconds, lights_kept=[0],
                       error=error, version="0", preset="fast", attempt=attempt)


# --- the record -----------------------------------------------------------------------------------------


def test_records_round_trip_and_a_torn_line_is_ignored(tmp_path):
    first, second = _record("a.jpg", "failed", error="worker process died: SIGKILL"), _record("a.jpg", "done", 2)
    append_record(tmp_path, first)
    append_record(tmp_path, second)
    with open(record_path(tmp_path), "a") as handle:
        handle.write('{"path": "b.jpg", "status": "do')  # what a full disk could leave
    assert read_records(tmp_path) == [first, second]


def test_state_is_the_last_done_or_failed_and_skipped_only_counts_alone():
    records = [_record("a", "done"), _record("a", "skipped"), _record("b", "done"), _record("b", "failed"),
               _record("c", "skipped"), _record("d", "failed", 1, "died"), _record("d", "done", 2)]
    states = {path: record.status for path, record in latest_states(records).items()}
    assert states == {"a": "done", "b": "failed", "c": "skipped", "d": "done"}
    summary = summarise(records)
    assert (summary.inputs, summary.done, summary.skipped, summary.retried) == (4, 2, 1, 1)
    assert [r.path for r in summary.failed] == ["b"] and summary.fit_seconds == 3.0


@pytest.mark.slow
def test_concurrent_appends_from_processes_keep_whole_lines(tmp_path):
    code = ("import sys; from pathlib import Path; from deface.batch.record import BatchRecord, append_record\n"
            "for i in range(200):\n"
            "    append_record(Path(sys.argv[1]), BatchRecord(path=f'{sys.argv[2]}-{i}' + 'x' * 3000, output='o',"
            " status='done', seconds=1.0, lights_kept=[0, 1], error=None, version='0', preset='p'))\n")
    writers = [subprocess.Popen([sys.executable, "-c", code, str(tmp_path), name], cwd=REPO) for name in "abc"]
    assert all(writer.wait(60) == 0 for writer in writers)
    assert len(read_records(tmp_path)) == 600 == len(record_path(tmp_path).read_text().splitlines())


def test_batch_status_summarises_and_names_failures(tmp_path):
    append_record(tmp_path, _record("in/a.jpg", "done", seconds=30.0))
    append_record(tmp_path, _record("in/b.jpg", "failed", error="in/b.jpg: no face found"))
    result = CliRunner().invoke(app, ["batch", "status", str(tmp_path)])
    assert result.exit_code == 0, result.output
    assert result.output.splitlines()[0].startswith("2 input(s): 1 done, 0 found finished, 1 failed")
    assert "failed: in/b.jpg: in/b.jpg: no face found" in result.output
    missing = CliRunner().invoke(app, ["batch", "status", str(tmp_path / "nothing")])
    assert missing.exit_code == 2 and "no batch record" in missing.output


def test_status_counts_the_done_inputs_tones_by_category_and_how_sure_they_are(tmp_path):
    from dataclasses import replace

    tones = {"a": (62.0, [58.0, 66.0]), "b": (48.0, [40.0, 55.0]), "c": (47.0, [20.0, 60.0]),
             "d": (-35.0, [-50.0, -10.0]), "e": (30.0, None)}
    for name, (ita, interval) in tones.items():
        append_record(tmp_path, replace(_record(f"{name}.jpg", "done"),
                                        skin_tone={"texture_ita": ita, "ita_interval": interval}))
    append_record(tmp_path, _record("f.jpg", "failed", error="no face"))  # no tone: not counted
    append_record(tmp_path, replace(_record("c.jpg", "done"), skin_tone={"texture_ita": 12.0, "ita_interval": [5.0,
                                                                                                              19.0]}))
    lines = summarise(read_records(tmp_path)).tones  # c's last fit (tan, sure) replaces its first
    assert lines[0].endswith("very light 1, light 1, intermediate 1, tan 1, brown 0, dark 1")
    assert lines[1].startswith("3 of 4 within 20 degrees") and "median 14" in lines[1] and len(lines) == 2
    append_record(tmp_path, replace(_record("g.jpg", "done"), skin_tone={
        "texture_ita": 40.0, "ita_interval": [38.0, 42.0], "ita_interval_2sigma": [36.0, 44.0],
        "light_level": "reference card"}))
    append_record(tmp_path, replace(_record("h.jpg", "done"), skin_tone={
        "texture_ita": 20.0, "ita_interval": [5.0, 32.0], "ita_interval_2sigma": [-8.0, 45.0],
        "light_level": "grey world"}))
    lines = summarise(read_records(tmp_path)).tones
    assert "two-sigma median 30" in lines[1]  # (8 + 53) / 2 = 30.5 over the two that record it
    assert lines[2] == "light level from: reference card 1, grey world 1"
    assert summarise([_record("a.jpg", "done")]).tones == []  # records written before the tone was recorded
    grey = {"texture_ita": None, "ita_interval": None, "note": "a grayscale photo shows no skin tone"}
    append_record(tmp_path, replace(_record("i.jpg", "done"), skin_tone=grey))  # not counted as any tone
    assert summarise(read_records(tmp_path)).tones[0].startswith("skin tones of 7 fit(s)")  # a-e, g, h
    assert tone_text(grey) == ", skin tone not shown (grayscale photo)"
    assert tone_text({"texture_ita": 41.6, "ita_interval": [30.2, 50.7]}) == ", skin ITA 42 (30 to 51)"
    assert tone_text({"texture_ita": 41.6, "ita_interval": [41.6, 41.6]}) == ", skin ITA 42"  # a known light
    assert tone_text({"texture_ita": 41.6, "ita_interval": None}) == ", skin ITA 42" and tone_text(None) == ""


# --- resuming -------------------------------------------------------------------------------------------


@pytest.fixture
def two_photos(tmp_path) -> Path:
    folder = tmp_path / "in"
    folder.mkdir()
    for name in ("a", "b"):
        Image.fromarray(np.full((40, 30, 3), 120, np.uint8)).save(folder / f"{name}.png")
    return folder


def _finished(folder: Path, config) -> None:
    """What write_fit records of the settings (params.json's preset and config)."""
    folder.mkdir(parents=True)
    write_json(folder / "params.json", {"preset": config.preset, "config": to_dict(config)})


def test_settings_differences_name_the_preset_and_fields(tmp_path):
    fast = presets.get("fast")
    _finished(tmp_path / "a", fast)
    params = tmp_path / "a" / "params.json"
    assert settings_differences(params, fast) == []
    assert settings_differences(params, override(fast, threads=4)) == []  # does not change the fit
    changed = settings_differences(params, override(fast, **{"iterations.stage2": 7}))
    assert len(changed) == 1 and changed[0].startswith("iterations.stage2 ") and "this run: 7" in changed[0]
    other = settings_differences(params, presets.get("default"))
    assert other[0] == "preset 'fast' (this run: 'deface')" and len(other) > 1


def test_a_bfm_fit_with_its_tone_turned_off_is_the_same_settings(tmp_path):
    """BFM has no tone axis, so its fits record tone.free_tone off; a rerun asking for the default is the same."""
    bfm = override(presets.get("default"), model="bfm")
    _finished(tmp_path / "a", override(bfm, **{"tone.free_tone": False}))
    assert settings_differences(tmp_path / "a" / "params.json", bfm) == []
    ict = presets.get("default")  # an ICT fit with the tone off would be other settings
    _finished(tmp_path / "b", override(ict, **{"tone.free_tone": False}))
    assert settings_differences(tmp_path / "b" / "params.json", ict) != []


def test_resuming_with_other_settings_is_refused_in_one_line(two_photos, tmp_path, monkeypatch):
    out = tmp_path / "out"
    _finished(out / "a", presets.get("fast"))
    monkeypatch.setattr(task, "fit", lambda *a, **k: pytest.fail("nothing may be fitted"))
    result = CliRunner().invoke(app, ["fit", str(two_photos), "-o", str(out), "--preset", "default", "--jobs", "1"])
    lines = result.output.splitlines()
    assert result.exit_code == 2 and len(lines) == 1
    assert lines[0].startswith(f"error: 1 finished output(s) in {out} were made with other settings")
    assert "preset 'fast' (this run: 'deface')" in lines[0] and not (out / "b").exists()


def test_two_inputs_with_one_output_name_are_a_usage_error(two_photos, tmp_path):
    Image.open(two_photos / "a.png").save(tmp_path / "a.jpg")
    result = CliRunner().invoke(app, ["fit", str(two_photos), str(tmp_path / "a.jpg"), "-o", str(tmp_path / "out")])
    assert result.exit_code == 2 and result.output.splitlines() == [
        f"error: {two_photos / 'a.png'} and {tmp_path / 'a.jpg'} would both write OUT/a; rename one, or fit them "
        "into different -o folders"]


def test_retry_failed_redoes_only_the_failures(two_photos, tmp_path):
    out = tmp_path / "out"
    items = list_inputs([two_photos])
    config = presets.get("fast")
    append_record(out, _record(str(two_photos / "a.png"), "failed", error="no face"))
    plan = plan_batch(items, out, config, retry_failed=True)
    assert [i.name for i in plan.todo] == ["a"] and [i.name for i in plan.left] == ["b"]
    assert [i.name for i in plan_batch(items, out, config).todo] == ["a", "b"]  # a plain rerun does all
    _finished(out / "b", config)
    plan = plan_batch(items, out, config)
    assert [i.name for i in plan.todo] == ["a"] and [i.name for i in plan.finished] == ["b"]


def test_retry_failed_on_the_command_line_attempts_only_the_failed_input(two_photos, tmp_path, monkeypatch):
    out, attempted = tmp_path / "out", []

    def no_face(frames, config, source, **_):
        attempted.append(Path(source).name)
        raise ValueError(f"{source}: no face found")

    monkeypatch.setattr(task, "fit", no_face)
    append_record(out, _record(str(two_photos / "a.png"), "failed", error="no face"))
    result = CliRunner().invoke(app, ["fit", str(two_photos), "-o", str(out), "--retry-failed", "--quiet"])
    assert result.exit_code == 1 and attempted == ["a.png"]
    assert "0 of 2 input(s) done, 1 failed, 1 not attempted (--retry-failed)" in result.output.splitlines()[-1]
    result = CliRunner().invoke(app, ["fit", str(two_photos), "-o", str(out), "--quiet", "--jobs", "1"])
    assert attempted == ["a.png", "a.png", "b.png"]  # a plain rerun fits every unfinished input
    assert [r.status for r in read_records(out)] == ["failed"] * 4


# --- the worker pool ------------------------------------------------------------------------------------


class Collect:
    def __init__(self):
        self.events = []

    def started(self, worker, index, attempt):
        self.events.append(("started", index, attempt))

    def progress(self, worker, index, message):
        self.events.append(("progress", index, message))

    def finished(self, worker, index, result, attempt):
        self.events.append(("finished", index, result, attempt))

    def died(self, worker, index, reason, attempt, retry):
        self.events.append(("died", index, reason, attempt, retry))

    def of(self, kind):
        return [event[1:] for event in self.events if event[0] == kind]


def test_pool_retries_a_job_whose_worker_died_once_and_fails_one_that_always_dies(tmp_path):
    jobs = [("a", "ok", tmp_path), ("b", "die-once", tmp_path), ("c", "die", tmp_path), ("d", "ok", tmp_path),
            ("e", "ok", tmp_path)]
    listener = Collect()
    LocalPool(batch_helpers.task, 2, batch_helpers.warm, (tmp_path,)).run(jobs, listener)
    finished = {index: (result[0], attempt) for index, result, attempt in listener.of("finished")}
    assert finished == {0: ("a", 1), 1: ("b", 2), 3: ("d", 1), 4: ("e", 1)}
    died = listener.of("died")
    assert sorted((index, attempt, retry) for index, _, attempt, retry in died) == [(1, 1, True), (2, 1, True),
                                                                             (2, 2, False)]
    assert all(reason == "worker process died: SIGKILL (out of memory, or kill -9)" for _, reason, _, _ in died)
    assert ("progress", 0, "a running") in listener.events
    started_in = {path.name.split(".")[1] for path in tmp_path.glob("*.started")}
    warmed = {path.name.split(".")[1] for path in tmp_path.glob("warm.*")}
    assert started_in <= warmed  # every worker warmed up once before its jobs; 3 deaths -> 5 workers at most
    assert len(warmed) <= 5 and len(started_in) < len(jobs) + 3


def test_pool_workers_run_one_job_at_a_time_and_each_warms_once(tmp_path):
    jobs = [(f"j{i}", "ok", tmp_path) for i in range(6)]
    listener = Collect()
    LocalPool(batch_helpers.task, 2, batch_helpers.warm, (tmp_path,)).run(jobs, listener)
    pids = {result[1] for _, result, _ in listener.of("finished")}
    assert len(listener.of("finished")) == 6 and len(pids) <= 2
    assert {p.name.split(".")[1] for p in tmp_path.glob("warm.*")} == {str(pid) for pid in pids}


def _recorded_tasks(folder: Path, config, fail=()):
    return [RecordedTask(f"t{i}", folder / f"t{i}" / "record.json", config,
                         functools.partial(batch_helpers.recorded, i, i in fail)) for i in range(4)]


@pytest.mark.slow
@pytest.mark.parametrize("jobs", [1, 2])
def test_recorded_tasks_run_once_per_configuration_and_report_in_order(tmp_path, jobs):
    config = override(presets.get("fast"), model="none")  # the workers' warm-up fails at once: only a head start
    seen = []
    records = run_recorded(_recorded_tasks(tmp_path, config), jobs, on_record=lambda i, r: seen.append(i))
    assert [r["value"] for r in records] == [0, 1, 2, 3] and seen == [0, 1, 2, 3]
    pids = {r["pid"] for r in records}
    assert pids == {os.getpid()} if jobs == 1 else len(pids) <= 2 and os.getpid() not in pids
    assert json.loads((tmp_path / "t2" / "record.json").read_text()) == records[2]
    assert records[2]["config"] == config_record(config)
    # A rerun reads the records back; a record made with another configuration is redone.
    stale = tmp_path / "t1" / "record.json"
    stale.write_text(json.dumps({**records[1], "value": -1, "config": config_record(override(config, seed=9))}))
    again = run_recorded(_recorded_tasks(tmp_path, config), jobs)
    assert [r["value"] for r in again] == [0, 1, 2, 3] and again[2:] == records[2:]
    assert again[1]["pid"] == os.getpid()  # the one task left runs in this process, whatever ``jobs``
    # A torn record (a kill mid-write) is redone too, and no partial file is left beside the records.
    (tmp_path / "t3" / "record.json").write_text('{"value": 3, "con')
    assert run_recorded(_recorded_tasks(tmp_path, config), 1)[3]["value"] == 3
    assert not list(tmp_path.rglob("*.partial"))


@pytest.mark.slow
def test_a_failed_recorded_task_fails_the_run_after_the_others(tmp_path):
    config = override(presets.get("fast"), model="none")
    with pytest.raises(TaskFailed, match="(?s)t1 failed: .*ValueError: task 1 fails"):
        run_recorded(_recorded_tasks(tmp_path, config, fail={1}), 2)
    assert [finished_record(tmp_path / f"t{i}" / "record.json", config) is not None for i in range(4)] == \
        [True, False, True, True]


def test_pool_stops_its_workers_when_the_parent_is_interrupted(tmp_path):
    class Interrupting(Collect):
        def progress(self, worker, index, message):
            super().progress(worker, index, message)
            if len(self.of("progress")) == 2:
                raise KeyboardInterrupt

    jobs = [(f"s{i}", "sleep", tmp_path) for i in range(4)]
    with pytest.raises(KeyboardInterrupt):
        LocalPool(batch_helpers.task, 2).run(jobs, Interrupting())
    pids = [int(path.name.split(".")[1]) for path in tmp_path.glob("*.started")]
    assert len(pids) == 2
    for pid in pids:
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)


def test_workers_end_when_their_parent_is_killed(tmp_path):
    code = ("import sys, batch_helpers\nfrom deface.batch.pool import LocalPool\n"
            "class Quiet:\n    def __getattr__(self, name):\n        return lambda *args: None\n"
            "jobs = [(f's{i}', 'sleep', sys.argv[1]) for i in range(4)]\n"
            "LocalPool(batch_helpers.task, 2).run(jobs, Quiet())\n")
    parent = subprocess.Popen([sys.executable, "-c", code, str(tmp_path)], cwd=REPO,
                              env={**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), str(REPO / "tests")])})
    deadline = time.monotonic() + 120
    while len(list(tmp_path.glob("*.started"))) < 2 and time.monotonic() < deadline:
        time.sleep(0.1)
    pids = [int(path.name.split(".")[1]) for path in tmp_path.glob("*.started")]
    assert len(pids) == 2
    parent.kill()
    parent.wait(30)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and any(_alive(pid) for pid in pids):
        time.sleep(0.1)
    assert not any(_alive(pid) for pid in pids)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:
        with open(f"/proc/{pid}/stat") as stat:  # a zombie (exited, not yet reaped by init) counts as gone
            return stat.read().split(")")[-1].split()[0] != "Z"
    except FileNotFoundError:
        return False


# --- real fits ------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def three_photos(photos, tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("three")
    for name in ("000031.jpg", "vd006.png", "nextface-s1.png"):
        (folder / name).symlink_to(photos / name)
    return folder


@pytest.mark.slow
def test_two_workers_give_the_same_results_as_one_process(three_photos, tmp_path):
    """The fit, and the renders and light coefficients written after it, run on the config's threads (here 1) in
    this process as in a worker (whose torch has 1 thread, where this process has one per core): the bits agree."""
    runs = {}
    for jobs in ("1", "2"):
        out = tmp_path / f"jobs{jobs}"
        process = run_deface("fit", three_photos, "-o", out, *TINY, "--jobs", jobs)
        assert process.wait(600) == 0, process.stderr.read()
        runs[jobs] = out
    for name in ("000031", "vd006", "nextface-s1"):
        one, two = arrays(runs["1"] / name), arrays(runs["2"] / name)
        assert one.keys() == two.keys()
        for key in one:
            np.testing.assert_array_equal(one[key], two[key], err_msg=f"{name}: {key}")
        params = [json.loads((runs[j] / name / "params.json").read_text()) for j in ("1", "2")]
        for key in ("identity", "expression", "pose", "lights", "albedo_coefficients", "config"):
            assert params[0][key] == params[1][key], f"{name}: {key}"
    engines = {record.engine for record in read_records(runs["2"])}
    assert engines == {"local"} and {r.engine for r in read_records(runs["1"])} == {"inline"}


@pytest.mark.slow
def test_a_worker_killed_mid_fit_fails_only_its_input_which_is_retried(three_photos, tmp_path):
    out = tmp_path / "out"
    process = run_deface("fit", three_photos, "-o", out, *TINY, "--jobs", "2")
    lock, pid = wait_for_lock(out, process)
    name = lock.name[1:-len(".lock")]
    os.kill(pid, signal.SIGKILL)
    assert process.wait(600) == 0, process.stderr.read()
    records = [r for r in read_records(out) if r.output == name]
    assert [(r.status, r.attempt) for r in records] == [("failed", 1), ("done", 2)]
    assert records[0].error == "worker process died: SIGKILL (out of memory, or kill -9)"
    assert {r.status for r in latest_states(read_records(out)).values()} == {"done"}
    assert sorted(p.name for p in out.iterdir() if p.is_dir()) == ["000031", "nextface-s1", "vd006"]
    assert not [p for p in out.iterdir() if p.name.startswith(".")]


@pytest.mark.slow
def test_ctrl_c_stops_the_workers_cleanly_and_a_rerun_resumes(three_photos, tmp_path):
    out = tmp_path / "out"
    process = run_deface("fit", three_photos, "-o", out, *TINY, "--jobs", "2")
    _, pid = wait_for_lock(out, process)
    process.send_signal(signal.SIGINT)
    assert process.wait(120) == 130
    lines = [line for line in process.stderr.read().splitlines() if line.startswith("interrupted")]
    assert len(lines) == 1 and lines[0].startswith("interrupted (SIGINT) during ")
    assert "run the same command again to resume" in lines[0]
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)  # the worker is gone
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no staging folder, no lock
    done_before = {r.path for r in read_records(out) if r.status == "done"}
    rerun = run_deface("fit", three_photos, "-o", out, *TINY, "--jobs", "2")
    assert rerun.wait(600) == 0, rerun.stderr.read()
    states = latest_states(read_records(out))
    assert len(states) == 3 and {r.status for r in states.values()} <= {"done", "skipped"}
    skipped = {r.path for r in read_records(out) if r.status == "skipped"}
    assert skipped == done_before
    assert sorted(p.name for p in out.iterdir() if p.is_dir()) == ["000031", "nextface-s1", "vd006"]
