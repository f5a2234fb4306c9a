"""The FastAPI application: build one with :func:`create_app` and serve it with uvicorn."""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator, Sequence
from contextlib import asynccontextmanager
from importlib.metadata import version

from fastapi import Depends, FastAPI, Request, status
from fastapi.exceptions import RequestValidationError
from fastapi.middleware.cors import CORSMiddleware
from fastapi.responses import JSONResponse

from api.access import API_KEY_HEADER, AccessPolicy
from api.announce import Announcer
from api.answers import MetricJSONResponse
from api.bodylimit import BodyLimit
from api.conditional import ConditionalReads
from api.deps import ApiContext, enforce_policy
from api.docpages import add_docs
from api.errors import ApiConfigError
from api.fastpath import LiveReads
from api.invalid import invalid_request
from api.routers import (
    bins,
    blocks,
    events,
    exports,
    features,
    health,
    history,
    keys,
    layers,
    layout,
    maps,
    places,
    robots,
    routes,
    semantics,
    stock,
    topology,
    viewer,
    wms,
)
from api.streams import EventStreams
from atlas.cache import RevisionCache
from atlas.live import STALENESS_S, LiveMaps
from shared.bus import Bus
from shared.settings import Settings
from shared.store import MapStore, StoreError, StoreUnavailableError
from shared.vocabulary import REVISION_HEADER

log = logging.getLogger(__name__)

DESCRIPTION = """\
A live semantic map of the warehouse for a Warehouse Management System.

* **maps**: the maps, their revisions and diffs between revisions (each write is one revision);
* **layers**: grid layers (occupancy, place labels, semantic labels, ...) as metadata, PNG or raw values;
* **features** and **layout**: walls, corridors and aisles, junctions, rack rows, bins, docks, ... as GeoJSON
  in map-frame metres, and the whole layout as a PNG or SVG picture with a legend;
* **bins**: storage bins by WMS id, with aisle, bay, level, footprint, opening, access pose, corridor and nearest
  junction; the WMS's own bin list imported and reconciled;
* **topology** and **routes**: the region graph, blocked regions and connections, drivable routes between bins,
  places and points;
* **places**: docks, gates and chargers set by operators;
* **robots**: each robot's latest pose and its track over the last minute;
* **semantics**: what is at a point, and the human label table of the place categories;
* **exports**: GeoJSON, ROS map_server, VDMA LIF 1.0, Open-RMF nav graph;
* **events**: each new revision as a Server-Sent Event, resumable with `Last-Event-ID`;
* **keys**: API keys (admin only);
* **health**: database, bus and stage workers.

The map viewer, a web page over these same reads, is at `/` (and `/viewer`).

Every read accepts `?revision=<id>` to see the map as it was then, and names the revision it covers in the
`X-Aisle-Revision-Id` header (lists, layout and topology in their body too). Lists page with
`?cursor=<next_cursor>`: every page is read at the revision of the first, however many revisions arrive
meanwhile. Errors are JSON with a `detail`; a request body over the server's limit (32 MiB by default) is a 413.
Positions are metres in the map frame (x, y; not WGS84), rounded to the millimetre; angles are radians from the map
frame's x axis, to 4 decimals; each numeric field's schema names its unit.
Live feature and bin reads (without `?revision=`) come from memory and may be up to 0.2 s (by default) behind
the newest revision; a client always reads the revisions it wrote itself.

Send an API key as `X-API-Key: <secret>` or `Authorization: Bearer <secret>`. Anything that changes
something needs a `write` key (keys: `admin`); reads need a `read` key when the server requires keys
for reads. Each key (or client address, without one) has a rate limit; over it, 429 with `Retry-After`.
"""


def create_app(
    *,
    store: MapStore,
    settings: Settings,
    bus: Bus | None = None,
    expected_workers: Sequence[str] = (),
    require_keys_for_reads: bool = False,
    rate_limit_per_s: float | None = 100.0,
    rate_limit_burst: int = 200,
    cors_origins: Sequence[str] = (),
    event_poll_s: float = 1.0,
    event_heartbeat_s: float = 15.0,
    live_staleness_s: float = STALENESS_S,
    key_recheck_s: float = 1.0,
    gzip_min_bytes: int = 65536,
) -> FastAPI:
    """The Aisle REST API over ``store``.

    Parameters
    ----------
    store : MapStore
        The map store to serve, already upgraded to the current schema.
    settings : Settings
        Aisle settings (the zenoh mode is reported by the health check; request bodies over
        ``api_max_body_bytes`` are refused with a 413).
    bus : Bus, optional
        A zenoh bus for worker liveliness; without one, liveness comes from stored heartbeats.
    expected_workers : sequence of str
        Stage workers that should be running (e.g. ``shared.settings.STAGES``); the health check
        is degraded while any of them is not alive.
    require_keys_for_reads : bool
        Whether reads need a ``read`` key too; writes always need a ``write`` key. Off suits the
        embedded stack on localhost; turn it on wherever the API is reachable from a network.
    rate_limit_per_s : float or None
        Requests per second per API key (per client address without one); None: unlimited.
    rate_limit_burst : int
        Requests a caller may make at once after a quiet spell.
    cors_origins : sequence of str
        Browser origins allowed to call the API (``https://wms.example.com``, or ``*``); none by default.
    event_poll_s, event_heartbeat_s : float
        How often event streams look for new revisions, and how long they stay silent before a heartbeat.
    live_staleness_s : float
        How far behind the store live feature and bin reads may be, seconds (0: each one looks at the store).
    key_recheck_s : float
        How long a verified API key is trusted for reads before its row is read again (a revoked key stops
        reading within this time; writes always read it), seconds.
    gzip_min_bytes : int
        Successful GET answers at least this long go gzip-compressed to clients that accept it (event streams,
        PNGs and zips never); every successful GET answer carries an ETag (:mod:`api.conditional`).
    """
    _check_origins(cors_origins)
    cache = RevisionCache()
    live = LiveMaps(store, cache, staleness_s=live_staleness_s)

    @asynccontextmanager
    async def lifespan(_app: FastAPI) -> AsyncIterator[None]:
        if bus is not None:
            live.follow(bus)
        try:
            live.warm(store.maps())  # a viewer's or WMS's first read after a restart then finds the map in memory
        except StoreUnavailableError as err:
            log.warning("live state not built ahead: %s", err)
        try:
            yield
        finally:
            live.close()

    app = FastAPI(title="Aisle", description=DESCRIPTION, version=version("aisle"), docs_url=None, redoc_url=None,
                  dependencies=[Depends(enforce_policy)], lifespan=lifespan, default_response_class=MetricJSONResponse)
    add_docs(app)
    access = AccessPolicy(require_keys_for_reads=require_keys_for_reads, rate_limit_per_s=rate_limit_per_s,
                          rate_limit_burst=rate_limit_burst, recheck_s=key_recheck_s)
    context = app.state.context = ApiContext(
        store=store, settings=settings, bus=bus, expected_workers=tuple(expected_workers), access=access,
        events=EventStreams(poll_s=event_poll_s, heartbeat_s=event_heartbeat_s),
        announcer=Announcer(bus, on_revision=live.written), cache=cache, live=live)
    app.add_exception_handler(RequestValidationError, invalid_request)
    app.add_exception_handler(StoreUnavailableError, _store_unavailable)
    app.add_exception_handler(StoreError, _store_error)
    app.add_exception_handler(Exception, _unexpected)
    for module in (health, maps, layers, features, layout, exports, bins, wms, stock, semantics, topology, blocks,
                   routes, places, robots, history, events, keys, viewer):
        app.include_router(module.router)
    app.add_middleware(BodyLimit, max_bytes=settings.api_max_body_bytes)
    app.add_middleware(LiveReads, context=context)  # inside CORS, so its answers get CORS headers too
    app.add_middleware(ConditionalReads, gzip_min_bytes=gzip_min_bytes)
    if cors_origins:
        app.add_middleware(
            CORSMiddleware,
            allow_origins=list(cors_origins),
            allow_methods=["GET", "POST", "PUT", "PATCH", "DELETE"],
            allow_headers=[API_KEY_HEADER, "Authorization", "Content-Type", "Last-Event-ID", "If-None-Match"],
            expose_headers=["Retry-After", "ETag", REVISION_HEADER],
            max_age=600,
        )
    return app


def _check_origins(origins: Sequence[str]) -> None:
    for origin in origins:
        if origin != "*" and (not origin.startswith(("http://", "https://")) or origin.endswith("/")):
            raise ApiConfigError(
                f"CORS origin {origin!r} must be '*' or scheme://host[:port] without a trailing slash, "
                "e.g. https://wms.example.com"
            )


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
