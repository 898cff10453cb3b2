"""Write one fit to ``OUT/<stem>/``:

textures/{diffuse,specular,roughness}.png  UV maps. diffuse: sRGB-encoded base colour (what viewers expect);
                                           specular, roughness: linear data (Blender: "Non-Color").
textures/confidence.png                    how well the photo(s) constrain each texel, linear grey in [0, 1]
                                           (docs/textures.md)
mesh.obj + mesh.mtl, mesh.glb              fitted mesh (cm; GLB in metres), a photo's expression; for a clip
                                           the identity with a neutral expression
params.json, params.npz                    named parameters and the run record; large arrays in the npz
                                           (params.json's lights as rendered: :func:`light_record`)
render.png                                 I_out (sRGB): the whole photo at the working scale with the fitted
                                           face composited where M_o says so; for a clip under frames/<i>/
render_face.png                            I_R (sRGB) over the working frame (the crop around the face)
lights/<k>.png, masks/light_<k>.png        I_Rs and M_L of each kept light k (k = the light's index), working frame
masks/face.png                             M_o, working frame
loss_log.csv                               stage, step, loss, then one column per named loss term
report.html + report/                      the page that shows the fit (deface/report/html.py), when the caller
                                           passes it as ``page`` (the batch does)
"""

from __future__ import annotations

import platform
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

from deface._version import __version__
from deface.export.files import staged_directory, write_json
from deface.export.mesh import TEXTURE_FILES, write_glb, write_obj
from deface.fit.config import to_dict
from deface.fit.output import FitOutput
from deface.io.images import save_png, to_uint8
from deface.render.renderer import Renderer

PARAMS_FORMAT = 3
"""Version of ``params.npz`` (its ``format_version``): 2 holds everything :func:`deface.export.load.load_fit`
needs to rebuild the fit (1, unversioned, had only the export mesh, textures and masks); 3 adds the crop around
the face (params.json ``crop``) and the whole photo at the working scale (``scene_srgb``), and gives the camera
in the input's pixels. Format 2 is read as a fit of the whole frame."""


def write_fit(result: FitOutput, final_folder: Path, record: dict,
              page: Callable[[FitOutput, Path, str], object] | None = None) -> Path:
    """Write everything for ``result`` atomically into ``final_folder``; ``record`` adds input details. ``page``
    (``deface.report.html.write_report``, which the batch passes) writes the fit's page into the staged folder,
    so that it appears with the rest."""
    renders = result.renders
    with staged_directory(final_folder) as folder:
        _write_textures(result, folder)
        _write_mesh(result, folder)
        _write_renders(result, renders, folder)
        _write_params(result, renders, folder, record)
        _write_loss_log(result, folder)
        if page is not None:
            page(result, folder, final_folder.name)
    return final_folder


def _write_textures(result: FitOutput, folder: Path) -> None:
    textures = result.textures
    save_png(folder / TEXTURE_FILES["diffuse"], _np(textures.diffuse), srgb=True)
    save_png(folder / TEXTURE_FILES["specular"], _np(textures.specular), srgb=False)
    save_png(folder / TEXTURE_FILES["roughness"], _np(textures.roughness), srgb=False)
    if result.texels.confidence is not None:
        save_png(folder / "textures" / "confidence.png", result.texels.confidence[..., None], srgb=False)


def _write_mesh(result: FitOutput, folder: Path) -> None:
    model = result.model
    vertices = result.export_vertices()
    write_obj(folder, vertices, model.triangles, model.uvs, model.triangle_uvs)
    write_glb(folder / "mesh.glb", vertices, model.triangles, model.uvs, model.triangle_uvs,
              to_uint8(_np(result.textures.diffuse), srgb=True),
              to_uint8(_np(result.textures.roughness), srgb=False))


def _write_renders(result: FitOutput, renders: list, folder: Path) -> None:
    for frame, rendered in enumerate(renders):
        base = folder if len(renders) == 1 else folder / "frames" / f"{frame:03d}"
        save_png(base / "render.png", _np(result.composite_photo(rendered, frame)))
        save_png(base / "render_face.png", _np(rendered.face))
        save_png(base / "masks" / "face.png", _np(rendered.face_region), srgb=False)
        for slot, light in enumerate(result.lights.kept):
            save_png(base / "lights" / f"{light}.png", _np(rendered.light_images[slot]))
            save_png(base / "masks" / f"light_{light}.png", _np(rendered.light_masks[slot]), srgb=False)


def light_record(renderer: Renderer, lights: torch.Tensor, kept: list[int], bands: int) -> dict:
    """params.json's ``lights``: each kept light's SH [B*B, 3] as the renderer renders it (negative radiance
    clamped, ``render.non_negative_lights``), so another renderer shows the light the fit was rendered with. The
    fitted coefficients themselves (``lights`` [n, B*B, 3], which may carry negative lobes the clamp takes off)
    stay in params.npz for reloading."""
    rendered = _np(renderer.rendered_lights(lights[kept]))
    return {"bands": bands, "kept": kept, "initial_count": int(lights.shape[0]),
            "sh": {str(k): rendered[slot].tolist() for slot, k in enumerate(kept)},
            "convention": "real orthonormal SH, index l*l+l+m, radiance towards the light, model frame" + (
                "; as rendered: the band-limited SH of the fitted radiance clamped at 0 "
                "(deface.render.sh.non_negative), which rings a little below 0"
                if renderer.config.non_negative_lights else "")}


def _write_params(result: FitOutput, renders: list, folder: Path, record: dict) -> None:
    config, model = result.config, result.model
    kept = list(result.lights.kept)
    params = {
        "format": "deface-params/1",
        "model": {"name": model.name, "expression_names": list(model.expression_names),
                  "expression_prior": model.expression_prior},
        "identity": _np(result.pose.identity).tolist(),
        "expression": _np(result.pose.expression).tolist(),
        "pose": {"rotation_axis_angle": _np(result.pose.rotation).tolist(),
                 "translation_cm": _np(result.pose.translation).tolist(),
                 "convention": "model -> camera; camera x right, y down, z forward (OpenCV)"},
        "camera": _person_camera(result) if record.get("kind") == "person" else _camera(result,
                                                                                      record.get("file_size")),
        "crop": result.framing.record(),
        "lights": light_record(result.renderer, result.lights.sh, kept, config.lights.bands),
        "textures": {"size": int(result.textures.diffuse.shape[0]),
                     "chosen_by": "config" if config.texture_size is not None else
                     "the face's pixels (texture_size none, texture_size_range)"},
        "albedo_coefficients": _np(result.albedo.coefficients).tolist(),
        "skin_tone": {"ita": result.albedo.tone if config.tone.free_tone else None, "free": config.tone.free_tone,
                      "convention": "ITA degrees on the albedo model's tone axis",
                      **result.skin_tone(),
                      "interval_convention": "texture_ita: the diffuse map's cheeks and forehead (deface.models.ita); "
                                          "ita_interval: the same with the map's level over the white level's "
                                          "one-sigma spread (illuminant.level_sigma)"},
        "illuminant": result.illuminant_record(),
        "frames": _frames(record.get("frames", [0]), result.kept_frames),
        "preset": config.preset,
        "config": to_dict(config),
        "seed": config.seed,
        "optional_networks": result.record.optional_networks,
        "seconds_per_stage": result.record.seconds,
        "iterations_run": {stage: len(losses) for stage, losses in result.record.losses.items()},
        "notes": result.record.notes,
        "versions": {"deface": __version__, "torch": torch.__version__, "numpy": np.__version__,
                     "python": platform.python_version()},
        "input": record,
    }
    write_json(folder / "params.json", params)
    np.savez_compressed(folder / "params.npz", **fit_arrays(result, renders))


def _camera(result: FitOutput, file_size: list[int] | None = None) -> dict:
    """The camera in the input's pixels (the whole photo as decoded, principal point at its centre), the working
    frame's (the crop the fit worked on), and, for a photo decoded smaller than its file (``file_size``, above
    LOAD_MAX_SIDE), the file's."""
    framing = result.framing
    width, height = framing.input_size
    working_width, working_height = framing.size
    focal = float(result.pose.focal) / framing.scale
    camera = {"focal_px": focal, "width": width, "height": height,
              "principal_point": [width / 2, height / 2], "working_scale": framing.scale,
              "pixels": "the input frame's as decoded (x right, y down, pixel centres at +0.5)",
              "working": {"focal_px": float(result.pose.focal), "width": working_width, "height": working_height,
                          "principal_point": [round(v, 4) for v in framing.principal_point]}}
    if file_size is not None and tuple(file_size) != (width, height):
        ratio = max(file_size) / max(width, height)
        camera["file"] = {"focal_px": focal * ratio, "width": int(file_size[0]), "height": int(file_size[1]),
                          "principal_point": [file_size[0] / 2, file_size[1] / 2]}
    return camera


def _person_camera(result: FitOutput) -> dict:
    """A fit of several photos: the working frames' camera (each photo's own is in ``input.photos``)."""
    width, height = result.framing.size
    return {"focal_px": float(result.pose.focal), "width": width, "height": height,
            "principal_point": [width / 2, height / 2],
            "pixels": "the working frames: each photo's square around its face, resized (input.photos[i] gives the "
                      "square's box and the frame's camera in that photo's pixels)"}


def fit_arrays(result: FitOutput, renders: list) -> dict[str, np.ndarray]:
    """The arrays of ``params.npz`` (format :data:`PARAMS_FORMAT`): the export mesh, textures and masks, and
    what re-rendering the fit needs (coefficients, pose, all lights, the frames' shadow transfer and photos)."""
    frames = result.frames
    arrays = {
        "format_version": np.array(PARAMS_FORMAT),
        "vertices": result.export_vertices(),
        "diffuse": _np(result.textures.diffuse).astype(np.float16),
        "specular": _np(result.textures.specular).astype(np.float16),
        "roughness": _np(result.textures.roughness).astype(np.float16),
        "light_masks": np.stack([_np(r.light_masks) for r in renders]).astype(np.float32),
        "face_region": np.stack([_np(r.face_region) for r in renders]).astype(np.float32),
        "landmarks_2d": np.stack([frame.landmarks for frame in frames]),
        "identity": _np(result.pose.identity), "expression": _np(result.pose.expression),
        "rotation": _np(result.pose.rotation), "translation": _np(result.pose.translation),
        "focal": _np(result.pose.focal), "albedo": _np(result.albedo.coefficients), "lights": _np(result.lights.sh),
        "kept": np.asarray(result.lights.kept, dtype=np.int64),
        "face_classifier": np.stack([_np(frame.face_classifier) for frame in frames]).astype(np.float32),
        "photos_srgb": np.stack([frame.photo_srgb for frame in frames]).astype(np.float16),
    }
    if frames[0].scene_srgb is not None:  # the photo around the crop, for render.png (8 bits, as written)
        arrays["scene_srgb"] = np.stack([to_uint8(frame.scene_srgb, srgb=False) for frame in frames])
    if any(frame.geometry.moves_uvs(result.model.uvs) for frame in frames):  # registered frames
        arrays["frame_uvs"] = np.stack([_np(frame.geometry.mesh.uvs) for frame in frames]).astype(np.float32)
    if result.texels.seen is not None:
        arrays["texture_seen"] = result.texels.seen.astype(np.float16)
    if result.texels.confidence is not None:
        arrays["confidence"] = result.texels.confidence.astype(np.float16)
    if frames[0].transfer is not None:
        arrays["transfer_occluded"] = np.stack([_np(frame.transfer.occluded) for frame in frames])
        arrays["transfer_visibility"] = np.stack([_np(frame.transfer.visibility) for frame in frames])
        arrays["transfer_vertices"] = np.stack([_np(frame.transfer.vertices) for frame in frames])
        arrays["transfer_rays"] = np.array(frames[0].transfer.rays)
    return arrays


def _frames(indices: list[int], kept: list[int] | None) -> list[int]:
    """Source frame numbers of the fitted frames (frames without a face were left out)."""
    return indices if kept is None else [indices[i] for i in kept]


def _write_loss_log(result: FitOutput, folder: Path) -> None:
    """``loss_log.csv``: stage, step, total loss, then one column per named term (empty where a stage has
    no such term)."""
    (folder / "loss_log.csv").write_text(loss_log_csv(result.record))


def loss_log_csv(record) -> str:
    names = sorted({name for steps in record.terms.values() for terms in steps for name in terms})
    lines = [",".join(["stage", "step", "loss", *names])]
    for stage, losses in record.losses.items():
        steps = record.terms.get(stage, [])
        for step, loss in enumerate(losses):
            terms = steps[step] if step < len(steps) else {}
            values = [f"{terms[name]:.6g}" if name in terms else "" for name in names]
            lines.append(",".join([stage, str(step), f"{loss:.6g}", *values]))
    return "\n".join(lines) + "\n"


def _np(tensor: torch.Tensor) -> np.ndarray:
    return tensor.detach().cpu().numpy()
