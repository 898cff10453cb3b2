"""What the Blender scene scripts share (tone_scenes.py, detail_scenes.py): the scene's reset, the face of
``../shared/data/detail-synth`` with its skin material, lights, camera and environment. Pure Blender Python (bpy,
mathutils; Debian's Blender has no numpy). Run by Blender through those scripts, which put this folder on
``sys.path``."""

import math
from pathlib import Path

import bpy
from mathutils import Vector

SHARED = Path(__file__).resolve().parents[3] / "shared" / "data"
MESH = SHARED / "detail-synth" / "mesh.obj"
NOMINAL_IRRADIANCE = 3.0
"""W/m^2 of a key light at the face at strength 1: the lit cheek of a light skin near sRGB 200 at exposure 1."""


def reset(samples, file_format, color_depth, denoise, seed=None):
    """An empty Cycles scene on the CPU, 512 x 512, the Standard view transform, writing RGB ``file_format`` at
    ``color_depth``; ``seed`` None leaves Cycles' default seed."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    if seed is not None:
        scene.cycles.seed = seed
    scene.cycles.use_denoising = denoise
    scene.render.resolution_x = scene.render.resolution_y = 512
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.render.image_settings.file_format = file_format
    scene.render.image_settings.color_depth = color_depth
    scene.render.image_settings.color_mode = "RGB"
    return scene


def face(albedo_path):
    """detail-synth's mesh (cm, scaled to m) with a Principled BSDF: base colour the albedo image at
    ``albedo_path``, specular 0.35, roughness 0.45, no subsurface (``albedo_path`` None: a uniform 80 % with no
    specular). Returns the object and its bounding box's centre."""
    bpy.ops.wm.obj_import(filepath=str(MESH), forward_axis="NEGATIVE_Z", up_axis="Y")
    obj = bpy.context.selected_objects[0]
    obj.scale = (0.01, 0.01, 0.01)
    bpy.ops.object.transform_apply(scale=True)
    bpy.ops.object.shade_smooth()
    material = bpy.data.materials.new("skin")
    material.use_nodes = True
    bsdf = material.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Subsurface"].default_value = 0.0
    if albedo_path is None:
        bsdf.inputs["Base Color"].default_value = (0.8, 0.8, 0.8, 1.0)
        bsdf.inputs["Specular"].default_value = 0.0
    else:
        texture = material.node_tree.nodes.new("ShaderNodeTexImage")
        texture.image = bpy.data.images.load(str(albedo_path))
        material.node_tree.links.new(texture.outputs["Color"], bsdf.inputs["Base Color"])
        bsdf.inputs["Specular"].default_value = 0.35
    bsdf.inputs["Roughness"].default_value = 0.45
    obj.data.materials.clear()
    obj.data.materials.append(material)
    corners = [obj.matrix_world @ Vector(c) for c in obj.bound_box]
    return obj, sum(corners, Vector()) / 8


def diffuse_material(name, colour, image=None):
    """A diffuse material of ``colour`` (RGB), or of the texture ``image`` (nearest texel) if given."""
    material = bpy.data.materials.new(name)
    material.use_nodes = True
    tree = material.node_tree
    tree.nodes.remove(tree.nodes["Principled BSDF"])
    diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
    if image is not None:
        texture = tree.nodes.new("ShaderNodeTexImage")
        texture.image = bpy.data.images.load(str(image))
        texture.interpolation = "Closest"
        tree.links.new(texture.outputs["Color"], diffuse.inputs["Color"])
    else:
        diffuse.inputs["Color"].default_value = (*colour, 1.0)
    tree.links.new(diffuse.outputs["BSDF"], tree.nodes["Material Output"].inputs["Surface"])
    return material


def blackbody_node(tree, kelvin):
    node = tree.nodes.new("ShaderNodeBlackbody")
    node.inputs["Temperature"].default_value = kelvin
    return node


def direction_of(angle):
    """The unit vector from the head toward (azimuth right of the camera, elevation) degrees."""
    azimuth, elevation = (math.radians(a) for a in angle)
    return Vector((math.sin(azimuth) * math.cos(elevation), -math.cos(azimuth) * math.cos(elevation),
                   math.sin(elevation)))


def camera(scene, centre):
    """An 85 mm lens (36 mm sensor) 1.1 m in front of ``centre``, looking at it."""
    data = bpy.data.cameras.new("camera")
    data.lens, data.sensor_width = 85.0, 36.0
    obj = bpy.data.objects.new("camera", data)
    scene.collection.objects.link(obj)
    obj.location = (centre.x, centre.y - 1.1, centre.z)
    obj.rotation_euler = (math.pi / 2, 0.0, 0.0)
    scene.camera = obj
    return obj


def light(scene, name, centre, angle, size, distance, kelvin, strength, kind="area"):
    """A blackbody light of ``kelvin`` from ``angle`` (azimuth, elevation degrees): an area light of side ``size`` m
    ``distance`` m from ``centre`` facing it, its irradiance there the nominal one x ``strength`` at any distance
    (power / (pi d^2), a Lambertian emitter: the distance changes the fall-off and the shadow, not the level); or
    (``kind`` "sun") a sun of angle ``size`` degrees from that direction."""
    direction = direction_of(angle)
    irradiance = NOMINAL_IRRADIANCE * strength
    if kind == "sun":
        data = bpy.data.lights.new(name, "SUN")
        data.angle = math.radians(size)
        data.energy = irradiance
        location = centre + 2.0 * direction
    else:
        data = bpy.data.lights.new(name, "AREA")
        data.size = size
        data.energy = irradiance * math.pi * distance ** 2
        location = centre + distance * direction
    data.use_nodes = True
    tree = data.node_tree
    tree.links.new(blackbody_node(tree, kelvin).outputs["Color"], tree.nodes["Emission"].inputs["Color"])
    obj = bpy.data.objects.new(name, data)
    scene.collection.objects.link(obj)
    obj.location = location
    obj.rotation_euler = (-direction).to_track_quat("-Z", "Y").to_euler()
    return obj


def environment(scene, settings):
    """A uniform world of ``settings["world"]`` (RGB) x ``settings["world_strength"]``."""
    world = bpy.data.worlds.new("world")
    world.use_nodes = True
    background = world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (*settings["world"], 1.0)
    background.inputs["Strength"].default_value = settings["world_strength"]
    scene.world = world
