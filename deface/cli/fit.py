"""`deface fit INPUT... -o OUT`: photos, folders of photos and clips -> textures, mesh, lights, renders."""

from __future__ import annotations

import signal
import threading
import time
import traceback
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich.markup import escape

from deface.cli import options
from deface.export.files import OutputBusy, OutputError, check_writable, claimed_output
from deface.export.outputs import write_fit
from deface.fit.config import FitConfig
from deface.fit.guard import NonFiniteError
from deface.fit.log import FitLog, console
from deface.fit.pipeline import fit
from deface.io.images import LOAD_MAX_SIDE, InputError, load_image, one_line
from deface.io.inputs import InputItem, list_inputs
from deface.io.video import read_spread_frames
from deface.landmarks.detect import NoFaceError
from deface.models.registry import require_face_model
from deface.paths import ModelFileError
from deface.report.html import write_index

# Failures of one input that are explained by their message (OSError: disk, permissions, missing files).
EXPECTED_ERRORS = (InputError, NoFaceError, ModelFileError, OutputError, NonFiniteError, ValueError, OSError)
EXIT_FAILED, EXIT_USAGE = 1, 2


class Interrupted(BaseException):
    """SIGINT or SIGTERM arrived; raised in the main thread so staged outputs are removed on the way out."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


@dataclass
class Tally:
    """What a run did with its inputs, for the summary line."""

    total: int
    done: int = 0
    failed: int = 0
    busy: int = 0

    @property
    def remaining(self) -> int:
        return self.total - self.done - self.failed - self.busy

    def summary(self) -> str:
        busy = f", {self.busy} left to another run" if self.busy else ""
        return f"{self.done} of {self.total} input(s) done, {self.failed} failed{busy}"


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
    overwrite: Annotated[bool, typer.Option(help="Redo inputs whose outputs already exist (default: skip them).")]
    = False,
    quiet: Annotated[bool, typer.Option(help="Only errors and a summary.")] = False,
    verbose: Annotated[bool, typer.Option(help="Print the full details (traceback, tool output) of each error.")]
    = False,
) -> None:
    """Fit each input and write OUT/<input stem>/ (textures, mesh.obj/.mtl/.glb, params, renders, masks)."""
    try:
        options.check_output(output)
        options.check_models_dir(models)
        config = options.fit_config(
            preset, config_file, sets, model=model, seed=seed, lights=lights, bands=bands, light_masks=light_masks,
            face_region=face_region, priors=priors, resolution=resolution, texture_size=texture_size,
            iterations=iterations, max_frames=max_frames, frame_stride=frame_stride, face_index=face_index,
            threads=threads,
        )
        items = list_inputs(inputs)
    except (InputError, ValueError, OSError) as error:
        report_error(error)
        raise typer.Exit(EXIT_USAGE) from None
    try:
        require_face_model(config.model, models)
        check_writable(output)
    except (ModelFileError, OutputError) as error:
        report_error(error)
        raise typer.Exit(EXIT_FAILED) from None
    if run(items, output, config, models, overwrite, quiet, verbose):
        raise typer.Exit(EXIT_FAILED)


def report_error(error: BaseException, verbose: bool = False) -> None:
    """One line on stderr (markup-safe); with ``verbose`` the traceback and chained causes first."""
    if verbose:
        console.print("".join(traceback.format_exception(error)).rstrip(), markup=False)
    console.print(f"[red]error:[/red] {escape(_message(error))}")


def _message(error: BaseException) -> str:
    if isinstance(error, MemoryError):
        return "out of memory; try a smaller --resolution or --max-frames"
    if not isinstance(error, EXPECTED_ERRORS):
        return f"unexpected {one_line(error)} (a bug: please report it with the output of --verbose)"
    lines = [line.strip() for line in str(error).splitlines() if line.strip()]
    if not lines:
        return one_line(error)
    return lines[0] if len(lines) == 1 else f"{lines[0]} (more with --verbose)"


def run(items: list[InputItem], output: Path, config: FitConfig, models=None, overwrite: bool = False,
        quiet: bool = False, verbose: bool = False) -> int:
    """Fit and write every input; returns the number that failed (each failure printed in one line).

    SIGINT / SIGTERM end the current input without partial outputs, print one line and exit 130 / 143.
    """
    tally = Tally(len(items))
    current = None
    try:
        with _signals_raise():
            for current in items:
                outcome = _fit_one(current, output, config, models, overwrite, quiet, verbose)
                setattr(tally, outcome, getattr(tally, outcome) + 1)
    except Interrupted as stop:
        console.print(f"interrupted ({stop}) during {current.path}: {tally.summary()}, {tally.remaining} not "
                      f"done; run the same command again to resume (finished inputs are skipped)")
        raise typer.Exit(128 + stop.signum) from None
    write_index(output, [item.name for item in items])
    console.print(f"{tally.summary()}; outputs in {output} (index.html)")
    return tally.failed


@contextmanager
def _signals_raise() -> Iterator[None]:
    """Turn SIGINT and SIGTERM into :class:`Interrupted` (main thread only), restoring the handlers after."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {number: signal.getsignal(number) for number in (signal.SIGINT, signal.SIGTERM)}

    def interrupt(signum, _frame):
        raise Interrupted(signum)

    for number in previous:
        signal.signal(number, interrupt)
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)


def load_frames(item: InputItem, config: FitConfig) -> tuple[list[np.ndarray], list[int]]:
    """sRGB frames of an input and their indices in the source (a photo is frame 0)."""
    if item.kind == "image":
        return [load_image(item.path, max_side=LOAD_MAX_SIDE)], [0]
    return read_spread_frames(item.path, config.max_frames, config.frame_stride, max_side=LOAD_MAX_SIDE)


def _fit_one(item: InputItem, output: Path, config: FitConfig, models, overwrite: bool, quiet: bool,
             verbose: bool) -> str:
    """Fit one input under its output folder's lock -> "done", "failed" or "busy" (another run has it)."""
    folder = output / item.name
    try:
        with claimed_output(folder):
            if (folder / "params.json").exists() and not overwrite:
                console.print(f"{item.path}: already done in {folder} (use --overwrite to redo)")
                return "done"
            _fit_and_write(item, folder, config, models, quiet)
    except OutputBusy as busy:
        console.print(escape(str(busy)))
        return "busy"
    except Exception as error:  # noqa: BLE001 - every failure of one input is one line; the batch goes on
        report_error(error, verbose)
        return "failed"
    return "done"


def _fit_and_write(item: InputItem, folder: Path, config: FitConfig, models, quiet: bool) -> None:
    started = time.perf_counter()
    frames, indices = load_frames(item, config)
    log = FitLog(name=item.name, quiet=quiet)
    result = fit(frames, config, models_dir=models, source=str(item.path), video=item.kind == "video", log=log)
    record = {"path": str(item.path), "kind": item.kind, "frames": indices,
              "size": [int(frames[0].shape[1]), int(frames[0].shape[0])]}
    try:
        write_fit(result, folder, record)
    except OSError as error:
        raise OutputError(f"{folder}: cannot write ({error.strerror or one_line(error)}); what was there "
                          "before is unchanged") from error
    console.print(f"{item.path}: done in {time.perf_counter() - started:.1f} s -> {folder}")
