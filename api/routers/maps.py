"""Maps and their revisions."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, HTTPException, Path, Query, status

from api.deps import MAX_ID, MapDep, StoreDep, find_revision
from api.models import COMMON_ERRORS, UNPROCESSABLE, MapDetail, MapSummary, RevisionOut, RevisionPage, not_found
from shared.store import MapInfo, MapStore, Revision

router = APIRouter(prefix="/v1/maps", tags=["maps"], responses=COMMON_ERRORS)

_NOT_FOUND = {**not_found("No such map or revision."), **UNPROCESSABLE}


def revision_out(revision: Revision) -> RevisionOut:
    return RevisionOut(
        id=revision.id,
        stage=revision.stage,
        created_at=revision.created_at,
        input_start_ns=revision.input_start_ns,
        input_end_ns=revision.input_end_ns,
        summary=dict(revision.summary),
        pinned=revision.pinned,
    )


def _summary(store: MapStore, map_info: MapInfo, latest: Revision | None) -> MapSummary:
    return MapSummary(
        name=map_info.name,
        frame_id=map_info.frame_id,
        created_at=map_info.created_at,
        latest_revision_id=None if latest is None else latest.id,
        layers=store.layer_names(map_info.id),
    )


@router.get("", summary="List maps")
def list_maps(store: StoreDep) -> list[MapSummary]:
    """Every map with its newest revision id and the names of its grid layers."""
    return [_summary(store, info, store.latest_revision(info.id)) for info in store.maps()]


@router.get("/{map_name}", summary="Describe a map", responses=_NOT_FOUND)
def get_map(map_info: MapDep, store: StoreDep) -> MapDetail:
    """One map with its newest revision and the names of its grid layers."""
    latest = store.latest_revision(map_info.id)
    return MapDetail(
        **_summary(store, map_info, latest).model_dump(),
        latest_revision=None if latest is None else revision_out(latest),
    )


@router.get("/{map_name}/revisions", summary="List revisions", responses=_NOT_FOUND)
def list_revisions(
    map_info: MapDep,
    store: StoreDep,
    after: Annotated[int, Query(ge=0, le=MAX_ID, description="Only revisions with a larger id (a page cursor).",
                                examples=[1200])] = 0,
    limit: Annotated[int, Query(ge=1, le=1000, description="Page size, count of revisions.", examples=[100])] = 100,
) -> RevisionPage:
    """Revisions of the map, oldest first, one page at a time."""
    revisions = store.revisions(map_info.id, after_id=after, limit=limit)
    next_after = revisions[-1].id if len(revisions) == limit else None
    return RevisionPage(revisions=[revision_out(r) for r in revisions], next_after=next_after)


@router.get("/{map_name}/revisions/{revision_id}", summary="Describe a revision", responses=_NOT_FOUND)
def get_revision(
    map_info: MapDep,
    store: StoreDep,
    revision_id: Annotated[int, Path(ge=1, le=MAX_ID, description="The revision's id.", examples=[1207])],
) -> RevisionOut:
    """One revision of the map: which stage wrote it, when, from which input, and what changed."""
    found = find_revision(store, map_info, revision_id)
    if found is None:
        raise HTTPException(
            status.HTTP_404_NOT_FOUND, f"revision {revision_id} is not a revision of map {map_info.name!r}"
        )
    return revision_out(found)


RevisionPath = Annotated[int, Path(ge=1, le=MAX_ID, description="The revision's id.", examples=[1207])]


def _pin(map_info: MapInfo, store: MapStore, revision_id: int, *, pinned: bool) -> RevisionOut:
    found = store.pin_revision(map_info.id, revision_id, pinned=pinned)
    if found is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"revision {revision_id} is not a revision of map "
                            f"{map_info.name!r} (old revisions are thinned by the retention settings)")
    return revision_out(found)


@router.put("/{map_name}/revisions/{revision_id}/pin", summary="Pin a revision", responses=_NOT_FOUND)
def pin_revision(map_info: MapDep, store: StoreDep, revision_id: RevisionPath) -> RevisionOut:
    """Keep this revision whatever the retention settings say, so the map can be read as it was then for as
    long as it stays pinned. Needs a write key."""
    return _pin(map_info, store, revision_id, pinned=True)


@router.delete("/{map_name}/revisions/{revision_id}/pin", summary="Unpin a revision", responses=_NOT_FOUND)
def unpin_revision(map_info: MapDep, store: StoreDep, revision_id: RevisionPath) -> RevisionOut:
    """Let the retention settings thin this revision again once it is old. Needs a write key."""
    return _pin(map_info, store, revision_id, pinned=False)
