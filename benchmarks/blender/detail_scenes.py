"""Blender scenes of known albedo for held-out report splits of the detail truth set: the features of
``../shared/data/detail-synth`` (a beard, freckles, moles, a birthmark) on four skin tones under lights and shadows
that detail-synth does not have (settings are chosen on detail-synth and reported on these sets). Run by Blender,
not by deface's Python:

    blender -b -P benchmarks/blender/detail_scenes.py -- OUT [--samples 64] [--only SCENE[,SCENE]] [--tones T[,T]]
        [--beard painted|directional]

Two splits, each in its own folder. Without ``--only``, the first: five scenes (leaves, hand, side, warmcool, top;
``/work/detail-report``). ``--only blinds,branch,brimside,fingers``: the second, which no setting is tuned on
(``/work/detail-report2``): a sun through venetian blinds (slanted stripes), a soft sun through large leaves (a
dapple with wide penumbrae), a hat brim's slanted shadow over the forehead and one eye under a high side key, and a
spread hand's shadow over the nose, mouth and beard. ``--only window,clamshell,overcast``: the third, lights that
cast no shadow over the face (a large window to one side, a key above with a fill below, an overcast sky), for
settings meant for photos without cast shadows (``/work/detail-report3``).

Writes a truth set that ``deface bench albedo OUT`` reads: ``OUT/albedo/<tone>.png`` (the truth), ``OUT/masks/``
and ``OUT/mesh.obj`` (copied from detail-synth: the same UV masks and geometry), ``OUT/images/<tone>_<scene>.png``,
``OUT/MANIFEST.tsv`` (file, tone, light, kelvin, strength, shadow: as detail-synth's), ``OUT/README.md``, and, to
look at, ``OUT/contact.png`` (a row per tone: its albedo, then its renders) and ``OUT/exposure.tsv`` (the sRGB
means of both cheeks and the forehead, and the clipped pixels, of each render). The manifest, sheet and table list
every render in OUT (and only the scenes with a render there); the README describes those scenes.

The approach copies detail-synth (README there): Cycles, its ``mesh.obj`` (cm, the project's UV layout) with a
Principled BSDF whose base colour is the albedo (specular 0.35, roughness 0.45, no subsurface), a grey wall behind
the head, an 85 mm lens at 1.1 m, 512 x 512, the Standard view transform (the PNGs hold plain sRGB). Albedos:
detail-synth's two, and two more made by moving its features onto other bases of ``../shared/data/skin-tone-synth``:
inside the features (the union of the beard, freckle and birthmark masks and of every texel where detail-synth's
map differs from its base, which takes the moles), new = new base x detail / old base per channel in linear RGB,
clipped to [0, 1]; elsewhere the new base as it is. Pure Python (Debian's Blender has no numpy); deterministic
(the leaves are seeded; the rest is fixed geometry). Debian's Blender has no denoiser: 64 samples, about 30 s a
render on two cores.
"""

import math
import random
import shutil
import struct
import sys
import zlib
from array import array
from pathlib import Path

import bpy
from bpy_extras.object_utils import world_to_camera_view
from mathutils import Matrix, Vector

sys.path.insert(0, str(Path(__file__).resolve().parent))  # Blender runs this file directly: find scene_common
import scene_common  # noqa: E402
from scene_common import (  # noqa: E402
    MESH,
    NOMINAL_IRRADIANCE,
    SHARED,
    camera,
    diffuse_material,
    direction_of,
    environment,
    light,
)

DETAIL = SHARED / "detail-synth"
BASES = SHARED / "skin-tone-synth" / "albedo"
MASKS = ("beard", "freckles", "freckle_area", "birthmark", "forehead")
FEATURES = ("beard", "freckles", "birthmark")
"""The masks whose texels take the features (with the texels where detail-synth's map differs from its base)."""
DIFFERS = 3
"""A texel differs from its base when a channel is this many 8-bit levels away."""

# tone -> the detail-synth map its features come from (the nearest tone; None: detail-synth's own map, copied)
TONES = {"ita50": "ita30", "ita30": None, "ita-10": None, "ita-30": "ita-10"}

# key / fill: kind (area: a square of side ``size`` m; sun: ``size`` is its angle in degrees), (azimuth right of the
# camera, elevation) degrees, distance m (area), kelvin, strength (x the nominal irradiance at the face);
# occluder: what casts a shadow from the key (None, "leaves", "hand"), its distance from the face along the key's
# direction m, and the point of the face (offset right and up from the head's centre, m) its shadow falls on;
# world: RGB of the environment and its strength.
SCENES = {
    "leaves":   dict(key=dict(kind="sun", angle=(25, 40), distance=None, size=1.0, kelvin=5600, strength=1.1),
                     fill=None, occluder=("leaves", 0.35, (0.0, 0.0)),
                     world=(0.55, 0.7, 1.0), world_strength=0.22),
    "hand":     dict(key=dict(kind="area", angle=(40, 25), distance=1.5, size=0.08, kelvin=4800, strength=1.0),
                     fill=None, occluder=("hand", 0.12, (0.03, -0.065)),
                     world=(1.0, 1.0, 1.0), world_strength=0.15),
    "side":     dict(key=dict(kind="area", angle=(-60, 12), distance=1.5, size=0.08, kelvin=5200, strength=1.0),
                     fill=dict(kind="area", angle=(35, 10), distance=1.2, size=1.0, kelvin=5200, strength=0.12),
                     occluder=None, world=(1.0, 1.0, 1.0), world_strength=0.05),
    "warmcool": dict(key=dict(kind="area", angle=(40, 25), distance=1.2, size=0.5, kelvin=3200, strength=0.85),
                     fill=dict(kind="area", angle=(-50, 5), distance=1.2, size=1.0, kelvin=9000, strength=0.35),
                     occluder=None, world=(0.6, 0.75, 1.0), world_strength=0.05),
    "top":      dict(key=dict(kind="area", angle=(10, 65), distance=1.2, size=0.4, kelvin=5000, strength=1.3),
                     fill=None, occluder=None, world=(1.0, 1.0, 1.0), world_strength=0.1),
    # the second held-out split (``--only blinds,branch,brimside,fingers``; not rendered by default)
    "blinds":   dict(key=dict(kind="sun", angle=(-35, 30), distance=None, size=0.53, kelvin=5800, strength=1.0),
                     fill=None, occluder=("blinds", 0.8, (0.0, 0.03)),
                     world=(1.0, 0.95, 0.88), world_strength=0.15),
    "branch":   dict(key=dict(kind="sun", angle=(-30, 50), distance=None, size=3.0, kelvin=5300, strength=1.1),
                     fill=None, occluder=("branch", 0.35, (0.0, 0.0)),
                     world=(0.55, 0.7, 1.0), world_strength=0.22),
    "brimside": dict(key=dict(kind="sun", angle=(-45, 45), distance=None, size=1.5, kelvin=5600, strength=1.1),
                     fill=None, occluder=("brim", None, None),
                     world=(0.55, 0.7, 1.0), world_strength=0.25),
    "fingers":  dict(key=dict(kind="area", angle=(20, 20), distance=1.5, size=0.1, kelvin=4200, strength=0.9),
                     fill=dict(kind="area", angle=(-40, 10), distance=1.2, size=1.0, kelvin=4200, strength=0.08),
                     occluder=("fingers", 0.07, (0.0, -0.035)),
                     world=(1.0, 1.0, 1.0), world_strength=0.12),
    # the third held-out split (``--only window,clamshell,overcast``): lights without a cast shadow, for the preset
    # meant for such photos (``no-cast-shadows``)
    "window":   dict(key=dict(kind="area", angle=(70, 10), distance=1.5, size=1.2, kelvin=6000, strength=1.0),
                     fill=None, occluder=None, world=(0.9, 0.93, 1.0), world_strength=0.08),
    "clamshell": dict(key=dict(kind="area", angle=(0, 40), distance=1.0, size=0.6, kelvin=5000, strength=0.9),
                      fill=dict(kind="area", angle=(0, -30), distance=1.0, size=0.8, kelvin=5000, strength=0.3),
                      occluder=None, world=(1.0, 1.0, 1.0), world_strength=0.05),
    "overcast": dict(key=dict(kind="area", angle=(15, 60), distance=2.0, size=3.0, kelvin=6500, strength=0.8),
                     fill=None, occluder=None, world=(0.8, 0.85, 1.0), world_strength=0.35),
}
DEFAULT_SCENES = ("leaves", "hand", "side", "warmcool", "top")
"""The scenes rendered without ``--only``: the first report split (``/work/detail-report``). The others
(blinds, branch, brimside, fingers) make a second held-out split, rendered into their own folder with ``--only``."""
WALL = dict(reflectance=0.35, distance=0.6)
"""The grey wall: its reflectance and its distance behind the head's centre, m."""
LEAVES = dict(seed=7, count=270, spread=0.6, length=(0.015, 0.035), width=(0.35, 0.55), depth=0.04)
"""The foliage: leaves (ellipses) scattered over a square of side ``spread`` m facing the key light, each ``length``
m long (half-axis) and ``width`` x as wide, up to ``depth`` m in front of or behind the square."""
BRANCH = dict(seed=5, count=55, spread=0.6, length=(0.04, 0.07), width=(0.5, 0.8), depth=0.08)
"""The branch scene's foliage (as :data:`LEAVES`): fewer, larger leaves, another seed."""
BLINDS = dict(pitch=0.03, width=0.025, tilt=40.0, length=1.8, count=64, turn=22.0)
"""Venetian blinds: ``count`` slats (thin boards ``length`` m long, ``width`` m wide) ``pitch`` m apart, each
tilted ``tilt`` degrees about its long axis out of the blinds' plane (which faces the key), the slats turned
``turn`` degrees in that plane (a head tilted to the window), so the stripes cross the face at a slant."""
BRIM = dict(radius=0.15, offset=(0.0, 0.0, 0.15), tilt=(10.0, 0.0))
"""A hat's brim: a disk of ``radius`` m, its centre offset (right, back, up) m from the head's centre, tilted
(degrees about the camera's axis, right side down; about the left-right axis, front edge down)."""
FINGERS = dict(spread=(-24.0, -8.0, 8.0, 24.0), turn=100.0)
"""The fingers scene's hand: the fingers fanned out by ``spread`` degrees, the hand turned ``turn`` degrees in its
plane (fingers toward the face's left, across it), its fingers' middle over the scene's shadow point."""
HAIRS = dict(seed=11, share=0.43, length=(4.0, 9.0), fan=35.0, spread=8.0, colour=(62, 46, 36))
"""``--beard directional``: hairs seeded ``seed`` until they cover ``share`` of the beard mask (the painted beard's
dark share), each ``length`` texels long (at 512²), pointing down in UV (v down) turned by up to ``fan`` degrees
outward at the mask's sides, plus a Gaussian of ``spread`` degrees; dark brown (8-bit sRGB ``colour``, each hair x
0.8-1.2 in linear)."""
PATCHES = {"left_cheek": (-0.045, -0.01), "right_cheek": (0.045, -0.01), "forehead": (-0.025, 0.085)}
"""Offsets (right, up) from the head's centre of the skin patches whose sRGB means exposure.tsv lists."""


def arguments():
    args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    out = Path(args[0])
    options = {"--samples": "64", "--only": ",".join(DEFAULT_SCENES), "--tones": ",".join(TONES), "--beard": "painted"}
    for flag, value in zip(args[1::2], args[2::2], strict=False):
        options[flag] = value
    scenes, tones = options["--only"].split(","), options["--tones"].split(",")
    for name in scenes + tones:
        if name not in SCENES and name not in TONES:
            raise SystemExit(f"detail_scenes.py: unknown scene or tone {name!r}")
    if options["--beard"] not in ("painted", "directional"):
        raise SystemExit(f"detail_scenes.py: --beard is painted or directional, not {options['--beard']!r}")
    return out, int(options["--samples"]), scenes, tones, options["--beard"]


# --- 8-bit RGB images as flat lists, top row first (Blender's pixels start at the bottom) ---

def read_rgb(path, size=None):
    """(width, height, [r, g, b, r, ...] 0-255) of a PNG, scaled to ``size`` x ``size`` if given."""
    image = bpy.data.images.load(str(path))
    if size is not None:
        image.scale(size, size)
    width, height = image.size
    pixels = array("f", bytes(4 * 4 * width * height))
    image.pixels.foreach_get(pixels)
    bpy.data.images.remove(image)
    values = [round(v * 255) for v in pixels]
    rows = [values[4 * width * y:4 * width * (y + 1)] for y in range(height - 1, -1, -1)]
    return width, height, [v for row in rows for i, v in enumerate(row) if i % 4 != 3]


def write_png(path, width, height, values):
    """An 8-bit RGB PNG of ``values`` (flat, top row first)."""
    data = bytes(values)
    raw = b"".join(b"\x00" + data[3 * width * y:3 * width * (y + 1)] for y in range(height))

    def chunk(tag, body):
        return struct.pack(">I", len(body)) + tag + body + struct.pack(">I", zlib.crc32(tag + body) & 0xFFFFFFFF)

    Path(path).write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))
                           + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


def to_linear(level):
    v = level / 255
    return v / 12.92 if v <= 0.04045 else ((v + 0.055) / 1.055) ** 2.4


def to_level(v):
    v = min(max(v, 0.0), 1.0)
    return round(255 * (12.92 * v if v <= 0.0031308 else 1.055 * v ** (1 / 2.4) - 0.055))


# --- the truth: albedos, masks, mesh ---

def feature_texels(detail, base, size):
    """Texels that take the features: the feature masks, the texels where ``detail`` differs from ``base``, and
    their neighbours (the features' soft edges)."""
    inside = [False] * (size * size)
    for name in FEATURES:
        mask = read_rgb(DETAIL / "masks" / f"{name}.png")[2]
        for i in range(size * size):
            inside[i] = inside[i] or mask[3 * i] > 127
    for i in range(size * size):
        if max(abs(detail[3 * i + c] - base[3 * i + c]) for c in range(3)) >= DIFFERS:
            inside[i] = True
    grown = list(inside)
    for y in range(size):
        for x in range(size):
            if inside[y * size + x]:
                for ny in range(max(y - 1, 0), min(y + 2, size)):
                    for nx in range(max(x - 1, 0), min(x + 2, size)):
                        grown[ny * size + nx] = True
    return grown


def transferred_albedo(tone, source):
    """``tone``'s base with the features of detail-synth's ``source`` map: new base x detail / old base."""
    size, _, detail = read_rgb(DETAIL / "albedo" / f"{source}.png")
    old, new = read_rgb(BASES / f"{source}.png")[2], read_rgb(BASES / f"{tone}.png")[2]
    linear = [to_linear(level) for level in range(256)]
    out = list(new)
    for i, inside in enumerate(feature_texels(detail, old, size)):
        if inside:
            for c in range(3):
                k = 3 * i + c
                out[k] = to_level(linear[new[k]] * linear[detail[k]] / max(linear[old[k]], 1e-4))
    return size, out


def directional_beard(tone, size, values):
    """``values`` (``tone``'s albedo, 8-bit sRGB) with the beard mask's texels repainted: the tone's base skin, then
    short dark hairs that grow one way, as a real beard's do (down the chin and jaw, fanning outward from the
    middle, each within a few degrees of its neighbours), until they cover :data:`HAIRS`' share of the mask. The
    painted beard's strokes point every way; a fit that tells hair from a shadow's edge by how its texture is
    organised must be tested on this one too."""
    mask = read_rgb(DETAIL / "masks" / "beard.png")[2]
    base = read_rgb(BASES / f"{tone}.png")[2]
    inside = [mask[3 * i] > 127 for i in range(size * size)]
    texels = [i for i, flag in enumerate(inside) if flag]
    out = list(values)
    for i in texels:
        out[3 * i:3 * i + 3] = base[3 * i:3 * i + 3]
    centre = sum(i % size for i in texels) / len(texels)
    half = max(abs(i % size - centre) for i in texels)
    rng = random.Random(HAIRS["seed"])
    dark, target = set(), HAIRS["share"] * len(texels)
    while len(dark) < target:
        start = rng.choice(texels)
        x, y = start % size, start // size
        angle = math.radians(90.0 + HAIRS["fan"] * (x - centre) / half + rng.gauss(0.0, HAIRS["spread"]))
        length = rng.uniform(*HAIRS["length"])
        shade = rng.uniform(0.8, 1.2)
        for step in range(int(2 * length) + 1):
            px, py = int(round(x + 0.5 * step * math.cos(angle))), int(round(y + 0.5 * step * math.sin(angle)))
            if 0 <= px < size and 0 <= py < size and inside[py * size + px]:
                k = py * size + px
                dark.add(k)
                out[3 * k:3 * k + 3] = [to_level(to_linear(level) * shade) for level in HAIRS["colour"]]
    return out


def write_truth(out, tones, beard="painted"):
    for folder in ("albedo", "masks", "images"):
        (out / folder).mkdir(parents=True, exist_ok=True)
    shutil.copyfile(MESH, out / "mesh.obj")
    for name in MASKS:
        shutil.copyfile(DETAIL / "masks" / f"{name}.png", out / "masks" / f"{name}.png")
    for tone in tones:
        if TONES[tone] is None:
            shutil.copyfile(DETAIL / "albedo" / f"{tone}.png", out / "albedo" / f"{tone}.png")
        else:
            size, values = transferred_albedo(tone, TONES[tone])
            write_png(out / "albedo" / f"{tone}.png", size, size, values)
        if beard == "directional":
            (out / "albedo" / ".directional").touch()
            size, _, values = read_rgb(out / "albedo" / f"{tone}.png")
            write_png(out / "albedo" / f"{tone}.png", size, size, directional_beard(tone, size, values))


# --- the scene ---

def reset(samples):
    """8-bit PNG, seed 0, no denoiser (Debian's Blender 3.4 has no OpenImageDenoise)."""
    return scene_common.reset(samples, "PNG", "8", denoise=False, seed=0)


def surface_point(obj, centre, offset):
    """The face's front surface at ``offset`` (right, up) from the head's centre."""
    start = Vector((centre.x + offset[0], centre.y - 1.0, centre.z + offset[1]))
    hit, location, _, _ = obj.ray_cast(start, Vector((0.0, 1.0, 0.0)))
    return location if hit else Vector((start.x, centre.y, start.z))


def wall(centre):
    bpy.ops.mesh.primitive_plane_add(size=4.0, location=(centre.x, centre.y + WALL["distance"], centre.z),
                                     rotation=(math.pi / 2, 0, 0))
    bpy.context.active_object.data.materials.append(diffuse_material("wall", (WALL["reflectance"],) * 3))


def unseen(obj, material):
    """An occluder: casts shadows, the camera does not see it."""
    obj.data.materials.append(material)
    obj.visible_camera = False
    return obj


def leaves(frame, params=LEAVES):
    """The foliage gobo: seeded random ellipses in one mesh, in ``frame``'s plane (its z faces the light)."""
    rng = random.Random(params["seed"])
    vertices, faces = [], []
    for _ in range(params["count"]):
        x, y = ((rng.random() - 0.5) * params["spread"] for _ in range(2))
        z = (rng.random() - 0.5) * 2 * params["depth"]
        length = rng.uniform(*params["length"])
        width = length * rng.uniform(*params["width"])
        turn = rng.uniform(0, math.pi)
        start = len(vertices)
        for k in range(12):
            t = 2 * math.pi * k / 12
            u, v = length * math.cos(t), width * math.sin(t) * (1 - 0.25 * math.cos(t))  # a leaf: wider at its base
            vertices.append(frame @ Vector((x + u * math.cos(turn) - v * math.sin(turn),
                                            y + u * math.sin(turn) + v * math.cos(turn), z)))
        faces.append(tuple(range(start, start + 12)))
    mesh = bpy.data.meshes.new("leaves")
    mesh.from_pydata([tuple(v) for v in vertices], [], faces)
    obj = bpy.data.objects.new("leaves", mesh)
    bpy.context.scene.collection.objects.link(obj)
    unseen(obj, diffuse_material("leaf", (0.05, 0.12, 0.03)))


def part(name, shape, size, placement, material):
    """An unseen part of a hand at ``placement``: a "box" of ``size`` (x, y, z) m, or a "cylinder" along y of
    ``size`` (radius, length) m."""
    if shape == "box":
        bpy.ops.mesh.primitive_cube_add(size=1.0)
        shape_matrix = Matrix.Diagonal((*size, 1.0))
    else:  # a cylinder along y
        bpy.ops.mesh.primitive_cylinder_add(vertices=16, radius=size[0], depth=size[1])
        shape_matrix = Matrix.Rotation(math.pi / 2, 4, "X")
    obj = bpy.context.active_object
    obj.name = name
    obj.matrix_world = placement @ shape_matrix
    return unseen(obj, material)


def hand(frame):
    """A hand held up between the key light and the face: a palm box and five finger cylinders, in ``frame``
    (z toward the light, y up the fingers)."""
    skin = diffuse_material("hand", (0.45, 0.3, 0.25))
    parts = [("palm", "box", (0.0, 0.0, 0.0), (0.085, 0.095, 0.025), 0.0)]
    for i, (x, length) in enumerate(((-0.032, 0.065), (-0.011, 0.08), (0.011, 0.085), (0.032, 0.075))):
        parts.append((f"finger{i}", "cylinder", (x, 0.0475 + length / 2, 0.0), (0.0085, length), 0.0))
    parts.append(("thumb", "cylinder", (0.055, 0.0, 0.008), (0.01, 0.065), math.radians(-40)))
    for name, shape, location, size, tilt in parts:
        local = Matrix.Translation(location) @ Matrix.Rotation(tilt, 4, "Z")
        part(name, shape, size, frame @ local, skin)


def blinds(frame):
    """Venetian blinds in ``frame``'s plane (its z faces the light): tilted slats, thin boxes along its x."""
    slat = diffuse_material("slat", (0.6, 0.6, 0.58))
    for i in range(BLINDS["count"]):
        y = (i - (BLINDS["count"] - 1) / 2) * BLINDS["pitch"]
        bpy.ops.mesh.primitive_cube_add(size=1.0)
        obj = bpy.context.active_object
        obj.name = f"slat{i}"
        obj.matrix_world = frame @ Matrix.Translation((0.0, y, 0.0)) @ Matrix.Rotation(
            math.radians(BLINDS["tilt"]), 4, "X") @ Matrix.Diagonal((BLINDS["length"], BLINDS["width"], 0.002, 1.0))
        unseen(obj, slat)


def fingers(frame):
    """A hand with its fingers spread, in ``frame`` (z toward the light): a palm box, four finger cylinders fanned
    out from the palm's top edge and a thumb, with its fingers' middle at the frame's origin."""
    skin = diffuse_material("hand", (0.45, 0.3, 0.25))
    base, lengths = 0.0475, (0.065, 0.08, 0.085, 0.075)
    middle = base + 0.04  # the fingers' middle, above the palm's centre
    parts = [((0.0, -middle, 0.0), 0.0, "box", (0.085, 0.095, 0.025))]
    for x, length, spread in zip((-0.032, -0.011, 0.011, 0.032), lengths, FINGERS["spread"], strict=True):
        turn = math.radians(-spread)  # a positive spread fans the finger out to its side (+x)
        at = Vector((x - math.sin(turn) * length / 2, base + math.cos(turn) * length / 2 - middle, 0.0))
        parts.append((tuple(at), turn, "cylinder", (0.0085, length)))
    parts.append(((-0.062, -0.012 - middle, 0.008), math.radians(50), "cylinder", (0.01, 0.065)))
    for i, (location, tilt, shape, size) in enumerate(parts):
        part(f"hand{i}", shape, size, frame @ Matrix.Translation(location) @ Matrix.Rotation(tilt, 4, "Z"), skin)


def brim(centre):
    """A hat's brim above the head (:data:`BRIM`): a thin dark disk."""
    roll, pitch = (math.radians(a) for a in BRIM["tilt"])
    bpy.ops.mesh.primitive_cylinder_add(vertices=64, radius=BRIM["radius"], depth=0.004)
    obj = bpy.context.active_object
    obj.name = "brim"
    obj.matrix_world = Matrix.Translation(centre + Vector(BRIM["offset"])) @ Matrix.Rotation(roll, 4, "Y") \
        @ Matrix.Rotation(pitch, 4, "X")
    unseen(obj, diffuse_material("brim", (0.08, 0.07, 0.06)))


def occluder(settings, obj, centre):
    """The scene's occluder between the key light and the point of the face its shadow falls on."""
    kind, distance, offset = settings["occluder"]
    if kind == "brim":
        brim(centre)
        return
    target = surface_point(obj, centre, offset)
    direction = direction_of(settings["key"]["angle"])
    turn = direction.to_track_quat("Z", "Y").to_matrix().to_4x4()
    frame = Matrix.Translation(target + distance * direction) @ turn
    if kind == "leaves":
        leaves(frame)
    elif kind == "hand":
        hand(frame @ Matrix.Rotation(math.radians(-25), 4, "Z"))
    elif kind == "branch":
        leaves(frame, BRANCH)
    elif kind == "blinds":
        blinds(frame @ Matrix.Rotation(math.radians(BLINDS["turn"]), 4, "Z"))
    else:
        fingers(frame @ Matrix.Rotation(math.radians(FINGERS["turn"]), 4, "Z"))


def render(out, tone, name, samples):
    settings = SCENES[name]
    scene = reset(samples)
    obj, centre = scene_common.face(out / "albedo" / f"{tone}.png")
    camera(scene, centre)
    wall(centre)
    light(scene, "key", centre, **settings["key"])
    if settings["fill"] is not None:
        light(scene, "fill", centre, **settings["fill"])
    if settings["occluder"] is not None:
        occluder(settings, obj, centre)
    environment(scene, settings)
    scene.render.filepath = str(out / "images" / f"{tone}_{name}.png")
    bpy.ops.render.render(write_still=True)


# --- the set's tables ---

def patch_pixels(out, tone):
    """Where the skin patches of :data:`PATCHES` are in every render, as fractions (x right, y up)."""
    scene = reset(1)
    obj, centre = scene_common.face(out / "albedo" / f"{tone}.png")
    cam = camera(scene, centre)
    bpy.context.view_layer.update()
    return {name: world_to_camera_view(scene, cam, surface_point(obj, centre, offset))
            for name, offset in PATCHES.items()}


def exposure(path, patches):
    """The sRGB mean (R, G, B) of each patch (9 x 9 pixels) and the count of pixels with a channel at 255."""
    width, height, values = read_rgb(path)
    means = {}
    for name, patch in patches.items():
        cx, cy = round(patch.x * width), round((1 - patch.y) * height)
        box = [3 * (y * width + x) for y in range(cy - 4, cy + 5) for x in range(cx - 4, cx + 5)]
        means[name] = tuple(sum(values[i + c] for i in box) / len(box) for c in range(3))
    return means, sum(1 for i in range(0, len(values), 3) if max(values[i:i + 3]) >= 255)


def rendered(out):
    return [(tone, name) for tone in TONES for name in SCENES if (out / "images" / f"{tone}_{name}.png").is_file()]


def scenes_in(out):
    """The scenes with a render in OUT, in SCENES' order."""
    return [name for name in SCENES if any(name == scene for _, scene in rendered(out))]


def write_manifest(out):
    lines = ["file\ttone\tlight\tkelvin\tstrength\tshadow"]
    for tone, name in rendered(out):
        key = SCENES[name]["key"]
        shadow = int(SCENES[name]["occluder"] is not None)
        lines.append(f"{tone}_{name}.png\t{tone}\t{name}\t{key['kelvin']}\t{key['strength']}\t{shadow}")
    (out / "MANIFEST.tsv").write_text("\n".join(lines) + "\n")


def write_exposure(out, patches):
    lines = ["file\t" + "\t".join(f"{name}_rgb" for name in PATCHES) + "\tclipped_pixels"]
    for tone, name in rendered(out):
        means, clipped = exposure(out / "images" / f"{tone}_{name}.png", patches)
        lines.append(f"{tone}_{name}.png\t" + "\t".join(",".join(f"{v:.0f}" for v in means[patch])
                                                          for patch in PATCHES) + f"\t{clipped}")
    (out / "exposure.tsv").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def write_contact(out, tile=128):
    """A row per tone: its albedo, then its renders in SCENES' order (the scenes with a render in OUT; black: that
    tone's render missing)."""
    columns = ["albedo", *scenes_in(out)]
    tones = [tone for tone in TONES if (out / "albedo" / f"{tone}.png").is_file()]
    width, height = tile * len(columns), tile * len(tones)
    sheet = [0] * (3 * width * height)
    for row, tone in enumerate(tones):
        for column, name in enumerate(columns):
            path = out / "albedo" / f"{tone}.png" if name == "albedo" else out / "images" / f"{tone}_{name}.png"
            if not path.is_file():
                continue
            values = read_rgb(path, tile)[2]
            for y in range(tile):
                start = 3 * ((row * tile + y) * width + column * tile)
                sheet[start:start + 3 * tile] = values[3 * tile * y:3 * tile * (y + 1)]
    write_png(out / "contact.png", width, height, sheet)


NUMBERS = ("no", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine")


def write_readme(out, samples):
    present = scenes_in(out)
    first = all(name in DEFAULT_SCENES for name in present)  # the first report split (the default scenes)
    scenes = "\n".join(f"   - `{name}`: {_describe(SCENES[name])}" for name in present)
    tones = "\n".join(f"   - `{tone}`: " + ("detail-synth's map, copied" if source is None else
                                            f"`../skin-tone-synth/albedo/{tone}.png` with the features of "
                                            f"detail-synth's `{source}` map") for tone, source in TONES.items())
    count = NUMBERS[len(present)] if len(present) < len(NUMBERS) else str(len(present))
    only = "" if present == list(DEFAULT_SCENES) else f" --only {','.join(present)}"
    if first:
        title = f"# {out.name}: renders of known albedo with dark features, a held-out report split"
        intro = f"""\
The report split of the detail truth set: the features of `../detail-synth` (a moustache and goatee, freckles,
moles, a birthmark) on four skin tones under {count} lights and shadows that detail-synth does not have. Settings are
chosen on detail-synth and reported here."""
        tell = """\
What it can tell: whether settings chosen on detail-synth keep the beard, freckles, moles and birthmark in the
albedo on other skin tones and take out shadows of other shapes (dappled foliage, a hand) and shading from other
directions (side, top, a warm key with a cool fill). What it cannot: real hair's geometry, real skin's subsurface
scattering, or a camera's tone curve."""
        generated = " Generated"
    elif all(SCENES[name]["occluder"] is None for name in present):
        title = f"# {out.name}: renders of known albedo with dark features, a held-out split without cast shadows"
        intro = f"""\
A third held-out split of the detail truth set: the features of `../detail-synth` on the same four skin tones as
`../detail-report`, under {count} lights that cast no shadow over the face (the face's own shading only), for settings
meant for photos without cast shadows (`deface fit --preset no-cast-shadows`)."""
        tell = """\
What it can tell: whether such settings keep the beard, freckles, moles and birthmark in the albedo and take out the
face's own shading under lights they were not chosen on. What it cannot: real hair's geometry, real skin's
subsurface scattering, or a camera's tone curve."""
        generated = "\nGenerated"
    else:
        title = f"# {out.name}: renders of known albedo with dark features, a second held-out split"
        intro = f"""\
A second held-out split of the detail truth set: the features of `../detail-synth` (a moustache and goatee,
freckles, moles, a birthmark) on the same four skin tones as `../detail-report`, under {count} lights and cast shadows
that neither detail-synth nor detail-report has. No setting is tuned on it. The 9x9 patches of `exposure.tsv` may
fall in a shadow here (the blinds' stripes, the dapple, the brim)."""
        tell = """\
What it can tell: whether settings keep the beard, freckles, moles and birthmark in the albedo and take out cast
shadows they were not chosen on: the stripes of venetian blinds across the face at a slant, a soft dapple of large
leaves with wide penumbrae, a hat brim's slanted shadow over the forehead and one eye, and a spread hand's shadow
over the nose, mouth and beard (a shadow on dark, textured albedo). What it cannot: real hair's geometry, real
skin's subsurface scattering, or a camera's tone curve."""
        generated = "\nGenerated"
    beard = ""
    if (out / "albedo" / ".directional").exists():
        only += " --beard directional"
        beard = f"""
   Then the beard mask's texels are repainted (`--beard directional`): the tone's base skin, then dark brown hairs
   (sRGB {HAIRS['colour']}) {HAIRS['length'][0]:g}-{HAIRS['length'][1]:g} texels long that grow one way, as a real
   beard's do: down, fanning up to {HAIRS['fan']:g} degrees outward at the sides, {HAIRS['spread']:g} degrees of
   spread (seed {HAIRS['seed']}), until they cover {HAIRS['share']:.0%} of the mask (the painted beard's share)."""
    (out / "README.md").write_text(f"""{title}

{intro}{generated} by `benchmarks/blender/detail_scenes.py` in the deface repository
(`blender -b -P benchmarks/blender/detail_scenes.py -- OUT --samples {samples}{only}`); renders never go into git.

How it was made:
1. Albedos (`albedo/<tone>.png`, the truth, 512², sRGB):
{tones}
   The features are moved per channel in linear RGB: new = new base x detail / old base, clipped to [0, 1], inside
   the union of `masks/beard.png`, `masks/freckles.png`, `masks/birthmark.png` and of every texel where detail-synth's
   map differs from its base by {DIFFERS}/255 or more (the moles), grown by one texel; elsewhere the new base as it
   is. `masks/` and `mesh.obj` are detail-synth's (the same UV layout and geometry).{beard}
2. Scene (Blender 3.4, Cycles, {samples} samples, no denoiser, Standard view transform, so the PNG holds plain sRGB):
   `mesh.obj` (cm) with a Principled BSDF (base colour = the albedo, specular 0.35, roughness 0.45, no subsurface),
   a grey wall ({WALL['reflectance']:.0%}) {WALL['distance']} m behind the head's centre, 85 mm lens at 1.1 m,
   512x512. Key strength 1 is {NOMINAL_IRRADIANCE:g} W/m² at the face. Occluders cast shadows and are unseen by
   the camera. Lights (azimuth right of the camera, elevation, in degrees):
{scenes}
3. `images/<tone>_<scene>.png`. The eyes are holes in the mesh (the face model has no eyeballs).

`MANIFEST.tsv`: file, tone, light (the scene), kelvin and strength (the key light's), shadow (1: an occluder casts
a shadow on the face). `exposure.tsv`: the sRGB means (9x9 pixels) of the left and right cheeks and of the
forehead, and the pixels with a channel at 255. `contact.png`: a row per tone, its albedo then its renders.

{tell}
""")


def _describe(settings):
    def one(light):
        size = f"{light['size']}° sun" if light["kind"] == "sun" else f"{light['size']} m area light at " \
                                                                       f"{light['distance']} m"
        return f"{size} from ({light['angle'][0]}, {light['angle'][1]}), {light['kelvin']} K, strength " \
               f"{light['strength']}"

    text = "key: " + one(settings["key"])
    if settings["fill"] is not None:
        text += "; fill: " + one(settings["fill"])
    if settings["occluder"] is not None:
        kind, distance, offset = settings["occluder"]
        if kind == "brim":
            text += (f"; a hat's brim (a disk of radius {BRIM['radius']} m, its centre {BRIM['offset']} m right, "
                     f"back and up of the head's centre, tilted {BRIM['tilt'][0]}° right side down and "
                     f"{BRIM['tilt'][1]}° front edge down) above the head")
        else:
            what = {"leaves": "a foliage gobo (seeded random leaf-shaped ellipses)",
                    "hand": "a hand (a palm box, five finger cylinders)",
                    "branch": f"a foliage gobo of larger leaves ({BRANCH['count']} seeded random leaf-shaped "
                              f"ellipses, {BRANCH['length'][0]}-{BRANCH['length'][1]} m half-length, seed "
                              f"{BRANCH['seed']})",
                    "blinds": f"venetian blinds ({BLINDS['width']} m slats {BLINDS['pitch']} m apart, tilted "
                              f"{BLINDS['tilt']:g}°, turned {BLINDS['turn']:g}° in their plane)",
                    "fingers": f"a hand with its fingers spread (a palm box, five finger cylinders, the fingers "
                               f"fanned {FINGERS['spread'][0]:g}° to {FINGERS['spread'][-1]:g}°)"}[kind]
            text += f"; {what} {distance} m in front of the face toward the key"
    return text + f"; sky {settings['world']} x {settings['world_strength']}"


def main():
    out, samples, scenes, tones, beard = arguments()
    write_truth(out, tones, beard)
    for tone in tones:
        for name in scenes:
            render(out, tone, name, samples)
    write_manifest(out)
    write_exposure(out, patch_pixels(out, tones[0]))
    write_contact(out)
    write_readme(out, samples)


main()
