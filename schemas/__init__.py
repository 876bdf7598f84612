"""Scene descriptions: the v1 scene model, its validation, JSON Schema and USD import/export.

Import the model and validator from here; nothing in this package imports Mitsuba or Dr.Jit.
"""

from pathlib import Path

from schemas.errors import SceneError, SceneProblem
from schemas.scene import SCHEMA_ID, Scene
from schemas.validation import validate_scene, validate_scene_json, with_film_overrides

EXAMPLES_DIR = Path(__file__).resolve().parent / "examples"
"""The example scenes shipped with the package (``*.json``)."""

__all__ = [
    "EXAMPLES_DIR",
    "SCHEMA_ID",
    "Scene",
    "SceneError",
    "SceneProblem",
    "validate_scene",
    "validate_scene_json",
    "with_film_overrides",
]
