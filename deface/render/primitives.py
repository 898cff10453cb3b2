"""Small synthetic meshes (UV sphere, planes) for tests, benchmarks and demos; counter-clockwise outward."""

from __future__ import annotations

import math

import torch

from deface.render.mesh import Mesh


def uv_sphere(radius: float = 1.0, rings: int = 32, segments: int = 64, dtype=torch.float64) -> Mesh:
    """A latitude-longitude sphere centred at the origin, poles on ±z, with a UV seam at u = 0/1.

    rings: latitude bands (>= 2); segments: longitude slices (>= 3). UV: u = longitude / 2pi,
    v = 1 - colatitude / pi.
    """
    if rings < 2 or segments < 3:
        raise ValueError("uv_sphere: need rings >= 2 and segments >= 3")
    theta = torch.linspace(0, math.pi, rings + 1, dtype=dtype)[1:-1]  # interior rings
    phi = torch.arange(segments, dtype=dtype) * (2 * math.pi / segments)  # [S]
    t, p = torch.meshgrid(theta, phi, indexing="ij")
    ring_points = torch.stack([t.sin() * p.cos(), t.sin() * p.sin(), t.cos()], -1).reshape(-1, 3)
    poles = torch.tensor([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]], dtype=dtype)
    vertices = radius * torch.cat([ring_points, poles])  # [(R-1) S + 2, 3]
    north, south = ring_points.shape[0], ring_points.shape[0] + 1

    def vid(ring: int, seg: int) -> int:  # ring 0..R-2
        return ring * segments + seg % segments

    # UV grid has segments + 1 columns (the seam is duplicated); pole UVs per segment.
    def uid(ring: int, seg: int) -> int:
        return ring * (segments + 1) + seg

    uv_phi = torch.arange(segments + 1, dtype=dtype) * (2 * math.pi / segments)
    uv_t, uv_p = torch.meshgrid(theta, uv_phi, indexing="ij")
    uvs = torch.stack([uv_p / (2 * math.pi), 1 - uv_t / math.pi], -1).reshape(-1, 2)
    seg_centres = (torch.arange(segments, dtype=dtype) + 0.5) / segments
    pole_uvs = torch.cat([torch.stack([seg_centres, torch.ones_like(seg_centres)], -1),
                          torch.stack([seg_centres, torch.zeros_like(seg_centres)], -1)])
    north_uv, south_uv = uvs.shape[0], uvs.shape[0] + segments
    uvs = torch.cat([uvs, pole_uvs])

    tris, tri_uvs = [], []
    for s in range(segments):
        tris.append([north, vid(0, s), vid(0, s + 1)])
        tri_uvs.append([north_uv + s, uid(0, s), uid(0, s + 1)])
        last = rings - 2
        tris.append([south, vid(last, s + 1), vid(last, s)])
        tri_uvs.append([south_uv + s, uid(last, s + 1), uid(last, s)])
        for r in range(rings - 2):
            a, b, c, d = vid(r, s), vid(r + 1, s), vid(r + 1, s + 1), vid(r, s + 1)
            ua, ub, uc, ud = uid(r, s), uid(r + 1, s), uid(r + 1, s + 1), uid(r, s + 1)
            tris += [[a, b, c], [a, c, d]]
            tri_uvs += [[ua, ub, uc], [ua, uc, ud]]
    return Mesh(vertices, torch.tensor(tris), uvs, torch.tensor(tri_uvs))


def grid_plane(
    x_range: tuple[float, float], y_range: tuple[float, float], z: float = 0.0, cells: int = 16,
    facing_up: bool = True, dtype=torch.float64,
) -> Mesh:
    """A regular grid of ``cells`` x ``cells`` quads at height z, normal +z (or -z); UV spans [0, 1]²."""
    xs = torch.linspace(*x_range, cells + 1, dtype=dtype)
    ys = torch.linspace(*y_range, cells + 1, dtype=dtype)
    gy, gx = torch.meshgrid(ys, xs, indexing="ij")
    vertices = torch.stack([gx, gy, torch.full_like(gx, z)], -1).reshape(-1, 3)
    u = (gx - x_range[0]) / (x_range[1] - x_range[0])
    v = (gy - y_range[0]) / (y_range[1] - y_range[0])
    uvs = torch.stack([u, v], -1).reshape(-1, 2)
    idx = torch.arange((cells + 1) ** 2).reshape(cells + 1, cells + 1)
    a, b = idx[:-1, :-1].reshape(-1), idx[:-1, 1:].reshape(-1)
    c, d = idx[1:, 1:].reshape(-1), idx[1:, :-1].reshape(-1)
    tris = torch.cat([torch.stack([a, b, c], -1), torch.stack([a, c, d], -1)])  # ccw seen from +z
    if not facing_up:
        tris = tris[:, [0, 2, 1]]
    return Mesh(vertices, tris, uvs, tris.clone())


def merge(*meshes: Mesh) -> Mesh:
    """One mesh holding all the given meshes (indices offset)."""
    if not meshes:
        raise ValueError("merge: need at least one mesh")
    v_off, u_off = 0, 0
    tris, tri_uvs = [], []
    for mesh in meshes:
        tris.append(mesh.triangles + v_off)
        tri_uvs.append(mesh.triangle_uvs + u_off)
        v_off += mesh.vertices.shape[0]
        u_off += mesh.uvs.shape[0]
    return Mesh(
        torch.cat([m.vertices for m in meshes]), torch.cat(tris), torch.cat([m.uvs for m in meshes]),
        torch.cat(tri_uvs),
    )
