"""Batch throughput and a kill-and-resume check of `deface fit --jobs N` (BENCHMARKS.md, "Batches").

    DEFACE_MODELS=../shared/models python benchmarks/batch_throughput.py ../shared/data/images /tmp/batchbench

1. kill-resume: `--jobs 2` on every photo, the driver killed with SIGKILL once half the inputs are recorded
   done (its workers are told by the kernel and remove their staged outputs), then the same command again;
   checks that every input ends with a complete output and that OUT/batch.jsonl agrees.
2. throughput: `--jobs 2`, then `--jobs 1`, each into a fresh folder; inputs per hour from the wall time.
The machine's load average is printed before and after each run (the machine may be shared).
Writes OUT/results.json and prints a markdown table.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from deface.batch.record import latest_states, read_records
from deface.io.inputs import list_inputs

FIT = ["--preset", "fast", "--quiet"]


def _command(images: Path, out: Path, jobs: int) -> list[str]:
    return [sys.executable, "-m", "deface.cli.main", "fit", str(images), "-o", str(out), "--jobs", str(jobs), *FIT]


def _load() -> str:
    return " ".join(Path("/proc/loadavg").read_text().split()[:3])


def _run(images: Path, out: Path, jobs: int) -> dict:
    load, started = _load(), time.monotonic()
    done = subprocess.run(_command(images, out, jobs), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    seconds = time.monotonic() - started
    states = latest_states(read_records(out))
    return {"jobs": jobs, "exit": done.returncode, "seconds": round(seconds, 1),
            "done": sum(r.status == "done" for r in states.values()),
            "failed": sum(r.status == "failed" for r in states.values()),
            "inputs_per_hour": round(len(states) * 3600 / seconds, 1),
            "mean_fit_seconds": round(sum(r.seconds for r in states.values()) / max(1, len(states)), 1),
            "load_before": load, "load_after": _load()}


def _kill_and_resume(images: Path, out: Path, total: int) -> dict:
    process = subprocess.Popen(_command(images, out, 2), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                               start_new_session=True)
    while process.poll() is None:
        if sum(r.status == "done" for r in read_records(out)) >= total // 2:
            process.send_signal(signal.SIGKILL)
            break
        time.sleep(0.5)
    process.wait()
    time.sleep(2)  # the workers' SIGTERM cleanup
    orphans = subprocess.run(["pgrep", "-s", str(process.pid)], capture_output=True, text=True).stdout.split()
    leftovers = sorted(p.name for p in out.iterdir() if p.name.startswith("."))
    done_at_kill = sum(r.status == "done" for r in read_records(out))
    resumed = _run(images, out, 2)
    states = latest_states(read_records(out))
    complete = sum((out / name / "params.json").is_file() for name in {i.name for i in list_inputs([images])})
    return {"done_at_kill": done_at_kill, "workers_left_after_kill": len(orphans),
            "dot_files_after_kill": leftovers, "resumed": resumed, "complete_outputs": complete,
            "recorded_inputs": len(states), "states": sorted({r.status for r in states.values()}),
            "skipped_on_resume": sum(r.status == "skipped" for r in read_records(out)),
            "leftovers_at_end": sorted(p.name for p in out.iterdir() if p.name.startswith("."))}


def main() -> None:
    images, out = Path(sys.argv[1]), Path(sys.argv[2])
    total = len(list_inputs([images]))
    out.mkdir(parents=True, exist_ok=True)
    results = {"inputs": total, "cpus": os.cpu_count()}
    results["kill_resume"] = _kill_and_resume(images, out / "kill-resume", total)
    print(json.dumps(results["kill_resume"], indent=1), flush=True)
    results["throughput"] = [_run(images, out / f"jobs{jobs}", jobs) for jobs in (2, 1)]
    (out / "results.json").write_text(json.dumps(results, indent=1))
    print("| --jobs | wall time (s) | inputs/hour | mean s per input | done | failed | load before -> after |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for run in results["throughput"]:
        print(f"| {run['jobs']} | {run['seconds']} | {run['inputs_per_hour']} | {run['mean_fit_seconds']} | "
              f"{run['done']} | {run['failed']} | {run['load_before']} -> {run['load_after']} |")


if __name__ == "__main__":
    main()
