"""Shortest drivable routes between two map points, region to portal to region.

The search graph has a node per portal between two usable regions (drivable, not blocked nor
avoided, joined by a ``connected`` or ``door`` connection) plus the two ends; inside each region
every pair of its portals (and an end in it) is joined by the straight distance. A* over that graph
gives a candidate; each leg of it is then checked on the free cells of the usable regions and, when
the straight leg is not free, replaced by a grid search inside its region; the leg's weight becomes
its true length (or the leg is dropped when the region has no free way through) and the search runs
again, until the shortest route consists of checked legs only. Straight distances never exceed true
lengths, so the result is the shortest among routes through the same portals. Last, corners that the
previous corner sees straight on the free cells are dropped, so the route does not detour through
portal midpoints; the regions passed are read off that straightened line.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Collection, Hashable
from dataclasses import dataclass
from typing import Any, Literal

import networkx as nx

from atlas.navigation.errors import NoRouteError
from atlas.navigation.graph import LOCATE_TOLERANCE_M, ROUTE_CONNECTIONS, NavMap
from atlas.navigation.grid import BoolGrid, Point, grid_path, grown, segment_clear

START, GOAL = "start", "goal"
WaypointKind = Literal["start", "portal", "via", "goal"]


@dataclass(frozen=True, slots=True)
class Waypoint:
    """A point of a route (map metres) in region ``region`` (its key).

    ``kind``: ``start``; ``portal`` (the route enters ``region`` here); ``via`` (a corner inside
    ``region`` where a straight leg would leave the free cells); ``goal``.
    """

    x_m: float
    y_m: float
    region: str
    kind: WaypointKind


@dataclass(frozen=True, slots=True)
class Route:
    """Waypoints from start to goal, the regions passed in order (ids), and the length in metres."""

    waypoints: tuple[Waypoint, ...]
    regions: tuple[int, ...]
    length_m: float


def usable_graph(nav: NavMap, *, avoid: Collection[int] = ()) -> nx.Graph:
    """Regions a route may use (drivable, not blocked, not in ``avoid``) and the connections it may take
    (``connected`` or ``door``, not blocked, with a portal), weighted by centroid-portal-centroid metres."""
    usable = nav.drivable_ids - nav.blocked_ids - set(avoid)
    graph = nx.Graph()
    graph.add_nodes_from(usable)
    for a, b, data in nav.graph.edges(data=True):
        portal = data["portal"]
        if (a in usable and b in usable and data["connection"] in ROUTE_CONNECTIONS and not data["blocked"]
                and portal is not None):
            ha, hb = nav.hub(a), nav.hub(b)
            weight = (math.dist(ha, (portal.x_m, portal.y_m)) if ha else 0.0) + (
                math.dist((portal.x_m, portal.y_m), hb) if hb else 0.0)
            graph.add_edge(a, b, portal=portal, weight=weight)
    return graph


def _why_not(nav: NavMap, rid: int, avoid: Collection[int], end: str) -> str | None:
    if rid in nav.blocked_ids:
        reasons = [b.block.reason for b in nav.blocks
                   if b.block.is_region and b.ids is not None and rid in b.ids and b.block.reason]
        why = f" ({reasons[0]})" if reasons else ""
        return f"the {end} lies in {nav.describe(rid)}, which is blocked{why}; unblock it or choose another {end}"
    if rid in avoid:
        return f"the {end} lies in {nav.describe(rid)}, which the request asks to avoid"
    return None


def plan_route(nav: NavMap, start: Point, goal: Point, *, avoid: Collection[int] = (),
               tolerance_m: float = LOCATE_TOLERANCE_M) -> Route:
    """The shortest drivable route from ``start`` to ``goal`` (map metres).

    Parameters
    ----------
    nav : NavMap
        The map.
    start, goal : (float, float)
        The ends; each may lie up to ``tolerance_m`` off a free drivable cell (a bin's access pose
        at an aisle's edge), and then starts or ends at that cell's centre.
    avoid : collection of int
        Region ids not to pass, on top of the blocked ones.

    Raises
    ------
    NoRouteError
        An end is off every drivable region or in a blocked or avoided one, or no usable regions
        and connections join the ends.
    """
    ends: list[tuple[int, Point]] = []
    for name, point in (("start", start), ("goal", goal)):
        found = nav.locate(*point, tolerance_m=tolerance_m)
        if found is None:
            raise NoRouteError(f"the {name} ({point[0]:.2f}, {point[1]:.2f}) is not within {tolerance_m:g} m of "
                               "a free cell of any drivable region (corridor, junction, room, open area)")
        why = _why_not(nav, found[0], avoid, name)
        if why is not None:
            raise NoRouteError(why)
        ends.append(found)
    (first, a), (last, b) = ends
    regions = usable_graph(nav, avoid=avoid)
    if not nx.has_path(regions, first, last):
        closed = len(nav.blocked_ids) + len(nav.blocked_pairs) + len(set(avoid))
        hint = f"; {closed} blocked or avoided regions and connections are left out" if closed else ""
        raise NoRouteError(f"no drivable connection joins {nav.describe(first)} and {nav.describe(last)}{hint}")
    mask = nav.mask(set(regions.nodes))
    search = _search_graph(nav, regions.subgraph(nx.node_connected_component(regions, first)), first, a, last, b)
    path = _shortest_checked(nav, search, mask)
    return _straightened(nav, _route(nav, search, path), mask)


def _search_graph(nav: NavMap, regions: nx.Graph, first: int, a: Point, last: int, b: Point) -> nx.Graph:
    search = nx.Graph()
    search.add_node(START, xy=a, region=first)
    search.add_node(GOAL, xy=b, region=last)
    for u, v, data in regions.edges(data=True):
        search.add_node((min(u, v), max(u, v)), xy=(data["portal"].x_m, data["portal"].y_m), region=None)
    for rid in regions.nodes:
        members: list[Hashable] = [(min(u, v), max(u, v)) for u, v in regions.edges(rid)]
        members += [end for end, region in ((START, first), (GOAL, last)) if region == rid]
        for i, u in enumerate(members):
            for v in members[i + 1:]:
                xy_u, xy_v = search.nodes[u]["xy"], search.nodes[v]["xy"]
                search.add_edge(u, v, region=rid, weight=math.dist(xy_u, xy_v), checked=False, via=())
    return search


def _shortest_checked(nav: NavMap, search: nx.Graph, mask: BoolGrid) -> list[Any]:
    def straight(u: Any, v: Any) -> float:
        return math.dist(search.nodes[u]["xy"], search.nodes[v]["xy"])

    while True:
        try:
            path: list[Any] = nx.astar_path(search, START, GOAL, heuristic=straight, weight="weight")
        except nx.NetworkXNoPath as err:
            raise NoRouteError("the regions connect, but the occupancy grid leaves no free way through them "
                               "(an obstacle since the decomposition?)") from err
        unchecked = [(u, v) for u, v in itertools.pairwise(path) if not search.edges[u, v]["checked"]]
        if not unchecked:
            return path
        for u, v in unchecked:
            _check_leg(nav, search, mask, u, v)


def _check_leg(nav: NavMap, search: nx.Graph, mask: BoolGrid, u: Any, v: Any) -> None:
    data = search.edges[u, v]
    p, q = search.nodes[u]["xy"], search.nodes[v]["xy"]
    if segment_clear(mask, nav.frame, p, q):
        data["checked"] = True
        return
    rid = data["region"]
    slices = grown(nav.grid.slices[rid], nav.frame.shape, 2)
    inside = (nav.grid.segments[slices] == rid) & mask[slices]
    points = grid_path(mask, nav.frame, p, q, within=slices) if inside.any() else None
    if points is None:
        search.remove_edge(u, v)
        return
    data.update(checked=True, via=tuple(points[1:-1]), via_from=u,
                weight=sum(math.dist(s, t) for s, t in itertools.pairwise(points)))


def _straightened(nav: NavMap, route: Route, mask: BoolGrid, *, step_m: float = 0.25) -> Route:
    """``route`` with every corner dropped that the previous kept corner sees straight on the free cells of the
    usable regions (so it no longer detours through portal midpoints), and the regions passed read off the
    straightened line."""
    points = [(w.x_m, w.y_m) for w in route.waypoints]
    kept = [0]
    while kept[-1] < len(points) - 1:
        i, j = kept[-1], kept[-1] + 1
        while j + 1 < len(points) and segment_clear(mask, nav.frame, points[i], points[j + 1]):
            j += 1
        kept.append(j)
    if len(kept) == len(points):
        return route
    waypoints = tuple(route.waypoints[k] for k in kept)
    segments = nav.grid.segments
    regions: list[int] = []
    length = 0.0
    for a, b in itertools.pairwise(waypoints):
        leg = math.hypot(b.x_m - a.x_m, b.y_m - a.y_m)
        length += leg
        for t in [k / max(1, math.ceil(leg / step_m)) for k in range(math.ceil(leg / step_m) + 1)]:
            row, col = nav.frame.cell(a.x_m + t * (b.x_m - a.x_m), a.y_m + t * (b.y_m - a.y_m))
            rid = int(segments[row, col]) if nav.frame.inside(row, col) else 0
            if rid and (not regions or regions[-1] != rid):
                regions.append(rid)
    return Route(waypoints, tuple(regions) or route.regions, length)


def _waypoint(xy: Point, region: str, kind: WaypointKind) -> Waypoint:
    return Waypoint(float(xy[0]), float(xy[1]), region, kind)


def _route(nav: NavMap, search: nx.Graph, path: list[Any]) -> Route:
    waypoints: list[Waypoint] = []
    regions: list[int] = []
    length = 0.0
    for i, node in enumerate(path):
        if i == 0:
            rid = search.nodes[node]["region"]
            regions.append(rid)
            waypoints.append(_waypoint(search.nodes[node]["xy"], nav.key(rid), "start"))
            continue
        edge = search.edges[path[i - 1], node]
        rid = edge["region"]
        if rid != regions[-1]:
            regions.append(rid)
        via = edge["via"] if edge.get("via_from", path[i - 1]) == path[i - 1] else edge["via"][::-1]
        waypoints.extend(_waypoint(xy, nav.key(rid), "via") for xy in via)
        length += edge["weight"]
        if node == GOAL:
            waypoints.append(_waypoint(search.nodes[node]["xy"], nav.key(rid), "goal"))
        else:
            entered = node[1] if node[0] == rid else node[0]
            waypoints.append(_waypoint(search.nodes[node]["xy"], nav.key(entered), "portal"))
    return Route(tuple(waypoints), tuple(regions), length)
