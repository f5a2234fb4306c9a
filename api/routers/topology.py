"""The region graph of the grid decomposition, with portals and the operator's blocks."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Query, Response, status
from pydantic import BaseModel, Field

from api.deps import CacheDep, MapDep, RevisionQuery, StoreDep
from api.models import COMMON_ERRORS, UNPROCESSABLE, Responses, example_config, naming_revision, not_found
from atlas.navigation import NavigationUnavailableError, load_navmap
from atlas.navigation.topology import topology_features, topology_node_link
from shared.vocabulary import REVISION_HEADER

router = APIRouter(prefix="/v1/maps/{map_name}", responses=COMMON_ERRORS)

_READ_ERRORS: Responses = {**not_found("No such map or revision."), **UNPROCESSABLE}


class TopologyNodeOut(BaseModel):
    id: str = Field(description="Region key (`r<id>`), also the key of the region's feature.")
    kind: str = Field(description="Place label: corridor, junction, room, open_area, storage, unidentified, ...")
    x: float | None = Field(description="Centroid x, metres, map frame (may lie outside a concave region).")
    y: float | None = Field(description="Centroid y, metres, map frame.")
    area_m2: float | None = Field(description="Floor area of the region, m².")
    aisle: str | None = Field(description="The aisle this corridor region is (`aisle-03`, the rack rows' corridor "
                                          "feature) where the racks are known; null otherwise.")
    drivable: bool = Field(description="Whether vehicles drive in it (corridor, junction, room, open area).")
    blocked: bool = Field(description="Closed by an operator.")


class TopologyEdgeOut(BaseModel):
    source: str
    target: str
    connection: str = Field(description="connected, storage_access, door or disconnected.")
    blocked: bool = Field(description="Closed by an operator.")
    portal: tuple[float, float] | None = Field(
        description="Middle of the regions' shared boundary (x, y), metres, map frame; null when they share none.")
    width_m: float | None = Field(description="Length of the shared boundary, metres (approximate).")


class TopologyGraphOut(BaseModel):
    map: str
    revision: int | None = Field(description="The revision read at (also the header `X-Aisle-Revision-Id`); null "
                                             "when the map has no revisions.")
    segments_revision_id: int | None = Field(description="Revision of the place_segments layer the graph is of.")


_TOPOLOGY_EXAMPLE: dict[str, Any] = {
    "directed": False, "multigraph": False, "graph": {"map": "site", "revision": 42, "segments_revision_id": 40},
    "nodes": [{"id": "r17", "kind": "corridor", "x": 8.4, "y": 5.6, "area_m2": 36.1, "aisle": "aisle-03",
               "drivable": True, "blocked": False},
              {"id": "r16", "kind": "junction", "x": 1.5, "y": 5.6, "area_m2": 9.0, "aisle": None, "drivable": True,
               "blocked": False}],
    "edges": [{"source": "r16", "target": "r17", "connection": "connected", "blocked": False,
               "portal": [3.05, 5.62], "width_m": 3.0}]}
_TOPOLOGY_GEOJSON_EXAMPLE: dict[str, Any] = {"type": "FeatureCollection", "revision": 42, "features": [
    {"type": "Feature", "id": "r17", "geometry": {"type": "Point", "coordinates": [8.4, 5.6]},
     "properties": {"kind": "corridor", "area_m2": 36.1, "aisle": "aisle-03", "drivable": True, "blocked": False}},
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
    revision: int | None = Field(description="The revision read at, or null for the newest.")

    model_config = example_config(**_TOPOLOGY_GEOJSON_EXAMPLE)


@router.get("/topology", summary="The region graph", tags=["topology"], responses=naming_revision({
    **_READ_ERRORS, status.HTTP_200_OK: {"content": {"application/json": {"examples": {
        "node-link": {"summary": "?format=node-link", "value": _TOPOLOGY_EXAMPLE},
        "geojson": {"summary": "?format=geojson", "value": _TOPOLOGY_GEOJSON_EXAMPLE}}}}}}))
def get_topology(
    response: Response,
    map_info: MapDep,
    store: StoreDep,
    revision: RevisionQuery,
    cache: CacheDep,
    format: Annotated[Literal["node-link", "geojson"], Query(
        description="`node-link` (networkx JSON) or `geojson` (regions as points, connections as lines).",
        examples=["node-link"])] = "node-link",
) -> TopologyOut | TopologyGeoJSONOut:
    """Regions of the grid decomposition and their connections (as of ``?revision=``), with portals and the
    operator's blocks. A map not decomposed yet has an empty graph. The revision read at (the newest without
    ``?revision=``) is in the answer and in the header ``X-Aisle-Revision-Id``."""
    try:
        nav = load_navmap(store, map_info.id, revision=revision, cache=cache)
    except NavigationUnavailableError:
        latest = store.latest_revision(map_info.id) if revision is None else None
        at = revision if latest is None else latest.id
        if at is not None:
            response.headers[REVISION_HEADER] = str(at)
        if format == "geojson":
            return TopologyGeoJSONOut(features=[], revision=at)
        return TopologyOut(directed=False, multigraph=False, nodes=[], edges=[],
                           graph=TopologyGraphOut(map=map_info.name, revision=at, segments_revision_id=None))
    if nav.revision is not None:
        response.headers[REVISION_HEADER] = str(nav.revision)
    if format == "geojson":
        return TopologyGeoJSONOut(features=[TopologyFeatureOut.model_validate(item) for item in topology_features(nav)],
                                  revision=nav.revision)
    return TopologyOut.model_validate(topology_node_link(nav, map_name=map_info.name))


