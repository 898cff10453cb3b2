"""`deface models list|check|build|fetch`: what is installed, what is missing and where to get it."""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.table import Table

from deface.models import registry
from deface.paths import models_dir_candidates

console = Console()
err_console = Console(stderr=True)

models_app = typer.Typer(no_args_is_help=True, help="Face-model files: list, check, build, fetch.")

Names = Annotated[list[str] | None, typer.Argument(help="Keys or groups to require (e.g. bfm); default: all.")]
From = Annotated[Path, typer.Option("--from", help="ICT-FaceKit checkout (or its FaceXModel folder).")]
Models = Annotated[Path | None, typer.Option("--models", help="Models directory (else DEFACE_MODELS, else the user "
                                                               "cache).")]


def register(app: typer.Typer) -> None:
    app.add_typer(models_app, name="models")


def _fail(message: str, code: int = 1) -> None:
    err_console.print(f"error: {message}", markup=False, highlight=False, soft_wrap=True)
    raise typer.Exit(code)


def _select(names: list[str] | None) -> list[registry.ModelFile]:
    try:
        return registry.select(names or [])
    except KeyError as error:
        _fail(str(error.args[0]))
        raise  # unreachable; keeps type checkers quiet


def _table(statuses: list[registry.FileStatus], show_checksum: bool) -> Table:
    table = Table(title="deface model files")
    for column in ("key", "file", "status", "required", "licence", "source / where from"):
        table.add_column(column, overflow="fold")
    if show_checksum:
        table.add_column("sha256")
    for st in statuses:
        found = f"[green]found[/green] {st.path}" if st.path else f"[red]missing[/red] -> {st.target}"
        row = [
            st.entry.key,
            st.entry.relative_path,
            found,
            "yes" if st.entry.required else "optional",
            st.entry.licence,
            st.entry.source,
        ]
        if show_checksum:
            row.append(st.checksum)
        table.add_row(*row)
    return table


@models_app.command("list")
def list_files(models: Models = None) -> None:
    """Show every known model file: found or missing, licence, where it comes from."""
    statuses = [registry.status(e, models) for e in registry.MODEL_FILES]
    console.print(_table(statuses, show_checksum=False))
    console.print("searched: " + ", ".join(str(d) for d in models_dir_candidates(models)), highlight=False)
    _bfm_report(models)


def _bfm_report(models: Path | None) -> str | None:
    """Print what `fit --model bfm` would use; returns the problem that would stop it, if any."""
    from deface.models.bfm import setup_report

    try:
        lines, problem = setup_report(models)
    except (OSError, ValueError) as error:  # an unreadable h5 file or broken metadata
        lines, problem = [], str(error)
    for line in lines:
        console.print(line, markup=False, highlight=False, soft_wrap=True)
    return problem


@models_app.command("check")
def check(
    names: Names = None,
    models: Models = None,
) -> None:
    """Verify files and checksums; exit 1 when a required (or named) file is missing or corrupt."""
    entries = _select(names)
    statuses = [registry.status(e, models, verify=True) for e in entries]
    console.print(_table(statuses, show_checksum=True))
    problems = [st.problem for st in statuses if st.problem and (st.entry.required or names)]
    if any(st.entry.group == "bfm" for st in statuses):
        bfm_problem = _bfm_report(models)
        if bfm_problem and names:
            problems.append(bfm_problem)
    for st in statuses:
        if st.problem and not (st.entry.required or names):
            console.print(f"note (optional): {st.problem}", markup=False, highlight=False, soft_wrap=True)
    if problems:
        for problem in problems:
            err_console.print(f"error: {problem}", markup=False, highlight=False, soft_wrap=True)
        raise typer.Exit(1)


@models_app.command("build")
def build(
    name: Annotated[str, typer.Argument(help="What to build: ict.")],
    source: From,
    models: Models = None,
) -> None:
    """Build a model pack from upstream files (ict: the face-area npz from ICT-FaceKit's OBJs)."""
    if name != "ict":
        _fail(f"cannot build '{name}'; only 'ict' is built (BFM/AlbedoMM h5 files are read directly)")
    from deface.models.ict_build import BuildError, build_ict_pack, save_pack

    target = models_dir_candidates(models)[0] / registry.model_file("ict").relative_path
    try:
        with console.status("reading ICT-FaceKit OBJs") as spinner:
            arrays = build_ict_pack(source, progress=lambda n: spinner.update(f"reading {n}.obj"))
    except BuildError as error:
        _fail(str(error))
    save_pack(arrays, target)
    console.print(f"wrote {target}", highlight=False)


@models_app.command("fetch")
def fetch(
    name: Annotated[str, typer.Argument(help="What to fetch: ict (the only freely downloadable model).")],
    models: Models = None,
    url: Annotated[str | None, typer.Option(help="Override the download URL (zip of the repository).")] = None,
    timeout: Annotated[float, typer.Option(help="Seconds before giving up on an unreachable server.")] = 10.0,
) -> None:
    """Download the public ICT-FaceKit repository and build the pack (needs internet)."""
    if name != "ict":
        entry = next((e for e in registry.MODEL_FILES if e.key == name or e.group == name), None)
        hint = f"; get it manually: {entry.source}" if entry else ""
        _fail(f"'{name}' cannot be fetched automatically (licence/registration){hint}")
    from deface.models.ict_build import (
        UPSTREAM_ZIP_URL,
        BuildError,
        FetchError,
        build_ict_pack,
        fetch_upstream,
        save_pack,
    )

    target = models_dir_candidates(models)[0] / registry.model_file("ict").relative_path
    target.parent.mkdir(parents=True, exist_ok=True)
    try:
        with tempfile.TemporaryDirectory(dir=target.parent) as tmp, console.status("downloading") as spinner:
            obj_dir = fetch_upstream(
                tmp,
                url or UPSTREAM_ZIP_URL,
                timeout,
                progress=lambda n: spinner.update(f"downloading: {n / 1e6:.0f} MB"),
            )
            spinner.update("building the face-area pack")
            save_pack(build_ict_pack(obj_dir), target)
    except (FetchError, BuildError) as error:
        _fail(str(error))
    console.print(f"wrote {target}", highlight=False)
