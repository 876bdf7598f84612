"""``GET /v1/schemas/scene``: the JSON Schema of scene documents (``schemas/scene.schema.json``)."""

from __future__ import annotations

import json
from importlib import resources
from typing import Any

from fastapi import APIRouter

router = APIRouter(prefix="/v1/schemas", tags=["schemas"])


@router.get("/scene", summary="Scene JSON Schema (hgrender/scene/v1)")
def scene_schema() -> dict[str, Any]:
    return json.loads(resources.files("schemas").joinpath("scene.schema.json").read_text())
