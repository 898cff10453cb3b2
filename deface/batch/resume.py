"""What a (re)run of a batch does with each input: fit it, skip it (finished), or leave it (``--retry-failed``
redoes only the inputs whose last record is a failure); and the check that finished outputs were made with
the same settings, so a resumed batch never silently mixes presets or configs.

The benchmarks' fits (:mod:`deface.batch.recorded`) resume by the same rule with one difference: a task whose
record was made with another configuration is redone (a benchmark measures the current settings), where a
batch refuses to mix them.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from deface.batch.record import latest_states, read_records
from deface.batch.task import finished_params
from deface.fit.config import FitConfig, differences, from_dict, supports_free_tone, to_dict
from deface.io.inputs import InputItem

# Config fields that do not change what is fitted: torch threads (a batch worker runs with 1).
IGNORED_SETTINGS = ("threads",)


class SettingsMismatch(ValueError):
    """Finished outputs in OUT were made with other settings than this run's (one line)."""


class SameOutput(ValueError):
    """Two inputs would write the same output folder (same file stem); one line."""


@dataclass(frozen=True)
class Plan:
    """The inputs of a run, split by what happens to them."""

    todo: list[InputItem]  # to fit
    finished: list[InputItem]  # output complete: skipped (recorded as such)
    left: list[InputItem]  # unfinished but not attempted: --retry-failed and no failure recorded


def plan_batch(items: list[InputItem], output: Path, config: FitConfig, overwrite: bool = False,
               retry_failed: bool = False) -> Plan:
    """Split ``items``; raises :class:`SettingsMismatch` when finished outputs have other settings
    (unless ``overwrite``, which redoes everything). A plain rerun fits every unfinished input;
    ``retry_failed`` only those whose last record in ``OUT/batch.jsonl`` is a failure."""
    check_distinct_outputs(items)
    if overwrite:
        return Plan(list(items), [], [])
    states = latest_states(read_records(output))
    failed = {path for path, record in states.items() if record.status == "failed"}
    todo, finished, left, mismatched = [], [], [], []
    for item in items:
        params = finished_params(output / item.name)
        if params is not None:
            finished.append(item)
            differences = settings_differences(params, config)
            if differences:
                mismatched.append((params, differences))
        elif retry_failed and str(item.path) not in failed:
            left.append(item)
        else:
            todo.append(item)
    if mismatched:
        params, differences = mismatched[0]
        raise SettingsMismatch(
            f"{len(mismatched)} finished output(s) in {output} were made with other settings (e.g. {params}: "
            f"{'; '.join(differences[:4])}); rerun with the same settings, use --overwrite to redo them, "
            f"or write to another -o")
    return Plan(todo, finished, left)


def config_record(config: FitConfig) -> dict:
    """The configuration as a record stores it and reads it back from JSON (tuples become lists)."""
    return json.loads(json.dumps(to_dict(config)))


def finished_record(path: Path, config: FitConfig) -> dict | None:
    """The JSON record at ``path`` when its task finished with this very configuration (its ``config`` is
    :func:`config_record` of ``config``), else None: the task is (re)done."""
    try:
        record = json.loads(path.read_text())
    except (FileNotFoundError, json.JSONDecodeError):  # not made yet, or torn by a writer older than run_task's
        return None
    return record if isinstance(record, dict) and record.get("config") == config_record(config) else None


def check_distinct_outputs(items: list[InputItem]) -> None:
    """Each input's output is OUT/<stem>: two inputs with one stem would overwrite (or skip) each other."""
    seen: dict[str, InputItem] = {}
    for item in items:
        other = seen.setdefault(item.name, item)
        if other is not item:
            raise SameOutput(f"{other.path} and {item.path} would both write OUT/{item.name}; rename one, or fit "
                             "them into different -o folders")


def settings_differences(params_file: Path, config: FitConfig) -> list[str]:
    """How the preset/config recorded in a finished ``params.json`` differs from ``config`` ([] = same).

    A params.json without a config (not written by ``deface fit``) cannot be compared and is accepted.
    """
    try:
        recorded = json.loads(params_file.read_text())
    except (OSError, ValueError):
        return [f"unreadable {params_file.name}"]
    if not isinstance(recorded, dict) or "config" not in recorded:
        return []
    try:
        made = from_dict(recorded["config"])
    except (ValueError, TypeError) as error:
        return [f"a config this version cannot read ({str(error).splitlines()[0]})"]
    config = supports_free_tone(config)  # what the fits recorded for a model without a tone axis
    changed = []
    if made.preset != config.preset:
        changed.append(f"preset '{made.preset}' (this run: '{config.preset}')")
    for path, (now, then) in differences(config, made).items():
        if path.split(".")[0] not in IGNORED_SETTINGS and path != "preset":
            changed.append(f"{path} {then} (this run: {now})")
    return changed
