"""Route planning on small literal maps: portals in order, corners round obstacles, blocks and connections."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from atlas.navigation import Block, NavMap, NoRouteError, build_navmap, plan_route
from atlas.navigation.graph import region_grid
from atlas.navigation.grid import segment_clear
from shared.store import GridLayer, TopologyEdge, TopologyNode

RES = 0.1


def _map(segments: np.ndarray, occupancy: np.ndarray, kinds: dict[int, str],
         links: list[tuple[int, int, str]], blocks: tuple[Block, ...] = ()) -> NavMap:
    grid = region_grid(GridLayer("place_segments", segments.astype(np.uint16), RES, 0.0, 0.0),
                       GridLayer("occupancy", occupancy.astype(np.int8), RES, 0.0, 0.0),
                       segments_revision=1, occupancy_revision=1)
    nodes = [TopologyNode(f"r{i}", kind, *grid.frame.centre(*np.argwhere(segments == i).mean(axis=0)), {})
             for i, kind in kinds.items()]
    nodes += [TopologyNode(b.keys[0], "blocked", b.x_m, b.y_m, b.attributes()) for b in blocks]
    edges = [TopologyEdge(f"r{a}", f"r{b}", {"connection": c}) for a, b, c in links]
    return build_navmap(grid, nodes, edges)


def _hall() -> tuple[np.ndarray, np.ndarray]:
    """A 1 m x 3 m hall in three rooms numbered 3, 1, 2 from left to right."""
    segments = np.zeros((10, 30), dtype=np.uint16)
    segments[:, :10], segments[:, 10:20], segments[:, 20:] = 3, 1, 2
    return segments, np.zeros((10, 30), dtype=np.int8)


def test_a_straight_route_lists_each_region_it_passes_in_order() -> None:
    segments, occupancy = _hall()
    nav = _map(segments, occupancy, {1: "corridor", 2: "room", 3: "junction"},
               [(3, 1, "connected"), (2, 1, "door")])
    route = plan_route(nav, (0.25, 0.55), (2.75, 0.55))
    assert [w.kind for w in route.waypoints] == ["start", "goal"]  # a straight line: no corner needed
    assert route.regions == (3, 1, 2)
    assert route.length_m == pytest.approx(2.5, abs=0.1)


@pytest.mark.parametrize("connection", ["storage_access", "disconnected"])
def test_only_connected_and_door_links_are_driven(connection: str) -> None:
    segments, occupancy = _hall()
    nav = _map(segments, occupancy, {1: "corridor", 2: "room", 3: "junction"},
               [(3, 1, "connected"), (1, 2, connection)])
    with pytest.raises(NoRouteError, match="no drivable connection"):
        plan_route(nav, (0.25, 0.55), (2.75, 0.55))


def test_an_end_in_storage_is_reached_from_the_drivable_region_beside_it_within_tolerance() -> None:
    segments, occupancy = _hall()
    nav = _map(segments, occupancy, {1: "corridor", 2: "storage", 3: "junction"}, [(3, 1, "connected")])
    route = plan_route(nav, (0.25, 0.55), (2.25, 0.55))
    assert route.waypoints[-1].region == "r1" and route.waypoints[-1].x_m < 2.0
    with pytest.raises(NoRouteError, match=r"not within 0\.5 m"):
        plan_route(nav, (0.25, 0.55), (2.75, 0.55), tolerance_m=0.5)


def test_a_leg_blocked_by_an_obstacle_goes_round_it_on_free_cells() -> None:
    segments, occupancy = _hall()
    occupancy[:8, 14:16] = 100  # a wall across the middle room with a gap at the top
    nav = _map(segments, occupancy, {1: "corridor", 2: "room", 3: "junction"},
               [(3, 1, "connected"), (1, 2, "connected")])
    route = plan_route(nav, (0.25, 0.25), (2.75, 0.25))
    assert any(w.kind == "via" and w.region == "r1" for w in route.waypoints)
    free = occupancy == 0
    points = [(w.x_m, w.y_m) for w in route.waypoints]
    assert all(segment_clear(free, nav.frame, p, q) for p, q in itertools.pairwise(points))
    assert route.length_m > 2.5


def test_blocked_regions_stop_routes_and_ends_in_them_are_named() -> None:
    segments, occupancy = _hall()
    middle = Block(("r1",), 1.55, 0.55, reason="spill")
    nav = _map(segments, occupancy, {1: "corridor", 2: "room", 3: "junction"},
               [(3, 1, "connected"), (1, 2, "connected")], (middle,))
    assert nav.blocked_ids == {1}
    with pytest.raises(NoRouteError, match="no drivable connection"):
        plan_route(nav, (0.25, 0.55), (2.75, 0.55))
    with pytest.raises(NoRouteError, match=r"r1 \(corridor\), which is blocked \(spill\)"):
        plan_route(nav, (1.55, 0.55), (2.75, 0.55))
    assert plan_route(nav, (0.25, 0.55), (0.75, 0.55)).regions == (3,)


def test_avoided_regions_are_left_out_like_blocked_ones() -> None:
    segments, occupancy = _hall()
    nav = _map(segments, occupancy, {1: "corridor", 2: "room", 3: "junction"},
               [(3, 1, "connected"), (1, 2, "connected")])
    with pytest.raises(NoRouteError, match="asks to avoid"):
        plan_route(nav, (0.25, 0.55), (1.55, 0.55), avoid={1})


def test_a_route_goes_round_a_rack_the_lidar_sees_through() -> None:
    """One open area, 4 m x 3 m, with a rack across its middle (x 1.9-2.1 m, y 0-2.5 m) whose bays are empty:
    the occupancy grid is free under it, but the bins' footprints are not drivable."""
    segments = np.ones((30, 40), dtype=np.uint16)
    rack = np.array([[1.9, 0.0], [2.1, 0.0], [2.1, 2.5], [1.9, 2.5], [1.9, 0.0]])
    grid = region_grid(GridLayer("place_segments", segments, RES, 0.0, 0.0),
                       GridLayer("occupancy", np.zeros((30, 40), dtype=np.int8), RES, 0.0, 0.0),
                       segments_revision=1, occupancy_revision=1, racks=[rack])
    nav = build_navmap(grid, [TopologyNode("r1", "open_area", 2.0, 1.5, {})], [])

    route = plan_route(nav, (0.5, 0.5), (3.5, 0.5))

    assert max(w.y_m for w in route.waypoints) > 2.5  # round the rack's end, not under it
    assert route.length_m > 2 * np.hypot(1.4, 2.0)  # at least to the rack end and back down
    for a, b in itertools.pairwise(route.waypoints):
        assert segment_clear(nav.grid.free, nav.frame, (a.x_m, a.y_m), (b.x_m, b.y_m))
