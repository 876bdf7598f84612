"""Write the JSON Schema of :class:`schemas.scene.Scene` to ``schemas/scene.schema.json``.

Run ``python -m schemas.export``; ``tests/scenes`` fails when the committed file is stale.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

from schemas.scene import SCHEMA_ID, Scene

SCHEMA_PATH = Path(__file__).with_name("scene.schema.json")


def scene_json_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of a v1 scene, as served at ``GET /v1/schemas/scene``."""
    schema = Scene.model_json_schema(by_alias=True, mode="validation")
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": f"https://hgrender.dev/schemas/{SCHEMA_ID.replace('/', '-')}.json",
        **schema,
    }


def render_schema_text() -> str:
    """The schema file's exact text (sorted keys, two-space indent, trailing newline)."""
    return json.dumps(scene_json_schema(), indent=2, sort_keys=True, ensure_ascii=False) + "\n"


def write_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` via a temporary file in the same directory and ``os.replace``."""
    descriptor, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(descriptor, "w", encoding="utf-8") as handle:
            handle.write(text)
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


def main() -> None:
    write_atomic(SCHEMA_PATH, render_schema_text())
    print(f"wrote {SCHEMA_PATH}")


if __name__ == "__main__":
    main()
