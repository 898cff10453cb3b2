"""`deface presets`: every preset with its one-line description and the settings where it differs from the
default preset, whose values are FitConfig's defaults (deface/fit/presets.py lists each preset as those
differences)."""

from __future__ import annotations

from typing import Annotated

import typer
from rich.markup import escape

from deface.cli.options import show_value
from deface.fit import presets
from deface.fit.config import differences
from deface.fit.log import console


def register(app: typer.Typer) -> None:
    app.command("presets")(presets_command)


def presets_command(
    name: Annotated[str | None, typer.Argument(help="Show only this preset.")] = None,
) -> None:
    """List the presets (`--preset NAME`): what each is for and its settings that differ from the default."""
    default = presets.get("default")
    chosen = list(presets.PRESETS) if name is None else [presets.DEFAULT_PRESET if name == "default" else name]
    if name is not None and chosen[0] not in presets.PRESETS:
        console.print(f"[red]error:[/red] unknown preset '{escape(name)}' (choose from: {', '.join(presets.names())})")
        raise typer.Exit(2)
    for key in chosen:
        is_default = key == presets.DEFAULT_PRESET
        title = f"{key} (the default)" if is_default else key
        console.print(f"[bold]{escape(title)}[/bold]: {escape(presets.DESCRIPTIONS[key])}")
        if is_default:
            console.print("    the defaults of every setting (`deface fit --help` lists them)", highlight=False)
            continue
        changed = {path: values for path, values in differences(presets.get(key), default).items() if path != "preset"}
        if not changed:
            console.print("    same settings as the default")
        for path, (mine, theirs) in changed.items():
            line = f"    {path} = {show_value(mine)}  (the default: {show_value(theirs)})"
            console.print(escape(line), highlight=False)
