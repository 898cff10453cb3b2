"""`deface fit INPUT... -o OUT`: photos, folders of photos and clips -> textures, mesh, lights, renders."""

from __future__ import annotations

import traceback
from pathlib import Path

import typer
from rich.markup import escape

from deface.batch.ray_engine import RayUnavailable
from deface.batch.resume import SameOutput, SettingsMismatch
from deface.batch.run import BatchOptions, Interrupted, run_batch
from deface.batch.task import error_message
from deface.cli import options
from deface.export.files import OutputError, check_writable
from deface.fit import presets
from deface.fit.config import FitConfig, override
from deface.fit.log import console
from deface.io.images import InputError
from deface.io.inputs import InputItem, list_inputs
from deface.models.registry import require_face_model
from deface.paths import ModelFileError

EXIT_FAILED, EXIT_USAGE = 1, 2


def register(app: typer.Typer) -> None:
    app.command("fit")(fit_command)


def fit_command(
    inputs: list[Path] = typer.Argument(..., help="Images, folders of images, or videos."),
    output: Path = typer.Option(..., "-o", "--output", help="Output folder; one sub-folder per input."),
    preset: str = typer.Option("default", help=f"One of: {', '.join(presets.names())}."),
    models: Path | None = typer.Option(None, "--models", help="Model files folder, the only one searched "
                                       "(default: DEFACE_MODELS, then the cache)."),
    model: str = typer.Option("ict", "--model", help="Face model: ict (embedded) or bfm (BFM 2017 + AlbedoMM)."),
    seed: int = typer.Option(0, help="Random seed (fits are deterministic for a seed)."),
    lights: int | None = typer.Option(None, help="Ablation: initial number of light conditions n (1-16)."),
    bands: int | None = typer.Option(None, help="Ablation: SH bands B per light (1-16)."),
    light_masks: bool | None = typer.Option(None, "--light-masks/--no-light-masks", help="Ablation: field f."),
    face_region: bool | None = typer.Option(None, "--face-region/--no-face-region", help="Ablation: field g."),
    priors: str | None = typer.Option(None, help="Ablation: priors to use, comma list of gp,lp,hp or none."),
    resolution: int | None = typer.Option(None, help="Working resolution (longest side, 32-2048 px)."),
    iterations: str | None = typer.Option(None, help="Iterations per stage as S1,S2,S3 (e.g. 300,400,200)."),
    max_frames: int | None = typer.Option(None, help="Video: number of frames used (evenly spread)."),
    frame_stride: int | None = typer.Option(None, help="Video: take every k-th frame first."),
    face_index: int | None = typer.Option(None, help="Which face when several (0 = largest)."),
    threads: int | None = typer.Option(None, help="Torch threads (default 1: bit-exact results per seed)."),
    overwrite: bool = typer.Option(False, help="Redo inputs whose outputs already exist (default: skip them)."),
    quiet: bool = typer.Option(False, help="Only errors and a summary."),
    verbose: bool = typer.Option(False, help="Print the full details (traceback, tool output) of each error."),
    jobs: int = typer.Option(0, "--jobs", "-j", help="Inputs fitted at once, each in its own worker process with "
                             "1 torch thread (0 = one per core; 1 = one after another in this process)."),
    retry_failed: bool = typer.Option(False, "--retry-failed", help="Redo only the inputs whose last record in "
                                      "OUT/batch.jsonl is a failure (a plain rerun fits every unfinished input)."),
    engine: str = typer.Option("local", help="local (this machine) or ray (a Ray cluster; pip install deface[ray])."),
    ray_address: str | None = typer.Option(None, "--ray-address", help="Ray cluster to join (default: RAY_ADDRESS, "
                                           "else a local Ray started for this run)."),
    ray_outputs: str = typer.Option("driver", "--ray-outputs", help="driver: tasks return the outputs and this "
                                    "machine writes them (safe default); shared: tasks write to OUT directly "
                                    "(OUT and the inputs must be on a filesystem every node sees)."),
) -> None:
    """Fit each input and write OUT/<input stem>/ (textures, mesh.obj/.mtl/.glb, params, renders, masks)."""
    try:
        options.check_output(output)
        options.check_models_dir(models)
        options.check_face_model(model)
        config = override(_config(preset, seed, lights, bands, light_masks, face_region, priors, resolution,
                                  iterations, max_frames, frame_stride, face_index, threads), model=model)
        items = list_inputs(inputs)
        batch = _batch_options(jobs, engine, ray_address, ray_outputs, overwrite, retry_failed, quiet, verbose)
    except (InputError, ValueError, OSError) as error:
        report_error(error)
        raise typer.Exit(EXIT_USAGE) from None
    try:
        require_face_model(model, models)
        check_writable(output)
    except (ModelFileError, OutputError) as error:
        report_error(error)
        raise typer.Exit(EXIT_FAILED) from None
    if run(items, output, config, models, batch=batch):
        raise typer.Exit(EXIT_FAILED)


def _batch_options(jobs, engine, ray_address, ray_outputs, overwrite, retry_failed, quiet, verbose) -> BatchOptions:
    options.check_ranges({"--jobs": jobs})
    options.check_choice("--engine", engine, ("local", "ray"))
    options.check_choice("--ray-outputs", ray_outputs, ("driver", "shared"))
    if engine != "ray" and ray_address:
        raise options.UsageError("--ray-address needs --engine ray")
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
    (exit 2); SIGINT / SIGTERM end the run
    without partial outputs, print one line and exit 130 / 143.
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


def _config(preset, seed, lights, bands, light_masks, face_region, priors, resolution, iterations,
            max_frames, frame_stride, face_index, threads=None) -> FitConfig:
    """The preset with the command line's changes, each option checked first (options.UsageError)."""
    options.check_ranges({"--seed": seed, "--lights": lights, "--bands": bands, "--resolution": resolution,
                          "--max-frames": max_frames, "--frame-stride": frame_stride,
                          "--face-index": face_index, "--threads": threads})
    config = presets.with_ablation(presets.get(preset), num_lights=lights, light_masks=light_masks,
                                   face_region=face_region, priors=priors, bands=bands)
    changes = {"seed": seed, "resolution": resolution, "max_frames": max_frames, "frame_stride": frame_stride,
               "face_index": face_index, "threads": threads}
    if iterations is not None:
        stage1, stage2, stage3 = options.parse_iterations(iterations)
        changes.update({"iterations.stage1": stage1, "iterations.stage2": stage2, "iterations.stage3": stage3})
    return override(config, **{key: value for key, value in changes.items() if value is not None})
