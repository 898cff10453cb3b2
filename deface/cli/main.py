"""The `deface` command: one typer app; each sub-command lives in its own module with `register(app)`."""

from __future__ import annotations

import importlib

import typer

app = typer.Typer(
    add_completion=False, no_args_is_help=True, help="Shadow-free 3D face textures from photos and videos."
)

SUBCOMMAND_MODULES = (
    "deface.cli.fit",
    "deface.cli.batch",
    "deface.cli.presets",
    "deface.cli.models",
    "deface.cli.eval",
    "deface.cli.bench",
    "deface.cli.demo",
    "deface.cli.relight",
    "deface.cli.serve",
)

for _name in SUBCOMMAND_MODULES:
    importlib.import_module(_name).register(app)


def main() -> None:
    app()


if __name__ == "__main__":
    main()
