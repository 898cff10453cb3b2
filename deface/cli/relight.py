"""`deface relight`, `deface turntable`, `deface transfer`, `deface report`: re-using finished fits (loaded with
deface.export.load.load_fit; deface/relight, deface/report)."""

from __future__ import annotations

from pathlib import Path

import typer

from deface.cli.fit import EXIT_FAILED, EXIT_USAGE, report_error
from deface.export.load import FitFormatError, load_fit
from deface.fit.log import console
from deface.relight.lights import PRESETS, LightSourceError, light_source, rotate_lights, yaw_matrix

LIGHT_HELP = (f"A preset ({', '.join(PRESETS)}), an SH file (.npy/.json, [K, B*B, 3]; a deface params.json "
              "uses its kept lights) or an equirectangular environment map (.hdr, .exr, or an 8-bit image).")


def register(app: typer.Typer) -> None:
    app.command("relight")(relight_command)
    app.command("turntable")(turntable_command)
    app.command("transfer")(transfer_command)
    app.command("report")(report_command)


def report_command(
    fit: Path = typer.Argument(..., help="A fit's output folder."),
    models: Path | None = typer.Option(None, "--models", help="Model files folder."),
) -> None:
    """Load a fit and (re)write its report.html (deface fit writes one for every fit)."""
    from deface.report.html import write_report

    loaded = _load(fit, models)
    console.print(f"{fit}: {write_report(loaded, fit, fit.name)}")


def relight_command(
    fit: Path = typer.Argument(..., help="A fit's output folder (OUT/<input name> of `deface fit`)."),
    output: Path = typer.Option(..., "-o", "--output", help="Folder for render.png and render_face.png."),
    light: str = typer.Option("studio", "--light", help=LIGHT_HELP),
    rotate_light: float = typer.Option(0.0, "--rotate-light", help="Turn the light about the vertical axis by "
                                       "this many degrees (positive: towards the subject's left)."),
    exposure: float = typer.Option(0.0, "--exposure", help="Scale the light by 2**EV."),
    models: Path | None = typer.Option(None, "--models", help="Model files folder."),
) -> None:
    """The fitted face under new light: composited into the photo, and alone with alpha."""
    from deface.relight.render import write_renders

    loaded = _load(fit, models)
    lights = _lights(light, loaded.lights.bands, rotate_light, exposure)
    write_renders(loaded, loaded.render(lights=lights), _folder(output), lights)
    console.print(f"{fit}: relit ({light}) -> {output}")


def turntable_command(
    fit: Path = typer.Argument(..., help="A fit's output folder."),
    output: Path = typer.Option(..., "-o", "--output", help="The animation: .mp4 or .gif."),
    light: str = typer.Option("studio", "--light", help=LIGHT_HELP),
    rotate_light: float = typer.Option(0.0, "--rotate-light", help="Turn the light first (degrees)."),
    exposure: float = typer.Option(0.0, "--exposure", help="Scale the light by 2**EV."),
    yaw: float = typer.Option(90.0, "--yaw", help="Yaw range in degrees (the head swings -yaw/2 .. +yaw/2)."),
    frames: int = typer.Option(36, "--frames", help="Frames in one loop (2-1000)."),
    fps: float = typer.Option(24.0, "--fps", help="Frames per second."),
    scale: float = typer.Option(1.0, "--scale", help="Image size relative to the fit's working image (0.25-8)."),
    frame: int = typer.Option(0, "--frame", help="Which fitted frame's mesh (a clip's)."),
    models: Path | None = typer.Option(None, "--models", help="Model files folder."),
) -> None:
    """The textured mesh turning under a light fixed relative to the camera."""
    from deface.relight.turntable import turntable_frames, write_animation

    if not 2 <= frames <= 1000 or not 0.25 <= scale <= 8 or fps <= 0 or output.suffix.lower() not in (
            ".mp4", ".mov", ".mkv", ".gif"):
        report_error(ValueError("--frames must be 2-1000, --scale 0.25-8, --fps > 0, and -o end in .mp4 or .gif"))
        raise typer.Exit(EXIT_USAGE)
    loaded = _load(fit, models)
    lights = _lights(light, loaded.lights.bands, rotate_light, exposure)
    try:
        images = turntable_frames(loaded, lights, yaw, frames, frame, scale)
        write_animation(images, output, fps)
    except (ValueError, OSError) as error:
        report_error(error)
        raise typer.Exit(EXIT_FAILED) from None
    console.print(f"{fit}: turntable of {frames} frames -> {output}")


def transfer_command(
    source: Path = typer.Argument(..., help="The fit whose textures are used."),
    target: Path = typer.Argument(..., help="The fit whose geometry, pose, lights and masks are used."),
    output: Path = typer.Option(..., "-o", "--output", help="Folder for render.png and render_face.png."),
    models: Path | None = typer.Option(None, "--models", help="Model files folder."),
) -> None:
    """The target's geometry, pose and lights with the source's textures (the evaluation's texture swap)."""
    from deface.relight.render import write_renders
    from deface.relight.transfer import transfer_renders

    source_fit, target_fit = _load(source, models), _load(target, models)
    try:
        renders = transfer_renders(source_fit, target_fit)
    except ValueError as error:
        report_error(error)
        raise typer.Exit(EXIT_FAILED) from None
    write_renders(target_fit, renders, _folder(output))
    console.print(f"{source} textures on {target} -> {output}")


def _load(path: Path, models: Path | None):
    try:
        return load_fit(path, models)
    except (FitFormatError, OSError) as error:
        report_error(error)
        raise typer.Exit(EXIT_FAILED) from None


def _lights(source: str, bands: int, rotate: float, exposure: float):
    try:
        lights = light_source(source, bands)
    except LightSourceError as error:
        report_error(error)
        raise typer.Exit(EXIT_USAGE) from None
    if rotate:
        lights = rotate_lights(lights, yaw_matrix(rotate))
    return lights * 2.0**exposure


def _folder(output: Path) -> Path:
    output.mkdir(parents=True, exist_ok=True)
    return output
