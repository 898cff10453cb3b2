"""`deface demo`: fit a real shadowed photo from ../shared with the embedded face model, end to end."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated

import typer

from deface.fit.log import console
from deface.paths import shared_dir

DEMO_PHOTO = "data/images/real-foliage-shadow-9177-004.png"


def register(app: typer.Typer) -> None:
    app.command("demo")(demo_command)


def demo_command(
    output: Annotated[Path, typer.Option("-o", "--output", help="Output folder.")] = Path("out/demo"),
    preset: Annotated[str, typer.Option(help="Preset to fit with (`deface presets` lists them).")] = "default",
) -> None:
    """Fit a photo with foliage shadows from ../shared/data/images and write everything to OUTPUT."""
    shared = shared_dir()
    if shared is None:
        console.print("[red]error:[/red] the demo needs ../shared beside the checkout (or DEFACE_SHARED); "
                      "use `deface fit PHOTO -o OUT` on your own photo instead")
        raise typer.Exit(2)
    os.environ.setdefault("DEFACE_MODELS", str(shared / "models"))
    from deface.cli.fit import run
    from deface.fit import presets
    from deface.io.inputs import list_inputs

    try:
        config = presets.get(preset)
    except ValueError as error:
        console.print(f"[red]error:[/red] {error}")
        raise typer.Exit(2) from None
    photo = shared / DEMO_PHOTO
    console.print(f"demo: fitting {photo} with preset '{preset}'")
    if run(list_inputs([photo]), output, config, overwrite=True):
        raise typer.Exit(1)
