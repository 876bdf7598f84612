"""A job request's scene (``service.submissions``): the request's film overrides are written into a JSON
document that is then validated once, a USD stage is overridden after its import, and what comes out is
the typed ``Scene`` the job is created from. No service runs here."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from hgcore.settings import SceneLimits
from schemas import Scene, SceneError, validate_scene
from schemas.usd_export import scene_to_usd
from service import submissions
from service.models import JobOptions
from tests.support.scenes import tiny_scene

LIMITS = SceneLimits(max_spp=1000)
OVERRIDES = JobOptions(spp=3, seed=7, integrator="rlt")


@pytest.fixture
def validations(monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    """The documents ``service.submissions`` validates, in order."""
    seen: list[Any] = []

    def counting(data: Any, limits: SceneLimits | None = None) -> Scene:
        seen.append(data)
        return validate_scene(data, limits)

    monkeypatch.setattr(submissions, "validate_scene", counting)
    return seen


def problem(call: Any) -> dict[str, str]:
    with pytest.raises(SceneError) as caught:
        call()
    return caught.value.problems[0]


def test_a_json_scene_is_validated_once_with_the_overrides_written_in(validations: list[Any]) -> None:
    document = tiny_scene(spp=4)
    scene = submissions.scene_from_json(document, OVERRIDES, LIMITS)
    assert isinstance(scene, Scene)
    assert (scene.film.spp, scene.film.seed, scene.film.integrator) == (3, 7, "rlt")
    assert len(validations) == 1 and validations[0]["film"]["spp"] == 3
    assert document["film"]["spp"] == 4  # the request's document is not changed
    plain = submissions.scene_from_json(document, JobOptions(), LIMITS)
    assert plain == validate_scene(document, LIMITS) and len(validations) == 2


def test_an_uploaded_json_scene_is_validated_once_with_the_overrides_written_in(
    validations: list[Any],
) -> None:
    content = json.dumps(tiny_scene(spp=4)).encode()
    scene, files = submissions.scene_from_upload("box.json", content, OVERRIDES, LIMITS)
    assert (scene.film.spp, scene.film.seed, scene.film.integrator, files) == (3, 7, "rlt", {})
    assert len(validations) == 1
    too_large = SceneLimits(max_file_bytes=len(content) - 1)
    assert (
        "HGRENDER_MAX_FILE_BYTES"
        in problem(lambda: submissions.scene_from_upload("box.json", content, OVERRIDES, too_large))[
            "message"
        ]
    )


def test_an_override_is_checked_against_the_limits_at_the_films_pointer() -> None:
    found = problem(lambda: submissions.scene_from_json(tiny_scene(), JobOptions(spp=1001), LIMITS))
    assert found["pointer"] == "/film/spp"
    assert found["message"] == "spp 1001 exceeds the limit of 1000 (HGRENDER_MAX_SPP)"


@pytest.mark.parametrize(
    ("document", "pointer"),
    [([1, 2], ""), ({**tiny_scene(), "film": [64]}, "/film"), ({**tiny_scene(), "film": None}, "/film")],
)
def test_a_malformed_document_is_reported_as_without_overrides(document: Any, pointer: str) -> None:
    with_overrides = problem(lambda: submissions.scene_from_json(document, OVERRIDES, LIMITS))
    without = problem(lambda: validate_scene(document, LIMITS))
    assert with_overrides == without and with_overrides["pointer"] == pointer


def test_a_usd_stage_is_overridden_after_its_import(tmp_path: Path) -> None:
    usd = scene_to_usd(validate_scene(tiny_scene(spp=4), LIMITS), tmp_path / "scene.usda")
    scene, files = submissions.scene_from_upload("scene.usda", usd.read_bytes(), OVERRIDES, LIMITS)
    assert isinstance(scene, Scene)
    assert (scene.film.spp, scene.film.seed, scene.film.integrator) == (3, 7, "rlt")
    assert list(files) == ["scene.usda"]
    found = problem(
        lambda: submissions.scene_from_upload("scene.usda", usd.read_bytes(), JobOptions(spp=1001), LIMITS)
    )
    assert found["pointer"] == "/film/spp"
