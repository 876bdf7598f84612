"""The browser viewer: ``/`` serves ``web/index.html`` and ``/web/...`` its ES modules and styles.

Plain files, no build step. They carry no data (the page fetches everything from ``/v1`` with the
user's bearer token), so they are served without authentication.
"""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter, FastAPI
from fastapi.responses import FileResponse
from fastapi.staticfiles import StaticFiles

WEB_DIR = Path(__file__).resolve().parents[3] / "web"

router = APIRouter(include_in_schema=False)


@router.get("/")
def index() -> FileResponse:
    return FileResponse(WEB_DIR / "index.html", media_type="text/html", headers={"Cache-Control": "no-cache"})


def install(app: FastAPI) -> None:
    """Serve the viewer at ``/`` (index) and ``/web`` (static files)."""
    if not (WEB_DIR / "index.html").is_file():
        raise ValueError(f"web_dir: {WEB_DIR} has no index.html")
    app.include_router(router)
    app.mount("/web", StaticFiles(directory=WEB_DIR), name="web")
