"""`deface fit INPUT... -o OUT`: photos, folders of photos and clips -> textures, mesh, lights, renders."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import typer

from deface.export.outputs import write_fit
from deface.fit import presets
from deface.fit.config import FitConfig, override
from deface.fit.log import FitLog, console
from deface.fit.pipeline import fit
from deface.io.images import InputError, load_image
from deface.io.inputs import InputItem, list_inputs
from deface.io.video import read_video_frames
from deface.landmarks.detect import NoFaceError
from deface.paths import ModelFileError

EXPECTED_ERRORS = (InputError, NoFaceError, ModelFileError, ValueError)


def register(app: typer.Typer) -> None:
    app.command("fit")(fit_command)


def fit_command(
    inputs: list[Path] = typer.Argument(..., help="Images, folders of images, or videos."),
    output: Path = typer.Option(..., "-o", "--output", help="Output folder; one sub-folder per input."),
    preset: str = typer.Option("default", help=f"One of: {', '.join(presets.names())}."),
    models: Path | None = typer.Option(None, "--models", help="Model files folder (else DEFACE_MODELS, cache)."),
    model: str = typer.Option("ict", "--model", help="Face model: ict (embedded) or bfm (BFM 2017 + AlbedoMM)."),
    seed: int = typer.Option(0, help="Random seed (fits are deterministic for a seed)."),
    lights: int | None = typer.Option(None, help="Ablation: initial number of light conditions n."),
    bands: int | None = typer.Option(None, help="Ablation: SH bands B per light."),
    light_masks: bool | None = typer.Option(None, "--light-masks/--no-light-masks", help="Ablation: field f."),
    face_region: bool | None = typer.Option(None, "--face-region/--no-face-region", help="Ablation: field g."),
    priors: str | None = typer.Option(None, help="Ablation: priors to use, comma list of gp,lp,hp or none."),
    resolution: int | None = typer.Option(None, help="Working resolution (longest side, px)."),
    iterations: str | None = typer.Option(None, help="Iterations per stage as S1,S2,S3 (e.g. 300,400,200)."),
    max_frames: int | None = typer.Option(None, help="Video: number of frames used (evenly spread)."),
    frame_stride: int | None = typer.Option(None, help="Video: take every k-th frame first."),
    face_index: int | None = typer.Option(None, help="Which face when several (0 = largest)."),
    threads: int | None = typer.Option(None, help="Torch threads (default 1: bit-exact results per seed)."),
    overwrite: bool = typer.Option(False, help="Redo inputs whose outputs already exist (default: skip them)."),
    quiet: bool = typer.Option(False, help="Only errors and a summary."),
) -> None:
    """Fit each input and write OUT/<input stem>/ (textures, mesh.obj/.mtl/.glb, params, renders, masks)."""
    try:
        config = override(_config(preset, seed, lights, bands, light_masks, face_region, priors, resolution,
                                  iterations, max_frames, frame_stride, face_index, threads), model=model)
        items = list_inputs(inputs)
    except (InputError, ValueError) as error:
        console.print(f"[red]error:[/red] {error}")
        raise typer.Exit(2) from None
    if run(items, output, config, models, overwrite, quiet):
        raise typer.Exit(1)


def run(items: list[InputItem], output: Path, config: FitConfig, models=None, overwrite: bool = False,
        quiet: bool = False) -> int:
    """Fit and write every input; returns the number that failed (each failure printed in one line)."""
    failures = sum(not _fit_one(item, output, config, models, overwrite, quiet) for item in items)
    console.print(f"{len(items) - failures} of {len(items)} input(s) done, {failures} failed; outputs in {output}")
    return failures


def _config(preset, seed, lights, bands, light_masks, face_region, priors, resolution, iterations,
            max_frames, frame_stride, face_index, threads=None) -> FitConfig:
    config = presets.with_ablation(presets.get(preset), num_lights=lights, light_masks=light_masks,
                                   face_region=face_region, priors=priors, bands=bands)
    changes = {"seed": seed, "resolution": resolution, "max_frames": max_frames, "frame_stride": frame_stride,
               "face_index": face_index, "threads": threads}
    if iterations is not None:
        stage1, stage2, stage3 = _parse_iterations(iterations)
        changes.update({"iterations.stage1": stage1, "iterations.stage2": stage2, "iterations.stage3": stage3})
    return override(config, **{key: value for key, value in changes.items() if value is not None})


def _parse_iterations(text: str) -> tuple[int, int, int]:
    try:
        values = tuple(int(part) for part in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3 or min(values) < 1:
        raise ValueError(f"--iterations takes three positive integers S1,S2,S3, got '{text}'")
    return values


def load_frames(item: InputItem, config: FitConfig) -> tuple[list[np.ndarray], list[int]]:
    """sRGB frames of an input and their indices in the source (a photo is frame 0)."""
    if item.kind == "image":
        return [load_image(item.path)], [0]
    frames, _fps = read_video_frames(item.path, stride=config.frame_stride)
    count = min(config.max_frames, len(frames))
    chosen = np.linspace(0, len(frames) - 1, count).round().astype(int).tolist()
    return [frames[i] for i in chosen], [i * config.frame_stride for i in chosen]


def _fit_one(item: InputItem, output: Path, config: FitConfig, models, overwrite: bool, quiet: bool) -> bool:
    folder = output / item.name
    if (folder / "params.json").exists() and not overwrite:
        console.print(f"{item.path}: already done in {folder} (use --overwrite to redo)")
        return True
    started = time.perf_counter()
    try:
        frames, indices = load_frames(item, config)
        log = FitLog(name=item.name, quiet=quiet)
        result = fit(frames, config, models_dir=models, source=str(item.path), video=item.kind == "video",
                     log=log)
        record = {"path": str(item.path), "kind": item.kind, "frames": indices,
                  "size": [int(frames[0].shape[1]), int(frames[0].shape[0])]}
        write_fit(result, folder, record)
    except EXPECTED_ERRORS as error:
        console.print(f"[red]error:[/red] {error}")
        return False
    console.print(f"{item.path}: done in {time.perf_counter() - started:.1f} s -> {folder}")
    return True
