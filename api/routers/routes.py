"""Drivable routes between bins, places and points."""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import APIRouter, Query, status
from pydantic import BaseModel, Field

from api.deps import CacheDep, MapDep, RevisionQuery, StoreDep
from api.models import COMMON_ERRORS, UNPROCESSABLE, ErrorOut, Responses, not_found
from api.translate import http_error
from atlas.errors import AtlasError
from atlas.navigation import FREE_BELOW, NavigationError
from atlas.navigation.plan import route_between

router = APIRouter(prefix="/v1/maps/{map_name}", responses=COMMON_ERRORS)

_ROUTE_ERRORS: Responses = {
    **not_found("No such map, revision, bin or place."),
    status.HTTP_409_CONFLICT: {"model": ErrorOut, "description": "No drivable route: an end is off every drivable "
                                                                 "region or in a blocked one, the regions do not "
                                                                 "connect, or the map has no regions yet."},
    **UNPROCESSABLE,
}


class RouteEnd(BaseModel):
    spec: str = Field(description="The end as asked, e.g. `bin:01-003-02`.")
    x_m: float = Field(description="Where the end is (a bin's access pose, a place's approach point): x, metres, "
                                   "map frame.")
    y_m: float = Field(description="y, metres, map frame.")
    yaw_rad: float | None = Field(description="Heading there, if the end has one (radians from the map frame's x "
                                              "axis).")
    region: str = Field(description="Key of the drivable region the route starts or ends in.")


class WaypointOut(BaseModel):
    x_m: float = Field(description="x, metres, map frame.")
    y_m: float = Field(description="y, metres, map frame.")
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
    length_m: float = Field(description="Along the waypoints, metres.")
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
        planned = route_between(store, cache, map_info.id, start=from_, goal=to, avoid=avoid, revision=revision)
    except (AtlasError, NavigationError) as err:
        raise http_error(err) from err
    nav, route, start, goal = planned.nav, planned.route, planned.start, planned.goal
    first, last = route.waypoints[0], route.waypoints[-1]
    passed = [RegionPassed(key=nav.key(r), kind=nav.regions[r].kind) for r in route.regions]
    return RouteOut(
        start=RouteEnd(spec=from_, x_m=start.x_m, y_m=start.y_m, yaw_rad=start.yaw_rad, region=first.region),
        goal=RouteEnd(spec=to, x_m=goal.x_m, y_m=goal.y_m, yaw_rad=goal.yaw_rad, region=last.region),
        waypoints=[WaypointOut(x_m=w.x_m, y_m=w.y_m, region=w.region, kind=w.kind) for w in route.waypoints],
        regions=passed,
        corridors=planned.corridors,
        length_m=round(route.length_m, 3),
        revision=nav.revision,
        free_below=FREE_BELOW,
    )
