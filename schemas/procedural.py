"""Triangle meshes generated from a few parameters: the procedural shapes of ``schemas.scene``.

NumPy only (no Mitsuba): the worker compiles these meshes, the USD exporter writes them as
``UsdGeom.Mesh`` and the validator counts their triangles against ``HGRENDER_MAX_TRIANGLES`` from the
parameters alone (:func:`mesh_size`), before anything is generated.

Every generator returns vertex positions (m, world frame before the shape's ``transform``), triangles
(counter-clockwise seen from the side the normals point to), per-vertex unit normals and texture
coordinates. The texture coordinates matter for anisotropic materials: the renderer's first tangent
follows ∂p/∂u, so on an ``optical_disc`` (u = normalised radius) a grating's vector is radial and its
tracks are concentric circles, as on a CD or DVD.

Shapes (local frame: x = right, y = up along the shape's ``normal``/``up``, z = towards the viewer):

* ``shell`` — a beetle-like ribbed ellipsoid: p(θ, φ) = (a cos θ, ρ b sin θ cos φ, ρ c sin θ sin φ) with
  ρ = 1 + rib_depth·cos(rib_count·φ) + segment_depth·cos(segment_count·θ); θ ∈ [0, π] runs along the long
  (x) axis, φ around it. Ribs run lengthwise like elytra grooves, segments across.
* ``wavy_sheet`` — a rectangle displaced along its normal by h(x, y) (``waves``: A sin(2πx/Λ); ``ripples``:
  A cos(2π r/Λ) with r the distance from the centre; ``egg_crate``: A sin(2πx/Λ) sin(2πy/Λ)).
* ``optical_disc`` — an annulus (inner hole) with u = (r − r_in)/(r_out − r_in), v = φ/2π.
* ``backdrop`` — a photographer's cyclorama: a floor that bends up into a back wall along a quarter
  cylinder of radius ``cove_radius_m``, so the horizon line disappears.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class GeneratedMesh:
    """A generated triangle mesh (float64 arrays; the renderer converts to float32)."""

    vertices_m: np.ndarray  # (N, 3)
    triangles: np.ndarray  # (M, 3) int64 vertex indices
    normals: np.ndarray  # (N, 3) unit vectors
    uvs: np.ndarray  # (N, 2)


# --- helpers -------------------------------------------------------------------------------------


def _grid_triangles(rows: int, columns: int) -> np.ndarray:
    """Two triangles per cell of a (rows+1)×(columns+1) vertex grid, clockwise in (row, column): seen from
    the side where row × column points."""
    r, c = np.meshgrid(np.arange(rows), np.arange(columns), indexing="ij")
    v00 = (r * (columns + 1) + c).ravel()
    v01, v10 = v00 + 1, v00 + columns + 1
    v11 = v10 + 1
    return np.concatenate([np.stack([v00, v11, v01], 1), np.stack([v00, v10, v11], 1)]).astype(np.int64)


def _vertex_normals(vertices: np.ndarray, triangles: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """Area-weighted averages of the face normals (``fallback`` where they cancel, e.g. at poles)."""
    a, b, c = (vertices[triangles[:, i]] for i in range(3))
    face = np.cross(b - a, c - a)  # length = twice the area: area weighting for free
    normals = np.zeros_like(vertices)
    for i in range(3):
        np.add.at(normals, triangles[:, i], face)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return np.where(length > 1e-300, normals / np.maximum(length, 1e-300), fallback)


def _unit(vector: Any) -> np.ndarray:
    array = np.asarray(vector, dtype=float)
    return array / np.linalg.norm(array)


def _local_frame(normal: Any, up: Any | None) -> np.ndarray:
    """Columns (x, y, z) of a right-handed frame with y = ``normal``; x ⟂ ``up`` when given (else any)."""
    y_axis = _unit(normal)
    if up is None:
        helper = np.array([0.0, 0.0, 1.0]) if abs(y_axis[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    else:
        helper = np.asarray(up, dtype=float)
    z_axis = helper - np.dot(helper, y_axis) * y_axis
    z_axis /= np.linalg.norm(z_axis)
    x_axis = np.cross(y_axis, z_axis)
    return np.stack([x_axis, y_axis, z_axis], axis=1)


def _placed(local: np.ndarray, frame: np.ndarray, center_m: Any) -> np.ndarray:
    return local @ frame.T + np.asarray(center_m, dtype=float)


# --- generators ----------------------------------------------------------------------------------


def shell(shape: Any) -> GeneratedMesh:
    """The ribbed ellipsoid of the module docstring; long axis along ``axis``, ``up`` its top."""
    n_theta, n_phi = shape.segments_along, shape.segments_around
    theta = np.linspace(0.0, math.pi, n_theta + 1)
    phi = np.linspace(0.0, 2.0 * math.pi, n_phi + 1)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    a, b, c = shape.semi_axes_m
    rho = (
        1.0
        + shape.rib_depth * np.cos(shape.rib_count * p)
        + shape.segment_depth * np.cos(shape.segment_count * t)
    )
    local = np.stack([a * np.cos(t), rho * b * np.sin(t) * np.cos(p), rho * c * np.sin(t) * np.sin(p)], -1)
    frame = _long_axis_frame(shape.axis, shape.up)
    vertices = _placed(local.reshape(-1, 3), frame, shape.center_m)
    triangles = _grid_triangles(n_theta, n_phi)
    fallback = np.sign(np.cos(t)).reshape(-1, 1) * frame[:, 0]
    normals = _vertex_normals(vertices, triangles, fallback).reshape(n_theta + 1, n_phi + 1, 3)
    # The φ = 0 and φ = 2π columns are one seam and each tip row is one point: without sharing their
    # normals the seam would show and the tips would shade like a star.
    seam = normals[:, 0] + normals[:, -1]
    normals[:, 0] = normals[:, -1] = seam / np.linalg.norm(seam, axis=1, keepdims=True)
    normals[0], normals[-1] = frame[:, 0], -frame[:, 0]
    normals = normals.reshape(-1, 3)
    uvs = np.stack([t / math.pi, p / (2.0 * math.pi)], -1).reshape(-1, 2)
    return GeneratedMesh(vertices, triangles, normals, uvs)


def _long_axis_frame(axis: Any, up: Any) -> np.ndarray:
    """Columns (x = long axis, y = up ⟂ axis, z = x × y)."""
    x_axis = _unit(axis)
    y_axis = np.asarray(up, dtype=float) - np.dot(up, x_axis) * x_axis
    y_axis /= np.linalg.norm(y_axis)
    return np.stack([x_axis, y_axis, np.cross(x_axis, y_axis)], axis=1)


def wavy_sheet(shape: Any) -> GeneratedMesh:
    """A height field over a ``width_m`` × ``height_m`` rectangle (height along ``up``)."""
    n = shape.segments
    x = np.linspace(-shape.width_m / 2, shape.width_m / 2, n + 1)
    z = np.linspace(-shape.height_m / 2, shape.height_m / 2, n + 1)
    zz, xx = np.meshgrid(z, x, indexing="ij")
    k = 2.0 * math.pi / shape.wavelength_m
    amplitude = shape.amplitude_m
    if shape.pattern == "waves":
        h, dh_dx, dh_dz = amplitude * np.sin(k * xx), amplitude * k * np.cos(k * xx), np.zeros_like(xx)
    elif shape.pattern == "ripples":
        r = np.hypot(xx, zz)
        safe = np.where(r > 0, r, 1.0)
        slope = -amplitude * k * np.sin(k * r)
        h, dh_dx, dh_dz = amplitude * np.cos(k * r), slope * xx / safe, slope * zz / safe
    else:  # egg_crate
        h = amplitude * np.sin(k * xx) * np.sin(k * zz)
        dh_dx = amplitude * k * np.cos(k * xx) * np.sin(k * zz)
        dh_dz = amplitude * k * np.sin(k * xx) * np.cos(k * zz)
    # Local frame: y = normal, z = −up (so height increases along up), x = y × z.
    frame = _local_frame(shape.normal, -np.asarray(shape.up, dtype=float))
    local = np.stack([xx, h, zz], -1).reshape(-1, 3)
    vertices = _placed(local, frame, shape.center_m)
    local_normals = np.stack([-dh_dx, np.ones_like(h), -dh_dz], -1).reshape(-1, 3)
    local_normals /= np.linalg.norm(local_normals, axis=1, keepdims=True)
    uvs = np.stack([(xx - x[0]) / shape.width_m, (zz - z[0]) / shape.height_m], -1).reshape(-1, 2)
    return GeneratedMesh(vertices, _grid_triangles(n, n), local_normals @ frame.T, uvs)


def optical_disc(shape: Any) -> GeneratedMesh:
    """An annulus whose ∂p/∂u is radial (u = normalised radius), facing ``normal``."""
    n_r, n_phi = shape.segments_radial, shape.segments_around
    radius = np.linspace(shape.inner_radius_m, shape.radius_m, n_r + 1)
    phi = np.linspace(0.0, 2.0 * math.pi, n_phi + 1)
    rr, pp = np.meshgrid(radius, phi, indexing="ij")
    frame = _local_frame(shape.normal, None)
    # Local (x, z) plane, y = normal; φ increases from z towards x.
    local = np.stack([rr * np.sin(pp), np.zeros_like(rr), rr * np.cos(pp)], -1).reshape(-1, 3)
    vertices = _placed(local, frame, shape.center_m)
    normals = np.broadcast_to(frame[:, 1], vertices.shape).copy()
    width = shape.radius_m - shape.inner_radius_m
    uvs = np.stack([(rr - shape.inner_radius_m) / width, pp / (2.0 * math.pi)], -1).reshape(-1, 2)
    return GeneratedMesh(vertices, _grid_triangles(n_r, n_phi), normals, uvs)


def backdrop(shape: Any) -> GeneratedMesh:
    """Floor (``depth_m`` in front of the cove), quarter-cylinder cove, wall (up to ``height_m``)."""
    radius, depth, height = shape.cove_radius_m, shape.depth_m, shape.height_m
    # Profile in the (forward, up) plane, starting at the floor's front edge, ending at the wall's top.
    floor = np.stack([np.linspace(depth, 0.0, 9), np.zeros(9)], 1)
    angles = np.linspace(0.0, math.pi / 2, shape.segments + 1)[1:]
    cove = np.stack([-radius * np.sin(angles), radius * (1.0 - np.cos(angles))], 1)
    wall = np.stack([np.full(8, -radius), np.linspace(radius, height, 9)[1:]], 1)
    profile = np.concatenate([floor, cove, wall])
    # Profile normals: up on the floor, forward on the wall, towards the cove's axis in between.
    cove_normals = np.stack([np.sin(angles), np.cos(angles)], 1)
    profile_normals = np.concatenate([np.tile([0.0, 1.0], (9, 1)), cove_normals, np.tile([1.0, 0.0], (8, 1))])
    across = np.linspace(-shape.width_m / 2, shape.width_m / 2, 2)
    forward = _unit(
        np.asarray(shape.facing, dtype=float) - np.dot(shape.facing, _unit(shape.up)) * _unit(shape.up)
    )
    up = _unit(shape.up)
    right = np.cross(forward, up)
    count = len(profile)
    s, a = np.meshgrid(np.arange(count), across, indexing="ij")
    origin = np.asarray(shape.floor_center_m, dtype=float) - forward * (depth / 2)
    vertices = (
        origin
        + profile[s.ravel(), 0, None] * forward
        + profile[s.ravel(), 1, None] * up
        + a.ravel()[:, None] * right
    )
    normals = profile_normals[s.ravel(), 0, None] * forward + profile_normals[s.ravel(), 1, None] * up
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(profile, axis=0), axis=1))])
    uvs = np.stack([(a.ravel() - across[0]) / shape.width_m, arc[s.ravel()] / arc[-1]], -1)
    return GeneratedMesh(vertices, _grid_triangles(count - 1, 1), normals, uvs)


GENERATORS = {"shell": shell, "wavy_sheet": wavy_sheet, "optical_disc": optical_disc, "backdrop": backdrop}


def generate_mesh(shape: Any) -> GeneratedMesh:
    """The mesh of a procedural shape model (``shape.type`` in :data:`GENERATORS`)."""
    return GENERATORS[shape.type](shape)


def mesh_size(shape: Any) -> tuple[int, int]:
    """(vertex count, triangle count) of a procedural shape, from its parameters only."""
    if shape.type == "shell":
        rows, columns = shape.segments_along, shape.segments_around
    elif shape.type == "wavy_sheet":
        rows, columns = shape.segments, shape.segments
    elif shape.type == "optical_disc":
        rows, columns = shape.segments_radial, shape.segments_around
    else:  # backdrop: 9 floor + segments cove + 8 wall profile points, two across
        rows, columns = 9 + shape.segments + 8 - 1, 1
    return (rows + 1) * (columns + 1), 2 * rows * columns
