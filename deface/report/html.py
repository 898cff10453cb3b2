"""``report.html`` for every fit and ``OUT/index.html`` for a batch: self-contained, offline pages (relative
links to the fit's own files and to the images made here under ``report/``; no scripts from anywhere else).

The fit's page shows the input beside I_out, each kept light as a lit sphere beside its mask, the face
region, the three textures and the albedo under the neutral light, a turntable GIF, the per-term loss curves,
time per stage, the preset and the values that differ from it, the optional networks and the run's notes.
"""

from __future__ import annotations

import html
import math
from dataclasses import asdict, is_dataclass
from pathlib import Path

import numpy as np
import torch

from deface.fit import presets
from deface.fit.output import FitOutput
from deface.io.images import save_png
from deface.relight.lights import preset_lights
from deface.relight.turntable import turntable_frames, write_animation
from deface.render.sh import cosine_lobe_coefficients, sh_basis, white_light

REPORT_DIR = "report"
SPHERE_SIZE = 96
SPHERE_ALBEDO = 0.6  # grey of the spheres that show each light
TURNTABLE_FRAMES = 12

# Marks the page as loaded with every image decoded (the browser test reads it); reports the broken ones.
CHECK_SCRIPT = """<script>
window.addEventListener("load", function () {
  var broken = Array.prototype.filter.call(document.images, function (i) {
    return !i.complete || i.naturalWidth === 0; });
  document.body.setAttribute("data-images", broken.length ? "broken " + broken.map(function (i) {
    return i.getAttribute("src"); }).join(" ") : "ok " + document.images.length);
});
</script>"""

STYLE = """<style>
body { font-family: system-ui, sans-serif; margin: 1.5em; color: #222; background: #fafafa; }
h1 { font-size: 1.4em; } h2 { font-size: 1.1em; margin-top: 1.6em; border-bottom: 1px solid #ccc; }
.row { display: flex; flex-wrap: wrap; gap: 1em; align-items: flex-start; }
figure { margin: 0; text-align: center; } figcaption { font-size: 0.85em; color: #555; }
img { image-rendering: pixelated; background: #000; border: 1px solid #ddd; }
table { border-collapse: collapse; font-size: 0.9em; } td, th { border: 1px solid #ddd; padding: 0.2em 0.6em; }
.notes li { font-size: 0.9em; }
</style>"""


def lit_sphere(light: torch.Tensor, size: int = SPHERE_SIZE, albedo: float = SPHERE_ALBEDO) -> np.ndarray:
    """[size, size, 4] a grey Lambertian sphere facing the camera (+z) under one SH light [B*B, 3] (as the
    renderer renders it: ``Renderer.rendered_lights``): linear RGB E(n) / pi * albedo, alpha 1 on the sphere (no
    shadows: a sphere does not shadow itself)."""
    bands = int(round(light.shape[0] ** 0.5))
    centre = (torch.arange(size, dtype=torch.float32) + 0.5) / size * 2 - 1
    y, x = torch.meshgrid(-centre, centre, indexing="ij")
    inside = x * x + y * y <= 1
    normals = torch.stack([x, y, torch.sqrt((1 - x * x - y * y).clamp_min(0))], -1)
    irradiance = sh_basis(normals, bands) @ (cosine_lobe_coefficients(bands)[:, None] * light) / math.pi
    colour = (albedo * irradiance).clamp_min(0) * inside[..., None]
    return torch.cat([colour, inside[..., None].float()], -1).numpy()


def write_report(fit: FitOutput, folder: Path, name: str = "") -> Path:
    """Write ``folder/report.html`` and its images (``folder/report/``) for ``fit`` written in ``folder``."""
    images = folder / REPORT_DIR
    images.mkdir(parents=True, exist_ok=True)
    base = "" if fit.num_frames == 1 else "frames/000/"
    rendered = fit.renderer.rendered_lights(fit.lights.kept_sh)
    for slot, light in enumerate(fit.lights.kept):
        save_png(images / f"sphere_{light}.png", lit_sphere(rendered[slot]))
    neutral = fit.render(lights=white_light(fit.lights.bands))[0]
    save_png(images / "neutral.png", neutral.face.numpy())
    for index, frame in enumerate(fit.frames):
        save_png(images / ("input.png" if index == 0 else f"input_{index:03d}.png"), frame.photo_srgb, srgb=False)
    write_animation(turntable_frames(fit, preset_lights("studio", fit.lights.bands), 90.0, TURNTABLE_FRAMES),
                    images / "turntable.gif", fps=8)
    curves = _loss_curves(fit, images / "losses.png")
    lights = "".join(
        f'<figure><img src="{REPORT_DIR}/sphere_{k}.png" width="{SPHERE_SIZE}"><img src="{base}masks/light_{k}.png" '
        f'height="{SPHERE_SIZE}"><figcaption>light {k}: sphere and mask M_L</figcaption></figure>'
        for k in fit.lights.kept)
    body = f"""<h1>deface fit {html.escape(name)}</h1>
<h2>Input and result</h2>
<div class="row">{_figure(f"{REPORT_DIR}/input.png", "input: the working image (the crop around the face)")}
{_figure(f"{base}render.png", "I_out: the fit composited into the photo")}
{_figure(f"{base}render_face.png", "I_R: the rendered face")}</div>
{_frames_section(fit)}
<h2>Lights kept ({len(fit.lights.kept)} of {fit.lights.sh.shape[0]}) and the face region</h2>
<div class="row">{lights}{_figure(f"{base}masks/face.png", "face region M_o")}</div>
<h2>Textures</h2>
<div class="row">{_figure("textures/diffuse.png", _diffuse_caption(fit), 256)}
{_figure("textures/specular.png", "specular", 256)}{_figure("textures/roughness.png", "roughness", 256)}
{_figure(f"{REPORT_DIR}/neutral.png", "albedo under the neutral light")}</div>
{_detail_hint(fit)}
<h2>Turntable (studio light)</h2>
<div class="row">{_figure(f"{REPORT_DIR}/turntable.gif", "the textured mesh turning")}</div>
<h2>Losses</h2>
<div class="row">{_figure(f"{REPORT_DIR}/losses.png", "per-term loss curves") if curves else "<p>no loss record</p>"}
</div>
<h2>Run</h2>
{_run_tables(fit)}"""
    page = (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>deface {html.escape(name)}'
            f"</title>{STYLE}</head>\n<body>\n{body}\n{CHECK_SCRIPT}\n</body></html>\n")
    path = folder / "report.html"
    path.write_text(page)
    return path


def _frames_section(fit: FitOutput) -> str:
    """Every frame (a clip's, or each photo of a person) beside its fit; empty for one photo (above)."""
    if fit.num_frames == 1:
        return ""
    inputs = [f"{REPORT_DIR}/input.png"] + [f"{REPORT_DIR}/input_{i:03d}.png" for i in range(1, fit.num_frames)]
    rows = "".join(
        f'<div class="row">{_figure(inputs[i], f"frame {i}: input")}'
        f'{_figure(f"frames/{i:03d}/render.png", f"frame {i}: the fit composited")}'
        f'{_figure(f"frames/{i:03d}/render_face.png", f"frame {i}: the rendered face")}</div>'
        for i in range(fit.num_frames))
    return f"<h2>Every frame beside its fit ({fit.num_frames} frames, one shape and one set of maps)</h2>\n{rows}"


def _diffuse_caption(fit: FitOutput) -> str:
    """The diffuse map's caption: its skin tone, and the range the unknown light level leaves open."""
    tone = fit.skin_tone()
    source = fit.illuminant and (fit.illuminant.detail or fit.illuminant.source)
    if fit.photo_illuminants:
        source = "each photo's own scene (the first photo's spread)"
    where = f"; light level from {source}" if source else ""
    if tone["texture_ita"] is None:
        return f"diffuse (skin tone not measured: {tone['note']})"
    if tone["ita_interval"] is None:
        return f"diffuse (skin ITA {tone['texture_ita']:.0f}{where})"
    darker, lighter = tone["ita_interval"]
    if lighter - darker < 0.5:
        return f"diffuse (skin ITA {tone['texture_ita']:.0f}{where})"
    return (f"diffuse (skin ITA {tone['texture_ita']:.0f}; {darker:.0f} to {lighter:.0f} for the light level"
            f"{where})")


def _detail_hint(fit: FitOutput) -> str:
    """How to keep more of a beard or freckles, for a fit whose stage 2 weighed their texture as shading evidence more
    than the no-cast-shadows preset does (a larger strength: the default, fast); the fit cannot tell a photo without
    cast shadows itself (docs/textures.md "Why the choice is the user's"). Empty otherwise, and for the presets that
    reproduce the paper or NextFace (strength 0: no evidence weight)."""
    lighter = presets.get("no-cast-shadows").shading_evidence.strength
    if fit.config.shading_evidence.strength <= lighter:
        return ""
    return ("<p>A beard, stubble or freckles paler here than in the photo? This preset keeps a cast shadow's edge "
            "out of the map at their cost. If nothing casts a shadow on this face (a hat brim, hair, leaves, a "
            "hand), fit it with <code>--preset no-cast-shadows</code>, which keeps more of them "
            "(docs/textures.md, \"Photos without cast shadows\").</p>")


def _figure(src: str, caption: str, width: int | None = None) -> str:
    size = f' width="{width}"' if width else ""
    return f'<figure><img src="{html.escape(src)}"{size}><figcaption>{html.escape(caption)}</figcaption></figure>'


def _loss_curves(fit: FitOutput, path: Path) -> bool:
    """One panel per stage: every named term per step (log scale); False when there is no record."""
    stages = [stage for stage, steps in fit.record.terms.items() if steps and any(steps)]
    if not stages:
        return False
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot

    figure, axes = pyplot.subplots(1, len(stages), figsize=(5.5 * len(stages), 3.6), squeeze=False)
    for axis, stage in zip(axes[0], stages, strict=True):
        steps = fit.record.terms[stage]
        names = sorted({name for terms in steps for name in terms})
        for term in names:
            values = np.array([abs(terms.get(term, np.nan)) for terms in steps])
            if np.nanmax(values, initial=0) > 0:
                axis.plot(values, label=term, linewidth=1.2)
        axis.plot(np.abs(fit.record.losses.get(stage, [])), label="total", color="black", linewidth=1.2,
                  linestyle="--")
        axis.set_yscale("log")
        axis.set_title(stage)
        axis.set_xlabel("step")
        axis.legend(fontsize=7)
    figure.tight_layout()
    figure.savefig(path, dpi=90)
    pyplot.close(figure)
    return True


def _run_tables(fit: FitOutput) -> str:
    times = "".join(f"<tr><td>{html.escape(s)}</td><td>{t:.1f} s</td></tr>" for s, t in fit.record.seconds.items())
    networks = "".join(f"<tr><td>{html.escape(k)}</td><td>{html.escape(str(v))}</td></tr>"
                       for k, v in fit.record.optional_networks.items())
    changed = "".join(f"<tr><td>{html.escape(k)}</td><td>{html.escape(str(v))}</td><td>{html.escape(str(d))}</td>"
                      f"</tr>" for k, v, d in config_changes(fit.config)) or '<tr><td colspan="3">none</td></tr>'

    notes = "".join(f"<li>{html.escape(note)}</li>" for note in fit.record.notes)
    return (f"<p>preset <b>{html.escape(fit.config.preset)}</b>, seed {fit.config.seed}</p>"
            f'<div class="row"><table><tr><th>stage</th><th>time</th></tr>{times}</table>'
            f"<table><tr><th>optional network</th><th>used?</th></tr>{networks}</table>"
            f"<table><tr><th>differs from the preset</th><th>value</th><th>preset</th></tr>{changed}</table></div>"
            f'<h2>Notes and warnings</h2><ul class="notes">{notes}</ul>')


def config_changes(config) -> list[tuple[str, object, object]]:
    """(dotted name, value, preset value) of every config value that differs from its named preset."""
    try:
        reference = presets.get(config.preset.split(":")[0])
    except (KeyError, ValueError):
        return []
    ours, theirs = _flat(asdict(config)), _flat(asdict(reference))
    return [(key, value, theirs.get(key)) for key, value in ours.items()
            if key != "preset" and theirs.get(key) != value]


def _flat(values: dict, prefix: str = "") -> dict:
    flat = {}
    for key, value in values.items():
        if isinstance(value, dict):
            flat.update(_flat(value, f"{prefix}{key}."))
        elif not is_dataclass(value):
            flat[f"{prefix}{key}"] = value
    return flat


def write_index(output: Path, names: list[str]) -> Path | None:
    """``output/index.html``: one entry per input folder that has a report (its I_out and a link); nothing
    (None) when no input has one."""
    rows = []
    for name in names:
        folder = output / name
        if not (folder / "report.html").is_file():
            continue
        thumb = f"{name}/render.png" if (folder / "render.png").is_file() else f"{name}/frames/000/render.png"
        rows.append(f'<figure><a href="{html.escape(name)}/report.html"><img src="{html.escape(thumb)}" '
                    f'height="160"></a><figcaption>{html.escape(name)}</figcaption></figure>')
    if not rows:
        return None
    page = (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>deface fits</title>{STYLE}'
            f'</head>\n<body><h1>deface fits ({len(rows)})</h1><div class="row">{"".join(rows)}</div>\n'
            f"{CHECK_SCRIPT}\n</body></html>\n")
    path = output / "index.html"
    path.write_text(page)
    return path
