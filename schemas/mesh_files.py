"""Small, bounded readers for the triangle meshes of scene bundles: Wavefront OBJ and Stanford PLY.

Only geometry is read: OBJ ``v``/``f`` records (``vt``, ``vn``, groups, materials and ``mtllib`` are
ignored — no other file is ever opened); PLY ``vertex`` x/y/z (+ nx/ny/nz) and ``face`` vertex-index
lists in ``ascii``, ``binary_little_endian`` or ``binary_big_endian``. Polygons are split into triangle
fans (exact for the convex polygons exporters write). Units are whatever the file uses, taken as metres.
Counts are checked against :class:`SceneLimits` before anything large is allocated.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hgcore.settings import SceneLimits
from schemas.bundle import resolve_bundle_file
from schemas.errors import SceneError
from schemas.scene import MeshFileShape, Scene


@dataclass(frozen=True)
class TriangleMesh:
    """Vertex positions (N, 3) float64 in metres, triangles (M, 3) int64, optional unit normals (N, 3)."""

    vertices_m: np.ndarray
    triangles: np.ndarray
    normals: np.ndarray | None = None


def fan_triangulate(face_sizes: np.ndarray, face_indices: np.ndarray, where: str) -> np.ndarray:
    """Triangles (M, 3) from polygons given as sizes and concatenated vertex indices (fan from corner 0)."""
    if face_sizes.size and int(face_sizes.min()) < 3:
        raise SceneError.at(where, f"a face has {int(face_sizes.min())} vertices; faces need at least 3")
    if int(face_sizes.sum()) != face_indices.size:
        raise SceneError.at(where, "face vertex counts do not match the number of face vertex indices")
    starts = np.concatenate([[0], np.cumsum(face_sizes)[:-1]]).astype(np.int64)
    triangles_per_face = face_sizes.astype(np.int64) - 2
    first = np.repeat(starts, triangles_per_face)
    # Offset of each triangle within its face: 0, 1, ..., size-3.
    offsets = np.arange(int(triangles_per_face.sum())) - np.repeat(
        np.cumsum(triangles_per_face) - triangles_per_face, triangles_per_face
    )
    corners = np.stack([first, first + offsets + 1, first + offsets + 2], axis=1)
    return face_indices[corners]


def _check_counts(vertex_count: int, triangle_count: int, limits: SceneLimits, where: str) -> None:
    if vertex_count > limits.max_vertices:
        raise SceneError.at(
            where,
            f"{vertex_count} vertices exceed the limit of {limits.max_vertices} (HGRENDER_MAX_VERTICES)",
        )
    if triangle_count > limits.max_triangles:
        raise SceneError.at(
            where,
            f"{triangle_count} triangles exceed the limit of {limits.max_triangles} (HGRENDER_MAX_TRIANGLES)",
        )


def _finish(
    vertices: np.ndarray, triangles: np.ndarray, normals: np.ndarray | None, where: str
) -> TriangleMesh:
    if vertices.shape[0] < 3 or triangles.shape[0] < 1:
        raise SceneError.at(where, "the mesh has no triangles")
    if not np.all(np.isfinite(vertices)):
        raise SceneError.at(where, "vertex positions must be finite")
    if triangles.min() < 0 or triangles.max() >= vertices.shape[0]:
        raise SceneError.at(where, "a face refers to a vertex that does not exist")
    if normals is not None:
        lengths = np.linalg.norm(normals, axis=1, keepdims=True)
        normals = normals / np.where(lengths > 0.0, lengths, 1.0) if np.all(np.isfinite(normals)) else None
    return TriangleMesh(vertices.astype(np.float64), triangles.astype(np.int64), normals)


def read_obj(path: Path, limits: SceneLimits, where: str) -> TriangleMesh:
    """Parse a Wavefront OBJ file (1-based and negative relative indices)."""
    vertices: list[list[float]] = []
    face_sizes: list[int] = []
    face_indices: list[int] = []
    with open(path, encoding="utf-8", errors="replace") as handle:
        for line_number, line in enumerate(handle, start=1):
            fields = line.split()
            if not fields:
                continue
            try:
                if fields[0] == "v":
                    vertices.append([float(fields[1]), float(fields[2]), float(fields[3])])
                elif fields[0] == "f":
                    corners = [int(token.split("/", 1)[0]) for token in fields[1:]]
                    # OBJ indices are 1-based; negative ones count back from the latest vertex.
                    face_indices.extend(c - 1 if c > 0 else len(vertices) + c for c in corners)
                    face_sizes.append(len(corners))
            except (ValueError, IndexError):
                raise SceneError.at(
                    f"{where}:{line_number}", f"malformed OBJ record {line.strip()[:60]!r}"
                ) from None
            if len(face_sizes) % 65536 == 0 or len(vertices) % 65536 == 0:
                _check_counts(len(vertices), len(face_indices) - 2 * len(face_sizes), limits, where)
    sizes = np.asarray(face_sizes, dtype=np.int64)
    _check_counts(len(vertices), int((sizes - 2).sum()), limits, where)
    triangles = fan_triangulate(sizes, np.asarray(face_indices, dtype=np.int64), where)
    return _finish(np.asarray(vertices, dtype=np.float64).reshape(-1, 3), triangles, None, where)


_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
    "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip


@dataclass
class _PlyElement:
    name: str
    count: int
    properties: list[tuple[str, str, str | None]]  # (name, value type, list count type or None)


def _parse_ply_header(handle: object, where: str) -> tuple[str, list[_PlyElement]]:
    read_line = handle.readline  # type: ignore[attr-defined]
    if read_line().strip() != b"ply":
        raise SceneError.at(where, "not a PLY file (missing 'ply' magic)")
    file_format, elements = "", []
    for _ in range(1000):  # headers are short; bound the loop on hostile input
        fields = read_line().decode("ascii", errors="replace").split()
        if not fields or fields[0] in ("comment", "obj_info"):
            continue
        if fields[0] == "format" and len(fields) >= 2:
            file_format = fields[1]
        elif fields[0] == "element" and len(fields) == 3:
            elements.append(_PlyElement(fields[1], int(fields[2]), []))
        elif fields[0] == "property" and elements:
            if fields[1] == "list" and len(fields) == 5:
                elements[-1].properties.append((fields[4], _PLY_TYPES[fields[3]], _PLY_TYPES[fields[2]]))
            elif len(fields) == 3:
                elements[-1].properties.append((fields[2], _PLY_TYPES[fields[1]], None))
            else:
                raise SceneError.at(where, f"malformed PLY property line {' '.join(fields)!r}")
        elif fields[0] == "end_header":
            if file_format not in ("ascii", "binary_little_endian", "binary_big_endian"):
                raise SceneError.at(where, f"unsupported PLY format {file_format!r}")
            return file_format, elements
        else:
            raise SceneError.at(where, f"malformed PLY header line {' '.join(fields)!r}")
    raise SceneError.at(where, "PLY header has no end_header")


def read_ply(path: Path, limits: SceneLimits, where: str) -> TriangleMesh:
    """Parse a PLY file's ``vertex`` and ``face`` elements (other elements are skipped)."""
    with open(path, "rb") as handle:
        try:
            file_format, elements = _parse_ply_header(handle, where)
        except (KeyError, ValueError, IndexError) as error:
            raise SceneError.at(where, f"malformed PLY header ({error})") from None
        counts = {element.name: element.count for element in elements}
        if min(counts.values(), default=0) < 0:
            raise SceneError.at(where, "negative PLY element count")
        _check_counts(counts.get("vertex", 0), counts.get("face", 0), limits, where)
        body = handle.read()
    byte_order = ">" if file_format == "binary_big_endian" else "<"
    vertices = normals = None
    face_sizes: list[int] = []
    face_indices: list[int] = []
    try:
        tokens = body.split() if file_format == "ascii" else None
        cursor = 0
        for element in elements:
            names = [name for name, _type, _count in element.properties]
            has_lists = any(count_type is not None for _n, _t, count_type in element.properties)
            if file_format == "ascii":
                assert tokens is not None
                rows: list[list[float]] = []
                for _ in range(element.count):
                    row: list[float] = []
                    for _name, _value_type, count_type in element.properties:
                        if count_type is None:
                            row.append(float(tokens[cursor]))
                            cursor += 1
                        else:
                            length = int(tokens[cursor])
                            values = [int(t) for t in tokens[cursor + 1 : cursor + 1 + length]]
                            if element.name == "face":
                                face_sizes.append(length)
                                face_indices.extend(values)
                            cursor += 1 + length
                    rows.append(row)
                scalar_names = [n for n, _t, c in element.properties if c is None]
                table = np.asarray(rows, dtype=np.float64).reshape(element.count, len(scalar_names))
                columns = {name: table[:, i] for i, name in enumerate(scalar_names)}
            elif not has_lists:
                dtype = np.dtype(
                    [(name, byte_order + value_type) for name, value_type, _c in element.properties]
                )
                table = np.frombuffer(body, dtype=dtype, count=element.count, offset=cursor)
                cursor += dtype.itemsize * element.count
                columns = {name: table[name].astype(np.float64) for name in names}
            else:
                columns = {}
                for _ in range(element.count):
                    for _name, value_type, count_type in element.properties:
                        if count_type is None:
                            cursor += np.dtype(value_type).itemsize
                            continue
                        length = int(np.frombuffer(body, byte_order + count_type, 1, cursor)[0])
                        cursor += np.dtype(count_type).itemsize
                        values = np.frombuffer(body, byte_order + value_type, length, cursor)
                        cursor += values.nbytes
                        if element.name == "face":
                            face_sizes.append(length)
                            face_indices.extend(int(v) for v in values)
            if element.name == "vertex":
                vertices = np.stack([columns["x"], columns["y"], columns["z"]], axis=1)
                if all(name in columns for name in ("nx", "ny", "nz")):
                    normals = np.stack([columns["nx"], columns["ny"], columns["nz"]], axis=1)
    except (KeyError, ValueError, IndexError, TypeError) as error:
        raise SceneError.at(where, f"malformed or truncated PLY data ({error})") from None
    if vertices is None:
        raise SceneError.at(where, "PLY file has no vertex element with x, y, z")
    sizes = np.asarray(face_sizes, dtype=np.int64)
    _check_counts(vertices.shape[0], int((sizes - 2).sum()), limits, where)
    triangles = fan_triangulate(sizes, np.asarray(face_indices, dtype=np.int64), where)
    return _finish(vertices, triangles, normals, where)


def read_mesh_file(bundle_dir: Path, relative_path: str, limits: SceneLimits, where: str) -> TriangleMesh:
    """Read the OBJ/PLY mesh at ``relative_path`` inside ``bundle_dir`` (confined, size-limited)."""
    path = resolve_bundle_file(bundle_dir, relative_path, where)
    if path.stat().st_size > limits.max_file_bytes:
        raise SceneError.at(where, f"{relative_path} exceeds the limit of {limits.max_file_bytes} bytes")
    if relative_path.lower().endswith(".obj"):
        return read_obj(path, limits, where)
    if relative_path.lower().endswith(".ply"):
        return read_ply(path, limits, where)
    raise SceneError.at(where, f"{relative_path}: mesh files must be .obj or .ply")


def load_scene_meshes(scene: Scene, bundle_dir: Path, limits: SceneLimits) -> dict[int, TriangleMesh]:
    """Read every ``mesh_file`` shape of ``scene`` (keyed by shape index), enforcing the triangle budget
    over the whole scene (inline meshes included). Errors point at ``/shapes/<i>/path``."""
    meshes: dict[int, TriangleMesh] = {}
    triangle_total = sum(len(getattr(shape, "indices", ())) for shape in scene.shapes)
    for index, shape in enumerate(scene.shapes):
        if not isinstance(shape, MeshFileShape):
            continue
        where = f"/shapes/{index}/path"
        mesh = read_mesh_file(bundle_dir, shape.path, limits, where)
        triangle_total += mesh.triangles.shape[0]
        _check_counts(0, triangle_total, limits, where)
        meshes[index] = mesh
    return meshes
