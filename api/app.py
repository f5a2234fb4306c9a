"""The FastAPI application: build one with :func:`create_app` and serve it with uvicorn."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from importlib.metadata import version

from fastapi import FastAPI, Request, status
from fastapi.responses import JSONResponse

from api.deps import ApiContext
from api.routers import features, health, layers, maps
from shared.bus import Bus
from shared.settings import Settings
from shared.store import MapStore, StoreError, StoreUnavailableError

log = logging.getLogger(__name__)

DESCRIPTION = """\
A live semantic map of the warehouse for a Warehouse Management System.

* **maps**: the maps and their revisions (each stage write is one revision);
* **layers**: grid layers (occupancy, ...) as metadata, PNG or raw values;
* **features**: walls, rack rows, bins, docks, ... as GeoJSON in map-frame metres;
* **health**: database, bus and stage workers.

Every read accepts `?revision=<id>` to see the map as it was then. Errors are JSON with a `detail`.
"""


def create_app(
    *,
    store: MapStore,
    settings: Settings,
    bus: Bus | None = None,
    expected_workers: Sequence[str] = (),
) -> FastAPI:
    """The Aisle REST API over ``store``.

    Parameters
    ----------
    store : MapStore
        The map store to serve, already upgraded to the current schema.
    settings : Settings
        Aisle settings (the zenoh mode is reported by the health check).
    bus : Bus, optional
        A zenoh bus for worker liveliness; without one, liveness comes from stored heartbeats.
    expected_workers : sequence of str
        Stage workers that should be running (e.g. ``shared.settings.STAGES``); the health check
        is degraded while any of them is not alive.
    """
    app = FastAPI(title="Aisle", description=DESCRIPTION, version=version("aisle"), docs_url="/docs")
    app.state.context = ApiContext(store=store, settings=settings, bus=bus,
                                   expected_workers=tuple(expected_workers))
    app.add_exception_handler(StoreUnavailableError, _store_unavailable)
    app.add_exception_handler(StoreError, _store_error)
    app.add_exception_handler(Exception, _unexpected)
    for module in (health, maps, layers, features):
        app.include_router(module.router)
    return app


async def _store_unavailable(request: Request, exc: Exception) -> JSONResponse:
    log.warning("%s %s: %s", request.method, request.url.path, exc)
    return JSONResponse({"detail": str(exc)}, status_code=status.HTTP_503_SERVICE_UNAVAILABLE,
                        headers={"Retry-After": "5"})


async def _store_error(request: Request, exc: Exception) -> JSONResponse:
    log.info("%s %s refused by the store: %s", request.method, request.url.path, exc)
    return JSONResponse({"detail": str(exc)}, status_code=status.HTTP_400_BAD_REQUEST)


async def _unexpected(request: Request, exc: Exception) -> JSONResponse:
    log.error("%s %s failed", request.method, request.url.path, exc_info=exc)
    return JSONResponse({"detail": "internal error; the server log has the details"},
                        status_code=status.HTTP_500_INTERNAL_SERVER_ERROR)
