"""`deface batch status OUT`: what a batch of `deface fit` did, from OUT/batch.jsonl."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.markup import escape

from deface.batch.record import read_records, record_path, summarise
from deface.fit.log import console


def register(app: typer.Typer) -> None:
    batch = typer.Typer(no_args_is_help=True, help="Batches of `deface fit` (status of an output folder).")
    batch.command("status")(status_command)
    app.add_typer(batch, name="batch")


def status_command(
    output: Path = typer.Argument(..., help="The -o folder of a `deface fit` batch."),
) -> None:
    """Inputs done / failed (with the reason) / found finished, fitting time, presets and versions."""
    if not record_path(output).is_file():
        console.print(f"[red]error:[/red] {escape(str(record_path(output)))}: no batch record (not a `deface fit` "
                      "output folder, or nothing was run yet)")
        raise typer.Exit(2)
    for line in summarise(read_records(output)).lines():
        typer.echo(line)
