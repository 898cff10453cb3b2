"""The texture-swap protocol (Sec. 4): fit source and target separately, re-render the target with its own
geometry, pose and lights but the source's textures ("target synthesis"), and score both the source
reconstruction and the target synthesis against the photos, over the face region h (our stand-in for
the authors' face parsing) and over the full image composited as the authors did. When dlib is installed
(``.[identity]``), each side also gets ``"identity": {"distance": d}``: the dlib descriptor distance between
that full composite and the photo (:mod:`deface.landmarks.identity`; lower is better, < 0.6 = same person).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from deface.eval.albedo_measures import colour_noise
from deface.eval.identity import identity_scores
from deface.eval.metrics import composite, mean_scores, score_images
from deface.eval.pairs import Pair
from deface.eval.report import PairScores, ReportRow
from deface.eval.uv_measure import SEEN, both_seen, detail_ratio, edge_fringe, speckle, uv_consistency
from deface.fit.config import FitConfig
from deface.fit.log import FitLog
from deface.fit.output import FitOutput
from deface.fit.pipeline import fit
from deface.io.images import linear_to_srgb, load_image, save_png
from deface.landmarks import identity
from deface.models.ita import texture_ita
from deface.relight.transfer import transfer_renders
from deface.texture.confidence import unwrap


@dataclass(frozen=True)
class PairOutcome:
    scores: PairScores
    row: ReportRow
    seconds_per_fit: float
    albedo_ita: dict  # {"source": ITA, "target": ITA} of the two fits' diffuse textures (same person)
    uv: dict  # UV-space measures (deface/eval/uv_measure.py): consistency, speckle, texels compared


def fit_side(paths: list[Path], config: FitConfig, models_dir, name: str, quiet: bool) -> FitOutput:
    frames = [load_image(path) for path in paths]
    log = FitLog(name=name, quiet=quiet)
    return fit(frames, config, models_dir=models_dir, source=name, video=len(frames) > 1, log=log)


_IDENTITY = identity.IdentityScorer()  # dlib models load on first use, once per process


def score_fit(result: FitOutput, renders: list | None = None) -> tuple[dict, list[np.ndarray]]:
    """Mean scores over frames of ``renders`` of ``result`` (default: its own render) against its photos (plus
    ``"identity"`` when dlib is installed and the photo has a face), and the sRGB outputs."""
    photos = [frame.photo_srgb for frame in result.frames]
    scores, outputs, pasted = [], [], []
    for frame, rendered in enumerate(renders or result.renders):
        output = linear_to_srgb(_np(rendered.face).clip(0, 1))
        mask = _np(rendered.coverage * result.frames[frame].face_classifier)
        scores.append(score_images(output, photos[frame], mask))
        pasted.append(composite(output, photos[frame], mask))
        outputs.append(_np(result.composite(rendered, frame)))
    mean = mean_scores(scores)
    if identity.available():
        found = identity_scores(_IDENTITY, pasted, photos)
        if found is not None:
            mean["identity"] = found
    return mean, outputs


def evaluate_pair(pair: Pair, config: FitConfig, folder: Path, models_dir=None, quiet: bool = True) -> PairOutcome:
    """Fit both sides of ``pair``, score, and save the images the report shows into ``folder``."""
    import time

    reason = identity.unavailable_reason()
    if reason is not None:
        warnings.warn(f"no identity scores: {reason}", stacklevel=2)

    started = time.perf_counter()
    source = fit_side(pair.source, config, models_dir, f"{pair.name}/source", quiet)
    target = fit_side(pair.target, config, models_dir, f"{pair.name}/target", quiet)
    seconds = (time.perf_counter() - started) / 2
    source_scores, source_outputs = score_fit(source)
    swap_scores, swap_outputs = score_fit(target, transfer_renders(source, target))  # as `deface transfer`
    images = _save_images(folder, source, target, source_outputs[0], swap_outputs[0])
    scores = PairScores(pair.name, source_scores, swap_scores)
    row = ReportRow(pair.name, images, {"source": source_scores, "target": swap_scores})
    shadow = load_image(pair.shadow_mask)[..., 0] if pair.shadow_mask is not None else None
    return PairOutcome(scores, row, seconds, {"source": _albedo_ita(source), "target": _albedo_ita(target)},
                       uv_scores(source, target, shadow))


def uv_scores(source: FitOutput, target: FitOutput, shadow: np.ndarray | None = None) -> dict:
    """The two fits' diffuse maps compared in UV space, their speckle (mean of both fits), and with the source
    photo's shadow mask ``shadow`` [H, W] the colour its edge left in the source's map (``edge_fringe``)."""
    region = both_seen(source.texels.seen, target.texels.seen)
    linear = [_np(fit.textures.diffuse).clip(0, 1) for fit in (source, target)]
    details = [fit_detail(fit) for fit in (source, target)]
    scores = {"consistency": uv_consistency(*(linear_to_srgb(m) for m in linear), region),
              "texels": int(region.sum()), "speckle": float(np.mean([d["speckle"] for d in details])),
              "detail": float(np.mean([d["detail"] for d in details])),
              "colour_noise": float(np.mean([colour_noise(m, region) for m in linear]))}
    if shadow is not None:
        working = _working_frame(shadow, source.framing)
        scores["edge_fringe"] = edge_fringe(*linear, unwrap(working[..., None], source.texels.views[0])[..., 0], region)
    return scores


def _working_frame(mask: np.ndarray, framing) -> np.ndarray:
    """A mask [H0, W0] in the photo's pixels resampled to the fit's working frame [H, W] (its crop and scale)."""
    return framing.window(framing.scene_image(mask[..., None].astype(np.float32)))[..., 0]


def fit_detail(result: FitOutput) -> dict[str, float]:
    """Speckle and detail ratio of a fit's diffuse map against its first frame read in UV, over the texels
    that frame saw (deface/eval/uv_measure.py)."""
    view = result.texels.views[0]
    region = view.seen(_np(result.frames[0].face_region)) >= SEEN
    photo, diffuse = unwrap(result.frames[0].photo.numpy(), view), _np(result.textures.diffuse)
    return {"speckle": speckle(diffuse, photo, region), "detail": detail_ratio(diffuse, photo, region)}


def _albedo_ita(result: FitOutput) -> float:
    """The skin tone of a fit's diffuse texture (deface/models/ita.py)."""
    return texture_ita(linear_to_srgb(_np(result.textures.diffuse).clip(0, 1)))


def _save_images(folder: Path, source: FitOutput, target: FitOutput, source_out, swap_out) -> dict[str, Path]:
    images = {
        "source": (source.frames[0].photo.numpy(), True),
        "target": (target.frames[0].photo.numpy(), True),
        "source reconstruction": (source_out, True),
        "target synthesis": (swap_out, True),
        "diffuse (source)": (_np(source.textures.diffuse), True),
        "diffuse (target)": (_np(target.textures.diffuse), True),
        "specular (source)": (_np(source.textures.specular), False),
        "roughness (source)": (_np(source.textures.roughness), False),
    }
    paths = {}
    for label, (image, srgb) in images.items():
        path = folder / (label.replace(" ", "_").replace("(", "").replace(")", "") + ".png")
        save_png(path, image, srgb=srgb)
        paths[label] = path
    return paths


def _np(tensor: torch.Tensor) -> np.ndarray:
    return tensor.detach().cpu().numpy()
