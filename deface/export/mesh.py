"""OBJ + MTL (opens in Blender, MeshLab and three.js) and GLB (glTF 2.0 metallic-roughness) writers.

OBJ UVs are written as they are: deface's UV convention is already OBJ's (v up, texture row 0 is v = 1).
MTL: ``map_Kd`` diffuse (sRGB), ``map_Ks`` specular, ``map_Pr`` roughness (the PBR extension Blender's
OBJ importer reads).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

TEXTURE_FILES = {"diffuse": "textures/diffuse.png", "specular": "textures/specular.png",
                 "roughness": "textures/roughness.png"}


def write_obj(folder: Path, vertices: np.ndarray, triangles: np.ndarray, uvs: np.ndarray,
              triangle_uvs: np.ndarray, name: str = "mesh") -> Path:
    """Write ``name.obj`` + ``name.mtl``; vertices [V, 3], triangles [F, 3], uvs [U, 2], triangle_uvs [F, 3]."""
    obj_path, mtl_path = folder / f"{name}.obj", folder / f"{name}.mtl"
    lines = [f"# deface face mesh: {len(vertices)} vertices, {len(triangles)} triangles, units cm",
             f"mtllib {mtl_path.name}", "o face"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices]
    lines += [f"vt {u:.6f} {v:.6f}" for u, v in uvs]
    lines += ["usemtl face", "s 1"]
    corners = np.stack([triangles + 1, triangle_uvs + 1], axis=-1)  # OBJ indices start at 1
    lines += [" ".join(["f"] + [f"{v}/{t}" for v, t in tri]) for tri in corners]
    obj_path.write_text("\n".join(lines) + "\n")
    mtl_path.write_text(
        "newmtl face\nKa 0 0 0\nKd 1 1 1\nKs 1 1 1\nNs 50\nillum 2\n"
        f"map_Kd {TEXTURE_FILES['diffuse']}\nmap_Ks {TEXTURE_FILES['specular']}\n"
        f"map_Pr {TEXTURE_FILES['roughness']}\n"
    )
    return obj_path


def write_glb(path: Path, vertices: np.ndarray, triangles: np.ndarray, uvs: np.ndarray,
              triangle_uvs: np.ndarray, diffuse_srgb: np.ndarray, roughness: np.ndarray) -> Path:
    """A GLB with a glTF metallic-roughness material (base colour = diffuse, metallic 0).

    glTF needs one UV per vertex, so corners are split at UV seams. Textures are uint8 images.
    """
    import trimesh
    from PIL import Image

    corner_vertex = triangles.reshape(-1)
    corner_uv = triangle_uvs.reshape(-1)
    keys = corner_vertex.astype(np.int64) * (len(uvs) + 1) + corner_uv
    unique, inverse = np.unique(keys, return_inverse=True)
    first = np.zeros(len(unique), dtype=np.int64)
    first[inverse] = np.arange(len(keys))
    split_vertices = vertices[corner_vertex[first]]
    split_uvs = uvs[corner_uv[first]]
    faces = inverse.reshape(-1, 3)
    metal_rough = np.zeros((*roughness.shape[:2], 3), dtype=np.uint8)
    metal_rough[..., 1] = roughness.reshape(roughness.shape[:2])  # glTF: G = roughness, B = metallic
    material = trimesh.visual.material.PBRMaterial(
        baseColorTexture=Image.fromarray(diffuse_srgb),
        metallicRoughnessTexture=Image.fromarray(metal_rough),
        metallicFactor=0.0,
        roughnessFactor=1.0,
    )
    visual = trimesh.visual.TextureVisuals(uv=split_uvs, material=material)
    mesh = trimesh.Trimesh(split_vertices / 100.0, faces, visual=visual, process=False)  # glTF is in metres
    path.write_bytes(trimesh.exchange.gltf.export_glb(trimesh.Scene(mesh)))
    return path
