"""Batches of `deface fit`: many inputs on every core (worker processes) or on a Ray cluster, surviving
crashed workers, resumable, with a per-input record in ``OUT/batch.jsonl``.

task.py      one input: lock, skip-finished, load, fit, write -> Outcome (the same in every engine)
resume.py    what a rerun does with each input; the check that finished outputs have the same settings
record.py    OUT/batch.jsonl (atomic appends) and its summary (`deface batch status`)
pool.py      spawned worker processes, one job at a time each; a dead worker fails (and retries) only its job
ray_engine.py  the same task as one Ray task per input (optional extra `deface[ray]`)
display.py   the live progress display / one line per input
run.py       the batch: plan, engine, lines, records, signals
recorded.py  tasks that record their result with their configuration (the benchmarks' fits): resumed, on the pool
"""
