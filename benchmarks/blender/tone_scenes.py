"""Blender scenes of known albedo for the skin-tone truth set (docs/skin-tone.md "A truth set that spans what
cameras do"): run by Blender, not by deface's Python.

    blender -b -P benchmarks/blender/tone_scenes.py -- OUT [--samples 32] [--only SCENE[,SCENE]] [--tones T[,T]]
                                                         [--variants plain,card,checker,white]

Writes ``OUT/exr/<scene>_<tone>_<variant>.exr`` (scene-linear, before any exposure) and ``OUT/exr/<...>.json`` (the
scene's settings and, for the card and checker variants, their box in the image). ``benchmarks/tone_truth.py
make OUT`` then exposes each render as a camera would (manual, average and centre-weighted metering) and writes the
PNGs and MANIFEST.tsv. The approach copies ``../shared/data/skin-tone-synth`` (README there): Cycles, the fitted mesh
of ``../shared/data/detail-synth`` (cm, the project's UV layout) with a Principled BSDF whose base colour is one of
``../shared/data/skin-tone-synth/albedo/*.png`` (specular 0.35, i.e. F0 = 0.08 x 0.35 = 0.028; roughness 0.45; no
subsurface), an 85 mm lens at 1.1 m, 512 x 512. Beyond it: walls from dark to pale, key lights at several
distances, coloured environments, a grey card (18 %) or a ColorChecker held beside the face, facing the camera.

Variants: ``plain``; ``card``: an 18 % grey card, 9 cm square, beside the face facing the camera; ``checker``: a
ColorChecker Classic (11 x 7.6 cm, the passport's size; texture from ``OUT/checker.png``, made by tone_truth.py)
where the card is, beside the cheek facing the camera;
``white``: the face's albedo a uniform 80 % with no specular (the key light's true white level on the face).
"""

import json
import math
import sys
from pathlib import Path

import bpy
from bpy_extras.object_utils import world_to_camera_view

sys.path.insert(0, str(Path(__file__).resolve().parent))  # Blender runs this file directly: find scene_common
import scene_common  # noqa: E402
from scene_common import SHARED, diffuse_material  # noqa: E402

ALBEDO = SHARED / "skin-tone-synth" / "albedo"
TONES = ("ita50", "ita30", "ita10", "ita-10", "ita-30")

# key: (azimuth right of the camera, elevation) degrees, distance m, softbox side m, kelvin, strength (x the nominal
# irradiance at the face); wall: reflectance (grey, or RGB), distance behind the face m (None: no wall, the
# environment shows); world: RGB of the environment and its strength. Odd scenes tune, even scenes report.
SCENES = {
    "studio":    dict(key=(40, 30), distance=1.2, size=0.5, kelvin=5500, strength=1.0,
                      wall=0.18, wall_distance=0.7, world=(1.0, 1.0, 1.0), world_strength=0.15),
    "highkey":   dict(key=(-35, 25), distance=1.5, size=0.8, kelvin=6500, strength=1.3,
                      wall=0.75, wall_distance=0.8, world=(1.0, 1.0, 1.0), world_strength=0.25),
    "lowkey":    dict(key=(55, 20), distance=0.6, size=0.3, kelvin=3200, strength=0.8,
                      wall=0.04, wall_distance=1.0, world=(1.0, 0.85, 0.7), world_strength=0.08),
    "outdoor":   dict(key=(30, 45), distance=3.0, size=0.3, kelvin=5600, strength=1.6,
                      wall=None, wall_distance=None, world=(0.45, 0.65, 1.0), world_strength=0.45),
    "beige":     dict(key=(-45, 35), distance=2.5, size=0.6, kelvin=4500, strength=0.7,
                      wall=(0.55, 0.45, 0.33), wall_distance=0.5, world=(1.0, 1.0, 1.0), world_strength=0.12),
    "bluegrey":  dict(key=(35, 30), distance=1.0, size=0.6, kelvin=5000, strength=1.1,
                      wall=(0.5, 0.58, 0.66), wall_distance=0.6, world=(1.0, 1.0, 1.0), world_strength=0.18),
    "tungsten":  dict(key=(50, 25), distance=0.9, size=0.4, kelvin=2800, strength=1.4,
                      wall=0.3, wall_distance=1.5, world=(0.6, 0.75, 1.0), world_strength=0.15),
    "greenroom": dict(key=(-40, 20), distance=1.8, size=1.0, kelvin=6000, strength=0.6,
                      wall=(0.25, 0.4, 0.22), wall_distance=0.9, world=(0.7, 1.0, 0.6), world_strength=0.18),
}
SPLIT = {name: ("tune" if i % 2 == 0 else "report") for i, name in enumerate(SCENES)}


def arguments():
    args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    out = Path(args[0])
    options = {"--samples": "32", "--only": ",".join(SCENES), "--tones": ",".join(TONES),
               "--variants": "plain"}
    for flag, value in zip(args[1::2], args[2::2], strict=False):
        options[flag] = value
    return out, int(options["--samples"]), options["--only"].split(","), options["--tones"].split(","), \
        options["--variants"].split(",")


def reset(samples):
    """32-bit OpenEXR, denoised when this Blender has OpenImageDenoise."""
    denoise = "OPENIMAGEDENOISE" in dir(bpy.app.build_options) and bpy.app.build_options.openimagedenoise
    return scene_common.reset(samples, "OPEN_EXR", "32", denoise)


def plane(name, size, location, material):
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=location, rotation=(math.pi / 2, 0, 0))
    obj = bpy.context.active_object
    obj.name = name
    obj.scale = (size[0], size[1], 1.0)
    obj.data.materials.append(material)
    return obj


def build(scene, settings, centre, variant, out):
    """Camera, wall, key light, environment and the variant's card; returns the card's or checker's box."""
    camera = scene_common.camera(scene, centre)
    wall = settings["wall"]
    if wall is not None:
        colour = (wall,) * 3 if isinstance(wall, float) else wall
        plane("wall", (4.0, 4.0), (centre.x, centre.y + settings["wall_distance"], centre.z),
              diffuse_material("wall", colour))
    scene_common.light(scene, "key", centre, settings["key"], settings["size"], settings["distance"],
                       settings["kelvin"], settings["strength"])
    scene_common.environment(scene, settings)
    azimuth = math.radians(settings["key"][0])
    if variant == "card":
        card = plane("card", (0.09, 0.09), (centre.x + 0.15 * _side(azimuth), centre.y - 0.02, centre.z - 0.04),
                     diffuse_material("card", (0.18, 0.18, 0.18)))
        return _box(scene, camera, card)
    if variant == "checker":
        checker = plane("checker", (0.11, 0.076), (centre.x + 0.16 * _side(azimuth), centre.y - 0.02,
                                                   centre.z - 0.04),
                        diffuse_material("checker", None, out / "checker.png"))
        return _box(scene, camera, checker)
    return None


def _side(azimuth):
    """The card goes on the key light's side, so the head does not shade it."""
    return 1.0 if azimuth >= 0 else -1.0


def _box(scene, camera, obj):
    """(left, top, right, bottom) of ``obj`` in the image, as fractions (top = 0)."""
    bpy.context.view_layer.update()  # matrix_world holds the new object's scale only after an update
    corners = [world_to_camera_view(scene, camera, obj.matrix_world @ v.co) for v in obj.data.vertices]
    xs, ys = [c.x for c in corners], [1.0 - c.y for c in corners]
    return [min(xs), min(ys), max(xs), max(ys)]


def main():
    out, samples, scenes, tones, variants = arguments()
    (out / "exr").mkdir(parents=True, exist_ok=True)
    for name in scenes:
        settings = SCENES[name]
        for variant in variants:
            for tone in (["white"] if variant == "white" else tones):
                stem = f"{name}_{tone}_{variant}"
                if (out / "exr" / f"{stem}.exr").exists():
                    continue
                scene = reset(samples)
                _, centre = scene_common.face(None if variant == "white" else ALBEDO / f"{tone}.png")
                box = build(scene, settings, centre, variant, out)
                scene.render.filepath = str(out / "exr" / f"{stem}.exr")
                bpy.ops.render.render(write_still=True)
                meta = {"scene": name, "tone": tone, "variant": variant, "split": SPLIT[name], "box": box,
                        "samples": samples, "settings": settings}
                (out / "exr" / f"{stem}.json").write_text(json.dumps(meta))


main()
