"""Blender scenes of known albedo with OCCLUDERS in front of the face (issue 60: glasses, hair and hands must stay
out of the albedo): detail-synth's face, albedos and features (a beard, freckles, moles, a birthmark) behind
glasses, hair strands or fingers, modelled as geometry the camera sees, with the truth of what each occluder hides
written in UV. Run by Blender, not by deface's Python:

    blender -b -P benchmarks/blender/occluder_scenes.py -- OUT [--samples 64] [--tones T[,T]] [--only SCENE[,SCENE]]

Scenes: an occluder (``glasses``: a thin dark frame with clear glass lenses; ``tinted``: the same frame with tinted,
sunglass-like lenses; ``strand``: dark-brown hair strands across the forehead and one cheek; ``fingers``: three
fingers resting on one cheek) under a light (``even``: detail-synth's large soft light at the camera; ``key``: a
key light from the right that makes the occluders cast shadows): ``glasses_even``, ``glasses_key``, ...,
``fingers_key``. Tones: detail-synth's two (ita30, ita-10) unless ``--tones`` names others of detail_scenes.py.

Writes, beside what ``deface bench albedo OUT`` reads (``OUT/albedo/<tone>.png``, ``OUT/masks/``, ``OUT/mesh.obj``
as detail_scenes.py writes them, ``OUT/images/<tone>_<scene>.png`` and ``OUT/MANIFEST.tsv``), the truth of the
occluders in UV (512², texel centres, row 0 at v = 1: the layout of the masks):

- ``OUT/visible/<tone>_<scene>.png``: texels whose surface point faces the camera and is not hidden by the face
  itself (the occluders ignored);
- ``OUT/occluded/<tone>_<scene>.png``: visible texels hidden by the occluder (the segment from the texel's surface
  point to the camera crosses the occluder; the lenses count);
- ``OUT/occluded/<tone>_<scene>_lens.png`` (glasses and tinted only): the texels of the former seen through a lens
  and not behind the frame;
- ``OUT/occluded/<tone>_<scene>_shadow.png`` (key light only): texels in the occluder's cast shadow from the key
  light (the segment to the light's centre crosses the occluder's opaque parts, or a tinted lens; the texel faces
  the light and the face does not shadow it itself); whether the camera sees them is the visible and occluded
  masks' business;
- ``OUT/photo_uv/<tone>_<scene>.png``: the render read at each visible texel (the pixel its surface point projects
  to, nearest; black elsewhere): the occluder's look where it hides the face, the skin's elsewhere;
- ``OUT/occluded/texels.tsv``: the masks' texel counts; ``OUT/contact.png`` (a row per tone: its albedo, then its
  renders) and ``OUT/occluded_contact.png`` (each scene's masks over the albedo); ``OUT/README.md``.

The scene copies detail_scenes.py's (it is imported as a module, see :func:`_detail_scenes`): Cycles, detail-synth's
``mesh.obj`` (cm, the project's UV layout) with the Principled BSDF of scene_common.face, detail_scenes' grey wall,
an 85 mm lens at 1.1 m, 512 x 512, the Standard view transform, no denoiser, seed 0. The caustics are off (the
lenses' light reaches the face by their transparency to every ray but the camera's: no fireflies). Pure Python (Debian's
Blender has no numpy). About 30 s a render at 64 samples on two cores.
"""

import ast
import math
import re
import sys
import textwrap
import types
from pathlib import Path

import bmesh
import bpy
from bpy_extras.object_utils import world_to_camera_view
from mathutils import Matrix, Vector
from mathutils.bvhtree import BVHTree

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))  # Blender runs this file directly: find scene_common and detail_scenes
import scene_common  # noqa: E402
from scene_common import NOMINAL_IRRADIANCE, camera, environment, light  # noqa: E402


def _detail_scenes():
    """detail_scenes.py as a module, without its last statement (``main()``, which renders its own scenes when the
    file is run by Blender): its truth (albedos, masks, mesh), PNG reading and writing, and scene pieces are used
    as they are, not copied."""
    path = HERE / "detail_scenes.py"
    tree = ast.parse(path.read_text(), str(path))
    tree.body = [node for node in tree.body
                 if not (isinstance(node, ast.Expr) and isinstance(node.value, ast.Call)
                         and getattr(node.value.func, "id", None) == "main")]
    module = types.ModuleType("detail_scenes")
    module.__file__ = str(path)
    sys.modules["detail_scenes"] = module
    exec(compile(tree, str(path), "exec"), module.__dict__)  # noqa: S102 - the repository's own file
    return module


detail = _detail_scenes()

DEFAULT_TONES = ("ita30", "ita-10")
"""detail-synth's two tones; ``--tones`` may name any of detail_scenes.TONES."""
LIGHTS = {
    "even": dict(kind="area", angle=(0, 8), distance=1.2, size=1.2, kelvin=4800, strength=0.9),
    "key": dict(kind="area", angle=(40, 25), distance=1.5, size=0.25, kelvin=4800, strength=1.0),
}
"""As scene_common.light's arguments: (azimuth right of the camera, elevation) degrees, distance m, side m, kelvin,
strength x the nominal irradiance. ``even``: detail-synth's (a large soft light at the camera, just above it);
``key``: upper right in front of the face, as detail-synth's key, small enough that the occluders' shadows show."""
SHADOWS = ("key",)
"""The lights whose occluder shadows are written (``_shadow.png``) and counted as shadows (MANIFEST's shadow): the
even light's are faint contact shadows (a 1.2 m light at 1.2 m: a thin frame or strand blocks a tiny part of it)."""
WORLD = dict(world=(1.0, 1.0, 1.0), world_strength=0.1)
OCCLUDERS = ("glasses", "tinted", "strand", "fingers")
SCENES = {f"{occluder}_{name}": (occluder, name) for occluder in OCCLUDERS for name in LIGHTS}
SIZE = 512
"""The truth masks' side (the albedo's)."""
EPSILON = 1e-4
"""m: a ray leaves a surface point this far along its direction (not to hit its own triangle)."""

GLASSES = dict(width=0.050, height=0.036, roundness=3.0, bridge=0.016, rise=0.001, clearance=0.004, wrap=6.0,
               tilt=8.0, thickness=0.002, rim=0.0015, temple=0.0012, side=0.088, back=0.012, ear_drop=0.03)
"""The glasses, in m and degrees: each lens a superellipse (|x/a|^n + |z/b|^n = 1, n = ``roundness``) ``width`` x
``height``, the lenses ``bridge`` apart, their centres ``rise`` above the eye holes' centres; the frame as close
to the face as leaves ``clearance`` between the lenses' back (or the rims) and the skin; each lens turned ``wrap``
(outer edge back) and tilted ``tilt`` (lower edge toward the face), ``thickness`` thick (glass); the rims, the
bridge and the endpieces are tubes of radius ``rim`` around the lenses' outline; the temples tubes of radius
``temple`` from the endpieces back to ``side`` m from the middle, ``back`` m behind the head's centre (over where
the ears are), then ``ear_drop`` down behind them. Every tube point is kept ``clearance`` from the skin."""
LENSES = {"glasses": (1.0, 1.0, 1.0), "tinted": (0.53, 0.48, 0.42)}
"""Each lens surface's transmitted colour (Refraction BSDF colour, and the transparency other rays see): clear, or a
grey-brown sunglass tint (x itself through both surfaces: about 25 % of the light)."""
FRAME_COLOUR = (0.015, 0.014, 0.013)
HAIR_COLOUR = (0.032, 0.019, 0.011)
"""Linear RGB: the frame's black acetate; dark-brown hair (sRGB about (50, 38, 27))."""
STRANDS = (
    # the points (right, up of the eye holes' midpoint, m) the strand runs through; its radius m
    (((-0.012, 0.080), (-0.028, 0.066), (-0.044, 0.052), (-0.050, 0.036), (-0.058, 0.020)), 0.0009),
    (((0.002, 0.082), (-0.006, 0.070), (0.000, 0.058), (0.006, 0.047)), 0.0008),
    (((0.034, 0.080), (0.044, 0.066), (0.049, 0.050), (0.046, 0.034), (0.054, 0.018)), 0.0008),
    (((-0.050, 0.066), (-0.030, 0.062), (-0.010, 0.060), (0.008, 0.063), (0.030, 0.062), (0.050, 0.058)), 0.0007),
    (((0.058, 0.026), (0.054, 0.004), (0.056, -0.018), (0.050, -0.040), (0.053, -0.062)), 0.0009),
    (((0.068, 0.030), (0.064, 0.002), (0.066, -0.022), (0.060, -0.046), (0.062, -0.068)), 0.0007),
)
HAIR_GAP = 0.0015
"""m between a strand and the skin."""
FINGERS = dict(bases=((0.040, -0.080), (0.056, -0.077), (0.071, -0.072)), length=(0.064, 0.070, 0.064),
               radius=(0.0080, 0.0085, 0.0078), lean=4.0, gap=0.001)
"""Three fingers on the face's left cheek (the image's right, toward the key light): capsules of ``radius`` m
from ``bases`` (right, up of the eyes' midpoint, m) up ``length`` m, leaning ``lean`` degrees outward, following
the cheek ``gap`` m off the skin; skin-coloured (the tone's forehead box, linear mean, as Principled base colour)."""


def arguments():
    args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    out = Path(args[0])
    options = {"--samples": "64", "--only": ",".join(SCENES), "--tones": ",".join(DEFAULT_TONES)}
    for flag, value in zip(args[1::2], args[2::2], strict=False):
        if flag not in options:
            raise SystemExit(f"occluder_scenes.py: unknown option {flag!r}")
        options[flag] = value
    scenes, tones = options["--only"].split(","), options["--tones"].split(",")
    for name in scenes:
        if name not in SCENES:
            raise SystemExit(f"occluder_scenes.py: unknown scene {name!r} (one of {', '.join(SCENES)})")
    for tone in tones:
        if tone not in detail.TONES:
            raise SystemExit(f"occluder_scenes.py: unknown tone {tone!r} (one of {', '.join(detail.TONES)})")
    return out, int(options["--samples"]), scenes, tones


# --- the face's geometry ---

def eye_centres(obj):
    """The centres (world) of the mesh's two eye holes, left then right: the two boundary loops (besides the
    outline, the largest) highest up."""
    bm = bmesh.new()
    bm.from_mesh(obj.data)
    neighbours = {}
    for edge in bm.edges:
        if edge.is_boundary:
            a, b = (v.index for v in edge.verts)
            neighbours.setdefault(a, []).append(b)
            neighbours.setdefault(b, []).append(a)
    bm.free()
    loops, seen = [], set()
    for start in neighbours:
        if start in seen:
            continue
        loop, stack = [], [start]
        while stack:
            v = stack.pop()
            if v not in seen:
                seen.add(v)
                loop.append(v)
                stack.extend(neighbours[v])
        loops.append(loop)
    loops.sort(key=len, reverse=True)
    world = obj.matrix_world
    centres = [sum((world @ obj.data.vertices[i].co for i in loop), Vector()) / len(loop) for loop in loops[1:]]
    eyes = sorted(centres, key=lambda c: -c.z)[:2]
    return sorted(eyes, key=lambda c: c.x)


class Surface:
    """The face as a BVH (world coordinates) for ray casts and nearest points."""

    def __init__(self, obj):
        world = obj.matrix_world
        self.tree = BVHTree.FromPolygons([world @ v.co for v in obj.data.vertices],
                                         [tuple(p.vertices) for p in obj.data.polygons])

    def front(self, x, z):
        """(point, normal) of the face seen from the front at (x, z), or None."""
        hit, normal, _, _ = self.tree.ray_cast(Vector((x, -1.0, z)), Vector((0.0, 1.0, 0.0)))
        return None if hit is None else (hit, normal.normalized())

    def clear(self, point, distance):
        """``point`` moved out along the nearest skin's normal until it is ``distance`` from the skin."""
        nearest, normal, _, gap = self.tree.find_nearest(point)
        if nearest is None:
            return point
        outside = (point - nearest).dot(normal) >= 0
        if outside and gap >= distance:
            return point
        outward = (point - nearest) / gap if outside and gap > 1e-9 else normal.normalized()
        return nearest + distance * outward


# --- meshes ---

PARTS = []
"""(role, vertices, faces) of every occluder part in the scene (world m): role "frame", "lens", "hair", "finger"."""


def mesh_object(name, role, vertices, faces, material, smooth=True):
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([tuple(v) for v in vertices], [], faces)
    for polygon in mesh.polygons:
        polygon.use_smooth = smooth
    mesh.materials.append(material)
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    PARTS.append((role, [Vector(v) for v in vertices], faces))
    return obj


def resampled(points, count):
    """``count`` points evenly spaced along the polyline ``points`` (open)."""
    lengths = [0.0]
    for a, b in zip(points, points[1:], strict=False):
        lengths.append(lengths[-1] + (b - a).length)
    out, k = [], 0
    for i in range(count):
        s = lengths[-1] * i / (count - 1)
        while k < len(points) - 2 and lengths[k + 1] < s:
            k += 1
        span = max(lengths[k + 1] - lengths[k], 1e-12)
        out.append(points[k].lerp(points[k + 1], min(max((s - lengths[k]) / span, 0.0), 1.0)))
    return out


def smoothed(points, passes=3, closed=False):
    for _ in range(passes):
        n = len(points)
        if closed:
            points = [(points[i - 1] + 2 * points[i] + points[(i + 1) % n]) / 4 for i in range(n)]
        else:
            points = [points[0]] + [(points[i - 1] + 2 * points[i] + points[i + 1]) / 4
                                    for i in range(1, n - 1)] + [points[-1]]
    return points


def catmull_rom(points, steps=12):
    """A Catmull-Rom curve through ``points`` (2-tuples or Vectors), ``steps`` points per span."""
    p = [Vector(points[0]) * 2 - Vector(points[1])] + [Vector(q) for q in points] + \
        [Vector(points[-1]) * 2 - Vector(points[-2])]
    out = []
    for i in range(1, len(p) - 2):
        for k in range(steps):
            t = k / steps
            out.append(0.5 * (2 * p[i] + (p[i + 1] - p[i - 1]) * t + (2 * p[i - 1] - 5 * p[i] + 4 * p[i + 1]
                                                                        - p[i + 2]) * t * t
                              + (3 * p[i] - p[i - 1] - 3 * p[i + 1] + p[i + 2]) * t ** 3))
    out.append(p[-2].copy())
    return out


def tube(path, radii, sides=12, closed=False):
    """(vertices, faces) of a tube of radius ``radii[i]`` around ``path[i]`` (parallel-transported rings); an open
    tube's end point of radius 0 is a pole (a capsule's or a tapered strand's tip)."""
    n = len(path)
    tangents = []
    for i in range(n):
        if closed:
            a, b = path[i - 1], path[(i + 1) % n]
        else:
            a, b = path[max(i - 1, 0)], path[min(i + 1, n - 1)]
        tangents.append((b - a).normalized())
    helper = Vector((0.0, 0.0, 1.0)) if abs(tangents[0].z) < 0.9 else Vector((1.0, 0.0, 0.0))
    normal = tangents[0].cross(helper).normalized()
    vertices, rings = [], []
    for i in range(n):
        normal = (normal - tangents[i] * normal.dot(tangents[i])).normalized()
        binormal = tangents[i].cross(normal)
        if radii[i] <= 1e-7 and not closed:
            rings.append([len(vertices)])
            vertices.append(path[i].copy())
            continue
        ring = []
        for k in range(sides):
            angle = 2 * math.pi * k / sides
            ring.append(len(vertices))
            vertices.append(path[i] + radii[i] * (math.cos(angle) * normal + math.sin(angle) * binormal))
        rings.append(ring)
    faces = []
    pairs = [(i, (i + 1) % n) for i in range(n)] if closed else [(i, i + 1) for i in range(n - 1)]
    for i, j in pairs:
        a, b = rings[i], rings[j]
        if len(a) == 1 and len(b) == 1:
            continue
        if len(a) == 1:
            faces += [(a[0], b[(k + 1) % sides], b[k]) for k in range(sides)]
        elif len(b) == 1:
            faces += [(a[k], a[(k + 1) % sides], b[0]) for k in range(sides)]
        else:
            faces += [(a[k], a[(k + 1) % sides], b[(k + 1) % sides], b[k]) for k in range(sides)]
    if not closed:  # flat caps where an end has a radius
        for ring, flip in ((rings[0], True), (rings[-1], False)):
            if len(ring) > 1:
                faces.append(tuple(reversed(ring)) if flip else tuple(ring))
    return vertices, faces


def capsule_profile(length, radius, taper=0.0, cap_steps=6, body=40):
    """Arc lengths and radii along a capsule of ``length`` (hemispherical ends of ``radius``), its radius shrinking
    linearly to (1 - ``taper``) x at the far end."""
    cap = min(radius, length / 2)
    s = [cap * (1 - math.cos(0.5 * math.pi * k / cap_steps)) for k in range(cap_steps)]
    s += [cap + (length - 2 * cap) * k / body for k in range(body + 1)]
    s += [length - cap * (1 - math.cos(0.5 * math.pi * k / cap_steps)) for k in range(cap_steps - 1, -1, -1)]
    radii = []
    for value in s:
        d = max(cap - value, value - (length - cap), 0.0)
        radii.append(math.sqrt(max(cap * cap - d * d, 0.0)) * (1 - taper * value / length))
    return s, radii


def along(points, s_values):
    """Points at arc lengths ``s_values`` along the polyline ``points``."""
    lengths = [0.0]
    for a, b in zip(points, points[1:], strict=False):
        lengths.append(lengths[-1] + (b - a).length)
    out, k = [], 0
    for s in s_values:
        while k < len(points) - 2 and lengths[k + 1] < s:
            k += 1
        span = max(lengths[k + 1] - lengths[k], 1e-12)
        out.append(points[k].lerp(points[k + 1], min(max((s - lengths[k]) / span, 0.0), 1.0)))
    return out, lengths[-1]


def on_skin(surface, points_2d, lift):
    """The polyline over the face through (x, z) points, ``lift`` m off the skin along its normal (points the front
    ray misses are dropped), kept ``lift`` from the skin everywhere, smoothed."""
    path = []
    for x, z in points_2d:
        hit = surface.front(x, z)
        if hit is not None:
            path.append(hit[0] + lift * hit[1])
    path = smoothed(path, 4)
    return [surface.clear(p, lift) for p in path]


# --- materials ---

def principled(name, colour, specular=0.5, roughness=0.4):
    material = bpy.data.materials.new(name)
    material.use_nodes = True
    bsdf = material.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*colour, 1.0)
    bsdf.inputs["Specular"].default_value = specular
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["Subsurface"].default_value = 0.0
    return material


def lens_material(name, colour):
    """A glass lens with a perfect anti-reflective coating: a Refraction BSDF (IOR 1.5, sharp, tinted ``colour``
    per surface) to camera rays and to the rays it refracts; a transparent surface of the same colour to every
    other ray (shadow rays, and the skin's diffuse and glossy bounces). A thin lens: it casts its tint as its
    shadow, not a caustic, and the face's light through it is counted once (a refracting surface to the skin's
    bounces as well would add the light seen through the lens to the light sampled through its transparency).
    Without reflections: a Glass BSDF mirrors detail-synth's 1.2 m even light over the whole lens (uncoated glass:
    a white glare; a quarter of it: still a speckle at 64 samples, as each sample picks reflection or refraction)."""
    material = bpy.data.materials.new(name)
    material.use_nodes = True
    tree = material.node_tree
    tree.nodes.remove(tree.nodes["Principled BSDF"])
    refraction = tree.nodes.new("ShaderNodeBsdfRefraction")
    refraction.inputs["Color"].default_value = (*colour, 1.0)
    refraction.inputs["Roughness"].default_value = 0.0
    refraction.inputs["IOR"].default_value = 1.5
    clear = tree.nodes.new("ShaderNodeBsdfTransparent")
    clear.inputs["Color"].default_value = (*colour, 1.0)
    path = tree.nodes.new("ShaderNodeLightPath")
    either = tree.nodes.new("ShaderNodeMath")
    either.operation = "MAXIMUM"
    tree.links.new(path.outputs["Is Camera Ray"], either.inputs[0])
    tree.links.new(path.outputs["Is Transmission Ray"], either.inputs[1])
    mix = tree.nodes.new("ShaderNodeMixShader")
    tree.links.new(either.outputs["Value"], mix.inputs["Fac"])
    tree.links.new(clear.outputs["BSDF"], mix.inputs[1])
    tree.links.new(refraction.outputs["BSDF"], mix.inputs[2])
    tree.links.new(mix.outputs["Shader"], tree.nodes["Material Output"].inputs["Surface"])
    return material


# --- the occluders ---

def outline(g, count=72):
    """The lens's outline in its own plane (x right, z up), counter-clockwise from its right end."""
    a, b, n = g["width"] / 2, g["height"] / 2, g["roundness"]
    points = []
    for k in range(count):
        t = 2 * math.pi * k / count
        c, s = math.cos(t), math.sin(t)
        points.append((a * math.copysign(abs(c) ** (2 / n), c), b * math.copysign(abs(s) ** (2 / n), s)))
    return points


def lens_frames(eyes, g, depth):
    """Each lens's placement (left, right): its centre in front of its eye at ``depth`` (world y of the lens
    centres), turned by the wrap and the tilt."""
    middle = (eyes[0] + eyes[1]) / 2
    offset = (g["width"] + g["bridge"]) / 2
    frames = []
    for side in (-1, 1):
        centre = Vector((middle.x + side * offset, depth, middle.z + g["rise"]))
        frames.append(Matrix.Translation(centre) @ Matrix.Rotation(math.radians(side * g["wrap"]), 4, "Z")
                      @ Matrix.Rotation(math.radians(g["tilt"]), 4, "X"))
    return frames


def glasses(surface, eyes, lens_colour, g=GLASSES):
    """The frame (rims, bridge, endpieces, temples) and two glass lenses in front of the eyes."""
    shape = outline(g)
    middle = (eyes[0] + eyes[1]) / 2
    # the lenses as close as the clearance allows: every point of a lens's back (and of its rim) in front of the skin
    start = middle.y
    worst = -1.0
    for frame in lens_frames(eyes, g, start):
        samples = [(x * f, z * f) for x, z in shape for f in (0.25, 0.5, 0.75, 1.0)]
        for x, z in samples:
            back = frame @ Vector((x, g["thickness"] / 2 + g["rim"], z))
            hit = surface.front(back.x, back.z)
            if hit is not None:
                worst = max(worst, back.y + g["clearance"] - hit[0].y)
    depth = start - worst
    frames = lens_frames(eyes, g, depth)
    rim = principled("frame", FRAME_COLOUR, specular=0.5, roughness=0.25)
    glass = lens_material("lens", lens_colour)
    half = g["thickness"] / 2
    for side, frame in zip(("left", "right"), frames, strict=True):
        ring = [frame @ Vector((x, 0.0, z)) for x, z in shape]
        vertices, faces = tube(ring, [g["rim"]] * len(ring), sides=10, closed=True)
        mesh_object(f"rim_{side}", "frame", vertices, faces, rim)
        front = [frame @ Vector((x, -half, z)) for x, z in shape]
        back = [frame @ Vector((x, half, z)) for x, z in shape]
        n = len(shape)
        faces = [tuple(range(n)), tuple(range(2 * n - 1, n - 1, -1))]  # outward: the front faces the camera
        faces += [(k, n + k, n + (k + 1) % n, (k + 1) % n) for k in range(n)]
        mesh_object(f"lens_{side}", "lens", front + back, faces, glass, smooth=False)
    # the bridge: an arc over the nose between the lenses' inner edges, a little above their middle
    a, b, n = g["width"] / 2, g["height"] / 2, g["roundness"]
    t = 0.5
    inner = (a * math.cos(t) ** (2 / n), b * math.sin(t) ** (2 / n))
    left = frames[0] @ Vector((inner[0], 0.0, inner[1]))
    right = frames[1] @ Vector((-inner[0], 0.0, inner[1]))
    top = (left + right) / 2 + Vector((0.0, -0.002, 0.004))
    arc = [left * (1 - u) ** 2 + top * 2 * u * (1 - u) + right * u * u for u in (k / 24 for k in range(25))]
    arc = [surface.clear(p, g["clearance"] + g["rim"]) for p in arc]
    vertices, faces = tube(smoothed(arc, 2), [g["rim"]] * len(arc), sides=10)
    mesh_object("bridge", "frame", vertices, faces, rim)
    # endpieces and temples: from each lens's outer edge back along the side of the head, then down behind the ear
    for side, frame in zip((-1, 1), frames, strict=True):
        edge = frame @ Vector((side * a * math.cos(t) ** (2 / n), 0.0, b * math.sin(t) ** (2 / n)))
        hinge = edge + Vector((side * 0.006, 0.010, 0.0))
        ear = Vector((middle.x + side * g["side"], surface_centre_y + g["back"], middle.z))
        drop = ear + Vector((0.0, 0.012, -g["ear_drop"]))
        path = catmull_rom([tuple(edge), tuple(hinge), tuple(ear), tuple(drop)], steps=20)
        path = [surface.clear(p, g["clearance"] + g["temple"]) for p in path]
        path = resampled(smoothed(path, 3), 60)
        s, radii = capsule_profile(sum((q - p).length for p, q in zip(path, path[1:], strict=False)), g["temple"])
        points, _ = along(path, s)
        vertices, faces = tube(points, [max(r, 0.0) for r in radii], sides=8)
        mesh_object(f"temple_{side}", "frame", vertices, faces, rim)
    return depth


def strands(surface, eyes):
    middle = (eyes[0] + eyes[1]) / 2
    hair = principled("hair", HAIR_COLOUR, specular=0.5, roughness=0.35)
    for i, (points, radius) in enumerate(STRANDS):
        curve = catmull_rom([(middle.x + x, middle.z + z) for x, z in points], steps=16)
        path = on_skin(surface, [(p.x, p.y) for p in curve], HAIR_GAP + radius)
        path = resampled(path, 80)
        length = sum((q - p).length for p, q in zip(path, path[1:], strict=False))
        s, radii = capsule_profile(length, radius, taper=0.5, cap_steps=4, body=70)
        points3, _ = along(path, s)
        vertices, faces = tube(points3, radii, sides=8)
        mesh_object(f"strand{i}", "hair", vertices, faces, hair)


def fingers(surface, eyes, colour, f=FINGERS):
    middle = (eyes[0] + eyes[1]) / 2
    skin = principled("finger", colour, specular=0.35, roughness=0.45)
    lean = math.radians(f["lean"])
    for i, ((x, z), length, radius) in enumerate(zip(f["bases"], f["length"], f["radius"], strict=True)):
        start = Vector((middle.x + x, middle.z + z))
        end = start + length * Vector((math.sin(lean), math.cos(lean)))
        line = [start.lerp(end, k / 60) for k in range(61)]
        path = on_skin(surface, [(p.x, p.y) for p in line], f["gap"] + radius)
        path = resampled(path, 60)
        total = sum((q - p).length for p, q in zip(path, path[1:], strict=False))
        s, radii = capsule_profile(total, radius, cap_steps=8, body=50)
        points3, _ = along(path, s)
        vertices, faces = tube(points3, radii, sides=20)
        mesh_object(f"finger{i}", "finger", vertices, faces, skin)


surface_centre_y = 0.0
"""The head's centre's y (world m), set by :func:`build`: the temples run back to it."""


def forehead_colour(out, tone):
    """The tone's albedo's linear mean over the forehead box: the fingers' base colour."""
    width, _, mask = detail.read_rgb(out / "masks" / "forehead.png")
    albedo = detail.read_rgb(out / "albedo" / f"{tone}.png")[2]
    inside = [i for i in range(width * width) if mask[3 * i] > 127]
    return tuple(sum(detail.to_linear(albedo[3 * i + c]) for i in inside) / len(inside) for c in range(3))


def build(out, tone, name, samples):
    """The scene of ``name`` for ``tone``: returns (scene, face, centre, surface, key light)."""
    global surface_centre_y
    occluder, light_name = SCENES[name]
    PARTS.clear()
    scene = detail.reset(samples)
    scene.cycles.caustics_reflective = False
    scene.cycles.caustics_refractive = False
    obj, centre = scene_common.face(out / "albedo" / f"{tone}.png")
    surface_centre_y = centre.y
    camera(scene, centre)
    detail.wall(centre)
    key = light(scene, "key", centre, **LIGHTS[light_name])
    environment(scene, WORLD)
    surface = Surface(obj)
    eyes = eye_centres(obj)
    if occluder in LENSES:
        glasses(surface, eyes, LENSES[occluder])
    elif occluder == "strand":
        strands(surface, eyes)
    else:
        fingers(surface, eyes, forehead_colour(out, tone))
    bpy.context.view_layer.update()
    return scene, obj, centre, surface, key


# --- the truth in UV ---

def texels(obj):
    """Every texel centre the mesh covers in UV (SIZE², row 0 at v = 1, texel (x, y) at u = (x + 0.5) / SIZE,
    v = 1 - (y + 0.5) / SIZE, as deface.models.uvmap.rasterize_uv): {index: (surface point, triangle normal)}."""
    mesh = obj.data
    mesh.calc_loop_triangles()
    uv = mesh.uv_layers.active.data
    world = obj.matrix_world
    rotation = world.to_3x3()
    out = {}
    for triangle in mesh.loop_triangles:
        corners = [(uv[k].uv[0] * SIZE - 0.5, (1.0 - uv[k].uv[1]) * SIZE - 0.5) for k in triangle.loops]
        points = [world @ mesh.vertices[v].co for v in triangle.vertices]
        normal = (rotation @ triangle.normal).normalized()
        (ax, ay), (bx, by), (cx, cy) = corners
        det = (bx - ax) * (cy - ay) - (cx - ax) * (by - ay)
        if abs(det) < 1e-12:
            continue
        x0, x1 = max(math.ceil(min(ax, bx, cx) - 1e-9), 0), min(math.floor(max(ax, bx, cx) + 1e-9), SIZE - 1)
        y0, y1 = max(math.ceil(min(ay, by, cy) - 1e-9), 0), min(math.floor(max(ay, by, cy) + 1e-9), SIZE - 1)
        for y in range(y0, y1 + 1):
            for x in range(x0, x1 + 1):
                w1 = ((x - ax) * (cy - ay) - (cx - ax) * (y - ay)) / det
                w2 = ((bx - ax) * (y - ay) - (x - ax) * (by - ay)) / det
                w0 = 1.0 - w1 - w2
                if w0 >= -1e-9 and w1 >= -1e-9 and w2 >= -1e-9:
                    out[y * SIZE + x] = (w0 * points[0] + w1 * points[1] + w2 * points[2], normal)
    return out


def parts_tree(roles):
    vertices, faces = [], []
    for role, part_vertices, part_faces in PARTS:
        if role in roles:
            start = len(vertices)
            vertices += part_vertices
            faces += [tuple(start + i for i in face) for face in part_faces]
    return BVHTree.FromPolygons(vertices, faces) if faces else None


def crosses(tree, point, target):
    """Whether the segment from ``point`` (leaving it by EPSILON) to ``target`` hits ``tree``."""
    if tree is None:
        return False
    direction = target - point
    distance = direction.length
    direction /= distance
    return tree.ray_cast(point + EPSILON * direction, direction, distance - EPSILON)[0] is not None


def truth_masks(texel_points, surface, camera_at, light_at, occluder):
    """{mask: set of texel indices}: visible, occluded, lens (glasses), shadow (module doc; ``light_at`` None: no
    shadow mask)."""
    everything = parts_tree({"frame", "lens", "hair", "finger"})
    opaque = parts_tree({"frame", "hair", "finger"})
    lens = parts_tree({"lens"})
    casting = everything if occluder == "tinted" else opaque
    masks = {"visible": set(), "occluded": set(), "lens": set(), "shadow": set()}
    for index, (point, normal) in texel_points.items():
        if normal.dot(camera_at - point) > 0 and not crosses(surface.tree, point, camera_at):
            masks["visible"].add(index)
            if crosses(everything, point, camera_at):
                masks["occluded"].add(index)
                if not crosses(opaque, point, camera_at) and crosses(lens, point, camera_at):
                    masks["lens"].add(index)
        if light_at is not None and normal.dot(light_at - point) > 0 \
                and not crosses(surface.tree, point, light_at) and crosses(casting, point, light_at):
            masks["shadow"].add(index)
    return masks


def write_mask(path, indices):
    values = bytearray(3 * SIZE * SIZE)
    for i in indices:
        values[3 * i:3 * i + 3] = b"\xff\xff\xff"
    detail.write_png(path, SIZE, SIZE, values)


def photo_in_uv(scene, render_path, texel_points, visible):
    """The render read at each visible texel's projection (nearest pixel), 8-bit sRGB; black elsewhere."""
    width, height, pixels = detail.read_rgb(render_path)
    cam = scene.camera
    values = bytearray(3 * SIZE * SIZE)
    for index in visible:
        projected = world_to_camera_view(scene, cam, texel_points[index][0])
        x = min(max(int(projected.x * width), 0), width - 1)
        y = min(max(int((1.0 - projected.y) * height), 0), height - 1)
        k = 3 * (y * width + x)
        values[3 * index:3 * index + 3] = bytes(pixels[k:k + 3])
    return values


def render(out, tone, name, samples, truths):
    scene, obj, centre, surface, key = build(out, tone, name, samples)
    occluder, light_name = SCENES[name]
    if name not in truths:
        points = texels(obj)
        light_at = key.matrix_world.translation if light_name in SHADOWS else None
        truths[name] = (points, truth_masks(points, surface, scene.camera.matrix_world.translation, light_at,
                                            occluder))
    points, masks = truths[name]
    path = out / "images" / f"{tone}_{name}.png"
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    stem = f"{tone}_{name}"
    write_mask(out / "visible" / f"{stem}.png", masks["visible"])
    write_mask(out / "occluded" / f"{stem}.png", masks["occluded"])
    if light_name in SHADOWS:
        write_mask(out / "occluded" / f"{stem}_shadow.png", masks["shadow"])
    if occluder in LENSES:
        write_mask(out / "occluded" / f"{stem}_lens.png", masks["lens"])
    detail.write_png(out / "photo_uv" / f"{stem}.png", SIZE, SIZE, photo_in_uv(scene, path, points, masks["visible"]))


# --- the set's tables and sheets ---

def rendered(out):
    return [(tone, name) for tone in detail.TONES for name in SCENES
            if (out / "images" / f"{tone}_{name}.png").is_file()]


def read_mask(path):
    if not path.is_file():
        return set()
    values = detail.read_rgb(path)[2]
    return {i for i in range(SIZE * SIZE) if values[3 * i] > 127}


def shadow_seen(out, stem):
    """Texels the camera sees (visible, not occluded) in the occluder's shadow."""
    return (read_mask(out / "occluded" / f"{stem}_shadow.png") & read_mask(out / "visible" / f"{stem}.png")) \
        - read_mask(out / "occluded" / f"{stem}.png")


def write_tables(out):
    lines = ["file\ttone\tlight\tkelvin\tstrength\tshadow\toccluder"]
    counts = ["file\tvisible\toccluded\tlens\tshadow\tshadow_seen"]
    for tone, name in rendered(out):
        stem = f"{tone}_{name}"
        occluder, light_name = SCENES[name]
        lit = LIGHTS[light_name]
        seen = len(shadow_seen(out, stem))
        lines.append(f"{stem}.png\t{tone}\t{light_name}\t{lit['kelvin']}\t{lit['strength']}\t"
                     f"{int(light_name in SHADOWS)}\t{occluder}")
        sizes = [len(read_mask(out / folder / f"{stem}{suffix}.png"))
                 for folder, suffix in (("visible", ""), ("occluded", ""), ("occluded", "_lens"),
                                        ("occluded", "_shadow"))]
        counts.append(f"{stem}.png\t" + "\t".join(str(n) for n in sizes) + f"\t{seen}")
    (out / "MANIFEST.tsv").write_text("\n".join(lines) + "\n")
    (out / "occluded" / "texels.tsv").write_text("\n".join(counts) + "\n")
    print("\n".join(counts))


def write_contact(out, tile=192):
    """A row per tone: its albedo, then its renders (black: missing)."""
    scenes = [name for name in SCENES if any(name == n for _, n in rendered(out))]
    tones = [tone for tone in detail.TONES if any(tone == t for t, _ in rendered(out))]
    columns = ["albedo", *scenes]
    width, height = tile * len(columns), tile * len(tones)
    sheet = bytearray(3 * width * height)
    for row, tone in enumerate(tones):
        for column, name in enumerate(columns):
            path = out / "albedo" / f"{tone}.png" if name == "albedo" else out / "images" / f"{tone}_{name}.png"
            if path.is_file():
                paste(sheet, width, detail.read_rgb(path, tile)[2], tile, row, column)
    detail.write_png(out / "contact.png", width, height, sheet)


def paste(sheet, width, values, tile, row, column):
    for y in range(tile):
        start = 3 * ((row * tile + y) * width + column * tile)
        sheet[start:start + 3 * tile] = bytes(values[3 * tile * y:3 * tile * (y + 1)])


OVERLAY = {"occluded": (255, 30, 30), "lens": (255, 220, 0), "shadow": (40, 90, 255), "outline": (0, 230, 0)}
OUTLINED = ("forehead", "birthmark")
"""The masks outlined on the occluded sheet: the reference box of plain skin deface bench albedo matches the map's
level on, and the birthmark (the strands pass beside both)."""


def outline_texels(out, tile):
    """Tile texels (y * tile + x) on the edge of the masks of OUTLINED, sampled at ``tile``²."""
    step = SIZE // tile
    edge = set()
    for name in OUTLINED:
        values = detail.read_rgb(out / "masks" / f"{name}.png")[2]
        inside = {(x, y) for y in range(tile) for x in range(tile) if values[3 * ((y * step) * SIZE + x * step)] > 127}
        edge |= {y * tile + x for x, y in inside
                 if any((x + dx, y + dy) not in inside for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)))}
    return edge


def write_occluded_contact(out, tile=256):
    """A row per tone, a column per scene: the albedo (halved where the texel is not visible) with the occluded
    texels red (those seen through a lens yellow) and the seen texels in the occluder's shadow blue, half
    opaque, and the outlines of the forehead box and the birthmark green; at ``tile``² (the masks at 512² scaled by
    nearest texel)."""
    scenes = [name for name in SCENES if any(name == n for _, n in rendered(out))]
    tones = [tone for tone in detail.TONES if any(tone == t for t, _ in rendered(out))]
    width, height = tile * len(scenes), tile * len(tones)
    sheet = bytearray(3 * width * height)
    step = SIZE // tile
    edge = outline_texels(out, tile)
    for row, tone in enumerate(tones):
        albedo = detail.read_rgb(out / "albedo" / f"{tone}.png")[2]
        for column, name in enumerate(scenes):
            stem = f"{tone}_{name}"
            visible = read_mask(out / "visible" / f"{stem}.png")
            occluded = read_mask(out / "occluded" / f"{stem}.png")
            lens = read_mask(out / "occluded" / f"{stem}_lens.png")
            shadow = shadow_seen(out, stem)
            values = bytearray(3 * tile * tile)
            for y in range(tile):
                for x in range(tile):
                    i = (y * step) * SIZE + x * step
                    colour = albedo[3 * i:3 * i + 3]
                    if i not in visible:
                        colour = [c // 2 for c in colour]
                    paint = OVERLAY["lens"] if i in lens else OVERLAY["occluded"] if i in occluded else \
                        OVERLAY["shadow"] if i in shadow else None
                    if paint is not None:
                        colour = [(c + p) // 2 for c, p in zip(colour, paint, strict=True)]
                    if y * tile + x in edge:
                        colour = OVERLAY["outline"]
                    values[3 * (y * tile + x):3 * (y * tile + x) + 3] = bytes(colour)
            paste(sheet, width, values, tile, row, column)
    detail.write_png(out / "occluded_contact.png", width, height, sheet)


def write_readme(out, samples):
    present = [name for name in SCENES if any(name == n for _, n in rendered(out))]
    tones = [tone for tone in detail.TONES if any(tone == t for t, _ in rendered(out))]
    g, f = GLASSES, FINGERS
    only = "" if present == list(SCENES) else f" --only {','.join(present)}"
    tone_flag = "" if tones == list(DEFAULT_TONES) else f" --tones {','.join(tones)}"
    tone_lines = "\n".join(f"   - `{tone}`: " + ("detail-synth's map, copied" if detail.TONES[tone] is None else
                                                f"`../skin-tone-synth/albedo/{tone}.png` with the features of "
                                                f"detail-synth's `{detail.TONES[tone]}` map (as detail_scenes.py)")
                           for tone in tones)

    def lit(settings):
        return (f"a {settings['size']} m square area light at {settings['distance']} m from "
                f"({settings['angle'][0]}, {settings['angle'][1]}), {settings['kelvin']} K, strength "
                f"{settings['strength']}")

    def at(points):
        return ", ".join(f"({x:+.3f}, {z:+.3f})" for x, z in points)

    strand_lines = "\n".join(f"     - radius {radius * 1000:.1f} mm, through {at(points)}"
                             for points, radius in STRANDS)
    fingers_text = "; ".join(f"radius {r * 1000:.1f} mm from {at([b])} up {v * 100:.1f} cm"
                             for b, v, r in zip(f["bases"], f["length"], f["radius"], strict=True))
    title = f"# {out.name}: renders of known albedo behind occluders (glasses, hair, fingers)"
    (out / "README.md").write_text(reflowed(f"""{title}

The truth set of issue 60: glasses, hair and hands in front of the face must stay out of the albedo. The face,
albedos and features of `../detail-synth` (a moustache and goatee, freckles, moles, a birthmark) behind occluders
modelled as geometry the camera sees, with the truth of what each occluder hides, in UV. Generated by
`benchmarks/blender/occluder_scenes.py` in the deface repository
(`blender -b -P benchmarks/blender/occluder_scenes.py -- OUT --samples {samples}{tone_flag}{only}`);
renders never go into git.

How it was made:
1. Albedos (`albedo/<tone>.png`, the truth, 512², sRGB), `masks/` and `mesh.obj`: as
   `benchmarks/blender/detail_scenes.py` writes them:
{tone_lines}
2. Scene (Blender 3.4, Cycles, {samples} samples, seed 0, no denoiser, caustics off, Standard view transform, so
   the PNG holds plain sRGB): `mesh.obj` (cm) with a Principled BSDF (base colour = the albedo, specular 0.35,
   roughness 0.45, no subsurface), a grey wall ({detail.WALL['reflectance']:.0%}) {detail.WALL['distance']} m
   behind the head's centre, 85 mm lens at 1.1 m, 512x512, a white sky x {WORLD['world_strength']}. Strength 1
   is {NOMINAL_IRRADIANCE:g} W/m² at the face. Lights (azimuth right of the camera, elevation, in degrees):
   - `even`: {lit(LIGHTS['even'])}: as detail-synth's even light, little shading, the occluders' shadows
     faint and mostly behind them;
   - `key`: {lit(LIGHTS['key'])}: upper right in front, the occluders cast shadows to the image's left and
     down.
3. Occluders: the camera sees them and they cast shadows. Positions are (right, up) of the eye holes' midpoint,
   m; "right" is the image's right (the face's left).
   - `glasses`: a black acetate frame (Principled, linear {FRAME_COLOUR}, roughness 0.25): rims (tubes of
     radius {g['rim'] * 1000:.1f} mm) around two lenses {g['width'] * 100:.1f} x {g['height'] * 100:.1f} cm
     (superellipses of exponent {g['roundness']:g}) {g['bridge'] * 100:.1f} cm apart, centred
     {g['rise'] * 1000:.0f} mm above the eye holes, wrapped {g['wrap']:g}° (outer edges back) and tilted
     {g['tilt']:g}° (lower edges toward the face), {g['clearance'] * 1000:.0f} mm from the skin at the nearest;
     a bridge arched over the nose; endpieces and temples (tubes of radius {g['temple'] * 1000:.1f} mm) back
     along the sides of the head to {g['side'] * 100:.1f} cm from the middle, over where the ears would be, then
     down. Clear lenses {g['thickness'] * 1000:.0f} mm thick with a perfect anti-reflective coating: a
     Refraction BSDF (IOR 1.5, sharp) to camera rays and the rays they refract, transparent to every other ray
     (shadow rays, the skin's bounces): a thin lens, no reflection, no shadow, no caustic. (A Glass BSDF mirrors
     the even light over the whole lens: a white, grainy glare at 64 samples.)
   - `tinted`: the same frame; the lenses' refraction and transparency tinted {LENSES['tinted']} per surface
     (sunglasses: about {LENSES['tinted'][1] ** 2:.0%} through a lens; they cast a tinted shadow).
   - `strand`: {len(STRANDS)} dark-brown hair strands (Principled, linear {HAIR_COLOUR}, roughness 0.35):
     curved tubes {HAIR_GAP * 1000:.1f} mm off the skin, tapering to half their radius, four over the forehead
     (beside, not over, the forehead box that `deface bench albedo` matches levels on, and the birthmark) and two
     down the right cheek:
{strand_lines}
   - `fingers`: three fingers on the right cheek (the key's side), capsules leaning {f['lean']:g}° outward,
     following the cheek {f['gap'] * 1000:.0f} mm off the skin: {fingers_text}. Their colour is the tone's
     albedo's mean over the forehead box (Principled, specular 0.35, roughness 0.45): a hand of the same skin.
4. `images/<tone>_<occluder>_<light>.png`. The eyes are holes in the mesh (the face model has no eyeballs).

The truth in UV (512², texel centres, row 0 at v = 1: the layout of `masks/` and of deface's maps). Each texel the
mesh covers in UV has a surface point (barycentric in its triangle) and the triangle's normal; rays are segments
from that point (leaving it by {EPSILON * 1000:.1f} mm):
- `visible/<stem>.png`: the point faces the camera and the face itself does not hide it (occluders ignored): the
  texels a photo could show at all;
- `occluded/<stem>.png`: visible texels whose segment to the camera crosses the occluder (frame, lenses, hair or
  fingers): hidden by it, or seen only through a lens;
- `occluded/<stem>_lens.png` (glasses, tinted): the former's texels seen through a lens and not behind the frame
  (the frame alone is `occluded` minus `lens`);
- `occluded/<stem>_shadow.png` (the key light's scenes only): texels facing the key light, not shadowed by the
  face itself, whose segment to the light's centre crosses the occluder's opaque parts (and tinted lenses; clear
  lenses cast no shadow): the hard shadow of the light's centre (its penumbra reaches a little further); seen or
  not (combine with `visible` and `occluded`). The even light's shadows are faint contact shadows (a thin frame
  or strand blocks a tiny part of a 1.2 m light) and have no mask;
- `photo_uv/<stem>.png`: the render read at each visible texel (the nearest pixel to its point's projection),
  black elsewhere: the occluder's look at the texels it hides, the skin's elsewhere;
- `occluded/texels.tsv`: each render's counts of visible, occluded, lens and shadow texels, and of the shadow's
  texels the camera sees (visible, not occluded).

`MANIFEST.tsv`: file, tone, light (even or key), kelvin and strength (the light's), shadow (1: the key light, whose
occluder shadows show and have a mask), occluder. `contact.png`: a row per tone, its albedo then its renders.
`occluded_contact.png`: a row per tone, a column per scene: the albedo (dimmed where not visible), the occluded
texels red (yellow: through a lens), the seen texels in the occluder's shadow blue, the forehead box and the
birthmark outlined green.

What it can tell: whether a fit keeps the frame, the lenses' tint, the hair and the fingers (and their shadows)
out of the albedo (`benchmarks/occluder_truth.py` measures the map's darkness and colour error under the
occluder), and whether it still keeps the features. What it cannot: real hair (the strands are smooth tubes),
reflections in lenses (these reflect nothing), real skin's subsurface scattering, or a camera's tone curve.
"""))


def reflowed(text, width=115):
    """Markdown ``text`` with its paragraphs and list items refilled to ``width`` (an item's continuation lines
    indented under its text); headings and blank lines as they are."""
    items = []
    for line in text.splitlines():
        stripped = line.lstrip()
        bullet = re.match(r"(- |\d+\. )", stripped)
        if not stripped or stripped.startswith("#"):
            items.append([line, None])
        elif bullet or not items or items[-1][1] is None:
            indent = len(line) - len(stripped)
            items.append([stripped, (indent, len(bullet.group(1)) if bullet else 0)])
        else:
            items[-1][0] += " " + stripped
    lines = []
    for content, shape in items:
        if shape is None:
            lines.append(content)
            continue
        indent, hang = shape
        lines.append(textwrap.fill(content, width, initial_indent=" " * indent,
                                   subsequent_indent=" " * (indent + hang), break_on_hyphens=False))
    return "\n".join(lines) + "\n"


def main():
    out, samples, scenes, tones = arguments()
    for folder in ("images", "visible", "occluded", "photo_uv"):
        (out / folder).mkdir(parents=True, exist_ok=True)
    detail.write_truth(out, tones)
    truths = {}
    for tone in tones:
        for name in scenes:
            render(out, tone, name, samples, truths)
    write_tables(out)
    write_contact(out)
    write_occluded_contact(out)
    write_readme(out, samples)


if __name__ == "__main__":
    main()
