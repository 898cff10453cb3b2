"""A finished fit's folder, as the page shows it: the files to display (all written by `deface fit`'s export and
report), the skin tone in words, and the folder as a zip."""

from __future__ import annotations

import json
import os
import zipfile
from dataclasses import dataclass
from pathlib import Path

from deface.batch.record import SURE_TONE_WIDTH
from deface.models.ita import ITA_GROUPS, ita_group

MAPS = (("diffuse", "diffuse: the skin's own colour, shadows removed"), ("specular", "specular"),
        ("roughness", "roughness"), ("confidence", "confidence: how well the photo shows each texel"))


@dataclass(frozen=True)
class FitView:
    """What the page shows of one fit (a clip's first frame for the per-frame images)."""

    name: str
    folder: Path
    mesh: Path  # mesh.glb
    photo: Path  # the photo at the working resolution (report/input.png)
    render: Path  # I_out: the fit composited into the photo
    render_face: Path  # I_R: the rendered face
    lights: tuple[tuple[int, Path, Path], ...]  # each kept light: index, lit sphere, mask
    maps: tuple[tuple[str, Path], ...]  # caption, UV map
    tone: str  # the skin tone in words (markdown)
    frames: int


def fit_view(folder: Path) -> FitView:
    """The view of the finished fit in ``folder`` (``OUT/<job>/<input name>``)."""
    params = json.loads((folder / "params.json").read_text())
    frames = len(params.get("frames") or [0])
    base = folder if frames == 1 else folder / "frames" / "000"
    lights = tuple((k, folder / "report" / f"sphere_{k}.png", base / "masks" / f"light_{k}.png")
                   for k in params["lights"]["kept"])
    maps = tuple((caption, folder / "textures" / f"{name}.png") for name, caption in MAPS
                 if (folder / "textures" / f"{name}.png").is_file())
    return FitView(folder.name, folder, folder / "mesh.glb", folder / "report" / "input.png", base / "render.png",
                   base / "render_face.png", lights, maps,
                   tone_words(params.get("skin_tone"), params.get("illuminant")), frames)


def tone_words(tone: dict | None, illuminant: dict | None) -> str:
    """The texture's skin tone (params.json ``skin_tone``) and how far the photo's unknown light level leaves it
    open, in words (markdown)."""
    if tone and tone.get("texture_ita") is None and tone.get("note"):
        return f"Skin tone: not measured ({tone['note']})."
    if not tone or tone.get("texture_ita") is None:
        return "Skin tone: not recorded for this fit."
    ita = tone["texture_ita"]
    scale = ", ".join(f"{name} {_bound(index)}" for index, (name, _) in enumerate(ITA_GROUPS))
    text = (f"**Skin tone: {ita_group(ita)}** (ITA {ita:.0f}° on the scale of Chardon et al. 1991 and Del Bino et "
            f"al. 2006: {scale}).")
    interval = tone.get("ita_interval")
    if interval is None:
        return text + (" This preset does not estimate how bright the photo's light was, so the reading has no "
                       "range (the default preset gives one).")
    darker, lighter = interval
    known = {"reference card": "the grey card marked in the photo", "given": "the white level it was given",
             "colour checker": "the colour checker found in the photo"}
    source = (illuminant or {}).get("source")
    if lighter - darker < 1.0 or source in known:
        how = known.get(source, "a known light")
        text += f" The light's brightness came from {how}, so no unknown light level widens this reading"
        if lighter - darker < 1.0:
            return text + "."
        return text + (f" (where it was held leaves ITA {darker:.0f}° to {lighter:.0f}°, "
                       f"{ita_group(darker)} to {ita_group(lighter)}).")
    text += (f" A photo does not say how bright its light was: with the light level one standard deviation "
             f"brighter or darker, the same photo reads as {ita_group(darker)} (ITA {darker:.0f}°) to "
             f"{ita_group(lighter)} ({lighter:.0f}°).")
    if lighter - darker > SURE_TONE_WIDTH:
        text += " A grey card or white paper in the photo, marked on it before fitting, narrows this."
    return text


def _bound(index: int) -> str:
    """The ITA range of category ``index`` of :data:`ITA_GROUPS` (lightest first), e.g. ``28-41°``."""
    lower = ITA_GROUPS[index][1]
    if index == 0:
        return f"above {lower:.0f}°"
    upper = ITA_GROUPS[index - 1][1]
    return f"below {upper:.0f}°" if lower == float("-inf") else f"{lower:.0f} to {upper:.0f}°"


def zip_folders(folders: list[Path], path: Path) -> Path:
    """Write every file of ``folders`` (each under its own name) into the zip ``path``, atomically: a partial
    zip is never left under that name."""
    partial = path.with_name(f".{path.name}.partial")
    try:
        with zipfile.ZipFile(partial, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=6) as archive:
            for folder in folders:
                for file in sorted(folder.rglob("*")):
                    if file.is_file():
                        archive.write(file, Path(folder.name) / file.relative_to(folder))
        os.replace(partial, path)
    except BaseException:
        partial.unlink(missing_ok=True)
        raise
    return path
