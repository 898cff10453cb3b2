"""`deface serve`: the local web app (deface/web; optional extra ``deface[web]``)."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape

from deface.cli import options
from deface.cli.fit import EXIT_FAILED, EXIT_USAGE, report_error
from deface.export.files import OutputError, check_writable
from deface.fit.log import console
from deface.paths import ModelFileError

WEB_EXTRA = "deface serve needs the web extra: pip install 'deface[web]' (Gradio)"


def register(app: typer.Typer) -> None:
    app.command("serve", epilog=options.settings_help())(serve_command)


def serve_command(
    output: Annotated[Path, typer.Option("-o", "--output", help="Folder for the uploads, fits, zips and Gradio's "
                                         "files (created); the app's files go nowhere else (docs/web.md).")]
    = Path("deface-web"),
    host: Annotated[str, typer.Option(help="Address to listen on; 0.0.0.0 opens it to other machines.")]
    = "127.0.0.1",
    port: Annotated[int, typer.Option(help="Port to listen on.")] = 7860,
    models: options.Models = None,
    workers: Annotated[int, typer.Option("--workers", "-j", help="Fits at once, each in its own worker process "
                                         "with 1 torch thread (0 = one per core); a job's photos share them, jobs "
                                         "wait in turn.")] = 0,
    iterations: options.Iterations = None,
    resolution: options.Resolution = None,
    texture_size: options.TextureSize = None,
    sets: options.Set = None,
    max_file_mb: Annotated[float, typer.Option("--max-file-mb", help="Largest upload accepted (MB per file).")]
    = 100.0,
    max_files: Annotated[int, typer.Option("--max-files", help="Most files in one job.")] = 16,
    keep_jobs: Annotated[int | None, typer.Option("--keep-jobs", help="Keep only the newest N finished jobs' "
                                                  "folders (a public demo's disk; default: keep all).")] = None,
) -> None:
    """A web page to drop photos or a clip on, watch the fit, turn the textured head in 3D, relight it and download
    the results (the same files as `deface fit`). The operator's --iterations, --resolution, --texture-size and --set
    apply to every fit, on top of the preset chosen in the page."""
    if importlib.util.find_spec("gradio") is None:  # not imported here: serve.py sets its environment first
        console.print(f"[red]error:[/red] {escape(WEB_EXTRA)}")
        raise typer.Exit(EXIT_FAILED)
    from deface.models.registry import require_face_model
    from deface.web.config import WebConfig
    from deface.web.serve import serve

    config = WebConfig(output=output, host=host, port=port, models=models, workers=workers, iterations=iterations,
                       resolution=resolution, texture_size=texture_size, settings=tuple(sets or ()),
                       max_file_mb=max_file_mb, max_files=max_files, keep_jobs=keep_jobs)
    try:
        config.check()
    except (ValueError, OSError) as error:
        report_error(error)
        raise typer.Exit(EXIT_USAGE) from None
    try:
        require_face_model(config.fit_config(config.presets[0]).model, models)
        check_writable(output)
    except (ModelFileError, OutputError) as error:
        report_error(error)
        raise typer.Exit(EXIT_FAILED) from None
    try:
        serve(config, announce=console.print)
    except OSError as error:  # the port is taken, the address cannot be bound
        reason = error.strerror or str(error).split(".")[0]
        report_error(OSError(f"cannot serve on {host}:{port} ({reason}); another --port or --host?"))
        raise typer.Exit(EXIT_FAILED) from None
