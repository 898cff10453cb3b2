"""`deface fit INPUT... -o OUT`: photos, folders of photos and clips -> textures, mesh, lights, renders."""

from __future__ import annotations

import traceback
from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape

from deface.batch.ray_engine import RayUnavailable
from deface.batch.resume import SameOutput, SettingsMismatch
from deface.batch.run import BatchOptions, Interrupted, run_batch
from deface.batch.task import error_message
from deface.cli import options
from deface.export.files import OutputError, check_writable
from deface.fit import user_options
from deface.fit.config import FitConfig
from deface.fit.log import console
from deface.io.images import InputError
from deface.io.inputs import InputItem, list_inputs, person_input
from deface.models.registry import require_face_model
from deface.paths import ModelFileError

EXIT_FAILED, EXIT_USAGE = 1, 2


def register(app: typer.Typer) -> None:
    app.command("fit", epilog=options.settings_help())(fit_command)


def fit_command(
    inputs: Annotated[list[Path], typer.Argument(help="Images, folders of images, or videos.")],
    output: Annotated[Path, typer.Option("-o", "--output", help="Output folder; one sub-folder per input.")],
    preset: options.Preset = None,
    config_file: options.ConfigFile = None,
    sets: options.Set = None,
    models: options.Models = None,
    model: options.Model = None,
    seed: options.Seed = None,
    lights: options.Lights = None,
    bands: options.Bands = None,
    light_masks: options.LightMasks = None,
    face_region: options.FaceRegion = None,
    priors: options.Priors = None,
    resolution: options.Resolution = None,
    texture_size: options.TextureSize = None,
    iterations: options.Iterations = None,
    max_frames: options.MaxFrames = None,
    frame_stride: options.FrameStride = None,
    face_index: options.FaceIndex = None,
    threads: options.Threads = None,
    card: options.Card = None,
    card_reflectance: options.CardReflectance = None,
    card_facing: options.CardFacing = None,
    white: options.White = None,
    checker: options.Checker = None,
    person: Annotated[str | None, typer.Option("--person", help="The inputs are photos of one person (a clip's "
                                               "frames count as photos): fit them as one, into OUT/PERSON/ (one "
                                               "shape and one set of maps; pose, expression, lights, masks and "
                                               "white level per photo).")] = None,
    people: Annotated[bool, typer.Option("--people", help="Each input is a folder of photos of one person, fitted "
                                         "as one into OUT/<folder name>/ (as --person).")] = False,
    overwrite: Annotated[bool, typer.Option(help="Redo inputs whose outputs already exist (default: skip them).")]
    = False,
    quiet: Annotated[bool, typer.Option(help="Only errors and a summary.")] = False,
    verbose: Annotated[bool, typer.Option(help="Print the full details (traceback, tool output) of each error.")]
    = False,
    jobs: Annotated[int, typer.Option("--jobs", "-j", help="Inputs fitted at once, each in its own worker process "
                                      "with 1 torch thread (0 = one per core; 1 = one after another in this "
                                      "process).")] = 0,
    retry_failed: Annotated[bool, typer.Option("--retry-failed", help="Redo only the inputs whose last record in "
                                               "OUT/batch.jsonl is a failure (a plain rerun fits every unfinished "
                                               "input).")] = False,
    engine: Annotated[str, typer.Option(help="local (this machine) or ray (a Ray cluster; pip install "
                                             "'deface[ray]').")] = "local",
    ray_address: Annotated[str | None, typer.Option("--ray-address", help="Ray cluster to join (default: "
                                                    "RAY_ADDRESS, else a local Ray started for this run).")] = None,
    ray_outputs: Annotated[str, typer.Option("--ray-outputs", help="driver: tasks return the outputs and this "
                                             "machine writes them (safe default); shared: tasks write to OUT "
                                             "directly (OUT and the inputs must be on a filesystem every node "
                                             "sees).")] = "driver",
) -> None:
    """Fit each input and write OUT/<input stem>/ (textures, mesh.obj/.mtl/.glb, params, renders, masks)."""
    try:
        user_options.check_output(output)
        user_options.check_models_dir(models)
        config = user_options.fit_config(
            preset, config_file, sets, model=model, seed=seed, lights=lights, bands=bands, light_masks=light_masks,
            face_region=face_region, priors=priors, resolution=resolution, texture_size=texture_size,
            iterations=iterations, max_frames=max_frames, frame_stride=frame_stride, face_index=face_index,
            threads=threads, card=card, card_reflectance=card_reflectance, card_facing=card_facing, white=white,
            checker=checker,
        )
        batch = _batch_options(jobs, engine, ray_address, ray_outputs, overwrite, retry_failed, quiet, verbose)
        items = people_inputs(inputs, person, people)
    except (InputError, ValueError, OSError) as error:
        report_error(error)
        raise typer.Exit(EXIT_USAGE) from None
    try:
        require_face_model(config.model, models)
        check_writable(output)
    except (ModelFileError, OutputError) as error:
        report_error(error)
        raise typer.Exit(EXIT_FAILED) from None
    if run(items, output, config, models, batch=batch):
        raise typer.Exit(EXIT_FAILED)


def people_inputs(inputs: list[Path], person: str | None, people: bool) -> list[InputItem]:
    """The inputs as fits: one per file (default), all of them as one person (``--person``), or one person per
    folder (``--people``)."""
    if person is not None and people:
        raise user_options.UsageError("--person and --people: give one (--people names each person by its folder)")
    if person is not None:
        return [person_input(person, list_inputs(inputs))]
    if not people:
        return list_inputs(inputs)
    files = [str(path) for path in inputs if not path.is_dir()]
    if files:
        raise InputError(f"--people takes folders, one per person: {', '.join(files)}")
    return [person_input(folder.resolve().name, list_inputs([folder])) for folder in inputs]


def _batch_options(jobs, engine, ray_address, ray_outputs, overwrite, retry_failed, quiet, verbose) -> BatchOptions:
    user_options.check_ranges({"--jobs": jobs})
    user_options.check_choice("--engine", engine, ("local", "ray"))
    user_options.check_choice("--ray-outputs", ray_outputs, ("driver", "shared"))
    if engine != "ray" and ray_address:
        raise user_options.UsageError("--ray-address needs --engine ray")
    return BatchOptions(jobs=jobs, overwrite=overwrite, retry_failed=retry_failed, quiet=quiet, verbose=verbose,
                        engine=engine, ray_address=ray_address, ray_outputs=ray_outputs)


def report_error(error: BaseException, verbose: bool = False) -> None:
    """One line on stderr (markup-safe); with ``verbose`` the traceback and chained causes first."""
    if verbose:
        console.print("".join(traceback.format_exception(error)).rstrip(), markup=False)
    console.print(f"[red]error:[/red] {escape(error_message(error))}")


def run(items: list[InputItem], output: Path, config: FitConfig, models=None, overwrite: bool = False,
        quiet: bool = False, verbose: bool = False, batch: BatchOptions | None = None) -> int:
    """Fit and write every input (deface.batch); returns the number that failed (each printed in one line).

    Finished outputs made with other settings, or two inputs with one output name, are a usage error
    (exit 2); SIGINT / SIGTERM end the run without partial outputs, print one line and exit 130 / 143.
    """
    batch = batch or BatchOptions(jobs=1, overwrite=overwrite, quiet=quiet, verbose=verbose)
    try:
        return run_batch(items, output, config, models, batch)
    except (SettingsMismatch, SameOutput) as error:
        report_error(error)
        raise typer.Exit(EXIT_USAGE) from None
    except RayUnavailable as error:
        console.print(f"[red]error:[/red] {escape(str(error))}")
        raise typer.Exit(EXIT_FAILED) from None
    except Interrupted as stop:
        raise typer.Exit(128 + stop.signum) from None
