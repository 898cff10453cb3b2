"""Batch throughput and a kill-and-resume check of `deface fit --jobs N` (BENCHMARKS.md, "Batches").

    DEFACE_MODELS=../shared/models python benchmarks/batch_throughput.py ../shared/data/images OUT kill-resume
    DEFACE_MODELS=../shared/models python benchmarks/batch_throughput.py ../shared/data/images OUT throughput [N]

kill-resume: `--jobs 2` on every photo, the driver killed with SIGKILL once half the inputs are recorded
  done (its workers are told by the kernel and remove their staged outputs), then the same command again;
  checks that every input ends with a complete output and that OUT/batch.jsonl agrees.
throughput: `--jobs 2`, then `--jobs 1`, each into a fresh folder, on the first N photos (default all);
  inputs per hour from the wall time, and the CPU seconds per input from batch.jsonl.
The machine's load average is kept before and after each run (the machine may be shared).
Results go to OUT/results.json (one key per part) and a markdown table is printed.
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
            "mean_cpu_seconds": _mean([r.cpu_seconds for r in states.values() if r.cpu_seconds]),
            "load_before": load, "load_after": _load()}


def _mean(values: list[float]) -> float | None:
    return round(sum(values) / len(values), 1) if values else None


def _subset(images: Path, out: Path, count: int | None) -> Path:
    """A folder of links to the first ``count`` inputs (all when None)."""
    if count is None:
        return images
    folder = out / f"first{count}"
    folder.mkdir(parents=True, exist_ok=True)
    for item in list_inputs([images])[:count]:
        link = folder / item.path.name
        if not link.exists():
            link.symlink_to(item.path.resolve())
    return folder


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
    images, out, part = Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3]
    out.mkdir(parents=True, exist_ok=True)
    results_file = out / "results.json"
    results = json.loads(results_file.read_text()) if results_file.exists() else {}
    results["cpus"] = os.cpu_count()
    if part == "kill-resume":
        results["kill_resume"] = _kill_and_resume(images, out / "kill-resume", len(list_inputs([images])))
        print(json.dumps(results["kill_resume"], indent=1))
    else:
        count = int(sys.argv[4]) if len(sys.argv) > 4 else None
        subset = _subset(images, out, count)
        results[f"throughput-{count or 'all'}"] = runs = [_run(subset, out / f"jobs{j}-{count or 'all'}", j)
                                                          for j in (2, 1)]
        print("| --jobs | inputs | wall time (s) | inputs/hour | mean s per input | mean CPU s per input | "
              "load before -> after |")
        print("| --- | --- | --- | --- | --- | --- | --- |")
        for run in runs:
            print(f"| {run['jobs']} | {run['done']} done, {run['failed']} failed | {run['seconds']} | "
                  f"{run['inputs_per_hour']} | {run['mean_fit_seconds']} | {run['mean_cpu_seconds']} | "
                  f"{run['load_before']} -> {run['load_after']} |")
    results_file.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
