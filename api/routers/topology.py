"""The region graph, blocked regions and connections, and drivable routes between bins, places and points."""

from __future__ import annotations

from typing import Annotated, Any, Literal

import networkx as nx
from fastapi import APIRouter, Body, Depends, HTTPException, Path, Query, Response, status
from pydantic import BaseModel, Field

from api.access import Caller
from api.announce import Announcer
from api.binindex import WmsMatching, bin_index, corridors_along
from api.cache import RevisionCache
from api.deps import AnnouncerDep, CallerDep, MapDep, RevisionQuery, StoreDep, get_cache
from api.models import COMMON_ERRORS, UNPROCESSABLE, ErrorOut, Responses, example_config, not_found
from api.navigation import (
    REGION_KEY_PATTERN,
    Block,
    End,
    EndSyntaxError,
    NavigationError,
    NavigationUnavailableError,
    NavMap,
    ResolvedBlock,
    UnknownEndError,
    load_navmap,
    locate_end,
    parse_end,
    plan_route,
    region_pair,
    write_blocks,
)
from api.navigation.blocks import OPERATOR_LOCK, now_iso, region_id
from api.navigation.grid import FREE_BELOW
from shared.store import MapInfo, MapStore

router = APIRouter(prefix="/v1/maps/{map_name}", responses=COMMON_ERRORS)

MAX_AVOID = 100

CacheDep = Annotated[RevisionCache, Depends(get_cache)]

_NO_REGIONS = "The map has no regions yet (not decomposed)."
_READ_ERRORS: Responses = {**not_found("No such map or revision."), **UNPROCESSABLE}
_ROUTE_ERRORS: Responses = {
    **not_found("No such map, revision, bin or place."),
    status.HTTP_409_CONFLICT: {"model": ErrorOut, "description": "No drivable route: an end is off every drivable "
                                                                 "region or in a blocked one, the regions do not "
                                                                 "connect, or the map has no regions yet."},
    **UNPROCESSABLE,
}
_BLOCK_ERRORS: Responses = {
    **not_found("No such map, region, connection or block."),
    status.HTTP_409_CONFLICT: {"model": ErrorOut, "description": _NO_REGIONS},
    **UNPROCESSABLE,
}


def _http(err: NavigationError) -> HTTPException:
    if isinstance(err, EndSyntaxError):
        return HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, str(err))
    if isinstance(err, UnknownEndError):
        return HTTPException(status.HTTP_404_NOT_FOUND, str(err))
    return HTTPException(status.HTTP_409_CONFLICT, str(err))


def _navmap(store: MapStore, map_info: MapInfo, revision: int | None, cache: RevisionCache) -> NavMap:
    try:
        return load_navmap(store, map_info.id, revision=revision, cache=cache)
    except NavigationError as err:
        raise _http(err) from err


# -- topology ------------------------------------------------------------------------------------------
class TopologyNodeOut(BaseModel):
    id: str = Field(description="Region key (`r<id>`), also the key of the region's feature.")
    kind: str = Field(description="Place label: corridor, junction, room, open_area, storage, unidentified, ...")
    x: float | None = Field(description="Centroid x, map metres (may lie outside a concave region).")
    y: float | None = Field(description="Centroid y, map metres.")
    area_m2: float | None
    drivable: bool = Field(description="Whether vehicles drive in it (corridor, junction, room, open area).")
    blocked: bool = Field(description="Closed by an operator.")


class TopologyEdgeOut(BaseModel):
    source: str
    target: str
    connection: str = Field(description="connected, storage_access, door or disconnected.")
    blocked: bool = Field(description="Closed by an operator.")
    portal: tuple[float, float] | None = Field(
        description="Middle of the regions' shared boundary (x, y), map metres; null when they share none.")
    width_m: float | None = Field(description="Length of the shared boundary, metres (approximate).")


class TopologyGraphOut(BaseModel):
    map: str
    revision: int | None = Field(description="The revision read at; null when the map has no revisions.")
    segments_revision_id: int | None = Field(description="Revision of the place_segments layer the graph is of.")


_TOPOLOGY_EXAMPLE: dict[str, Any] = {
    "directed": False, "multigraph": False, "graph": {"map": "site", "revision": 42, "segments_revision_id": 40},
    "nodes": [{"id": "r17", "kind": "corridor", "x": 8.4, "y": 5.6, "area_m2": 36.1, "drivable": True,
               "blocked": False},
              {"id": "r16", "kind": "junction", "x": 1.5, "y": 5.6, "area_m2": 9.0, "drivable": True,
               "blocked": False}],
    "edges": [{"source": "r16", "target": "r17", "connection": "connected", "blocked": False,
               "portal": [3.05, 5.62], "width_m": 3.0}]}
_TOPOLOGY_GEOJSON_EXAMPLE: dict[str, Any] = {"type": "FeatureCollection", "revision": 42, "features": [
    {"type": "Feature", "id": "r17", "geometry": {"type": "Point", "coordinates": [8.4, 5.6]},
     "properties": {"kind": "corridor", "area_m2": 36.1, "drivable": True, "blocked": False}},
    {"type": "Feature", "id": "r16-r17",
     "geometry": {"type": "LineString", "coordinates": [[1.5, 5.6], [3.05, 5.62], [8.4, 5.6]]},
     "properties": {"source": "r16", "target": "r17", "connection": "connected", "blocked": False,
                    "width_m": 3.0}}]}


class TopologyOut(BaseModel):
    """networkx node-link JSON (``networkx.node_link_graph(data, edges="edges")`` reads it back)."""

    directed: bool
    multigraph: bool
    graph: TopologyGraphOut
    nodes: list[TopologyNodeOut]
    edges: list[TopologyEdgeOut]

    model_config = example_config(**_TOPOLOGY_EXAMPLE)


class TopologyFeatureOut(BaseModel):
    type: Literal["Feature"] = "Feature"
    id: str = Field(description="A region key, or `<source>-<target>` for a connection.")
    geometry: dict[str, Any] = Field(description="Point (region centroid) or LineString (hub, portal, hub).")
    properties: dict[str, Any]


class TopologyGeoJSONOut(BaseModel):
    type: Literal["FeatureCollection"] = "FeatureCollection"
    features: list[TopologyFeatureOut]
    revision: int | None

    model_config = example_config(**_TOPOLOGY_GEOJSON_EXAMPLE)


def _topology_graph(nav: NavMap, map_info: MapInfo) -> nx.Graph:
    graph = nx.Graph(map=map_info.name, revision=nav.revision, segments_revision_id=nav.grid.segments_revision)
    for _, data in sorted(nav.graph.nodes(data=True)):
        region = data["region"]
        graph.add_node(region.key, kind=region.kind, x=region.x_m, y=region.y_m, area_m2=region.area_m2,
                       drivable=region.drivable, blocked=data["blocked"])
    for a, b, data in sorted(nav.graph.edges(data=True)):
        portal = data["portal"]
        graph.add_edge(nav.key(a), nav.key(b), connection=data["connection"], blocked=data["blocked"],
                       portal=None if portal is None else (portal.x_m, portal.y_m),
                       width_m=None if portal is None else portal.width_m)
    return graph


def _geojson(nav: NavMap) -> list[TopologyFeatureOut]:
    features = []
    for _, data in sorted(nav.graph.nodes(data=True)):
        region = data["region"]
        if region.x_m is None or region.y_m is None:
            continue
        features.append(TopologyFeatureOut(
            id=region.key, geometry={"type": "Point", "coordinates": [region.x_m, region.y_m]},
            properties={"kind": region.kind, "area_m2": region.area_m2, "drivable": region.drivable,
                        "blocked": data["blocked"]}))
    for a, b, data in sorted(nav.graph.edges(data=True)):
        portal, hubs = data["portal"], (nav.hub(a), nav.hub(b))
        if portal is None or hubs[0] is None or hubs[1] is None:
            continue
        line = [list(hubs[0]), [portal.x_m, portal.y_m], list(hubs[1])]
        features.append(TopologyFeatureOut(
            id=f"{nav.key(a)}-{nav.key(b)}", geometry={"type": "LineString", "coordinates": line},
            properties={"source": nav.key(a), "target": nav.key(b), "connection": data["connection"],
                        "blocked": data["blocked"], "width_m": portal.width_m}))
    return features


@router.get("/topology", summary="The region graph", tags=["topology"], responses={
    **_READ_ERRORS, status.HTTP_200_OK: {"content": {"application/json": {"examples": {
        "node-link": {"summary": "?format=node-link", "value": _TOPOLOGY_EXAMPLE},
        "geojson": {"summary": "?format=geojson", "value": _TOPOLOGY_GEOJSON_EXAMPLE}}}}}})
def get_topology(
    map_info: MapDep,
    store: StoreDep,
    revision: RevisionQuery,
    cache: CacheDep,
    format: Annotated[Literal["node-link", "geojson"], Query(
        description="`node-link` (networkx JSON) or `geojson` (regions as points, connections as lines).",
        examples=["node-link"])] = "node-link",
) -> TopologyOut | TopologyGeoJSONOut:
    """Regions of the grid decomposition and their connections (as of ``?revision=``), with portals and the
    operator's blocks. A map not decomposed yet has an empty graph."""
    try:
        nav = load_navmap(store, map_info.id, revision=revision, cache=cache)
    except NavigationUnavailableError:
        if format == "geojson":
            return TopologyGeoJSONOut(features=[], revision=revision)
        return TopologyOut(directed=False, multigraph=False, nodes=[], edges=[],
                           graph=TopologyGraphOut(map=map_info.name, revision=revision, segments_revision_id=None))
    if format == "geojson":
        return TopologyGeoJSONOut(features=_geojson(nav), revision=nav.revision)
    return TopologyOut.model_validate(nx.node_link_data(_topology_graph(nav, map_info), edges="edges"))


# -- blocked regions and connections ---------------------------------------------------------------------
class BlockIn(BaseModel):
    reason: str | None = Field(default=None, max_length=200, description="Why, for the people who read it.")

    model_config = example_config(reason="spill in aisle 3")


class BlockOut(BaseModel):
    target: Literal["region", "connection"]
    regions: list[str] | None = Field(
        description="The region (or the two regions of the connection) the block applies to now; null when "
                    "nothing lies at its point any more (the map changed), so it has no effect.")
    blocked_keys: list[str] = Field(description="The region keys named when it was blocked.")
    x_m: float = Field(description="A point inside the region, or the connection's portal, when blocked (metres).")
    y_m: float
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


def _store_blocks(store: MapStore, announcer: Announcer, map_info: MapInfo, keep: list[ResolvedBlock],
                  added: Block | None, change: str) -> int:
    blocks = [item.block for item in keep] + ([added] if added is not None else [])
    written = write_blocks(store, map_info.id, blocks, change=change)
    announcer.announce(map_info, written)
    return written.id


@router.put("/topology/blocked/regions/{region}", summary="Block a region", tags=["topology"],
            responses={**_BLOCK_ERRORS, status.HTTP_201_CREATED: {"model": BlockChange,
                                                                  "description": "Blocked (it was not)."}})
def block_region(map_info: MapDep, store: StoreDep, announcer: AnnouncerDep,
                 cache: CacheDep, caller: CallerDep, response: Response,
                 region: RegionPath, body: BlockBody = None) -> BlockChange:
    """Close a drivable region to routes (stored as an ``operator`` revision); 201 when newly blocked, 200 when
    it was blocked already (the reason is replaced). Needs a write key."""
    with OPERATOR_LOCK:
        nav = _navmap(store, map_info, None, cache)
        rid = _existing_region(nav, region)
        if not nav.regions[rid].drivable:
            raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT,
                                f"{nav.describe(rid)} is not a drivable region; routes never pass it")
        hub = nav.hub(rid)
        if hub is None:
            raise HTTPException(status.HTTP_409_CONFLICT, f"{nav.describe(rid)} has no cells in the segment layer")
        same = [item for item in nav.blocks if item.ids == (rid,)]
        block = Block((region,), hub[0], hub[1], body.reason if body else None, now_iso(), _caller_name(caller))
        revision = _store_blocks(store, announcer, map_info, [i for i in nav.blocks if i not in same], block,
                                 f"blocked region {region}")
    response.status_code = status.HTTP_200_OK if same else status.HTTP_201_CREATED
    return BlockChange(block=_block_out(ResolvedBlock(block, (rid,)), nav), revision_id=revision)


@router.delete("/topology/blocked/regions/{region}", summary="Unblock a region", tags=["topology"],
               responses=_BLOCK_ERRORS)
def unblock_region(map_info: MapDep, store: StoreDep, announcer: AnnouncerDep,
                   cache: CacheDep, region: RegionPath) -> Unblocked:
    """Open a blocked region again (every block on it, including ones no longer matching anything that were
    made for this key). 404 when it is not blocked. Needs a write key."""
    rid = region_id(region)
    with OPERATOR_LOCK:
        nav = _navmap(store, map_info, None, cache)
        gone = [item for item in nav.blocks if item.block.is_region
                and (item.ids == (rid,) or (item.ids is None and item.block.keys == (region,)))]
        if not gone:
            raise HTTPException(status.HTTP_404_NOT_FOUND, f"region {region} is not blocked")
        revision = _store_blocks(store, announcer, map_info, [i for i in nav.blocks if i not in gone], None,
                                 f"unblocked region {region}")
    return Unblocked(removed=[_block_out(item, nav) for item in gone], revision_id=revision)


def _existing_region(nav: NavMap, key: str) -> int:
    rid = region_id(key)
    if rid is None or rid not in nav.regions:
        raise HTTPException(status.HTTP_404_NOT_FOUND,
                            f"the map has no region {key}; see /v1/maps/<map>/topology for its regions")
    return rid


@router.put("/topology/blocked/connections/{a}/{b}", summary="Block a connection", tags=["topology"],
            responses={**_BLOCK_ERRORS, status.HTTP_201_CREATED: {"model": BlockChange,
                                                                  "description": "Blocked (it was not)."}})
def block_connection(map_info: MapDep, store: StoreDep, announcer: AnnouncerDep,
                     cache: CacheDep, caller: CallerDep, response: Response,
                     a: RegionPath, b: RegionPath, body: BlockBody = None) -> BlockChange:
    """Close the passage between two neighbouring regions (either order); 201 when newly blocked, 200 when it
    was already (the reason is replaced). Needs a write key."""
    with OPERATOR_LOCK:
        nav = _navmap(store, map_info, None, cache)
        ids = tuple(sorted((_existing_region(nav, a), _existing_region(nav, b))))
        if not nav.graph.has_edge(*ids):
            raise HTTPException(status.HTTP_404_NOT_FOUND, f"regions {a} and {b} are not connected")
        portal = nav.graph.edges[ids]["portal"]
        if portal is None:
            raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT,
                                f"regions {a} and {b} share no boundary; no vehicle passes between them")
        same = [item for item in nav.blocks if item.ids == ids]
        block = Block(region_pair(nav.key(ids[0]), nav.key(ids[1])), portal.x_m, portal.y_m,
                      body.reason if body else None, now_iso(), _caller_name(caller))
        revision = _store_blocks(store, announcer, map_info, [i for i in nav.blocks if i not in same], block,
                                 f"blocked connection {a}-{b}")
    response.status_code = status.HTTP_200_OK if same else status.HTTP_201_CREATED
    return BlockChange(block=_block_out(ResolvedBlock(block, ids), nav), revision_id=revision)


@router.delete("/topology/blocked/connections/{a}/{b}", summary="Unblock a connection", tags=["topology"],
               responses=_BLOCK_ERRORS)
def unblock_connection(map_info: MapDep, store: StoreDep, announcer: AnnouncerDep,
                       cache: CacheDep, a: RegionPath, b: RegionPath
                       ) -> Unblocked:
    """Open a blocked connection again (either order). 404 when it is not blocked. Needs a write key."""
    keys = region_pair(a, b)
    ids = tuple(sorted(i for i in (region_id(a), region_id(b)) if i is not None))
    with OPERATOR_LOCK:
        nav = _navmap(store, map_info, None, cache)
        gone = [item for item in nav.blocks if not item.block.is_region
                and (item.ids == ids or (item.ids is None and item.block.keys == keys))]
        if not gone:
            raise HTTPException(status.HTTP_404_NOT_FOUND, f"the connection {a}-{b} is not blocked")
        revision = _store_blocks(store, announcer, map_info, [i for i in nav.blocks if i not in gone], None,
                                 f"unblocked connection {a}-{b}")
    return Unblocked(removed=[_block_out(item, nav) for item in gone], revision_id=revision)


# -- routes --------------------------------------------------------------------------------------------
class RouteEnd(BaseModel):
    spec: str = Field(description="The end as asked, e.g. `bin:01-003-02`.")
    x_m: float = Field(description="Where the end is (a bin's access pose, a place's approach point), metres.")
    y_m: float
    yaw_rad: float | None = Field(description="Heading there, if the end has one (radians from the map x axis).")
    region: str = Field(description="Key of the drivable region the route starts or ends in.")


class WaypointOut(BaseModel):
    x_m: float
    y_m: float
    region: str = Field(description="Region key: where the route is from here on.")
    kind: Literal["start", "portal", "via", "goal"] = Field(
        description="`portal`: the route enters `region` here; `via`: a corner inside `region` around an obstacle.")


class RegionPassed(BaseModel):
    key: str
    kind: str = Field(description="corridor, junction, room or open_area.")


class RouteOut(BaseModel):
    start: RouteEnd
    goal: RouteEnd
    waypoints: list[WaypointOut] = Field(description="Start to goal; straight legs between them stay on free cells.")
    regions: list[RegionPassed] = Field(description="Regions passed, in order.")
    corridors: list[str] = Field(description="Keys of the corridor features the route runs through, in order: "
                                             "aisles (`aisle-03`, from the rack rows) and decomposition corridors.")
    length_m: float
    revision: int | None = Field(description="The revision the route was planned on.")
    free_below: int = Field(description="Occupancy values 0 <= v < free_below count as free.")

    model_config = {"json_schema_extra": {"examples": [{
        "start": {"spec": "bin:01-001-01", "x_m": 4.35, "y_m": 5.6, "yaw_rad": -1.571, "region": "r17"},
        "goal": {"spec": "dock:G1", "x_m": 5.5, "y_m": 0.0, "yaw_rad": None, "region": "r2"},
        "waypoints": [{"x_m": 4.35, "y_m": 5.6, "region": "r17", "kind": "start"},
                      {"x_m": 3.05, "y_m": 5.63, "region": "r16", "kind": "portal"},
                      {"x_m": 1.53, "y_m": 4.05, "region": "r2", "kind": "portal"},
                      {"x_m": 5.5, "y_m": 0.0, "region": "r2", "kind": "goal"}],
        "regions": [{"key": "r17", "kind": "corridor"}, {"key": "r16", "kind": "junction"},
                    {"key": "r2", "kind": "corridor"}],
        "corridors": ["aisle-01", "r2"], "length_m": 9.17, "revision": 42, "free_below": FREE_BELOW}]}}


_END_DOC = ("`bin:<WMS id>` (the bin's access pose), `dock:<key>`, `gate:<key>`, `charger:<key>` or "
            "`place:<kind>/<key>` (the place's approach pose), or `point:<x>,<y>` (map metres).")


def _avoid(nav: NavMap, keys: list[str] | None) -> set[int]:
    if not keys:
        return set()
    if len(keys) > MAX_AVOID:
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, f"at most {MAX_AVOID} regions to avoid")
    ids = set()
    for key in keys:
        rid = region_id(key)
        if rid is None:
            raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT,
                                f"avoid={key!r} is not a region key; region keys look like r17")
        if rid not in nav.regions:
            raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, f"avoid={key}: the map has no region {key}")
        ids.add(rid)
    return ids


def _detected_bin(end: End, matching: WmsMatching | None) -> End:
    """A ``bin:`` end named by the WMS's own id, as Aisle's id of the matched bin."""
    if end.kind != "bin" or end.key is None or matching is None:
        return end
    detected = matching.detected_of(end.key)
    return end if detected is None else End(end.text, end.kind, detected, end.xy)


@router.get("/routes", summary="Shortest drivable route", tags=["routes"], responses=_ROUTE_ERRORS)
def get_route(
    map_info: MapDep,
    store: StoreDep,
    revision: RevisionQuery,
    cache: CacheDep,
    from_: Annotated[str, Query(alias="from", min_length=1, max_length=200, description=f"Start: {_END_DOC}",
                                examples=["bin:01-001-01"])],
    to: Annotated[str, Query(min_length=1, max_length=200, description=f"Goal: {_END_DOC}", examples=["dock:G1"])],
    avoid: Annotated[list[str] | None, Query(description="Region keys not to pass (repeatable), on top of the "
                                                         "blocked ones.", examples=[["r18"]])] = None,
) -> RouteOut:
    """The shortest route a vehicle can drive between two ends (as of ``?revision=``): through drivable regions
    (corridors, junctions, rooms, open areas) and their `connected` or `door` connections, never through
    blocked or avoided ones, each leg on free cells of the occupancy grid."""
    try:
        matching = bin_index(store, cache, map_info.id, revision).matching
        ends = [_detected_bin(parse_end(text), matching) for text in (from_, to)]
        start, goal = (locate_end(store, map_info.id, end, revision=revision) for end in ends)
        nav = load_navmap(store, map_info.id, revision=revision, cache=cache)
        avoided = _avoid(nav, avoid)
        route = plan_route(nav, (start.x_m, start.y_m), (goal.x_m, goal.y_m), avoid=avoided)
    except NavigationError as err:
        raise _http(err) from err
    first, last = route.waypoints[0], route.waypoints[-1]
    passed = [RegionPassed(key=nav.key(r), kind=nav.regions[r].kind) for r in route.regions]
    return RouteOut(
        start=RouteEnd(spec=from_, x_m=start.x_m, y_m=start.y_m, yaw_rad=start.yaw_rad, region=first.region),
        goal=RouteEnd(spec=to, x_m=goal.x_m, y_m=goal.y_m, yaw_rad=goal.yaw_rad, region=last.region),
        waypoints=[WaypointOut(x_m=w.x_m, y_m=w.y_m, region=w.region, kind=w.kind) for w in route.waypoints],
        regions=passed,
        corridors=corridors_along(bin_index(store, cache, map_info.id, revision).corridors,
                                  [(w.x_m, w.y_m) for w in route.waypoints]),
        length_m=round(route.length_m, 3),
        revision=nav.revision,
        free_below=FREE_BELOW,
    )
