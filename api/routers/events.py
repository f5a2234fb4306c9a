"""Live map changes as Server-Sent Events: one event per revision, resumable with Last-Event-ID."""

from __future__ import annotations

import datetime as dt
import logging
import time
from collections.abc import AsyncIterator
from typing import Annotated

import anyio
from fastapi import APIRouter, Depends, Header, HTTPException, Query, Request, status
from fastapi.sse import EventSourceResponse, ServerSentEvent
from pydantic import BaseModel, Field

from api.deps import MAX_ID, ContextDep, MapDep, StoreDep
from api.models import COMMON_ERRORS, UNPROCESSABLE, ErrorOut, as_json, not_found
from shared.store import MapInfo, MapStore, Revision

log = logging.getLogger(__name__)

router = APIRouter(prefix="/v1/maps/{map_name}/events", tags=["events"])

PAGE_SIZE = 100
"""Revisions read from the store per query while catching up."""
RECONNECT_MS = 3000
"""How long a browser EventSource waits before reconnecting, sent in the stream's first lines."""
EVENT_NAME = "revision"


class FeatureChanges(BaseModel):
    added: int
    removed: int
    moved: int
    changed: int = Field(0, description="Features whose properties changed in place (same key and geometry), "
                                        "count: e.g. bin states whose occupancy or last sighting changed.")
    total: int = Field(description="Features of the kind the stage asserts after the revision.")


class RevisionEvent(BaseModel):
    revision_id: int
    map: str
    stage: str
    created_at: dt.datetime
    layers_updated: list[str]
    features: dict[str, FeatureChanges] = Field(description="Per feature kind the stage wrote, what changed.")
    topology_changed: bool
    occupancy_changed: list[str] = Field(
        default_factory=list, description="Aisle's ids of the bins whose occupancy (empty, occupied, unknown) the "
                                          "revision changed (the first 1000; `features.bin_state` counts every bin "
                                          "state written); read them with `GET …/bins/{id}`.")


def revision_event(map_info: MapInfo, revision: Revision) -> RevisionEvent:
    """The event body of one revision, from its stored summary."""
    summary = revision.summary
    changes = summary.get("features", {})
    return RevisionEvent(
        revision_id=revision.id,
        map=map_info.name,
        stage=revision.stage,
        created_at=revision.created_at,
        layers_updated=list(summary.get("layers_updated", [])),
        features={kind: FeatureChanges(**{name: int(counts.get(name, 0))
                                          for name in ("added", "removed", "moved", "changed", "total")})
                  for kind, counts in changes.items()},
        topology_changed=bool(summary.get("topology_changed", False)),
        occupancy_changed=[str(bin_id) for bin_id in summary.get("occupancy_changed", [])],
    )


def get_cursor(
    map_info: MapDep,
    store: StoreDep,
    after: Annotated[int | None, Query(ge=0, le=MAX_ID, examples=[1200], description=(
        "Send revisions with a larger id (0: every revision). Default: only revisions from now on."))] = None,
    last_event_id: Annotated[str | None, Header(alias="Last-Event-ID", max_length=20, examples=["1206"], description=(
        "The id of the last event received; a reconnecting EventSource sends it. Wins over `?after=`."))] = None,
) -> int:
    """The revision id after which the stream starts: 422 for a Last-Event-ID that is not one, 409 for one (or an
    ``?after=``) beyond the map's newest revision, which the stream would wait for for ever."""
    if last_event_id is not None and not (last_event_id.isascii() and last_event_id.isdigit()
                                          and int(last_event_id) <= MAX_ID):
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT,
                            f"Last-Event-ID must be a revision id (an integer from 0 to {MAX_ID}), "
                            f"not {last_event_id!r}")
    latest = store.latest_revision(map_info.id)
    newest = 0 if latest is None else latest.id
    asked, name = (int(last_event_id), "Last-Event-ID") if last_event_id is not None else (after, "after")
    if asked is None:
        return newest
    if asked > newest:
        raise HTTPException(status.HTTP_409_CONFLICT,
                            f"{name} {asked} is beyond the newest revision of map {map_info.name!r} ({newest}); "
                            "the map store may have been replaced: reconnect without it to follow from now, or "
                            f"with ?after={newest}")
    return asked


@router.get(
    "",
    summary="Live revisions (Server-Sent Events)",
    response_class=EventSourceResponse,
    responses={status.HTTP_200_OK: {"content": {"text/event-stream": {}},
                                    "description": "`event: revision`, `id: <revision id>`, `data: <JSON>`."},
               **as_json({**COMMON_ERRORS, **not_found("No such map."), **UNPROCESSABLE,
                          status.HTTP_409_CONFLICT: {"model": ErrorOut, "description": "`Last-Event-ID` or `?after=` "
                                                     "is beyond the map's newest revision."}})},
)
async def map_events(
    request: Request,
    context: ContextDep,
    map_info: MapDep,
    cursor: Annotated[int, Depends(get_cursor)],
) -> AsyncIterator[ServerSentEvent]:
    """Each new revision of the map as one event, in order, each once.

    The event id is the revision id: an EventSource reconnecting with ``Last-Event-ID`` (or a client
    passing ``?after=``) gets every later revision, in order, none twice. Without either, the
    stream starts at the newest revision. Idle streams send a ``: heartbeat`` comment now and then.
    The stream polls the store, so it sees revisions written by any process (all streams of a process share one
    look at the map's newest revision per poll).
    """
    streams, store = context.events, context.store
    streams.opened()
    log.debug("event stream on map %r opened after revision %d", map_info.name, cursor)
    try:
        yield ServerSentEvent(comment=f"map {map_info.name}: revisions after {cursor}", retry=RECONNECT_MS)
        last_sent = time.monotonic()
        while not await request.is_disconnected():
            newest = await anyio.to_thread.run_sync(streams.newest, store, map_info.id)
            revisions = await anyio.to_thread.run_sync(_page, store, map_info.id, cursor) if newest > cursor else []
            for revision in revisions:
                yield ServerSentEvent(data=revision_event(map_info, revision), event=EVENT_NAME, id=str(revision.id))
                cursor = revision.id
            if revisions:
                last_sent = time.monotonic()
                if len(revisions) == PAGE_SIZE:
                    continue
            elif time.monotonic() - last_sent >= streams.heartbeat_s:
                yield ServerSentEvent(comment="heartbeat")
                last_sent = time.monotonic()
            await anyio.sleep(streams.poll_s)
    finally:
        streams.closed()
        log.debug("event stream on map %r closed after revision %d", map_info.name, cursor)


def _page(store: MapStore, map_id: int, after_id: int) -> list[Revision]:
    return store.revisions(map_id, after_id=after_id, limit=PAGE_SIZE)
