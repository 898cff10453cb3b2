"""The `deface` command: one typer app; each sub-command lives in its own module."""

from __future__ import annotations

import typer

app = typer.Typer(add_completion=False, no_args_is_help=True, help="Shadow-free 3D face textures from photos and videos.")


def main() -> None:
    app()
