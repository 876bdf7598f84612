"""Scene descriptions: the v1 scene model, its validation, JSON Schema and USD import/export.

Import the model and validator from here; nothing in this package imports Mitsuba or Dr.Jit.
"""

from schemas.errors import SceneError, SceneProblem
from schemas.limits import SceneLimits
from schemas.scene import SCHEMA_ID, Scene
from schemas.validation import validate_scene, validate_scene_json

__all__ = [
    "SCHEMA_ID",
    "Scene",
    "SceneError",
    "SceneLimits",
    "SceneProblem",
    "validate_scene",
    "validate_scene_json",
]
