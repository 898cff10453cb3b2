"""Blender scenes of known albedo for the several-photos-of-one-person fit (issue 59): ONE person (one albedo: the
face, beard, freckles, moles and birthmark of ``../shared/data/detail-synth``) seen in a SET of photos, each with its
own head turn and its own lights and cast shadows. Every set is rendered for every tone (a tone is another person).
Run by Blender, not by deface's Python:

    blender -b -P benchmarks/blender/person_scenes.py -- OUT [--samples 64] [--split seen|heldout] [--tones T[,T]]
        [--only SET[,SET]] [--check]

``--split seen`` (the default; ``/work/person-synth``): the sets ``three``, ``turn`` and ``five``, which settings may
be tuned on. ``--split heldout`` (``/work/person-synth-heldout``): the sets ``porch``, ``garden`` and ``desk``,
other yaws, lights (blinds, a branch, spread fingers, warm and cool colours, an overcast sky) and occluder seeds; no
setting is tuned on them. ``--tones``: default ita30,ita-10 (detail_scenes' tones: ita50, ita30, ita-10, ita-30).
``--only``: render only these sets of the split (the tables still list every render in OUT). ``--check``: write the
truth and the geometric tables (which texels each photo shows, lights and shadows), print them, render nothing.

The yaw: a rotation of the head (the mesh) about the world's vertical axis (+z) through the head's centre (the
mesh's bounding-box centre, as in scene_common), right-handed: POSITIVE YAW TURNS THE HEAD TO THE SUBJECT'S LEFT,
i.e. the nose toward the CAMERA'S RIGHT (+x in the image). The camera, wall and lights do not turn: a light's
(azimuth right of the camera, elevation) is in the camera's frame. Occluders follow the turned head: the point their
shadow is aimed at is a point of the face (offset right and up from the head's centre in the head's own frame, on its
front surface) carried by the head's turn, the occluder then placed between it and the key (as detail_scenes does on
the unturned head); a hat's brim turns with the head.

Each photo's cast shadows are checked geometrically, not assumed: every texel of the features (the beard, the
freckle area, the birthmark, the forehead box, and the eyes: the skin within EYE_RIM of the eye holes) is put on the
posed mesh (its UV triangle, barycentric) and rays are cast to the camera and to KEY_GRID x KEY_GRID points over the
key light (its square, or a sun's disk). A texel is SHOWN when it faces the camera within 70 degrees (deface's albedo
benchmark's limit) and the head does not hide it; LIT (without a cast shadow) when it faces the key's centre (cosine
>= 0.1), the head does not hide the key's centre and the occluder hides none of the key's points; in the OCCLUDER'S
SHADOW when the occluder hides half of them or more. ``shadow_over`` (MANIFEST.tsv) lists the features with at least
SHADOW_SHARE of their shown texels in the occluder's shadow; ``shadows.tsv`` has the shares; the README gives, per
set, the share of the beard's shown texels that one photo at least shows lit, and ``coverage.png`` maps it.
The beard mask runs under the chin: texels there face down and only a light below the eyes' height reaches them,
so the keys that must light them sit 5-10 degrees below it.

Writes (the layout of detail_scenes.py, plus the sets): ``OUT/albedo/<tone>.png``, ``OUT/masks/*.png``,
``OUT/mesh.obj`` (by detail_scenes' own functions), ``OUT/images/<tone>_<set>_<n>.png`` (n = 1, 2, ... the photo's
place in the set), ``OUT/MANIFEST.tsv`` (file, tone, light, kelvin, strength, shadow, set, yaw, shadow_over),
``OUT/cameras.json`` (per file: camera and head world matrices, mesh.obj to world, lens, sensor, image size),
``OUT/shadows.tsv``, ``OUT/coverage.png``, ``OUT/exposure.tsv``, ``OUT/contact.png`` (a row per set and tone: the
albedo, then the set's photos in order) and ``OUT/README.md``. The tables list every render in OUT; the README
describes those sets.

The scene is detail_scenes.py's (Cycles, detail-synth's mesh with a Principled BSDF, a grey wall 0.6 m behind the
head's centre, an 85 mm lens at 1.1 m, 512 x 512, Standard view transform), reused by importing it; its occluders
(leaves, hand, brim, fingers, blinds, branch) and light kinds. Pure Python (Debian's Blender has no numpy);
deterministic (Cycles seed 0; the foliage is seeded; the rest is fixed geometry). Debian's Blender has no
denoiser: 64 samples, about 30 s a render on two cores.
"""

import json
import math
import sys
import textwrap
import time
import types
from pathlib import Path

import bpy
from bpy_extras.object_utils import world_to_camera_view
from mathutils import Matrix, Vector
from mathutils.bvhtree import BVHTree

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))  # Blender runs this file directly: find scene_common and detail_scenes
import scene_common  # noqa: E402
from scene_common import NOMINAL_IRRADIANCE, camera, direction_of, environment, light  # noqa: E402


def _import_detail_scenes():
    """detail_scenes.py as a module. It is a script that calls ``main()`` on its last line (Blender runs it with
    ``-P``), so it is executed without that call: its functions and tables, not a render."""
    if "detail_scenes" in sys.modules:
        return sys.modules["detail_scenes"]
    path = HERE / "detail_scenes.py"
    source = path.read_text()
    lines = source.rstrip().splitlines()
    if lines[-1].strip() == "main()":
        source = "\n".join(lines[:-1]) + "\n"
    elif "__main__" not in source:
        raise SystemExit(f"person_scenes.py: {path} no longer ends with main(); import it another way")
    module = types.ModuleType("detail_scenes")
    module.__file__ = str(path)
    sys.modules["detail_scenes"] = module
    exec(compile(source, str(path), "exec"), module.__dict__)  # noqa: S102 (the repository's own file)
    return module


detail = _import_detail_scenes()

DEFAULT_TONES = ("ita30", "ita-10")
FEATURES = ("beard", "freckles", "birthmark", "forehead", "eyes")
"""What a cast shadow can be over (MANIFEST's shadow_over), in this order."""
FEATURE_MASKS = {"beard": "beard", "freckles": "freckle_area", "birthmark": "birthmark", "forehead": "forehead"}
"""The feature -> the mask (masks/) whose texels it is; "eyes" has no mask: the skin within EYE_RIM of the holes."""
EYE_RIM = 0.012
"""The eyes: texels within this many metres (on the head) of a vertex of an eye hole's rim (the lids, corners)."""
SHADOW_SHARE = 0.2
"""A feature is in shadow_over when this share of its shown texels is in the occluder's shadow."""
SHOWN_ANGLE = 70.0
"""A texel is shown when it faces the camera within this many degrees (deface's albedo benchmark's MAX_ANGLE)."""
LIT_COSINE = 0.1
"""A texel is lit when it faces the key's centre within acos(this), the head does not hide the key's centre from it
(the head's own shadows: the nose's, the chin's) and the occluder hides none of the key's points (its penumbra is
shadow)."""
OFFSET = 0.001
"""Rays start this many metres off the surface (along its smooth normal): the mesh's flat triangles and folds under
the chin would otherwise shadow themselves."""
KEY_GRID = 3
"""The key is sampled at KEY_GRID x KEY_GRID points (see key_points)."""
SIZE = 512


# --- the sets ---

def area(angle, size, kelvin, strength, distance=1.5):
    return dict(kind="area", angle=angle, distance=distance, size=size, kelvin=kelvin, strength=strength)


def sun(angle, size, kelvin, strength):
    return dict(kind="sun", angle=angle, distance=None, size=size, kelvin=kelvin, strength=strength)


def photo(yaw, name, key, fill=None, occluder=None, world=(1.0, 1.0, 1.0), world_strength=0.1):
    """One photo: the head's yaw (degrees), the light's name (MANIFEST's light), the key and fill lights (as
    detail_scenes' SCENES), the occluder (None or a dict: kind; distance m from the face toward the key; at: the
    face's point its shadow falls on, offset (right, up) m from the head's centre in the head's frame; turn: degrees
    in the occluder's plane; params: the foliage's parameters) and the sky."""
    return dict(yaw=yaw, light=name, key=key, fill=fill, occluder=occluder, world=world, world_strength=world_strength)


def foliage(params, distance, at, **changes):
    return dict(kind="leaves", params=dict(params, **changes), distance=distance, at=at)


LEAVES, BRANCH = detail.LEAVES, detail.BRANCH
SKY = (0.55, 0.7, 1.0)
SETS = {
    "seen": {
        "three": [
            photo(-20, "key-left", area((-35, -5), 0.3, 5200, 1.0),
                  fill=area((40, 10), 1.0, 5200, 0.15, distance=1.2), world_strength=0.06),
            photo(0, "hand", area((30, 15), 0.08, 4800, 1.0),
                  occluder=dict(kind="hand", distance=0.12, at=(0.0, -0.03), turn=155.0), world_strength=0.15),
            photo(25, "window-right", area((40, -10), 1.2, 6000, 1.0), world=(0.9, 0.93, 1.0), world_strength=0.08),
        ],
        "turn": [
            photo(-30, "key-left", area((-45, -5), 0.3, 5200, 1.0),
                  fill=area((40, 10), 1.0, 5200, 0.12, distance=1.2), world_strength=0.06),
            photo(0, "brim", area((25, 50), 0.15, 5000, 1.1), occluder=dict(kind="brim"), world_strength=0.15),
            photo(30, "key-right", area((45, -5), 0.3, 5200, 1.0),
                  fill=area((-40, 10), 1.0, 5200, 0.12, distance=1.2), world_strength=0.06),
        ],
        "five": [
            photo(-35, "even", area((0, 5), 1.5, 5000, 0.9, distance=1.2), world_strength=0.1),
            photo(-10, "leaves", sun((-15, 40), 1.0, 5600, 1.1), occluder=foliage(LEAVES, 0.35, (0.0, 0.0)),
                  world=SKY, world_strength=0.22),
            photo(0, "key", area((-30, 10), 0.3, 4800, 1.0), world_strength=0.12),
            photo(15, "brim", area((30, 50), 0.15, 5000, 1.1), occluder=dict(kind="brim"), world_strength=0.15),
            photo(35, "hand", area((-20, 10), 0.08, 4800, 1.0),
                  occluder=dict(kind="hand", distance=0.12, at=(0.0, -0.045), turn=155.0), world_strength=0.15),
        ],
    },
    "heldout": {
        "porch": [
            photo(-8, "blinds", sun((-40, 30), 0.53, 5800, 1.0),
                  occluder=dict(kind="blinds", distance=0.8, at=(0.0, -0.03), turn=30.0),
                  world=(1.0, 0.95, 0.88), world_strength=0.15),
            photo(24, "warmcool", area((40, -8), 0.5, 3200, 0.85, distance=1.2),
                  fill=area((-50, 5), 1.0, 9000, 0.35, distance=1.2), world=(0.6, 0.75, 1.0), world_strength=0.05),
            photo(12, "overcast", area((15, 60), 3.0, 6500, 0.8, distance=2.0), world=(0.8, 0.85, 1.0),
                  world_strength=0.35),
            photo(-22, "lamp-left", area((-40, -8), 0.25, 3300, 1.0), world=(1.0, 0.9, 0.8), world_strength=0.06),
        ],
        "garden": [
            photo(20, "branch", sun((35, 45), 3.0, 5300, 1.1),
                  occluder=foliage(BRANCH, 0.35, (0.02, 0.0), seed=31), world=SKY, world_strength=0.22),
            photo(-15, "cool-key", area((-35, -5), 0.4, 7500, 1.0),
                  fill=area((45, 5), 1.0, 3000, 0.2, distance=1.2), world=(0.7, 0.8, 1.0), world_strength=0.06),
            photo(5, "lamp", area((15, -5), 0.3, 3000, 0.95), world=(1.0, 0.9, 0.8), world_strength=0.06),
            photo(30, "window", area((50, -10), 1.2, 6500, 1.0), world=(0.9, 0.93, 1.0), world_strength=0.08),
        ],
        "desk": [
            photo(-5, "fingers", area((20, 20), 0.1, 4200, 0.9),
                  fill=area((-40, 10), 1.0, 4200, 0.08, distance=1.2),
                  occluder=dict(kind="fingers", distance=0.07, at=(0.0, -0.045), turn=100.0), world_strength=0.12),
            photo(18, "lamp-side", area((35, -10), 0.25, 2900, 1.0), world=(1.0, 0.9, 0.8), world_strength=0.06),
            photo(-28, "window-cool", area((-40, -10), 1.2, 7500, 1.0), world=(0.85, 0.9, 1.0), world_strength=0.08),
            photo(8, "leaves", sun((10, 50), 1.0, 5600, 1.1), occluder=foliage(LEAVES, 0.35, (0.03, 0.01), seed=23),
                  world=SKY, world_strength=0.22),
        ],
    },
}


def arguments():
    args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    if not args or args[0].startswith("--"):
        raise SystemExit("person_scenes.py: usage: blender -b -P person_scenes.py -- OUT [--samples N] "
                         "[--split seen|heldout] [--tones T[,T]] [--only SET[,SET]] [--check]")
    out, rest = Path(args[0]), args[1:]
    check = "--check" in rest
    rest = [a for a in rest if a != "--check"]
    options = {"--samples": "64", "--split": "seen", "--tones": ",".join(DEFAULT_TONES), "--only": ""}
    for flag, value in zip(rest[0::2], rest[1::2], strict=False):
        if flag not in options:
            raise SystemExit(f"person_scenes.py: unknown option {flag!r}")
        options[flag] = value
    split = options["--split"]
    if split not in SETS:
        raise SystemExit(f"person_scenes.py: --split is seen or heldout, not {split!r}")
    tones = options["--tones"].split(",")
    for tone in tones:
        if tone not in detail.TONES:
            raise SystemExit(f"person_scenes.py: unknown tone {tone!r} (one of {', '.join(detail.TONES)})")
    sets = options["--only"].split(",") if options["--only"] else list(SETS[split])
    for name in sets:
        if name not in SETS[split]:
            raise SystemExit(f"person_scenes.py: no set {name!r} in split {split}")
    return out, int(options["--samples"]), split, sets, tones, check


# --- the scene ---

def yaw_matrix(centre, yaw):
    """The head's world matrix: a turn of ``yaw`` degrees about the vertical axis through ``centre``."""
    return Matrix.Translation(centre) @ Matrix.Rotation(math.radians(yaw), 4, "Z") @ Matrix.Translation(-centre)


OBJ_TO_BLENDER = Matrix(((0.01, 0.0, 0.0, 0.0), (0.0, 0.0, -0.01, 0.0), (0.0, 0.01, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)))
"""mesh.obj's coordinates (cm; y up, z toward the viewer) -> the imported mesh's (m; z up, -y toward the camera)."""


def occluders(settings, obj, centre, head):
    """The photo's occluder, following the turned head (``head``: its world matrix)."""
    spec = settings["occluder"]
    if spec["kind"] == "brim":
        detail.brim(centre)
        brim = bpy.data.objects["brim"]
        brim.matrix_world = head @ brim.matrix_world
        return
    target = head @ detail.surface_point(obj, centre, spec["at"])  # obj.ray_cast is in the head's own frame
    direction = direction_of(settings["key"]["angle"])
    turn = direction.to_track_quat("Z", "Y").to_matrix().to_4x4()
    frame = Matrix.Translation(target + spec["distance"] * direction) @ turn
    if spec["kind"] == "leaves":
        detail.leaves(frame, spec["params"])
    else:
        frame = frame @ Matrix.Rotation(math.radians(spec["turn"]), 4, "Z")
        {"hand": detail.hand, "blinds": detail.blinds, "fingers": detail.fingers}[spec["kind"]](frame)


def build(out, tone, settings, samples):
    """The photo's scene; returns (scene, head object, head's centre, head matrix, camera)."""
    scene = detail.reset(samples)
    obj, centre = scene_common.face(out / "albedo" / f"{tone}.png")
    head = yaw_matrix(centre, settings["yaw"])
    obj.matrix_world = head
    cam = camera(scene, centre)
    detail.wall(centre)
    light(scene, "key", centre, **settings["key"])
    if settings["fill"] is not None:
        light(scene, "fill", centre, **settings["fill"])
    if settings["occluder"] is not None:
        occluders(settings, obj, centre, head)
    environment(scene, settings)
    bpy.context.view_layer.update()
    return scene, obj, centre, head, cam


def photos(split, sets, tones):
    """(tone, set, n, file, settings) of every render of ``sets``, tone by tone."""
    return [(tone, name, n, f"{tone}_{name}_{n}.png", settings)
            for tone in tones for name in sets for n, settings in enumerate(SETS[split][name], 1)]


# --- the geometry: which texels each photo shows, lights and shades ---

def feature_texels(obj):
    """The features' texels on the head (its own frame): {feature: [(texel index, point, normal), ...]}, from the UV
    triangles (barycentric at the texel centres, v up) and the masks; the eyes from the eye holes' rims."""
    mesh = obj.data
    masks = {}
    for feature, mask in FEATURE_MASKS.items():
        _, _, values = detail.read_rgb(detail.DETAIL / "masks" / f"{mask}.png", SIZE)
        masks[feature] = [values[3 * i] > 127 for i in range(SIZE * SIZE)]
    rims = eye_rims(mesh)
    near_eyes = [sum((mesh.vertices[i].co for i in rim), Vector()) / len(rim) for rim in rims]
    uv = mesh.uv_layers.active.data
    points = {}
    for polygon in mesh.polygons:
        loops = list(polygon.loop_indices)
        corners = [(uv[k].uv.x * SIZE - 0.5, (1.0 - uv[k].uv.y) * SIZE - 0.5) for k in loops]
        vertices = [mesh.vertices[mesh.loops[k].vertex_index] for k in loops]
        centroid = sum((v.co for v in vertices), Vector()) / 3
        eyeish = any((centroid - c).length < 0.035 for c in near_eyes)
        (x0, y0), (x1, y1), (x2, y2) = corners
        det = (y1 - y2) * (x0 - x2) + (x2 - x1) * (y0 - y2)
        if abs(det) < 1e-12:
            continue
        for y in range(max(math.floor(min(y0, y1, y2)), 0), min(math.ceil(max(y0, y1, y2)), SIZE - 1) + 1):
            for x in range(max(math.floor(min(x0, x1, x2)), 0), min(math.ceil(max(x0, x1, x2)), SIZE - 1) + 1):
                index = y * SIZE + x
                if index in points:
                    continue
                a = ((y1 - y2) * (x - x2) + (x2 - x1) * (y - y2)) / det
                b = ((y2 - y0) * (x - x2) + (x0 - x2) * (y - y2)) / det
                c = 1.0 - a - b
                if min(a, b, c) < -1e-6:
                    continue
                wanted = eyeish or any(masks[f][index] for f in FEATURE_MASKS)
                if not wanted:
                    continue
                point = a * vertices[0].co + b * vertices[1].co + c * vertices[2].co
                normal = (a * vertices[0].normal + b * vertices[1].normal + c * vertices[2].normal).normalized()
                points[index] = (point, normal)
    texels = {feature: [] for feature in FEATURES}
    rim_points = [mesh.vertices[i].co.copy() for rim in rims for i in rim]
    for index in sorted(points):
        point, normal = points[index]
        for feature in FEATURE_MASKS:
            if masks[feature][index]:
                texels[feature].append((index, point, normal))
        if min((point - r).length for r in rim_points) < EYE_RIM:
            texels["eyes"].append((index, point, normal))
    return texels


def eye_rims(mesh):
    """The vertex indices of the eye holes' rims: the mesh's boundary loops other than its outline, above the
    head's middle (the mouth's hole is below it)."""
    count = {}
    for polygon in mesh.polygons:
        vs = list(polygon.vertices)
        for i in range(len(vs)):
            edge = (min(vs[i], vs[i - 1]), max(vs[i], vs[i - 1]))
            count[edge] = count.get(edge, 0) + 1
    neighbours = {}
    for (a, b), n in count.items():
        if n == 1:
            neighbours.setdefault(a, []).append(b)
            neighbours.setdefault(b, []).append(a)
    loops, seen = [], set()
    for start in sorted(neighbours):
        if start in seen:
            continue
        stack, loop = [start], []
        while stack:
            v = stack.pop()
            if v not in seen:
                seen.add(v)
                loop.append(v)
                stack.extend(neighbours[v])
        loops.append(sorted(loop))
    loops.sort(key=len)
    inner = loops[:-1]  # the longest loop is the mesh's outline
    middle = sum(v.co.z for v in mesh.vertices) / len(mesh.vertices)
    rims = [loop for loop in inner if sum(mesh.vertices[i].co.z for i in loop) / len(loop) > middle]
    if len(rims) != 2:
        raise SystemExit(f"person_scenes.py: expected two eye holes in the mesh, found {len(rims)}")
    return rims


def world_bvh(objects):
    vertices, polygons = [], []
    for obj in objects:
        start = len(vertices)
        vertices.extend(obj.matrix_world @ v.co for v in obj.data.vertices)
        polygons.extend(tuple(start + i for i in p.vertices) for p in obj.data.polygons)
    return BVHTree.FromPolygons(vertices, polygons) if polygons else None


def key_points(settings, centre):
    """KEY_GRID x KEY_GRID points of the key light (area: a grid over its square, corners included) or, for a sun,
    directions over its disk's angular square: [(point or None, direction or None)]."""
    key = settings["key"]
    direction = direction_of(key["angle"])
    turn = (-direction).to_track_quat("-Z", "Y").to_matrix()
    steps = [2 * i / (KEY_GRID - 1) - 1 for i in range(KEY_GRID)]
    offsets = [(u, v) for v in steps for u in steps]
    if key["kind"] == "sun":
        half = math.radians(key["size"]) / 2
        return [(None, (direction + math.tan(half) * (turn @ Vector((u, v, 0.0)))).normalized())
                for u, v in offsets]
    location = centre + key["distance"] * direction
    return [(location + key["size"] / 2 * (turn @ Vector((u, v, 0.0))), None) for u, v in offsets]


def survey(obj, centre, head, cam, settings, texels):
    """{feature: [(shown, lit, occluded, self-shadowed, angle), ...]} per texel (in ``texels``' order): whether the
    photo shows it, lights it without a cast shadow, has it in the occluder's shadow, in the head's own shadow, and
    the angle between its normal and the way to the camera (degrees)."""
    head_bvh = world_bvh([obj])
    others = [o for o in bpy.context.scene.objects if o.type == "MESH" and o is not obj and o.visible_camera is False]
    occluder_bvh = world_bvh(others)
    rotation = head.to_3x3()
    eye = cam.matrix_world.translation
    points = key_points(settings, centre)
    middle = len(points) // 2
    shown_cos = math.cos(math.radians(SHOWN_ANGLE))
    result = {}
    for feature, items in texels.items():
        flags = []
        for _, local, local_normal in items:
            p, n = head @ local, (rotation @ local_normal).normalized()
            start = p + OFFSET * n
            view = eye - p
            cosine = n.dot(view.normalized())
            shown = cosine >= shown_cos and head_bvh.ray_cast(start, view.normalized(), view.length)[0] is None
            blocked_occluder = 0
            for k, (location, direction) in enumerate(points):
                if direction is None:
                    ray = location - p
                    reach, direction = ray.length, ray.normalized()
                else:
                    reach = 10.0
                if k == middle:
                    facing = n.dot(direction)
                    own = facing <= 0.0 or head_bvh.ray_cast(start, direction, reach)[0] is not None
                if occluder_bvh is not None and occluder_bvh.ray_cast(start, direction, reach)[0] is not None:
                    blocked_occluder += 1
            lit = facing >= LIT_COSINE and not own and blocked_occluder == 0
            flags.append((shown, lit, facing > 0 and blocked_occluder >= len(points) / 2, facing > 0 and own,
                          math.degrees(math.acos(max(-1.0, min(1.0, cosine))))))
        result[feature] = flags
    return result


def shares(flags):
    """(shown texels, share of them lit, in the occluder's shadow, in the head's own shadow)."""
    shown = [f for f in flags if f[0]]
    if not shown:
        return 0, 0.0, 0.0, 0.0
    return (len(shown), sum(f[1] for f in shown) / len(shown), sum(f[2] for f in shown) / len(shown),
            sum(f[3] for f in shown) / len(shown))


def shadow_over(result):
    return [f for f in FEATURES if shares(result[f])[0] and shares(result[f])[2] >= SHADOW_SHARE]


def coverage(results, feature):
    """(texels shown in some photo of the set, share of them shown and lit in one photo at least, the texels
    shown but never lit, the smallest angle to the camera at which a photo shows one of those)."""
    count = len(results[0][feature])
    ever = [any(r[feature][i][0] for r in results) for i in range(count)]
    good = [any(r[feature][i][0] and r[feature][i][1] for r in results) for i in range(count)]
    shown = sum(ever)
    never = [i for i in range(count) if ever[i] and not good[i]]
    closest = min((r[feature][i][4] for i in never for r in results if r[feature][i][0]), default=None)
    return shown, (sum(good) / shown if shown else 0.0), len(never), closest


def geometry(out, split, tone):
    """Every set's survey, computed on its photos' scenes (the same for every tone): the texels, {set: [result,
    ...]} and the cameras' records {set: [record, ...]}."""
    scene = detail.reset(1)
    obj, _ = scene_common.face(None)
    texels = feature_texels(obj)
    print("person_scenes.py: texels " + ", ".join(f"{f} {len(t)}" for f, t in texels.items()), flush=True)
    surveys, records = {}, {}
    for name, settings_list in SETS[split].items():
        surveys[name], records[name] = [], []
        for settings in settings_list:
            scene, obj, centre, head, cam = build(out, tone, settings, 1)
            surveys[name].append(survey(obj, centre, head, cam, settings, texels))
            records[name].append(camera_record(scene, cam, head, settings))
    return texels, surveys, records


def camera_record(scene, cam, head, settings):
    def rows(matrix):
        return [[round(v, 7) + 0.0 for v in row] for row in matrix]  # + 0.0: no -0.0

    return {"camera_matrix_world": rows(cam.matrix_world), "head_matrix_world": rows(head),
            "mesh_obj_to_world": rows(head @ OBJ_TO_BLENDER),
            "lens_mm": cam.data.lens, "sensor_width_mm": cam.data.sensor_width,
            "image_size": [scene.render.resolution_x, scene.render.resolution_y],
            "focal_px": round(cam.data.lens / cam.data.sensor_width * scene.render.resolution_x, 4),
            "yaw_deg": float(settings["yaw"])}


def check_matrices(out, tone):
    """mesh_obj_to_world takes mesh.obj's first vertex to where Blender puts it (the importer's axes)."""
    detail.reset(1)
    obj, centre = scene_common.face(out / "albedo" / f"{tone}.png")
    head = yaw_matrix(centre, 30.0)
    obj.matrix_world = head
    for line in (out / "mesh.obj").read_text().splitlines():
        if line.startswith("v "):
            first = Vector([float(v) for v in line.split()[1:4]])
            break
    mine = head @ OBJ_TO_BLENDER @ first
    blender = obj.matrix_world @ obj.data.vertices[0].co
    if (mine - blender).length > 1e-6:
        raise SystemExit(f"person_scenes.py: mesh.obj -> world is off: {mine} vs {blender}")


# --- the tables ---

def rendered(out, split, tones):
    return [row for row in photos(split, list(SETS[split]), tones) if (out / "images" / row[3]).is_file()]


def write_manifest(out, rows, surveys):
    lines = ["file\ttone\tlight\tkelvin\tstrength\tshadow\tset\tyaw\tshadow_over"]
    for tone, name, n, file, settings in rows:
        key = settings["key"]
        shadow = int(settings["occluder"] is not None)
        over = ",".join(shadow_over(surveys[name][n - 1]))
        lines.append(f"{file}\t{tone}\t{settings['light']}\t{key['kelvin']}\t{key['strength']}\t{shadow}\t{name}\t"
                     f"{float(settings['yaw']):.1f}\t{over}")
    (out / "MANIFEST.tsv").write_text("\n".join(lines) + "\n")


def write_shadows(out, split, surveys):
    """Per photo (the same for every tone): for each feature its shown texels and the shares of them lit, in the
    occluder's shadow and in the head's own shadow."""
    lines = ["set\tphoto\tyaw\tlight\t" + "\t".join(f"{f}_shown\t{f}_lit\t{f}_occluded\t{f}_self" for f in FEATURES)]
    for name, settings_list in SETS[split].items():
        for n, settings in enumerate(settings_list, 1):
            cells = []
            for feature in FEATURES:
                count, lit, occluded, own = shares(surveys[name][n - 1][feature])
                cells += [str(count), f"{lit:.3f}", f"{occluded:.3f}", f"{own:.3f}"]
            lines.append(f"{name}\t{n}\t{settings['yaw']}\t{settings['light']}\t" + "\t".join(cells))
    (out / "shadows.tsv").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def write_coverage(out, split, texels, surveys, size=256):
    """coverage.png: a UV map per set, side by side: the beard's and the freckle area's texels green where a photo
    of the set shows them lit without a cast shadow, red where photos show them but none lit, grey where no photo
    shows them; the rest of the map dark."""
    names = list(SETS[split])
    width = size * len(names)
    sheet = [24] * (3 * width * size)
    scale = SIZE // size
    for column, name in enumerate(names):
        results = surveys[name]
        for feature in ("freckles", "beard"):
            for i, (index, _, _) in enumerate(texels[feature]):
                shown = any(r[feature][i][0] for r in results)
                good = any(r[feature][i][0] and r[feature][i][1] for r in results)
                colour = (40, 200, 40) if good else (220, 30, 30) if shown else (110, 110, 110)
                if feature == "freckles":
                    colour = tuple(c // 2 for c in colour)
                y, x = index // SIZE // scale, index % SIZE // scale
                start = 3 * (y * width + column * size + x)
                sheet[start:start + 3] = colour
    detail.write_png(out / "coverage.png", width, size, sheet)


def write_cameras(out, rows, records):
    cameras = {file: records[name][n - 1] for _, name, n, file, _ in rows}
    (out / "cameras.json").write_text(json.dumps(cameras, indent=1) + "\n")


def patch_pixels(out, split, tone):
    """{(set, n): {patch: (x, y) fraction, or None where the photo does not show it}}: detail_scenes' skin patches
    on the turned head."""
    patches = {}
    for name, settings_list in SETS[split].items():
        for n, settings in enumerate(settings_list, 1):
            scene, obj, centre, head, cam = build(out, tone, settings, 1)
            head_bvh = world_bvh([obj])
            eye = cam.matrix_world.translation
            found = {}
            for patch, offset in detail.PATCHES.items():
                point = head @ detail.surface_point(obj, centre, offset)
                view = eye - point
                hidden = head_bvh.ray_cast(point + 1e-4 * view.normalized(), view.normalized(), view.length)[0]
                found[patch] = None if hidden is not None else world_to_camera_view(scene, cam, point)
            patches[(name, n)] = found
    return patches


def write_exposure(out, rows, patches):
    lines = ["file\t" + "\t".join(f"{name}_rgb" for name in detail.PATCHES) + "\tclipped_pixels"]
    for _, name, n, file, _ in rows:
        found = patches[(name, n)]
        means, clipped = detail.exposure(out / "images" / file, {k: v for k, v in found.items() if v is not None})
        cells = [",".join(f"{v:.0f}" for v in means[patch]) if patch in means else "hidden"
                 for patch in detail.PATCHES]
        lines.append(f"{file}\t" + "\t".join(cells) + f"\t{clipped}")
    (out / "exposure.tsv").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def write_contact(out, split, tones, tile=128):
    """A row per set and tone (sets in order, tones within a set): its albedo, then the set's photos in order
    (black where a render is missing)."""
    rows = [(name, tone) for name in SETS[split] for tone in tones]
    columns = 1 + max(len(photos_) for photos_ in SETS[split].values())
    width, height = tile * columns, tile * len(rows)
    sheet = [0] * (3 * width * height)
    for row, (name, tone) in enumerate(rows):
        paths = [out / "albedo" / f"{tone}.png"] + [out / "images" / f"{tone}_{name}_{n}.png"
                                                   for n in range(1, len(SETS[split][name]) + 1)]
        for column, path in enumerate(paths):
            if not path.is_file():
                continue
            values = detail.read_rgb(path, tile)[2]
            for y in range(tile):
                start = 3 * ((row * tile + y) * width + column * tile)
                sheet[start:start + 3 * tile] = values[3 * tile * y:3 * tile * (y + 1)]
    detail.write_png(out / "contact.png", width, height, sheet)


def describe_light(key):
    if key["kind"] == "sun":
        what = f"{key['size']}° sun"
    else:
        what = f"{key['size']} m area light at {key['distance']} m"
    return f"{what} from ({key['angle'][0]}, {key['angle'][1]}), {key['kelvin']} K, strength {key['strength']}"


def describe_occluder(spec):
    kind = spec["kind"]
    if kind == "brim":
        brim = detail.BRIM
        return (f"a hat's brim (a disk of radius {brim['radius']} m, its centre {brim['offset']} m right, back and "
                f"up of the head's centre, tilted {brim['tilt'][0]}° right side down, in the head's frame: it turns "
                f"with the head)")
    at = f"aimed at the face's point ({spec['at'][0]}, {spec['at'][1]}) m right and up of the head's centre"
    if kind == "leaves":
        p = spec["params"]
        return (f"a foliage gobo ({p['count']} seeded leaf-shaped ellipses, {p['length'][0]}-{p['length'][1]} m "
                f"half-length, over {p['spread']} m, seed {p['seed']}) {spec['distance']} m toward the key, {at}")
    what = {"hand": "a hand (a palm box, five finger cylinders)",
            "fingers": f"a hand with its fingers spread ({detail.FINGERS['spread'][0]:g}° to "
                       f"{detail.FINGERS['spread'][-1]:g}°)",
            "blinds": f"venetian blinds ({detail.BLINDS['width']} m slats {detail.BLINDS['pitch']} m apart, tilted "
                      f"{detail.BLINDS['tilt']:g}°)"}[kind]
    return f"{what} {spec['distance']} m toward the key, turned {spec['turn']:g}° in its plane, {at}"


def wrapped(text, first="", rest=""):
    return textwrap.fill(text, 117, initial_indent=first, subsequent_indent=rest, break_on_hyphens=False)


def set_coverage_text(results):
    beard_shown, beard_share, never, closest = coverage(results, "beard")
    freckles_shown, freckles_share, _, _ = coverage(results, "freckles")
    text = (f"beard: {beard_share:.1%} of the {beard_shown} beard texels the set's photos show are shown lit without a "
            f"cast shadow in at least one photo")
    if never:
        text += f" (the {never} others: no photo shows them closer than {closest:.0f}° to the camera's direction)"
    return text + f"; freckle area: {freckles_share:.1%} of {freckles_shown}"


def write_readme(out, split, samples, tones, surveys, rows):
    present = [name for name in SETS[split] if any(r[1] == name for r in rows)]
    sets_text = []
    for name in present:
        sets_text.append(wrapped(f"`{name}` ({len(SETS[split][name])} photos; {set_coverage_text(surveys[name])}):",
                                 "- ", "  "))
        for n, settings in enumerate(SETS[split][name], 1):
            text = f"yaw {settings['yaw']:+d}°, light `{settings['light']}`: key {describe_light(settings['key'])}"
            if settings["fill"] is not None:
                text += f"; fill {describe_light(settings['fill'])}"
            if settings["occluder"] is not None:
                text += f"; {describe_occluder(settings['occluder'])}"
            text += f"; sky {settings['world']} x {settings['world_strength']}."
            over = shadow_over(surveys[name][n - 1])
            text += f" Cast shadow over: {', '.join(over) if over else 'none'}."
            sets_text.append(wrapped(text, f"  {n}. ", "     "))
    title = {"seen": "the seen split (settings may be tuned on it)",
             "heldout": "the held-out split (no setting is tuned on it)"}[split]
    tone_list = ", ".join(f"`{t}`" for t in tones)
    only = "" if present == list(SETS[split]) else f" --only {','.join(present)}"
    command = f"-- OUT --samples {samples} --split {split} --tones {','.join(tones)}{only}"
    (out / "README.md").write_text(f"""# {out.name}: one person in several photos, {title}

A truth set for fits of several photos of one person (issue 59): one albedo (a person) seen in a set of photos, each
with its own head turn (yaw) and its own lights and cast shadows. Every set is rendered for every tone ({tone_list};
a tone is another person). Generated by `benchmarks/blender/person_scenes.py` in the deface repository:

    blender -b -P benchmarks/blender/person_scenes.py {command}

Renders never go into git.

How it was made, as `benchmarks/blender/detail_scenes.py` (whose functions it imports):
1. Albedos (`albedo/<tone>.png`, the truth, 512², sRGB): detail_scenes' (for ita30 and ita-10 detail-synth's maps:
   a painted moustache and goatee, about 140 freckles, five moles, a birthmark). `masks/` and `mesh.obj` are
   detail-synth's (the same UV layout and geometry).
2. Scene (Blender 3.4, Cycles, {samples} samples, seed 0, no denoiser, Standard view transform, so the PNG holds plain
   sRGB): `mesh.obj` (cm) with a Principled BSDF (base colour = the albedo, specular 0.35, roughness 0.45, no
   subsurface), a grey wall ({detail.WALL['reflectance']:.0%}) {detail.WALL['distance']} m behind the head's centre, an
   85 mm lens (36 mm sensor) 1.1 m in front of the head's centre, 512x512. Key strength 1 is {NOMINAL_IRRADIANCE:g}
   W/m² at the face. Occluders cast shadows and are unseen by the camera.
3. The head turns: yaw is a right-handed rotation of the head about the world's vertical axis through the head's
   centre (the mesh's bounding-box centre); POSITIVE YAW TURNS THE HEAD TO THE SUBJECT'S LEFT, the nose toward the
   camera's right. Lights are placed in the camera's frame ((azimuth right of the camera, elevation) in degrees; a
   negative elevation is below the eyes' height) and do not turn with the head. Occluders follow the head: the point
   a shadow is aimed at is a point of the face (right and up of the head's centre in the head's own frame, on its
   front surface) carried by the turn, the occluder placed between it and the key; a hat's brim turns with the head.
   A hand's turn is in its own plane from fingers-up (155°: fingers down).

Sets (`images/<tone>_<set>_<n>.png`, n the photo's place in the set):
{chr(10).join(sets_text)}

Which texels a photo shows, lights and shades is computed from the geometry, not assumed: every texel of the beard
mask, the freckle area, the birthmark, the forehead box and the eyes (the skin within {EYE_RIM * 100:g} cm of an eye
hole) is put on the posed mesh (its UV triangle). SHOWN: facing the camera within {SHOWN_ANGLE:g}° (the albedo
benchmark's limit) and not hidden by the head. LIT without a cast shadow: facing the key's centre (cosine >=
{LIT_COSINE}), the head not hiding the key's centre (no shadow of the nose, chin, ...) and the occluder hiding none of
{KEY_GRID}x{KEY_GRID} points over the key (its square, or a sun's disk; the occluder's penumbra is shadow). In the
OCCLUDER'S SHADOW: the occluder hides half of those points or more. Rays start {OFFSET * 1000:g} mm off the surface.

`MANIFEST.tsv`: file, tone, light (the photo's light), kelvin and strength (the key's), shadow (1: an occluder casts a
shadow on the face), set, yaw (degrees), shadow_over (the features with {SHADOW_SHARE:.0%} or more of their shown texels
in the occluder's shadow, of: beard, freckles (the freckle area), birthmark, forehead (the forehead box), eyes; empty:
none). `shadows.tsv` (per photo; the same for every tone): for each feature, its shown texels and the shares of them
lit, in the occluder's shadow and in the head's own shadow (the key's centre hidden by the head or behind the
surface).

`cameras.json`: per file, `camera_matrix_world` (4x4, rows; Blender's camera looks down its local -z with +y up),
`head_matrix_world` (the imported head: its mesh in metres, z up, -y toward the camera), `mesh_obj_to_world`
(`mesh.obj`'s vertices in cm, as written, to world metres: the head's matrix times the import's axes), `lens_mm`,
`sensor_width_mm` (the sensor spans the image's width), `image_size`, `focal_px` (lens / sensor width x width) and
`yaw_deg`. A world point p is at pixel x = W/2 + f q.x / -q.z, y = H/2 - f q.y / -q.z (from the top-left corner of
the image, pixel centres at +0.5), q = the camera matrix's inverse times p.

`exposure.tsv`: the sRGB means (9x9 pixels) of detail_scenes' skin patches (left and right cheeks, forehead) on the
turned head (`hidden` where the head hides the patch; a patch may lie in a cast shadow), and the pixels with a
channel at 255. `contact.png`: a row per set and tone (the sets in the order above, the tones within a set): the
albedo, then the set's photos in order. `coverage.png`: per set (left to right) the UV map's beard and freckle area
(darker): green where a photo shows the texel lit, red where photos show it but none lit, grey where none shows it.

What it can tell: whether a fit of several photos of one person recovers one clean albedo when each photo shows the
face from another side under other lights, with cast shadows over the beard, the freckles or the forehead in some
photos and not in others. What it cannot: real hair's geometry, real skin's subsurface scattering, a camera's tone
curve, expressions, or one person under different cameras (one lens and distance throughout).
""")


def main():
    out, samples, split, sets, tones, check = arguments()
    started = time.time()
    detail.write_truth(out, tones)
    check_matrices(out, tones[0])
    texels, surveys, records = geometry(out, split, tones[0])
    print(f"person_scenes.py: geometry in {time.time() - started:.0f} s", flush=True)
    for name in SETS[split]:
        print(f"{name}: beard {coverage(surveys[name], 'beard')}, freckles {coverage(surveys[name], 'freckles')}",
              flush=True)
    write_shadows(out, split, surveys)
    write_coverage(out, split, texels, surveys)
    if not check:
        for tone, _, _, file, settings in photos(split, sets, tones):
            begun = time.time()
            scene = build(out, tone, settings, samples)[0]
            scene.render.filepath = str(out / "images" / file)
            bpy.ops.render.render(write_still=True)
            print(f"person_scenes.py: {file} in {time.time() - begun:.0f} s", flush=True)
    rows = rendered(out, split, tones)
    write_manifest(out, rows, surveys)
    write_cameras(out, rows, records)
    write_exposure(out, rows, patch_pixels(out, split, tones[0]))
    write_contact(out, split, tones)
    write_readme(out, split, samples, tones, surveys, rows)
    print(f"person_scenes.py: done in {time.time() - started:.0f} s", flush=True)


main()
