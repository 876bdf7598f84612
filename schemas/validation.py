"""Validation of untrusted scene JSON into :class:`schemas.scene.Scene`, with JSON-pointer errors."""

from __future__ import annotations

import json
import math
from typing import Any

from pydantic import ValidationError

from hgcore.settings import SceneLimits
from schemas.errors import SceneError, SceneProblem, json_pointer
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


MAX_REPORTED_PROBLEMS = 100
"""A response lists at most this many problems (a document of a million bad numbers gets the first 100)."""

#: Film fields with a deployment limit: field → (SceneLimits attribute, environment variable).
FILM_LIMITS: dict[str, tuple[str, str]] = {
    "width": ("max_resolution", "HGRENDER_MAX_RESOLUTION"),
    "height": ("max_resolution", "HGRENDER_MAX_RESOLUTION"),
    "spp": ("max_spp", "HGRENDER_MAX_SPP"),
    "bands": ("max_bands", "HGRENDER_MAX_BANDS"),
}

#: Numeric arrays of meshes: bounded by the vertex and triangle limits, so the walk does not descend.
_NUMERIC_ARRAYS = frozenset({"vertices_m", "indices", "normals", "uvs", "uv_sets", "matrix", "to_world"})
_TABULATED_ARRAYS = ("wavelengths_nm", "values")


def _limit_problem(pointer: str, what: str, value: int, limit: int, variable: str) -> list[SceneProblem]:
    """One problem when ``value`` exceeds ``limit`` (named by its environment variable), else none."""
    if value <= limit:
        return []
    return [{"pointer": pointer, "message": f"{what} {value} exceeds the limit of {limit} ({variable})"}]


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _list(document: dict[str, Any], key: str) -> list[Any]:
    value = document.get(key)
    return value if isinstance(value, list) else []


def _mesh_totals(shapes: list[Any]) -> tuple[int, int]:
    """(vertices, triangles) over the inline meshes of a raw shape list."""
    meshes = [s for s in shapes if isinstance(s, dict) and s.get("type") == "mesh"]
    return sum(len(_list(m, "vertices_m")) for m in meshes), sum(len(_list(m, "indices")) for m in meshes)


def _string_and_table_problems(data: Any, limits: SceneLimits) -> list[SceneProblem]:
    """Strings and object keys longer than ``max_string_chars`` and tabulated spectra longer than
    ``max_spectrum_samples``, anywhere in the document (one iterative walk; the oversized text itself is
    never echoed)."""
    problems: list[SceneProblem] = []
    max_chars, max_samples = limits.max_string_chars, limits.max_spectrum_samples
    stack: list[tuple[Any, list[str | int]]] = [(data, [])]
    while stack and len(problems) < MAX_REPORTED_PROBLEMS:
        node, parts = stack.pop()
        if isinstance(node, str) and len(node) > max_chars:
            problems.append(
                {
                    "pointer": json_pointer(parts),
                    "message": f"string of {len(node)} characters exceeds the limit of {max_chars} "
                    "(HGRENDER_MAX_STRING_CHARS)",
                }
            )
        elif isinstance(node, dict):
            tabulated = node.get("type") == "tabulated"
            for key, value in node.items():
                if len(key) > max_chars:
                    problems.append(
                        {
                            "pointer": json_pointer(parts),
                            "message": f"object key of {len(key)} characters exceeds the limit of "
                            f"{max_chars} (HGRENDER_MAX_STRING_CHARS)",
                        }
                    )
                    continue
                if tabulated and key in _TABULATED_ARRAYS and isinstance(value, list):
                    problems += _limit_problem(
                        json_pointer([*parts, key]),
                        "spectrum samples",
                        len(value),
                        max_samples,
                        "HGRENDER_MAX_SPECTRUM_SAMPLES",
                    )
                    continue
                if key not in _NUMERIC_ARRAYS:
                    stack.append((value, [*parts, key]))
        elif isinstance(node, list):
            stack.extend((item, [*parts, index]) for index, item in enumerate(node))
    return problems


def document_image_pointers(data: dict[str, Any]) -> list[str]:
    """The pointers of the distinct image files a raw scene document names, first mention each: material
    fields that are ``{"type": "image", "path": …}`` and environment emitters' ``path`` (``schemas.textures``
    checks the files themselves). Values of the wrong type are left to the schema."""

    def image_path(node: Any) -> str | None:
        return node.get("path") if isinstance(node, dict) and isinstance(node.get("path"), str) else None

    paths: list[tuple[str, str]] = []
    materials = data.get("materials")
    for material_id, material in (materials if isinstance(materials, dict) else {}).items():
        for key, value in (material if isinstance(material, dict) else {}).items():
            path = image_path(value)
            if path is not None and value.get("type") == "image":
                paths.append((path, json_pointer(["materials", str(material_id), key, "path"])))
    for index, emitter in enumerate(_list(data, "emitters")):
        path = image_path(emitter)
        if path is not None and emitter.get("type") == "environment":
            paths.append((path, json_pointer(["emitters", index, "path"])))
    seen: dict[str, str] = {}
    for path, pointer in paths:
        seen.setdefault(path, pointer)
    return list(seen.values())


def check_document_limits(data: dict[str, Any], limits: SceneLimits) -> list[SceneProblem]:
    """Problems where a raw (not yet validated) scene document exceeds the deployment's collection
    limits: checked before the schema, so that validating or rendering it never costs more than the
    limits allow. Values of the wrong type are left to the schema."""
    materials = data.get("materials")
    shapes, emitters = _list(data, "shapes"), _list(data, "emitters")
    vertices, triangles = _mesh_totals(shapes)
    images = document_image_pointers(data)
    # the first image over the limit is named
    image_pointer = images[limits.max_textures] if len(images) > limits.max_textures else "/materials"
    problems = [
        *_limit_problem(
            "/materials",
            "material count",
            len(materials) if isinstance(materials, dict) else 0,
            limits.max_materials,
            "HGRENDER_MAX_MATERIALS",
        ),
        *_limit_problem(
            "/emitters", "emitter count", len(emitters), limits.max_emitters, "HGRENDER_MAX_EMITTERS"
        ),
        *_limit_problem(
            "/shapes",
            "shape + emitter count",
            len(shapes) + len(emitters),
            limits.max_primitives,
            "HGRENDER_MAX_PRIMITIVES",
        ),
        *_limit_problem(
            "/shapes", "triangle count", triangles, limits.max_triangles, "HGRENDER_MAX_TRIANGLES"
        ),
        *_limit_problem("/shapes", "vertex count", vertices, limits.max_vertices, "HGRENDER_MAX_VERTICES"),
        *_limit_problem(
            image_pointer, "image count", len(images), limits.max_textures, "HGRENDER_MAX_TEXTURES"
        ),
    ]
    return problems or _string_and_table_problems(data, limits)


def check_limits(scene: Scene, limits: SceneLimits) -> list[SceneProblem]:
    """Problems where a validated scene's film exceeds the deployment's limits (defaults included)."""
    film = scene.film
    problems = [
        problem
        for name, (attribute, variable) in FILM_LIMITS.items()
        for problem in _limit_problem(
            f"/film/{name}", name, getattr(film, name), getattr(limits, attribute), variable
        )
    ]
    problems += _limit_problem(
        "/film", "pixel count", film.width * film.height, limits.max_pixels, "HGRENDER_MAX_PIXELS"
    )
    # Procedural shapes' triangles come from their (validated, capped) parameters: counted here, with
    # the inline meshes' again so that the total is what the renderer will hold.
    procedural = [mesh_size(shape) for shape in scene.shapes if isinstance(shape, PROCEDURAL_SHAPE_TYPES)]
    if not procedural:
        return problems
    inline = [shape for shape in scene.shapes if isinstance(shape, MeshShape)]
    vertices = sum(len(mesh.vertices_m) for mesh in inline) + sum(v for v, _ in procedural)
    triangles = sum(len(mesh.indices) for mesh in inline) + sum(t for _, t in procedural)
    return [
        *problems,
        *_limit_problem(
            "/shapes", "triangle count", triangles, limits.max_triangles, "HGRENDER_MAX_TRIANGLES"
        ),
        *_limit_problem("/shapes", "vertex count", vertices, limits.max_vertices, "HGRENDER_MAX_VERTICES"),
    ]


def _in_document(data: Any, pointer: str) -> Any:
    """The value at a simple JSON pointer (no escapes needed for the fields it is used on), or None."""
    node = data
    for part in pointer.split("/")[1:]:
        if isinstance(node, dict):
            node = node.get(part)
        elif isinstance(node, list) and part.isdigit() and int(part) < len(node):
            node = node[int(part)]
        else:
            return None
    return node


def _explain(data: Any, problem: SceneProblem, limits: SceneLimits) -> SceneProblem:
    """Say what is wrong in the deployment's terms: a film value above its configured limit names that
    limit (not the schema's hard cap), and NaN or infinity is called what it is."""
    value = _in_document(data, problem["pointer"])
    if isinstance(value, float) and not math.isfinite(value):
        return {"pointer": problem["pointer"], "message": f"{value} is not a finite number"}
    name = problem["pointer"].removeprefix("/film/")
    if problem["pointer"].startswith("/film/") and name in FILM_LIMITS and _is_number(value):
        attribute, variable = FILM_LIMITS[name]
        limit = getattr(limits, attribute)
        if value > limit:
            return _limit_problem(problem["pointer"], name, value, limit, variable)[0]
    return problem


def _bounded(problems: list[SceneProblem]) -> list[SceneProblem]:
    """At most ``MAX_REPORTED_PROBLEMS`` problems, the last one saying how many were left out."""
    if len(problems) <= MAX_REPORTED_PROBLEMS:
        return problems
    left_out = len(problems) - MAX_REPORTED_PROBLEMS + 1
    return [
        *problems[: MAX_REPORTED_PROBLEMS - 1],
        {"pointer": "", "message": f"and {left_out} more problems"},
    ]


def validate_scene(data: Any, limits: SceneLimits | None = None) -> Scene:
    """Validate a parsed JSON document into a :class:`Scene`; raise :class:`SceneError` with pointers.

    ``limits``: the process's settings. None reads ``SceneLimits()`` from the ``HGRENDER_MAX_*``
    environment variables, for tests and benchmarks only: every production call passes its own
    (``tests/test_layering.py`` checks it), so no process re-reads its environment per scene.
    """
    limits = limits if limits is not None else SceneLimits()
    if not isinstance(data, dict):
        raise SceneError.at("", f"a scene must be a JSON object, got {type(data).__name__}")
    problems = check_document_limits(data, limits)
    if problems:
        raise SceneError(_bounded(problems))
    try:
        scene = Scene.model_validate(data)
    except ValidationError as error:
        problems = [_explain(data, p, limits) for p in problems_from_validation_error(data, error)]
        raise SceneError(_bounded(problems)) from None
    except (ValueError, TypeError, RecursionError) as error:
        # Defensive: anything pydantic itself could not locate still becomes a located SceneError.
        raise SceneError.at("", f"invalid scene: {error}") from None
    problems = check_limits(scene, limits)
    if problems:
        raise SceneError(problems)
    return scene


def load_scene_json(text: str | bytes, limits: SceneLimits | None = None) -> Any:
    """Parse a JSON scene document, enforcing ``limits.max_file_bytes`` before parsing (not validated:
    :func:`validate_scene` does that, once, after any film overrides are written in)."""
    limits = limits if limits is not None else SceneLimits()
    size_bytes = len(text.encode() if isinstance(text, str) else text)
    if size_bytes > limits.max_file_bytes:
        raise SceneError.at(
            "",
            f"scene document of {size_bytes} bytes exceeds the limit of {limits.max_file_bytes} "
            "(HGRENDER_MAX_FILE_BYTES)",
        )
    try:
        return json.loads(text)
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as error:
        raise SceneError.at("", f"not valid JSON: {error}") from None


def validate_scene_json(text: str | bytes, limits: SceneLimits | None = None) -> Scene:
    """Parse and validate a JSON scene document, enforcing ``limits.max_file_bytes`` before parsing."""
    return validate_scene(load_scene_json(text, limits), limits)


def override_film(document: Any, **film: Any) -> Any:
    """The scene document with the film fields in ``film`` that are not None replaced (not validated).

    A document that is not an object, or whose ``film`` is not one, is returned as it is: validating it
    then reports it (at ``""`` or ``/film``) exactly as without overrides."""
    changes = {key: value for key, value in film.items() if value is not None}
    if not changes or not isinstance(document, dict) or not isinstance(document.get("film", {}), dict):
        return document
    return {**document, "film": {**document.get("film", {}), **changes}}


def with_film_overrides(scene: Scene, limits: SceneLimits | None = None, **film: Any) -> Scene:
    """The scene with the film fields in ``film`` that are not None replaced (a request's or a command
    line's ``spp``, ``seed``, ``integrator``, ...), validated again, so that ``limits`` apply to the values
    that will actually be rendered."""
    if all(value is None for value in film.values()):
        return scene
    return validate_scene(override_film(scene.to_json_dict(), **film), limits)
