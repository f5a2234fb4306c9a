"""The interactive API docs (Swagger UI at ``/docs``) served with their own assets, so they work offline.

FastAPI's default page loads Swagger UI from a public CDN, and shows nothing on a site without internet access.
Here the page points at the files of the npm package ``swagger-ui-dist`` shipped in ``api/static/swagger-ui/``
(see its README there), served under ``/docs/assets/``, as FastAPI's "Self-hosting JavaScript and CSS for docs"
describes. ReDoc is not offered.
"""

from __future__ import annotations

from pathlib import Path

from fastapi import FastAPI
from fastapi.openapi.docs import get_swagger_ui_html
from starlette.requests import Request
from starlette.responses import HTMLResponse
from starlette.staticfiles import StaticFiles

ASSETS_DIR = Path(__file__).parent / "static" / "swagger-ui"
"""The shipped Swagger UI files."""
DOCS_URL = "/docs"
ASSETS_URL = "/docs/assets"


def add_docs(app: FastAPI) -> None:
    """Serve Swagger UI at ``/docs`` over ``app``'s OpenAPI document, with assets from the package.

    ``app`` must be built with ``docs_url=None`` and ``redoc_url=None``. The page and its assets are plain
    Starlette routes, outside the app-wide key check (as FastAPI's own docs page is); the OpenAPI document
    itself is public as before.
    """

    async def swagger_ui(request: Request) -> HTMLResponse:
        root = request.scope.get("root_path", "").rstrip("/")
        return get_swagger_ui_html(
            openapi_url=root + str(app.openapi_url), title=f"{app.title} - Swagger UI",
            swagger_js_url=f"{root}{ASSETS_URL}/swagger-ui-bundle.js",
            swagger_css_url=f"{root}{ASSETS_URL}/swagger-ui.css",
            swagger_favicon_url=f"{root}{ASSETS_URL}/favicon-32x32.png",
            swagger_ui_parameters={"validatorUrl": None})  # no badge fetched from the public validator

    app.mount(ASSETS_URL, StaticFiles(directory=ASSETS_DIR), name="swagger-ui-assets")
    app.add_route(DOCS_URL, swagger_ui, include_in_schema=False)
