"""The example scenes the viewer's submit form offers (``schemas/examples``): the gallery's first, in its
order, with their paper figure, most telling view and thumbnail; then the others by name."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from hgcore.store.base import ArtifactNotFoundError
from schemas import EXAMPLES_DIR
from schemas.gallery import GALLERY_BY_NAME, THUMBNAILS_DIR
from service.models import ExampleScene


def example_scenes() -> list[ExampleScene]:
    """Every example scene, the gallery's first (in the gallery's order), then the others by name."""
    examples = []
    for path in sorted(EXAMPLES_DIR.glob("*.json")):
        title = json.loads(path.read_text()).get("name", path.stem)
        entry = GALLERY_BY_NAME.get(path.stem)
        if entry is None:
            examples.append(ExampleScene(name=path.name, title=title))
            continue
        has_thumbnail = (THUMBNAILS_DIR / f"{path.stem}.png").is_file()
        examples.append(
            ExampleScene(
                name=path.name,
                title=title,
                figure=entry.figure,
                view=entry.viewer_view,
                thumbnail=f"/v1/examples/{path.stem}/thumbnail.png" if has_thumbnail else None,
            )
        )
    order = list(GALLERY_BY_NAME)
    return sorted(examples, key=lambda e: (order.index(e.name[:-5]) if e.figure else len(order), e.name))


def example_document(name: str) -> dict[str, Any]:
    """The scene document ``<name>`` (``cornell_box.json``); ArtifactNotFoundError (404) if none."""
    path = EXAMPLES_DIR / name
    if not path.is_file():
        raise ArtifactNotFoundError(name)
    return json.loads(path.read_text())


def thumbnail_png(stem: str) -> bytes:
    """The PNG thumbnail of gallery scene ``stem``; ArtifactNotFoundError (404) if none."""
    path: Path = THUMBNAILS_DIR / f"{stem}.png"
    if stem not in GALLERY_BY_NAME or not path.is_file():
        raise ArtifactNotFoundError(f"{stem}/thumbnail.png")
    return path.read_bytes()
