"""Write one fit to ``OUT/<stem>/``:

textures/{diffuse,specular,roughness}.png  UV maps. diffuse: sRGB-encoded base colour (what viewers expect);
                                           specular, roughness: linear data (Blender: "Non-Color").
textures/confidence.png                    how well the photo(s) constrain each texel, linear grey in [0, 1]
                                           (docs/textures.md)
mesh.obj + mesh.mtl, mesh.glb              fitted mesh (cm; GLB in metres), a photo's expression; for a clip
                                           the identity with a neutral expression
params.json, params.npz                    named parameters and the run record; large arrays in the npz
render.png, render_face.png                I_out and I_R (sRGB); for a clip under frames/<i>/
lights/<k>.png, masks/light_<k>.png        I_Rs and M_L of each kept light k (k = the light's index)
masks/face.png                             M_o
loss_log.csv                               stage, step, loss
"""

from __future__ import annotations

import platform
from pathlib import Path

import numpy as np
import torch

import deface
from deface.export.files import save_png, staged_directory, to_uint8, write_json
from deface.export.mesh import TEXTURE_FILES, write_glb, write_obj
from deface.fit.config import to_dict


def write_fit(result, final_folder: Path, record: dict) -> Path:
    """Write everything for ``result`` atomically into ``final_folder``; ``record`` adds input details."""
    renders = result.render()
    with staged_directory(final_folder) as folder:
        _write_textures(result, folder)
        _write_mesh(result, folder)
        _write_renders(result, renders, folder)
        _write_params(result, renders, folder, record)
        _write_loss_log(result, folder)
    return final_folder


def _write_textures(result, folder: Path) -> None:
    textures = result.textures
    save_png(folder / TEXTURE_FILES["diffuse"], _np(textures.diffuse), srgb=True)
    save_png(folder / TEXTURE_FILES["specular"], _np(textures.specular), srgb=False)
    save_png(folder / TEXTURE_FILES["roughness"], _np(textures.roughness), srgb=False)
    if result.confidence is not None:
        save_png(folder / "textures" / "confidence.png", result.confidence[..., None], srgb=False)


def _export_vertices(result) -> np.ndarray:
    context = result.context
    scene, model = context.scene, context.model
    expression = scene.expression[0] if scene.num_frames == 1 else torch.zeros_like(scene.expression[0])
    with torch.no_grad():
        return model.vertices(scene.identity, expression).numpy()


def _write_mesh(result, folder: Path) -> None:
    model = result.context.model
    vertices = _export_vertices(result)
    write_obj(folder, vertices, model.triangles, model.uvs, model.triangle_uvs)
    write_glb(folder / "mesh.glb", vertices, model.triangles, model.uvs, model.triangle_uvs,
              to_uint8(_np(result.textures.diffuse), srgb=True),
              to_uint8(_np(result.textures.roughness), srgb=False))


def _write_renders(result, renders: list, folder: Path) -> None:
    kept = result.context.decoupling.kept
    for frame, rendered in enumerate(renders):
        base = folder if len(renders) == 1 else folder / "frames" / f"{frame:03d}"
        save_png(base / "render.png", _np(result.composite(rendered, frame)))
        save_png(base / "render_face.png", _np(rendered.face))
        save_png(base / "masks" / "face.png", _np(rendered.face_region), srgb=False)
        for slot, light in enumerate(kept):
            save_png(base / "lights" / f"{light}.png", _np(rendered.light_images[slot]))
            save_png(base / "masks" / f"light_{light}.png", _np(rendered.light_masks[slot]), srgb=False)


def _write_params(result, renders: list, folder: Path, record: dict) -> None:
    context = result.context
    scene, config, target = context.scene, context.config, context.target
    kept = context.decoupling.kept
    width, height = target.size
    lights = scene.lights.detach().numpy()
    params = {
        "format": "deface-params/1",
        "model": {"name": context.model.name, "expression_names": list(context.model.expression_names),
                  "expression_prior": context.model.expression_prior},
        "identity": _np(scene.identity).tolist(),
        "expression": _np(scene.expression).tolist(),
        "pose": {"rotation_axis_angle": _np(scene.rotation).tolist(),
                 "translation_cm": _np(scene.translation).tolist(),
                 "convention": "model -> camera; camera x right, y down, z forward (OpenCV)"},
        "camera": {"focal_px": float(scene.focal.detach()), "width": width, "height": height,
                   "principal_point": [width / 2, height / 2], "working_scale": target.scale},
        "lights": {"bands": config.lights.bands, "kept": kept, "initial_count": int(lights.shape[0]),
                   "sh": {str(k): lights[k].tolist() for k in kept},
                   "convention": "real orthonormal SH, index l*l+l+m, radiance towards the light, model frame"},
        "albedo_coefficients": _np(scene.albedo).tolist(),
        "skin_tone": {"ita": float(scene.tone.detach()) if config.tone.free_tone else None,
                      "free": config.tone.free_tone, "convention": "ITA degrees on the albedo model's tone axis"},
        "illuminant": context.illuminant.record() if context.illuminant is not None else None,
        "frames": _frames(record.get("frames", [0]), target.kept_frames),
        "preset": config.preset,
        "config": to_dict(config),
        "seed": config.seed,
        "optional_networks": result.optional_networks,
        "seconds_per_stage": result.log.seconds,
        "iterations_run": {stage: len(losses) for stage, losses in result.log.losses.items()},
        "notes": result.log.notes,
        "versions": {"deface": deface.__version__, "torch": torch.__version__, "numpy": np.__version__,
                     "python": platform.python_version()},
        "input": record,
    }
    write_json(folder / "params.json", params)
    np.savez_compressed(
        folder / "params.npz",
        vertices=_export_vertices(result),
        diffuse=_np(result.textures.diffuse).astype(np.float16),
        specular=_np(result.textures.specular).astype(np.float16),
        roughness=_np(result.textures.roughness).astype(np.float16),
        light_masks=np.stack([_np(r.light_masks) for r in renders]).astype(np.float16),
        face_region=np.stack([_np(r.face_region) for r in renders]).astype(np.float16),
        **({"confidence": result.confidence.astype(np.float16)} if result.confidence is not None else {}),
        landmarks_2d=np.stack([lm.points for lm in target.landmarks]),
    )


def _frames(indices: list[int], kept: list[int] | None) -> list[int]:
    """Source frame numbers of the fitted frames (frames without a face were left out)."""
    return indices if kept is None else [indices[i] for i in kept]


def _write_loss_log(result, folder: Path) -> None:
    lines = ["stage,step,loss"]
    for stage, losses in result.log.losses.items():
        lines += [f"{stage},{step},{loss:.6g}" for step, loss in enumerate(losses)]
    (folder / "loss_log.csv").write_text("\n".join(lines) + "\n")


def _np(tensor: torch.Tensor) -> np.ndarray:
    return tensor.detach().cpu().numpy()
