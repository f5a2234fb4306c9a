"""Regions and connections operators close to routes, and opening them again."""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import APIRouter, Body, Path, Response, status
from pydantic import BaseModel, Field

from api.access import Caller
from api.deps import AnnouncerDep, CacheDep, CallerDep, MapDep, RevisionQuery, StoreDep
from api.models import COMMON_ERRORS, UNPROCESSABLE, ErrorOut, Responses, example_config, not_found
from api.translate import http_error
from atlas.errors import AtlasError
from atlas.navigation import (
    BLOCKABLE_KEY_PATTERN,
    REGION_KEY_PATTERN,
    NavigationError,
    NavigationUnavailableError,
    NavMap,
    ResolvedBlock,
    blocking,
    load_navmap,
)

router = APIRouter(prefix="/v1/maps/{map_name}", responses=COMMON_ERRORS)

_NO_REGIONS = "The map has no regions yet (not decomposed)."
_READ_ERRORS: Responses = {**not_found("No such map or revision."), **UNPROCESSABLE}
_BLOCK_ERRORS: Responses = {
    **not_found("No such map, region, connection or block."),
    status.HTTP_409_CONFLICT: {"model": ErrorOut, "description": _NO_REGIONS},
    **UNPROCESSABLE,
}


class BlockIn(BaseModel):
    reason: str | None = Field(default=None, max_length=200, description="Why, for the people who read it.")

    model_config = example_config(reason="spill in aisle 3")


class BlockOut(BaseModel):
    target: Literal["region", "connection"]
    regions: list[str] | None = Field(
        description="The region (every region of a blocked aisle, or the two regions of the connection) the block "
                    "applies to now; null when nothing matches it any more (the map changed), so it has no effect.")
    blocked_keys: list[str] = Field(description="The region or aisle keys named when it was blocked.")
    x_m: float = Field(description="A point inside the region, or the connection's portal, when blocked: x, "
                                   "metres, map frame.")
    y_m: float = Field(description="y, metres, map frame.")
    reason: str | None
    blocked_at: str = Field(description="When, ISO 8601 UTC.")
    blocked_by: str | None = Field(description="Name of the API key that blocked it.")


_BLOCK_EXAMPLE = {"target": "region", "regions": ["r17"], "blocked_keys": ["r17"], "x_m": 8.43, "y_m": 5.63,
                  "reason": "spill in aisle 3", "blocked_at": "2025-03-04T10:15:00Z", "blocked_by": "shift-lead"}


class BlockList(BaseModel):
    blocks: list[BlockOut]
    revision: int | None = Field(description="The revision read at; null when the map has no regions yet.")

    model_config = example_config(blocks=[_BLOCK_EXAMPLE], revision=43)


class BlockChange(BaseModel):
    block: BlockOut
    revision_id: int = Field(description="The operator revision that stored the change.")

    model_config = example_config(block=_BLOCK_EXAMPLE, revision_id=43)


class Unblocked(BaseModel):
    removed: list[BlockOut]
    revision_id: int = Field(description="The operator revision that stored the change.")

    model_config = example_config(removed=[_BLOCK_EXAMPLE], revision_id=44)


def _block_out(item: ResolvedBlock, nav: NavMap) -> BlockOut:
    block = item.block
    return BlockOut(target="region" if block.is_region else "connection",
                    regions=None if item.ids is None else [nav.key(i) for i in item.ids],
                    blocked_keys=list(block.keys), x_m=block.x_m, y_m=block.y_m, reason=block.reason,
                    blocked_at=block.blocked_at, blocked_by=block.blocked_by)


RegionPath = Annotated[str, Path(pattern=REGION_KEY_PATTERN, description="Region key, e.g. `r17`.",
                                 examples=["r17"])]
BlockablePath = Annotated[str, Path(
    pattern=BLOCKABLE_KEY_PATTERN, examples=["r17", "aisle-03"],
    description="Region key (`r17`), or an aisle's key (`aisle-03`, its `corridor` feature): every drivable "
                "region lying in the aisle.")]
BlockBody = Annotated[BlockIn | None, Body(
    description="Optional: why it is blocked.",
    openapi_examples={"reason": {"summary": "with a reason", "value": {"reason": "spill in aisle 3"}}})]


@router.get("/topology/blocked", summary="Blocked regions and connections", tags=["topology"],
            responses=_READ_ERRORS)
def list_blocks(map_info: MapDep, store: StoreDep, revision: RevisionQuery, cache: CacheDep) -> BlockList:
    """What operators have closed (as of ``?revision=``), with the regions each block applies to now."""
    try:
        nav = load_navmap(store, map_info.id, revision=revision, cache=cache)
    except NavigationUnavailableError:
        return BlockList(blocks=[], revision=revision)
    return BlockList(blocks=[_block_out(item, nav) for item in nav.blocks], revision=nav.revision)


def _caller_name(caller: Caller) -> str | None:
    return None if caller.key is None else caller.key.name


@router.put("/topology/blocked/regions/{region}", summary="Block a region", tags=["topology"],
            responses={**_BLOCK_ERRORS, status.HTTP_201_CREATED: {"model": BlockChange,
                                                                  "description": "Blocked (it was not)."}})
def block_region(map_info: MapDep, store: StoreDep, announcer: AnnouncerDep,
                 cache: CacheDep, caller: CallerDep, response: Response,
                 region: BlockablePath, body: BlockBody = None) -> BlockChange:
    """Close a drivable region, or every drivable region of an aisle, to routes (stored as an ``operator``
    revision); 201 when newly blocked, 200 when it was blocked already (the reason is replaced). Region keys stay
    the same while the place is the same, across revisions. Needs a write key."""
    try:
        done = blocking.block_region(store, cache, map_info.id, region, reason=body.reason if body else None,
                                     by=_caller_name(caller))
    except (AtlasError, NavigationError) as err:
        raise http_error(err) from err
    announcer.announce(map_info, done.revision)
    response.status_code = status.HTTP_200_OK if done.renewed else status.HTTP_201_CREATED
    return BlockChange(block=_block_out(done.block, done.nav), revision_id=done.revision.id)


@router.delete("/topology/blocked/regions/{region}", summary="Unblock a region", tags=["topology"],
               responses=_BLOCK_ERRORS)
def unblock_region(map_info: MapDep, store: StoreDep, announcer: AnnouncerDep,
                   cache: CacheDep, region: BlockablePath) -> Unblocked:
    """Open a blocked region or aisle again (every block made for this key, and every region block that applies
    to this region now). 404 when it is not blocked. Needs a write key."""
    try:
        done = blocking.unblock_region(store, cache, map_info.id, region)
    except (AtlasError, NavigationError) as err:
        raise http_error(err) from err
    announcer.announce(map_info, done.revision)
    return Unblocked(removed=[_block_out(item, done.nav) for item in done.removed], revision_id=done.revision.id)


@router.put("/topology/blocked/connections/{a}/{b}", summary="Block a connection", tags=["topology"],
            responses={**_BLOCK_ERRORS, status.HTTP_201_CREATED: {"model": BlockChange,
                                                                  "description": "Blocked (it was not)."}})
def block_connection(map_info: MapDep, store: StoreDep, announcer: AnnouncerDep,
                     cache: CacheDep, caller: CallerDep, response: Response,
                     a: RegionPath, b: RegionPath, body: BlockBody = None) -> BlockChange:
    """Close the passage between two neighbouring regions (either order); 201 when newly blocked, 200 when it
    was already (the reason is replaced). Needs a write key."""
    try:
        done = blocking.block_connection(store, cache, map_info.id, a, b, reason=body.reason if body else None,
                                         by=_caller_name(caller))
    except (AtlasError, NavigationError) as err:
        raise http_error(err) from err
    announcer.announce(map_info, done.revision)
    response.status_code = status.HTTP_200_OK if done.renewed else status.HTTP_201_CREATED
    return BlockChange(block=_block_out(done.block, done.nav), revision_id=done.revision.id)


@router.delete("/topology/blocked/connections/{a}/{b}", summary="Unblock a connection", tags=["topology"],
               responses=_BLOCK_ERRORS)
def unblock_connection(map_info: MapDep, store: StoreDep, announcer: AnnouncerDep,
                       cache: CacheDep, a: RegionPath, b: RegionPath
                       ) -> Unblocked:
    """Open a blocked connection again (either order). 404 when it is not blocked. Needs a write key."""
    try:
        done = blocking.unblock_connection(store, cache, map_info.id, a, b)
    except (AtlasError, NavigationError) as err:
        raise http_error(err) from err
    announcer.announce(map_info, done.revision)
    return Unblocked(removed=[_block_out(item, done.nav) for item in done.removed], revision_id=done.revision.id)
