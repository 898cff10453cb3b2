"""One input of a batch, the same in every engine (this process, local workers, Ray tasks): claim the output
folder, skip it when finished, load, fit, write -> :class:`Outcome`. Expected failures of one input become
a one-line message; only an interrupt (a ``BaseException``) passes through, leaving nothing half-written.
"""

from __future__ import annotations

import time
import traceback
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from deface.export.files import OutputBusy, OutputError, claimed_output
from deface.export.outputs import write_fit
from deface.fit.config import FitConfig
from deface.fit.framing import decode_side, face_box
from deface.fit.guard import NonFiniteError
from deface.fit.log import FitLog
from deface.fit.output import FitOutput
from deface.fit.pipeline import fit, fit_photos
from deface.io.images import LOAD_MAX_PIXELS, LOAD_MAX_SIDE, InputError, image_size, load_image, one_line
from deface.io.inputs import InputItem, classify
from deface.io.video import read_spread_frames
from deface.landmarks.detect import NoFaceError, detect_landmarks
from deface.paths import ModelFileError
from deface.report.html import write_report
from deface.runtime import torch_threads

# Failures of one input that are explained by their message (OSError: disk, permissions, missing files).
EXPECTED_ERRORS = (InputError, NoFaceError, ModelFileError, OutputError, NonFiniteError, ValueError, OSError)


@dataclass(frozen=True)
class Job:
    """Everything a worker needs to fit one input (picklable)."""

    item: InputItem
    output: Path  # OUT; the input's folder is OUT/<item.name>
    config: FitConfig
    models: Path | None = None
    overwrite: bool = False

    @property
    def folder(self) -> Path:
        return self.output / self.item.name


@dataclass(frozen=True)
class Outcome:
    """What became of one input."""

    status: str  # "done", "failed", "skipped" (already finished) or "busy" (another run holds it)
    seconds: float
    lights_kept: tuple[int, ...] | None = None
    error: str | None = None  # one line (failed, busy)
    cpu_seconds: float | None = None  # CPU time of the process (all its threads) during this input
    skin_tone: dict | None = None  # done: the texture's ITA and interval (FitOutput.skin_tone)
    detail: str | None = None  # traceback of a failure, for --verbose


def error_message(error: BaseException) -> str:
    """One line for a failure: the first line of an expected error's message, else a bug report request."""
    if isinstance(error, MemoryError):
        return "out of memory; try a smaller --resolution or --max-frames"
    if not isinstance(error, EXPECTED_ERRORS):
        return f"unexpected {one_line(error)} (a bug: please report it with the output of --verbose)"
    lines = [line.strip() for line in str(error).splitlines() if line.strip()]
    if not lines:
        return one_line(error)
    return lines[0] if len(lines) == 1 else f"{lines[0]} (more with --verbose)"


def finished_params(folder: Path) -> Path | None:
    """``folder/params.json`` when the input's output is complete (it appears by one rename), else None."""
    params = folder / "params.json"
    return params if params.is_file() else None


def run_job(job: Job, log: FitLog) -> Outcome:
    """Fit one input under its output folder's lock; expected and unexpected failures -> "failed"."""
    started, cpu = time.perf_counter(), time.process_time()
    try:
        with claimed_output(job.folder):
            if finished_params(job.folder) and not job.overwrite:
                return Outcome("skipped", 0.0)
            kept, tone = fit_and_write(job.item, job.folder, job.config, job.models, log)
    except OutputBusy as busy:
        return Outcome("busy", 0.0, error=str(busy))
    except Exception as error:  # noqa: BLE001 - every failure of one input is one line; the batch goes on
        return Outcome("failed", time.perf_counter() - started, error=error_message(error),
                       detail="".join(traceback.format_exception(error)).rstrip(),
                       cpu_seconds=time.process_time() - cpu)
    return Outcome("done", time.perf_counter() - started, lights_kept=kept, cpu_seconds=time.process_time() - cpu,
                   skin_tone=tone)


def load_frames(item: InputItem, config: FitConfig) -> tuple[list[np.ndarray], list[int], object]:
    """sRGB frames of an input, their indices in the source (a photo is frame 0), and a photo's landmarks where
    they were found on its frame already (else None: the fit finds them)."""
    if item.kind == "image":
        frame, landmarks = load_photo(item.path, config)
        return [frame], [0], landmarks
    frames, indices = read_spread_frames(item.path, config.max_frames, config.frame_stride, max_side=LOAD_MAX_SIDE)
    return frames, indices, None


def load_photo(path: Path, config: FitConfig) -> tuple[np.ndarray, object]:
    """A photo decoded at ``LOAD_MAX_SIDE``, or larger where its face needs more of the file's pixels to reach the
    fit's working resolution (:func:`deface.fit.framing.decode_side`, within ``LOAD_MAX_PIXELS``); with the
    landmarks found on the frame returned, when finding the size needed them (else None)."""
    frame = load_image(path, max_side=LOAD_MAX_SIDE)
    file_size, decoded_size = image_size(path), (frame.shape[1], frame.shape[0])
    if max(file_size) <= max(decoded_size) or not config.crop.enabled:
        return frame, None
    try:
        landmarks = detect_landmarks(frame, face_index=config.face_index, source=str(path))
    except (NoFaceError, ValueError):
        return frame, None  # the fit says so, with its own message
    side = decode_side(face_box([landmarks.points], decoded_size), decoded_size, file_size, config.resolution,
                       config.crop.margin, LOAD_MAX_PIXELS)
    return (load_image(path, max_side=side), None) if side > 1.05 * max(decoded_size) else (frame, landmarks)


def fit_and_write(item: InputItem, folder: Path, config: FitConfig, models,
                  log: FitLog) -> tuple[tuple[int, ...], dict]:
    """Fit ``item`` and write its outputs atomically into ``folder`` -> the kept lights' indices and the texture's
    skin tone."""
    with torch_threads(config.threads):  # writing renders too: the same threads as the fit, in any engine
        return _fit_and_write(item, folder, config, models, log)


def fit_input(item: InputItem, config: FitConfig, models, log: FitLog) -> tuple[FitOutput, dict]:
    """Fit ``item`` -> the fit and what params.json's ``input`` says of it."""
    if item.kind == "person":
        return fit_person(item, config, models, log)
    frames, indices, landmarks = load_frames(item, config)
    record = {"path": str(item.path), "kind": item.kind, "frames": indices,
              "size": [int(frames[0].shape[1]), int(frames[0].shape[0])]}
    if item.kind == "image":  # a photo above LOAD_MAX_SIDE was decoded smaller: params.json's camera says both
        record["file_size"] = list(image_size(item.path))
        if max(record["size"]) > LOAD_MAX_SIDE:
            log.info(f"decoded at {record['size'][0]} x {record['size'][1]} of the file's "
                     f"{record['file_size'][0]} x {record['file_size'][1]}: the face is small in the photo")
    result = fit(frames, config, models_dir=models, source=str(item.path), video=item.kind == "video", log=log,
                 landmarks=landmarks)
    return result, record


def fit_person(item: InputItem, config: FitConfig, models, log: FitLog) -> tuple[FitOutput, dict]:
    """Fit a person's photos as one fit (deface/fit/person.py); a clip's frames (``max_frames`` spread over it) are
    photos too, named ``clip.mp4#index``; photos without a face are left out (said)."""
    loaded, sources, given = [], [], []
    for path in item.photos:
        try:
            photos = person_photos(path, config)
        except InputError as error:
            log.info(f"{one_line(error)}; left out of the fit")
            given.append(str(path))
            continue
        for source, photo in photos:
            loaded.append(photo)
            sources.append(source)
            given.append(source)
    if not loaded:
        raise InputError(f"{item.name}: none of its {len(item.photos)} photos could be read")
    result, crops = fit_photos([photo for photo, _ in loaded], sources, config, models_dir=models, log=log,
                               landmarks=[found for _, found in loaded])
    used, side, focal = {crop.source for crop in crops}, result.framing.size[0], float(result.pose.focal)
    record = {"path": str(item.path), "kind": "person", "name": item.name, "frames": list(range(len(crops))),
              "photos": [crop.record(focal, side) for crop in crops],
              "left_out": [source for source in given if source not in used]}
    return result, record


def person_photos(path: Path, config: FitConfig) -> list[tuple[str, tuple[np.ndarray, object]]]:
    """(source, (photo, its landmarks or None)) of one file given to ``--person``: a photo, or a clip's frames
    spread over it (as a clip's fit takes them), each a photo of its own."""
    if classify(path) != "video":
        return [(str(path), load_photo(path, config))]
    frames, indices = read_spread_frames(path, config.max_frames, config.frame_stride, max_side=LOAD_MAX_SIDE)
    return [(f"{path}#{index}", (frame, None)) for frame, index in zip(frames, indices, strict=True)]


def _fit_and_write(item: InputItem, folder: Path, config: FitConfig, models,
                   log: FitLog) -> tuple[tuple[int, ...], dict]:
    result, record = fit_input(item, config, models, log)
    try:
        write_fit(result, folder, record, page=write_report)
    except OSError as error:
        raise OutputError(f"{folder}: cannot write ({error.strerror or one_line(error)}); what was there "
                          "before is unchanged") from error
    return tuple(int(k) for k in result.lights.kept), result.skin_tone()
