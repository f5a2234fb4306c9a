"""The map viewer: one page and its static files (script, style, the vendored Leaflet), served from the package.

Nothing is fetched from elsewhere at run time. The page is open to everyone, as ``/v1/health`` is: it holds no
map data, and asks the reader for an API key when the API's map reads need one (see :mod:`api.access`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

from fastapi import APIRouter, HTTPException, status
from fastapi import Path as PathParam
from fastapi.responses import FileResponse

router = APIRouter(tags=["viewer"], include_in_schema=False)

ROOT = Path(__file__).resolve().parents[1] / "viewer"
"""The viewer's files: ``index.html``, ``viewer.js``, ``viewer.css`` and ``leaflet/`` (Leaflet 1.9.4, BSD-2)."""
ASSETS = {path.relative_to(ROOT).as_posix(): path for path in sorted(ROOT.rglob("*")) if path.is_file()}
"""Every file served, by its path under ``/viewer/``; nothing else under that prefix is (no path tricks)."""
PAGE_PATHS = ("/", "/viewer")
ASSET_ROUTE = "/viewer/{asset:path}"
_MEDIA_TYPES = {".js": "text/javascript", ".css": "text/css", ".html": "text/html", ".png": "image/png",
                ".svg": "image/svg+xml"}


@router.get("/")
@router.get("/viewer")
def page() -> FileResponse:
    """The viewer page."""
    return FileResponse(ROOT / "index.html", media_type="text/html", headers={"Cache-Control": "no-cache"})


@router.get(ASSET_ROUTE)
def asset(asset: Annotated[str, PathParam(max_length=200)]) -> FileResponse:
    """One of the viewer's files (:data:`ASSETS`); 404 for anything else."""
    path = ASSETS.get(asset)
    if path is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"the viewer has no file {asset!r}")
    return FileResponse(path, media_type=_MEDIA_TYPES.get(path.suffix, "application/octet-stream"),
                        headers={"Cache-Control": "no-cache"})
