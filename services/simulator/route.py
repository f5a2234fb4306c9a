"""Routes for the simulated robots: through every aisle, or through given waypoints.

Consecutive waypoints are joined by a straight line when the robot fits along it, otherwise by
a shortest path on the ground-truth free space (obstacles grown by the robot radius).
"""

from __future__ import annotations

import math
from collections import defaultdict

import cv2
import numpy as np
import numpy.typing as npt
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from services.simulator.errors import SimulatorError
from services.simulator.groundtruth import ground_truth_grids
from services.simulator.world import AreaKind, FloatArray, World


class _FreeSpace:
    """Cells where the robot's centre may go, at ``resolution_m``."""

    def __init__(self, world: World, *, resolution_m: float, radius_m: float) -> None:
        grids = ground_truth_grids(world, resolution_m=resolution_m, height_m=0.2, margin_m=0.5)
        blocked = (grids.occupancy != 0).astype(np.uint8)
        clearance = cv2.distanceTransform(1 - blocked, cv2.DIST_L2, 5) * resolution_m
        self.free = clearance > radius_m
        self.origin = np.array([grids.origin_x_m, grids.origin_y_m])
        self.resolution_m = resolution_m

    def cell(self, point: FloatArray) -> tuple[int, int]:
        col, row = np.floor((point - self.origin) / self.resolution_m).astype(int)
        return int(row), int(col)

    def is_free(self, point: FloatArray) -> bool:
        row, col = self.cell(point)
        return 0 <= row < self.free.shape[0] and 0 <= col < self.free.shape[1] and bool(self.free[row, col])

    def line_free(self, a: FloatArray, b: FloatArray) -> bool:
        steps = max(2, math.ceil(float(np.hypot(*(b - a))) / (0.5 * self.resolution_m)))
        return all(self.is_free(a + f * (b - a)) for f in np.linspace(0.0, 1.0, steps))

    def plan(self, a: FloatArray, b: FloatArray) -> FloatArray:
        """Shortest 8-connected path a -> b through free cells, simplified, metres (k, 2)."""
        for name, p in (("start", a), ("goal", b)):
            if not self.is_free(p):
                raise SimulatorError(f"route {name} {np.round(p, 2).tolist()} is not in free space")
        rows, cols = self.free.shape
        index = np.arange(rows * cols).reshape(rows, cols)
        src_l, dst_l, w_l = [], [], []
        for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
            r0, r1 = max(0, -dr), rows - max(0, dr)
            c0, c1 = max(0, -dc), cols - max(0, dc)
            ok = self.free[r0:r1, c0:c1] & self.free[r0 + dr:r1 + dr, c0 + dc:c1 + dc]
            src_l.append(index[r0:r1, c0:c1][ok])
            dst_l.append(index[r0 + dr:r1 + dr, c0 + dc:c1 + dc][ok])
            w_l.append(np.full(int(ok.sum()), math.hypot(dr, dc)))
        src, dst, w = np.concatenate(src_l), np.concatenate(dst_l), np.concatenate(w_l)
        graph = coo_matrix((w, (src, dst)), shape=(rows * cols, rows * cols)).tocsr()
        start, goal = index[self.cell(a)], index[self.cell(b)]
        _, predecessors = dijkstra(graph, directed=False, indices=start, return_predecessors=True)
        if predecessors[goal] < 0:
            raise SimulatorError(f"no free path from {np.round(a, 2).tolist()} to {np.round(b, 2).tolist()}")
        cells = [goal]
        while cells[-1] != start:
            cells.append(int(predecessors[cells[-1]]))
        rc = np.array([divmod(c, cols) for c in reversed(cells)], dtype=np.float64)
        points = self.origin + (rc[:, ::-1] + 0.5) * self.resolution_m
        simplified = cv2.approxPolyDP(points.astype(np.float32).reshape(-1, 1, 2), 0.5 * self.resolution_m, False)
        middle = simplified.reshape(-1, 2).astype(np.float64)[1:-1]
        return np.vstack([a, middle, b])


def _aisle_lines(world: World) -> list[list[FloatArray]]:
    """Per block, each aisle's centreline (2, 2) from end to end, in aisle order."""
    by_block: dict[str, dict[int, list[FloatArray]]] = defaultdict(lambda: defaultdict(list))
    for area in world.areas:
        if area.kind is AreaKind.CORRIDOR and "aisle" in area.detail and "start" in area.detail:
            by_block[str(area.detail["block"])][int(area.detail["aisle"])].append(
                np.array([area.detail["start"], area.detail["end"]]))
    lines = []
    for block in by_block.values():
        block_lines = []
        for aisle in sorted(block):
            points = np.vstack(block[aisle])
            direction = points[1] - points[0]
            direction /= np.hypot(*direction)
            s = points @ direction
            block_lines.append(np.array([points[np.argmin(s)], points[np.argmax(s)]]))
        lines.append(block_lines)
    return lines


def survey_route(world: World, *, first_aisle: int = 0, overshoot_m: float = 1.2, radius_m: float = 0.45,
                 resolution_m: float = 0.1) -> FloatArray:
    """Waypoints (k, 2), metres, of a serpentine drive through every aisle of every block.

    Each aisle is driven from end to end and ``overshoot_m`` beyond, into the corridor, where the
    free space allows; consecutive aisles are joined by the shortest free path. The drive starts
    at aisle number ``first_aisle`` (counted from 0 over all blocks, modulo their number), so
    several robots can survey from different places.
    """
    space = _FreeSpace(world, resolution_m=resolution_m, radius_m=radius_m)
    legs: list[FloatArray] = []
    for block_lines in _aisle_lines(world):
        for i, line in enumerate(block_lines):
            a, b = (line if i % 2 == 0 else line[::-1]).copy()
            direction = (b - a) / np.hypot(*(b - a))
            for end, sign in ((0, -1.0), (1, 1.0)):
                for extra in np.linspace(overshoot_m, 0.0, 7):
                    candidate = (a, b)[end] + sign * extra * direction
                    if space.is_free(candidate):
                        if end == 0:
                            a = candidate
                        else:
                            b = candidate
                        break
            legs.append(np.array([a, b]))
    if not legs:
        raise SimulatorError(f"world {world.name!r} has no aisles to survey")
    start = first_aisle % len(legs)
    return connect(space, legs[start:] + legs[:start])


def connect(space: _FreeSpace, legs: list[FloatArray]) -> FloatArray:
    """Join polylines end to start, planning around obstacles where a straight join is blocked."""
    points = [legs[0]]
    for leg in legs[1:]:
        a, b = points[-1][-1], leg[0]
        if not space.line_free(a, b):
            points.append(space.plan(a, b)[1:-1])
        points.append(leg)
    route = np.vstack(points)
    keep = np.ones(len(route), bool)
    keep[1:] = np.hypot(*np.diff(route, axis=0).T) > 1e-6
    return route[keep]


def waypoint_route(world: World, waypoints: npt.ArrayLike, *, radius_m: float = 0.45,
                   resolution_m: float = 0.1) -> FloatArray:
    """A drivable route (k, 2) through ``waypoints`` (n, 2) in order, metres."""
    points = np.asarray(waypoints, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 2 or len(points) < 2 or not np.isfinite(points).all():
        raise SimulatorError(f"waypoints must be at least two finite [x, y] points, got shape {points.shape}")
    space = _FreeSpace(world, resolution_m=resolution_m, radius_m=radius_m)
    return connect(space, [p[None] for p in points])
