"""Exporters: OBJ/MTL and GLB open in trimesh with the right UVs; staged folders never half-write."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from deface.export.files import staged_directory
from deface.export.mesh import write_glb, write_obj
from deface.io.images import to_uint8

# A unit quad with a UV seam: vertex 0 carries two UVs.
VERTICES = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
TRIANGLES = np.array([[0, 1, 2], [0, 2, 3]])
UVS = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5]], np.float32)
TRIANGLE_UVS = np.array([[0, 1, 2], [4, 2, 3]])


def test_obj_round_trip_keeps_positions_and_v_up_uvs(tmp_path):
    path = write_obj(tmp_path, VERTICES, TRIANGLES, UVS, TRIANGLE_UVS)
    text = path.read_text()
    assert "mtllib mesh.mtl" in text and "f 1/5 3/3 4/4" in text  # the seam corner uses its second UV
    mesh = trimesh.load(path, process=False, force="mesh")
    assert mesh.faces.shape == (2, 3)
    # Corner (1, 1) of the quad has UV (1, 1): v up, as OBJ and deface agree.
    corner = np.flatnonzero(np.all(np.isclose(mesh.vertices, [1, 1, 0]), axis=1))[0]
    assert np.allclose(mesh.visual.uv[corner], [1, 1])
    assert "map_Pr textures/roughness.png" in (tmp_path / "mesh.mtl").read_text()


def test_glb_has_split_seams_and_a_pbr_material(tmp_path):
    diffuse = np.full((8, 8, 3), 200, np.uint8)
    roughness = np.full((8, 8, 1), 100, np.uint8)
    write_glb(tmp_path / "m.glb", VERTICES, TRIANGLES, UVS, TRIANGLE_UVS, diffuse, roughness)
    mesh = list(trimesh.load(tmp_path / "m.glb").geometry.values())[0]
    assert len(mesh.vertices) == 5  # vertex 0 split at the seam
    assert np.allclose(mesh.vertices.max(0), [0.01, 0.01, 0])  # cm -> m
    material = mesh.visual.material
    assert material.baseColorTexture is not None and material.metallicFactor == 0


def test_staged_directory_keeps_the_previous_result_on_failure(tmp_path):
    final = tmp_path / "result"
    with staged_directory(final) as folder:
        (folder / "a.txt").write_text("first")
    with pytest.raises(RuntimeError):
        with staged_directory(final) as folder:
            (folder / "a.txt").write_text("half")
            raise RuntimeError("interrupted")
    assert (final / "a.txt").read_text() == "first"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["result"]


def test_to_uint8_gamma_encodes_only_colour():
    assert to_uint8(np.array([0.5]), srgb=False)[0] == 128
    assert to_uint8(np.array([0.5]), srgb=True)[0] == round(0.5 ** (1 / 2.2) * 255)


def test_params_lights_are_the_lights_as_rendered():
    """A fitted light with a negative lobe is written as the renderer renders it: its radiance over the sphere is
    (nearly) non-negative, and rendering the written light again changes nothing."""
    import torch

    from deface.export.outputs import light_record
    from deface.render.renderer import Renderer
    from deface.render.sh import RADIANCE_SAMPLES, fibonacci_sphere, sh_basis

    bands = 3
    lights = torch.zeros(3, bands * bands, 3)
    lights[:, 0] = 1.0  # uniform radiance ...
    lights[:, 2] = torch.tensor([2.5, 2.0, 1.5])  # ... minus a lobe below the face, more in red than in blue
    renderer = Renderer()
    basis = sh_basis(torch.as_tensor(fibonacci_sphere(RADIANCE_SAMPLES), dtype=torch.float32), bands)
    assert (basis @ lights[1]).min() < -0.3  # the fitted light is negative somewhere
    record = light_record(renderer, lights, [2, 0], bands)
    assert record["kept"] == [2, 0] and set(record["sh"]) == {"0", "2"} and record["initial_count"] == 3
    written = torch.tensor([record["sh"]["2"], record["sh"]["0"]])
    np.testing.assert_allclose(written.numpy(), renderer.rendered_lights(lights[[2, 0]]).numpy(), rtol=1e-6)
    assert (basis @ written[0]).min() > -0.05 * (basis @ written[0]).max()  # what is left of the lobe: ringing
    np.testing.assert_allclose(renderer.rendered_lights(written).numpy(), written.numpy(), atol=0.05)
    assert "clamped" in record["convention"]
