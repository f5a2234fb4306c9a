"""Request dependencies: the app's store, settings and bus, the caller and their rights, and the map and
revision a route reads."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import Annotated, cast

import anyio
from fastapi import Depends, HTTPException, Path, Query, Request, Security, status
from fastapi.security import APIKeyHeader, HTTPAuthorizationCredentials, HTTPBearer

from api.access import API_KEY_HEADER, AccessPolicy, Caller, check_role, credentials_of
from api.announce import Announcer
from api.streams import EventStreams
from atlas.cache import RevisionCache
from atlas.live import LiveMaps
from shared.bus import Bus
from shared.settings import Settings
from shared.store import MapInfo, MapStore, Revision
from shared.store.keys import Role

MAX_ID = 2**31 - 1
"""Largest row id the store holds (a 32-bit integer column); larger ids in a request are refused as 422."""


@dataclass(frozen=True, slots=True)
class ApiContext:
    """What :func:`api.app.create_app` was built with; kept on ``app.state.context``."""

    store: MapStore
    settings: Settings
    bus: Bus | None
    expected_workers: Sequence[str]
    access: AccessPolicy
    events: EventStreams
    announcer: Announcer
    cache: RevisionCache
    """Things derived from one revision of a map (decoded layers, bin indexes)."""
    live: LiveMaps
    """The live state of each map, for live reads."""
    maps: dict[str, MapInfo] = field(default_factory=dict)
    """Maps found so far, by name."""


# Dependencies that neither block nor wait are ``async def``: FastAPI runs a plain ``def`` dependency in a
# worker thread, and that hop costs more than most of them do.
async def get_context(request: Request) -> ApiContext:
    return cast(ApiContext, request.app.state.context)


ContextDep = Annotated[ApiContext, Depends(get_context)]


async def get_store(context: ContextDep) -> MapStore:
    return context.store


async def get_settings(context: ContextDep) -> Settings:
    return context.settings


async def get_announcer(context: ContextDep) -> Announcer:
    return context.announcer


async def get_cache(context: ContextDep) -> RevisionCache:
    return context.cache


StoreDep = Annotated[MapStore, Depends(get_store)]
AnnouncerDep = Annotated[Announcer, Depends(get_announcer)]
"""Announce a revision the API wrote (on the bus, when there is one)."""
SettingsDep = Annotated[Settings, Depends(get_settings)]
CacheDep = Annotated[RevisionCache, Depends(get_cache)]
"""What was derived from one revision of a map (decoded layers, bin indexes)."""

_api_key_header = APIKeyHeader(name=API_KEY_HEADER, auto_error=False, scheme_name="ApiKey",
                               description="An Aisle API key, `aisle_<id>_<secret>`.")
_bearer = HTTPBearer(auto_error=False, scheme_name="Bearer", description="The same API key as a bearer token.")


async def get_caller(
    request: Request,
    context: ContextDep,
    api_key: Annotated[str | None, Security(_api_key_header)],
    bearer: Annotated[HTTPAuthorizationCredentials | None, Security(_bearer)],
) -> Caller:
    """The caller, let in by :meth:`api.access.AccessPolicy.admit` (401, 403 or 429 otherwise).

    Decided from memory when it can be (:meth:`~api.access.AccessPolicy.judge`), as the fast path does; otherwise
    the key is read in a worker thread. ``api_key`` and ``bearer`` are here to document both ways to send a key
    in OpenAPI; the key is read off the request by :func:`api.access.credentials_of`, as on the fast path.
    """
    credentials = credentials_of(request.scope)
    route = str(getattr(request.scope.get("route"), "path", request.url.path))
    verdict = context.access.judge(credentials, method=request.method, route=route)
    if verdict is not None:
        return context.access.settle(verdict)
    return await anyio.to_thread.run_sync(partial(context.access.admit, context.store, credentials,
                                                  method=request.method, route=route))


CallerDep = Annotated[Caller, Depends(get_caller)]


async def enforce_policy(caller: CallerDep) -> None:
    """App-wide: every request is let in by :func:`get_caller` (writes need a ``write`` key, reads a ``read`` key
    when the app requires keys for reads)."""


async def require_admin(caller: CallerDep) -> Caller:
    """The caller, if their key is an ``admin`` key (401/403 otherwise)."""
    check_role(caller, Role.ADMIN)
    return caller


AdminDep = Annotated[Caller, Depends(require_admin)]


async def get_map(
    map_name: Annotated[str, Path(description="Name of the map, e.g. `site`.", max_length=64, examples=["site"])],
    context: ContextDep,
) -> MapInfo:
    """The map named in the path, or 404 naming the maps that do exist.

    Maps are never renamed or removed (the store has no way to), so a map once found is remembered.
    """
    found = context.maps.get(map_name)
    if found is None:
        found = await anyio.to_thread.run_sync(_find_map, context.store, map_name)
        context.maps[map_name] = found
    return found


def _find_map(store: MapStore, name: str) -> MapInfo:
    found = store.get_map(name)
    if found is None:
        known = [info.name for info in store.maps()]
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"no map named {name!r}; known maps: {known}")
    return found


MapDep = Annotated[MapInfo, Depends(get_map)]


def find_revision(store: MapStore, map_info: MapInfo, revision_id: int) -> Revision | None:
    """Revision ``revision_id`` if it belongs to the map, else None."""
    found = store.revisions(map_info.id, after_id=revision_id - 1, limit=1)
    return found[0] if found and found[0].id == revision_id else None


async def get_revision(
    map_info: MapDep,
    store: StoreDep,
    revision: Annotated[
        int | None,
        Query(ge=1, le=MAX_ID, description="Read the map as it was at this revision id (default: now).",
              examples=[1207]),
    ] = None,
) -> int | None:
    """The ``?revision=`` to read at, after checking it is a revision of the map (404 otherwise)."""
    if revision is not None:
        await anyio.to_thread.run_sync(check_revision, store, map_info, revision)
    return revision


def check_revision(store: MapStore, map_info: MapInfo, revision: int) -> None:
    """404 unless ``revision`` is a revision of the map, saying which is its newest."""
    if find_revision(store, map_info, revision) is None:
        latest = store.latest_revision(map_info.id)
        newest = "it has no revisions yet" if latest is None else f"its newest is {latest.id}"
        raise HTTPException(
            status.HTTP_404_NOT_FOUND,
            f"revision {revision} is not a revision of map {map_info.name!r}; {newest} (old revisions are thinned "
            "by the retention settings unless pinned)",
        )


RevisionQuery = Annotated[int | None, Depends(get_revision)]
