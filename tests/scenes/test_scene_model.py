"""The v1 scene model: examples, JSON Schema freshness, located errors, limits, fuzzed malformed input."""

from __future__ import annotations

import copy
import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hgcore.optics.array_ops import NUMPY
from hgcore.optics.thin_film import film_shear
from hgcore.settings import SceneLimits
from schemas import EXAMPLES_DIR, SceneError, validate_scene, validate_scene_json
from schemas.export import SCHEMA_PATH, render_schema_text, scene_json_schema
from schemas.scene import GratingMaterial, PerspectiveCamera, Transform

EXAMPLE_PATHS = sorted(EXAMPLES_DIR.glob("*.json"))
EXPECTED_EXAMPLES = {
    "cornell_box.json",
    "thin_film_sphere_light.json",
    "thin_film_cylinder_light.json",
    "dvd_small_source.json",
    "dvd_large_source.json",
    "rough_metals.json",
    "mirror_coherence.json",
}
#: The gallery scenes (worker/gallery.py, docs/gallery.md): their own film shows the phenomenon.
GALLERY_EXAMPLES = {
    "fig1f_dvd_small_source.json",
    "fig1f_dvd_large_source.json",
    "fig7_thin_film_sphere_light.json",
    "fig7_thin_film_cylinder_light.json",
    "fig8_mirror_coherence.json",
    "fig9_modes_1.json",
    "fig9_modes_16.json",
    "fig1de_rough_metals.json",
}


def minimal_scene() -> dict[str, Any]:
    return {
        "schema": "hgrender/scene/v1",
        "camera": {"origin_m": [0, 0, 5], "target_m": [0, 0, 0]},
        "materials": {"white": {"type": "diffuse", "reflectance": 0.5}},
        "shapes": [{"type": "sphere", "material": "white", "center_m": [0, 0, 0], "radius_m": 1.0}],
        "emitters": [
            {
                "type": "sphere",
                "center_m": [0, 3, 0],
                "radius_m": 0.1,
                "spectrum": {"type": "d65"},
                "power_w": 1.0,
            }
        ],
    }


def problems_of(data: Any, limits: SceneLimits | None = None) -> list[dict[str, str]]:
    with pytest.raises(SceneError) as caught:
        validate_scene(data, limits)
    return caught.value.problems


def test_all_required_examples_exist() -> None:
    assert {path.name for path in EXAMPLE_PATHS} >= EXPECTED_EXAMPLES | GALLERY_EXAMPLES


def test_gallery_table_lists_every_gallery_example() -> None:
    from worker.gallery import GALLERY

    assert {f"{entry.name}.json" for entry in GALLERY} == GALLERY_EXAMPLES


@pytest.mark.parametrize("path", EXAMPLE_PATHS, ids=lambda path: path.name)
def test_example_validates_and_round_trips_through_json(path: Path) -> None:
    document = json.loads(path.read_text())
    scene = validate_scene(document)
    if path.name in GALLERY_EXAMPLES:
        # A preview in which the phenomenon is visible: at least 256² (docs/gallery.md).
        assert min(scene.film.width, scene.film.height) >= 256
    else:
        # The test fixtures render quickly in tests: 64x64 film and 16 spp.
        assert (scene.film.width, scene.film.height, scene.film.spp) == (64, 64, 16)
    assert validate_scene(json.loads(json.dumps(scene.to_json_dict()))) == scene
    # The published JSON Schema accepts every example too (it is what HTTP clients validate against).
    jsonschema.validate(document, scene_json_schema())


def test_thin_film_examples_differ_only_in_the_emitter_shape() -> None:
    sphere_scene = validate_scene(json.loads((EXAMPLES_DIR / "thin_film_sphere_light.json").read_text()))
    cylinder_scene = validate_scene(json.loads((EXAMPLES_DIR / "thin_film_cylinder_light.json").read_text()))
    assert sphere_scene.shapes == cylinder_scene.shapes
    assert sphere_scene.materials == cylinder_scene.materials
    (sphere_light,) = sphere_scene.emitters
    (cylinder_light,) = cylinder_scene.emitters
    assert sphere_light.spectrum == cylinder_light.spectrum
    assert sphere_light.power_w == cylinder_light.power_w
    # Fig. 7 geometry: a 0.6 cm sphere about 60 cm away; a 20 cm x 0.1 cm cylinder at the same place.
    assert math.dist(sphere_light.center_m, [0, 0, 0]) == pytest.approx(0.6, rel=1e-9)
    assert sphere_light.radius_m == 0.006
    assert math.dist(cylinder_light.p0_m, cylinder_light.p1_m) == pytest.approx(0.2, rel=1e-12)
    assert cylinder_light.radius_m == 0.001


def test_fig7_gallery_pair_differs_only_in_the_emitter_shape() -> None:
    """Fig. 7: the same object under a sphere and a cylinder source of identical spectrum and power."""
    sphere_scene, cylinder_scene = (
        validate_scene(json.loads((EXAMPLES_DIR / f"fig7_thin_film_{kind}_light.json").read_text()))
        for kind in ("sphere", "cylinder")
    )
    assert sphere_scene.shapes == cylinder_scene.shapes
    assert sphere_scene.materials == cylinder_scene.materials
    assert sphere_scene.camera == cylinder_scene.camera
    (sphere_light,), (cylinder_light,) = sphere_scene.emitters, cylinder_scene.emitters
    assert sphere_light.spectrum == cylinder_light.spectrum
    assert sphere_light.power_w == cylinder_light.power_w
    centre = [(a + b) / 2 for a, b in zip(cylinder_light.p0_m, cylinder_light.p1_m, strict=True)]
    assert centre == pytest.approx(sphere_light.center_m)
    assert (sphere_light.radius_m, cylinder_light.radius_m) == (0.006, 0.001)
    # Eq. 18's fringes need the incident field coherent across the film's shear, 2τ·tanθ_t·cosθ_i
    # transverse (thin_film.film_shear; 0.13 µm at 45° for the gallery's 0.30 µm, n 2.4 film): the sphere's
    # ℓ = 2r/(ka) must exceed it and the tube's short-axis ℓ₂ = r√12/(kL) fall below it (r: source to shell).
    film = sphere_scene.materials["coated_silver"]
    k_per_m = 2.0 * math.pi / 550e-9
    incident = np.array([math.sqrt(0.5), 0.0, -math.sqrt(0.5)])  # 45° onto the normal +z
    shear = np.array(
        film_shear((0.0, 0.0, 1.0), tuple(incident), film.film_thickness_um * 1e-6, film.film_ior, 1.0, NUMPY)
    )
    shear_m = float(np.linalg.norm(shear - (shear @ incident) * incident))
    r_m = math.dist(sphere_light.center_m, sphere_scene.shapes[0].center_m)
    length_m = math.dist(cylinder_light.p0_m, cylinder_light.p1_m)
    assert 2.0 * r_m / (k_per_m * sphere_light.radius_m) > 10.0 * shear_m
    assert r_m * math.sqrt(12.0) / (k_per_m * length_m) < shear_m


def test_committed_json_schema_is_current() -> None:
    assert SCHEMA_PATH.read_text() == render_schema_text(), "stale: run `python -m schemas.export`"


def test_errors_name_json_pointers_through_unions() -> None:
    data = minimal_scene()
    data["shapes"][0]["radius_m"] = -1.0
    data["materials"]["white"]["reflectance"] = {
        "type": "tabulated",
        "wavelengths_nm": [500, 400],
        "values": [1, 1],
    }
    data["emitters"][0]["radiance_scale"] = 2.0
    data["camera"]["fov_deg"] = 180.0
    pointers = {problem["pointer"] for problem in problems_of(data)}
    assert pointers == {
        "/shapes/0/radius_m",
        "/materials/white/reflectance/wavelengths_nm",
        "/emitters/0",
        "/camera/fov_deg",
    }


def test_pointer_escapes_and_missing_fields() -> None:
    data = minimal_scene()
    data["materials"]["a/b~c"] = {"type": "diffuse"}
    del data["shapes"][0]["radius_m"]
    problems = problems_of(data)
    assert {p["pointer"] for p in problems} == {"/materials/a~1b~0c", "/shapes/0/radius_m"}
    assert str(SceneError(problems)).startswith("/")


def test_unknown_material_reference_and_extra_fields_are_located() -> None:
    data = minimal_scene()
    data["shapes"][0]["material"] = "nope"
    assert problems_of(data) == [{"pointer": "/shapes/0/material", "message": "unknown material 'nope'"}]
    data = minimal_scene()
    data["shapes"][0]["colour"] = "red"
    assert [p["pointer"] for p in problems_of(data)] == ["/shapes/0/colour"]


def test_wavelength_sampling_defaults_to_auto_and_is_validated() -> None:
    assert validate_scene(minimal_scene()).film.wavelength_sampling == "auto"
    for mode in ("uniform", "importance"):
        chosen = minimal_scene() | {"film": {"wavelength_sampling": mode}}
        assert validate_scene(chosen).film.wavelength_sampling == mode
    problems = problems_of(minimal_scene() | {"film": {"wavelength_sampling": "hero"}})
    assert [p["pointer"] for p in problems] == ["/film/wavelength_sampling"]


def test_strings_are_not_coerced_to_numbers_and_nan_is_rejected() -> None:
    data = minimal_scene()
    data["shapes"][0]["radius_m"] = "1.0"
    assert [p["pointer"] for p in problems_of(data)] == ["/shapes/0/radius_m"]
    with pytest.raises(SceneError, match=r"^/film/spp"):
        validate_scene_json(json.dumps(minimal_scene() | {"film": {"spp": 1.5}}))
    with pytest.raises(SceneError, match=r"^/shapes/0/center_m/1"):
        validate_scene_json(
            json.dumps(minimal_scene()).replace('[0, 0, 0], "radius_m"', '[0, NaN, 0], "radius_m"')
        )


def test_limits_apply_and_read_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    data = minimal_scene()
    data["film"] = {"width": 300, "spp": 20}
    monkeypatch.setenv("HGRENDER_MAX_RESOLUTION", "256")
    monkeypatch.setenv("HGRENDER_MAX_SPP", "10")
    problems = problems_of(data)
    assert {p["pointer"] for p in problems} == {"/film/width", "/film/spp"}
    assert "HGRENDER_MAX_RESOLUTION" in problems[0]["message"]
    monkeypatch.delenv("HGRENDER_MAX_RESOLUTION")
    monkeypatch.delenv("HGRENDER_MAX_SPP")
    assert validate_scene(data).film.width == 300
    with pytest.raises(SceneError, match="HGRENDER_MAX_TRIANGLES"):
        mesh = {
            "type": "mesh",
            "material": "white",
            "vertices_m": [[0, 0, 0], [1, 0, 0], [0, 1, 0]],
            "indices": [[0, 1, 2]] * 3,
        }
        validate_scene(minimal_scene() | {"shapes": [mesh]}, SceneLimits(max_triangles=2))
    with pytest.raises(SceneError, match="HGRENDER_MAX_FILE_BYTES"):
        validate_scene_json(json.dumps(minimal_scene()), SceneLimits(max_file_bytes=100))


def test_grating_presets_fill_pitch_and_depth() -> None:
    dvd = GratingMaterial.model_validate({"type": "grating", "preset": "dvd"})
    assert (dvd.pitch_um, dvd.pit_depth_nm) == (0.74, 105.0)
    cd = GratingMaterial.model_validate({"type": "grating", "preset": "cd", "pitch_um": 1.5})
    assert cd.pitch_um == 1.5
    data = minimal_scene()
    data["materials"]["g"] = {"type": "grating"}
    assert problems_of(data) == [
        {"pointer": "/materials/g", "message": "pitch_um is required when no preset is given"}
    ]


def test_camera_fov_from_lens_and_default() -> None:
    lens = PerspectiveCamera.model_validate(
        {"origin_m": [0, 0, 1], "target_m": [0, 0, 0], "focal_length_mm": 50.0, "sensor_width_mm": 36.0}
    )
    # 2·atan(18/50) = 39.5978°, the classic full-frame 50 mm horizontal field of view.
    assert lens.horizontal_fov_deg() == pytest.approx(39.597752709, abs=1e-8)
    assert (
        PerspectiveCamera.model_validate({"origin_m": [0, 0, 1], "target_m": [0, 0, 0]}).horizontal_fov_deg()
        == 40.0
    )
    data = minimal_scene()
    data["camera"]["up"] = [0, 0, 2]
    assert problems_of(data)[0]["pointer"] == "/camera"


def test_thin_lens_focus_defaults_to_the_target_and_is_validated() -> None:
    """A look-at thin lens focuses on the target unless told; one placed by ``to_world`` must be told; a
    negative aperture is refused; 0 (the default) is a pinhole."""
    camera = PerspectiveCamera.model_validate({"origin_m": [0, 3, 4], "target_m": [0, 0, 0]})
    assert (camera.aperture_radius_m, camera.focus_distance()) == (0.0, 5.0)
    lens = PerspectiveCamera.model_validate(
        {"origin_m": [0, 3, 4], "target_m": [0, 0, 0], "aperture_radius_m": 0.01, "focus_distance_m": 2.0}
    )
    assert lens.focus_distance() == 2.0
    data = minimal_scene()
    data["camera"] = {
        "to_world": [[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, -1, 5], [0, 0, 0, 1]],
        "aperture_radius_m": 0.01,
    }
    problem = problems_of(data)[0]
    assert problem["pointer"] == "/camera" and "focus_distance_m" in problem["message"]
    data = minimal_scene()
    data["camera"]["aperture_radius_m"] = -0.01
    assert problems_of(data)[0]["pointer"] == "/camera/aperture_radius_m"


@given(
    axis=st.lists(st.floats(-1, 1), min_size=3, max_size=3).filter(
        lambda a: math.fsum(c * c for c in a) > 1e-3
    ),
    angle_deg=st.floats(-360, 360),
    scale=st.floats(0.1, 10),
)
def test_trs_matrix_is_a_scaled_rotation_about_the_axis(
    axis: list[float], angle_deg: float, scale: float
) -> None:
    matrix = Transform(
        translate_m=[1.0, 2.0, 3.0], rotate_axis=axis, rotate_deg=angle_deg, scale=scale
    ).to_matrix()
    linear = [row[:3] for row in matrix[:3]]
    # The axis is an eigenvector with eigenvalue `scale`; columns are orthogonal with length `scale`.
    mapped = [math.fsum(linear[r][c] * axis[c] for c in range(3)) for r in range(3)]
    assert mapped == pytest.approx([scale * a for a in axis], abs=1e-9 * scale)
    for i in range(3):
        for j in range(3):
            dot = math.fsum(linear[r][i] * linear[r][j] for r in range(3))
            assert dot == pytest.approx(scale * scale if i == j else 0.0, abs=1e-9 * scale * scale)
    # Trace of a rotation is 1 + 2 cos θ.
    trace = sum(linear[i][i] for i in range(3)) / scale
    assert trace == pytest.approx(1 + 2 * math.cos(math.radians(angle_deg)), abs=1e-9)
    assert [row[3] for row in matrix[:3]] == [1.0, 2.0, 3.0]


JSON_LEAVES = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(2**70), 2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=8),
)
JSON_VALUES = st.recursive(
    JSON_LEAVES,
    lambda children: (
        st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=6), children, max_size=4)
    ),
    max_leaves=20,
)


def _all_paths(node: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    paths = [prefix]
    if isinstance(node, dict):
        for key, value in node.items():
            paths += _all_paths(value, (*prefix, key))
    elif isinstance(node, list):
        for index, value in enumerate(node):
            paths += _all_paths(value, (*prefix, index))
    return paths


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_malformed_json_always_gives_located_scene_errors(data: st.DataObject) -> None:
    """Replace, delete or wrap one node of a valid example: the result is a Scene or a located SceneError."""
    base = json.loads(data.draw(st.sampled_from(EXAMPLE_PATHS)).read_text())
    document = copy.deepcopy(base)
    path = data.draw(st.sampled_from(_all_paths(document)[1:]))
    parent = document
    for part in path[:-1]:
        parent = parent[part]
    action = data.draw(st.sampled_from(["replace", "delete", "wrap"]))
    if action == "replace":
        parent[path[-1]] = data.draw(JSON_VALUES)
    elif action == "delete":
        del parent[path[-1]]
    else:
        parent[path[-1]] = [parent[path[-1]]]
    try:
        validate_scene(document)
    except SceneError as error:
        assert error.problems
        for problem in error.problems:
            assert problem["pointer"] == "" or problem["pointer"].startswith("/")
            assert problem["message"]
        # The pointer leads into the document (up to a missing leaf), so users can find the problem.
        first = error.problems[0]["pointer"]
        node: Any = document
        for token in first.split("/")[1:-1]:
            token = token.replace("~1", "/").replace("~0", "~")
            node = node[int(token)] if isinstance(node, list) else node[token]


@settings(max_examples=100, deadline=None)
@given(document=JSON_VALUES)
def test_arbitrary_json_values_never_escape_as_other_exceptions(document: Any) -> None:
    try:
        validate_scene(document)
    except SceneError as error:
        assert error.problems


def test_schemas_package_does_not_import_mitsuba_or_drjit() -> None:
    """service/ imports schemas/, and service/ must never load Mitsuba or Dr.Jit (even transitively)."""
    code = (
        "import importlib, pkgutil, sys, schemas; "
        "[importlib.import_module(m.name) for m in pkgutil.walk_packages(schemas.__path__, 'schemas.')]; "
        "bad = [m for m in sys.modules if m.split('.')[0] in ('mitsuba', 'drjit')]; "
        "assert not bad, bad"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)


def absorbing_film_scene(substrate: dict, extinction: Any) -> dict:
    scene = minimal_scene()
    scene["materials"]["coated"] = {
        "type": "thin_film",
        "film_thickness_um": 0.12,
        "film_ior": 2.7,
        "film_extinction": extinction,
        "substrate": substrate,
    }
    scene["shapes"][0]["material"] = "coated"
    return scene


def test_film_extinction_is_validated_and_named() -> None:
    """κ_f ∈ [0, 10], and an absorbing film only on a conductor (T = 1 − R needs a lossless film)."""
    coated = validate_scene(absorbing_film_scene({"conductor": "Ag"}, 0.4)).materials["coated"]
    assert coated.film_extinction == 0.4
    assert validate_scene(absorbing_film_scene({"ior": 1.5}, 0.0)).materials["coated"].film_extinction == 0.0
    for extinction in (-0.1, 10.5, "tarnish"):
        (problem,) = problems_of(absorbing_film_scene({"conductor": "Ag"}, extinction))
        assert problem["pointer"] == "/materials/coated/film_extinction", problem
    (problem,) = problems_of(absorbing_film_scene({"ior": 1.5}, 0.4))
    assert "film_extinction" in problem["message"] and "conductor substrate" in problem["message"], problem
