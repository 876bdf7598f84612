"""Validation of untrusted scene JSON into :class:`schemas.scene.Scene`, with JSON-pointer errors."""

from __future__ import annotations

import json
from typing import Any

from pydantic import ValidationError

from schemas.errors import SceneError, SceneProblem, json_pointer
from schemas.limits import SceneLimits
from schemas.procedural import mesh_size
from schemas.scene import PROCEDURAL_SHAPE_TYPES, MeshShape, Scene


def _pointer_for(data: Any, loc: tuple[str | int, ...], error_type: str) -> str:
    """Map a pydantic error location onto the input document.

    pydantic inserts union tags (``('shapes', 2, 'sphere', 'radius_m')``) into locations; walking the
    input alongside the location keeps only the parts that exist in the document, so the pointer is
    ``/shapes/2/radius_m``. A missing field's name is kept although it is absent from the input.
    """
    parts: list[str | int] = []
    node = data
    for index, part in enumerate(loc):
        is_last = index == len(loc) - 1
        in_dict = isinstance(node, dict) and isinstance(part, str) and part in node
        in_list = isinstance(node, list) and isinstance(part, int) and 0 <= part < len(node)
        if in_dict or in_list:
            parts.append(part)
            node = node[part]
        elif is_last and error_type == "missing":
            parts.append(part)
        # else: a union tag or a synthetic part ('[key]'), not a place in the document
    return json_pointer(parts)


def problems_from_validation_error(data: Any, error: ValidationError) -> list[SceneProblem]:
    """Convert pydantic errors into located problems (reference errors carry their own pointers)."""
    problems: list[SceneProblem] = []
    for item in error.errors(include_url=False):
        context = item.get("ctx") or {}
        if item["type"] == "scene_reference" and "problems" in context:
            problems.extend(context["problems"])
            continue
        pointer = _pointer_for(data, tuple(item["loc"]), item["type"])
        message = item["msg"]
        if item["loc"] and item["loc"][-1] == "[key]":
            message = f"invalid key: {message}"
        message = message.removeprefix("Value error, ")
        problems.append({"pointer": pointer, "message": message})
    return problems


def _limit_problem(pointer: str, what: str, value: int, limit: int, variable: str) -> list[SceneProblem]:
    """One problem when ``value`` exceeds ``limit`` (named by its environment variable), else none."""
    if value <= limit:
        return []
    return [{"pointer": pointer, "message": f"{what} {value} exceeds the limit of {limit} ({variable})"}]


def check_limits(scene: Scene, limits: SceneLimits) -> list[SceneProblem]:
    """Problems where a structurally valid scene exceeds the deployment's resource limits."""
    film = scene.film
    meshes = [shape for shape in scene.shapes if isinstance(shape, MeshShape)]
    procedural = [mesh_size(shape) for shape in scene.shapes if isinstance(shape, PROCEDURAL_SHAPE_TYPES)]
    return [
        *_limit_problem("/film/width", "width", film.width, limits.max_resolution, "HGRENDER_MAX_RESOLUTION"),
        *_limit_problem(
            "/film/height", "height", film.height, limits.max_resolution, "HGRENDER_MAX_RESOLUTION"
        ),
        *_limit_problem(
            "/film", "pixel count", film.width * film.height, limits.max_pixels, "HGRENDER_MAX_PIXELS"
        ),
        *_limit_problem("/film/spp", "spp", film.spp, limits.max_spp, "HGRENDER_MAX_SPP"),
        *_limit_problem("/film/bands", "bands", film.bands, limits.max_bands, "HGRENDER_MAX_BANDS"),
        *_limit_problem(
            "/shapes",
            "shape + emitter count",
            len(scene.shapes) + len(scene.emitters),
            limits.max_primitives,
            "HGRENDER_MAX_PRIMITIVES",
        ),
        *_limit_problem(
            "/shapes",
            "triangle count",
            sum(len(mesh.indices) for mesh in meshes) + sum(triangles for _, triangles in procedural),
            limits.max_triangles,
            "HGRENDER_MAX_TRIANGLES",
        ),
        *_limit_problem(
            "/shapes",
            "vertex count",
            sum(len(mesh.vertices_m) for mesh in meshes) + sum(vertices for vertices, _ in procedural),
            limits.max_vertices,
            "HGRENDER_MAX_VERTICES",
        ),
    ]


def validate_scene(data: Any, limits: SceneLimits | None = None) -> Scene:
    """Validate a parsed JSON document into a :class:`Scene`; raise :class:`SceneError` with pointers.

    ``limits`` defaults to ``SceneLimits()`` (read from ``HGRENDER_MAX_*`` environment variables).
    """
    limits = limits if limits is not None else SceneLimits()
    if not isinstance(data, dict):
        raise SceneError.at("", f"a scene must be a JSON object, got {type(data).__name__}")
    try:
        scene = Scene.model_validate(data)
    except ValidationError as error:
        raise SceneError(problems_from_validation_error(data, error)) from None
    except (ValueError, TypeError, RecursionError) as error:
        # Defensive: anything pydantic itself could not locate still becomes a located SceneError.
        raise SceneError.at("", f"invalid scene: {error}") from None
    problems = check_limits(scene, limits)
    if problems:
        raise SceneError(problems)
    return scene


def validate_scene_json(text: str | bytes, limits: SceneLimits | None = None) -> Scene:
    """Parse and validate a JSON scene document, enforcing ``limits.max_file_bytes`` before parsing."""
    limits = limits if limits is not None else SceneLimits()
    size_bytes = len(text.encode() if isinstance(text, str) else text)
    if size_bytes > limits.max_file_bytes:
        raise SceneError.at(
            "",
            f"scene document of {size_bytes} bytes exceeds the limit of {limits.max_file_bytes} "
            "(HGRENDER_MAX_FILE_BYTES)",
        )
    try:
        data = json.loads(text)
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as error:
        raise SceneError.at("", f"not valid JSON: {error}") from None
    return validate_scene(data, limits)
