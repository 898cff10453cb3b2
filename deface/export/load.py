"""Reading a fit back: :func:`load_fit` rebuilds the :class:`~deface.fit.output.FitOutput` that
:func:`deface.export.outputs.write_fit` wrote, from ``params.json`` + ``params.npz`` (format
:data:`~deface.export.outputs.PARAMS_FORMAT`) and the face model. Re-rendering it reproduces the fit's own
renders (tests/test_fit_state.py); the textures come from ``params.npz`` (float16), not the 8-bit PNGs.
"""

from __future__ import annotations

import csv
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from deface.export.outputs import PARAMS_FORMAT
from deface.fit.config import FitConfig, from_dict
from deface.fit.framing import Framing
from deface.fit.output import (
    FitAlbedo,
    FitLights,
    FitOutput,
    FitPose,
    FitTexels,
    OutputFrame,
    RunRecord,
    frozen_geometry,
)
from deface.fit.state import fit_renderer
from deface.fit.texels import frame_views
from deface.models.registry import load_face_model
from deface.priors.illuminant import IlluminantEstimate
from deface.render.frame import cast_frame
from deface.render.mesh import Textures
from deface.render.renderer import ShadowTransfer

OLDEST_FORMAT = 2
"""The oldest ``params.npz`` format :func:`load_fit` reads (2: a fit of the whole frame, without a crop)."""


class FitFormatError(ValueError):
    """A folder is not a deface fit this version can load; the message says what is missing."""


def load_fit(path: str | Path, models_dir=None) -> FitOutput:
    """The fit written to ``path`` (an output folder ``OUT/<stem>``) by ``deface fit``."""
    folder = Path(path)
    arrays, params = _read(folder)
    config = _config(folder, params)
    model = load_face_model(config.model, models_dir)
    pose = FitPose(*(torch.as_tensor(arrays[name], dtype=torch.float32)
                     for name in ("identity", "expression", "rotation", "translation", "focal")))
    renderer = fit_renderer(config)
    framing = _framing(params)
    frames = []
    for frame in range(pose.expression.shape[0]):
        geometry = frozen_geometry(model, pose, frame, framing)
        if "frame_uvs" in arrays:  # the frame's UVs moved into register (deface/fit/frame_register.py)
            geometry = geometry.with_uvs(torch.as_tensor(arrays["frame_uvs"][frame]))
        cast = cast_frame(renderer, geometry.mesh, geometry.camera, _transfer(arrays, frame, config),
                          config.render.supersampling)
        scene = arrays["scene_srgb"][frame].astype(np.float32) / 255.0 if "scene_srgb" in arrays else None
        frames.append(OutputFrame(
            geometry, cast, arrays["photos_srgb"][frame].astype(np.float32),
            _tensor(arrays["face_classifier"][frame]), _tensor(arrays["light_masks"][frame]),
            _tensor(arrays["face_region"][frame]), arrays["landmarks_2d"][frame], scene))
    textures = Textures(*(_tensor(arrays[name]) for name in ("diffuse", "specular", "roughness")))
    losses, terms = read_loss_log(folder / "loss_log.csv")
    record = RunRecord(params.get("seconds_per_stage", {}), losses, terms, params.get("notes", []),
                       params.get("optional_networks", {}))
    views = tuple(frame_views(model, frames, textures.diffuse.shape[0]))
    seen, confidence = (arrays[name].astype(np.float32) if name in arrays else None
                        for name in ("texture_seen", "confidence"))
    illuminant = params.get("illuminant")
    fit = FitOutput(
        model=model, config=config, frames=tuple(frames), pose=pose,
        albedo=FitAlbedo(_tensor(arrays["albedo"]), _tone(params)),
        lights=FitLights(_tensor(arrays["lights"]), tuple(int(k) for k in arrays["kept"])),
        textures=textures, texels=FitTexels(None, seen, confidence, views),
        illuminant=None if illuminant is None else IlluminantEstimate.from_record(illuminant),
        framing=framing, kept_frames=None, record=record, renders=(),
        photo_illuminants=tuple(IlluminantEstimate.from_record(r) for r in (illuminant or {}).get("per_photo", [])))
    return replace(fit, renders=tuple(fit.render()))


def _read(folder: Path) -> tuple[dict[str, np.ndarray], dict]:
    if not (folder / "params.json").is_file() or not (folder / "params.npz").is_file():
        raise FitFormatError(f"{folder}: not a deface fit (params.json and params.npz expected; "
                             "`deface fit INPUT -o OUT` writes them to OUT/<input name>)")
    params = json.loads((folder / "params.json").read_text())
    with np.load(folder / "params.npz") as npz:
        arrays = {name: npz[name] for name in npz.files}
    version = int(arrays["format_version"]) if "format_version" in arrays else 1
    if version < OLDEST_FORMAT:
        raise FitFormatError(
            f"{folder}: written by an older deface (params.npz format {version}, this version reads "
            f"{PARAMS_FORMAT}): it lacks the pose, lights, shadow transfer and photos needed to re-render; "
            "fit the input again (`deface fit ... --overwrite`)")
    if version > PARAMS_FORMAT:
        raise FitFormatError(f"{folder}: params.npz format {version} is newer than this deface reads "
                             f"({PARAMS_FORMAT}); update deface")
    return arrays, params


def _framing(params: dict) -> Framing:
    """The crop the fit worked on; a format-2 fit (no ``crop``) worked on the whole frame, its camera in working
    pixels."""
    if "crop" in params:
        return Framing.from_record(params["crop"])
    camera = params["camera"]
    return Framing.whole((int(camera["width"]), int(camera["height"])), float(camera.get("working_scale", 1.0)))


def read_loss_log(path: Path) -> tuple[dict[str, list[float]], dict[str, list[dict[str, float]]]]:
    """The loss curves of ``loss_log.csv`` (stage -> totals, stage -> named terms per step); empty if absent."""
    losses: dict[str, list[float]] = {}
    terms: dict[str, list[dict[str, float]]] = {}
    if not path.is_file():
        return losses, terms
    with path.open(newline="") as handle:
        for row in csv.DictReader(handle):
            stage = row.pop("stage")
            row.pop("step", None)
            losses.setdefault(stage, []).append(float(row.pop("loss")))
            terms.setdefault(stage, []).append({name: float(value) for name, value in row.items() if value})
    return losses, terms


def _config(folder: Path, params: dict) -> FitConfig:
    try:
        return from_dict(params.get("config", {}))
    except (ValueError, TypeError) as error:
        raise FitFormatError(f"{folder}: params.json's config cannot be read by this deface ({error})") from None


def _transfer(arrays: dict[str, np.ndarray], frame: int, config: FitConfig) -> ShadowTransfer | None:
    if "transfer_occluded" not in arrays:
        return None
    return ShadowTransfer(_tensor(arrays["transfer_occluded"][frame]), _tensor(arrays["transfer_visibility"][frame]),
                          _tensor(arrays["transfer_vertices"][frame]), config.lights.bands,
                          int(arrays["transfer_rays"]))


def _tone(params: dict) -> float:
    ita = (params.get("skin_tone") or {}).get("ita")
    return float(ita) if ita is not None else 0.0


def _tensor(array: np.ndarray) -> torch.Tensor:
    return torch.as_tensor(np.asarray(array, dtype=np.float32))
