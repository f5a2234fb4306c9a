"""Classified map C_M (eq. 3.7), world rendering C_W (eq. 3.8), the 3x3 sensor model and K(W,M).

The log posterior of a world is ``sum_cells log p(C_M | C_W) + gamma * log psi2`` (eqs. 3.5, 3.6) plus
the context prior (:mod:`~services.floor_plan.context`). :class:`Canvas` keeps per-cell counts of
unit interiors, walls and doors so that a kernel re-scores only the cells it changes.
"""

from __future__ import annotations

import enum
from collections.abc import Iterable, Sequence
from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt
from skimage.morphology import skeletonize

from services.floor_plan.errors import FloorPlanError
from services.floor_plan.world import Rect, World


class CellClass(enum.IntEnum):
    """Cell classes of C_M and C_W (eqs. 3.7, 3.8)."""

    FREE = 0
    UNKNOWN = 1
    WALL = 2


SEED_SENSOR_MODEL: tuple[tuple[float, ...], ...] = ((0.8, 0.1, 0.1), (0.1, 0.8, 0.1), (0.1, 0.1, 0.8))
"""Table 3.1 as ``p[C_W][C_M]`` in :class:`CellClass` order (free, unknown, wall)."""


def classify_map(
    occupancy: npt.NDArray[np.integer], *, occupied_percent: int = 65, free_percent: int = 25
) -> npt.NDArray[np.uint8]:
    """C_M (eq. 3.7): occupancy (-1 unknown, 0..100) -> :class:`CellClass` codes, uint8 of the same shape.

    Raises
    ------
    FloorPlanError
        Not a 2-D map, smaller than 3x3 cells, or without any free cell.
    """
    occ = np.asarray(occupancy)
    if occ.ndim != 2 or min(occ.shape) < 3:
        raise FloorPlanError(f"occupancy must be a 2-D grid of at least 3x3 cells, got shape {occ.shape}")
    if not 0 <= free_percent < occupied_percent <= 100:
        raise FloorPlanError(
            f"need 0 <= free_percent < occupied_percent <= 100, got {free_percent}, {occupied_percent}"
        )
    out = np.full(occ.shape, CellClass.UNKNOWN, dtype=np.uint8)
    out[occ >= occupied_percent] = CellClass.WALL
    out[(occ >= 0) & (occ <= free_percent)] = CellClass.FREE
    if not (out == CellClass.FREE).any():
        raise FloorPlanError("the map has no free cell: nothing to explain with units")
    return out


def beam_traces(classes: npt.NDArray[np.uint8], *, width_cells: int) -> npt.NDArray[np.bool_]:
    """Free cells that are the traces of single laser beams through space the map has not seen (through a window or
    a door into the unknown outside): free runs narrower than ``width_cells`` (in no square of that many free cells
    a side) beside an unknown cell. Free space a robot saw, a room's floor, a doorway, is wider; a trace between
    furniture drawn occupied has no unknown beside it.

    >>> cm = np.full((9, 12), CellClass.UNKNOWN, np.uint8); cm[1:8, 1:6] = CellClass.FREE  # a room seen free
    >>> cm[4, 6:12] = CellClass.FREE  # a beam from it into the unknown
    >>> np.argwhere(beam_traces(cm, width_cells=3)).tolist()
    [[4, 6], [4, 7], [4, 8], [4, 9], [4, 10], [4, 11]]
    """
    free = (classes == CellClass.FREE).astype(np.uint8)
    seen = cv2.morphologyEx(free, cv2.MORPH_OPEN, np.ones((width_cells, width_cells), np.uint8),
                            borderType=cv2.BORDER_REPLICATE)
    unknown = (classes == CellClass.UNKNOWN).astype(np.uint8)
    out: npt.NDArray[np.bool_] = (free > seen) & (cv2.dilate(unknown, np.ones((3, 3), np.uint8)) > 0)
    return out


def log_sensor_table(model: Sequence[Sequence[float]] = SEED_SENSOR_MODEL) -> npt.NDArray[np.float64]:
    """Log of a 3x3 sensor model ``p[C_W][C_M]``; rows are normalised to sum to one."""
    table = np.asarray(model, dtype=np.float64)
    if table.shape != (3, 3) or (table <= 0).any():
        raise FloorPlanError(f"the sensor model must be 3x3 positive probabilities, got {table.tolist()}")
    out: npt.NDArray[np.float64] = np.log(table / table.sum(axis=1, keepdims=True))
    return out


def render(world: World, shape: tuple[int, int], *, wall_cells: int,
           obstacles: npt.NDArray[np.bool_] | None = None) -> npt.NDArray[np.uint8]:
    """C_W (eq. 3.8): walls where a unit's wall is not opened by a door, free inside units, else unknown.

    ``obstacles`` (solid blocks of the map, :func:`solid_obstacles`) render as walls too.
    """
    n_int, n_wall, n_door = _counts(world, shape, wall_cells)
    if obstacles is not None:
        n_wall += obstacles
    return _classes(n_int, n_wall, n_door)


def solid_obstacles(classes_map: npt.NDArray[np.uint8], *, min_cells: int) -> npt.NDArray[np.bool_]:
    """Solid blocks of the map: occupied cells inside an occupied square of ``min_cells`` (rounded up to odd;
    a morphological opening), e.g. rack blocks drawn solid or the filled outside of a building. Thin walls are not."""
    walls = (classes_map == CellClass.WALL).astype(np.uint8)
    side = min_cells | 1  # an odd square: OpenCV's opening by an even one comes back shifted by a cell
    opened = cv2.morphologyEx(walls, cv2.MORPH_OPEN, np.ones((side, side), np.uint8))
    return opened.astype(bool)


def wall_thickness_cells(classes_map: npt.NDArray[np.uint8], *, obstacles: npt.NDArray[np.bool_]) -> int:
    """The map's typical wall thickness in cells (at least 1): its wall cells (occupied, not a solid obstacle)
    over the length of their skeleton, i.e. the mean width of its walls; 2 for a map without such walls.

    >>> grid = np.zeros((9, 12), np.uint8); grid[4, 1:11] = CellClass.WALL
    >>> wall_thickness_cells(grid, obstacles=np.zeros(grid.shape, bool))
    1
    """
    walls = (classes_map == CellClass.WALL) & ~obstacles
    length = int(np.count_nonzero(skeletonize(walls)))  # type: ignore[no-untyped-call]  # skimage is untyped
    if length == 0:
        return 2
    return max(1, round(int(np.count_nonzero(walls)) / length))


def enclosed_blocks(obstacles: npt.NDArray[np.bool_]) -> npt.NDArray[np.bool_]:
    """The solid obstacles that do not touch the map's border: blocks standing in the building (racks drawn
    solid, solid furniture), as opposed to a filled outside."""
    count, labels = cv2.connectedComponents(obstacles.astype(np.uint8), connectivity=8)
    border = np.unique(np.r_[labels[0], labels[-1], labels[:, 0], labels[:, -1]])
    inside = np.ones(count, bool)
    inside[border] = False
    inside[0] = False
    out: npt.NDArray[np.bool_] = inside[labels]
    return out


def cell_prediction_rate(classes_map: npt.NDArray[np.uint8], classes_world: npt.NDArray[np.uint8]) -> float:
    """K(W,M) (eq. 3.39): the share of all cells where C_M equals C_W."""
    return float(np.mean(classes_map == classes_world))


class CellOp(NamedTuple):
    sign: int
    rect: Rect
    door: bool


def _counts(
    world: World, shape: tuple[int, int], wall_cells: int
) -> tuple[npt.NDArray[np.int16], npt.NDArray[np.int16], npt.NDArray[np.int16]]:
    counts = (np.zeros(shape, np.int16), np.zeros(shape, np.int16), np.zeros(shape, np.int16))
    ops = [CellOp(1, r, False) for r in world.units.values()] + [CellOp(1, d, True) for d in world.doors]
    _apply(counts, ops, Rect(0, shape[0] - 1, 0, shape[1] - 1), wall_cells)
    return counts


def _classes(
    n_int: npt.NDArray[np.int16], n_wall: npt.NDArray[np.int16], n_door: npt.NDArray[np.int16]
) -> npt.NDArray[np.uint8]:
    out = np.full(n_int.shape, CellClass.UNKNOWN, dtype=np.uint8)
    out[(n_int > 0) | (n_door > 0)] = CellClass.FREE
    out[(n_wall > 0) & (n_door == 0)] = CellClass.WALL
    return out


def _clip(rect: Rect, window: Rect) -> tuple[slice, slice] | None:
    r0, r1 = max(rect.r0, window.r0), min(rect.r1, window.r1)
    c0, c1 = max(rect.c0, window.c0), min(rect.c1, window.c1)
    if r0 > r1 or c0 > c1:
        return None
    return slice(r0 - window.r0, r1 - window.r0 + 1), slice(c0 - window.c0, c1 - window.c0 + 1)


def _apply(
    counts: tuple[npt.NDArray[np.int16], npt.NDArray[np.int16], npt.NDArray[np.int16]],
    ops: Iterable[CellOp],
    window: Rect,
    wall_cells: int,
) -> None:
    """Add (sign +1) or remove (-1) units and doors on count arrays covering ``window``."""
    n_int, n_wall, n_door = counts
    for sign, rect, door in ops:
        outer = _clip(rect, window)
        if outer is None:
            continue
        if door:
            n_door[outer] += sign
            continue
        n_wall[outer] += sign
        inner = _clip(rect.inner(wall_cells), window)
        if inner is not None:
            n_wall[inner] -= sign
            n_int[inner] += sign


class Canvas:
    """The world's cell counts over the map and its log likelihood + overlap prior, updated incrementally.

    Parameters
    ----------
    classes_map : (H, W) uint8
        C_M.
    log_table : (3, 3) float
        ``log p[C_W][C_M]`` (:func:`log_sensor_table`).
    wall_cells : int
        Wall thickness in cells.
    log_overlap : float
        log psi2 (< 0): the prior's penalty per cell claimed by one unit more than one (eq. 3.5).
    obstacles : (H, W) bool, optional
        Solid obstacles: fixed walls of the world; a unit's free space on them pays the overlap penalty.
    blocks : (H, W) bool, optional
        The obstacles standing in the building (:func:`enclosed_blocks`): fixed walls a unit may stand
        around without penalty (a hall around its racks); they are never part of a unit's free space.
    """

    def __init__(
        self, classes_map: npt.NDArray[np.uint8], log_table: npt.NDArray[np.float64], *, wall_cells: int,
        log_overlap: float, obstacles: npt.NDArray[np.bool_] | None = None,
        blocks: npt.NDArray[np.bool_] | None = None,
    ) -> None:
        self.shape: tuple[int, int] = (int(classes_map.shape[0]), int(classes_map.shape[1]))
        self.wall_cells = wall_cells
        self.log_overlap = log_overlap
        # per-cell log-likelihood of unknown, and the gain of rendering free / wall instead
        ll = log_table[:, classes_map].astype(np.float64)
        self._unknown = np.zeros((self.shape[0] + 1, self.shape[1] + 1))
        self._unknown[1:, 1:] = ll[CellClass.UNKNOWN].cumsum(0).cumsum(1)
        self._gain_free = np.ascontiguousarray(ll[CellClass.FREE] - ll[CellClass.UNKNOWN])
        self._gain_wall = np.ascontiguousarray(ll[CellClass.WALL] - ll[CellClass.UNKNOWN])
        self._counts = (np.zeros(self.shape, np.int16), np.zeros(self.shape, np.int16), np.zeros(self.shape, np.int16))
        self.full = Rect(0, self.shape[0] - 1, 0, self.shape[1] - 1)
        self.score = float(self._unknown[-1, -1])
        # blocks standing in the building: fixed walls a unit may stand around (a hall around its racks)
        self._blocks = np.zeros(self.shape, bool) if blocks is None else blocks.astype(bool)
        if obstacles is not None:  # fixed walls of the world: counted once, never moved
            self._counts[1][obstacles & ~self._blocks] = 1
        if obstacles is not None or blocks is not None:
            self.score = self._window_score(self._counts, self.full)

    def classes(self) -> npt.NDArray[np.uint8]:
        """C_W of the current counts."""
        out = _classes(*self._counts)
        out[self._blocks] = CellClass.WALL
        return out

    def _window_score(
        self, counts: tuple[npt.NDArray[np.int16], npt.NDArray[np.int16], npt.NDArray[np.int16]], window: Rect
    ) -> float:
        n_int, n_wall, n_door = counts
        sl = (slice(window.r0, window.r1 + 1), slice(window.c0, window.c1 + 1))
        u = self._unknown
        total = u[window.r1 + 1, window.c1 + 1] - u[window.r0, window.c1 + 1] - u[window.r1 + 1, window.c0] + u[
            window.r0, window.c0]
        has_wall = n_wall > 0
        door = n_door > 0
        wall = (has_wall & ~door) | self._blocks[sl]
        free = ~wall & ((n_int > 0) | door)
        total += float(np.sum(self._gain_free[sl], where=free)) + float(np.sum(self._gain_wall[sl], where=wall))
        overlap = int(np.count_nonzero(n_int > 1)) + int(np.count_nonzero(has_wall & (n_int > 0)))
        if overlap:
            gamma = n_int.astype(np.int32) + has_wall - 1
            return float(total) + self.log_overlap * float(np.maximum(gamma, 0).sum())
        return float(total)

    def _view(self, window: Rect) -> tuple[npt.NDArray[np.int16], npt.NDArray[np.int16], npt.NDArray[np.int16]]:
        sl = (slice(window.r0, window.r1 + 1), slice(window.c0, window.c1 + 1))
        a, b, c = self._counts
        return a[sl], b[sl], c[sl]

    def delta(self, ops: Sequence[CellOp], windows: Sequence[Rect]) -> float:
        """Change of the score if ``ops`` were applied; every cell they change must lie in ``windows``.

        The windows must not overlap each other.
        """
        total = 0.0
        for w in windows:
            view = self._view(w)
            before = self._window_score(view, w)
            trial = (view[0].copy(), view[1].copy(), view[2].copy())
            _apply(trial, ops, w, self.wall_cells)
            total += self._window_score(trial, w) - before
        return total

    def commit(self, ops: Sequence[CellOp], delta: float) -> None:
        _apply(self._counts, ops, self.full, self.wall_cells)
        self.score += delta

    def rescore(self) -> float:
        """The score recomputed over the whole map (for checks)."""
        return self._window_score(self._counts, self.full)


def unit_op(sign: int, rect: Rect) -> CellOp:
    return CellOp(sign, rect, False)


def door_op(sign: int, rect: Rect) -> CellOp:
    return CellOp(sign, rect, True)
